//! `sylva-bake`: turns glTF trees and tree placements into a Sylva scene
//! (LoD packs + grouped-batch tiles + manifest). See `--help`.

mod cli;

fn main() {
    cli::main();
}

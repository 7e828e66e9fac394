//! `sylva-bake library`: the built-in species library.

use anyhow::Result;
use clap::Subcommand;
use sylva_bake::library::GENERA;

/// What `sylva-bake library` does.
#[derive(Subcommand)]
pub(crate) enum LibraryCommand {
    /// The library's genera: family, form, leaf and bark, and how to name one
    /// in `--model` (`NAME=library:GENUS[:VARIANT]`).
    List {
        /// Print a JSON array instead of text.
        #[arg(long)]
        json: bool,
    },
}

pub(crate) fn library(command: &LibraryCommand) -> Result<()> {
    match command {
        LibraryCommand::List { json } => {
            if *json {
                let rows: Vec<serde_json::Value> = GENERA
                    .iter()
                    .map(|g| {
                        serde_json::json!({
                            "genus": g.name,
                            "family": g.family,
                            "conifer": g.conifer,
                            "leaf": format!("{:?}", g.leaf).to_lowercase(),
                            "bark": format!("{:?}", g.bark).to_lowercase(),
                            "crown_ratio": g.crown_ratio,
                            "model": format!("library:{}", g.name),
                        })
                    })
                    .collect();
                println!("{}", serde_json::Value::Array(rows));
            } else {
                println!("{} genera (use as --model NAME=library:GENUS[:VARIANT]):", GENERA.len());
                for g in GENERA.iter() {
                    println!(
                        "  {:<12} {:<13} {:<9} leaves {:<8} bark {:<9} crown width/height {:.2}–{:.2}",
                        g.name,
                        g.family,
                        if g.conifer { "conifer" } else { "broadleaf" },
                        format!("{:?}", g.leaf).to_lowercase(),
                        format!("{:?}", g.bark).to_lowercase(),
                        g.crown_ratio[0],
                        g.crown_ratio[1]
                    );
                }
            }
            Ok(())
        }
    }
}

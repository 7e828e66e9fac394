//! The integration tests of `sylva-bake`, one module a subject, in one test
//! binary (one link instead of four; docs/BENCHMARKS.md, "The test suite's
//! time"). Run one module with `cargo test -p sylva-bake --test it cli::`.

mod common;

mod cli;
mod out_safety;
mod slurm;
mod terrain;

//! Species names and tables (issue 44): any bytes as a `--species-table` CSV
//! → a table or an error, never a panic; then every line of the bytes as an
//! inventory label through the library's choice (table code, Latin genus,
//! common name, family, archetype) and the seasons a `--model` of that name
//! would get — a tree for every label, and a code the table holds always
//! answers with its Latin name.
#![no_main]
use libfuzzer_sys::fuzz_target;
use sylva_bake::input::allometry::Allometry;
use sylva_bake::input::names::SpeciesTable;
use sylva_bake::library::choose::{autumn_of, choose};

fuzz_target!(|data: &[u8]| {
    let table = SpeciesTable::parse(data, "fuzz").ok();
    let mut allometry = Allometry::default();
    allometry.species_table = table;
    let text = String::from_utf8_lossy(data);
    for label in text.lines().take(64) {
        let (genus, _why) = choose(label, &allometry);
        assert!(!genus.name.is_empty());
        let _ = autumn_of(label);
        if let Some(t) = &allometry.species_table {
            if let Some((latin, _)) = t.latin(label) {
                assert!(!latin.is_empty(), "an empty Latin name for {label:?}");
            }
        }
    }
});

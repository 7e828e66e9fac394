//! The inventory CSV's header path (issue 42): any bytes as a CSV file → its
//! header record (up to a line break outside quotes, at most 1 MiB), the
//! separator detected from it, then every row streamed with its attributes —
//! an error or rows, never a panic, and every row's attribute values as many
//! as the header's attribute names.
#![no_main]
use libfuzzer_sys::fuzz_target;
use sylva_bake::input::placements::{detect_delimiter, header_record, stream_csv, ReadOptions, Report, MAX_HEADER_BYTES};

fuzz_target!(|data: &[u8]| {
    let Ok(header) = header_record(data, MAX_HEADER_BYTES) else { return };
    assert!(data.starts_with(&header));
    let delimiter = detect_delimiter(&header);
    let mut report = Report::default();
    let mut widths = std::collections::BTreeSet::new();
    let _ = stream_csv(data, delimiter, &ReadOptions::default(), true, &mut report, &mut |p| {
        widths.insert(p.attrs.len());
        Ok(())
    });
    assert!(widths.len() <= 1, "rows with different attribute counts: {widths:?}");
});

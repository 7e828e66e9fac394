//! Manifest decoder: any bytes → Ok or a DecodeError; never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(m) = sylva::format::Manifest::decode("fuzz/scene.json", data) {
        // A valid manifest round-trips.
        let again = sylva::format::Manifest::decode("again", &m.encode()).expect("re-encoded manifest decodes");
        assert_eq!(again.counts, m.counts);
    }
});

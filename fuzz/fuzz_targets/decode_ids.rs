//! Tree-id sidecar decoder: any bytes → Ok or a DecodeError; never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(ids) = sylva::format::decode_ids("fuzz.ids", data) {
        assert_eq!(sylva::format::encode_ids(&ids), data);
    }
});

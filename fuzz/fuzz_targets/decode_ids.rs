//! Tree-id sidecar decoder (both versions, text ids too): any bytes → Ok or
//! a DecodeError; never a panic; what decodes encodes to the same bytes.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(ids) = sylva::format::decode_tree_ids("fuzz.ids", data) {
        assert_eq!(sylva::format::encode_tree_ids(&ids).unwrap(), data);
        for (i, _) in &ids.texts {
            assert!(ids.text(*i).is_some());
        }
    }
});

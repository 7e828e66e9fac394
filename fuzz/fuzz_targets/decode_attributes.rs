//! Attribute sidecar and filter: any schema JSON and sidecar bytes → Ok or an
//! error; never a panic. The input's first byte splits it: a schema (JSON, as
//! in scene.json) and the sidecar bytes; what decodes is re-encoded to the same
//! bytes, read value by value, and searched with a filter of every column.
#![no_main]
use libfuzzer_sys::fuzz_target;
use sylva::format::attributes::{decode_attributes, encode_attributes, AttributeSchema};

fuzz_target!(|data: &[u8]| {
    let Some((&split, rest)) = data.split_first() else { return };
    let (schema, sidecar) = rest.split_at((split as usize).min(rest.len()));
    let Ok(schema) = serde_json::from_slice::<AttributeSchema>(schema) else { return };
    if schema.validate().is_err() {
        return;
    }
    let count = sidecar.get(8..16).map_or(0, |b| u64::from_le_bytes(b.try_into().unwrap()).min(1 << 16) as usize);
    if let Ok(codes) = decode_attributes("fuzz.attr", sidecar, &schema, count) {
        assert_eq!(encode_attributes(&schema, &codes), sidecar);
        for i in 0..count {
            let _ = codes.json(&schema, i);
        }
        let filter: serde_json::Value =
            schema.columns.iter().map(|c| (c.name.clone(), serde_json::json!([null, null]))).collect();
        if let Ok(f) = sylva::scene::query::Filter::parse(Some(&schema), &filter) {
            for i in 0..count {
                let _ = f.matches(Some(&schema), Some(&codes), i, 0, None);
            }
        }
    }
});

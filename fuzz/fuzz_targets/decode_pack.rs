//! LoD pack decoder: any bytes → Ok or a DecodeError; never a panic. A stored
//! pack's head and blocks too (`PackHead::decode`, `stored::unstore`).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(head) = sylva::format::pack::PackHead::decode("fuzz.pack", data) {
        for p in sylva::format::pack::PackPart::ALL {
            let _ = (head.fetch_of(p), head.fetch_bytes(p), head.part_bytes(p));
        }
        if let Ok(logical) = sylva::format::stored::unstore("fuzz.pack", data.to_vec()) {
            let _ = sylva::format::decode_pack("fuzz.pack", &logical);
        }
    }
    if let Ok(pack) = sylva::format::decode_pack("fuzz.pack", data) {
        // Whatever validated must be safe to use: mesh sections match their metadata.
        for (l, level) in pack.meta.mesh_levels.iter().enumerate() {
            assert_eq!(pack.mesh_vertices(l as u32).len(), level.vertex_count as usize);
            let indices = pack.mesh_indices(l as u32);
            assert!(indices.iter().all(|&i| i < level.vertex_count));
        }
    }
});

//! The glTF importer never panics, hangs or runs out of memory on hostile
//! GLB/glTF bytes: it imports or returns an error. Node graphs (cycles,
//! reuse), accessors, views and buffers are the surface (docs/SECURITY.md).
#![no_main]
use libfuzzer_sys::fuzz_target;
use sylva_bake::input::gltf_import::{import_slice, Classifier};

fuzz_target!(|data: &[u8]| {
    // No base folder: external URIs are refused, as for a model read from memory.
    let _ = import_slice(data, None, &Classifier::default());
});

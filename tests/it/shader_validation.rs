//! Every composed WGSL shader parses and validates with naga (as wgpu would),
//! without a GPU.

#[test]
fn all_shaders_validate() {
    for (name, shader) in sylva::render::shaders::ALL {
        let source = shader.source();
        let module = naga::front::wgsl::parse_str(&source)
            .unwrap_or_else(|e| panic!("{name}.wgsl: {}", e.emit_to_string(&source)));
        let mut validator =
            naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::default());
        validator.validate(&module).unwrap_or_else(|e| panic!("{name}.wgsl: {e:?}"));
        assert!(!module.entry_points.is_empty(), "{name} has no entry points");
    }
}

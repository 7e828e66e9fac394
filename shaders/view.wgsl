// The view every pass but the refinement's reads (group 0, binding 0; the
// `View` struct is in layout.wgsl, its CPU twin `lod::shared::ViewUniform`).
// Bound by `SharedLayouts::view_group` (src/render/layouts.rs).

@group(0) @binding(0) var<storage, read> view: View;

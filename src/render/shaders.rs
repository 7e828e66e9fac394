//! WGSL sources, composed at compile time (WGSL has no includes): each pass's
//! file (`shaders/<pass>.wgsl`, named like its constant here and its Rust file
//! in `src/render/`) after the modules it uses, each binding declared once:
//! `layout.wgsl` (the structs every pass reads), `instance.wgsl` (a tree
//! decoded), `select.wgsl` (the selection rules the passes share; twin
//! `src/lod/select.rs`), `light.wgsl` (the lighting model), `style_bits.wgsl`
//! (the styles' bit layout), `view.wgsl` (the view, group 0),
//! `trees.wgsl` (the tree passes' pools and draw params, groups 2 and 3),
//! `styles.wgsl` (the styles' binding and colours), `shadow.wgsl` (the shadow
//! map and its lookup, for the lit passes).

/// The mesh pass (and the bake's billboard capture).
pub const MESH: &str = concat!(
    include_str!("../../shaders/layout.wgsl"),
    include_str!("../../shaders/instance.wgsl"),
    include_str!("../../shaders/select.wgsl"),
    include_str!("../../shaders/light.wgsl"),
    include_str!("../../shaders/style_bits.wgsl"),
    include_str!("../../shaders/view.wgsl"),
    include_str!("../../shaders/trees.wgsl"),
    include_str!("../../shaders/styles.wgsl"),
    include_str!("../../shaders/shadow.wgsl"),
    include_str!("../../shaders/mesh.wgsl")
);

/// The billboard pass.
pub const BILLBOARD: &str = concat!(
    include_str!("../../shaders/layout.wgsl"),
    include_str!("../../shaders/instance.wgsl"),
    include_str!("../../shaders/select.wgsl"),
    include_str!("../../shaders/light.wgsl"),
    include_str!("../../shaders/style_bits.wgsl"),
    include_str!("../../shaders/view.wgsl"),
    include_str!("../../shaders/trees.wgsl"),
    include_str!("../../shaders/styles.wgsl"),
    include_str!("../../shaders/shadow.wgsl"),
    include_str!("../../shaders/billboard.wgsl")
);

/// The multi-view impostor pass.
pub const IMPOSTOR: &str = concat!(
    include_str!("../../shaders/layout.wgsl"),
    include_str!("../../shaders/instance.wgsl"),
    include_str!("../../shaders/select.wgsl"),
    include_str!("../../shaders/light.wgsl"),
    include_str!("../../shaders/style_bits.wgsl"),
    include_str!("../../shaders/view.wgsl"),
    include_str!("../../shaders/trees.wgsl"),
    include_str!("../../shaders/styles.wgsl"),
    include_str!("../../shaders/shadow.wgsl"),
    include_str!("../../shaders/impostor_views.wgsl"),
    include_str!("../../shaders/impostor.wgsl")
);

/// The cluster pass (ellipsoids and lines).
pub const CLUSTER: &str = concat!(
    include_str!("../../shaders/layout.wgsl"),
    include_str!("../../shaders/instance.wgsl"),
    include_str!("../../shaders/select.wgsl"),
    include_str!("../../shaders/light.wgsl"),
    include_str!("../../shaders/style_bits.wgsl"),
    include_str!("../../shaders/view.wgsl"),
    include_str!("../../shaders/trees.wgsl"),
    include_str!("../../shaders/styles.wgsl"),
    include_str!("../../shaders/shadow.wgsl"),
    include_str!("../../shaders/cluster.wgsl")
);

/// The cull and LoD-selection compute passes.
pub const CULL: &str = concat!(
    include_str!("../../shaders/layout.wgsl"),
    include_str!("../../shaders/instance.wgsl"),
    include_str!("../../shaders/select.wgsl"),
    include_str!("../../shaders/style_bits.wgsl"),
    include_str!("../../shaders/view.wgsl"),
    include_str!("../../shaders/cull.wgsl")
);

/// The sky/ground background.
pub const SKY: &str = concat!(
    include_str!("../../shaders/layout.wgsl"),
    include_str!("../../shaders/light.wgsl"),
    include_str!("../../shaders/view.wgsl"),
    include_str!("../../shaders/sky.wgsl")
);

/// The batch-bounds debug view.
pub const BOUNDS: &str = concat!(
    include_str!("../../shaders/layout.wgsl"),
    include_str!("../../shaders/instance.wgsl"),
    include_str!("../../shaders/view.wgsl"),
    include_str!("../../shaders/bounds.wgsl")
);

/// The terrain pass.
pub const TERRAIN: &str = concat!(
    include_str!("../../shaders/layout.wgsl"),
    include_str!("../../shaders/instance.wgsl"),
    include_str!("../../shaders/light.wgsl"),
    include_str!("../../shaders/view.wgsl"),
    include_str!("../../shaders/shadow.wgsl"),
    include_str!("../../shaders/terrain.wgsl")
);

/// The canopy pass.
pub const CANOPY: &str = concat!(
    include_str!("../../shaders/layout.wgsl"),
    include_str!("../../shaders/instance.wgsl"),
    include_str!("../../shaders/select.wgsl"),
    include_str!("../../shaders/light.wgsl"),
    include_str!("../../shaders/view.wgsl"),
    include_str!("../../shaders/canopy.wgsl")
);

/// Progressive refinement's accumulate and resolve passes.
pub const ACCUMULATE: &str = include_str!("../../shaders/accumulate.wgsl");

/// Every composed shader with its name, for validation tests.
pub const ALL: &[(&str, &str)] = &[
    ("mesh", MESH),
    ("billboard", BILLBOARD),
    ("impostor", IMPOSTOR),
    ("cluster", CLUSTER),
    ("cull", CULL),
    ("sky", SKY),
    ("bounds", BOUNDS),
    ("terrain", TERRAIN),
    ("canopy", CANOPY),
    ("accumulate", ACCUMULATE),
];

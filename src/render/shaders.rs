//! WGSL sources, composed when a pipeline is made (WGSL has no includes): each pass's
//! file (`shaders/<pass>.wgsl`, named like its constant here and its Rust file
//! in `src/render/`) after the modules it uses, each binding declared once:
//! `layout.wgsl` (the structs every pass reads), `instance.wgsl` (a tree
//! decoded), `select.wgsl` (the selection rules the passes share; twin
//! `src/lod/select.rs`), `light.wgsl` (the lighting model), `sky_model.wgsl` (the clear sky and
//! the air, which the path tracer reads too), `style_bits.wgsl`
//! (the styles' bit layout), `view.wgsl` (the view, group 0),
//! `trees.wgsl` (the tree passes' pools and draw params, groups 2 and 3),
//! `styles.wgsl` (the styles' binding and colours), `shadow.wgsl` (the shadow
//! map and its lookup, for the lit passes).
//! Each module is in the binary once, composed into a pass's source when its
//! pipeline is made (composed at compile time with `concat!`, the shared
//! modules were in the wasm once per pass), and without its comments and
//! indentation (`build.rs` minifies `shaders/` into `OUT_DIR`: naga's errors
//! count lines of the minified text).

/// A pass's WGSL: runs of modules in order, joined by [`Shader::source`].
#[derive(Debug, Clone, Copy)]
pub struct Shader(pub &'static [&'static [&'static str]]);

impl Shader {
    /// The composed source.
    #[must_use]
    pub fn source(&self) -> String {
        self.0.concat().concat()
    }
}

static LAYOUT_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/layout.wgsl"));
static INSTANCE_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/instance.wgsl"));
static SELECT_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/select.wgsl"));
static LIGHT_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/light.wgsl"));
static SKY_MODEL_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/sky_model.wgsl"));
static STYLE_BITS_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/style_bits.wgsl"));
static VIEW_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/view.wgsl"));
static TREES_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/trees.wgsl"));
static STYLES_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/styles.wgsl"));
static SHADOW_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/shadow.wgsl"));
static MESH_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/mesh.wgsl"));
static BILLBOARD_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/billboard.wgsl"));
static IMPOSTOR_VIEWS_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/impostor_views.wgsl"));
static IMPOSTOR_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/impostor.wgsl"));
static CLUSTER_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/cluster.wgsl"));
static CULL_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/cull.wgsl"));
static SKY_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/sky.wgsl"));
static BOUNDS_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/bounds.wgsl"));
static TERRAIN_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/terrain.wgsl"));
static CANOPY_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/canopy.wgsl"));
static ACCUMULATE_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/accumulate.wgsl"));
static TRACE_TYPES_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/trace_types.wgsl"));
static TOP_LEVEL_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/top_level.wgsl"));
static TRACE_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/trace.wgsl"));
static TRACE_PROBE_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/trace_probe.wgsl"));
static TRACE_PROBE_RAY_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/trace_probe_ray.wgsl"));
static TRACE_SCENE_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/trace_scene.wgsl"));
static TRACE_SCENE_PROBE_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/trace_scene_probe.wgsl"));
static PATH_TRACE_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/path_trace.wgsl"));
static PATH_DISPLAY_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/path_display.wgsl"));

/// The modules every tree pass (mesh, billboard, impostor, cluster) reads,
/// before its own.
static TREE_PASS: &[&str] = &[
    LAYOUT_WGSL,
    INSTANCE_WGSL,
    SELECT_WGSL,
    LIGHT_WGSL,
    SKY_MODEL_WGSL,
    STYLE_BITS_WGSL,
    VIEW_WGSL,
    TREES_WGSL,
    STYLES_WGSL,
    SHADOW_WGSL,
];

/// The mesh pass (and the bake's billboard capture).
pub static MESH: Shader = Shader(&[TREE_PASS, &[MESH_WGSL]]);

/// The billboard pass.
pub static BILLBOARD: Shader = Shader(&[TREE_PASS, &[BILLBOARD_WGSL]]);

/// The multi-view impostor pass.
pub static IMPOSTOR: Shader = Shader(&[TREE_PASS, &[IMPOSTOR_VIEWS_WGSL, IMPOSTOR_WGSL]]);

/// The cluster pass (ellipsoids and lines).
pub static CLUSTER: Shader = Shader(&[TREE_PASS, &[CLUSTER_WGSL]]);

/// The cull and LoD-selection compute passes.
pub static CULL: Shader =
    Shader(&[&[LAYOUT_WGSL, SKY_MODEL_WGSL, INSTANCE_WGSL, SELECT_WGSL, STYLE_BITS_WGSL, VIEW_WGSL, CULL_WGSL]]);

/// The sky/ground background.
pub static SKY: Shader = Shader(&[&[LAYOUT_WGSL, LIGHT_WGSL, SKY_MODEL_WGSL, VIEW_WGSL, SKY_WGSL]]);

/// The batch-bounds debug view.
pub static BOUNDS: Shader = Shader(&[&[LAYOUT_WGSL, SKY_MODEL_WGSL, INSTANCE_WGSL, VIEW_WGSL, BOUNDS_WGSL]]);

/// The terrain pass.
pub static TERRAIN: Shader =
    Shader(&[&[LAYOUT_WGSL, INSTANCE_WGSL, LIGHT_WGSL, SKY_MODEL_WGSL, VIEW_WGSL, SHADOW_WGSL, TERRAIN_WGSL]]);

/// The canopy pass.
pub static CANOPY: Shader =
    Shader(&[&[LAYOUT_WGSL, INSTANCE_WGSL, SELECT_WGSL, LIGHT_WGSL, SKY_MODEL_WGSL, VIEW_WGSL, CANOPY_WGSL]]);

/// Progressive refinement's accumulate and resolve passes.
pub static ACCUMULATE: Shader = Shader(&[&[ACCUMULATE_WGSL]]);

/// The tracer's probe: rays through one species' hierarchy (`render/trace.rs`).
pub static TRACE_PROBE: Shader = Shader(&[&[TRACE_TYPES_WGSL, TRACE_WGSL, TRACE_PROBE_RAY_WGSL, TRACE_PROBE_WGSL]]);

/// The path tracer (`render/path_trace.rs`).
pub static PATH_TRACE: Shader =
    Shader(&[&[TRACE_TYPES_WGSL, TRACE_WGSL, TRACE_SCENE_WGSL, SKY_MODEL_WGSL, PATH_TRACE_WGSL]]);

/// The path tracer's image on a colour target (`render/path_trace.rs`).
pub static PATH_DISPLAY: Shader = Shader(&[&[PATH_DISPLAY_WGSL]]);

/// The tracer's top level built on the GPU (`render/top_level.rs`).
pub static TOP_LEVEL: Shader = Shader(&[&[TRACE_TYPES_WGSL, TOP_LEVEL_WGSL]]);

/// The tracer's scene probe: rays through both levels (`render/trace.rs`).
pub static TRACE_SCENE_PROBE: Shader =
    Shader(&[&[TRACE_TYPES_WGSL, TRACE_WGSL, TRACE_SCENE_WGSL, TRACE_PROBE_RAY_WGSL, TRACE_SCENE_PROBE_WGSL]]);

/// Every composed shader with its name, for validation tests.
pub static ALL: &[(&str, Shader)] = &[
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
    ("trace_probe", TRACE_PROBE),
    ("trace_scene_probe", TRACE_SCENE_PROBE),
    ("path_trace", PATH_TRACE),
    ("top_level", TOP_LEVEL),
    ("path_display", PATH_DISPLAY),
];

// A ray of the tracer's probes. Must match `ProbeRay` in src/render/trace.rs.
struct ProbeRay {
    origin: vec3<f32>,
    t_max: f32,
    dir: vec3<f32>,
    pad: f32,
};


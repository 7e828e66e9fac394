// Traces a list of rays through one species' hierarchy and writes each nearest
// hit: the twin test of the WGSL walk against src/trace/bvh.rs, and the
// measure of rays per second (src/render/trace.rs, `TraceProbe::trace`). Needs
// trace.wgsl and trace_probe_ray.wgsl.

@group(0) @binding(0) var<storage, read> bvh_nodes: array<BvhNode>;
@group(0) @binding(1) var<storage, read> bvh_tris: array<TraceTriangle>;
@group(0) @binding(2) var<storage, read> probe_rays: array<ProbeRay>;
@group(0) @binding(3) var<storage, read_write> probe_hits: array<TraceHit>;

// The probe tests the walk alone: every hit kept.
fn trace_keeps(species: u32, tri: TraceTriangle, u: f32, v: f32) -> bool {
    return true;
}

@compute @workgroup_size(64)
fn trace_probe(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= arrayLength(&probe_rays) {
        return;
    }
    let r = probe_rays[i];
    probe_hits[i] = trace_bvh(r.origin, r.dir, r.t_max, 0u, 0u, 0u);
}

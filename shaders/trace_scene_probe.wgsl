// Traces a list of rays through a scene's two levels and writes each nearest
// hit: the twin test of the WGSL two-level walk against src/trace/scene.rs
// (src/render/trace.rs, `TraceProbe::trace_scene`). Needs trace.wgsl,
// trace_scene.wgsl and trace_probe_ray.wgsl.

@group(0) @binding(0) var<uniform> trace_params: TraceParams;
@group(0) @binding(1) var<storage, read> bvh_nodes: array<BvhNode>;
@group(0) @binding(2) var<storage, read> bvh_tris: array<TraceTriangle>;
@group(0) @binding(3) var<storage, read> trace_species: array<TraceSpecies>;
@group(0) @binding(4) var<storage, read> trace_instances: array<TraceInstance>;
@group(0) @binding(5) var<storage, read> trace_materials: array<TraceMaterial>;
@group(0) @binding(6) var<storage, read> trace_texels: array<u32>;
@group(0) @binding(7) var<storage, read> probe_rays: array<ProbeRay>;
@group(0) @binding(8) var<storage, read_write> probe_scene_hits: array<SceneHit>;

@compute @workgroup_size(64)
fn trace_scene_probe(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= arrayLength(&probe_rays) {
        return;
    }
    let r = probe_rays[i];
    probe_scene_hits[i] = trace_scene(r.origin, r.dir, r.t_max);
}

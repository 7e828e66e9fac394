// Hemi-octahedral view grid of the multi-view impostors: which baked views a
// direction falls between and how much each counts. Pure functions, shared by
// the impostor pass and its CPU-oracle test. Must match src/render/impostor.rs.

// A direction of the upper hemisphere (z ≥ 0; lower ones are clamped to the
// horizon) → grid coordinates in [0, 1]²: the octahedral projection rotated
// 45° so the horizon is the square's border and straight up its centre.
fn hemi_oct_encode(d: vec3<f32>) -> vec2<f32> {
    let v = vec3<f32>(d.xy, max(d.z, 0.0));
    let p = v.xy / max(abs(v.x) + abs(v.y) + v.z, 1e-8);
    return vec2<f32>(p.x + p.y, p.x - p.y) * 0.5 + 0.5;
}

// Grid coordinates → unit direction.
fn hemi_oct_decode(g: vec2<f32>) -> vec3<f32> {
    let e = g * 2.0 - 1.0;
    let x = (e.x + e.y) * 0.5;
    let y = (e.x - e.y) * 0.5;
    return normalize(vec3<f32>(x, y, max(1.0 - abs(x) - abs(y), 0.0)));
}

// Direction of view `layer` (row · grid + column) of a `grid`² hemi-octahedral grid.
fn impostor_view_dir(layer: u32, grid: u32) -> vec3<f32> {
    let n = f32(grid - 1u);
    return hemi_oct_decode(vec2<f32>(f32(layer % grid), f32(layer / grid)) / n);
}

// Image axes of the view looking back along `d` (right, up); up is the
// world's up projected, and +y where d is straight up.
fn impostor_view_right(d: vec3<f32>) -> vec3<f32> {
    let r = cross(vec3<f32>(0.0, 0.0, 1.0), d);
    if dot(r, r) < 1e-8 {
        return vec3<f32>(0.0, 1.0, 0.0);
    }
    return normalize(r);
}

// The three views around direction `d` (unit, model space) and their blend
// weights (barycentric in the grid triangle holding `d`; they sum to 1).
struct ImpostorViews {
    layers: vec3<u32>,
    weights: vec3<f32>,
};

fn impostor_views(d: vec3<f32>, grid: u32) -> ImpostorViews {
    let n = f32(grid - 1u);
    let f = hemi_oct_encode(d) * n;
    let cell = clamp(floor(f), vec2<f32>(0.0), vec2<f32>(n - 1.0));
    let t = clamp(f - cell, vec2<f32>(0.0), vec2<f32>(1.0));
    let c = vec2<u32>(cell);
    var out: ImpostorViews;
    if t.x + t.y <= 1.0 {
        out.layers = vec3<u32>(c.y * grid + c.x, c.y * grid + c.x + 1u, (c.y + 1u) * grid + c.x);
        out.weights = vec3<f32>(1.0 - t.x - t.y, t.x, t.y);
    } else {
        out.layers = vec3<u32>((c.y + 1u) * grid + c.x + 1u, (c.y + 1u) * grid + c.x, c.y * grid + c.x + 1u);
        out.weights = vec3<f32>(t.x + t.y - 1.0, 1.0 - t.x, 1.0 - t.y);
    }
    return out;
}

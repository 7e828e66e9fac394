// View-angle billboards (Eichner 2024, §3.3): one quad per tree, facing the eye
// horizontally and snapped to the baked elevation of the array layer chosen by
// eq. 3.1; alpha-tested colour, relit with the baked normals under the same sun
// and ambient as the meshes. Rust side: src/render/billboard.rs.

// (Group 0, binding 0: the view, `shaders/view.wgsl`.)

@group(1) @binding(0) var bb_color: texture_2d_array<f32>;
@group(1) @binding(1) var bb_normal: texture_2d_array<f32>;
@group(1) @binding(2) var bb_sampler: sampler;
// The tree's own baked sky visibility (r; one white texel where not baked).
@group(1) @binding(3) var bb_ao: texture_2d_array<f32>;

// (Group 2: batches, instances, draw items and styles; group 3: the draw's
// params. Declared once in `shaders/trees.wgsl`.)


struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) uv: vec2<f32>,
    @location(1) @interpolate(flat) layer: u32,
    // Rotation (radians) from the captured model frame to the world, for normals.
    @location(2) @interpolate(flat) normal_yaw: f32,
    @location(3) @interpolate(flat) item_y: u32,
    @location(4) @interpolate(flat) tint: vec3<f32>,
    // How far the quad's shadow lookups move towards the sun (m): its half width.
    @location(5) @interpolate(flat) lift: f32,
    // Forest-scale occlusion (`canopy_occlusion`), by height in the quad.
    @location(6) canopy: f32,
    // The tree's pool instance (the id pass).
    @location(7) @interpolate(flat) item_x: u32,
    // The tree's style byte (`tree_style`).
    @location(8) @interpolate(flat) style: u32,
    // The tree's variation (0–31: its autumn progress).
    @location(9) @interpolate(flat) variation: f32,
};

const PI: f32 = 3.14159265;

// Array layer by eq. 3.1: i = a − ⌊(2a/π)·acos(V·U)⌋, V the unit vector from the
// tree to the eye, U up; clamped to the a baked angles.
fn billboard_layer(to_eye: vec3<f32>, angles: u32) -> u32 {
    let a = f32(angles);
    let cos_zenith = clamp(normalize(to_eye).z, -1.0, 1.0);
    let i = a - floor(2.0 * a / PI * acos(cos_zenith));
    return u32(clamp(i, 0.0, a - 1.0));
}

@vertex
fn vs_main(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> VertexOut {
    let item = items[draw.ids.x + instance];
    let batch = batches[item.y & 0x7fffffu];
    var tree = unpack_instance(instances[item.x], batch, view);
    tree.scale *= tree_growth(styles[STYLE_FLAGS], item.x);
    // A thinned batch's kept trees stand in for the others: bigger, about the
    // crown's centre (so a far canopy's top line barely rises).
    let thin = thinning(batch, view);
    let angles = max(draw.ids.w & 0xffffu, 2u);
    let azimuths = max(draw.ids.w >> 16u, 1u);
    let base = tree.pos + vec3<f32>(0.0, 0.0, draw.bb_center.z * tree.scale);
    // Towards the eye, or in a shadow cascade towards the sun: billboards cast
    // the silhouette the sun sees.
    let to_eye = towards_eye(base, view);
    let phi = atan2(to_eye.y, to_eye.x);
    let k = billboard_layer(to_eye, angles);
    // Azimuth layer: the captured direction closest to the eye, in the tree's frame.
    let az_step = 2.0 * PI / f32(azimuths);
    let rel = phi - tree.yaw;
    let az = u32(round(rel / az_step + f32(azimuths) * 4.0)) % azimuths;
    // The quad is snapped to the baked elevation (Eichner 2024, §3.3), so a layer switch
    // is masked by the matching perspective.
    let elevation = f32(k) * (PI * 0.5) / f32(angles - 1u);
    let dir = vec3<f32>(cos(elevation) * cos(phi), cos(elevation) * sin(phi), sin(elevation));
    let up = vec3<f32>(-sin(elevation) * cos(phi), -sin(elevation) * sin(phi), cos(elevation));
    let right = cross(-dir, up);
    // Two triangles: corners (-1,-1) (1,-1) (1,1) / (-1,-1) (1,1) (-1,1).
    var corners = array<vec2<f32>, 6>(
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, -1.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, 1.0), vec2<f32>(-1.0, 1.0),
    );
    let boost = coverage_boost(thin, batch);
    let c = corners[vertex % 6u];
    let half_w = draw.bb_center.w * tree.scale * boost;
    let half_h = draw.bb_size.x * tree.scale * boost;
    // The crown aspect stretches the quad horizontally: its width, and the
    // horizontal part of its height seen from above.
    let pos = base + crown_stretch(right * (c.x * half_w) + up * (c.y * half_h), tree);
    var out: VertexOut;
    out.clip = view.clip_from_eye * vec4<f32>(pos, 1.0);
    out.uv = vec2<f32>(0.5 + 0.5 * c.x, 0.5 - 0.5 * c.y);
    // The tree's mesh variant's billboards where the pack has them (bb_size.y variants).
    let variants = max(u32(draw.bb_size.y), 1u);
    let variant = variant_of(u32(tree.variation), variants - 1u);
    out.layer = (variant * azimuths + az) * angles + k;
    out.normal_yaw = phi - f32(az) * az_step;
    out.item_y = item.y;
    out.item_x = item.x;
    out.style = tree_style(styles[STYLE_FLAGS], item.x, batch.species);
    out.tint = variation_tint(tree.variation);
    out.variation = tree.variation;
    out.lift = half_w * max(tree.aspect, 1.0);
    // The height in the crown of what this point of the quad shows: along the
    // quad's up seen from the side, the crown's top seen from above.
    let top = draw.bb_center.z + draw.bb_size.x;
    let shown = draw.bb_center.z + draw.bb_size.x * (up.z * c.y + 0.8 * sin(elevation));
    out.canopy = canopy_occlusion(batch, shown / max(top, 1e-3));
    return out;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    let color = textureSample(bb_color, bb_sampler, in.uv, in.layer);
    let packed_normal = textureSample(bb_normal, bb_sampler, in.uv, in.layer);
    let baked_ao = textureSample(bb_ao, bb_sampler, in.uv, in.layer).r;
    if color.a < 0.5 || !fade_keeps(in.item_y, in.clip.xy, view.eye_lo.w) {
        discard;
    }
    // The mean of the texel's normals (not normalised: see `shade_filtered`).
    let m = rotate_z(packed_normal.xyz * 2.0 - 1.0, in.normal_yaw);
    let n = normalize(m);
    let is_leaf = packed_normal.a > 0.75;
    // Leaf-off before the bare capture has come: the wood the leaves let through.
    if is_leaf && leaves_off(in.variation) {
        discard;
    }
    let own = color.rgb * in.tint;
    var albedo = styled_albedo(select(own, seasonal_leaf(own, in.variation), is_leaf), styles[in.style & 63u]);
    if view.params.z == 1u {
        albedo = repr_color(REPR_BILLBOARD) * (0.6 + 0.4 * color.g);
    }
    let ao = own_ao(baked_ao, view);
    let sun = sun_visibility(frag_rel(in.clip, view), n, in.lift, open_sun(in.canopy));
    let lit = highlighted(shade_filtered(albedo, m, is_leaf, view, sun, in.canopy, ao), in.style);
    return vec4<f32>(haze(lit, in.clip, view), 1.0);
}

// Shadow cascades: depth only, alpha-tested.
@fragment
fn fs_shadow(in: VertexOut) {
    let color = textureSample(bb_color, bb_sampler, in.uv, in.layer);
    // (Sampled first: a texture sample under a per-tree condition breaks WGSL's uniformity rule.)
    let leafy = textureSample(bb_normal, bb_sampler, in.uv, in.layer).a > 0.75;
    let leaf_off = leafy && leaves_off(in.variation);
    if color.a < 0.5 || leaf_off || !fade_keeps(in.item_y, in.clip.xy, view.eye_lo.w) {
        discard;
    }
}

// Picking: the tree's pool instance + 1, alpha-tested.
@fragment
fn fs_id(in: VertexOut) -> @location(0) u32 {
    let color = textureSample(bb_color, bb_sampler, in.uv, in.layer);
    // (Sampled first: a texture sample under a per-tree condition breaks WGSL's uniformity rule.)
    let leafy = textureSample(bb_normal, bb_sampler, in.uv, in.layer).a > 0.75;
    let leaf_off = leafy && leaves_off(in.variation);
    if color.a < 0.5 || leaf_off || !fade_keeps(in.item_y, in.clip.xy, view.eye_lo.w) {
        discard;
    }
    return in.item_x + 1u;
}

// The path tracer (issue 48): per pixel a path through the forest's two levels
// (trace_scene.wgsl) with the sun as a disk of its true angular size sampled
// at every vertex (soft shadows), the sky as an environment, leaves that
// reflect and transmit (two-sided Lambert), bark and ground that reflect, up to
// `bounces` bounces; samples accumulate into `accum` while the camera rests.
// Everything is relative to the point the instances were placed around on the
// CPU (the eye they were loaded for; the eye is at `origin` from it).
// Rust side: src/render/path_trace.rs. Needs trace.wgsl and trace_scene.wgsl.

// Must match `PathParams` in src/render/path_trace.rs.
struct PathParams {
    // Camera basis: forward (unit), right and up scaled by the half field of view.
    forward: vec4<f32>,
    right: vec4<f32>,
    up: vec4<f32>,
    // Unit vector towards the sun; w: the cosine of its angular radius.
    sun_dir: vec4<f32>,
    // Irradiance of the sun at normal incidence over pi (the raster's
    // `sun_color`: a white surface facing it reflects this).
    sun_color: vec4<f32>,
    // The sky's radiance at the zenith and at the horizon (w: unused).
    sky_zenith: vec4<f32>,
    sky_horizon: vec4<f32>,
    // The ground plane: albedo (rgb) and height relative to the eye (w; -1e30: none).
    ground: vec4<f32>,
    // The raster's ambient light (its `Lighting.ambient`), for the simple light.
    ambient: vec4<f32>,
    width: u32,
    height: u32,
    // The first sample of this dispatch (sequence index), and how many it adds.
    sample: u32,
    samples: u32,
    bounces: u32,
    // 1: the raster's simple light instead (sun and sky, no bounce, no
    // transmission): the light error split from the geometry error.
    simple: u32,
    // The share of a leaf's albedo it transmits (the rest it reflects).
    leaf_transmit: f32,
    // The eye's height above the scene origin (the raster's haze thins with height).
    eye_z: f32,
    // The eye relative to the point the scene was placed around (xyz).
    origin: vec4<f32>,
    // An HDR environment (x: 1 when bound, y: its radiance's scale): the
    // sky and the sun then, importance sampled at every vertex.
    env: vec4<f32>,
    // x: 1 to jitter samples within their pixels, 0 for pixel centres.
    sampling: vec4<f32>,
    // The clear sky of Preetham et al. 1999, the air and the raster light's
    // parts, as the raster's view has them (sky_model.wgsl): physical light,
    // LIGHT_SKY the clear sky (else the gradient), LIGHT_AERIAL the air
    // between the eye and the first hit; the simple light mirrors the
    // raster's parts.
    sky: Sky,
};

@group(0) @binding(0) var<uniform> trace_params: TraceParams;
@group(0) @binding(1) var<uniform> path: PathParams;
@group(0) @binding(2) var<storage, read> bvh_nodes: array<BvhNode>;
@group(0) @binding(3) var<storage, read> bvh_tris: array<TraceTriangle>;
@group(0) @binding(4) var<storage, read> trace_species: array<TraceSpecies>;
@group(0) @binding(5) var<storage, read> trace_instances: array<TraceInstance>;
@group(0) @binding(6) var<storage, read> trace_materials: array<TraceMaterial>;
@group(0) @binding(7) var<storage, read> trace_texels: array<u32>;
@group(0) @binding(8) var<storage, read_write> accum: array<vec4<f32>>;
// The environment (src/trace/environment.rs, `Environment::gpu_array`):
// [width, height, total, 0], its texels (rgb, 0) from the zenith row, the
// marginal CDF over rows, each row's CDF over its columns.
@group(0) @binding(9) var<storage, read> env: array<f32>;

const PI: f32 = 3.14159265;
const FAR: f32 = 1e7;

// A hash of three words (PCG-style, Jarzynski & Olano 2020): the random
// numbers of a pixel's sample, dimension by dimension.
fn hash3(v0: vec3<u32>) -> vec3<u32> {
    var v = v0 * 1664525u + 1013904223u;
    v.x += v.y * v.z;
    v.y += v.z * v.x;
    v.z += v.x * v.y;
    v ^= v >> vec3<u32>(16u);
    v.x += v.y * v.z;
    v.y += v.z * v.x;
    v.z += v.x * v.y;
    return v;
}

var<private> rng_state: vec3<u32>;

fn rand2() -> vec2<f32> {
    rng_state = hash3(rng_state + vec3<u32>(0u, 0u, 0x9e3779b9u));
    return vec2<f32>(f32(rng_state.x >> 8u), f32(rng_state.y >> 8u)) / 16777216.0;
}

// A unit vector around `n`, cosine-weighted.
fn cosine_around(n: vec3<f32>, r: vec2<f32>) -> vec3<f32> {
    let phi = 2.0 * PI * r.x;
    let s = sqrt(r.y);
    // A helper axis far from n (never parallel to it: no zero cross product).
    let t = select(vec3<f32>(1.0, 0.0, 0.0), vec3<f32>(0.0, 1.0, 0.0), abs(n.x) > 0.5);
    let a = normalize(cross(t, n));
    let b = cross(n, a);
    return normalize(a * (cos(phi) * s) + b * (sin(phi) * s) + n * sqrt(max(1.0 - r.y, 0.0)));
}

// A direction within the sun's disk (uniform over its cone).
fn sun_sample(r: vec2<f32>) -> vec3<f32> {
    let d = path.sun_dir.xyz;
    let cos_max = path.sun_dir.w;
    let c = 1.0 - r.x * (1.0 - cos_max);
    let s = sqrt(max(1.0 - c * c, 0.0));
    let phi = 2.0 * PI * r.y;
    let t = select(vec3<f32>(0.0, 0.0, 1.0), vec3<f32>(1.0, 0.0, 0.0), abs(d.z) > 0.9);
    let a = normalize(cross(t, d));
    let b = cross(d, a);
    return normalize(a * (cos(phi) * s) + b * (sin(phi) * s) + d * c);
}

// The clear sky's radiance towards d (render units, linear sRGB).
// Twin: `PreethamSky::radiance` in src/trace/sky.rs.
fn sky_preetham(d: vec3<f32>) -> vec3<f32> {
    return preetham_radiance(d, path.sky.sun.xyz, path.sky.zenith, path.sky.perez);
}

fn part_on(part: u32) -> bool {
    return (path.sky.parts.x & part) != 0u;
}

// `color` at `dist` along the primary ray d, seen through the air
// (`aerial` in light.wgsl, the same model).
fn through_air(color: vec3<f32>, d: vec3<f32>, dist: f32) -> vec3<f32> {
    let rel = d * dist;
    let t = air_transmittance(rel, path.eye_z, path.sky.rayleigh, path.sky.mie);
    return color * t + sky_preetham(air_light_dir(rel)) * (1.0 - t);
}

fn env_on() -> bool {
    return path.env.x > 0.5;
}

fn env_size() -> vec2<u32> {
    return vec2<u32>(u32(env[0]), u32(env[1]));
}

// The map's (u, v) of a unit direction: u the azimuth (0.5 north, clockwise),
// v the zenith angle over pi. Twin: `Environment::uv`.
fn env_uv(d: vec3<f32>) -> vec2<f32> {
    let u = atan2(d.x, d.y) / (2.0 * PI) + 0.5;
    return vec2<f32>(u - floor(u), acos(clamp(d.z, -1.0, 1.0)) / PI);
}

fn env_direction(uv: vec2<f32>) -> vec3<f32> {
    let az = (uv.x - 0.5) * 2.0 * PI;
    let th = uv.y * PI;
    return vec3<f32>(sin(th) * sin(az), sin(th) * cos(az), cos(th));
}

fn env_texel(uv: vec2<f32>) -> vec2<u32> {
    let s = env_size();
    return min(vec2<u32>(uv * vec2<f32>(s)), s - vec2<u32>(1u));
}

fn env_rgb(t: vec2<u32>) -> vec3<f32> {
    let k = 4u + 4u * (t.y * env_size().x + t.x);
    return vec3<f32>(env[k], env[k + 1u], env[k + 2u]);
}

// The environment's radiance towards d (nearest texel). Twin: `Environment::radiance`.
fn env_radiance(d: vec3<f32>) -> vec3<f32> {
    return env_rgb(env_texel(env_uv(d))) * path.env.y;
}

// The density (per steradian) of drawing d. Twin: `Environment::pdf`.
fn env_pdf(d: vec3<f32>) -> f32 {
    let uv = env_uv(d);
    let t = env_texel(uv);
    let sin_theta = sin(uv.y * PI);
    if sin_theta <= 0.0 {
        return 0.0;
    }
    let row_sin = sin((f32(t.y) + 0.5) / f32(env_size().y) * PI);
    let lum = max(dot(env_rgb(t), vec3<f32>(0.2126, 0.7152, 0.0722)), 0.0);
    return lum * row_sin / env[2] / (2.0 * PI * PI * sin_theta);
}

// The last k with cdf[k] <= x among `n` ascending values from `base`.
fn env_find(base: u32, n: u32, x: f32) -> u32 {
    var lo = 0u;
    var hi = n - 1u;
    while lo + 1u < hi {
        let mid = (lo + hi) / 2u;
        if env[base + mid] <= x {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return lo;
}

// A direction drawn from the environment's luminance × sin(theta) (xyz) and
// its density (w). Twin: `Environment::sample`.
fn env_sample(xi: vec2<f32>) -> vec4<f32> {
    let s = env_size();
    let mb = 4u + 4u * s.x * s.y;
    let cb = mb + s.y + 1u;
    let j = min(env_find(mb, s.y + 1u, xi.x), s.y - 1u);
    let dv = (xi.x - env[mb + j]) / max(env[mb + j + 1u] - env[mb + j], 1e-30);
    let rb = cb + j * (s.x + 1u);
    let i = min(env_find(rb, s.x + 1u, xi.y), s.x - 1u);
    let du = (xi.y - env[rb + i]) / max(env[rb + i + 1u] - env[rb + i], 1e-30);
    let uv = vec2<f32>((f32(i) + clamp(du, 0.0, 1.0)) / f32(s.x), (f32(j) + clamp(dv, 0.0, 1.0)) / f32(s.y));
    let d = env_direction(uv);
    return vec4<f32>(d, env_pdf(d));
}

// The weight of light found by escaping along d, sampled by the surface with
// density pdf_surface: 1 without an environment (nothing else samples the
// sky), else against the environment's own sampling.
fn escape_weight(d: vec3<f32>, pdf_surface: f32) -> f32 {
    if !env_on() {
        return 1.0;
    }
    return power_weight(pdf_surface, env_pdf(d));
}

// The power heuristic's weight of a strategy of density a beside one of b
// (Veach & Guibas 1995).
fn power_weight(a: f32, b: f32) -> f32 {
    let a2 = a * a;
    return select(0.0, a2 / (a2 + b * b), a2 > 0.0);
}

// The sky's radiance in direction d (the sun's disk not included: it is
// sampled); below the horizon, the ground's albedo under it. With an
// environment, the environment (its sun included).
fn sky(d: vec3<f32>) -> vec3<f32> {
    if env_on() {
        return env_radiance(d);
    }
    // Below the horizon, where nothing traced lies: level ground of the
    // ground's albedo lit by the sun and the sky, unshadowed (Lambertian:
    // albedo x (the sun's irradiance / pi + the sky's mean radiance, taken
    // 45 degrees up in the same azimuth)).
    let sun_on_ground = path.sun_color.rgb * max(path.sun_dir.z, 0.0);
    if part_on(LIGHT_SKY) {
        if d.z < 0.0 {
            let up45 = normalize(vec3<f32>(d.x, d.y, 0.0) + vec3<f32>(0.0, 0.0, length(d.xy) + 1e-3));
            return path.ground.rgb * (sun_on_ground + sky_preetham(up45));
        }
        return sky_preetham(d);
    }
    if d.z < 0.0 {
        return path.ground.rgb * (sun_on_ground + mix(path.sky_horizon.rgb, path.sky_zenith.rgb, 0.84));
    }
    return mix(path.sky_horizon.rgb, path.sky_zenith.rgb, sqrt(d.z));
}

// The raster's background where a view ray meets nothing (shaders/sky.wgsl):
// the sky above the horizon, its ground colour below.
fn raster_background(d: vec3<f32>) -> vec3<f32> {
    if d.z >= 0.0 || part_on(LIGHT_SKY) {
        return sky(d);
    }
    let scale = path.sky_horizon.rgb / vec3<f32>(0.62, 0.74, 0.86);
    let ground = vec3<f32>(0.16, 0.15, 0.08) * scale;
    return mix(path.sky_horizon.rgb * 0.5 + ground * 0.5, ground, sqrt(min(-d.z * 4.0, 1.0)));
}

// The raster's aerial perspective (haze_at in shaders/light.wgsl): `color`
// seen through `dist` metres of air along the unit direction d.
fn raster_haze(color: vec3<f32>, d: vec3<f32>, dist: f32) -> vec3<f32> {
    if part_on(LIGHT_AERIAL) {
        return through_air(color, d, dist);
    }
    let rel = d * dist;
    let h = max(path.eye_z + 0.5 * rel.z, 0.0);
    let f = 1.0 - exp(-dist * (1.0 / 16000.0) * exp(-h / 1500.0));
    return mix(color, path.sky_horizon.rgb, f);
}

// An sRGB-encoded texel's linear colour and alpha.
fn texel_linear(t: u32) -> vec4<f32> {
    let c = vec4<f32>(f32(t & 0xffu), f32((t >> 8u) & 0xffu), f32((t >> 16u) & 0xffu), f32(t >> 24u)) / 255.0;
    let lin = select(pow((c.rgb + 0.055) / 1.055, vec3<f32>(2.4)), c.rgb / 12.92, c.rgb <= vec3<f32>(0.04045));
    return vec4<f32>(lin, c.a);
}

// A texture layer's linear colour at uv: bilinear, repeating (the raster's sampler at mip 0).
fn texel_color(base: u32, size: u32, uv: vec2<f32>) -> vec3<f32> {
    let n = i32(size);
    let x = fract(uv.x) * f32(size) - 0.5;
    let y = fract(uv.y) * f32(size) - 0.5;
    let x0 = floor(x);
    let y0 = floor(y);
    let f = vec2<f32>(x - x0, y - y0);
    var c: array<vec3<f32>, 4>;
    for (var k = 0; k < 4; k++) {
        let tx = (((i32(x0) + (k & 1)) % n) + n) % n;
        let ty = (((i32(y0) + (k >> 1u)) % n) + n) % n;
        c[k] = texel_linear(trace_texels[base + u32(ty * n + tx)]).rgb;
    }
    return mix(mix(c[0], c[1], f.x), mix(c[2], c[3], f.x), f.y);
}

// What a path meets: where, the surface's normal (facing the ray), its albedo
// and whether it is a leaf; t < 0 for the sky.
struct Surface {
    t: f32,
    normal: vec3<f32>,
    albedo: vec3<f32>,
    leaf: bool,
};

// The nearest surface along o + t d: a tree (the two levels) or the ground plane.
fn hit_surface(o: vec3<f32>, d: vec3<f32>) -> Surface {
    var s: Surface;
    s.t = -1.0;
    var t_max = FAR;
    var t_ground = -1.0;
    if abs(d.z) > 1e-9 {
        let t = (path.ground.w - o.z) / d.z;
        // (A ground far below everything, -1e30: none.)
        if t > 0.0 && t < FAR {
            t_ground = t;
            t_max = t;
        }
    }
    let h = trace_scene(o, d, t_max);
    if h.hit.t > 0.0 {
        let inst = trace_instances[h.slot];
        let sp = trace_species[inst.species & 0xffffffu];
        let tri = bvh_tris[h.hit.index];
        let m = trace_materials[sp.material_base + tri.material];
        // The geometric normal, carried out of model space (inverse transpose).
        let nm = cross(tri.e1, tri.e2);
        var n = normalize(vec3<f32>(nm.x / inst.scale_xy, nm.y / inst.scale_xy, nm.z / inst.scale_z));
        let c = cos(inst.yaw);
        let sn = sin(inst.yaw);
        n = vec3<f32>(c * n.x - sn * n.y, sn * n.x + c * n.y, n.z);
        s.t = h.hit.t;
        s.normal = select(n, -n, dot(n, d) > 0.0);
        // The raster's albedo: material × vertex colour × texture.
        let vc = vec3<f32>(f32(tri.color & 0xffu), f32((tri.color >> 8u) & 0xffu), f32((tri.color >> 16u) & 0xffu)) / 255.0;
        var albedo = m.base_color.rgb * vc;
        if m.texel_base != NO_TEXTURE && m.size > 0u {
            albedo *= texel_color(m.texel_base, m.size, trace_uv(sp, tri, h.hit.u, h.hit.v));
        }
        // The tree's tint, as the raster's `variation_tint` (shaders/light.wgsl).
        let tint = inst.species >> 24u;
        if tint > 0u {
            let v = f32(tint - 1u) / 31.0 - 0.5;
            albedo *= vec3<f32>(1.0 + 0.12 * v, 1.0 + 0.08 * v, 1.0 - 0.05 * v);
        }
        s.albedo = albedo;
        s.leaf = m.kind == 0u;
        return s;
    }
    if t_ground > 0.0 {
        s.t = t_ground;
        // Facing the ray (an eye below the plane sees its underside).
        s.normal = vec3<f32>(0.0, 0.0, select(1.0, -1.0, d.z > 0.0));
        s.albedo = path.ground.rgb;
        s.leaf = false;
    }
    return s;
}

// Whether the environment is seen from p along l (the ground plane, where
// there is one, hides what lies below the horizon).
fn env_visible(p: vec3<f32>, l: vec3<f32>) -> bool {
    if l.z < 0.0 && path.ground.w > -1e29 {
        return false;
    }
    return trace_scene(p, l, FAR).hit.t < 0.0;
}

// Whether the sun is seen from p along l (nothing, the ground included, in the way).
fn sun_visible(p: vec3<f32>, l: vec3<f32>) -> bool {
    if l.z <= 0.0 {
        return false;
    }
    return trace_scene(p, l, FAR).hit.t < 0.0;
}

@compute @workgroup_size(8, 8)
fn path_trace(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= path.width || gid.y >= path.height {
        return;
    }
    let pixel = gid.y * path.width + gid.x;
    var sum = vec3<f32>(0.0);
    for (var k = 0u; k < path.samples; k++) {
        rng_state = hash3(vec3<u32>(gid.x, gid.y, path.sample + k));
        var jitter = rand2();
        if path.sampling.x < 0.5 {
            jitter = vec2<f32>(0.5);
        }
        let ndc = vec2<f32>(
            (f32(gid.x) + jitter.x) / f32(path.width) * 2.0 - 1.0,
            1.0 - (f32(gid.y) + jitter.y) / f32(path.height) * 2.0,
        );
        var d = normalize(path.forward.xyz + path.right.xyz * ndc.x + path.up.xyz * ndc.y);
        var o = path.origin.xyz;
        var throughput = vec3<f32>(1.0);
        var radiance = vec3<f32>(0.0);
        // The density with which the surface sampled the path's last direction.
        var last_pdf = 0.0;
        // The primary ray and how far it went before its first hit (-1: none).
        let d0 = d;
        var primary_t = -1.0;
        for (var bounce = 0u; bounce <= path.bounces; bounce++) {
            let s = hit_surface(o, d);
            if bounce == 0u {
                primary_t = s.t;
            }
            if s.t < 0.0 {
                if path.simple == 1u && bounce == 0u {
                    radiance += raster_background(d);
                } else if bounce == 0u {
                    radiance += throughput * sky(d);
                } else {
                    radiance += throughput * sky(d) * escape_weight(d, last_pdf);
                }
                break;
            }
            let p = o + d * s.t;
            let eps = 2e-3 + 1e-6 * length(p);
            var reflect_share = 1.0;
            if s.leaf {
                reflect_share = 1.0 - path.leaf_transmit;
            }
            if path.simple == 1u {
                // The raster's light (shade() in shaders/light.wgsl with its
                // shadows and occlusion off, its parts as the raster's): the
                // sun on a leaf reflected and transmitted (or the wrap term),
                // the sky's light (or the hemisphere), the air; no bounce.
                let ndl = dot(s.normal, path.sun_dir.xyz);
                var diffuse = max(ndl, 0.0);
                var up = 0.5 + 0.5 * clamp(s.normal.z, -1.0, 1.0);
                let t = select(0.25, path.sky.sun.w, part_on(LIGHT_TRANSMISSION));
                if s.leaf {
                    diffuse = select(1.0, 1.0 - t, part_on(LIGHT_TRANSMISSION)) * max(ndl, 0.0) + t * max(-ndl, 0.0);
                    up = 0.5 + 0.25 * clamp(s.normal.z, -1.0, 1.0);
                }
                var sky_light = path.ambient.rgb * mix(vec3<f32>(0.62, 0.58, 0.5), vec3<f32>(1.1, 1.12, 1.18), up);
                if part_on(LIGHT_SKY_LIGHT) {
                    sky_light = sh_irradiance(s.normal, path.sky.sh);
                    if s.leaf {
                        sky_light = (1.0 - t) * sky_light + t * sh_irradiance(-s.normal, path.sky.sh);
                    }
                }
                radiance = raster_haze(s.albedo * (sky_light + path.sun_color.rgb * diffuse), d, s.t);
                break;
            }
            if env_on() {
                // The environment, importance sampled, weighed against the
                // chance the surface's own sampling finds the same direction.
                let e = env_sample(rand2());
                let l = e.xyz;
                let cos_l = dot(s.normal, l);
                let side = select(-1.0, 1.0, cos_l > 0.0);
                let share = select(1.0 - reflect_share, reflect_share, cos_l > 0.0);
                if share > 0.0 && e.w > 0.0 && env_visible(p + s.normal * (eps * side), l) {
                    let pdf_surface = share * abs(cos_l) / PI;
                    let f = s.albedo * share / PI;
                    radiance += throughput * f * env_radiance(l) * abs(cos_l) / e.w * power_weight(e.w, pdf_surface);
                }
            } else {
                // The sun, sampled on its disk: reflected on the side facing the
                // ray, transmitted through a leaf from the other side.
                let l = sun_sample(rand2());
                let cos_l = dot(s.normal, l);
                let side = select(-1.0, 1.0, cos_l > 0.0);
                let share = select(1.0 - reflect_share, reflect_share, cos_l > 0.0);
                if share > 0.0 && sun_visible(p + s.normal * (eps * side), l) {
                    radiance += throughput * s.albedo * share * path.sun_color.rgb * abs(cos_l);
                }
            }
            // The next direction: reflected (cosine around the facing normal)
            // or, through a leaf, transmitted (around the other side's).
            let r = rand2();
            var n = s.normal;
            var chosen = reflect_share;
            if r.x >= reflect_share {
                n = -n;
                chosen = 1.0 - reflect_share;
            }
            d = cosine_around(n, rand2());
            o = p + n * eps;
            throughput *= s.albedo;
            // The density of that direction (for the environment's weight where it escapes).
            let pdf_surface = chosen * max(dot(n, d), 0.0) / PI;
            if bounce == path.bounces {
                // The last vertex still sees the sky (its sun is sampled above).
                if hit_surface(o, d).t < 0.0 {
                    radiance += throughput * sky(d) * escape_weight(d, pdf_surface);
                }
                break;
            }
            last_pdf = pdf_surface;
            // Russian roulette past the first bounce.
            if bounce >= 1u {
                let q = clamp(max(throughput.r, max(throughput.g, throughput.b)), 0.05, 1.0);
                if r.y > q {
                    break;
                }
                throughput /= q;
            }
        }
        // (A sample gone non-finite is dropped rather than poisoning the pixel.)
        // All the light the path gathered reaches the eye through the air of
        // the primary segment (the simple light hazes its own, as the raster).
        if path.simple == 0u && primary_t > 0.0 && part_on(LIGHT_AERIAL) {
            radiance = through_air(radiance, d0, primary_t);
        }
        if all(radiance == radiance) && all(abs(radiance) < vec3<f32>(1e30)) {
            sum += radiance;
        }
    }
    accum[pixel] += vec4<f32>(sum, f32(path.samples));
}

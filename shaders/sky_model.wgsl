// The clear sky and the air as plain functions, read by the raster's light
// (light.wgsl: the view's `Sky`) and by the path tracer (path_trace.wgsl: its
// params), so both see one model. CPU twins: src/trace/sky.rs (Preetham,
// Shirley & Smits 1999) and src/render/sky_light.rs (the air).

// The sky's light, the air, the light's parts. Must match `SkyUniform` in
// src/lod/shared.rs (written by src/render/sky_light.rs).
struct Sky {
    // Irradiance over pi from the sky and the ground below the horizon:
    // spherical harmonics to order 2, pre-multiplied by their constants (`sky_sh`).
    sh: array<vec4<f32>, 9>,
    // Preetham et al. 1999: Perez coefficients A-E for (Y, x, y).
    perez: array<vec4<f32>, 5>,
    // The zenith's (Y, x, y) over their distribution; w: render units per kcd/m2.
    zenith: vec4<f32>,
    // The fitted sun (xyz); w: the share of a leaf's albedo it transmits.
    sun: vec4<f32>,
    // Rayleigh scattering at the origin's height (rgb, 1/m), w: scale height (m).
    rayleigh: vec4<f32>,
    // x: the haze's extinction at the origin's height (1/m), y: scale height (m).
    mie: vec4<f32>,
    // The air's light: the horizon's radiance as air[0] + sum over k = 1..4 of
    // air[2k-1] cos(k phi) + air[2k] sin(k phi), phi the azimuth from east
    // towards north (`air_light`).
    air: array<vec4<f32>, 9>,
    // x: LIGHT_* bits on.
    parts: vec4<u32>,
};

// The light's parts (`SkyUniform::parts`). Must match `LIGHT_*` in src/lod/shared.rs.
const LIGHT_SKY: u32 = 1u;
const LIGHT_AERIAL: u32 = 2u;
const LIGHT_SKY_LIGHT: u32 = 4u;
const LIGHT_TRANSMISSION: u32 = 8u;
const LIGHT_SOFT_SHADOWS: u32 = 16u;

// The irradiance over pi on a surface facing n (spherical harmonics of the
// sky and the ground below the horizon, Ramamoorthi & Hanrahan 2001; CPU twin
// `eval_sh` in src/render/sky_light.rs). n may be a mean of unit normals
// (length r <= 1): the second band's 3z^2 - r^2 then averages to 0 over
// normals spread all round, as the other terms do.
fn sh_irradiance(n: vec3<f32>, c: array<vec4<f32>, 9>) -> vec3<f32> {
    let e = c[0].rgb + c[1].rgb * n.y + c[2].rgb * n.z + c[3].rgb * n.x + c[4].rgb * (n.x * n.y)
        + c[5].rgb * (n.y * n.z) + c[6].rgb * (3.0 * n.z * n.z - dot(n, n)) + c[7].rgb * (n.x * n.z)
        + c[8].rgb * (n.x * n.x - n.y * n.y);
    return max(e, vec3<f32>(0.0));
}

// Perez et al.'s distribution for (Y, x, y): coefficients A-E (`p`, each a
// vec4 of Y, x, y) at the zenith angle's cosine and the angle to the sun
// (Preetham et al. 1999, eq. 3; twin `perez` in src/trace/sky.rs).
fn perez_yxy(cos_theta: f32, gamma: f32, p: array<vec4<f32>, 5>) -> vec3<f32> {
    let cg = cos(gamma);
    return (1.0 + p[0].xyz * exp(p[1].xyz / max(cos_theta, 0.01))) * (1.0 + p[2].xyz * exp(p[3].xyz * gamma) + p[4].xyz * cg * cg);
}

// The clear sky's radiance towards the unit direction d (linear sRGB, in
// `zenith.w` render units per kcd/m2): `zenith` the zenith's (Y, x, y) over
// their distribution there, `sun` the fitted sun. Twin: `PreethamSky::radiance`.
fn preetham_radiance(d: vec3<f32>, sun: vec3<f32>, zenith: vec4<f32>, p: array<vec4<f32>, 5>) -> vec3<f32> {
    let gamma = acos(clamp(dot(d, sun), -1.0, 1.0));
    let yxy = zenith.xyz * perez_yxy(d.z, gamma, p);
    let y = max(yxy.z, 1e-4);
    let big_x = yxy.y * yxy.x / y;
    let big_z = (1.0 - yxy.y - yxy.z) * yxy.x / y;
    let rgb = vec3<f32>(
        3.2406 * big_x - 1.5372 * yxy.x - 0.4986 * big_z,
        -0.9689 * big_x + 1.8758 * yxy.x + 0.0415 * big_z,
        0.0557 * big_x - 0.2040 * yxy.x + 1.0570 * big_z,
    );
    return max(rgb, vec3<f32>(0.0)) * zenith.w;
}

// The length of air at the scene origin's density equivalent to `s` metres
// rising `dz` through a layer of scale height h, from `eye_z` (>= 0) up: the
// optical depth of an exponential layer in closed form (as a difference of
// the two ends' densities, finite however high the eye).
fn air_depth(eye_z: f32, s: f32, dz: f32, h: f32) -> f32 {
    let x = dz / h;
    let a = exp(-eye_z / h);
    return select(s / x * (a - exp(-eye_z / h - x)), s * a * (1.0 - 0.5 * x), abs(x) < 1e-4);
}

// The air's transmittance from an eye `eye_z` metres above the scene's
// origin over `rel` (metres): Rayleigh (rgb per metre, w its scale height)
// and the haze (x per metre, y its scale height). Twin: `air_transmittance`
// in src/render/sky_light.rs.
fn air_transmittance(rel: vec3<f32>, eye_z: f32, rayleigh: vec4<f32>, mie: vec4<f32>) -> vec3<f32> {
    let z = max(eye_z, 0.0);
    let s = length(rel);
    let tau = rayleigh.rgb * air_depth(z, s, rel.z, rayleigh.w) + vec3<f32>(mie.x * air_depth(z, s, rel.z, mie.y));
    return exp(-tau);
}

// The light the air scatters towards the eye over a long path towards `rel`:
// the horizon's radiance in that azimuth, from the Fourier series the CPU
// fitted (`SkyLight::air_ring`) — a few multiplies per fragment where the
// clear sky's own formula costs exponentials and an arccosine.
fn air_light(rel: vec3<f32>, air: array<vec4<f32>, 9>) -> vec3<f32> {
    let h = rel.xy / max(length(rel.xy), 1e-6);
    var l = air[0].rgb;
    // cos(k phi) + i sin(k phi) as powers of h.
    var e = vec2<f32>(1.0, 0.0);
    for (var k = 1u; k <= 4u; k++) {
        e = vec2<f32>(e.x * h.x - e.y * h.y, e.y * h.x + e.x * h.y);
        l += air[2u * k - 1u].rgb * e.x + air[2u * k].rgb * e.y;
    }
    return max(l, vec3<f32>(0.0));
}

// Where the air's light comes from along the view towards `rel`: over a long
// path the light the air scatters towards the eye is the sky's own radiance
// at the horizon in that azimuth (above the horizon: the sky behind).
fn air_light_dir(rel: vec3<f32>) -> vec3<f32> {
    let d = rel / max(length(rel), 1e-6);
    let h = vec3<f32>(d.xy, max(d.z, 0.0));
    return select(normalize(h), vec3<f32>(1.0, 0.0, 0.0), dot(h, h) < 1e-8);
}

// The styles' bit layout (twin: src/scene/style.rs) and the colours it gives;
// `styles.wgsl` binds them for the draw passes, the cull reads them for
// filtered-out trees.

// Styles, in the cull control buffer from byte 256 (the draw passes
// bind them from there): a header, the palette (64 packed RGBA8 colours,
// entry 0 unused) and the flags at word 64, then, with STYLE_TREES, a byte per
// pool instance: bits 0–5 its palette entry (0: its own colour), bit 6
// selected, bit 7 filtered out (or not standing at the view's date); with
// STYLE_DATED the growth bytes after them (STYLE_GROWTH_AT). Must match
// src/render/gpu_data.rs.
const STYLE_CONTROL_WORD: u32 = 64u;
const STYLE_HEADER_WORDS: u32 = 128u;
const STYLE_FLAGS: u32 = 64u;
const STYLE_TREES: u32 = 1u;
const STYLE_BY_SPECIES: u32 = 2u;
const STYLE_DATED: u32 = 4u;
// Header word: where the growth bytes start (words from the styles' start);
// with STYLE_DATED a byte per pool instance there: the tree's scale at the
// view's date over its own, in 1/128 (src/format/timeline.rs `growth_byte`).
const STYLE_GROWTH_AT: u32 = 65u;
const STYLE_SELECTED: u32 = 64u;
const STYLE_HIDDEN: u32 = 128u;

// Byte `instance & 3` of a word of style bytes.
fn style_byte_of(word: u32, instance: u32) -> u32 {
    return (word >> ((instance & 3u) * 8u)) & 0xffu;
}

// The style byte of a tree: from the header's `flags` and (with STYLE_TREES)
// the `word` of style bytes holding pool instance `instance` of model species `species`.
fn style_of(flags: u32, word: u32, instance: u32, species: u32) -> u32 {
    var b = select(0u, style_byte_of(word, instance), (flags & STYLE_TREES) != 0u);
    if (flags & STYLE_BY_SPECIES) != 0u {
        b = (b & 0xc0u) | min(species + 1u, 63u);
    }
    return b;
}

// A style's colour (palette word `entry`, sRGB with its weight in alpha; 0:
// none) in place of a tree's albedo, keeping the light and dark of its texture.
fn styled_albedo(albedo: vec3<f32>, entry: u32) -> vec3<f32> {
    if entry == 0u {
        return albedo;
    }
    let c = unpack4x8unorm(entry);
    let l = dot(albedo, vec3<f32>(0.2126, 0.7152, 0.0722));
    let shade = clamp(l / 0.06, 0.45, 1.6);
    return mix(albedo, pow(c.rgb, vec3<f32>(2.2)) * 0.6 * shade, c.a);
}

// A selected tree's colour: tinted towards a bright yellow.
fn highlighted(color: vec3<f32>, style: u32) -> vec3<f32> {
    return select(color, mix(color, vec3<f32>(1.0, 0.82, 0.1), 0.55), (style & STYLE_SELECTED) != 0u);
}

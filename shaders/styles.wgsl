// The styles of the tree passes: the cull control buffer from
// `STYLE_OFFSET_BYTES` (style_bits.wgsl `style_of` and friends, the layout there).
// Composed after style_bits.wgsl, view.wgsl and trees.wgsl into the mesh,
// billboard, impostor and cluster passes by `src/render/shaders.rs`; group 2
// is their instance group (`trees.wgsl`).

@group(2) @binding(3) var<storage, read> styles: array<u32>;

// The style byte of pool instance `instance` of model species `species` (its
// word read only where the style has per-tree bytes).
fn tree_style(flags: u32, instance: u32, species: u32) -> u32 {
    var word = 0u;
    if (flags & STYLE_TREES) != 0u {
        word = styles[STYLE_HEADER_WORDS + instance / 4u];
    }
    return style_of(flags, word, instance, species);
}

// The scale pool instance `instance` is drawn at over its own: at a date
// (STYLE_DATED) its growth byte, else 1. Twin: `growth_of_byte` in
// src/format/timeline.rs.
fn tree_growth(flags: u32, instance: u32) -> f32 {
    if (flags & STYLE_DATED) == 0u {
        return 1.0;
    }
    let word = styles[styles[STYLE_GROWTH_AT] + instance / 4u];
    return f32(style_byte_of(word, instance)) / 128.0;
}

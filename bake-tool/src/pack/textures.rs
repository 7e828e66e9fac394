//! A pack's block-compressed variants (issue 47): the same pack with its RGBA
//! texture arrays — impostor colour and surface, billboard colour and normals,
//! the material textures — encoded as BC7 or ETC2 RGBA8 (16 bytes per 4 × 4
//! texels, a quarter of RGBA8), which GPUs sample directly: BC7 desktop ones
//! (`texture-compression-bc`), ETC2 phones, tablets and Apple silicon
//! (`texture-compression-etc2`). Everything else, including the billboards' R8
//! occlusion, is as in the pack. A viewer whose device has the feature
//! fetches the variant instead of the pack (`SpeciesEntry::variants`).
//!
//! Measured on the demo (docs/BENCHMARKS.md "Textures compressed on the
//! GPU"): the far tiers' arrays a quarter of their GPU bytes, their deflated
//! download about 40 % smaller, the rendered views 0.002–0.003 MS-RMSE from
//! the RGBA8 ones. The encoder is Intel's ISPC texture compressor
//! (`intel_tex_2`, its "very fast" alpha profile: as close as its "basic"
//! one on these textures at a third of the time). ETC2 by etcpak
//! (`ctt-etcpak`: every ETC2 colour mode, EAC alpha). (The ISPC compressor's
//! ETC1 was tried first and left: an assertion in its kernel aborts the
//! process on some blocks — a bake must fail by its error, never abort.)

use anyhow::{anyhow, Result};
use rayon::prelude::*;
use sylva::format::pack::{encode_pack, kind, Section, TexelEncoding, TextureArrayMeta};

/// The pack `bytes` (a pack as built, not stored) with its RGBA texture
/// arrays block-encoded as `encoding`. Arrays whose side is no multiple of 4
/// stay plain (their `META` says so).
///
/// # Errors
/// A pack that does not decode (`name` names it).
pub fn block_encoded(name: &str, bytes: &[u8], encoding: TexelEncoding) -> Result<Vec<u8>> {
    let pack = sylva::format::decode_pack(name, bytes)?;
    let mut meta = pack.meta.clone();
    let encodable = |t: &Option<TextureArrayMeta>| t.filter(|t| t.size.is_multiple_of(4) && t.encoding.is_none());
    let material = encodable(&meta.material_texture);
    let billboards = encodable(&meta.billboards.as_ref().map(|b| b.texture));
    let impostors = encodable(&meta.impostors.as_ref().map(|i| i.texture));
    let mut sections = Vec::with_capacity(pack.sections.len());
    for (e, data) in &pack.sections {
        if e.kind == kind::META || e.kind == kind::STORED {
            continue;
        }
        let texture = match e.kind {
            kind::MATERIAL_TEXTURES => material,
            kind::BILLBOARD_COLOR | kind::BILLBOARD_NORMAL => billboards,
            kind::IMPOSTOR_COLOR | kind::IMPOSTOR_SURFACE => impostors,
            _ => None,
        };
        let data = match texture {
            Some(t) => encode_array(&t, data, encoding),
            None => data.to_vec(),
        };
        sections.push(Section { kind: e.kind, index: e.index, count: e.count, stride: e.stride, data });
    }
    let encoded = |t: TextureArrayMeta| TextureArrayMeta { encoding: Some(encoding), ..t };
    if let (Some(t), Some(m)) = (material, meta.material_texture.as_mut()) {
        // What the viewer counts of the plain texels (adaptive transparency), counted here.
        let texels = pack.section(kind::MATERIAL_TEXTURES, 0).unwrap_or(&[]);
        for mat in &mut meta.materials {
            if let Some(l) = mat.texture_layer {
                mat.coverage = Some(sylva::render::mesh::layer_coverage(&t, texels, l, mat.alpha_cutoff));
            }
        }
        *m = encoded(t);
    }
    if let (Some(t), Some(b)) = (billboards, meta.billboards.as_mut()) {
        b.texture = encoded(t);
    }
    if let (Some(t), Some(i)) = (impostors, meta.impostors.as_mut()) {
        i.texture = encoded(t);
    }
    let out = encode_pack(&meta, &sections);
    sylva::format::decode_pack(name, &out).map_err(|e| anyhow!("the {} variant of {e}", encoding.name()))?;
    Ok(out)
}

/// One RGBA8 array (mips one after another, each holding every layer) as
/// blocks in the same order; layers encoded in parallel.
fn encode_array(t: &TextureArrayMeta, data: &[u8], encoding: TexelEncoding) -> Vec<u8> {
    let blocked = TextureArrayMeta { encoding: Some(encoding), ..*t };
    let mut out = Vec::with_capacity(blocked.byte_len() as usize);
    for mip in 0..t.mips {
        let size = (t.size >> mip).max(1);
        let layer_bytes = t.mip_bytes(mip, 4) as usize;
        let start = t.mip_offset(mip, 4) as usize;
        let layers: Vec<Vec<u8>> = (0..t.layers as usize)
            .into_par_iter()
            .map(|l| {
                let texels = data.get(start + l * layer_bytes..start + (l + 1) * layer_bytes).unwrap_or(&[]);
                encode_image(texels, size, encoding)
            })
            .collect();
        for l in layers {
            out.extend_from_slice(&l);
        }
    }
    out
}

/// One `size`² RGBA8 image as blocks; a side under 4 (or not a multiple of
/// it) is padded by repeating the last row and column.
fn encode_image(texels: &[u8], size: u32, encoding: TexelEncoding) -> Vec<u8> {
    let padded_side = size.next_multiple_of(4);
    let mut padded = vec![0u8; (padded_side * padded_side * 4) as usize];
    for y in 0..padded_side {
        for x in 0..padded_side {
            let src = ((y.min(size - 1) * size + x.min(size - 1)) * 4) as usize;
            let dst = ((y * padded_side + x) * 4) as usize;
            if let Some(px) = texels.get(src..src + 4) {
                padded[dst..dst + 4].copy_from_slice(px);
            }
        }
    }
    match encoding {
        TexelEncoding::Bc7 => {
            let surface = intel_tex_2::RgbaSurface {
                data: &padded,
                width: padded_side,
                height: padded_side,
                stride: padded_side * 4,
            };
            intel_tex_2::bc7::compress_blocks(&intel_tex_2::bc7::alpha_very_fast_settings(), &surface)
        }
        TexelEncoding::Etc2 => {
            // etcpak reads its ETC input as BGRA.
            for px in padded.chunks_exact_mut(4) {
                px.swap(0, 2);
            }
            let surface = ctt_etcpak::Surface::new(&padded, padded_side, padded_side);
            // (Its heuristics off: every mode tried, T, H and planar included.)
            ctt_etcpak::etc2_rgba::compress_blocks(&surface, false)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Decodes blocks of a `side`² image back to RGBA8 (independent decoders:
    /// `bcdec_rs` for BC7, `texture2ddecoder` for ETC2).
    fn decode(blocks: &[u8], side: u32, encoding: TexelEncoding) -> Vec<u8> {
        let padded = side.next_multiple_of(4);
        let mut out = vec![0u8; (padded * padded * 4) as usize];
        for (i, b) in blocks.chunks(16).enumerate() {
            let (bx, by) = (i as u32 % (padded / 4), i as u32 / (padded / 4));
            let mut px = [0u8; 64];
            match encoding {
                TexelEncoding::Bc7 => bcdec_rs::bc7(b, &mut px, 16),
                TexelEncoding::Etc2 => {
                    let mut argb = [0u32; 16];
                    texture2ddecoder::decode_etc2_rgba8_block(b, &mut argb);
                    for (p, c) in px.chunks_exact_mut(4).zip(argb) {
                        let [b, g, r, a] = c.to_le_bytes();
                        p.copy_from_slice(&[r, g, b, a]);
                    }
                }
            }
            for row in 0..4 {
                let at = (((by * 4 + row) * padded + bx * 4) * 4) as usize;
                out[at..at + 16].copy_from_slice(&px[row as usize * 16..][..16]);
            }
        }
        out
    }

    #[test]
    fn an_array_encodes_to_blocks_that_decode_close_to_it() {
        // Two layers, 16² with its mips down to 1²: a gradient with a cut-out.
        let t = TextureArrayMeta::plain(16, 2, 5);
        let mut data = Vec::new();
        for mip in 0..5 {
            let s = 16 >> mip;
            for layer in 0..2u32 {
                for y in 0..s {
                    for x in 0..s {
                        let a = if x + y < s { 255 } else { 0 };
                        data.extend_from_slice(&[(x * 255 / s) as u8, (y * 255 / s) as u8, (layer * 200) as u8, a]);
                    }
                }
            }
        }
        assert_eq!(data.len() as u64, t.byte_len());
        for encoding in [TexelEncoding::Bc7, TexelEncoding::Etc2] {
            let blocks = encode_array(&t, &data, encoding);
            let blocked = TextureArrayMeta { encoding: Some(encoding), ..t };
            // 16² = 16 blocks, 8² 4, 4² 1, 2² and 1² a whole block each; × 2 layers.
            assert_eq!(blocks.len() as u64, blocked.byte_len());
            assert_eq!(blocks.len(), (16 + 4 + 1 + 1 + 1) * 2 * 16);
            // Mip 0, layer 1 decodes close to the texels (RMSE under 8 of 255: the demo's arrays
            // measure 0.01–0.02 of 1), alpha exact at the cut.
            let at = (blocked.mip_bytes(0, 4)) as usize;
            let back = decode(&blocks[at..at + 256], 16, encoding);
            let src = &data[16 * 16 * 4..16 * 16 * 8];
            // (Colour under cut-out texels is free to change: compared where both keep the texel.)
            let kept: Vec<(&[u8], &[u8])> =
                back.chunks(4).zip(src.chunks(4)).filter(|(a, b)| a[3] >= 128 && b[3] >= 128).collect();
            let sq: f64 =
                kept.iter().flat_map(|(a, b)| a.iter().zip(*b)).map(|(a, b)| f64::from(a.abs_diff(*b)).powi(2)).sum();
            let rmse = (sq / (kept.len() * 4) as f64).sqrt();
            let worst = kept.iter().flat_map(|(a, b)| a.iter().zip(*b)).map(|(a, b)| a.abs_diff(*b)).max().unwrap();
            // (ETC2's planar mode fits this gradient closely — RMSE 1.0 against BC7's 5.0 —
            // but four hues in the 2² mip's one block cost it up to 22 levels there.)
            let tiny_largest = if encoding == TexelEncoding::Bc7 { 12 } else { 24 };
            assert!(
                kept.len() > 100 && rmse < 8.0 && worst <= 32,
                "{encoding:?}: RMSE {rmse}, largest difference {worst}"
            );
            eprintln!("{encoding:?}: RMSE {rmse:.2}, largest {worst}");
            let alpha_flips = back.chunks(4).zip(src.chunks(4)).filter(|(a, b)| (a[3] >= 128) != (b[3] >= 128)).count();
            assert_eq!(alpha_flips, 0, "{encoding:?}");
            // The 2² mip's block repeats its texels: its first texel decodes close.
            let m3 = blocked.mip_offset(3, 4) as usize;
            let tiny = decode(&blocks[m3..m3 + 16], 2, encoding);
            let src3 = &data[t.mip_offset(3, 4) as usize..][..4];
            assert!(
                tiny[..4].iter().zip(src3).all(|(a, b)| a.abs_diff(*b) <= tiny_largest),
                "{encoding:?}: {:?} {src3:?}",
                &tiny[..4]
            );
        }
    }
}

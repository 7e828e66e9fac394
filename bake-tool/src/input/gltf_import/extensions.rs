//! glTF extensions as real exporters and optimisers write them, read from the
//! JSON directly (the gltf crate refuses files that *require* an extension it
//! does not know, and exposes none of these):
//!
//! - `KHR_mesh_quantization` (gltfpack, glTF-Transform `quantize`): integer
//!   positions, normals and texture coordinates ([`super::accessors::read_floats`]);
//! - `KHR_texture_transform`: offset, rotation, scale and `texCoord` of the base
//!   colour texture, applied to the texture coordinates at import;
//! - `EXT_mesh_gpu_instancing` (gltfpack `-mi`, glTF-Transform `instance`): a
//!   node's mesh drawn once per TRANSLATION/ROTATION/SCALE row.
//!
//! `EXT_meshopt_compression` / `KHR_meshopt_compression` buffers (gltfpack
//! `-c`) are decoded with the `meshopt` crate ([`decode_meshopt`]). Compressed
//! geometry and textures that the bake cannot decode
//! (`KHR_draco_mesh_compression`, `KHR_texture_basisu` / KTX2) are refused with their name and how to write a
//! plain copy; nothing is dropped without a word.

use anyhow::{bail, Result};
use glam::{Mat3, Mat4, Quat, Vec3};
use serde_json::Value;

/// Extensions the importer handles itself (taken out of `extensionsRequired`
/// before the gltf crate validates the file).
pub const HANDLED: &[&str] = &[
    "EXT_meshopt_compression",
    "KHR_meshopt_compression",
    "KHR_mesh_quantization",
    "KHR_texture_transform",
    "EXT_mesh_gpu_instancing",
    "KHR_materials_emissive_strength",
    "KHR_materials_unlit",
];

/// The error for an extension the bake cannot read, with the way out.
fn unsupported(ext: &str) -> Option<String> {
    Some(match ext {
        "KHR_draco_mesh_compression" => "the model's geometry is Draco-compressed (KHR_draco_mesh_compression), which \
             sylva-bake does not decode: decompress it with `npx @gltf-transform/cli cp model.glb model-plain.glb` \
             (glTF Transform decodes Draco when it reads a file and writes plain geometry), or export it again \
             without Draco compression (in Blender: glTF export, Data › Compression off)"
            .to_string(),
        "KHR_texture_basisu" => "the model's textures are KTX2 / Basis Universal (KHR_texture_basisu), which \
             sylva-bake does not decode: use PNG, JPEG or WebP textures (gltfpack writes KTX2 only with -tc)"
            .to_string(),
        _ => return None,
    })
}

/// Checks the extensions a file requires: known compressions are refused by
/// name, and so is any other required extension the bake does not know. (A
/// KTX2 image that a texture really uses is refused when it is loaded.)
///
/// # Errors
/// An extension the bake cannot read.
pub fn check(root: &Value) -> Result<()> {
    let list = |key: &str| -> Vec<String> {
        root.get(key)
            .and_then(Value::as_array)
            .map(|a| a.iter().filter_map(Value::as_str).map(str::to_string).collect())
            .unwrap_or_default()
    };
    // Only required ones: a file that merely uses them keeps plain fallbacks
    // (uncompressed accessors, PNG/JPEG sources), which are read.
    let required = list("extensionsRequired");
    for ext in &required {
        if let Some(message) = unsupported(ext) {
            bail!("{message}");
        }
    }
    let gltf_knows = gltf::json::extensions::ENABLED_EXTENSIONS;
    for ext in &required {
        if !HANDLED.contains(&ext.as_str()) && !gltf_knows.contains(&ext.as_str()) {
            bail!(
                "the model requires the glTF extension {ext}, which sylva-bake does not support (it reads {}); \
                 re-export the model without it",
                HANDLED.join(", ")
            );
        }
    }
    Ok(())
}

/// Which texture coordinates a material's base colour texture reads, and how
/// they are transformed (`KHR_texture_transform`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UvSet {
    /// `TEXCOORD_n`.
    pub set: u32,
    /// The 2×3 transform, column-major (identity without the extension).
    pub transform: Mat3,
}

impl Default for UvSet {
    fn default() -> Self {
        Self { set: 0, transform: Mat3::IDENTITY }
    }
}

impl UvSet {
    /// The transformed coordinate.
    #[must_use]
    pub fn apply(&self, uv: [f32; 2]) -> [f32; 2] {
        let v = self.transform * Vec3::new(uv[0], uv[1], 1.0);
        [v.x, v.y]
    }
}

/// The base colour texture coordinates of material `index` (`None`: the default material).
#[must_use]
pub fn uv_set(root: &Value, index: Option<usize>) -> UvSet {
    let Some(info) = index.and_then(|i| root.pointer(&format!("/materials/{i}/pbrMetallicRoughness/baseColorTexture")))
    else {
        return UvSet::default();
    };
    let num = |v: Option<&Value>, default: f64| v.and_then(Value::as_f64).filter(|x| x.is_finite()).unwrap_or(default);
    let mut set = info.get("texCoord").and_then(Value::as_u64).unwrap_or(0).min(7) as u32;
    let Some(t) = info.pointer("/extensions/KHR_texture_transform") else {
        return UvSet { set, transform: Mat3::IDENTITY };
    };
    if let Some(n) = t.get("texCoord").and_then(Value::as_u64) {
        set = n.min(7) as u32;
    }
    let pair = |key: &str, default: f64| {
        let a = t.get(key).and_then(Value::as_array);
        [num(a.and_then(|a| a.first()), default) as f32, num(a.and_then(|a| a.get(1)), default) as f32]
    };
    let (offset, scale) = (pair("offset", 0.0), pair("scale", 1.0));
    let rotation = num(t.get("rotation"), 0.0) as f32;
    let (s, c) = rotation.sin_cos();
    // The extension's matrix: translation × rotation × scale (column-major here).
    let translation = Mat3::from_cols(Vec3::X, Vec3::Y, Vec3::new(offset[0], offset[1], 1.0));
    let rotate = Mat3::from_cols(Vec3::new(c, -s, 0.0), Vec3::new(s, c, 0.0), Vec3::Z);
    let scale = Mat3::from_diagonal(Vec3::new(scale[0], scale[1], 1.0));
    UvSet { set, transform: translation * rotate * scale }
}

/// The accessors of node `index`'s `EXT_mesh_gpu_instancing`: TRANSLATION,
/// ROTATION, SCALE (each optional), or `None` without the extension.
#[must_use]
pub fn instancing(root: &Value, index: usize) -> Option<[Option<usize>; 3]> {
    let attributes = root.pointer(&format!("/nodes/{index}/extensions/EXT_mesh_gpu_instancing/attributes"))?;
    let get = |k: &str| attributes.get(k).and_then(Value::as_u64).map(|v| v as usize);
    Some([get("TRANSLATION"), get("ROTATION"), get("SCALE")])
}

/// The instance transforms from instancing rows.
#[must_use]
pub fn instance_matrices(
    translation: &[[f32; 3]],
    rotation: &[[f32; 4]],
    scale: &[[f32; 3]],
    count: usize,
) -> Vec<Mat4> {
    (0..count)
        .map(|i| {
            let t = translation.get(i).map_or(Vec3::ZERO, |v| Vec3::from(*v));
            let r = rotation.get(i).map_or(Quat::IDENTITY, |q| Quat::from_array(*q).normalize());
            let s = scale.get(i).map_or(Vec3::ONE, |v| Vec3::from(*v));
            Mat4::from_scale_rotation_translation(s, if r.is_finite() { r } else { Quat::IDENTITY }, t)
        })
        .collect()
}

/// The meshopt extension object of `value` (either name), if any.
fn meshopt(value: &Value) -> Option<&Value> {
    let ext = value.get("extensions")?;
    ext.get("EXT_meshopt_compression").or_else(|| ext.get("KHR_meshopt_compression"))
}

/// Buffers that only stand in for meshopt-compressed data (`fallback: true`):
/// they may have no bytes of their own; [`decode_meshopt`] fills their views.
#[must_use]
pub fn meshopt_fallbacks(root: &Value) -> Vec<usize> {
    let declared = root.get("extensionsUsed").and_then(Value::as_array).is_some_and(|used| {
        used.iter().any(|e| matches!(e.as_str(), Some("EXT_meshopt_compression" | "KHR_meshopt_compression")))
    });
    if !declared {
        return Vec::new();
    }
    let buffers = root.get("buffers").and_then(Value::as_array).map(Vec::as_slice).unwrap_or_default();
    (0..buffers.len())
        .filter(|&i| meshopt(&buffers[i]).and_then(|m| m.get("fallback")).and_then(Value::as_bool) == Some(true))
        .collect()
}

/// Decodes every meshopt-compressed buffer view into the bytes its plain
/// counterpart names (`buffers[view.buffer][view.byteOffset..]`). Returns the
/// views decoded.
///
/// # Errors
/// A compressed range outside its buffer, a decoded size that does not fit
/// the view, an unknown mode or filter, or data the decoder refuses.
pub fn decode_meshopt(root: &Value, buffers: &mut [Vec<u8>]) -> Result<usize> {
    let views = root.get("bufferViews").and_then(Value::as_array).map(Vec::as_slice).unwrap_or_default();
    let mut decoded = 0;
    for (j, view) in views.iter().enumerate() {
        let Some(m) = meshopt(view) else { continue };
        let what = format!("buffer view {j} (meshopt)");
        let u = |v: Option<&Value>| v.and_then(Value::as_u64).map(|x| x as usize);
        let (Some(src_buffer), Some(len), Some(stride), Some(count)) =
            (u(m.get("buffer")), u(m.get("byteLength")), u(m.get("byteStride")), u(m.get("count")))
        else {
            bail!("{what}: the extension needs buffer, byteLength, byteStride and count");
        };
        let src_offset = u(m.get("byteOffset")).unwrap_or(0);
        let src = buffers
            .get(src_buffer)
            .and_then(|b| b.get(src_offset..src_offset.checked_add(len)?))
            .ok_or_else(|| anyhow::anyhow!("{what}: bytes {src_offset}..+{len} lie outside buffer {src_buffer}"))?
            .to_vec();
        let size = count.checked_mul(stride).filter(|s| *s <= crate::input::gltf_import::sources::MAX_BUFFER_BYTES);
        let Some(size) = size else { bail!("{what}: {count} elements of {stride} bytes are too many") };
        let mode = m.get("mode").and_then(Value::as_str).unwrap_or("");
        let filter = m.get("filter").and_then(Value::as_str).unwrap_or("NONE");
        let (Some(dst_buffer), dst_offset, Some(dst_len)) =
            (u(view.get("buffer")), u(view.get("byteOffset")).unwrap_or(0), u(view.get("byteLength")))
        else {
            bail!("{what}: the view needs buffer and byteLength");
        };
        let fits =
            buffers.get(dst_buffer).is_some_and(|b| dst_offset.checked_add(dst_len).is_some_and(|e| e <= b.len()));
        if !fits {
            bail!("{what}: the view lies outside buffer {dst_buffer}");
        }
        // Checked before decoding: the declared counts must fit what the view holds.
        if size > dst_len {
            bail!("{what}: {count} × {stride} decoded bytes do not fit the view's {dst_len}");
        }
        if mode == "TRIANGLES" && !count.is_multiple_of(3) {
            bail!("{what}: {count} triangle indices are no whole number of triangles");
        }
        let bytes = decode_view(&src, mode, filter, stride, count).map_err(|e| anyhow::anyhow!("{what}: {e}"))?;
        buffers[dst_buffer][dst_offset..dst_offset + size].copy_from_slice(&bytes);
        decoded += 1;
    }
    Ok(decoded)
}

/// One compressed view decoded: `count` elements of `stride` bytes.
fn decode_view(src: &[u8], mode: &str, filter: &str, stride: usize, count: usize) -> Result<Vec<u8>, String> {
    let err = |e: meshopt::Error| format!("the meshopt decoder refused the data ({e:?})");
    match mode {
        "ATTRIBUTES" => {
            if stride == 0 || !stride.is_multiple_of(4) || stride > 128 {
                return Err(format!("attribute stride {stride} (a multiple of 4 up to 128 is read)"));
            }
            let mut words: Vec<u32> = decode_words(src, stride / 4, count).map_err(err)?;
            apply_filter(&mut words, filter, stride)?;
            Ok(bytemuck::cast_slice(&words).to_vec())
        }
        "TRIANGLES" | "INDICES" => {
            let bytes = match (stride, mode) {
                (2, "TRIANGLES") => {
                    bytemuck::cast_slice(&meshopt::decode_index_buffer::<u16>(src, count).map_err(err)?).to_vec()
                }
                (4, "TRIANGLES") => {
                    bytemuck::cast_slice(&meshopt::decode_index_buffer::<u32>(src, count).map_err(err)?).to_vec()
                }
                (2, _) => {
                    bytemuck::cast_slice(&meshopt::decode_index_sequence::<u16>(src, count).map_err(err)?).to_vec()
                }
                (4, _) => {
                    bytemuck::cast_slice(&meshopt::decode_index_sequence::<u32>(src, count).map_err(err)?).to_vec()
                }
                _ => return Err(format!("index stride {stride} (2 or 4)")),
            };
            Ok(bytes)
        }
        other => Err(format!("unknown mode {other:?} (ATTRIBUTES, TRIANGLES, INDICES)")),
    }
}

/// Decodes `count` vertices of `words` 32-bit words each.
fn decode_words(src: &[u8], words: usize, count: usize) -> meshopt::Result<Vec<u32>> {
    macro_rules! by_width {
        ($($n:literal)*) => {
            match words {
                $($n => meshopt::decode_vertex_buffer::<[u32; $n]>(src, count).map(|v| v.concat()),)*
                _ => unreachable!("checked by the caller"),
            }
        };
    }
    by_width!(1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20 21 22 23 24 25 26 27 28 29 30 31 32)
}

/// Undoes a vertex filter in place.
fn apply_filter(words: &mut [u32], filter: &str, stride: usize) -> Result<(), String> {
    match (filter, stride) {
        ("NONE", _) => {}
        ("OCTAHEDRAL", 4) => meshopt::decode_filter_oct(bytemuck::cast_slice_mut::<u32, [i8; 4]>(words)),
        ("OCTAHEDRAL", 8) => meshopt::decode_filter_oct(bytemuck::cast_slice_mut::<u32, [i16; 4]>(words)),
        ("QUATERNION", 8) => meshopt::decode_filter_quat(bytemuck::cast_slice_mut::<u32, [i16; 4]>(words)),
        ("COLOR", 4) => meshopt::decode_filter_color(bytemuck::cast_slice_mut::<u32, [u8; 4]>(words)),
        ("COLOR", 8) => meshopt::decode_filter_color(bytemuck::cast_slice_mut::<u32, [u16; 4]>(words)),
        ("EXPONENTIAL", _) => {
            macro_rules! by_width {
                ($($n:literal)*) => {
                    match stride / 4 {
                        $($n => meshopt::decode_filter_exp(bytemuck::cast_slice_mut::<u32, [u32; $n]>(words)),)*
                        _ => return Err(format!("EXPONENTIAL filter at stride {stride}")),
                    }
                };
            }
            by_width!(1 2 3 4 5 6 7 8)
        }
        (f, s) => return Err(format!("filter {f:?} at stride {s}")),
    }
    Ok(())
}

/// The error for image `index` when it is KTX2 (`mime`, `uri`), else `None`.
#[must_use]
pub fn ktx2_image(index: usize, mime: Option<&str>, uri: Option<&str>) -> Option<String> {
    let uri = uri.unwrap_or("");
    let ktx = mime == Some("image/ktx2") || uri.to_lowercase().ends_with(".ktx2") || uri.starts_with("data:image/ktx2");
    ktx.then(|| format!("image {index} is KTX2: {}", unsupported("KHR_texture_basisu").unwrap_or_default()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texture_transform_follows_the_extension_matrix() {
        let root = serde_json::json!({"materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0,
            "extensions": {"KHR_texture_transform": {"rotation": std::f64::consts::FRAC_PI_2, "scale": [2.0, 1.0],
                "offset": [0.0, 1.0], "texCoord": 2}}}}}]});
        let t = uv_set(&root, Some(0));
        assert_eq!(t.set, 2);
        // translation × rotation × scale; rotation rows (cos, sin), (−sin, cos).
        let [u, v] = t.apply([1.0, 0.0]);
        assert!((u - 0.0).abs() < 1e-6 && (v - (1.0 - 2.0)).abs() < 1e-6, "{u} {v}");
        assert_eq!(uv_set(&root, None), UvSet::default());
        assert_eq!(uv_set(&serde_json::json!({}), Some(3)), UvSet::default());
    }
}

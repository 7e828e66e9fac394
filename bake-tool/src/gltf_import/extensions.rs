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
//! Compressed geometry and textures that the bake cannot decode
//! (`KHR_draco_mesh_compression`, `EXT_meshopt_compression`,
//! `KHR_texture_basisu` / KTX2) are refused with their name and how to write a
//! plain copy; nothing is dropped without a word.

use anyhow::{bail, Result};
use glam::{Mat3, Mat4, Quat, Vec3};
use serde_json::Value;

/// Extensions the importer handles itself (taken out of `extensionsRequired`
/// before the gltf crate validates the file).
pub const HANDLED: &[&str] = &[
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
             sylva-bake does not decode: export it again without Draco compression (in Blender: glTF export, \
             Data › Compression off)"
            .to_string(),
        "EXT_meshopt_compression" | "KHR_meshopt_compression" => format!(
            "the model's buffers are meshopt-compressed ({ext}), which sylva-bake does not decode yet: gltfpack \
             writes it only with -c or -cc; run gltfpack without them (its quantisation, -mi instancing and \
             texture transforms are read)"
        ),
        "KHR_texture_basisu" => "the model's textures are KTX2 / Basis Universal (KHR_texture_basisu), which \
             sylva-bake does not decode: use PNG, JPEG or WebP textures (gltfpack writes KTX2 only with -tc)"
            .to_string(),
        _ => return None,
    })
}

/// Checks the extensions a file requires or uses: known compressions are
/// refused by name; any other required extension the bake does not know too.
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
    let (required, used) = (list("extensionsRequired"), list("extensionsUsed"));
    for ext in required.iter().chain(&used) {
        if let Some(message) = unsupported(ext) {
            bail!("{message}");
        }
    }
    // KTX2 images without the extension declared.
    let images = root.get("images").and_then(Value::as_array).map(Vec::as_slice).unwrap_or_default();
    for (i, image) in images.iter().enumerate() {
        let mime = image.get("mimeType").and_then(Value::as_str).unwrap_or("");
        let uri = image.get("uri").and_then(Value::as_str).unwrap_or("");
        if mime == "image/ktx2" || uri.to_lowercase().ends_with(".ktx2") || uri.starts_with("data:image/ktx2") {
            let message = unsupported("KHR_texture_basisu").unwrap_or_default();
            bail!("image {i} is KTX2: {message}");
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

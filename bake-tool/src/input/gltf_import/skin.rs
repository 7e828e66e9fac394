//! Skinned meshes in their rest pose: each vertex is placed by its joints'
//! global transforms times their inverse bind matrices, weighted (glTF 2.0
//! §3.7.3.3); the node's own transform does not apply. Without this, the parts
//! of a skinned tree (wind-rigged exports) land stacked in their bind space.

use anyhow::{anyhow, bail, Result};
use glam::Mat4;

use super::accessors;

/// The global transform of every node reachable from `roots` (the first path
/// found, for nodes listed twice).
#[must_use]
pub fn node_globals(doc: &gltf::Document, roots: &[usize]) -> Vec<Option<Mat4>> {
    let nodes: Vec<gltf::Node<'_>> = doc.nodes().collect();
    let mut globals = vec![None; nodes.len()];
    let mut stack: Vec<(usize, Mat4)> = roots.iter().map(|&r| (r, Mat4::IDENTITY)).collect();
    while let Some((i, parent)) = stack.pop() {
        if globals[i].is_some() {
            continue;
        }
        let world = parent * Mat4::from_cols_array_2d(&nodes[i].transform().matrix());
        globals[i] = Some(world);
        stack.extend(nodes[i].children().map(|c| (c.index(), world)));
    }
    globals
}

/// The joint matrices of `skin` (global joint transform × inverse bind matrix).
///
/// # Errors
/// A joint outside the scene, or an inverse bind matrix accessor that is not
/// MAT4 of floats or is shorter than the joint list.
pub fn joint_matrices(skin: &gltf::Skin<'_>, buffers: &[Vec<u8>], globals: &[Option<Mat4>]) -> Result<Vec<Mat4>> {
    let what = format!("skin {}", skin.index());
    let joints: Vec<usize> = skin.joints().map(|j| j.index()).collect();
    let inverse_bind: Vec<Mat4> = match skin.inverse_bind_matrices() {
        Some(a) => {
            let role = format!("inverseBindMatrices of {what}");
            if a.dimensions() != gltf::accessor::Dimensions::Mat4 || a.data_type() != gltf::accessor::DataType::F32 {
                bail!("accessor {} ({role}) is not MAT4 of floats", a.index());
            }
            accessors::check(&a, buffers, &role)?;
            let m: Vec<Mat4> = skin
                .reader(|b| buffers.get(b.index()).map(Vec::as_slice))
                .read_inverse_bind_matrices()
                .map(|it| it.map(|m| Mat4::from_cols_array_2d(&m)).collect())
                .unwrap_or_default();
            if m.len() < joints.len() {
                bail!("{role}: {} matrices for {} joints", m.len(), joints.len());
            }
            m
        }
        None => vec![Mat4::IDENTITY; joints.len()],
    };
    joints
        .iter()
        .zip(&inverse_bind)
        .map(|(&j, ibm)| {
            let g = globals
                .get(j)
                .copied()
                .flatten()
                .ok_or_else(|| anyhow!("{what}: joint node {j} is not in the scene"))?;
            Ok(g * *ibm)
        })
        .collect()
}

/// Per vertex of `prim`, the weighted joint matrix (JOINTS_0 / WEIGHTS_0).
///
/// # Errors
/// Missing or mistyped joint and weight attributes, or a joint index beyond the skin.
pub fn vertex_matrices(
    prim: &gltf::Primitive<'_>,
    buffers: &[Vec<u8>],
    joints: &[Mat4],
    what: &str,
) -> Result<Vec<Mat4>> {
    use gltf::accessor::{DataType as D, Dimensions as N};
    let (Some(ja), Some(wa)) = (prim.get(&gltf::Semantic::Joints(0)), prim.get(&gltf::Semantic::Weights(0))) else {
        bail!("{what} is skinned but has no JOINTS_0 and WEIGHTS_0");
    };
    if ja.dimensions() != N::Vec4 || !matches!(ja.data_type(), D::U8 | D::U16) {
        bail!("accessor {} (JOINTS_0 of {what}) is not VEC4 of u8 or u16", ja.index());
    }
    let weights_ok = wa.data_type() == D::F32 || (wa.normalized() && matches!(wa.data_type(), D::U8 | D::U16));
    if wa.dimensions() != N::Vec4 || !weights_ok {
        bail!("accessor {} (WEIGHTS_0 of {what}) is not VEC4 of floats or normalized u8/u16", wa.index());
    }
    // Bounded before anything is read: as many rows as vertices, no more than a model may have.
    let n = prim.get(&gltf::Semantic::Positions).map_or(0, |a| a.count());
    if ja.count() != n || wa.count() != n || n > super::MAX_VERTICES {
        bail!(
            "{what}: {} joint and {} weight rows for {n} vertices (at most {})",
            ja.count(),
            wa.count(),
            super::MAX_VERTICES
        );
    }
    accessors::check(&ja, buffers, &format!("JOINTS_0 of {what}"))?;
    accessors::check(&wa, buffers, &format!("WEIGHTS_0 of {what}"))?;
    let reader = prim.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
    let js: Vec<[u16; 4]> = reader.read_joints(0).map(|j| j.into_u16().collect()).unwrap_or_default();
    let ws: Vec<[f32; 4]> = reader.read_weights(0).map(|w| w.into_f32().collect()).unwrap_or_default();
    js.iter()
        .zip(&ws)
        .enumerate()
        .map(|(v, (j, w))| {
            let total: f32 = w.iter().sum();
            if !(total.is_finite() && total > 0.0) {
                return Ok(Mat4::IDENTITY);
            }
            let mut m = Mat4::ZERO;
            for k in 0..4 {
                if w[k] == 0.0 {
                    continue;
                }
                let joint = joints.get(usize::from(j[k])).ok_or_else(|| {
                    anyhow!("vertex {v} of {what} names joint {} of a skin with {}", j[k], joints.len())
                })?;
                m += *joint * (w[k] / total);
            }
            Ok(m)
        })
        .collect()
}

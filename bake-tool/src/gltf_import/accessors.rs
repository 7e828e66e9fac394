//! Bounds of accessors, buffer views and buffers, checked before a read.
//!
//! The gltf crate's reader stops quietly at the end of a too-short buffer
//! view, so a hostile or broken file bakes with part of its triangles and no
//! word of it. Every accessor a primitive reads is checked here first: its
//! view lies inside its buffer, its elements (with the view's stride) inside
//! its view, and the same for sparse indices and values. The message names
//! the accessor, what reads it, and the numbers that do not fit.

use anyhow::{anyhow, bail, Result};

/// Checks that `accessor` can be read whole from `buffers`; `role` says what
/// reads it (e.g. `POSITION of mesh "tree" primitive 0`).
///
/// # Errors
/// A view outside its buffer, elements outside their view, a stride smaller
/// than an element, or a missing buffer.
pub fn check(accessor: &gltf::Accessor<'_>, buffers: &[Vec<u8>], role: &str) -> Result<()> {
    let name = format!("accessor {} ({role})", accessor.index());
    let element = accessor.size();
    let count = accessor.count();
    if count == 0 {
        bail!("{name}: count 0 (glTF requires at least 1 element)");
    }
    if let Some(view) = accessor.view() {
        let view_len = check_view(&view, buffers).map_err(|e| anyhow!("{name}: {e}"))?;
        let stride = view.stride().unwrap_or(element);
        if stride < element {
            bail!(
                "{name}: byteStride {stride} of buffer view {} is less than its {element}-byte elements",
                view.index()
            );
        }
        let need = span(accessor.offset(), count, stride, element)
            .ok_or_else(|| anyhow!("{name}: {count} elements overflow the address space"))?;
        if need > view_len {
            bail!(
                "{name}: {count} elements of {element} bytes at offset {} with stride {stride} need {need} bytes, \
                 but buffer view {} has {view_len}",
                accessor.offset(),
                view.index()
            );
        }
    }
    if let Some(sparse) = accessor.sparse() {
        let n = sparse.count();
        if n > count {
            bail!("{name}: {n} sparse values for {count} elements");
        }
        let indices = sparse.indices();
        let index_bytes = match indices.index_type() {
            gltf::accessor::sparse::IndexType::U8 => 1,
            gltf::accessor::sparse::IndexType::U16 => 2,
            gltf::accessor::sparse::IndexType::U32 => 4,
        };
        for (what, view, offset, size) in [
            ("sparse indices", indices.view(), indices.offset(), index_bytes),
            ("sparse values", sparse.values().view(), sparse.values().offset(), element),
        ] {
            let view_len = check_view(&view, buffers).map_err(|e| anyhow!("{name} {what}: {e}"))?;
            let need = span(offset, n, size, size).ok_or_else(|| anyhow!("{name}: {what} overflow"))?;
            if need > view_len {
                bail!("{name}: {n} {what} need {need} bytes, but buffer view {} has {view_len}", view.index());
            }
        }
    }
    Ok(())
}

/// Bytes from the start of a view that `count` elements at `offset` span.
fn span(offset: usize, count: usize, stride: usize, element: usize) -> Option<usize> {
    if count == 0 {
        return Some(offset);
    }
    (count - 1).checked_mul(stride)?.checked_add(element)?.checked_add(offset)
}

/// The length of a view that lies inside its buffer.
fn check_view(view: &gltf::buffer::View<'_>, buffers: &[Vec<u8>]) -> Result<usize> {
    let b = view.buffer().index();
    let buffer = buffers.get(b).ok_or_else(|| anyhow!("buffer view {} names missing buffer {b}", view.index()))?;
    let end = view.offset().checked_add(view.length());
    match end {
        Some(end) if end <= buffer.len() => Ok(view.length()),
        _ => bail!(
            "buffer view {} spans bytes {}..{} of buffer {b}, which has {}",
            view.index(),
            view.offset(),
            view.offset().saturating_add(view.length()),
            buffer.len()
        ),
    }
}

/// Checks that an attribute or index accessor has the type its semantic
/// needs (glTF 2.0 §3.7.2.1); the reader assumes it.
///
/// # Errors
/// A type or component type the semantic does not allow.
pub fn check_type(accessor: &gltf::Accessor<'_>, semantic: Option<&gltf::Semantic>, role: &str) -> Result<()> {
    use gltf::accessor::{DataType as D, Dimensions as N};
    let (dims, data) = (accessor.dimensions(), accessor.data_type());
    let normalized_or_float = matches!(data, D::F32) || (accessor.normalized() && matches!(data, D::U8 | D::U16));
    let ok = match semantic {
        None => dims == N::Scalar && matches!(data, D::U8 | D::U16 | D::U32),
        Some(gltf::Semantic::Positions | gltf::Semantic::Normals) => dims == N::Vec3 && data == D::F32,
        Some(gltf::Semantic::Tangents) => dims == N::Vec4 && data == D::F32,
        Some(gltf::Semantic::TexCoords(_)) => dims == N::Vec2 && normalized_or_float,
        Some(gltf::Semantic::Colors(_)) => matches!(dims, N::Vec3 | N::Vec4) && normalized_or_float,
        // Joints, weights and custom attributes are not read.
        Some(_) => true,
    };
    if !ok {
        bail!("accessor {} ({role}) is {dims:?} of {data:?}, which glTF does not allow there", accessor.index());
    }
    Ok(())
}

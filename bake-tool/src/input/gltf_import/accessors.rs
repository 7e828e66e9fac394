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
    // KHR_mesh_quantization: 8- and 16-bit positions and texture coordinates
    // (normalized or not), normalized signed normals.
    let quantized = matches!(data, D::F32 | D::I8 | D::U8 | D::I16 | D::U16);
    let signed_normalized = data == D::F32 || (accessor.normalized() && matches!(data, D::I8 | D::I16));
    let ok = match semantic {
        None => dims == N::Scalar && matches!(data, D::U8 | D::U16 | D::U32),
        Some(gltf::Semantic::Positions) => dims == N::Vec3 && quantized,
        Some(gltf::Semantic::Normals) => dims == N::Vec3 && signed_normalized,
        Some(gltf::Semantic::Tangents) => dims == N::Vec4 && signed_normalized,
        Some(gltf::Semantic::TexCoords(_)) => dims == N::Vec2 && quantized,
        Some(gltf::Semantic::Colors(_)) => matches!(dims, N::Vec3 | N::Vec4) && normalized_or_float,
        // Joints, weights and custom attributes are not read.
        Some(_) => true,
    };
    if !ok {
        bail!("accessor {} ({role}) is {dims:?} of {data:?}, which glTF does not allow there", accessor.index());
    }
    Ok(())
}

/// Reads an attribute accessor of `N` components as floats, whatever its
/// component type (`KHR_mesh_quantization`: 8- and 16-bit integers, normalized
/// to [0, 1] / [−1, 1] when the accessor says so, otherwise their values).
/// `None` for index-only types (u32). Stride and sparse values are the gltf
/// crate's; [`check`] has bounded them.
pub fn read_floats<const N: usize>(accessor: &gltf::Accessor<'_>, buffers: &[Vec<u8>]) -> Option<Vec<[f32; N]>>
where
    [f32; N]: gltf::accessor::Item,
    [i8; N]: gltf::accessor::Item,
    [u8; N]: gltf::accessor::Item,
    [i16; N]: gltf::accessor::Item,
    [u16; N]: gltf::accessor::Item,
{
    use gltf::accessor::{DataType as D, Dimensions, Iter};
    // The element must be what is read: a SCALAR read as VEC3 would misread
    // (and trip the gltf crate's size assertion; found by the import_gltf fuzz target).
    let dims = match N {
        2 => Dimensions::Vec2,
        3 => Dimensions::Vec3,
        4 => Dimensions::Vec4,
        _ => return None,
    };
    if accessor.dimensions() != dims {
        return None;
    }
    let get = |b: gltf::Buffer<'_>| buffers.get(b.index()).map(Vec::as_slice);
    let normalized = accessor.normalized();
    // glTF 2.0 §3.11: c / max, clamped at −1 for signed types.
    let scaled = |c: f32, max: f32| if normalized { (c / max).max(-1.0) } else { c };
    Some(match accessor.data_type() {
        D::F32 => Iter::<[f32; N]>::new(accessor.clone(), get)?.collect(),
        D::I8 => Iter::<[i8; N]>::new(accessor.clone(), get)?.map(|v| v.map(|c| scaled(f32::from(c), 127.0))).collect(),
        D::U8 => Iter::<[u8; N]>::new(accessor.clone(), get)?.map(|v| v.map(|c| scaled(f32::from(c), 255.0))).collect(),
        D::I16 => {
            Iter::<[i16; N]>::new(accessor.clone(), get)?.map(|v| v.map(|c| scaled(f32::from(c), 32767.0))).collect()
        }
        D::U16 => {
            Iter::<[u16; N]>::new(accessor.clone(), get)?.map(|v| v.map(|c| scaled(f32::from(c), 65535.0))).collect()
        }
        D::U32 => return None,
    })
}

//! FlatGeobuf: the flatgeobuf crate streams the features and verifies their
//! FlatBuffers; their geometries and property buffers are read here with
//! every index checked (the crate's own readers trust the file's lengths and
//! ring ends, and panic on hostile ones).

use std::fs::File;
use std::io::{BufReader, Read};
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use flatgeobuf::{ColumnType, GeometryType};

use super::{DeclaredCrs, Feature, Format, Geometry, Layer, Value, MAX_VERTICES};

pub(super) fn open(path: &Path) -> Result<Layer> {
    let file = File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
    let len = file.metadata().map(|m| m.len()).unwrap_or(0);
    let (header_buf, _) = read_header(&mut BufReader::new(file), len)?;
    let header = flatgeobuf::size_prefixed_root_as_header(&header_buf).expect("verified by read_header");
    let fields: Vec<String> =
        header.columns().map(|cols| cols.iter().map(|c| c.name().to_string()).collect()).unwrap_or_default();
    let mut notes = vec![format!("{:?} features", header.geometry_type())];
    let crs = match header.crs() {
        Some(crs) if crs.code() > 0 && crs.org().is_none_or(|o| o.eq_ignore_ascii_case("EPSG")) => {
            Some(DeclaredCrs::Epsg(crs.code() as u32))
        }
        Some(crs) => match crs.wkt() {
            Some(wkt) if !wkt.trim().is_empty() => Some(DeclaredCrs::read_wkt(wkt)),
            _ => None,
        },
        None => None,
    };
    if let Some(c) = &crs {
        notes.push(format!("CRS {} (header)", c.describe()));
    }
    let count = Some(header.features_count()).filter(|&n| n > 0);
    let name = header
        .name()
        .filter(|n| !n.is_empty())
        .map(str::to_string)
        .or_else(|| path.file_stem().map(|s| s.to_string_lossy().into_owned()))
        .unwrap_or_default();
    Ok(Layer {
        path: path.to_path_buf(),
        format: Format::FlatGeobuf,
        name,
        fields,
        names_cut: false,
        crs,
        count,
        notes,
        geometry_column: None,
        parsed: None,
        text_encoding: None,
    })
}

pub(super) fn pass(layer: &Layer, f: &mut dyn FnMut(Feature) -> Result<()>) -> Result<u64> {
    let file = File::open(&layer.path).with_context(|| format!("cannot open {}", layer.path.display()))?;
    let len = file.metadata().map(|m| m.len()).unwrap_or(0);
    for_each_fgb_feature(BufReader::new(file), len, f)
}

/// A feature's geometry from its (verified) FlatBuffer, every index checked:
/// the crate's own reader slices by the file's ring ends unchecked.
fn geometry(g: flatgeobuf::Geometry<'_>, default: GeometryType, depth: u32) -> Geometry {
    let kind = if g.type_() == GeometryType::Unknown { default } else { g.type_() };
    let xy: Vec<f64> = g.xy().map(|v| v.iter().collect()).unwrap_or_default();
    let z: Vec<f64> = g.z().map(|v| v.iter().collect()).unwrap_or_default();
    if xy.len() / 2 > MAX_VERTICES {
        return Geometry::Other("a geometry of more than 4 million vertices");
    }
    match kind {
        GeometryType::Point | GeometryType::MultiPoint => {
            let points: Vec<[f64; 3]> = xy
                .chunks_exact(2)
                .enumerate()
                .map(|(i, p)| [p[0], p[1], z.get(i).copied().unwrap_or(f64::NAN)])
                .collect();
            if points.is_empty() {
                Geometry::Empty
            } else {
                Geometry::Points(points)
            }
        }
        GeometryType::Polygon => {
            let n = xy.len() / 2;
            let ends: Vec<usize> = match g.ends() {
                Some(e) if !e.is_empty() => e.iter().map(|e| e as usize).collect(),
                _ => vec![n],
            };
            let mut rings = Vec::with_capacity(ends.len().min(n + 1));
            let mut start = 0usize;
            for end in ends {
                if end < start || end > n {
                    return Geometry::Other("a polygon whose ring ends lie outside its vertices");
                }
                rings.push(xy[2 * start..2 * end].chunks_exact(2).map(|p| [p[0], p[1]]).collect());
                start = end;
            }
            if rings.is_empty() || n == 0 {
                Geometry::Empty
            } else {
                Geometry::Polygons(vec![rings])
            }
        }
        GeometryType::MultiPolygon if depth == 0 => {
            let mut polygons = Vec::new();
            for part in g.parts().iter().flat_map(|p| p.iter()) {
                match geometry(part, GeometryType::Polygon, 1) {
                    Geometry::Polygons(p) => polygons.extend(p),
                    Geometry::Empty => {}
                    other => return other,
                }
            }
            if polygons.is_empty() {
                Geometry::Empty
            } else {
                Geometry::Polygons(polygons)
            }
        }
        GeometryType::LineString | GeometryType::MultiLineString => Geometry::Other("LineString"),
        _ => Geometry::Other("curve, collection or surface"),
    }
}

/// A feature's properties (FlatGeobuf's property buffer: a u16 column index,
/// then the value as the column's type says), every length checked.
fn properties(bytes: &[u8], types: &[ColumnType], values: &mut [Value]) -> Result<()> {
    let mut at = 0usize;
    let take = |at: &mut usize, n: usize| -> Result<&[u8]> {
        let end = at.checked_add(n).filter(|&e| e <= bytes.len()).context("a property runs past the feature's end")?;
        let b = &bytes[*at..end];
        *at = end;
        Ok(b)
    };
    while at < bytes.len() {
        let col = usize::from(u16::from_le_bytes(take(&mut at, 2)?.try_into().expect("2 bytes")));
        let ty = *types.get(col).with_context(|| format!("a property of column {col}, which the header lacks"))?;
        let fixed = |n: usize, at: &mut usize| -> Result<[u8; 8]> {
            let mut b = [0u8; 8];
            b[..n].copy_from_slice(take(at, n)?);
            Ok(b)
        };
        let value = match ty {
            ColumnType::Bool => Value::Bool(fixed(1, &mut at)?[0] != 0),
            ColumnType::Byte => Value::Int(i64::from(fixed(1, &mut at)?[0] as i8)),
            ColumnType::UByte => Value::Int(i64::from(fixed(1, &mut at)?[0])),
            ColumnType::Short => Value::Int(i64::from(i16::from_le_bytes(fixed(2, &mut at)?[..2].try_into()?))),
            ColumnType::UShort => Value::Int(i64::from(u16::from_le_bytes(fixed(2, &mut at)?[..2].try_into()?))),
            ColumnType::Int => Value::Int(i64::from(i32::from_le_bytes(fixed(4, &mut at)?[..4].try_into()?))),
            ColumnType::UInt => Value::Int(i64::from(u32::from_le_bytes(fixed(4, &mut at)?[..4].try_into()?))),
            ColumnType::Long => Value::Int(i64::from_le_bytes(fixed(8, &mut at)?)),
            ColumnType::ULong => {
                let v = u64::from_le_bytes(fixed(8, &mut at)?);
                i64::try_from(v).map_or_else(|_| Value::Text(v.to_string()), Value::Int)
            }
            ColumnType::Float => Value::Float(f64::from(f32::from_le_bytes(fixed(4, &mut at)?[..4].try_into()?))),
            ColumnType::Double => Value::Float(f64::from_le_bytes(fixed(8, &mut at)?)),
            ColumnType::String | ColumnType::Json | ColumnType::DateTime => {
                let len = u32::from_le_bytes(fixed(4, &mut at)?[..4].try_into()?) as usize;
                Value::Text(String::from_utf8_lossy(take(&mut at, len)?).into_owned())
            }
            _ => {
                let len = u32::from_le_bytes(fixed(4, &mut at)?[..4].try_into()?) as usize;
                take(&mut at, len)?;
                Value::Null
            }
        };
        if let Some(slot) = values.get_mut(col) {
            *slot = value;
        }
    }
    Ok(())
}

/// A FlatGeobuf's header (size-prefixed, verified) and the bytes left after it.
fn read_header<R: Read>(reader: &mut R, len: u64) -> Result<(Vec<u8>, u64)> {
    let mut head = [0u8; 12];
    reader.read_exact(&mut head).map_err(|_| anyhow!("not a FlatGeobuf (shorter than its header)"))?;
    if &head[..3] != b"fgb" || head[4..7] != *b"fgb" {
        bail!("not a FlatGeobuf (no magic bytes)");
    }
    let header_len = u64::from(u32::from_le_bytes(head[8..12].try_into().expect("4 bytes")));
    let left = len.saturating_sub(12);
    if header_len < 8 || header_len > left.min(MAX_PART_BYTES) {
        bail!("a header of {header_len} bytes in a file of {len}");
    }
    let mut header_buf = head[8..12].to_vec();
    header_buf.resize(header_len as usize + 4, 0);
    reader.read_exact(&mut header_buf[4..]).map_err(|e| anyhow!("unreadable header ({e})"))?;
    flatgeobuf::size_prefixed_root_as_header(&header_buf).map_err(|e| anyhow!("invalid header ({e})"))?;
    Ok((header_buf, left - header_len))
}

/// The bytes of a FlatGeobuf's packed R-tree index (Hilbert-packed nodes of
/// 40 bytes, `node_size` children each), or `None` past any sane size.
fn index_bytes(features: u64, node_size: u16) -> Option<u64> {
    if node_size == 0 || features == 0 {
        return Some(0);
    }
    // As the specification's packed Hilbert R-tree: levels up to and with a
    // single root (one feature has a leaf and a root).
    let node = u64::from(node_size.max(2));
    let (mut n, mut nodes) = (features, features);
    loop {
        n = n.div_ceil(node);
        nodes = nodes.checked_add(n)?;
        if n == 1 {
            break;
        }
    }
    nodes.checked_mul(40)
}

/// Streams a FlatGeobuf's features (the fuzz target's entry), `len` bytes
/// long, their values in the header's column order (the layer's fields).
/// Each feature's size is checked against what is left before anything is
/// allocated, its FlatBuffer verified, its geometry and properties read
/// with every index checked.
///
/// # Errors
/// Unreadable bytes (with the feature where they are), or `f`'s error.
pub fn for_each_fgb_feature<R: Read>(mut reader: R, len: u64, f: &mut dyn FnMut(Feature) -> Result<()>) -> Result<u64> {
    let (header_buf, mut left) = read_header(&mut reader, len)?;
    let header = flatgeobuf::size_prefixed_root_as_header(&header_buf).expect("verified by read_header");
    let types: Vec<ColumnType> =
        header.columns().map(|cols| cols.iter().map(|c| c.type_()).collect()).unwrap_or_default();
    let default = header.geometry_type();
    let index = index_bytes(header.features_count(), header.index_node_size())
        .filter(|&i| i <= left)
        .with_context(|| format!("an index of {} features larger than the file", header.features_count()))?;
    std::io::copy(&mut (&mut reader).take(index), &mut std::io::sink())
        .map_err(|e| anyhow!("unreadable index ({e})"))?;
    left -= index;
    let mut buf = Vec::new();
    let mut count = 0u64;
    while left > 0 {
        let index = count + 1;
        let mut size = [0u8; 4];
        reader.read_exact(&mut size).map_err(|e| anyhow!("feature {index}: unreadable ({e})"))?;
        let n = u64::from(u32::from_le_bytes(size));
        left = left.saturating_sub(4);
        if n > left || n > MAX_PART_BYTES {
            bail!("feature {index}: says it is {n} bytes, the file has {left} left");
        }
        buf.clear();
        buf.extend_from_slice(&size);
        buf.resize(n as usize + 4, 0);
        reader.read_exact(&mut buf[4..]).map_err(|e| anyhow!("feature {index}: unreadable ({e})"))?;
        left -= n;
        let fbs = flatgeobuf::size_prefixed_root_as_feature(&buf)
            .map_err(|e| anyhow!("feature {index}: invalid FlatBuffer ({e})"))?;
        let geometry = fbs.geometry().map_or(Geometry::Empty, |g| geometry(g, default, 0));
        let mut values = vec![Value::Null; types.len()];
        if let Some(p) = fbs.properties() {
            properties(p.bytes(), &types, &mut values).with_context(|| format!("feature {index}"))?;
        }
        count = index;
        f(Feature { index, geometry, values })?;
    }
    Ok(count)
}

/// The largest header or feature read (a FlatGeobuf feature is one tree or
/// one stand; 256 MiB is far past either).
const MAX_PART_BYTES: u64 = 256 << 20;

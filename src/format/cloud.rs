//! Billboard clouds with multi-layer indirect texturing (García et al. 2007): the `CLDA`
//! section's records and the cloud's metadata.
//!
//! A cloud replaces a tree's leaves by a few dozen planes fitted to the
//! foliage. Each plane carries a grid of cells (the paper's Hash Texture); a
//! cell lists the leaves whose projection overlaps it, front to back along the
//! plane's normal (the Lists Texture); a list entry maps the plane's
//! coordinates to the leaf's own texture coordinates, so the leaf is drawn from
//! the material texture (the Leaves Texture) at its exact place, orientation
//! and size. A cell also holds the average of its leaves (the low-resolution
//! texture), which the shader uses for the entries it skips at a distance.
//!
//! All records are little-endian u32 words in one section, uploaded to one
//! storage buffer as they are: planes, then cells, then fragments. Layout
//! tables: `docs/FORMAT.md`.

use half::f16;
use serde::{Deserialize, Serialize};

use super::error::{finite, finite_all, Problem};
use super::mesh::MeshLevelMeta;

/// Words per plane record.
pub const PLANE_WORDS: usize = 16;
/// Words per cell record.
pub const CELL_WORDS: usize = 3;
/// Words per fragment (list entry) record.
pub const FRAGMENT_WORDS: usize = 10;
/// Most cells a plane may have per side.
pub const MAX_GRID: u32 = 256;
/// Most fragments one cell may list (its count is 8 bits).
pub const MAX_CELL_FRAGMENTS: u32 = 255;
/// Most fragments a cloud may hold (a cell's first fragment is 24 bits).
pub const MAX_FRAGMENTS: u32 = 1 << 24;
/// Most `CLDA` words (64 MiB: within WebGPU's default 128 MiB storage binding).
pub const MAX_WORDS: u64 = 16 << 20;

/// The billboard cloud of a pack (`META.cloud`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CloudMeta {
    /// Planes (records at the start of `CLDA`).
    pub planes: u32,
    /// Cells of all planes.
    pub cells: u32,
    /// List entries of all cells.
    pub fragments: u32,
    /// The index of the `cloud` material the planes' quads use.
    pub material: u32,
    /// The cloud is drawn while the tree's projected height is at least this
    /// many pixels (below the coarsest mesh level's threshold).
    pub select_px: f32,
    /// The cloud's geometry: the coarsest mesh level's wood and one quad per
    /// plane (`CLVX`, `CLIX`; `select_px` as above).
    pub mesh: MeshLevelMeta,
    /// The bake's LoD policy measurement (`crate::lod::policy::policy_keeps`):
    /// the cloud's and the far tier's error against the full mesh at
    /// `select_px`. Without it the cloud is not a default tier.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pareto_error: Option<[f32; 2]>,
    /// The same draws' modelled GPU time per tree (µs), the cloud's and the far
    /// tier's (`crate::lod::policy`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pareto_cost: Option<[f32; 2]>,
}

impl CloudMeta {
    /// Words of the `CLDA` section.
    #[must_use]
    pub fn words(&self) -> u64 {
        u64::from(self.planes) * PLANE_WORDS as u64
            + u64::from(self.cells) * CELL_WORDS as u64
            + u64::from(self.fragments) * FRAGMENT_WORDS as u64
    }
}

/// One plane as the bake builds it (model space, metres at scale 1). A point
/// of the plane is `origin + s·axis_s + t·axis_t` for (s, t) in [0, 1]².
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CloudPlane {
    /// Corner at (s, t) = (0, 0).
    pub origin: [f32; 3],
    /// Edge along s (its full length).
    pub axis_s: [f32; 3],
    /// Edge along t.
    pub axis_t: [f32; 3],
    /// Unit normal; lists run front to back along it.
    pub normal: [f32; 3],
    /// First cell of the plane's grid (row-major, `grid[0]` cells a row).
    pub first_cell: u32,
    /// Cells along s and t.
    pub grid: [u32; 2],
}

/// One grid cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CloudCell {
    /// First fragment of the cell's list.
    pub first: u32,
    /// Fragments in the list (≤ 255).
    pub count: u32,
    /// Average of the cell's leaves: sRGB colour and coverage (0–255).
    pub average: [u8; 4],
    /// Their mean normal (octahedral snorm8 x, y), model space.
    pub normal_oct: [i8; 2],
    /// Their mean own occlusion (sky visibility 0–255).
    pub ao: u8,
}

/// One list entry: a leaf as seen on a plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CloudFragment {
    /// Leaf texture coordinates from plane coordinates:
    /// `uv = (a[0]·s + a[1]·t + b[0], a[2]·s + a[3]·t + b[1])`.
    pub a: [f32; 4],
    /// Offset of the map.
    pub b: [f32; 2],
    /// The leaf's texture rectangle (min u, min v, max u, max v): outside it
    /// the entry is transparent.
    pub uv_rect: [f32; 4],
    /// The leaf's material.
    pub material: u16,
    /// The leaf's normal (octahedral snorm8 x, y), model space.
    pub normal_oct: [i8; 2],
    /// Linear vertex colour (RGB bytes) and own occlusion (sky visibility 0–255).
    pub color_ao: [u8; 4],
}

fn pack16(lo: u32, hi: u32) -> u32 {
    (lo & 0xffff) | (hi << 16)
}

fn h(v: f32) -> u32 {
    u32::from(f16::from_f32(v).to_bits())
}

fn from_h(bits: u32) -> f32 {
    f16::from_bits((bits & 0xffff) as u16).to_f32()
}

/// Encodes planes, cells and fragments into `CLDA` words.
#[must_use]
pub fn encode_cloud(planes: &[CloudPlane], cells: &[CloudCell], fragments: &[CloudFragment]) -> Vec<u32> {
    let mut w =
        Vec::with_capacity(planes.len() * PLANE_WORDS + cells.len() * CELL_WORDS + fragments.len() * FRAGMENT_WORDS);
    for p in planes {
        w.extend(p.origin.map(f32::to_bits));
        w.push(p.first_cell);
        w.extend(p.axis_s.map(f32::to_bits));
        w.push(p.grid[0]);
        w.extend(p.axis_t.map(f32::to_bits));
        w.push(p.grid[1]);
        w.extend(p.normal.map(f32::to_bits));
        w.push(0);
    }
    for c in cells {
        w.push((c.first & 0x00ff_ffff) | (c.count.min(MAX_CELL_FRAGMENTS) << 24));
        w.push(u32::from_le_bytes(c.average));
        w.push(u32::from_le_bytes([c.normal_oct[0] as u8, c.normal_oct[1] as u8, c.ao, 0]));
    }
    for f in fragments {
        w.extend(f.a.map(f32::to_bits));
        w.extend(f.b.map(f32::to_bits));
        w.push(pack16(h(f.uv_rect[0]), h(f.uv_rect[1])));
        w.push(pack16(h(f.uv_rect[2]), h(f.uv_rect[3])));
        w.push(u32::from(f.material) | u32::from(f.normal_oct[0] as u8) << 16 | u32::from(f.normal_oct[1] as u8) << 24);
        w.push(u32::from_le_bytes(f.color_ao));
    }
    w
}

/// A decoded cloud (for tests and tools).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DecodedCloud {
    /// Planes.
    pub planes: Vec<CloudPlane>,
    /// Cells.
    pub cells: Vec<CloudCell>,
    /// Fragments.
    pub fragments: Vec<CloudFragment>,
}

/// Decodes `CLDA` words laid out as `meta` says (lengths not checked: see [`validate_cloud`]).
#[must_use]
pub fn decode_cloud(meta: &CloudMeta, words: &[u32]) -> DecodedCloud {
    let f = |w: &[u32]| [f32::from_bits(w[0]), f32::from_bits(w[1]), f32::from_bits(w[2])];
    let np = meta.planes as usize;
    let nc = meta.cells as usize;
    let planes_end = np * PLANE_WORDS;
    let cells_end = planes_end + nc * CELL_WORDS;
    let planes = words[..planes_end.min(words.len())]
        .chunks_exact(PLANE_WORDS)
        .map(|p| CloudPlane {
            origin: f(&p[0..3]),
            first_cell: p[3],
            axis_s: f(&p[4..7]),
            grid: [p[7], p[11]],
            axis_t: f(&p[8..11]),
            normal: f(&p[12..15]),
        })
        .collect();
    let cells = words[planes_end.min(words.len())..cells_end.min(words.len())]
        .chunks_exact(CELL_WORDS)
        .map(|c| {
            let n = c[2].to_le_bytes();
            CloudCell {
                first: c[0] & 0x00ff_ffff,
                count: c[0] >> 24,
                average: c[1].to_le_bytes(),
                normal_oct: [n[0] as i8, n[1] as i8],
                ao: n[2],
            }
        })
        .collect();
    let fragments = words[cells_end.min(words.len())..]
        .chunks_exact(FRAGMENT_WORDS)
        .map(|w| CloudFragment {
            a: [w[0], w[1], w[2], w[3]].map(f32::from_bits),
            b: [f32::from_bits(w[4]), f32::from_bits(w[5])],
            uv_rect: [from_h(w[6]), from_h(w[6] >> 16), from_h(w[7]), from_h(w[7] >> 16)],
            material: (w[8] & 0xffff) as u16,
            normal_oct: [(w[8] >> 16) as u8 as i8, (w[8] >> 24) as u8 as i8],
            color_ao: w[9].to_le_bytes(),
        })
        .collect();
    DecodedCloud { planes, cells, fragments }
}

/// Checks a `CLDA` section against `meta`: at least one plane and at most
/// [`MAX_WORDS`], its length, every plane's grid inside the cells, every cell's
/// list inside the fragments, every fragment's material below `materials`,
/// finite floats. With the quads' plane ids checked against `planes` (the
/// pack's validation) the shader reads only inside the buffer.
///
/// # Errors
/// The first problem found.
pub fn validate_cloud(meta: &CloudMeta, data: &[u8], materials: usize) -> Result<(), Problem> {
    if meta.fragments > MAX_FRAGMENTS {
        return Err(Problem::OutOfRange {
            what: "META.cloud.fragments".into(),
            value: meta.fragments.into(),
            allowed: format!("at most {MAX_FRAGMENTS}"),
        });
    }
    finite("META.cloud.select_px", meta.select_px.into())?;
    if meta.planes == 0 || meta.words() > MAX_WORDS {
        return Err(Problem::Invalid(format!(
            "META.cloud has {} planes and {} words (need 1 or more planes, at most {MAX_WORDS} words)",
            meta.planes,
            meta.words()
        )));
    }
    if meta.material as usize >= materials {
        return Err(Problem::OutOfRange {
            what: "META.cloud.material".into(),
            value: meta.material.into(),
            allowed: format!("less than {materials} materials"),
        });
    }
    if data.len() as u64 != meta.words() * 4 {
        return Err(Problem::Invalid(format!(
            "META.cloud declares {} planes, {} cells and {} fragments ({} bytes), the CLDA section holds {} bytes",
            meta.planes,
            meta.cells,
            meta.fragments,
            meta.words() * 4,
            data.len()
        )));
    }
    let words: Vec<u32> = data.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
    let cloud = decode_cloud(meta, &words);
    for (i, p) in cloud.planes.iter().enumerate() {
        let what = format!("CLDA plane[{i}]");
        for v in [p.origin, p.axis_s, p.axis_t, p.normal] {
            finite_all(&what, &v)?;
        }
        let [gw, gh] = p.grid;
        if !(1..=MAX_GRID).contains(&gw) || !(1..=MAX_GRID).contains(&gh) {
            return Err(Problem::Invalid(format!("{what} has a {gw}×{gh} grid (1–{MAX_GRID} cells a side)")));
        }
        let end = u64::from(p.first_cell) + u64::from(gw) * u64::from(gh);
        if end > u64::from(meta.cells) {
            return Err(Problem::Invalid(format!("{what} covers cells {}..{end} of {}", p.first_cell, meta.cells)));
        }
    }
    for (i, c) in cloud.cells.iter().enumerate() {
        if u64::from(c.first) + u64::from(c.count) > u64::from(meta.fragments) {
            return Err(Problem::Invalid(format!(
                "CLDA cell[{i}] lists fragments {}..{} of {}",
                c.first,
                c.first + c.count,
                meta.fragments
            )));
        }
    }
    for (i, f) in cloud.fragments.iter().enumerate() {
        let what = format!("CLDA fragment[{i}]");
        finite_all(&what, &f.a)?;
        finite_all(&what, &f.b)?;
        finite_all(&what, &f.uv_rect)?;
        if usize::from(f.material) >= materials {
            return Err(Problem::OutOfRange {
                what: format!("{what}.material"),
                value: f.material.into(),
                allowed: format!("less than {materials} materials"),
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> (CloudMeta, Vec<u32>) {
        let planes = [CloudPlane {
            origin: [0.0, 1.0, 2.0],
            axis_s: [1.0, 0.0, 0.0],
            axis_t: [0.0, 0.0, 2.0],
            normal: [0.0, -1.0, 0.0],
            first_cell: 0,
            grid: [2, 1],
        }];
        let cells = [
            CloudCell { first: 0, count: 1, average: [10, 20, 30, 128], normal_oct: [-5, 7], ao: 200 },
            CloudCell { first: 1, count: 0, average: [0; 4], normal_oct: [0, 0], ao: 0 },
        ];
        let fragments = [CloudFragment {
            a: [4.0, 0.5, -0.25, 8.0],
            b: [-1.5, 0.75],
            uv_rect: [0.0, 0.25, 1.0, 0.5],
            material: 1,
            normal_oct: [-127, 64],
            color_ao: [255, 128, 0, 99],
        }];
        let meta = CloudMeta {
            planes: 1,
            cells: 2,
            fragments: 1,
            material: 2,
            select_px: 40.0,
            mesh: MeshLevelMeta {
                vertex_count: 0,
                index_count: 0,
                pos_min: [0.0; 3],
                pos_max: [1.0; 3],
                uv_min: [0.0; 2],
                uv_max: [1.0; 2],
                draws: Vec::new(),
                select_px: 40.0,
                policy_px: None,
                variants: 0,
            },
            pareto_error: None,
            pareto_cost: None,
        };
        let words = encode_cloud(&planes, &cells, &fragments);
        assert_eq!(
            decode_cloud(&meta, &words),
            DecodedCloud { planes: planes.to_vec(), cells: cells.to_vec(), fragments: fragments.to_vec() }
        );
        (meta, words)
    }

    #[test]
    fn records_round_trip_and_validate() {
        let (meta, words) = sample();
        assert_eq!(words.len() as u64, meta.words());
        let bytes: Vec<u8> = bytemuck::cast_slice(&words).to_vec();
        validate_cloud(&meta, &bytes, 3).unwrap();
    }

    #[test]
    fn hostile_records_are_refused() {
        let (meta, words) = sample();
        let check = |words: &[u32], materials: usize| {
            validate_cloud(&meta, bytemuck::cast_slice(words), materials).map_err(|e| e.to_string())
        };
        assert!(check(&words, 1).unwrap_err().contains("material"));
        assert!(check(&words[..words.len() - 1], 3).unwrap_err().contains("CLDA section holds"));
        let mut grid = words.clone();
        grid[7] = 3; // 3×1 cells from cell 0 of 2
        assert!(check(&grid, 3).unwrap_err().contains("covers cells"));
        grid[7] = 0;
        assert!(check(&grid, 3).unwrap_err().contains("grid"));
        let mut list = words.clone();
        list[PLANE_WORDS + CELL_WORDS] = 1 | (1 << 24); // cell 1 lists fragment 1 of 1
        assert!(check(&list, 3).unwrap_err().contains("lists fragments"));
        let mut nan = words.clone();
        nan[PLANE_WORDS + 2 * CELL_WORDS] = f32::NAN.to_bits();
        assert!(check(&nan, 3).is_err());
        let mut origin = words;
        origin[0] = f32::INFINITY.to_bits();
        assert!(check(&origin, 3).is_err());
        // No planes (an empty storage binding), or more words than a binding holds.
        let empty = CloudMeta { planes: 0, cells: 0, fragments: 0, ..meta.clone() };
        assert!(validate_cloud(&empty, &[], 3).unwrap_err().to_string().contains("planes"));
        let huge = CloudMeta { fragments: MAX_WORDS as u32 / 10 + 1, ..meta.clone() };
        assert!(validate_cloud(&huge, &[], 3).unwrap_err().to_string().contains("words"));
    }
}

//! LoD packs (`species/<name>.pack`): every level of detail of one species.
//!
//! A pack is a header, a section table and sections aligned to
//! [`PACK_SECTION_ALIGN`] bytes, so each section can be handed to
//! `queue.write_buffer` / `queue.write_texture` as it is. The `META` section is
//! JSON ([`PackMeta`]) describing the levels; binary sections hold vertices,
//! indices and texture arrays. Readers skip section kinds they do not know in
//! a version 1 pack, which is how later levels (ellipsoids, lines) were added
//! without breaking older readers; a stored pack (version 2, each part
//! deflated: [`crate::format::stored`]) places every section in a part.
//! Layout tables: `docs/FORMAT.md`.
//!
//! One file for one format (about 670 lines): the header, section table, metadata,
//! the head/parts split a viewer fetches by range and the encoder and decoder
//! must stay side by side, so a change to the layout is made in one place.

use serde::{Deserialize, Serialize};

use super::error::{at_most, finite, finite_all, DecodeError, Problem, Reader};
pub use super::mesh::{
    ao_from_snorm8, ao_to_snorm8, variant_of, DrawRange, MaterialKind, MaterialMeta, MeshLevelMeta, MeshVertex,
    VariantVertex, MAX_VARIANTS,
};
use super::mesh::{mesh_meta_finite, validate_mesh, validate_variants};

/// First four bytes of a pack file.
pub const PACK_MAGIC: [u8; 4] = *b"SYPK";
/// Pack format version of a pack whose sections lie in the file as they are
/// (what [`encode_pack`] writes; read by this build).
pub const PACK_VERSION: u16 = 1;
/// Pack format version of a *stored* pack: the same head, then each
/// [`PackPart`] deflated as one block ([`StoredBlock`], the `STOR` section);
/// what a bake writes to a scene (read by this build; `crate::format::stored`).
pub const PACK_VERSION_STORED: u16 = 2;
/// Bytes per `STOR` entry.
pub const STORED_BLOCK_BYTES: u64 = 32;
/// Bytes in the pack header.
pub const PACK_HEADER_BYTES: usize = 32;
/// Bytes per section-table entry.
pub const PACK_SECTION_ENTRY_BYTES: usize = 32;
/// Alignment of every section's offset (covers GPU buffer offset and copy alignments).
pub const PACK_SECTION_ALIGN: u64 = 256;
/// Most sections a pack may declare.
pub const MAX_PACK_SECTIONS: u32 = 4096;
/// Largest texture side a pack may declare (WebGPU's default `max_texture_dimension_2d`).
pub const MAX_TEXTURE_SIZE: u32 = 8192;
/// Most layers a texture array may declare (WebGPU's default `max_texture_array_layers`).
pub const MAX_TEXTURE_LAYERS: u32 = 256;

/// Section kinds (FourCC).
pub mod kind {
    /// JSON metadata ([`super::PackMeta`]).
    pub const META: [u8; 4] = *b"META";
    /// A stored pack's blocks ([`super::StoredBlock`] × count, stride 32),
    /// the second section, right after `META`: part of the head.
    pub const STORED: [u8; 4] = *b"STOR";
    /// Mesh vertices ([`super::MeshVertex`]) of level `index`.
    pub const MESH_VERTICES: [u8; 4] = *b"MVTX";
    /// Mesh indices (u32) of level `index`.
    pub const MESH_INDICES: [u8; 4] = *b"MIDX";
    /// The other variants' vertices ([`super::VariantVertex`]) of mesh level
    /// `index` (`META.mesh_levels[index].variants` of them). Optional.
    pub const MESH_VARIANTS: [u8; 4] = *b"MVAR";
    /// Material texture array, RGBA8, mip-major.
    pub const MATERIAL_TEXTURES: [u8; 4] = *b"MTEX";
    /// Billboard colour+alpha array, RGBA8 (sRGB), mip-major.
    pub const BILLBOARD_COLOR: [u8; 4] = *b"BBCO";
    /// Billboard normal (xyz) + leaf flag (w) array, RGBA8, mip-major.
    pub const BILLBOARD_NORMAL: [u8; 4] = *b"BBNO";
    /// Billboard ambient occlusion (the tree's own sky visibility), R8, mip-major.
    /// Optional: a pack without it draws its billboards unoccluded.
    pub const BILLBOARD_AO: [u8; 4] = *b"BBAO";
    /// The tree's own ambient occlusion field ([`AoFieldRef`]): a grid of sky
    /// visibility that ellipsoids and lines sample where a ray hits them. Optional.
    pub const AO_FIELD: [u8; 4] = *b"AOFD";
    /// Multi-view impostor colour+alpha array ([`super::ImpostorMeta`]), RGBA8
    /// (sRGB), one layer per hemi-octahedral view, mip-major. Optional.
    pub const IMPOSTOR_COLOR: [u8; 4] = *b"IMCO";
    /// Multi-view impostor surface array, RGBA8, mip-major: octahedral normal
    /// (r, g), depth (b: −radius … +radius towards the view as 0 … 1) and
    /// occlusion with the leaf flag (a: leaf ? ½ + ½·ao : ½·ao).
    pub const IMPOSTOR_SURFACE: [u8; 4] = *b"IMSF";
    /// Ellipsoid records of one cluster level (`index` = level), 24 bytes each.
    pub const ELLIPSOIDS: [u8; 4] = *b"ELPS";
    /// Line records of one cluster level (`index` = level), 16 bytes each.
    pub const LINES: [u8; 4] = *b"LINE";
    /// Billboard cloud geometry ([`super::MeshVertex`]): the coarsest mesh
    /// level's wood and one quad per plane (García et al. 2007). Optional.
    pub const CLOUD_VERTICES: [u8; 4] = *b"CLVX";
    /// Billboard cloud indices (u32).
    pub const CLOUD_INDICES: [u8; 4] = *b"CLIX";
    /// Billboard cloud planes, cells and list entries (u32 words,
    /// [`crate::format::cloud`]).
    pub const CLOUD_DATA: [u8; 4] = *b"CLDA";
    /// The far tiers' kinds: the sections a deciduous species has a second
    /// state of (index 1, the bare wood; `META.season.bare_far`).
    pub const FAR_TIERS: [[u8; 4]; 5] =
        [BILLBOARD_COLOR, BILLBOARD_NORMAL, BILLBOARD_AO, IMPOSTOR_COLOR, IMPOSTOR_SURFACE];
}

/// A far-tier texel (billboard normal alpha, impostor surface flag, 0–255) is a leaf above this.
pub const LEAF_FLAG_MIN: u8 = 191;

/// Bytes of the `AOFD` section's header.
pub const AO_FIELD_HEADER_BYTES: usize = 32;
/// Most cells along one side of an `AOFD` grid (WebGPU's 3D texture limit is 2048).
pub const MAX_AO_FIELD_CELLS: u32 = 256;

/// The `AOFD` section: a tree's own sky visibility on a grid (model space,
/// scale 1). Header (little endian): cells along x, y, z (u32 × 3), the centre
/// of cell (0, 0, 0) (f32 × 3), the cell side (f32), 0 (u32); then one byte per
/// cell (0–255 = visibility 0–1), x fastest, then y, then z.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AoFieldRef<'a> {
    /// Cells along x, y, z.
    pub dims: [u32; 3],
    /// Centre of cell (0, 0, 0).
    pub origin: [f32; 3],
    /// Side of a cell.
    pub cell: f32,
    /// One byte per cell.
    pub cells: &'a [u8],
}

impl<'a> AoFieldRef<'a> {
    /// Reads and checks a section.
    ///
    /// # Errors
    /// A header that does not match the bytes, dimensions of 0 or over
    /// [`MAX_AO_FIELD_CELLS`], non-finite or non-positive geometry.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, Problem> {
        let r = Reader::new(bytes);
        let dims = [r.u32("AOFD.dims", 0)?, r.u32("AOFD.dims", 4)?, r.u32("AOFD.dims", 8)?];
        let f = |at| r.u32("AOFD", at).map(f32::from_bits);
        let origin = [f(12)?, f(16)?, f(20)?];
        let cell = f(24)?;
        let reserved = r.u32("AOFD.reserved", 28)?;
        if reserved != 0 {
            return Err(Problem::Invalid(format!("AOFD.reserved is {reserved}, must be 0")));
        }
        finite_all("AOFD.origin", &origin)?;
        finite("AOFD.cell", cell.into())?;
        if cell <= 0.0 {
            return Err(Problem::Invalid(format!("AOFD.cell is {cell}, must be positive")));
        }
        for d in dims {
            if d == 0 || d > MAX_AO_FIELD_CELLS {
                return Err(Problem::OutOfRange {
                    what: "AOFD.dims".into(),
                    value: d.into(),
                    allowed: format!("1–{MAX_AO_FIELD_CELLS}"),
                });
            }
        }
        let n = dims.iter().map(|d| *d as usize).product::<usize>();
        if bytes.len() != AO_FIELD_HEADER_BYTES + n {
            return Err(Problem::Invalid(format!(
                "AOFD holds {} bytes, its {}×{}×{} grid needs {}",
                bytes.len(),
                dims[0],
                dims[1],
                dims[2],
                AO_FIELD_HEADER_BYTES + n
            )));
        }
        Ok(Self { dims, origin, cell, cells: &bytes[AO_FIELD_HEADER_BYTES..] })
    }

    /// The section's bytes for a grid.
    #[must_use]
    pub fn encode(dims: [u32; 3], origin: [f32; 3], cell: f32, cells: &[u8]) -> Vec<u8> {
        let mut out = Vec::with_capacity(AO_FIELD_HEADER_BYTES + cells.len());
        for d in dims {
            out.extend_from_slice(&d.to_le_bytes());
        }
        for v in origin {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&cell.to_le_bytes());
        out.extend_from_slice(&0u32.to_le_bytes());
        out.extend_from_slice(cells);
        out
    }
}

/// A texture array stored in a section.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TextureArrayMeta {
    /// Width and height of mip 0.
    pub size: u32,
    /// Array layers.
    pub layers: u32,
    /// Mip levels stored (mip 0 included).
    pub mips: u32,
    /// How the texels are stored when not one RGBA8 (or R8) texel after
    /// another: `"bc7"` or `"etc2"`, 4 × 4 texel blocks of 16 bytes (a pack's
    /// block-compressed variant, [`TexelEncoding`]). Absent: plain texels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub encoding: Option<TexelEncoding>,
}

/// A GPU block encoding of an RGBA texture array.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TexelEncoding {
    /// BC7 (BPTC): 16 bytes per 4 × 4 block, RGBA, sampled by GPUs with
    /// `texture-compression-bc` (desktop adapters).
    Bc7,
    /// ETC2 RGBA8 (ETC2 colour with EAC alpha): 16 bytes per 4 × 4 block —
    /// the 8-byte EAC alpha block, then the 8-byte colour block, each a
    /// big-endian 64-bit word — sampled by GPUs with `texture-compression-etc2`
    /// (phones and tablets, Apple silicon).
    Etc2,
}

impl PackMeta {
    /// The block encodings of its texture arrays (none for a plain pack).
    #[must_use]
    pub fn encodings(&self) -> Vec<TexelEncoding> {
        let arrays = [
            self.material_texture,
            self.billboards.as_ref().map(|b| b.texture),
            self.impostors.as_ref().map(|i| i.texture),
        ];
        let mut out: Vec<TexelEncoding> = arrays.iter().flatten().filter_map(|t| t.encoding).collect();
        out.dedup();
        out
    }

    /// The first block encoding of its texture arrays that is not among
    /// `sampled` (what a device samples): such a pack cannot be uploaded there.
    #[must_use]
    pub fn unsampled(&self, sampled: &[TexelEncoding]) -> Option<TexelEncoding> {
        self.encodings().into_iter().find(|e| !sampled.contains(e))
    }
}

impl TexelEncoding {
    /// The name in the manifest's and `META`'s JSON.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            TexelEncoding::Bc7 => "bc7",
            TexelEncoding::Etc2 => "etc2",
        }
    }
}

impl TextureArrayMeta {
    /// Plain texels (no block encoding).
    #[must_use]
    pub fn plain(size: u32, layers: u32, mips: u32) -> Self {
        Self { size, layers, mips, encoding: None }
    }

    /// Bytes of the whole RGBA8 array with all its mips.
    #[must_use]
    pub fn byte_len(&self) -> u64 {
        self.byte_len_of(4)
    }

    /// Bytes of the whole array with all its mips at `texel_bytes` per texel
    /// (or, block-encoded, at its blocks' bytes).
    #[must_use]
    pub fn byte_len_of(&self, texel_bytes: u64) -> u64 {
        (0..self.mips).map(|m| self.mip_bytes(m, texel_bytes) * u64::from(self.layers)).sum()
    }

    /// Bytes of one layer of mip `m`: its texels, or its 4 × 4 blocks (a
    /// mip smaller than a block takes a whole one).
    #[must_use]
    pub fn mip_bytes(&self, m: u32, texel_bytes: u64) -> u64 {
        let s = u64::from((self.size >> m).max(1));
        match self.encoding {
            None => s * s * texel_bytes,
            Some(TexelEncoding::Bc7 | TexelEncoding::Etc2) => s.div_ceil(4).pow(2) * 16,
        }
    }

    /// Byte offset of mip `m` within the section (mips are stored one after another,
    /// each holding all layers) at `texel_bytes` per texel.
    #[must_use]
    pub fn mip_offset(&self, m: u32, texel_bytes: u64) -> u64 {
        TextureArrayMeta { mips: m, ..*self }.byte_len_of(texel_bytes)
    }
}

/// The view-angle billboard array (Eichner 2024, §3.3, alg. 3.1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BillboardMeta {
    /// Elevation angles, evenly spaced over 0–90° (layer = azimuth * angles + elevation).
    pub angles: u32,
    /// Azimuths around the tree (1 = one image per elevation).
    pub azimuths: u32,
    /// The colour and normal arrays' layout.
    pub texture: TextureArrayMeta,
    /// Centre of the capture box (model space, metres at scale 1).
    pub center: [f32; 3],
    /// Half width of each billboard quad, metres at scale 1.
    pub half_width: f32,
    /// Half height of each billboard quad, metres at scale 1.
    pub half_height: f32,
    /// Billboards are drawn while the projected tree height is below the finest
    /// mesh level's `select_px` and at least this (0: to the draw distance).
    pub select_px: f32,
    /// The mesh variants captured (absent: 1, variant 0's): the layers of
    /// variant v are `v × angles × azimuths` on, and a tree draws its mesh
    /// variant's (`variant_of`). Either 1 or mesh level 0's variants + 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub variants: Option<u32>,
}

/// Multi-view impostors: the tree rendered orthographically from the vertices
/// of a `grid`×`grid` hemi-octahedral grid of directions over the upper
/// hemisphere, each view framing the bounding sphere (`center`, `radius`).
/// The viewer blends the three views nearest the eye per pixel, reprojected
/// with each view's depth (`shaders/impostor.wgsl`); layer = row · grid + column.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImpostorMeta {
    /// Views per side of the hemi-octahedral grid (2–16).
    pub grid: u32,
    /// The colour and surface arrays' layout (grid² layers).
    pub texture: TextureArrayMeta,
    /// Centre of the bounding sphere (model space, metres at scale 1).
    pub center: [f32; 3],
    /// Its radius: every view's half extent, and the depth range's half.
    pub radius: f32,
    /// Per mip (mip 0 first): the coverage-weighted mean length of the texels'
    /// mean normal (0–1), how much the normals a texel covers agree; the
    /// viewer shades filtered normals with it. Empty in older packs (1).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub normal_length: Vec<f32>,
    /// Half extents of the box about `center` the views show (the captured
    /// tree's: variant 0's of a pack with variants, whose `bounds_*` hold them
    /// all). Absent: the box of `bounds_*` about `center`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub half_extent: Option<[f32; 3]>,
    /// The mesh variants captured (absent: 1, variant 0's): the views of
    /// variant v are layers `v × grid²` on, and a tree draws its mesh
    /// variant's (`variant_of`). Either 1 or mesh level 0's variants + 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub variants: Option<u32>,
}

/// The `META` section of a pack.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PackMeta {
    /// Species name.
    pub name: String,
    /// Tree height at scale 1, metres.
    pub height_m: f32,
    /// Model-space bounds at scale 1 (Z up, trunk base at the origin).
    pub bounds_min: [f32; 3],
    /// Upper model-space bounds.
    pub bounds_max: [f32; 3],
    /// Materials.
    pub materials: Vec<MaterialMeta>,
    /// Material texture array, if any material is textured.
    pub material_texture: Option<TextureArrayMeta>,
    /// Mesh levels, finest first.
    pub mesh_levels: Vec<MeshLevelMeta>,
    /// Billboard array, if baked.
    pub billboards: Option<BillboardMeta>,
    /// Clustered-ellipsoid and line levels (Clasen et al. 2010), if baked.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clusters: Option<super::cluster::ClusterMeta>,
    /// Multi-view impostors of the far field, if baked (drawn instead of the
    /// billboards where both are present, unless a viewer asks for billboards).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub impostors: Option<ImpostorMeta>,
    /// The billboard cloud (García et al. 2007), if baked.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cloud: Option<super::cloud::CloudMeta>,
    /// A deciduous species' seasons (leaf-on, autumn, leaf-off); absent for
    /// an evergreen, which looks the same all year.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub season: Option<SeasonMeta>,
}

/// A deciduous tree's seasons (a pack's [`SeasonMeta`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub enum Season {
    /// In leaf (what every tier is baked in).
    #[default]
    LeafOn,
    /// The leaves in their autumn colour.
    Autumn,
    /// Bare wood: no leaves, the far tiers' bare captures.
    LeafOff,
}

impl Season {
    /// Every season, in the year's order from spring.
    pub const ALL: [Season; 3] = [Season::LeafOn, Season::Autumn, Season::LeafOff];

    /// Its name (`leaf-on`, `autumn`, `leaf-off`), as `--season` and `setSeason` take it.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Season::LeafOn => "leaf-on",
            Season::Autumn => "autumn",
            Season::LeafOff => "leaf-off",
        }
    }

    /// The state code the tree passes read (`DrawParams.season.w`).
    #[must_use]
    pub fn code(self) -> f32 {
        match self {
            Season::LeafOn => 0.0,
            Season::Autumn => 1.0,
            Season::LeafOff => 2.0,
        }
    }
}

impl std::str::FromStr for Season {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let folded = s.trim().to_ascii_lowercase().replace(['_', ' '], "-");
        match folded.as_str() {
            "leaf-on" | "leafon" | "summer" | "spring" | "on" => Ok(Season::LeafOn),
            "autumn" | "fall" => Ok(Season::Autumn),
            "leaf-off" | "leafoff" | "winter" | "bare" | "off" => Ok(Season::LeafOff),
            _ => Err(format!("unknown season {s:?}: expected leaf-on, autumn or leaf-off")),
        }
    }
}

/// The seasons of a deciduous species. Leaf-on is what every tier holds;
/// autumn recolours the leaves (every tier marks its leaf texels); leaf-off
/// drops them where the tier has them apart (mesh leaves, cloud planes,
/// ellipsoids) and, for the far tiers, draws captures of the bare wood: the
/// billboard and impostor sections with index 1, the same layout as index 0's,
/// in a fetch part of their own ([`PackPart::BareBillboards`], [`PackPart::BareImpostors`]) that only a leaf-off
/// view fetches.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SeasonMeta {
    /// The leaves' autumn colour (sRGB).
    pub autumn: [u8; 3],
    /// The far tiers' bare captures are in the pack (sections with index 1).
    pub bare_far: bool,
    /// The bare wood's covered texels over the leafy tree's (0–1), over the
    /// far tiers' captured views at their resolution: what canopy rasters keep
    /// of a leaf-off crown when the pack has no bare billboards.
    pub bare_cover: f32,
    /// The genus whose leaf calendar the species keeps (Latin, `Fagus`;
    /// [`crate::phenology`]) when the view has a date; absent: the default
    /// deciduous calendar.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub genus: Option<String>,
}

/// A section-table entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SectionEntry {
    /// FourCC kind.
    pub kind: [u8; 4],
    /// Level or slot index for kinds that repeat.
    pub index: u32,
    /// Byte offset in the file (multiple of [`PACK_SECTION_ALIGN`]).
    pub offset: u64,
    /// Byte length.
    pub bytes: u64,
    /// Element count (0 for blobs).
    pub count: u32,
    /// Bytes per element (0 for blobs).
    pub stride: u32,
}

/// A section to write: its table fields and its bytes.
#[derive(Debug, Clone, PartialEq)]
pub struct Section {
    /// FourCC kind.
    pub kind: [u8; 4],
    /// Level or slot index.
    pub index: u32,
    /// Element count (0 for blobs).
    pub count: u32,
    /// Bytes per element (0 for blobs).
    pub stride: u32,
    /// Contents.
    pub data: Vec<u8>,
}

/// A decoded and validated pack. Binary sections are borrowed from the file bytes.
#[derive(Debug, Clone, PartialEq)]
pub struct Pack<'a> {
    /// The metadata.
    pub meta: PackMeta,
    /// All sections in file order, known kinds or not.
    pub sections: Vec<(SectionEntry, &'a [u8])>,
}

impl Pack<'_> {
    /// The bytes of the section `kind`/`index`, if present.
    #[must_use]
    pub fn section(&self, kind: [u8; 4], index: u32) -> Option<&[u8]> {
        self.sections.iter().find(|(e, _)| e.kind == kind && e.index == index).map(|(_, b)| *b)
    }

    /// Vertices of mesh level `level`, copied into an aligned vector.
    #[must_use]
    pub fn mesh_vertices(&self, level: u32) -> Vec<MeshVertex> {
        self.section(kind::MESH_VERTICES, level).map(bytemuck::pod_collect_to_vec).unwrap_or_default()
    }

    /// The tree's own ambient occlusion field, if the pack has one (validated on decode).
    #[must_use]
    pub fn ao_field(&self) -> Option<AoFieldRef<'_>> {
        self.section(kind::AO_FIELD, 0).and_then(|b| AoFieldRef::parse(b).ok())
    }

    /// Indices of mesh level `level`, copied into an aligned vector.
    #[must_use]
    pub fn mesh_indices(&self, level: u32) -> Vec<u32> {
        self.section(kind::MESH_INDICES, level).map(bytemuck::pod_collect_to_vec).unwrap_or_default()
    }
}

/// Encodes a pack: `META` first, then `sections` in order, each aligned.
#[must_use]
pub fn encode_pack(meta: &PackMeta, sections: &[Section]) -> Vec<u8> {
    let meta_json = serde_json::to_vec(meta).expect("PackMeta serialises");
    let mut all = vec![Section { kind: kind::META, index: 0, count: 0, stride: 0, data: meta_json }];
    all.extend_from_slice(sections);
    let table_end = (PACK_HEADER_BYTES + all.len() * PACK_SECTION_ENTRY_BYTES) as u64;
    let mut offsets = Vec::with_capacity(all.len());
    let mut at = table_end;
    for s in &all {
        at = at.next_multiple_of(PACK_SECTION_ALIGN);
        offsets.push(at);
        at += s.data.len() as u64;
    }
    let file_bytes = at;
    let mut out = Vec::with_capacity(file_bytes as usize);
    out.extend_from_slice(&PACK_MAGIC);
    out.extend_from_slice(&PACK_VERSION.to_le_bytes());
    out.extend_from_slice(&(PACK_HEADER_BYTES as u16).to_le_bytes());
    out.extend_from_slice(&(all.len() as u32).to_le_bytes());
    out.extend_from_slice(&(PACK_SECTION_ALIGN as u32).to_le_bytes());
    out.extend_from_slice(&file_bytes.to_le_bytes());
    out.extend_from_slice(&0u64.to_le_bytes());
    for (s, off) in all.iter().zip(&offsets) {
        out.extend_from_slice(&s.kind);
        out.extend_from_slice(&s.index.to_le_bytes());
        out.extend_from_slice(&off.to_le_bytes());
        out.extend_from_slice(&(s.data.len() as u64).to_le_bytes());
        out.extend_from_slice(&s.count.to_le_bytes());
        out.extend_from_slice(&s.stride.to_le_bytes());
    }
    for (s, off) in all.iter().zip(&offsets) {
        out.resize(*off as usize, 0);
        out.extend_from_slice(&s.data);
    }
    out
}

/// Decodes and validates a pack. `file` names the file in errors.
///
/// # Errors
/// A [`DecodeError`] for a wrong magic or version, a section outside the file,
/// misaligned or overlapping, metadata that is not valid JSON or does not match
/// the sections (counts, sizes, indices, non-finite numbers, texture limits).
pub fn decode_pack<'a>(file: &str, bytes: &'a [u8]) -> Result<Pack<'a>, DecodeError> {
    decode_pack_inner(bytes).map_err(|p| DecodeError::new(file, p))
}

/// Reads the header and section table from `bytes` (the whole file, or when
/// `full` is false only its first bytes). Checks every entry against the file
/// size the header declares.
pub(super) fn read_table(bytes: &[u8], full: bool) -> Result<(Vec<SectionEntry>, u64), Problem> {
    let r = Reader::new(bytes);
    r.magic("Sylva LoD pack", &PACK_MAGIC)?;
    let version = r.u16("header.version", 4)?;
    if version != PACK_VERSION && version != PACK_VERSION_STORED {
        return Err(Problem::UnsupportedVersion { found: version.into(), supported: PACK_VERSION_STORED.into() });
    }
    let header_bytes = r.u16("header.header_bytes", 6)?;
    if usize::from(header_bytes) != PACK_HEADER_BYTES {
        return Err(Problem::Invalid(format!("header.header_bytes is {header_bytes}, expected {PACK_HEADER_BYTES}")));
    }
    let count = at_most("header.section_count", r.u32("header.section_count", 8)?.into(), MAX_PACK_SECTIONS.into())?;
    let align = u64::from(r.u32("header.section_align", 12)?);
    if align != PACK_SECTION_ALIGN {
        return Err(Problem::Invalid(format!("header.section_align is {align}, expected {PACK_SECTION_ALIGN}")));
    }
    let file_bytes = r.u64("header.file_bytes", 16)?;
    let len = bytes.len() as u64;
    // (A stored pack's file may be larger than its parts inflated, file_bytes.)
    if (file_bytes < len && version != PACK_VERSION_STORED) || (full && file_bytes != len) {
        return Err(if file_bytes > len {
            Problem::Truncated { what: "pack (header.file_bytes)".into(), start: 0, end: file_bytes, len }
        } else {
            Problem::Invalid(format!("header.file_bytes is {file_bytes} but the file has {len} bytes"))
        });
    }
    let table_end = PACK_HEADER_BYTES as u64 + count * PACK_SECTION_ENTRY_BYTES as u64;
    r.slice("section table", PACK_HEADER_BYTES as u64, table_end - PACK_HEADER_BYTES as u64)?;
    // `count` is bounded and the table is inside the bytes: safe to allocate.
    let mut sections = Vec::with_capacity(count as usize);
    let mut prev_end = table_end;
    for i in 0..count {
        let at = PACK_HEADER_BYTES as u64 + i * PACK_SECTION_ENTRY_BYTES as u64;
        let what = format!("section[{i}]");
        let k = r.slice(&what, at, 4)?;
        let entry = SectionEntry {
            kind: [k[0], k[1], k[2], k[3]],
            index: r.u32(&what, at + 4)?,
            offset: r.u64(&what, at + 8)?,
            bytes: r.u64(&what, at + 16)?,
            count: r.u32(&what, at + 24)?,
            stride: r.u32(&what, at + 28)?,
        };
        let name = format!("section[{i}] '{}'", String::from_utf8_lossy(&entry.kind));
        if !entry.offset.is_multiple_of(PACK_SECTION_ALIGN) {
            return Err(Problem::Invalid(format!(
                "{name} offset {} is not a multiple of {PACK_SECTION_ALIGN}",
                entry.offset
            )));
        }
        if entry.offset < prev_end {
            return Err(Problem::Invalid(format!(
                "{name} at offset {} overlaps the previous section or the table (ends at {prev_end})",
                entry.offset
            )));
        }
        if entry.stride != 0 && u64::from(entry.count) * u64::from(entry.stride) != entry.bytes {
            return Err(Problem::Invalid(format!(
                "{name} declares {} elements of {} bytes but holds {} bytes",
                entry.count, entry.stride, entry.bytes
            )));
        }
        let end = entry.offset.checked_add(entry.bytes).filter(|e| *e <= file_bytes);
        let Some(end) = end else {
            return Err(Problem::Truncated { what: name, start: entry.offset, end: u64::MAX, len: file_bytes });
        };
        prev_end = end;
        sections.push(entry);
    }
    if sections.first().is_none_or(|e| e.kind != kind::META) {
        return Err(Problem::Invalid("the first section is not META".into()));
    }
    // A stored pack's blocks follow META; no other pack has them.
    let stored_at = sections.iter().position(|e| e.kind == kind::STORED);
    match (version == PACK_VERSION_STORED, stored_at) {
        (true, Some(1)) | (false, None) => {}
        (true, _) => return Err(Problem::Invalid("a stored pack (version 2) whose second section is not STOR".into())),
        (false, Some(_)) => return Err(Problem::Invalid("a STOR section in a version 1 pack".into())),
    }
    Ok((sections, file_bytes))
}

fn decode_pack_inner(bytes: &[u8]) -> Result<Pack<'_>, Problem> {
    let (entries, file_bytes) = read_table(bytes, false)?;
    if file_bytes != bytes.len() as u64 && entries.get(1).is_some_and(|e| e.kind == kind::STORED) {
        return Err(Problem::Invalid(
            "a stored pack (its parts deflated): read it through format::stored::unstore, or by parts".into(),
        ));
    }
    let (entries, _) = read_table(bytes, true)?;
    let sections: Vec<(SectionEntry, &[u8])> =
        entries.into_iter().map(|e| (e, &bytes[e.offset as usize..(e.offset + e.bytes) as usize])).collect();
    let meta: PackMeta = serde_json::from_slice(sections[0].1).map_err(|e| Problem::Json(format!("META: {e}")))?;
    let pack = Pack { meta, sections };
    validate_meta(&pack, false)?;
    Ok(pack)
}

/// The head of a pack (header, section table, `META`, and a stored pack's
/// `STOR`): what a viewer reads first, to fetch only the sections its views
/// need by byte range.
#[derive(Debug, Clone, PartialEq)]
pub struct PackHead {
    /// The metadata.
    pub meta: PackMeta,
    /// The section table (`META` first).
    pub entries: Vec<SectionEntry>,
    /// Size of the whole pack (a stored pack's: as if its parts were not
    /// deflated; the offsets of `entries` are in that layout).
    pub file_bytes: u64,
    /// A stored pack's blocks, one per part it holds, in file order (empty
    /// for a version 1 pack).
    pub stored: Vec<StoredBlock>,
    /// The head bytes themselves (header, table, `META`, `STOR`).
    pub bytes: Vec<u8>,
}

/// One part of a stored pack: the bytes `logical` (start, end exclusive; as
/// the section table places them, alignment padding included) are in the file
/// at `stored`, deflated (RFC 1951, raw: no zlib or gzip wrapper).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StoredBlock {
    /// The part's range in the pack as the section table places it.
    pub logical: (u64, u64),
    /// Where its deflated bytes are in the file.
    pub stored: (u64, u64),
}

/// How to fetch one part: the file's bytes `range` (start, end exclusive),
/// and, for a stored pack, the part's size once inflated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PartFetch {
    /// Bytes of the file to fetch.
    pub range: (u64, u64),
    /// `Some(n)`: the bytes are deflated; inflated they are exactly `n` bytes,
    /// the part's range in the section table's layout ([`PackHead::part_range`]).
    pub inflated: Option<u64>,
}

/// Deflate expands no more than about 1032:1; a block claiming more is refused
/// before anything is inflated.
pub const MAX_INFLATE_RATIO: u64 = 1100;

/// The parts of a pack a viewer fetches separately, each one byte range (in a
/// stored pack one deflated block).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PackPart {
    /// Billboard colour, normal and occlusion arrays (a far tier).
    Billboards,
    /// Multi-view impostor colour and surface arrays (the other far tier).
    Impostors,
    /// Ellipsoid and line levels.
    Clusters,
    /// The coarser mesh levels (1 and up) and the material textures every mesh
    /// level samples.
    MeshCoarse,
    /// Mesh level 0, the full mesh (needed only close up; always with `MeshCoarse`).
    MeshFull,
    /// The bare tree's billboards (a deciduous species' far field in
    /// leaf-off, [`SeasonMeta`]): fetched instead of `Billboards` then.
    BareBillboards,
    /// The bare tree's impostors: fetched instead of `Impostors` in leaf-off.
    BareImpostors,
}

/// Index of [`PackPart::Billboards`] in [`PackPart::ALL`].
pub const PART_BILLBOARDS: usize = 0;
/// Index of [`PackPart::Impostors`] in [`PackPart::ALL`].
pub const PART_IMPOSTORS: usize = 1;
/// Index of [`PackPart::BareBillboards`] in [`PackPart::ALL`].
pub const PART_BARE_BILLBOARDS: usize = 5;
/// Index of [`PackPart::BareImpostors`] in [`PackPart::ALL`].
pub const PART_BARE_IMPOSTORS: usize = 6;
/// The far tiers' parts (indices into [`PackPart::ALL`]).
pub const FAR_PARTS: [usize; 4] = [PART_BILLBOARDS, PART_IMPOSTORS, PART_BARE_BILLBOARDS, PART_BARE_IMPOSTORS];

/// Number of [`PackPart`]s.
pub const PACK_PARTS: usize = 7;

impl PackPart {
    /// Every part (indices of the per-part arrays a viewer keeps).
    pub const ALL: [PackPart; PACK_PARTS] = [
        PackPart::Billboards,
        PackPart::Impostors,
        PackPart::Clusters,
        PackPart::MeshCoarse,
        PackPart::MeshFull,
        PackPart::BareBillboards,
        PackPart::BareImpostors,
    ];

    /// Indices into [`Self::ALL`] in fetch order: the far tiers (either
    /// state, either kind) first, then coarse to fine.
    pub const FETCH_ORDER: [usize; PACK_PARTS] =
        [PART_IMPOSTORS, PART_BILLBOARDS, PART_BARE_IMPOSTORS, PART_BARE_BILLBOARDS, 2, 3, 4];

    /// A far field (billboards or impostors, of one season): fetched whatever
    /// the GPU budget, before anything finer.
    #[must_use]
    pub fn is_far(self) -> bool {
        matches!(self, PackPart::Billboards | PackPart::Impostors | PackPart::BareBillboards | PackPart::BareImpostors)
    }

    /// The bare wood's far tier (state 1) in place of this leafy one, and back.
    #[must_use]
    pub fn other_state(self) -> Option<Self> {
        match self {
            PackPart::Billboards => Some(PackPart::BareBillboards),
            PackPart::Impostors => Some(PackPart::BareImpostors),
            PackPart::BareBillboards => Some(PackPart::Billboards),
            PackPart::BareImpostors => Some(PackPart::Impostors),
            _ => None,
        }
    }

    /// The bare wood's far tier (a deciduous species' state 1).
    #[must_use]
    pub fn is_bare(self) -> bool {
        matches!(self, PackPart::BareBillboards | PackPart::BareImpostors)
    }

    /// Index of this part in [`Self::ALL`].
    #[must_use]
    pub fn index(self) -> usize {
        Self::ALL.iter().position(|p| *p == self).expect("every part is in ALL")
    }

    /// The part a section belongs to (`None` for `META`, `STOR` and unknown kinds).
    #[must_use]
    pub fn of(k: [u8; 4], index: u32) -> Option<Self> {
        let bare = index == 1;
        match k {
            kind::BILLBOARD_COLOR | kind::BILLBOARD_NORMAL | kind::BILLBOARD_AO if bare => {
                Some(PackPart::BareBillboards)
            }
            kind::BILLBOARD_COLOR | kind::BILLBOARD_NORMAL | kind::BILLBOARD_AO => Some(PackPart::Billboards),
            kind::IMPOSTOR_COLOR | kind::IMPOSTOR_SURFACE if bare => Some(PackPart::BareImpostors),
            kind::IMPOSTOR_COLOR | kind::IMPOSTOR_SURFACE => Some(PackPart::Impostors),
            kind::ELLIPSOIDS | kind::LINES | kind::AO_FIELD => Some(PackPart::Clusters),
            kind::MESH_VERTICES | kind::MESH_INDICES | kind::MESH_VARIANTS if index == 0 => Some(PackPart::MeshFull),
            kind::MESH_VERTICES
            | kind::MESH_INDICES
            | kind::MESH_VARIANTS
            | kind::MATERIAL_TEXTURES
            | kind::CLOUD_VERTICES
            | kind::CLOUD_INDICES
            | kind::CLOUD_DATA => Some(PackPart::MeshCoarse),
            _ => None,
        }
    }
}

impl PackHead {
    /// Decodes the first bytes of a pack (at least its head; a whole pack works too).
    ///
    /// # Errors
    /// A [`DecodeError`] as for [`decode_pack`], for the header, table, `META`
    /// and a stored pack's blocks.
    pub fn decode(file: &str, bytes: &[u8]) -> Result<Self, DecodeError> {
        let inner = || -> Result<Self, Problem> {
            let (entries, file_bytes) = read_table(bytes, false)?;
            let m = entries[0];
            let r = Reader::new(bytes);
            let meta_bytes = r.slice("META section", m.offset, m.bytes)?;
            let meta: PackMeta = serde_json::from_slice(meta_bytes).map_err(|e| Problem::Json(format!("META: {e}")))?;
            let mut head_end = m.offset + m.bytes;
            let mut head = Self { meta, entries, file_bytes, stored: Vec::new(), bytes: Vec::new() };
            if let Some(s) = head.entries.get(1).copied().filter(|e| e.kind == kind::STORED) {
                let table = r.slice("STOR section", s.offset, s.bytes)?;
                head.stored = read_blocks(&head, s, table)?;
                head_end = s.offset + s.bytes;
            }
            head.bytes = bytes[..head_end as usize].to_vec();
            Ok(head)
        };
        inner().map_err(|p| DecodeError::new(file, p))
    }

    /// The byte range (start, end exclusive) covering every section of `part`
    /// as the section table places them, or `None` when the pack has none.
    /// (A stored pack's file holds it deflated elsewhere: [`Self::fetch_of`].)
    #[must_use]
    pub fn part_range(&self, part: PackPart) -> Option<(u64, u64)> {
        part_range_in(&self.entries, part)
    }

    /// What to fetch for `part`: its range, or in a stored pack its block
    /// (validated on decode: every part held is exactly one block).
    #[must_use]
    pub fn fetch_of(&self, part: PackPart) -> Option<PartFetch> {
        let range = self.part_range(part)?;
        if self.stored.is_empty() {
            return Some(PartFetch { range, inflated: None });
        }
        let b = self.stored.iter().find(|b| b.logical == range)?;
        Some(PartFetch { range: b.stored, inflated: Some(range.1 - range.0) })
    }

    /// Bytes of `part` in the file (deflated in a stored pack), 0 when absent.
    #[must_use]
    pub fn fetch_bytes(&self, part: PackPart) -> u64 {
        self.fetch_of(part).map_or(0, |f| f.range.1 - f.range.0)
    }

    /// Bytes of `part` once fetched (and inflated): what it holds in memory, 0 when absent.
    #[must_use]
    pub fn part_bytes(&self, part: PackPart) -> u64 {
        self.part_range(part).map_or(0, |(a, b)| b - a)
    }

    /// A pack of the sections held in `parts` (each `(file offset, bytes)`),
    /// validated; sections not held are simply absent.
    ///
    /// # Errors
    /// A [`DecodeError`] when a held section does not match the metadata.
    pub fn assemble<'a>(&'a self, file: &str, parts: &'a [(u64, Vec<u8>)]) -> Result<Pack<'a>, DecodeError> {
        let mut sections = Vec::with_capacity(self.entries.len());
        for e in &self.entries {
            if e.kind == kind::META {
                sections.push((*e, &self.bytes[e.offset as usize..(e.offset + e.bytes) as usize]));
                continue;
            }
            let held = parts.iter().find(|(at, b)| *at <= e.offset && e.offset + e.bytes <= at + b.len() as u64);
            if let Some((at, b)) = held {
                let start = (e.offset - at) as usize;
                sections.push((*e, &b[start..start + e.bytes as usize]));
            }
        }
        let pack = Pack { meta: self.meta.clone(), sections };
        validate_meta(&pack, true).map_err(|p| DecodeError::new(file, p))?;
        Ok(pack)
    }
}

/// The byte range covering every section of `part` in a section table.
pub(super) fn part_range_in(entries: &[SectionEntry], part: PackPart) -> Option<(u64, u64)> {
    let mut it = entries.iter().filter(|e| PackPart::of(e.kind, e.index) == Some(part));
    let first = it.next()?;
    let (mut lo, mut hi) = (first.offset, first.offset + first.bytes);
    for e in it {
        lo = lo.min(e.offset);
        hi = hi.max(e.offset + e.bytes);
    }
    Some((lo, hi))
}

/// Reads and checks a stored pack's `STOR` table against its section table:
/// blocks in file order right after the head, one per part the pack holds,
/// each exactly that part's range.
fn read_blocks(head: &PackHead, s: SectionEntry, table: &[u8]) -> Result<Vec<StoredBlock>, Problem> {
    if s.index != 0 || s.stride as u64 != STORED_BLOCK_BYTES || s.count as usize > PACK_PARTS {
        return Err(Problem::Invalid(format!(
            "the STOR section declares {} blocks of {} bytes (index {}): at most {PACK_PARTS} of 32",
            s.count, s.stride, s.index
        )));
    }
    let r = Reader::new(table);
    let head_end = s.offset + s.bytes;
    let mut blocks = Vec::with_capacity(s.count as usize);
    let mut stored_end = head_end;
    // Parts follow the head and each other in the section table's layout (at
    // most the alignment's padding apart), and the last one ends the pack: so
    // what a reader allocates is what the blocks hold.
    let mut logical_end = head_end;
    for i in 0..u64::from(s.count) {
        let what = format!("STOR block[{i}]");
        let at = i * STORED_BLOCK_BYTES;
        let word = |o: u64| r.u64(&what, at + o);
        let (lo, len, so, slen) = (word(0)?, word(8)?, word(16)?, word(24)?);
        let end = lo.checked_add(len).filter(|e| *e <= head.file_bytes);
        let (Some(end), true) = (end, len > 0 && lo >= logical_end && lo - logical_end < PACK_SECTION_ALIGN) else {
            return Err(Problem::Invalid(format!(
                "{what}: bytes {lo} + {len} are not the next part after byte {logical_end} within the pack's {} bytes",
                head.file_bytes
            )));
        };
        let stored = so.checked_add(slen).filter(|_| so == stored_end && slen > 0);
        let (Some(stored), true) = (stored, len <= slen.saturating_mul(MAX_INFLATE_RATIO)) else {
            return Err(Problem::Invalid(format!(
                "{what}: stored at {so} + {slen} bytes for {len} (blocks follow the head and each other, \
                 inflating at most {MAX_INFLATE_RATIO}:1)"
            )));
        };
        (logical_end, stored_end) = (end, stored);
        blocks.push(StoredBlock { logical: (lo, end), stored: (so, stored) });
    }
    if logical_end != head.file_bytes {
        return Err(Problem::Invalid(format!(
            "the STOR section's parts end at byte {logical_end}, the pack's header says {}",
            head.file_bytes
        )));
    }
    // Each part held is one block, and each block one part.
    let parts: Vec<(u64, u64)> = PackPart::ALL.iter().filter_map(|p| head.part_range(*p)).collect();
    let unplaced = head.entries.iter().skip(2).find(|e| PackPart::of(e.kind, e.index).is_none());
    if let Some(e) = unplaced {
        return Err(Problem::Invalid(format!(
            "section {} in a stored pack belongs to no part",
            String::from_utf8_lossy(&e.kind)
        )));
    }
    if parts.len() != blocks.len() || !parts.iter().all(|p| blocks.iter().any(|b| b.logical == *p)) {
        return Err(Problem::Invalid(format!(
            "the STOR section's {} blocks are not the pack's {} parts",
            blocks.len(),
            parts.len()
        )));
    }
    Ok(blocks)
}

/// Checks the metadata against the sections. `partial`: sections may be
/// missing (not fetched); those present must match.
fn validate_meta(pack: &Pack<'_>, partial: bool) -> Result<(), Problem> {
    let m = &pack.meta;
    finite("META.height_m", m.height_m.into())?;
    finite_all("META.bounds_min", &m.bounds_min)?;
    finite_all("META.bounds_max", &m.bounds_max)?;
    if m.height_m <= 0.0 {
        return Err(Problem::Invalid(format!("META.height_m is {}, must be positive", m.height_m)));
    }
    let layers = m.material_texture.map_or(0, |t| t.layers);
    for (i, mat) in m.materials.iter().enumerate() {
        finite_all(&format!("META.materials[{i}].base_color"), &mat.base_color)?;
        finite(format!("META.materials[{i}].alpha_cutoff"), mat.alpha_cutoff.into())?;
        if let Some(c) = mat.coverage {
            if !(0.0..=1.0).contains(&c) {
                return Err(Problem::Invalid(format!("META.materials[{i}].coverage is {c}, must be 0–1")));
            }
        }
        if let Some(layer) = mat.texture_layer {
            if layer >= layers {
                return Err(Problem::OutOfRange {
                    what: format!("META.materials[{i}].texture_layer"),
                    value: layer.into(),
                    allowed: format!("less than the {layers} material texture layers"),
                });
            }
        }
    }
    if let Some(t) = &m.material_texture {
        let data = pack.section(kind::MATERIAL_TEXTURES, 0);
        if !(partial && data.is_none()) {
            validate_texture("META.material_texture", t, data, 4)?;
        }
    }
    for (l, level) in m.mesh_levels.iter().enumerate() {
        let vtx = pack.section(kind::MESH_VERTICES, l as u32);
        let idx = pack.section(kind::MESH_INDICES, l as u32);
        mesh_meta_finite(&format!("META.mesh_levels[{l}]"), level)?;
        if partial && (vtx.is_none() || idx.is_none()) {
            continue;
        }
        let sections = format!("MVTX/MIDX section with index {l}");
        validate_mesh(&format!("META.mesh_levels[{l}]"), level, vtx, idx, m.materials.len(), &sections)?;
        validate_variants(&format!("META.mesh_levels[{l}]"), level, pack.section(kind::MESH_VARIANTS, l as u32))?;
    }
    if let Some(c) = &m.cloud {
        mesh_meta_finite("META.cloud.mesh", &c.mesh)?;
        finite("META.cloud.select_px", c.select_px.into())?;
        let vtx = pack.section(kind::CLOUD_VERTICES, 0);
        let idx = pack.section(kind::CLOUD_INDICES, 0);
        let data = pack.section(kind::CLOUD_DATA, 0);
        if !(partial && (vtx.is_none() || idx.is_none() || data.is_none())) {
            validate_mesh("META.cloud.mesh", &c.mesh, vtx, idx, m.materials.len(), "CLVX/CLIX sections")?;
            let Some(data) = data else {
                return Err(Problem::Invalid("META.cloud has no CLDA section".into()));
            };
            super::cloud::validate_cloud(c, data, m.materials.len())?;
            if m.materials[c.material as usize].kind != MaterialKind::Cloud {
                return Err(Problem::Invalid("META.cloud.material is not a `cloud` material".into()));
            }
            // Each quad's plane (vertex colour red + 256 × green) must exist.
            for (i, v) in vtx.unwrap_or_default().chunks_exact(20).enumerate() {
                let material = usize::from(u16::from_le_bytes([v[6], v[7]]));
                let plane = u32::from(v[16]) + 256 * u32::from(v[17]);
                if m.materials[material].kind == MaterialKind::Cloud && plane >= c.planes {
                    return Err(Problem::OutOfRange {
                        what: format!("META.cloud.mesh vertex[{i}] plane"),
                        value: plane.into(),
                        allowed: format!("less than {} planes", c.planes),
                    });
                }
            }
        }
    }
    // Mesh levels draw no cloud planes.
    for (l, _) in m.mesh_levels.iter().enumerate() {
        for (i, v) in pack.section(kind::MESH_VERTICES, l as u32).unwrap_or_default().chunks_exact(20).enumerate() {
            let material = usize::from(u16::from_le_bytes([v[6], v[7]]));
            if m.materials.get(material).is_some_and(|x| x.kind == MaterialKind::Cloud) {
                return Err(Problem::Invalid(format!(
                    "META.mesh_levels[{l}] vertex[{i}] uses the `cloud` material {material}"
                )));
            }
        }
    }
    // The far tiers' states: leaf-on (index 0), and the bare wood (index 1)
    // of a deciduous species that has it; no other index.
    let states = if m.season.as_ref().is_some_and(|s| s.bare_far) { 2 } else { 1 };
    if let Some(s) = &m.season {
        finite("META.season.bare_cover", s.bare_cover.into())?;
        if !(0.0..=1.0).contains(&s.bare_cover) {
            return Err(Problem::Invalid(format!("META.season.bare_cover is {}, must be 0–1", s.bare_cover)));
        }
        if let Some(g) = &s.genus {
            if g.is_empty() || g.len() > 64 || !g.bytes().all(|b| b.is_ascii_alphabetic() || b == b'-') {
                return Err(Problem::Invalid(format!(
                    "META.season.genus {:?}: a Latin genus, 1–64 letters (or `-`)",
                    g.chars().take(80).collect::<String>()
                )));
            }
        }
    }
    for (e, _) in &pack.sections {
        if kind::FAR_TIERS.contains(&e.kind) && e.index >= states {
            return Err(Problem::Invalid(format!(
                "section {} with index {}: the far tiers have {states} state{} here (index 1 is a \
                 deciduous species' bare wood, with META.season.bare_far)",
                String::from_utf8_lossy(&e.kind),
                e.index,
                if states == 1 { "" } else { "s" }
            )));
        }
    }
    if let Some(b) = &m.billboards {
        finite_all("META.billboards.center", &b.center)?;
        finite_all("META.billboards", &[b.half_width, b.half_height, b.select_px])?;
        let variants = far_variants("META.billboards.variants", b.variants, m)?;
        if b.angles < 2
            || b.azimuths == 0
            || u64::from(b.angles) * u64::from(b.azimuths) * u64::from(variants) != u64::from(b.texture.layers)
        {
            return Err(Problem::Invalid(format!(
                "META.billboards has {} angles × {} azimuths × {variants} variants but {} layers (need ≥ 2 angles)",
                b.angles, b.azimuths, b.texture.layers
            )));
        }
        for state in 0..states {
            for k in [kind::BILLBOARD_COLOR, kind::BILLBOARD_NORMAL] {
                let data = pack.section(k, state);
                if !(partial && data.is_none()) {
                    validate_texture(&format!("META.billboards.texture (state {state})"), &b.texture, data, 4)?;
                }
            }
            // Optional at any time: older packs have no occlusion. One R8
            // texel after another even where the colours are block-encoded.
            if let Some(data) = pack.section(kind::BILLBOARD_AO, state) {
                let plain = TextureArrayMeta { encoding: None, ..b.texture };
                validate_texture("META.billboards.texture (BBAO)", &plain, Some(data), 1)?;
            }
        }
    }
    if let Some(i) = &m.impostors {
        finite_all("META.impostors.center", &i.center)?;
        finite("META.impostors.radius", f64::from(i.radius))?;
        if let Some(h) = &i.half_extent {
            finite_all("META.impostors.half_extent", h)?;
            if h.iter().any(|v| *v < 0.0 || *v > i.radius * 1.01) {
                return Err(Problem::Invalid(format!(
                    "META.impostors.half_extent {h:?} is not within the radius {}",
                    i.radius
                )));
            }
        }
        let variants = far_variants("META.impostors.variants", i.variants, m)?;
        if !(2..=16).contains(&i.grid) || i.grid * i.grid * variants != i.texture.layers || i.radius <= 0.0 {
            return Err(Problem::Invalid(format!(
                "META.impostors has a {0}×{0} grid (2–16 per side) of {3} variants, {1} layers (need grid² × \
                 variants) and radius {2} (need > 0)",
                i.grid, i.texture.layers, i.radius, variants
            )));
        }
        finite_all("META.impostors.normal_length", &i.normal_length)?;
        if i.normal_length.len() > i.texture.mips as usize || i.normal_length.iter().any(|l| !(0.0..=1.0).contains(l)) {
            return Err(Problem::Invalid(format!(
                "META.impostors.normal_length has {} values (at most one per mip, {}), each 0–1",
                i.normal_length.len(),
                i.texture.mips
            )));
        }
        for state in 0..states {
            for k in [kind::IMPOSTOR_COLOR, kind::IMPOSTOR_SURFACE] {
                let data = pack.section(k, state);
                if !(partial && data.is_none()) {
                    validate_texture(&format!("META.impostors.texture (state {state})"), &i.texture, data, 4)?;
                }
            }
        }
    }
    if let Some(c) = &m.clusters {
        finite_all("META.clusters.line_color", &c.line_color)?;
        let kinds = [
            ("ellipsoid_levels", &c.ellipsoid_levels, kind::ELLIPSOIDS, 24),
            ("line_levels", &c.line_levels, kind::LINES, 16),
        ];
        for (name, levels, k, stride) in kinds {
            at_most(format!("META.clusters.{name} count"), levels.len() as u64, 32)?;
            for (l, level) in levels.iter().enumerate() {
                let what = format!("META.clusters.{name}[{l}]");
                finite_all(&what, &[level.select_px, level.error, level.noise_threshold, level.normal_blend])?;
                let data = pack.section(k, l as u32);
                if partial && data.is_none() {
                    continue;
                }
                let Some(data) = data else {
                    return Err(Problem::Invalid(format!(
                        "{what} has no {} section with index {l}",
                        String::from_utf8_lossy(&k)
                    )));
                };
                if data.len() as u64 != u64::from(level.count) * stride {
                    return Err(Problem::Invalid(format!(
                        "{what} declares {} records of {stride} bytes, the section holds {} bytes",
                        level.count,
                        data.len()
                    )));
                }
            }
        }
    }
    if let Some(data) = pack.section(kind::AO_FIELD, 0) {
        AoFieldRef::parse(data)?;
    }
    Ok(())
}

/// A far tier's variants (`None`: 1): 1, or mesh level 0's variants + 1 (a
/// tree's far tier shows its mesh variant).
fn far_variants(what: &str, variants: Option<u32>, m: &PackMeta) -> Result<u32, Problem> {
    let meshes = m.mesh_levels.first().map_or(1, |l| l.variants.saturating_add(1));
    match variants.unwrap_or(1) {
        v if v == 1 || v == meshes => Ok(v),
        v => Err(Problem::OutOfRange {
            what: what.into(),
            value: v.into(),
            allowed: format!("1, or mesh level 0's {meshes} variants"),
        }),
    }
}

fn validate_texture(what: &str, t: &TextureArrayMeta, data: Option<&[u8]>, texel_bytes: u64) -> Result<(), Problem> {
    at_most(format!("{what}.size"), t.size.into(), MAX_TEXTURE_SIZE.into())?;
    at_most(format!("{what}.layers"), t.layers.into(), MAX_TEXTURE_LAYERS.into())?;
    let full_chain = 32 - t.size.max(1).leading_zeros();
    at_most(format!("{what}.mips"), t.mips.into(), full_chain.into())?;
    if t.size == 0 || t.layers == 0 || t.mips == 0 {
        return Err(Problem::Invalid(format!("{what} has a zero size, layer count or mip count")));
    }
    if let Some(e) = t.encoding {
        // Blocks of RGBA textures only, and whole blocks at mip 0 (WebGPU's rule).
        if texel_bytes != 4 || !t.size.is_multiple_of(4) {
            return Err(Problem::Invalid(format!(
                "{what} is {} encoded but {}",
                e.name(),
                if texel_bytes != 4 { "not an RGBA texture" } else { "its size is no multiple of 4" }
            )));
        }
    }
    let Some(data) = data else {
        return Err(Problem::Invalid(format!("{what} has no texture section")));
    };
    let need = t.byte_len_of(texel_bytes);
    if data.len() as u64 != need {
        return Err(Problem::Invalid(format!("{what} needs {need} bytes, the section holds {}", data.len())));
    }
    Ok(())
}

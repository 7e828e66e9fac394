//! The options of every bake that builds LoD packs (`bake` and `demo`).

use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::Args;
use sylva::format::canopy::FINEST_CELL_M;
use sylva::format::index::DEFAULT_NODE_TILES;
use sylva_bake::bake::batching::{default_cell_size, SceneTree, MAX_CELL_SIZE_M};
use sylva_bake::pack::{FarBake, PackOptions};

use super::*;

#[derive(Args, Clone)]
pub(crate) struct PackArgs {
    /// Billboard elevation angles over 0–90° (Eichner 2024, alg. 3.1).
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(2..=64))]
    pub(crate) billboard_angles: u32,
    /// Billboard azimuths around the tree.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=16))]
    pub(crate) billboard_azimuths: u32,
    /// Billboard resolution per layer (power of two).
    #[arg(long, default_value_t = 128)]
    pub(crate) billboard_size: u32,
    /// Far-field representations to bake: multi-view impostors (blended views
    /// over the hemisphere, the tree keeps its shape all round), Eichner 2024's
    /// view-angle billboards, or both (the viewer draws the impostors).
    #[arg(long, value_enum, default_value_t = FarBake::Both)]
    pub(crate) far_tier: FarBake,
    /// Impostor views per side of the hemi-octahedral grid (grid² views).
    #[arg(long, default_value_t = sylva_bake::pack::DEFAULT_IMPOSTOR_GRID, value_parser = clap::value_parser!(u32).range(2..=16))]
    pub(crate) impostor_grid: u32,
    /// Impostor resolution per view (power of two).
    #[arg(long, default_value_t = sylva_bake::pack::DEFAULT_IMPOSTOR_SIZE)]
    pub(crate) impostor_size: u32,
    /// Planes of the billboard cloud (García et al. 2007: leaves kept exact on planes
    /// fitted to the foliage; e.g. 64). 0 bakes none. The viewer draws it only
    /// when asked (`sylva render --only clouds`, bench method `billboard-cloud`).
    #[arg(long, default_value_t = sylva_bake::pack::DEFAULT_CLOUD_PLANES, value_parser = clap::value_parser!(u32).range(0..=1024))]
    pub(crate) cloud_planes: u32,
    /// Bake deciduous species in one state (leaf-on) only: no autumn colour, no
    /// bare far tiers (smaller packs). By default a species whose name places a
    /// deciduous genus (a library tree, or `--model oak=…`) gets leaf-on,
    /// autumn and leaf-off (`sylva render --season`, the viewer's `setSeason`).
    #[arg(long)]
    pub(crate) no_seasons: bool,
    /// Write the species packs as they are (pack version 1), not stored with
    /// each part deflated: for viewers older than stored packs (the default
    /// fetches about a seventh of the bytes; docs/FORMAT.md "Stored packs").
    #[arg(long)]
    pub(crate) raw_packs: bool,
    /// GPU block-compressed variants of every pack to write beside it, comma
    /// separated: `bc7` (desktop GPUs), `etc2` (phones, tablets, Apple
    /// silicon) — both by default: a quarter of the texture memory, fewer
    /// bytes to fetch — or `none`. A viewer fetches the first variant its GPU
    /// samples (BC7 before ETC2), else the plain pack.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "bc7,etc2")]
    pub(crate) gpu_textures: Vec<GpuTextures>,
    /// Capture the far tiers (impostors, billboards) of each of a library
    /// tree's mesh variants, not variant 0's alone: far trees keep their own
    /// shapes (closer to their meshes) for 3× the far tiers' bytes.
    #[arg(long)]
    pub(crate) far_tier_variants: bool,
    /// Material texture size (power of two).
    #[arg(long, default_value_t = 512)]
    pub(crate) texture_size: u32,
    /// Do not add the simplified mesh level.
    #[arg(long)]
    pub(crate) no_simplified_level: bool,
    /// Do not add clustered-ellipsoid and line levels (Clasen et al. 2010).
    #[arg(long)]
    pub(crate) no_clusters: bool,
    /// Do not bake each tree's own ambient occlusion (darker inside the crown,
    /// alike at every level of detail); the viewer then draws crowns unoccluded.
    #[arg(long)]
    pub(crate) no_ao: bool,
    /// EM starts per cluster level; the one with the lowest image error is kept.
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=32))]
    pub(crate) cluster_tries: u32,
    /// Write billboard layers as PNG strips into this directory.
    #[arg(long, value_name = "DIR")]
    pub(crate) debug_dump: Option<PathBuf>,
    /// Keep the species packs built in this folder, and take a pack from it when
    /// the same model is baked again with the same pack options by the same
    /// sylva-bake on the same GPU and driver: re-bakes of an inventory then skip the packs (seconds to
    /// minutes a species). Delete the folder to free its space.
    #[arg(long, value_name = "DIR", env = "SYLVA_BAKE_PACK_CACHE")]
    pub(crate) pack_cache: Option<PathBuf>,
    /// Batch grid cell size in metres (default: from the data's density; at most 655).
    #[arg(long)]
    pub(crate) cell_size: Option<u32>,
    /// Grid cells per tile side.
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..=256))]
    pub(crate) tile_cells: u32,
    /// Most tiles per node of the hierarchical tile index; scenes with more tiles
    /// than this get one (`merge` must be given the same value).
    #[arg(long, default_value_t = DEFAULT_NODE_TILES, value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub(crate) index_node_tiles: u32,
    /// Width of the finest canopy raster cells, metres: what far views draw where
    /// trees are a pixel or two (finer: sharper forest edges from afar, more
    /// bytes; `merge` must be given the same value).
    #[arg(long, default_value_t = FINEST_CELL_M, value_parser = parse_canopy_cell)]
    pub(crate) canopy_cell: f64,
    /// Bake only shard I of N of the tile grid (0-based), e.g. 0/4, as one task of
    /// an array job; join the N outputs with `sylva-bake merge`. Shard 0 also bakes
    /// the species packs. Every shard reads the whole input.
    #[arg(long, value_name = "I/N", value_parser = parse_shard)]
    pub(crate) shard: Option<(u32, u32)>,
}

pub(crate) fn parse_delimiter(s: &str) -> Result<u8, String> {
    match s {
        "tab" | "\\t" | "\t" => Ok(b'\t'),
        _ if s.len() == 1 && s.is_ascii() => Ok(s.as_bytes()[0]),
        _ => Err(format!("{s:?}: one ASCII character, e.g. ';' or tab")),
    }
}

pub(crate) fn parse_shard(s: &str) -> Result<(u32, u32), String> {
    let (i, n) = s.split_once('/').ok_or_else(|| format!("{s:?}: expected I/N, e.g. 0/4"))?;
    let i: u32 = i.trim().parse().map_err(|_| format!("{s:?}: I must be a whole number"))?;
    let n: u32 = n.trim().parse().map_err(|_| format!("{s:?}: N must be a whole number"))?;
    if n == 0 || n > 65_536 || i >= n {
        return Err(format!("{s:?}: need 0 ≤ I < N ≤ 65536"));
    }
    Ok((i, n))
}

impl PackArgs {
    pub(crate) fn options(&self) -> Result<PackOptions> {
        for (name, v, max) in [
            ("--billboard-size", self.billboard_size, 2048),
            ("--texture-size", self.texture_size, 4096),
            ("--impostor-size", self.impostor_size, 1024),
        ] {
            if !v.is_power_of_two() || v < 4 || v > max {
                bail!("{name} {v}: must be a power of two between 4 and {max}");
            }
        }
        // With --far-tier-variants a library tree's far tiers hold each variant's layers.
        let variants = if self.far_tier_variants { sylva_bake::library::VARIANTS } else { 1 };
        // The capture holds every view at twice the size (colour, normal,
        // occlusion, depth: 16 bytes a texel) until the mips are built.
        let capture_bytes =
            u64::from(self.impostor_grid).pow(2) * (2 * u64::from(self.impostor_size)).pow(2) * 16 * variants;
        if capture_bytes > 1 << 30 {
            bail!(
                "--impostor-grid {} with --impostor-size {}{} needs {:.1} GiB while baking: at most 1 GiB \
                 (e.g. --impostor-grid 8 --impostor-size 256)",
                self.impostor_grid,
                self.impostor_size,
                if variants > 1 { " and --far-tier-variants" } else { "" },
                capture_bytes as f64 / f64::from(1u32 << 30)
            );
        }
        let per = if variants > 1 { format!(" × {variants} variants (--far-tier-variants)") } else { String::new() };
        if u64::from(self.billboard_angles) * u64::from(self.billboard_azimuths) * variants > 256 {
            bail!("--billboard-angles × --billboard-azimuths{per} must be at most 256 (WebGPU's array layer limit)");
        }
        if u64::from(self.impostor_grid).pow(2) * variants > 256 {
            bail!("--impostor-grid squared{per} must be at most 256 (WebGPU's array layer limit)");
        }
        Ok(PackOptions {
            texture_size: self.texture_size,
            billboard_angles: self.billboard_angles,
            billboard_azimuths: self.billboard_azimuths,
            billboard_size: self.billboard_size,
            simplified_level: !self.no_simplified_level,
            clusters: !self.no_clusters,
            cluster_tries: self.cluster_tries as usize,
            ao: !self.no_ao,
            far_tier: self.far_tier,
            impostor_grid: self.impostor_grid,
            impostor_size: self.impostor_size,
            cloud_planes: self.cloud_planes,
            seasons: !self.no_seasons,
            raw_packs: self.raw_packs,
            gpu_textures: gpu_textures(&self.gpu_textures)?,
            far_variants: self.far_tier_variants,
        })
    }

    pub(crate) fn cell_size(&self, trees: &[SceneTree]) -> Result<u32> {
        match self.cell_size {
            Some(c) if c == 0 || c > MAX_CELL_SIZE_M => {
                bail!("--cell-size {c}: must be 1–{MAX_CELL_SIZE_M} m (16-bit positions at ≤ 1 cm)")
            }
            Some(c) => Ok(c),
            None => Ok(default_cell_size(trees, 500.0)),
        }
    }
}

/// `--gpu-textures`: one of a comma-separated list.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum GpuTextures {
    /// BC7 variants (desktop GPUs).
    Bc7,
    /// ETC2 variants (phones, tablets, Apple silicon).
    Etc2,
    /// Plain packs only.
    None,
}

/// The encodings `--gpu-textures` names, each once, BC7 first whatever the
/// order given (the manifest lists variants in the viewers' preference).
fn gpu_textures(list: &[GpuTextures]) -> Result<Vec<sylva::format::pack::TexelEncoding>> {
    use sylva::format::pack::TexelEncoding;
    if list.contains(&GpuTextures::None) {
        if list.len() > 1 {
            bail!("--gpu-textures: `none` stands alone (not with bc7 or etc2)");
        }
        return Ok(Vec::new());
    }
    Ok([(GpuTextures::Bc7, TexelEncoding::Bc7), (GpuTextures::Etc2, TexelEncoding::Etc2)]
        .into_iter()
        .filter_map(|(g, e)| list.contains(&g).then_some(e))
        .collect())
}

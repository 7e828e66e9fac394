//! `sylva bench --memory`: bytes per tree on disk, over the wire (gzip and
//! brotli, as a static host serves pre-compressed files) and on the GPU, per
//! species pack, against Eichner 2024's eq. 4.1 for the same parameters.

use std::io::Write as _;
use std::path::Path;

use anyhow::{Context, Result};
use serde::Serialize;

use crate::format::pack::decode_pack;
use crate::format::Manifest;
use crate::render::forest::PoolConfig;

/// Bytes of a set of files, raw and compressed.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq)]
pub struct Sizes {
    /// As stored.
    pub raw: u64,
    /// gzip, level 9.
    pub gzip: u64,
    /// brotli, quality 11 (window 22).
    pub brotli: u64,
}

impl Sizes {
    fn of(bytes: &[u8]) -> Result<Self> {
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
        gz.write_all(bytes)?;
        let gzip = gz.finish()?.len() as u64;
        let mut br = Vec::new();
        {
            let mut w = brotli::CompressorWriter::new(&mut br, 1 << 16, 11, 22);
            w.write_all(bytes)?;
        }
        Ok(Self { raw: bytes.len() as u64, gzip, brotli: br.len() as u64 })
    }

    fn add(&mut self, o: Self) {
        self.raw += o.raw;
        self.gzip += o.gzip;
        self.brotli += o.brotli;
    }

    fn per(self, n: u64) -> [f64; 3] {
        let n = n.max(1) as f64;
        [self.raw as f64 / n, self.gzip as f64 / n, self.brotli as f64 / n]
    }
}

/// One species pack.
#[derive(Debug, Clone, Serialize)]
pub struct PackMemory {
    /// Species name.
    pub name: String,
    /// File bytes, raw and compressed.
    pub file: Sizes,
    /// Bytes uploaded to the GPU when every level is resident (all sections but META).
    pub gpu: u64,
    /// Of which billboard textures (colour + normal arrays with mips).
    pub billboard_gpu: u64,
    /// Billboard views (elevation angles × azimuths) and texture side.
    pub billboard_views: u32,
    /// Billboard texture side in texels.
    pub billboard_size: u32,
    /// Levels drawn: mesh levels + cluster levels + billboards.
    pub levels: u32,
}

/// The whole model (`memory.json`).
#[derive(Debug, Clone, Serialize)]
pub struct MemoryModel {
    /// Trees.
    pub trees: u64,
    /// Batches.
    pub batches: u64,
    /// Tiles.
    pub tiles: u64,
    /// Species.
    pub species: u64,
    /// `scene.json`.
    pub manifest: Sizes,
    /// Tile files (instances and batch records).
    pub tiles_bytes: Sizes,
    /// Id sidecars (fetched only for picking).
    pub ids_bytes: Sizes,
    /// Tile bytes per tree: raw, gzip, brotli.
    pub tile_bytes_per_tree: [f64; 3],
    /// Everything a full view fetches (manifest, tiles, packs) per tree: raw, gzip, brotli.
    pub fetched_bytes_per_tree: [f64; 3],
    /// Per species.
    pub packs: Vec<PackMemory>,
    /// GPU bytes per resident tree: 8 B instance plus its share of the batch records.
    pub gpu_bytes_per_tree: f64,
    /// GPU bytes with every tree and pack resident: instances, batches, packs (no pools).
    pub gpu_scene_bytes: u64,
    /// GPU bytes of the renderer's preallocated pools at their defaults.
    pub gpu_pool_bytes: u64,
    /// Seed 004's eq. 4.1 for this scene's n, t, m, a, r, l: bytes beyond the trees' own transforms.
    pub seed004_eq41_bytes: u64,
    /// Seed 004's eq. 4.1 plus the 64-byte matrix per tree it keeps besides.
    pub seed004_with_transforms_bytes: u64,
    /// This scene's counterpart: instances (transform included), batches, billboard textures.
    pub sylva_comparable_bytes: u64,
}

/// Seed 004 eq. 4.1: `4n + 64t + 24m + 16amr² + 52lt + 4lm` bytes, for `n` trees,
/// `t` batches, `m` meshes, `a` billboard angles, `r`² texels per billboard and
/// `l` levels of detail.
#[must_use]
pub fn seed004_eq41(n: u64, t: u64, m: u64, a: u64, r: u64, l: u64) -> u64 {
    4 * n + 64 * t + 24 * m + 16 * a * m * r * r + 52 * l * t + 4 * l * m
}

/// Measures the scene in `dir` (a local directory).
///
/// # Errors
/// Missing or corrupt files (named).
pub fn measure(dir: &Path) -> Result<MemoryModel> {
    let read = |rel: &str| -> Result<Vec<u8>> {
        let p = dir.join(rel);
        crate::paths::read_regular(&p, None, crate::paths::MAX_SCENE_FILE_BYTES)
            .with_context(|| format!("cannot read {}", p.display()))
    };
    let manifest_bytes = read("scene.json")?;
    let m = Manifest::decode("scene.json", &manifest_bytes).map_err(|e| anyhow::anyhow!("{e}"))?;
    let manifest = Sizes::of(&manifest_bytes)?;
    let mut tiles = Sizes::default();
    let mut ids = Sizes::default();
    let all_tiles = crate::format::index::read_all_tiles(dir, &m).map_err(anyhow::Error::msg)?;
    for t in &all_tiles {
        tiles.add(Sizes::of(&read(&t.url)?)?);
        ids.add(Sizes::of(&read(&t.ids_url)?)?);
    }
    let mut packs = Vec::new();
    for s in &m.species {
        let bytes = read(&s.pack)?;
        let bytes = crate::format::stored::unstore(&s.pack, bytes).map_err(|e| anyhow::anyhow!("{e}"))?;
        let pack = decode_pack(&s.pack, &bytes).map_err(|e| anyhow::anyhow!("{e}"))?;
        let gpu = pack.sections.iter().filter(|(e, _)| &e.kind != b"META").map(|(e, _)| e.bytes).sum();
        // (One season's billboards: a viewer holds the state it draws.)
        let billboard_gpu = pack
            .sections
            .iter()
            .filter(|(e, _)| (&e.kind == b"BBCO" || &e.kind == b"BBNO") && e.index == 0)
            .map(|(e, _)| e.bytes)
            .sum();
        let bb = pack.meta.billboards.as_ref();
        let cluster_levels = pack.meta.clusters.as_ref().map_or(0, |c| c.ellipsoid_levels.len() as u32);
        packs.push(PackMemory {
            name: s.name.clone(),
            file: Sizes::of(&bytes)?,
            gpu,
            billboard_gpu,
            // (Every mesh variant's views where the pack has them per variant.)
            billboard_views: bb.map_or(0, |b| b.angles * b.azimuths * b.variants.unwrap_or(1)),
            billboard_size: bb.map_or(0, |b| b.texture.size),
            levels: pack.meta.mesh_levels.len() as u32 + cluster_levels.min(4) + u32::from(bb.is_some()),
        });
    }
    let n = m.counts.trees;
    let t = m.counts.batches;
    let species = m.species.len() as u64;
    let mut fetched = manifest;
    fetched.add(tiles);
    for p in &packs {
        fetched.add(p.file);
    }
    let pack_gpu: u64 = packs.iter().map(|p| p.gpu).sum();
    let instance_gpu = 8 * n + 80 * t;
    // Eq. 4.1 with this scene's parameters (the largest per species where they differ).
    let a = packs.iter().map(|p| u64::from(p.billboard_views)).max().unwrap_or(0);
    let r = packs.iter().map(|p| u64::from(p.billboard_size)).max().unwrap_or(0);
    let l = packs.iter().map(|p| u64::from(p.levels)).max().unwrap_or(0);
    let eq41 = seed004_eq41(n, t, species, a, r, l);
    let billboards: u64 = packs.iter().map(|p| p.billboard_gpu).sum();
    Ok(MemoryModel {
        trees: n,
        batches: t,
        tiles: all_tiles.len() as u64,
        species,
        manifest,
        tiles_bytes: tiles,
        ids_bytes: ids,
        tile_bytes_per_tree: tiles.per(n),
        fetched_bytes_per_tree: fetched.per(n),
        packs,
        gpu_bytes_per_tree: instance_gpu as f64 / n.max(1) as f64,
        gpu_scene_bytes: instance_gpu + pack_gpu,
        gpu_pool_bytes: PoolConfig::default().bytes(),
        seed004_eq41_bytes: eq41,
        seed004_with_transforms_bytes: eq41 + 64 * n,
        sylva_comparable_bytes: instance_gpu + billboards,
    })
}

/// The model as a plain-text report.
#[must_use]
pub fn report(m: &MemoryModel) -> String {
    use std::fmt::Write as _;
    let mb = |b: u64| b as f64 / 1e6;
    let mut s = String::new();
    let _ = writeln!(s, "{} trees, {} batches, {} tiles, {} species", m.trees, m.batches, m.tiles, m.species);
    let _ = writeln!(s, "{:<28} {:>12} {:>12} {:>12}", "", "raw", "gzip -9", "brotli 11");
    let row = |s: &mut String, name: &str, v: Sizes| {
        let _ = writeln!(s, "{name:<28} {:>10.3} MB {:>9.3} MB {:>9.3} MB", mb(v.raw), mb(v.gzip), mb(v.brotli));
    };
    row(&mut s, "scene.json", m.manifest);
    row(&mut s, "tiles", m.tiles_bytes);
    row(&mut s, "ids (picking only)", m.ids_bytes);
    for p in &m.packs {
        row(&mut s, &format!("pack {}", p.name), p.file);
    }
    let per = |v: [f64; 3]| format!("{:>9.2} B {:>10.2} B {:>10.2} B", v[0], v[1], v[2]);
    let _ = writeln!(s, "{:<28} {}", "tile bytes per tree", per(m.tile_bytes_per_tree));
    let _ = writeln!(s, "{:<28} {}", "fetched per tree (all)", per(m.fetched_bytes_per_tree));
    let _ = writeln!(
        s,
        "GPU: {:.2} B per resident tree; scene fully resident {:.2} MB (packs {:.2} MB); pools preallocated {:.1} MB",
        m.gpu_bytes_per_tree,
        mb(m.gpu_scene_bytes),
        mb(m.packs.iter().map(|p| p.gpu).sum()),
        mb(m.gpu_pool_bytes)
    );
    let _ = writeln!(
        s,
        "Eichner 2024, eq. 4.1 for these n, t, m, a, r, l: {:.2} MB ({:.2} MB with its 64 B matrix per tree); Sylva's counterpart {:.2} MB",
        mb(m.seed004_eq41_bytes),
        mb(m.seed004_with_transforms_bytes),
        mb(m.sylva_comparable_bytes)
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eq41_matches_the_seeds_worked_example() {
        // Seed 004 §4.5.1: 9.2·10^5 trees, 500 batches, 5 meshes, 10 angles at
        // 128², 2 levels → "~16.9 MB".
        let b = seed004_eq41(920_000, 500, 5, 10, 128, 2);
        assert!((b as f64 / 1e6 - 16.9).abs() < 0.1, "{b}");
    }

    #[test]
    fn the_fixture_scene_is_measured() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/forest-small");
        let m = measure(&dir).unwrap();
        assert_eq!((m.trees, m.species), (3000, 3));
        // 8 B per instance plus headers and batch records.
        assert!((8.0..16.0).contains(&m.tile_bytes_per_tree[0]), "{:?}", m.tile_bytes_per_tree);
        assert!(m.tiles_bytes.brotli < m.tiles_bytes.raw && m.tiles_bytes.gzip < m.tiles_bytes.raw);
        assert!(m.packs.iter().all(|p| p.gpu > 0 && p.billboard_gpu > 0 && p.gpu < p.file.raw));
        assert!(report(&m).contains("eq. 4.1"));
        assert!(format!("{:#}", measure(Path::new("/nonexistent")).unwrap_err()).contains("scene.json"));
    }
}

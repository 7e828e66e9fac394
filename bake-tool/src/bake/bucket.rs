//! External partitioning of trees by tile, for bakes larger than memory: trees
//! are appended to one of N temporary bucket files by a hash of their tile, so
//! each bucket holds whole tiles and can be tiled on its own, in input order
//! (which keeps the output identical to tiling all trees at once).

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use glam::DVec3;

use crate::bake::batching::{tile_of, SceneTree};

/// A tree as stored in a bucket file (56 bytes, native endian: the file never
/// leaves the machine that wrote it).
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct TreeRecord {
    pos: [f64; 3],
    id: u64,
    scale: f32,
    yaw_rad: f32,
    species: u32,
    variation: u32,
    aspect: f32,
    row: u32,
}
const _: () = assert!(std::mem::size_of::<TreeRecord>() == 56);

impl From<&SceneTree> for TreeRecord {
    fn from(t: &SceneTree) -> Self {
        Self {
            pos: t.pos.to_array(),
            id: t.id,
            scale: t.scale,
            yaw_rad: t.yaw_rad,
            species: t.species,
            variation: u32::from(t.variation) | u32::from(t.dated) << 8,
            aspect: t.aspect,
            row: t.row,
        }
    }
}

impl From<&TreeRecord> for SceneTree {
    fn from(r: &TreeRecord) -> Self {
        Self {
            pos: DVec3::from_array(r.pos),
            species: r.species,
            scale: r.scale,
            aspect: r.aspect,
            yaw_rad: r.yaw_rad,
            variation: (r.variation & 0xff) as u8,
            id: r.id,
            row: r.row,
            dated: r.variation & 0x100 != 0,
        }
    }
}

/// The bucket (of `count`) of tile `(x, y)`: a hash unrelated to the shard hash.
#[must_use]
pub fn bucket_of_tile(x: i64, y: i64, count: u32) -> u32 {
    crate::bake::batching::tile_hash(x, y, 0xD6E8_FEB8_6659_FD93, 0xA076_1D64_78BD_642F, count)
}

/// Trees of a scene: in memory, or partitioned by tile into bucket files.
pub enum TreeSource {
    /// All trees at once.
    Memory(Vec<SceneTree>),
    /// Bucket files (each a whole number of tiles) and the trees in all.
    Buckets {
        /// The files, removed with their directory when the source is dropped.
        files: Vec<PathBuf>,
        /// Trees in all buckets.
        trees: u64,
        /// The temporary directory.
        dir: PathBuf,
    },
}

impl TreeSource {
    /// Whether there are no trees.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        match self {
            TreeSource::Memory(t) => t.is_empty(),
            TreeSource::Buckets { trees, .. } => *trees == 0,
        }
    }

    /// Trees in all.
    #[must_use]
    pub fn len(&self) -> u64 {
        match self {
            TreeSource::Memory(t) => t.len() as u64,
            TreeSource::Buckets { trees, .. } => *trees,
        }
    }

    /// Groups of trees holding whole tiles, one in memory at a time.
    pub fn for_each_group(&self, f: &mut dyn FnMut(&[SceneTree]) -> Result<()>) -> Result<()> {
        match self {
            TreeSource::Memory(t) => f(t),
            TreeSource::Buckets { files, .. } => {
                for path in files {
                    let bytes =
                        std::fs::read(path).with_context(|| format!("cannot read bucket {}", path.display()))?;
                    let records: Vec<TreeRecord> = bytemuck::pod_collect_to_vec(&bytes);
                    let trees: Vec<SceneTree> = records.iter().map(SceneTree::from).collect();
                    drop(records);
                    f(&trees)?;
                }
                Ok(())
            }
        }
    }
}

impl Drop for TreeSource {
    fn drop(&mut self) {
        if let TreeSource::Buckets { dir, .. } = self {
            let _ = std::fs::remove_dir_all(dir);
        }
    }
}

/// Appends trees to `count` bucket files under `dir` by their tile.
pub struct BucketWriter {
    dir: PathBuf,
    writers: Vec<std::io::BufWriter<std::fs::File>>,
    cell_size_m: u32,
    tile_cells: u32,
    trees: u64,
}

impl BucketWriter {
    /// Creates `dir` (emptied) and `count` bucket files in it.
    pub fn new(dir: &Path, count: u32, cell_size_m: u32, tile_cells: u32) -> Result<Self> {
        let _ = std::fs::remove_dir_all(dir);
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let writers = (0..count)
            .map(|i| {
                let p = dir.join(format!("bucket-{i}.bin"));
                std::fs::File::create(&p)
                    .map(|f| std::io::BufWriter::with_capacity(1 << 16, f))
                    .with_context(|| format!("cannot create {}", p.display()))
            })
            .collect::<Result<_>>()?;
        Ok(Self { dir: dir.to_path_buf(), writers, cell_size_m, tile_cells, trees: 0 })
    }

    /// Appends one tree to its tile's bucket.
    pub fn push(&mut self, t: &SceneTree) -> Result<()> {
        let (x, y) = tile_of(t.pos, self.cell_size_m, self.tile_cells);
        let b = bucket_of_tile(x, y, self.writers.len() as u32) as usize;
        let rec = TreeRecord::from(t);
        self.writers[b].write_all(bytemuck::bytes_of(&rec)).context("cannot write a bucket file (disk full?)")?;
        self.trees += 1;
        Ok(())
    }

    /// Flushes the files; the source removes them when dropped.
    pub fn finish(self) -> Result<TreeSource> {
        let mut files = Vec::new();
        for (i, mut w) in self.writers.into_iter().enumerate() {
            w.flush().context("cannot write a bucket file (disk full?)")?;
            files.push(self.dir.join(format!("bucket-{i}.bin")));
        }
        Ok(TreeSource::Buckets { files, trees: self.trees, dir: self.dir })
    }
}

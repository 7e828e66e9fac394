//! What the streamer needs of the place where tiles and packs live (the GPU
//! pools of [`crate::render::forest::ForestRenderer`], or a fake in tests): the
//! streamer defines this interface and the renderer implements it, so the scene
//! layer never imports the render layer and streams without a GPU in tests.

use std::ops::Range;

use crate::format::pack::PACK_PARTS;
use crate::format::{Pack, PackMeta, Tile};

/// Where a resident tile lives in the pools.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TileSlot {
    /// Batch pool range.
    pub batches: Range<u32>,
    /// Instance pool range.
    pub instances: Range<u32>,
    /// Instances per species (index, count), to keep residency counts.
    pub species_counts: Vec<(u32, u32)>,
}

/// Why a tile could not be made resident.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PoolError {
    /// Not enough contiguous room: evict something and retry.
    #[error("the GPU pools are full ({0})")]
    Full(&'static str),
    /// A batch names a species the renderer was not told about.
    #[error("batch species {0} is outside the scene's species list")]
    UnknownSpecies(u32),
}

/// Resident storage for a streamed scene: tiles in pools, species packs, and
/// what the current view can need of each pack.
pub trait Residency {
    /// Species the residency can hold at most.
    fn species_capacity(&self) -> u32;
    /// A scene's manifest arrived: size the pools for `trees` in `batches` of
    /// `species` species (never beyond the device) and drop any loaded packs.
    fn begin_scene(&mut self, trees: u64, batches: u64, species: u32);
    /// Makes a tile resident.
    ///
    /// # Errors
    /// [`PoolError::Full`] when there is no room (nothing changed), or
    /// [`PoolError::UnknownSpecies`].
    fn upload_tile(&mut self, tile: &Tile) -> Result<TileSlot, PoolError>;
    /// Gives a resident tile's room back.
    fn evict_tile(&mut self, slot: TileSlot);
    /// Makes (a part-assembled or whole) pack resident as species `species`.
    fn upload_pack(&mut self, species: u32, pack: &Pack<'_>);
    /// Which parts of species `species`' pack ([`crate::format::pack::PackPart::ALL`]
    /// order) the resident trees within reach of the current view can need.
    fn parts_needed(&self, species: usize, meta: &PackMeta) -> [bool; PACK_PARTS];
    /// Free and total instance slots.
    fn instance_room(&self) -> (u32, u32);
    /// Bytes held (pools and packs), for the GPU budget.
    fn bytes(&self) -> u64;
    /// Whether the pools were cut down to the device's limits.
    fn limited_by_device(&self) -> bool;
}

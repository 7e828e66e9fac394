//! Tile files (`tiles/<x>_<y>.tile`): grouped batches of tree instances.
//!
//! A tile holds the batches (grid cell × species, Eichner 2024, §3.4) of a square
//! group of grid cells. Each batch has bounds for culling and a run of
//! 8-byte instance records quantised relative to the batch origin. The batch
//! and instance arrays are laid out exactly as the GPU reads them, so the
//! renderer uploads them without repacking. Layout tables: `docs/FORMAT.md`.
//!
//! Versions 3 and 4 store the instances in prefix levels: level ℓ holds each
//! density-ordered batch's next trees up to a share of it ([`Levels`]), so
//! the first bytes of the file up to a level's end are an even thinning of
//! every batch, and a far view fetches that byte range only
//! ([`Tile::decode_prefix`]). Version 3 steps the shares by 2 for every
//! batch; version 4 by √2, scaled for batches shorter than the tile's tallest
//! (a view needs fewer of them at the same distance).

use super::error::{at_most, finite_all, pod_vec, DecodeError, Problem, Reader};

/// First four bytes of a tile file.
pub const TILE_MAGIC: [u8; 4] = *b"SYTL";
/// Newest tile format version written and read by this build: 4, the
/// instances in prefix levels of √2 steps scaled by each batch's height
/// ([`Tile::encode`], [`Levels`]). Version 3 (levels of 2× steps) is still
/// read by range; versions 1 and 2 (one run of instances per batch; 2 when a
/// batch carries crown aspects) whole.
pub const TILE_VERSION: u16 = 4;
/// Oldest tile format version this build reads.
pub const TILE_VERSION_MIN: u16 = 1;
/// Bytes in the tile header.
pub const TILE_HEADER_BYTES: usize = 32;
/// Most batches one tile may declare (decoders refuse more before allocating).
pub const MAX_TILE_BATCHES: u32 = 1 << 20;
/// Most instances one tile may declare.
pub const MAX_TILE_INSTANCES: u32 = 1 << 26;
/// Prefix levels this build writes (version 4, [`Levels`]): the tile's
/// tallest batch ends at `2^((ℓ+1−L)/2)` of its trees at level ℓ: 1/128,
/// 1/91, 1/64 (the least prefix thinning keeps, `THIN_MIN_FRACTION` in
/// `shaders/layout.wgsl`), …, 1/√2, all — the canopy cross-fade keeps fewer
/// than 1/64 where trees are about a pixel tall.
pub const TILE_LEVELS: u32 = 15;
/// Prefix levels version 3 tiles were written with: 1/64, 1/32, …, ½, all.
pub const TILE_LEVELS_V3: u32 = 7;
/// Most prefix levels a tile may declare.
pub const MAX_TILE_LEVELS: u32 = 16;
/// Largest batch split into levels: bigger ones (and batches that are not
/// density-ordered) lie whole in level 0.
pub const MAX_PARTIAL_BATCH: u32 = (1 << 24) - 1;

/// Bits of the quantised height above the batch origin.
pub const Z_BITS: u32 = 11;
/// Bits of the quantised yaw.
pub const YAW_BITS: u32 = 8;
/// Bits of the quantised log2 scale.
pub const SCALE_BITS: u32 = 8;
/// Bits of the tint/variation index.
pub const VARIATION_BITS: u32 = 5;
/// Bits of the quantised crown aspect (they replace the variation bits in a
/// [`BATCH_CROWN_ASPECT`] batch).
pub const CROWN_BITS: u32 = 5;
/// Largest horizontal quantisation step: keeps position error ≤ 0.5 cm.
pub const MAX_XY_STEP_M: f32 = 0.01;
/// Largest vertical quantisation step: height error ≤ 0.8 cm, so with the
/// horizontal error the 3D position error stays ≤ 1 cm.
pub const MAX_Z_STEP_M: f32 = 0.016;

/// One batch: the trees of one species in one grid cell (Eichner 2024, §3.4).
///
/// Must match `Batch` in `shaders/layout.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuBatch {
    /// Quantisation origin, metres relative to the scene origin (cell corner at the lowest ground).
    pub origin_m: [f32; 3],
    /// First instance of this batch within the tile.
    pub instance_offset: u32,
    /// Bounding-sphere centre (trunk bases to tree tops), metres relative to the scene origin.
    pub center_m: [f32; 3],
    /// Bounding-sphere radius in metres.
    pub radius_m: f32,
    /// Half size of the axis-aligned bounding box around `center_m`.
    pub half_extent_m: [f32; 3],
    /// Number of instances.
    pub instance_count: u32,
    /// Index into the manifest's species list.
    pub species: u32,
    /// Metres per step of the quantised x and y.
    pub xy_step_m: f32,
    /// Metres per step of the quantised z.
    pub z_step_m: f32,
    /// Scale of quantised scale 0.
    pub scale_min: f32,
    /// log2 of the scale ratio between consecutive quantised scales.
    pub scale_log2_step: f32,
    /// Height of the tallest tree of the batch in metres.
    pub max_height_m: f32,
    /// Flags ([`BATCH_DENSITY_ORDERED`], [`BATCH_CROWN_ASPECT`]).
    pub flags: u32,
    /// Crown aspect range of a [`BATCH_CROWN_ASPECT`] batch (zero otherwise):
    /// bits 0–15 the smallest aspect in 1/8192, bits 16–31 the log2 ratio
    /// between consecutive quantised aspects in 1/65536 (see [`CrownRange`]).
    pub crown: u32,
}

/// Batch flag (in `flags`): the instances are density-ordered, so every
/// prefix is an even thinning of the whole (prefix thinning may draw fewer).
pub const BATCH_DENSITY_ORDERED: u32 = 1;
/// Batch flag (in `flags`, tile version 2): the top 5 bits of each instance's
/// word 1 are its crown aspect (crown width over height, relative to the
/// species model) instead of its variation, and the variation is a hash of
/// its position ([`variation_of`]).
pub const BATCH_CROWN_ASPECT: u32 = 2;
/// Batch flag (in `flags`): the trees are not standing at the scene's latest
/// date (a census's dead or removed trees, trees planted later): drawn,
/// picked and counted only at a date ([`crate::format::timeline`]).
pub const BATCH_DATED: u32 = 8;
/// Every batch flag a tile file may carry.
pub const BATCH_FLAGS: u32 = BATCH_DENSITY_ORDERED | BATCH_CROWN_ASPECT | BATCH_DATED;
/// Batch flag of a tile decoded from a prefix of its file, in memory and on
/// the GPU only (refused in files): `instance_count` is the resident prefix
/// and bits [`PARTIAL_COUNT_SHIFT`]–31 the batch's whole count, which prefix
/// thinning and its coverage boost count with.
pub const BATCH_PARTIAL: u32 = 4;
/// Shift of a [`BATCH_PARTIAL`] batch's whole count in its flags.
pub const PARTIAL_COUNT_SHIFT: u32 = 8;

impl GpuBatch {
    /// The batch's whole tree count: `instance_count`, or for a
    /// [`BATCH_PARTIAL`] batch the count its flags carry.
    #[must_use]
    pub fn whole_count(&self) -> u32 {
        if self.flags & BATCH_PARTIAL != 0 {
            self.flags >> PARTIAL_COUNT_SHIFT
        } else {
            self.instance_count
        }
    }
}

/// How a tile file's prefix levels split its batches: which trees of each
/// batch the first `level + 1` levels hold ([`Levels::prefix`]). Computed from
/// the file's version, level count and batch records alone (no bytes stored),
/// with only exactly rounded arithmetic, so every reader splits alike.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Levels {
    /// The tile's version: 3 (2× steps, every batch alike) or 4 (√2 steps,
    /// scaled by each batch's height).
    pub version: u16,
    /// Levels in the file (1–[`MAX_TILE_LEVELS`]).
    pub count: u32,
    /// The tile's tallest tree in metres (the most of its batches'
    /// `max_height_m`): version 4 scales the other batches' shares by their
    /// height to it.
    pub tallest_m: f32,
}

impl Levels {
    /// The levels of a tile of `version` with `count` levels and these batches
    /// (whole or resident: their heights are the same).
    #[must_use]
    pub fn new(version: u16, count: u32, batches: &[GpuBatch]) -> Self {
        let tallest_m = batches.iter().map(|b| b.max_height_m).fold(0.0f32, f32::max);
        Self { version, count, tallest_m }
    }

    /// The share of the tile's tallest batch that levels `0..=level` hold:
    /// `2^(level+1−count)` (version 3) or `2^((level+1−count)/2)` (version 4);
    /// 1 from the last level on.
    #[must_use]
    pub fn share(&self, level: u32) -> f64 {
        if level + 1 >= self.count {
            return 1.0;
        }
        let steps = self.count - 1 - level;
        let (halvings, root) = if self.version >= 4 { (steps / 2, steps % 2 == 1) } else { (steps, false) };
        // Powers of two (built from their bits) and one factor 1/√2: exact, or
        // one correctly rounded product.
        let base = if halvings >= 1000 { 0.0 } else { f64::from_bits(u64::from(1023 - halvings) << 52) };
        if root {
            base * std::f64::consts::FRAC_1_SQRT_2
        } else {
            base
        }
    }

    /// Trees of `batch` (its whole count `n`) in the prefix of levels
    /// `0..=level`: all of them at the last level and for batches that are not
    /// density-ordered or bigger than [`MAX_PARTIAL_BATCH`]; else version 3
    /// `ceil(n · share)`, version 4 `ceil(n · max(share · r², min(share, 1/64)))`
    /// (at least 1) with `r` the batch's `max_height_m` over the tile's
    /// tallest — a view needs `r²` as many of a shorter batch's trees at the
    /// same distance, and never fewer than 1/64 where it needs that many of
    /// the tallest (prefix thinning keeps at least 1/64 of a batch in view).
    #[must_use]
    pub fn prefix(&self, batch: &GpuBatch, level: u32) -> u32 {
        let n = batch.instance_count;
        if level + 1 >= self.count || batch.flags & BATCH_DENSITY_ORDERED == 0 || n > MAX_PARTIAL_BATCH {
            return n;
        }
        if self.version < 4 {
            let halvings = self.count - 1 - level;
            if halvings >= 32 {
                return n.min(1);
            }
            return ((u64::from(n) + (1u64 << halvings) - 1) >> halvings) as u32;
        }
        let share = self.share(level);
        let r = if self.tallest_m > 0.0 {
            (f64::from(batch.max_height_m) / f64::from(self.tallest_m)).min(1.0)
        } else {
            1.0
        };
        let f = (share * r * r).max(share.min(1.0 / 64.0));
        ((f64::from(n) * f).ceil() as u32).clamp(1, n)
    }

    /// The fewest levels (1..=count) whose share of the tallest batch is at
    /// least `f` (all of them for `f` above the last but one, or NaN).
    #[must_use]
    pub fn covering(&self, f: f32) -> u32 {
        (0..self.count).find(|&l| self.share(l) >= f64::from(f)).map_or(self.count, |l| l + 1)
    }
}

/// The crown aspects of a [`BATCH_CROWN_ASPECT`] batch: quantised aspect q
/// (0–31) means `min · 2^(q · log2_step)`, both fixed-point in [`GpuBatch::crown`]
/// so that the CPU and every GPU decode the same f32.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CrownRange {
    /// Smallest aspect, 1/8192 steps (up to 8).
    pub min_q: u16,
    /// log2 ratio between consecutive quantised aspects, 1/65536 steps (up to 1).
    pub log2_step_q: u16,
}

impl CrownRange {
    /// The range packed in a batch's `crown` word.
    #[must_use]
    pub fn unpack(word: u32) -> Self {
        Self { min_q: (word & 0xffff) as u16, log2_step_q: (word >> 16) as u16 }
    }

    /// The batch's `crown` word.
    #[must_use]
    pub fn pack(self) -> u32 {
        u32::from(self.min_q) | u32::from(self.log2_step_q) << 16
    }

    /// The smallest range holding aspects `lo..=hi`: the smallest aspect is
    /// clamped to 1/8192–8 (not finite or not positive: 1/8192), the step to
    /// at most an octave (a top aspect up to 2^31 times the smallest).
    #[must_use]
    pub fn covering(lo: f32, hi: f32) -> Self {
        let lo = if lo.is_finite() && lo > 0.0 { lo } else { 1.0 / 8192.0 };
        let hi = if hi.is_finite() { hi } else { lo };
        let min_q = (lo * 8192.0).floor().clamp(1.0, 65535.0) as u16;
        let min = f32::from(min_q) / 8192.0;
        let levels = ((1u32 << CROWN_BITS) - 1) as f32;
        let step = (hi.max(min) / min).log2() / levels;
        Self { min_q, log2_step_q: (step * 65536.0).ceil().clamp(0.0, 65535.0) as u16 }
    }

    /// Aspect of quantised value `q` (as `unpack_instance` in WGSL computes it).
    #[must_use]
    pub fn aspect(self, q: u32) -> f32 {
        f32::from(self.min_q) / 8192.0 * (q as f32 * (f32::from(self.log2_step_q) / 65536.0)).exp2()
    }

    /// The quantised value nearest to `aspect` (in log2).
    #[must_use]
    pub fn quantise(self, aspect: f32) -> u32 {
        let step = f32::from(self.log2_step_q) / 65536.0;
        let levels = ((1u32 << CROWN_BITS) - 1) as f32;
        if step <= 0.0 {
            return 0;
        }
        ((aspect / (f32::from(self.min_q) / 8192.0)).log2() / step).round().clamp(0.0, levels) as u32
    }
}

/// Variation (0–31) of an instance of a [`BATCH_CROWN_ASPECT`] batch: a hash of
/// its quantised position word (as `variation_of` in WGSL).
#[must_use]
pub fn variation_of(xy: u32) -> u32 {
    xy.wrapping_mul(0x9E37_79B1) >> (32 - VARIATION_BITS)
}
const _: () = assert!(std::mem::size_of::<GpuBatch>() == 80);

/// One tree: 8 bytes, relative to its batch origin.
///
/// Word 0: x (bits 0–15), y (16–31) in `xy_step_m` steps.
/// Word 1: z (bits 0–10) in `z_step_m` steps, yaw (11–18) in 1/256 turns,
/// scale (19–26) in `scale_log2_step` steps above `scale_min`, variation (27–31)
/// — or, in a [`BATCH_CROWN_ASPECT`] batch, the crown aspect (27–31) of the batch's [`CrownRange`].
/// Must match `unpack_instance` in `shaders/instance.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PackedInstance {
    /// x | y << 16.
    pub xy: u32,
    /// z | yaw << 11 | scale << 19 | variation << 27.
    pub zysv: u32,
}
const _: () = assert!(std::mem::size_of::<PackedInstance>() == 8);

/// A tree decoded from a [`PackedInstance`], in metres relative to the scene origin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Instance {
    /// Trunk base position.
    pub position_m: [f32; 3],
    /// Rotation about the up axis in radians, in `[0, 2π)`.
    pub yaw_rad: f32,
    /// Scale applied to the species model (its height).
    pub scale: f32,
    /// Horizontal over vertical scale: the crown width relative to the
    /// model's at this height (1 unless the batch has [`BATCH_CROWN_ASPECT`]).
    pub aspect: f32,
    /// Tint/variation index, 0–31.
    pub variation: u8,
}

impl PackedInstance {
    /// Packs quantised fields; each is masked to its bit width.
    #[must_use]
    pub fn new(x: u16, y: u16, z: u32, yaw: u32, scale: u32, variation: u32) -> Self {
        let mask = |v: u32, bits: u32| v & ((1 << bits) - 1);
        Self {
            xy: u32::from(x) | (u32::from(y) << 16),
            zysv: mask(z, Z_BITS)
                | (mask(yaw, YAW_BITS) << Z_BITS)
                | (mask(scale, SCALE_BITS) << (Z_BITS + YAW_BITS))
                | (mask(variation, VARIATION_BITS) << (Z_BITS + YAW_BITS + SCALE_BITS)),
        }
    }

    /// Decodes the instance relative to the scene origin using its batch.
    #[must_use]
    pub fn decode(self, batch: &GpuBatch) -> Instance {
        let x = (self.xy & 0xffff) as f32;
        let y = (self.xy >> 16) as f32;
        let z = (self.zysv & ((1 << Z_BITS) - 1)) as f32;
        let yaw = (self.zysv >> Z_BITS) & ((1 << YAW_BITS) - 1);
        let scale = (self.zysv >> (Z_BITS + YAW_BITS)) & ((1 << SCALE_BITS) - 1);
        let top = self.zysv >> (Z_BITS + YAW_BITS + SCALE_BITS);
        let (aspect, variation) = if batch.flags & BATCH_CROWN_ASPECT != 0 {
            (CrownRange::unpack(batch.crown).aspect(top), variation_of(self.xy))
        } else {
            (1.0, top)
        };
        Instance {
            position_m: [
                batch.origin_m[0] + x * batch.xy_step_m,
                batch.origin_m[1] + y * batch.xy_step_m,
                batch.origin_m[2] + z * batch.z_step_m,
            ],
            yaw_rad: yaw as f32 * (std::f32::consts::TAU / (1 << YAW_BITS) as f32),
            scale: batch.scale_min * (scale as f32 * batch.scale_log2_step).exp2(),
            aspect,
            variation: variation as u8,
        }
    }
}

/// A decoded tile: its grid position, batches and instances.
#[derive(Debug, Clone, PartialEq)]
pub struct Tile {
    /// Tile column in the scene's tile grid.
    pub tile_x: i32,
    /// Tile row in the scene's tile grid.
    pub tile_y: i32,
    /// Batches, in instance order.
    pub batches: Vec<GpuBatch>,
    /// All instances of all batches.
    pub instances: Vec<PackedInstance>,
}

/// A tile decoded from a prefix of its file ([`Tile::decode_prefix`]).
#[derive(Debug, Clone, PartialEq)]
pub struct TilePrefix {
    /// The resident trees: each batch's first `instance_count`, batch after
    /// batch; batches holding less than their whole count carry
    /// [`BATCH_PARTIAL`]. The whole tile when `levels == of`.
    pub tile: Tile,
    /// Levels held.
    pub levels: u32,
    /// Levels in the file (1 for versions 1 and 2).
    pub of: u32,
    /// How the file's levels split its batches.
    pub scheme: Levels,
}

impl TilePrefix {
    /// Per batch with fewer trees resident than it has, `[resident start,
    /// resident count, start in the whole tile]` (instance indices): maps a
    /// resident instance to its index in the tile's instance order (that of
    /// `.ids` and `.attr`). Empty for a whole tile.
    #[must_use]
    pub fn runs(&self) -> Vec<[u32; 3]> {
        if self.levels >= self.of {
            return Vec::new();
        }
        let mut whole = 0;
        self.tile
            .batches
            .iter()
            .map(|b| {
                let run = [b.instance_offset, b.instance_count, whole];
                whole += b.whole_count();
                run
            })
            .collect()
    }
}

impl TilePrefix {
    /// The batches as the file has them (whole counts, no [`BATCH_PARTIAL`];
    /// instance offsets those of the resident trees) of a file in levels (what
    /// decides the levels a view wants, more or fewer); empty for a file
    /// without levels.
    #[must_use]
    pub fn whole_batches(&self) -> Vec<GpuBatch> {
        if self.of <= 1 {
            return Vec::new();
        }
        let mask = BATCH_PARTIAL | (u32::MAX << PARTIAL_COUNT_SHIFT);
        self.tile
            .batches
            .iter()
            .map(|b| GpuBatch { instance_count: b.whole_count(), flags: b.flags & !mask, ..*b })
            .collect()
    }
}

/// The index in the whole tile's instance order of resident instance `i`, for
/// a tile's [`TilePrefix::runs`] (the identity for none).
#[must_use]
pub fn whole_index(runs: &[[u32; 3]], i: u32) -> u32 {
    if runs.is_empty() {
        return i;
    }
    let k = runs.partition_point(|r| r[0] <= i).saturating_sub(1);
    runs.get(k).map_or(i, |r| r[2] + (i - r[0]))
}

impl Tile {
    /// The version [`Tile::encode`] writes: 3.
    #[must_use]
    pub fn version(&self) -> u16 {
        TILE_VERSION
    }

    /// The version [`Tile::encode_whole`] writes: 2 if a batch carries crown aspects, else 1.
    #[must_use]
    pub fn whole_version(&self) -> u16 {
        if self.batches.iter().any(|b| b.flags & BATCH_CROWN_ASPECT != 0) {
            2
        } else {
            1
        }
    }

    /// The levels [`Tile::encode`] writes ([`TILE_LEVELS`] of version 4).
    #[must_use]
    pub fn levels(&self) -> Levels {
        Levels::new(TILE_VERSION, TILE_LEVELS, &self.batches)
    }

    /// Instances in the prefix of levels `0..=l` for each level `l` of
    /// `levels` (cumulative; the last is all).
    #[must_use]
    pub fn level_counts(&self, levels: &Levels) -> Vec<u32> {
        (0..levels.count).map(|l| self.batches.iter().map(|b| levels.prefix(b, l)).sum()).collect()
    }

    /// File bytes up to the end of each level of the file [`Tile::encode`]
    /// writes: the byte ranges a viewer fetches.
    #[must_use]
    pub fn level_bytes(&self) -> Vec<u64> {
        let levels = self.levels();
        let head = (TILE_HEADER_BYTES + self.batches.len() * 80 + 4 + 4 * levels.count as usize) as u64;
        self.level_counts(&levels).iter().map(|&c| head + 8 * u64::from(c)).collect()
    }

    /// Encodes the tile into its version 4 file bytes ([`Tile::levels`]):
    /// header, batches, the level table (level count, then each level's
    /// cumulative instance count), then the instances level after level, in
    /// each level batch after batch.
    #[must_use]
    pub fn encode(&self) -> Vec<u8> {
        self.encode_levels(&self.levels())
    }

    /// Encodes the tile as version 3 wrote it ([`TILE_LEVELS_V3`] levels of 2×
    /// steps): for tests that scenes baked before still read.
    #[must_use]
    pub fn encode_v3(&self) -> Vec<u8> {
        self.encode_levels(&Levels::new(3, TILE_LEVELS_V3, &self.batches))
    }

    fn encode_levels(&self, levels: &Levels) -> Vec<u8> {
        let counts = self.level_counts(levels);
        let mut out = self.encode_head(levels.version, 4 + 4 * counts.len());
        out.extend_from_slice(&levels.count.to_le_bytes());
        for c in &counts {
            out.extend_from_slice(&c.to_le_bytes());
        }
        for l in 0..levels.count {
            for b in &self.batches {
                let from = if l == 0 { 0 } else { levels.prefix(b, l - 1) };
                let to = levels.prefix(b, l);
                let start = b.instance_offset as usize;
                out.extend_from_slice(bytemuck::cast_slice(
                    &self.instances[start + from as usize..start + to as usize],
                ));
            }
        }
        out
    }

    /// Encodes the tile as versions 1 and 2 wrote it (each batch's instances in
    /// one run; [`Tile::whole_version`]): for tests that old scenes still read.
    #[must_use]
    pub fn encode_whole(&self) -> Vec<u8> {
        let mut out = self.encode_head(self.whole_version(), 0);
        out.extend_from_slice(bytemuck::cast_slice(&self.instances));
        out
    }

    fn encode_head(&self, version: u16, table_bytes: usize) -> Vec<u8> {
        let mut out = Vec::with_capacity(
            TILE_HEADER_BYTES
                + self.batches.len() * std::mem::size_of::<GpuBatch>()
                + table_bytes
                + self.instances.len() * 8,
        );
        out.extend_from_slice(&TILE_MAGIC);
        out.extend_from_slice(&version.to_le_bytes());
        out.extend_from_slice(&(TILE_HEADER_BYTES as u16).to_le_bytes());
        out.extend_from_slice(&(self.batches.len() as u32).to_le_bytes());
        out.extend_from_slice(&(self.instances.len() as u32).to_le_bytes());
        out.extend_from_slice(&self.tile_x.to_le_bytes());
        out.extend_from_slice(&self.tile_y.to_le_bytes());
        out.extend_from_slice(&(std::mem::size_of::<GpuBatch>() as u16).to_le_bytes());
        out.extend_from_slice(&(std::mem::size_of::<PackedInstance>() as u16).to_le_bytes());
        out.extend_from_slice(&0u32.to_le_bytes());
        out.extend_from_slice(bytemuck::cast_slice(&self.batches));
        out
    }

    /// Decodes and validates tile bytes. `file` names the file in errors;
    /// `species_count` is the manifest's species count (batches must index it).
    ///
    /// # Errors
    /// A [`DecodeError`] for a wrong magic or version, a size that does not match
    /// the declared counts, a count above the format's limits, a non-finite or
    /// negative bound, a batch whose instance run is outside the tile or out of
    /// order, or an unknown species.
    pub fn decode(file: &str, bytes: &[u8], species_count: u32) -> Result<Self, DecodeError> {
        decode_tile(bytes, species_count, false).map(|p| p.tile).map_err(|p| DecodeError::new(file, p))
    }

    /// Decodes the first bytes of a tile file, up to the end of one of its
    /// levels ([`Tile::level_bytes`]; all of them for versions 1 and 2): the
    /// trees held, batches holding a prefix marked [`BATCH_PARTIAL`].
    ///
    /// # Errors
    /// As [`Tile::decode`], and for a length that is not a level's end.
    pub fn decode_prefix(file: &str, bytes: &[u8], species_count: u32) -> Result<TilePrefix, DecodeError> {
        decode_tile(bytes, species_count, true).map_err(|p| DecodeError::new(file, p))
    }

    /// Bytes of the instance records (what "bytes per tree" counts).
    #[must_use]
    pub fn instance_bytes(&self) -> usize {
        self.instances.len() * std::mem::size_of::<PackedInstance>()
    }
}

fn decode_tile(bytes: &[u8], species_count: u32, prefix: bool) -> Result<TilePrefix, Problem> {
    let r = Reader::new(bytes);
    r.magic("Sylva tile", &TILE_MAGIC)?;
    let version = r.u16("header.version", 4)?;
    if !(TILE_VERSION_MIN..=TILE_VERSION).contains(&version) {
        return Err(Problem::UnsupportedVersion { found: version.into(), supported: TILE_VERSION.into() });
    }
    let header_bytes = r.u16("header.header_bytes", 6)?;
    if usize::from(header_bytes) != TILE_HEADER_BYTES {
        return Err(Problem::Invalid(format!("header.header_bytes is {header_bytes}, expected {TILE_HEADER_BYTES}")));
    }
    let batch_count = at_most("header.batch_count", r.u32("header.batch_count", 8)?.into(), MAX_TILE_BATCHES.into())?;
    let instance_count =
        at_most("header.instance_count", r.u32("header.instance_count", 12)?.into(), MAX_TILE_INSTANCES.into())?;
    let tile_x = r.i32("header.tile_x", 16)?;
    let tile_y = r.i32("header.tile_y", 20)?;
    let batch_stride = r.u16("header.batch_stride", 24)?;
    let instance_stride = r.u16("header.instance_stride", 26)?;
    if usize::from(batch_stride) != std::mem::size_of::<GpuBatch>()
        || usize::from(instance_stride) != std::mem::size_of::<PackedInstance>()
    {
        return Err(Problem::Invalid(format!(
            "record sizes batch={batch_stride} instance={instance_stride}, expected 80 and 8"
        )));
    }
    let flags = r.u32("header.flags", 28)?;
    if flags != 0 {
        return Err(Problem::Invalid(format!(
            "header.flags is {flags:#x}; tile versions 1 to 4 define no header flags (must be 0)"
        )));
    }
    let batch_start = TILE_HEADER_BYTES as u64;
    let batch_len = batch_count * 80;
    // Version 3: the level table after the batches.
    let (levels, table_len) = if version >= 3 {
        let at = batch_start + batch_len;
        let levels = r.u32("levels.count", at)?;
        if !(1..=MAX_TILE_LEVELS).contains(&levels) {
            return Err(Problem::OutOfRange {
                what: "levels.count".into(),
                value: levels.into(),
                allowed: format!("1 to {MAX_TILE_LEVELS}"),
            });
        }
        (levels, 4 + 4 * u64::from(levels))
    } else {
        (1, 0)
    };
    let instance_start = batch_start + batch_len + table_len;
    let instance_len = instance_count * 8;
    let end = instance_start + instance_len;
    let level_ends: Vec<u64> = if version >= 3 {
        (0..levels)
            .map(|l| {
                let c = r.u32("levels.counts", batch_start + batch_len + 4 + 4 * u64::from(l))?;
                Ok(instance_start + 8 * u64::from(c))
            })
            .collect::<Result<_, Problem>>()?
    } else {
        vec![end]
    };
    // A prefix ends where a level does (the last of the levels ending there:
    // levels adding no trees end where the one before does).
    let held = match level_ends.iter().rposition(|&e| e == bytes.len() as u64) {
        Some(l) if prefix && level_ends.last() == Some(&end) => l as u32 + 1,
        _ => levels,
    };
    let end = if held < levels { bytes.len() as u64 } else { end };
    // Check the whole size before allocating anything from the counts.
    if end != bytes.len() as u64 {
        return Err(if end > bytes.len() as u64 {
            Problem::Truncated {
                what: format!("{batch_count} batches and {instance_count} instances"),
                start: 0,
                end,
                len: bytes.len() as u64,
            }
        } else {
            Problem::Invalid(format!(
                "{} trailing bytes after {batch_count} batches and {instance_count} instances",
                bytes.len() as u64 - end
            ))
        });
    }
    let batches: Vec<GpuBatch> = pod_vec(r.slice("batches", batch_start, batch_len)?);
    let mut next = 0u64;
    for (i, b) in batches.iter().enumerate() {
        if version < 2 && b.flags & BATCH_CROWN_ASPECT != 0 {
            return Err(Problem::Invalid(format!(
                "batch[{i}] has crown aspects (flag {BATCH_CROWN_ASPECT}), which need tile version 2; this tile is version {version}"
            )));
        }
        validate_batch(i, b, species_count)?;
        if u64::from(b.instance_offset) != next {
            return Err(Problem::Invalid(format!(
                "batch[{i}].instance_offset is {}, expected {next}: batches must cover the instances in order",
                b.instance_offset
            )));
        }
        next += u64::from(b.instance_count);
    }
    if next != instance_count {
        return Err(Problem::Invalid(format!(
            "batches hold {next} instances but the header declares {instance_count}"
        )));
    }
    let scheme = Levels::new(version, levels, &batches);
    if version < 3 {
        let instances = pod_vec(r.slice("instances", instance_start, instance_len)?);
        return Ok(TilePrefix { tile: Tile { tile_x, tile_y, batches, instances }, levels: 1, of: 1, scheme });
    }
    // The level table must be what the batches' counts give.
    for (l, &e) in level_ends.iter().enumerate() {
        let want: u64 = batches.iter().map(|b| u64::from(scheme.prefix(b, l as u32))).sum();
        if e != instance_start + 8 * want {
            return Err(Problem::Invalid(format!(
                "levels.counts[{l}] is {}, the batches' level {l} prefixes hold {want}",
                (e - instance_start) / 8
            )));
        }
    }
    // Gather each batch's trees from the levels held, batch after batch.
    let held_bytes = r.slice("instances", instance_start, end - instance_start)?;
    let stored: Vec<PackedInstance> = pod_vec(held_bytes);
    let resident: Vec<u32> = batches.iter().map(|b| scheme.prefix(b, held - 1)).collect();
    let mut starts = Vec::with_capacity(batches.len());
    let mut at = 0u32;
    for &k in &resident {
        starts.push(at);
        at += k;
    }
    let mut instances = vec![PackedInstance::default(); at as usize];
    let mut from = 0usize;
    for l in 0..held {
        for (i, b) in batches.iter().enumerate() {
            let lo = if l == 0 { 0 } else { scheme.prefix(b, l - 1) };
            let hi = scheme.prefix(b, l);
            let n = (hi - lo) as usize;
            let dst = (starts[i] + lo) as usize;
            instances[dst..dst + n].copy_from_slice(&stored[from..from + n]);
            from += n;
        }
    }
    let batches = batches
        .into_iter()
        .zip(resident.iter().zip(&starts))
        .map(|(b, (&k, &start))| {
            if k < b.instance_count {
                GpuBatch {
                    instance_offset: start,
                    instance_count: k,
                    flags: b.flags | BATCH_PARTIAL | (b.instance_count << PARTIAL_COUNT_SHIFT),
                    ..b
                }
            } else {
                GpuBatch { instance_offset: start, ..b }
            }
        })
        .collect();
    Ok(TilePrefix { tile: Tile { tile_x, tile_y, batches, instances }, levels: held, of: levels, scheme })
}

fn validate_batch(i: usize, b: &GpuBatch, species_count: u32) -> Result<(), Problem> {
    let what = format!("batch[{i}]");
    finite_all(&format!("{what}.origin_m"), &b.origin_m)?;
    finite_all(&format!("{what}.center_m"), &b.center_m)?;
    finite_all(&format!("{what}.half_extent_m"), &b.half_extent_m)?;
    finite_all(&what, &[b.radius_m, b.xy_step_m, b.z_step_m, b.scale_min, b.scale_log2_step, b.max_height_m])?;
    if b.species >= species_count {
        return Err(Problem::OutOfRange {
            what: format!("{what}.species"),
            value: b.species.into(),
            allowed: format!("less than the scene's {species_count} species"),
        });
    }
    let positive =
        [("radius_m", b.radius_m), ("xy_step_m", b.xy_step_m), ("z_step_m", b.z_step_m), ("scale_min", b.scale_min)];
    for (name, v) in positive {
        if v < 0.0 || (name != "radius_m" && v == 0.0) {
            return Err(Problem::Invalid(format!("{what}.{name} is {v}, must be positive")));
        }
    }
    if b.half_extent_m.iter().any(|&h| h < 0.0) || b.scale_log2_step < 0.0 || b.max_height_m < 0.0 {
        return Err(Problem::Invalid(format!("{what} has a negative extent, scale step or height")));
    }
    if b.flags & !BATCH_FLAGS != 0 {
        return Err(Problem::Invalid(format!(
            "{what}.flags is {:#x}: unknown flags {:#x}",
            b.flags,
            b.flags & !BATCH_FLAGS
        )));
    }
    if b.flags & BATCH_CROWN_ASPECT == 0 && b.crown != 0 {
        return Err(Problem::Invalid(format!("{what}.crown is {:#x} without the crown flag (must be 0)", b.crown)));
    }
    if b.flags & BATCH_CROWN_ASPECT != 0 && CrownRange::unpack(b.crown).min_q == 0 {
        return Err(Problem::Invalid(format!("{what}.crown has a smallest aspect of 0 (must be positive)")));
    }
    if b.xy_step_m > MAX_XY_STEP_M * 1.0001 || b.z_step_m > MAX_Z_STEP_M * 1.0001 {
        return Err(Problem::Invalid(format!(
            "{what} quantisation steps {} m / {} m exceed the 1 cm position error bound",
            b.xy_step_m, b.z_step_m
        )));
    }
    Ok(())
}

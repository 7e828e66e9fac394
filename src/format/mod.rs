//! Sylva's file formats: the scene manifest, LoD packs and tiles.
//!
//! Everything here is versioned, little endian and validated on decode.
//! Decoders promise: for any input bytes they return `Ok` or a
//! [`DecodeError`] naming the file and the problem; they never panic and never
//! allocate more than a small multiple of the input size, whatever counts the
//! input declares. The spec is `docs/FORMAT.md`; fuzz targets live in `fuzz/`.

pub mod attributes;
pub mod canopy;
pub mod cloud;
pub mod cluster;
pub mod entries;
mod error;
pub mod geofit;
pub mod ids;
pub mod imagery;
pub mod index;
pub mod manifest;
pub mod mesh;
pub mod pack;
pub mod stored;
pub mod terrain;
pub mod tile;
pub mod timeline;

pub use error::{DecodeError, Problem};
pub use ids::{decode_ids, decode_tree_ids, encode_ids, encode_tree_ids, TreeIds};
pub use index::{build_index, IndexNode, IndexRef};
pub use manifest::{Bounds, Counts, Crs, Home, Manifest, ShardStamp, SpeciesEntry, TileEntry};
pub use pack::{decode_pack, encode_pack, Pack, PackMeta, Section};
pub use terrain::{TerrainEntry, TerrainTile};
pub use tile::{GpuBatch, Instance, PackedInstance, Tile};

//! Scenes: fetching (one abstraction for local paths, HTTP and the browser's
//! `fetch`), streaming and residency.

pub mod canopy;
pub mod fetch;
pub mod imagery;
pub mod index_walk;
pub mod quadtree;
pub mod query;
pub mod residency;
pub mod streaming;
pub mod style;
pub mod terrain;

#[cfg(not(target_arch = "wasm32"))]
pub use fetch::ThreadFetcher;
pub use fetch::{FetchError, Fetcher, RequestId};
pub use residency::{PoolError, Residency, TileSlot};
pub use streaming::{
    Degraded, LoadFailure, LocatedTree, SceneStream, StreamConfig, StreamEvent, StreamStats, TreeData,
};

//! What the stream reports: its counters, the budgets it degraded within,
//! the files it gave up on and its events.

/// What a budget or device limit currently holds back (all false: nothing).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Degraded {
    /// The GPU pools are full of wanted tiles: the draw distance for new tiles is
    /// shortened to `reach_m`.
    pub pools_full: bool,
    /// Pack parts (finer levels) are held back by the GPU budget.
    pub gpu_budget: bool,
    /// Requests wait for the download budget.
    pub bandwidth: bool,
    /// The GPU pools were cut down to the device's limits (largest storage binding).
    pub device_limit: bool,
    /// The distance up to which tiles are requested (the draw distance unless the
    /// pools are full).
    pub reach_m: f32,
}

/// A file given up on (not found, corrupt, or failed every retry): what the
/// view lacks. Listed in the frame stats as `failed`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LoadFailure {
    /// The URL.
    pub url: String,
    /// What went wrong.
    pub message: String,
}

/// Most failures kept in the list (the count in [`StreamStats::broken`] goes on).
pub const MAX_LISTED_FAILURES: usize = 64;

/// Something a user should hear about.
#[derive(Debug, Clone, PartialEq)]
pub enum StreamEvent {
    /// The manifest is loaded.
    ManifestLoaded {
        /// Trees in the scene.
        trees: u64,
    },
    /// A fetch or decode failed; `retrying` says whether it will be tried again.
    Failed {
        /// The URL.
        url: String,
        /// What went wrong.
        message: String,
        /// Whether another attempt is scheduled.
        retrying: bool,
    },
    /// The manifest could not be loaded: nothing can be drawn.
    Fatal {
        /// What went wrong.
        message: String,
    },
}

/// Counters for stats.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StreamStats {
    /// Bytes received.
    pub bytes_fetched: u64,
    /// Of them, bytes of tiles (whole or prefix levels).
    pub tile_bytes_fetched: u64,
    /// Tiles in the GPU pools.
    pub tiles_resident: u64,
    /// Requests in flight.
    pub loading: u64,
    /// Tiles or packs given up on.
    pub broken: u64,
    /// Tiles the view wants.
    pub tiles_wanted: u64,
    /// Tiles known (listed by the manifest or by index nodes read so far).
    pub tiles_known: u64,
    /// Index nodes read (0 for a flat manifest).
    pub index_nodes_loaded: u64,
    /// Index nodes in the scene (0 for a flat manifest).
    pub index_nodes_total: u64,
    /// Requests started, of every kind.
    pub requests: u64,
    /// What budgets or limits hold back now.
    pub degraded: Degraded,
    /// Terrain tiles decoded and kept.
    pub terrain_resident: u64,
    /// Terrain tiles drawn by the current view.
    pub terrain_drawn: u64,
    /// Ground imagery images decoded and kept.
    pub imagery_resident: u64,
    /// Terrain tiles drawn with an image this frame.
    pub imagery_drawn: u64,
    /// Canopy rasters decoded and kept.
    pub canopy_resident: u64,
    /// Canopy rasters drawn by the current view.
    pub canopy_drawn: u64,
    /// Bytes of canopy rasters received.
    pub canopy_bytes_fetched: u64,
    /// Times a resident tile was trimmed to fewer prefix levels to make room
    /// (eviction by prefix).
    pub tiles_trimmed: u64,
}

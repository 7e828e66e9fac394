//! Frame statistics, gathered once for both hosts by [`super::Frame`]:
//! `sylva render --stats` (native) and `stats()` in the browser (`web/`) report
//! the same keys from the same code (docs/FORMAT.md §frame stats).

use serde::Serialize;

use crate::render::counters::CullCounters;
use crate::render::forest::ForestRenderer;
use crate::render::gpu_data::{DrawArgs, Repr, REPR_COUNT};
use crate::scene::{Fetcher, SceneStream};

/// Per-frame statistics; the keys are stable and documented (docs/FORMAT.md §stats),
/// and the browser reports the same object.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct FrameStats {
    /// Draw calls recorded (≤ species × representations).
    pub draw_calls: u32,
    /// Instances drawn per representation (`mesh0`, `mesh1`, `ellipsoid`, `billboard`).
    pub instances: std::collections::BTreeMap<String, u64>,
    /// Shadow casters drawn per representation, summed over the cascades
    /// (empty without shadows).
    pub shadow_casters: std::collections::BTreeMap<String, u64>,
    /// Shadow cascades drawn (0: shadows off, or the sun is down).
    pub shadow_cascades: u32,
    /// Shadow casters dropped because a segment was full (should be 0).
    pub shadow_items_dropped: u32,
    /// Batch slots the cull pass tested.
    pub batches_tested: u32,
    /// Batches that passed the batch test.
    pub batches_visible: u32,
    /// Instances the per-instance pass tested.
    pub instances_tested: u32,
    /// Items dropped because a segment was full (should be 0).
    pub items_dropped: u32,
    /// Tiles resident in the GPU pools.
    pub tiles_resident: u64,
    /// Requests in flight.
    pub tiles_loading: u64,
    /// Bytes fetched so far.
    pub bytes_fetched: u64,
    /// Of them, tile bytes (whole tiles or prefix levels).
    pub tile_bytes_fetched: u64,
    /// Times a resident tile was trimmed to fewer prefix levels to make room.
    pub tiles_trimmed: u64,
    /// Requests started so far (manifest, index nodes, tiles, packs).
    pub requests: u64,
    /// Tiles known so far (flat list, or leaves of the index nodes read).
    pub tiles_known: u64,
    /// Tiles in the scene.
    pub tiles_total: u64,
    /// Terrain tiles drawn this frame (0 without terrain).
    pub terrain_drawn: u64,
    /// Terrain tiles decoded and kept (CPU; those drawn are also on the GPU).
    pub terrain_resident: u64,
    /// Terrain tiles drawn with a ground image this frame.
    pub imagery_drawn: u64,
    /// Ground images decoded and kept (CPU; those drawn are also on the GPU).
    pub imagery_resident: u64,
    /// Canopy rasters drawn this frame (0 without a canopy, or while trees are big).
    pub canopy_drawn: u64,
    /// Canopy rasters decoded and kept (CPU; those drawn are also on the GPU).
    pub canopy_resident: u64,
    /// Of `bytes_fetched`, canopy raster bytes.
    pub canopy_bytes_fetched: u64,
    /// Index nodes read so far (0 for a flat manifest).
    pub index_nodes_loaded: u64,
    /// Index nodes in the scene (0 for a flat manifest).
    pub index_nodes_total: u64,
    /// What budgets or device limits hold back (`pools_full`, `gpu_budget`,
    /// `bandwidth`, `reach_m`).
    pub degraded: std::collections::BTreeMap<String, serde_json::Value>,
    /// Files given up on (not found, corrupt, or failed every retry): what the
    /// image lacks. Empty when the view is complete.
    pub failed: Vec<crate::scene::LoadFailure>,
    /// Trees in the scene.
    pub trees_total: u64,
    /// Trees resident on the GPU.
    pub trees_resident: u64,
    /// GPU memory estimate (pools + packs + terrain), bytes.
    pub gpu_bytes: u64,
    /// CPU time to prepare and record the frame, ms.
    pub frame_cpu_ms: f64,
    /// GPU time per pass (`cull`, `draw`), ms. Natively, of measured frames: the
    /// wall time from submitting a pass until the GPU is done with it (each is
    /// waited for; lavapipe's compute timestamps read ~0). In the browser: timestamp
    /// queries around the passes (where the adapter has them) of the latest frame
    /// read back; empty without them.
    pub gpu_ms: std::collections::BTreeMap<String, f64>,
    /// The GPU adapter: name (backend, type), or the browser's vendor and architecture.
    pub adapter: String,
    /// Progressive refinement ([`crate::render::refine`]): steps done since the camera
    /// came to rest (1 on a moving camera's frames, its plain first step; 0
    /// while data is loading or when not refining).
    pub refine_step: u32,
    /// The quality level being refined (projected sizes × 2^level).
    pub refine_level: u32,
    /// Refinement done: the image is final and the host stops drawing. Always
    /// false when refinement is off.
    pub refine_converged: bool,
    /// How the scene's textures are fetched and held on the GPU: `bc7` or
    /// `etc2` (the packs' block-compressed variants, where the GPU samples
    /// them) or `plain` (RGBA8).
    pub textures: String,
    /// The browser's frame-time governor (`web/governor.js`, which fills it in):
    /// its level and why. Off here, natively and in tests: full quality.
    pub governor: GovernorReport,
}

/// A frame-time governor's state, as `stats().governor` reports it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GovernorReport {
    /// Whether it governs (never natively).
    pub enabled: bool,
    /// Its level: 0 full quality, each step cheaper (impostors, shadows, render scale, LoD).
    pub level: u32,
    /// The render scale of its level (the canvas's pixels per CSS pixel × DPR).
    pub scale: f32,
    /// How impostors are drawn: `full` (three views blended, each pixel's own
    /// depth) or `moving` (`RenderSettings::moving_impostors`).
    pub impostors: String,
    /// The frame time it holds while the camera moves (ms).
    pub target_ms: f32,
    /// The smallest render scale it uses.
    pub min_scale: f32,
    /// Why it is at its level, in words.
    pub reason: String,
}

impl Default for GovernorReport {
    fn default() -> Self {
        Self {
            enabled: false,
            level: 0,
            scale: 1.0,
            impostors: "full".into(),
            target_ms: 33.0,
            min_scale: 0.35,
            reason: "off".into(),
        }
    }
}

impl FrameStats {
    /// The stats of a frame of `renderer` fed by `stream`, without the GPU
    /// counters (see [`Self::apply_counters`]) and GPU times.
    #[must_use]
    pub fn gather<F: Fetcher>(
        renderer: &ForestRenderer,
        stream: &SceneStream<F>,
        draw_calls: u32,
        frame_cpu_ms: f64,
    ) -> Self {
        let s = stream.stats();
        let d = s.degraded;
        let degraded = [
            ("pools_full", serde_json::json!(d.pools_full)),
            ("gpu_budget", serde_json::json!(d.gpu_budget)),
            ("bandwidth", serde_json::json!(d.bandwidth)),
            ("device_limit", serde_json::json!(d.device_limit)),
            ("reach_m", serde_json::json!(if d.reach_m.is_finite() { f64::from(d.reach_m) } else { -1.0 })),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect();
        FrameStats {
            draw_calls,
            instances: Repr::ALL.iter().map(|r| (r.name().to_string(), 0)).collect(),
            batches_tested: renderer.batch_slots(),
            tiles_resident: s.tiles_resident,
            tiles_loading: s.loading,
            bytes_fetched: s.bytes_fetched,
            tile_bytes_fetched: s.tile_bytes_fetched,
            tiles_trimmed: s.tiles_trimmed,
            requests: s.requests,
            tiles_known: s.tiles_known,
            tiles_total: stream.manifest().map_or(0, |m| m.counts.tiles),
            terrain_drawn: u64::from(renderer.terrain().drawn()),
            terrain_resident: s.terrain_resident,
            imagery_drawn: u64::from(renderer.terrain().imaged),
            imagery_resident: s.imagery_resident,
            canopy_drawn: u64::from(renderer.canopy().drawn()),
            canopy_resident: s.canopy_resident,
            canopy_bytes_fetched: s.canopy_bytes_fetched,
            index_nodes_loaded: s.index_nodes_loaded,
            index_nodes_total: s.index_nodes_total,
            degraded,
            failed: stream.failures().to_vec(),
            trees_total: stream.manifest().map_or(0, |m| m.counts.trees),
            trees_resident: renderer.resident_instances(),
            gpu_bytes: renderer.gpu_bytes(),
            frame_cpu_ms,
            textures: stream.textures_in_use().map_or("plain", |e| e.name()).into(),
            ..Default::default()
        }
    }

    /// Fills in the cull passes' counters read back from the GPU (the
    /// camera's, and the shadow cascades' of the same frame).
    pub fn apply_counters(&mut self, counters: &CullCounters) {
        self.batches_visible = counters.control.batches_visible;
        self.instances_tested = counters.control.instances_tested;
        self.items_dropped = counters.control.items_dropped;
        self.shadow_cascades = counters.cascades;
        self.shadow_items_dropped = counters.shadow_dropped;
        self.shadow_casters.clear();
        for repr in Repr::ALL {
            self.instances.insert(repr.name().into(), 0);
        }
        let count = |map: &mut std::collections::BTreeMap<String, u64>, slots: &[DrawArgs]| {
            for (slot, args) in slots.iter().enumerate() {
                let repr = Repr::ALL[slot % REPR_COUNT as usize];
                *map.entry(repr.name().into()).or_default() += u64::from(args.instance_count);
            }
        };
        count(&mut self.instances, &counters.slots);
        count(&mut self.shadow_casters, &counters.shadow_slots);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counters_decode_from_a_readback() {
        let mut words = vec![0u32; 8 + 2 * 5];
        words[0] = 7; // batches visible
        words[4] = 300; // instances tested
        words[5] = 2; // items dropped
        words[8 + 1] = 40; // slot 0: mesh0 instances
        words[8 + 5 + 1] = 9; // slot 1: mesh1 instances
        let c = CullCounters::from_bytes(bytemuck::cast_slice(&words), 2, 0);
        assert_eq!((c.control.batches_visible, c.control.instances_tested, c.control.items_dropped), (7, 300, 2));
        assert_eq!(c.slots.iter().map(|s| s.instance_count).collect::<Vec<_>>(), vec![40, 9]);
        assert_eq!(CullCounters::readback_bytes(2, 0), 32 + 40);
        assert_eq!(CullCounters::readback_bytes(2, 1), 2 * (32 + 40));
        let mut stats = FrameStats::default();
        stats.apply_counters(&c);
        assert!(stats.shadow_casters.is_empty());
        // With a cascade: its control words (3 dropped) and slots after the camera's.
        let mut with = words.clone();
        with.extend([0, 0, 0, 0, 0, 3, 0, 0]);
        with.extend([0, 11, 0, 0, 0, 0, 0, 0, 0, 0]);
        let c = CullCounters::from_bytes(bytemuck::cast_slice(&with), 2, 1);
        stats.apply_counters(&c);
        assert_eq!((stats.shadow_cascades, stats.shadow_items_dropped), (1, 3));
        assert_eq!((stats.shadow_casters["mesh0"], stats.instances["mesh0"]), (11, 40));
        assert_eq!((stats.instances["mesh0"], stats.instances["mesh1"], stats.instances["billboard"]), (40, 9, 0));
        // A short readback decodes what is there.
        assert_eq!(
            CullCounters::from_bytes(&bytemuck::cast_slice::<u32, u8>(&words)[..10], 2, 0).control.batches_visible,
            7
        );
    }
}

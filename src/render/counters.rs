//! The cull pass's counters as read back after a frame (the renderer copies
//! them out; [`crate::frame::stats::FrameStats`] reports them).

use super::gpu_data::{CullControl, DrawArgs};

/// The cull pass's counters and draw arguments as read back after a frame:
/// [`CullControl`], then one [`DrawArgs`] per draw slot; then, per shadow
/// cascade, its cull pass's control words and slots.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CullCounters {
    /// The control words.
    pub control: CullControl,
    /// Per draw slot (`species * REPR_COUNT + repr`).
    pub slots: Vec<DrawArgs>,
    /// Shadow cascades read back with them.
    pub cascades: u32,
    /// Items the cascades' cull passes dropped (full segments), summed.
    pub shadow_dropped: u32,
    /// The cascades' slots, one after another.
    pub shadow_slots: Vec<DrawArgs>,
}

impl CullCounters {
    /// Bytes of one cascade's part: its control words, then its slots.
    #[must_use]
    pub fn cascade_bytes(slot_count: u32) -> u64 {
        (size_of::<CullControl>() + slot_count as usize * size_of::<DrawArgs>()) as u64
    }

    /// Bytes of a readback of `slot_count` slots for the camera and each of
    /// `cascades` shadow cascades.
    #[must_use]
    pub fn readback_bytes(slot_count: u32, cascades: u32) -> u64 {
        Self::cascade_bytes(slot_count) * (1 + u64::from(cascades))
    }

    /// Decodes a readback of `slot_count` slots and `cascades` cascades (a
    /// shorter one decodes what is there: whole slots only).
    #[must_use]
    pub fn from_bytes(bytes: &[u8], slot_count: u32, cascades: u32) -> Self {
        let part = Self::cascade_bytes(slot_count) as usize;
        let decode = |bytes: &[u8]| {
            let head = size_of::<CullControl>().min(bytes.len());
            let mut control = CullControl::default();
            bytemuck::bytes_of_mut(&mut control)[..head].copy_from_slice(&bytes[..head]);
            let rest = &bytes[head..bytes.len().min(part).max(head)];
            let whole = rest.len() / size_of::<DrawArgs>() * size_of::<DrawArgs>();
            (control, bytemuck::pod_collect_to_vec::<u8, DrawArgs>(&rest[..whole]))
        };
        let (control, slots) = decode(bytes);
        let mut out = Self { control, slots, cascades, ..Self::default() };
        for c in 0..cascades as usize {
            let Some(cascade) = bytes.get(part * (1 + c)..) else { break };
            let (control, slots) = decode(cascade);
            out.shadow_dropped += control.items_dropped;
            out.shadow_slots.extend(slots);
        }
        out
    }
}

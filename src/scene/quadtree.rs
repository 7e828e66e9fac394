//! Quadtree keys, shared by the quadtree layers (terrain, its imagery, the
//! canopy rasters): a tile is `(level, x, y)`, level 0 the root, its four
//! children at `level + 1`, `2x + i`, `2y + j`.

/// A tile's key: (level, x, y).
pub type QuadKey = (u8, u32, u32);

/// The ancestor of `key` at `level` (≤ its own).
#[must_use]
pub fn ancestor(key: QuadKey, level: u8) -> QuadKey {
    let d = key.0 - level.min(key.0);
    (key.0 - d, key.1 >> d, key.2 >> d)
}

/// Where tile `inner` lies in the uv square of its ancestor `outer`.
#[must_use]
pub fn uv_in(outer: QuadKey, inner: QuadKey) -> [f32; 4] {
    let d = inner.0 - outer.0;
    let scale = 1.0 / f64::from(1u32 << d);
    let (ox, oy) = (inner.1 - (outer.1 << d), inner.2 - (outer.2 << d));
    [(f64::from(ox) * scale) as f32, (f64::from(oy) * scale) as f32, scale as f32, scale as f32]
}

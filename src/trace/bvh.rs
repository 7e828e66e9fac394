//! A bounding volume hierarchy over one species' full mesh: the bottom level
//! of the tracer's two levels (Dietrich et al. 2005, §4.1, with a BVH where
//! they used a kd-tree). Built by the surface area heuristic (MacDonald &
//! Booth 1990) evaluated over bins of the triangles' centroids (Wald 2007,
//! "On fast construction of SAH-based bounding volume hierarchies", §3), in
//! arrays the GPU reads as they are: [`BvhNode`]s (32 bytes) and
//! [`GpuTriangle`]s (64 bytes) in leaf order.
//!
//! [`Bvh::intersect`] is the twin of `trace_bvh` in `shaders/trace.wgsl`.

use glam::Vec3;

use super::{inv_dir, ray_box, ray_triangle, Hit, Ray, Triangle};
use crate::format::mesh::{MeshLevelMeta, MeshVertex};

/// Deepest node the build makes (a node there becomes a leaf whatever its
/// size), so a traversal's stack never holds more than [`STACK`] entries.
pub const MAX_DEPTH: u32 = 48;
/// Entries of a traversal's stack (CPU and WGSL): each inner node visited
/// replaces itself with at most two children, so depth + 1 suffice.
pub const STACK: usize = 64;
/// Centroid bins per axis evaluated by the build.
const BINS: usize = 12;
/// Nodes with at most this many triangles are leaves.
const LEAF_MIN: u32 = 2;
/// Nodes with more than this many triangles are split even where the heuristic
/// prices a leaf lower.
const LEAF_MAX: u32 = 16;

/// A node of the hierarchy, as the GPU reads it. Must match `BvhNode` in
/// `shaders/trace.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct BvhNode {
    /// Lower corner of the box around everything below the node.
    pub min: [f32; 3],
    /// A leaf's first triangle; an inner node's first child (the second
    /// follows it).
    pub first: u32,
    /// Upper corner.
    pub max: [f32; 3],
    /// A leaf's triangle count; 0 for an inner node.
    pub count: u32,
}

/// A triangle as the GPU reads it ([`Triangle`]'s corner and edges), with the
/// mesh's own index of it, its material and its corners' texture
/// coordinates (for the alpha test of leaf cards). 64 bytes. Must match
/// `TraceTriangle` in `shaders/trace.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuTriangle {
    /// First corner.
    pub v0: [f32; 3],
    /// The triangle's index in the mesh (its first index / 3).
    pub id: u32,
    /// Second corner − first.
    pub e1: [f32; 3],
    /// The species' material index.
    pub material: u32,
    /// Third corner − first.
    pub e2: [f32; 3],
    /// The corners' vertex colours averaged, linear RGBA8 (r low): the
    /// raster multiplies albedo and alpha by them.
    pub color: u32,
    /// The corners' texture coordinates as the vertices quantise them (u, v
    /// as u16 in 1/65535 steps of the level's uv range; u low), then 0.
    pub uv: [u32; 4],
}

/// What a triangle carries besides its corners: its material, its corners'
/// quantised texture coordinates (see [`GpuTriangle::uv`]) and their colour.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TriangleSurface {
    /// The species' material index.
    pub material: u32,
    /// Per corner, u | v << 16.
    pub uv: [u32; 3],
    /// The corners' vertex colours averaged, linear RGBA8 (r low).
    pub color: u32,
}

impl Default for TriangleSurface {
    /// Material 0, no texture coordinates, white.
    fn default() -> Self {
        Self { material: 0, uv: [0; 3], color: u32::MAX }
    }
}

impl GpuTriangle {
    /// The triangle the tests see.
    #[must_use]
    pub fn triangle(&self) -> Triangle {
        Triangle { v0: self.v0.into(), e1: self.e1.into(), e2: self.e2.into() }
    }
}

/// A species' hierarchy: nodes (the root first) and triangles in leaf order.
/// Empty for a mesh without triangles.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Bvh {
    /// The nodes, root at 0.
    pub nodes: Vec<BvhNode>,
    /// The triangles, each leaf's a contiguous run.
    pub triangles: Vec<GpuTriangle>,
}

/// An axis-aligned box being grown.
#[derive(Debug, Clone, Copy)]
struct Bounds {
    min: Vec3,
    max: Vec3,
}

impl Bounds {
    const EMPTY: Self = Self { min: Vec3::splat(f32::INFINITY), max: Vec3::splat(f32::NEG_INFINITY) };

    fn grow(&mut self, other: &Self) {
        self.min = self.min.min(other.min);
        self.max = self.max.max(other.max);
    }

    /// Half the surface area (the heuristic needs only ratios); 0 when empty.
    fn half_area(&self) -> f32 {
        let d = (self.max - self.min).max(Vec3::ZERO);
        d.x * d.y + d.y * d.z + d.z * d.x
    }
}

/// The box of a triangle as the tracer sees it (its corner plus its edges).
fn triangle_bounds(t: &Triangle) -> Bounds {
    let (b, c) = (t.v0 + t.e1, t.v0 + t.e2);
    Bounds { min: t.v0.min(b).min(c), max: t.v0.max(b).max(c) }
}

impl Bvh {
    /// Builds the hierarchy over `triangles` (their order gives their ids),
    /// all of material 0 without texture coordinates. Deterministic: the same
    /// triangles give the same arrays.
    #[must_use]
    pub fn build(triangles: &[Triangle]) -> Self {
        Self::build_with(triangles, &[])
    }

    /// Builds the hierarchy over `triangles` with each one's `surfaces`
    /// entry (material, texture coordinates; missing entries: the default).
    #[must_use]
    pub fn build_with(triangles: &[Triangle], surfaces: &[TriangleSurface]) -> Self {
        let boxes: Vec<(Vec3, Vec3)> = triangles
            .iter()
            .map(|t| {
                let b = triangle_bounds(t);
                (b.min, b.max)
            })
            .collect();
        let (nodes, order) = build_nodes(&boxes);
        let triangles = order
            .iter()
            .map(|&i| {
                let t = &triangles[i as usize];
                let s = surfaces.get(i as usize).copied().unwrap_or_default();
                GpuTriangle {
                    v0: t.v0.into(),
                    id: i,
                    e1: t.e1.into(),
                    material: s.material,
                    e2: t.e2.into(),
                    color: s.color,
                    uv: [s.uv[0], s.uv[1], s.uv[2], 0],
                }
            })
            .collect();
        Self { nodes, triangles }
    }

    /// Builds the hierarchy of a pack's mesh level: its positions dequantised
    /// as `shaders/mesh.wgsl` does (model space at scale 1), every index triple
    /// a triangle (a trailing partial triple or an index past the vertices
    /// ends the list: the pack's checks refuse those before this).
    #[must_use]
    pub fn of_mesh(level: &MeshLevelMeta, vertices: &[MeshVertex], indices: &[u32]) -> Self {
        Self::build(&mesh_triangles(level, vertices, indices))
    }

    /// The nearest hit of `ray`, walking the hierarchy front to back.
    #[must_use]
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.intersect_where(ray, |_, _, _| true)
    }

    /// The nearest hit of `ray` that `keeps` (a triangle, the hit's
    /// barycentric u and v) keeps: the alpha test of leaf cards.
    /// Twin: `trace_bvh` in `shaders/trace.wgsl` (with `trace_keeps`).
    #[must_use]
    pub fn intersect_where(&self, ray: &Ray, keeps: impl Fn(&GpuTriangle, f32, f32) -> bool) -> Option<Hit> {
        let mut best = None;
        walk(&self.nodes, ray, |first, count, closest| {
            let mut nearer = None;
            for (i, t) in self.triangles[first as usize..(first + count) as usize].iter().enumerate() {
                let limit = nearer.unwrap_or(closest);
                if let Some((d, u, v)) =
                    ray_triangle(ray.origin, ray.dir, &t.triangle(), limit).filter(|h| keeps(t, h.1, h.2))
                {
                    nearer = Some(d);
                    best = Some(Hit { t: d, triangle: t.id, u, v, index: first + i as u32 });
                }
            }
            nearer
        });
        best
    }

    /// The deepest leaf's depth (the root's is 0).
    #[must_use]
    pub fn depth(&self) -> u32 {
        depth_of(&self.nodes)
    }
}

/// The deepest leaf's depth in `nodes` (the root's is 0).
#[must_use]
pub fn depth_of(nodes: &[BvhNode]) -> u32 {
    let mut deepest = 0;
    let mut work = vec![(0usize, 0u32)];
    while let Some((i, d)) = work.pop() {
        let Some(n) = nodes.get(i) else { break };
        deepest = deepest.max(d);
        if n.count == 0 {
            work.push((n.first as usize, d + 1));
            work.push((n.first as usize + 1, d + 1));
        }
    }
    deepest
}

/// Walks `nodes` for `ray` front to back, skipping boxes entered at or beyond
/// the nearest hit so far: at each leaf reached, `leaf(first, count, closest)`
/// tests its primitives against `closest` and returns a nearer hit's distance,
/// if any. Returns the nearest distance found (`ray.t_max` if none).
/// Twin: the walk of `trace_bvh` in `shaders/trace.wgsl` (and of `trace_scene` in `trace_scene.wgsl`).
pub fn walk(nodes: &[BvhNode], ray: &Ray, mut leaf: impl FnMut(u32, u32, f32) -> Option<f32>) -> f32 {
    let mut closest = ray.t_max;
    let Some(root) = nodes.first() else { return closest };
    let inv = inv_dir(ray.dir);
    let Some(enter) = ray_box(ray.origin, inv, root.min.into(), root.max.into(), closest) else { return closest };
    let mut stack = [(0u32, 0f32); STACK];
    stack[0] = (0, enter);
    let mut sp = 1;
    while sp > 0 {
        sp -= 1;
        let (ni, entered) = stack[sp];
        if entered >= closest {
            continue;
        }
        let node = &nodes[ni as usize];
        if node.count > 0 {
            if let Some(t) = leaf(node.first, node.count, closest) {
                closest = t;
            }
            continue;
        }
        let child = |i: u32| {
            let c = &nodes[i as usize];
            ray_box(ray.origin, inv, c.min.into(), c.max.into(), closest).map(|t| (i, t))
        };
        match (child(node.first), child(node.first + 1)) {
            (Some(a), Some(b)) => {
                // The farther first, so the nearer is walked next.
                let (near, far) = if b.1 < a.1 { (b, a) } else { (a, b) };
                stack[sp] = far;
                stack[sp + 1] = near;
                sp += 2;
            }
            (Some(a), None) | (None, Some(a)) => {
                stack[sp] = a;
                sp += 1;
            }
            (None, None) => {}
        }
    }
    closest
}

/// Builds hierarchy nodes over primitives given by their boxes (the binned
/// surface area heuristic, as [`Bvh::build`] describes): the nodes, root
/// first, and the primitives' order — a leaf's `first..first + count` are
/// positions in it. Deterministic. Empty for no primitives.
#[must_use]
pub fn build_nodes(prim_boxes: &[(Vec3, Vec3)]) -> (Vec<BvhNode>, Vec<u32>) {
    if prim_boxes.is_empty() {
        return (Vec::new(), Vec::new());
    }
    let boxes: Vec<Bounds> = prim_boxes.iter().map(|&(min, max)| Bounds { min, max }).collect();
    let centroids: Vec<Vec3> = boxes.iter().map(|b| (b.min + b.max) * 0.5).collect();
    let mut order: Vec<u32> = (0..boxes.len() as u32).collect();
    let mut root = Bounds::EMPTY;
    boxes.iter().for_each(|b| root.grow(b));
    // Boxes grow by a hair so that a hit on a primitive lying in a box's
    // face is not lost to the slab test's rounding.
    let pad = Vec3::splat((root.max - root.min).max_element() * 1e-6 + 1e-7);
    let bounds_of = |range: &[u32]| {
        let mut b = Bounds::EMPTY;
        range.iter().for_each(|&i| b.grow(&boxes[i as usize]));
        (b.min - pad, b.max + pad)
    };
    let node = |range: &[u32], first: u32| {
        let (min, max) = bounds_of(range);
        BvhNode { min: min.into(), first, max: max.into(), count: range.len() as u32 }
    };
    let mut nodes = vec![node(&order, 0)];
    let mut work = vec![(0usize, 0u32)];
    while let Some((ni, depth)) = work.pop() {
        let (start, count) = (nodes[ni].first as usize, nodes[ni].count);
        if count <= LEAF_MIN || depth >= MAX_DEPTH {
            continue;
        }
        let range = &mut order[start..start + count as usize];
        let Some((axis, split, cost)) = best_split(range, &boxes, &centroids) else { continue };
        let area = Bounds { min: nodes[ni].min.into(), max: nodes[ni].max.into() }.half_area().max(1e-30);
        // Price of a leaf: one intersection per primitive; of a split: one
        // traversal step plus the children's primitives by their area.
        if 1.0 + cost / area >= count as f32 && count <= LEAF_MAX {
            continue;
        }
        let (cmin, cmax) = centroid_range(range, &centroids);
        let left_len = partition(range, |i| bin_of(centroids[i as usize], axis, cmin, cmax) < split);
        if left_len == 0 || left_len == range.len() {
            continue;
        }
        let left = nodes.len();
        let (l, r) = range.split_at(left_len);
        let (ln, rn) = (node(l, start as u32), node(r, (start + left_len) as u32));
        nodes.push(ln);
        nodes.push(rn);
        nodes[ni].first = left as u32;
        nodes[ni].count = 0;
        work.push((left + 1, depth + 1));
        work.push((left, depth + 1));
    }
    (nodes, order)
}

/// The triangles of a mesh level, positions dequantised as `shaders/mesh.wgsl`
/// does (`pos_min + q / 65535 · extent`).
#[must_use]
pub fn mesh_triangles(level: &MeshLevelMeta, vertices: &[MeshVertex], indices: &[u32]) -> Vec<Triangle> {
    let min = Vec3::from(level.pos_min);
    let extent = Vec3::from(level.pos_max) - min;
    let position = |i: u32| {
        vertices.get(i as usize).map(|v| {
            let q = Vec3::new(f32::from(v.position[0]), f32::from(v.position[1]), f32::from(v.position[2]));
            min + q / 65535.0 * extent
        })
    };
    indices
        .chunks_exact(3)
        .map_while(|c| Some(Triangle::new(position(c[0])?, position(c[1])?, position(c[2])?)))
        .collect()
}

/// Each triangle's material (its first corner's, as the raster's flat
/// attribute takes it), its corners' quantised texture coordinates and their
/// colours averaged, in the order of [`mesh_triangles`].
#[must_use]
pub fn mesh_surfaces(vertices: &[MeshVertex], indices: &[u32]) -> Vec<TriangleSurface> {
    let uv = |i: u32| vertices.get(i as usize).map_or(0, |v| u32::from(v.uv[0]) | (u32::from(v.uv[1]) << 16));
    let color = |c: &[u32]| {
        let mut sum = [0u32; 4];
        for &i in c {
            let v = vertices.get(i as usize).map_or([255; 4], |v| v.color);
            (0..4).for_each(|k| sum[k] += u32::from(v[k]));
        }
        (0..4).fold(0, |word, k| word | (((sum[k] + 1) / 3).min(255) << (8 * k)))
    };
    indices
        .chunks_exact(3)
        .map(|c| TriangleSurface {
            material: vertices.get(c[0] as usize).map_or(0, |v| u32::from(v.material)),
            uv: [uv(c[0]), uv(c[1]), uv(c[2])],
            color: color(c),
        })
        .collect()
}

/// The centroids' range over `range` of triangles.
fn centroid_range(range: &[u32], centroids: &[Vec3]) -> (Vec3, Vec3) {
    range.iter().fold((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)), |(lo, hi), &i| {
        let c = centroids[i as usize];
        (lo.min(c), hi.max(c))
    })
}

/// The bin of a centroid along `axis` of the centroids' range `cmin..cmax`.
fn bin_of(c: Vec3, axis: usize, cmin: Vec3, cmax: Vec3) -> usize {
    let extent = cmax[axis] - cmin[axis];
    (((c[axis] - cmin[axis]) / extent * BINS as f32) as usize).min(BINS - 1)
}

/// The cheapest split of `range` by the binned surface area heuristic:
/// `(axis, first bin of the right side, Σ half area × triangles)`, or `None`
/// where every centroid is the same point.
fn best_split(range: &[u32], boxes: &[Bounds], centroids: &[Vec3]) -> Option<(usize, usize, f32)> {
    let (cmin, cmax) = centroid_range(range, centroids);
    let mut best: Option<(usize, usize, f32)> = None;
    for axis in 0..3 {
        if cmax[axis] - cmin[axis] <= 0.0 {
            continue;
        }
        let mut bins = [(Bounds::EMPTY, 0u32); BINS];
        for &i in range {
            let b = &mut bins[bin_of(centroids[i as usize], axis, cmin, cmax)];
            b.0.grow(&boxes[i as usize]);
            b.1 += 1;
        }
        // Left sweep: the area and count of bins 0..k, for each split k.
        let mut left = [(0f32, 0u32); BINS];
        let mut acc = (Bounds::EMPTY, 0);
        for k in 1..BINS {
            acc.0.grow(&bins[k - 1].0);
            acc.1 += bins[k - 1].1;
            left[k] = (acc.0.half_area(), acc.1);
        }
        let mut acc = (Bounds::EMPTY, 0);
        for k in (1..BINS).rev() {
            acc.0.grow(&bins[k].0);
            acc.1 += bins[k].1;
            let (la, ln) = left[k];
            if ln == 0 || acc.1 == 0 {
                continue;
            }
            let cost = la * ln as f32 + acc.0.half_area() * acc.1 as f32;
            if best.is_none_or(|b| cost < b.2) {
                best = Some((axis, k, cost));
            }
        }
    }
    best
}

/// Moves the entries of `range` for which `left` holds to its front (in a
/// deterministic order); returns how many there are.
fn partition(range: &mut [u32], left: impl Fn(u32) -> bool) -> usize {
    let mut i = 0;
    for j in 0..range.len() {
        if left(range[j]) {
            range.swap(i, j);
            i += 1;
        }
    }
    i
}

#[cfg(test)]
mod tests {
    use super::super::brute_force;
    use super::*;

    use super::super::Xorshift32 as Rng;

    /// A point in the cube `lo..hi` on each axis.
    fn vec(rng: &mut Rng, lo: f32, hi: f32) -> Vec3 {
        rng.inside(Vec3::splat(lo), Vec3::splat(hi))
    }

    /// A cloud of small random triangles in a 10 m cube, like leaf cards.
    fn leaves(n: usize, rng: &mut Rng) -> Vec<Triangle> {
        (0..n)
            .map(|_| {
                let a = vec(rng, 0.0, 10.0);
                Triangle::new(a, a + vec(rng, -0.3, 0.3), a + vec(rng, -0.3, 0.3))
            })
            .collect()
    }

    #[test]
    fn the_hierarchy_finds_what_brute_force_finds() {
        let mut rng = Rng(0x5eed);
        let tris = leaves(3000, &mut rng);
        let bvh = Bvh::build(&tris);
        assert!(bvh.nodes.len() > 100 && bvh.depth() <= MAX_DEPTH, "{} nodes, depth {}", bvh.nodes.len(), bvh.depth());
        let mut hits = 0;
        for _ in 0..2000 {
            let origin = vec(&mut rng, -5.0, 15.0);
            let ray = Ray { origin, dir: vec(&mut rng, 0.0, 10.0) - origin, t_max: 2.0 };
            let (a, b) = (bvh.intersect(&ray), brute_force(&tris, &ray));
            assert_eq!(a.map(|h| h.t), b.map(|h| h.t), "{ray:?}");
            if let (Some(a), Some(b)) = (a, b) {
                assert_eq!(a.triangle, b.triangle);
                hits += 1;
            }
        }
        assert!(hits > 200, "only {hits} of 2000 rays hit: the test would not see a wrong traversal");
    }

    #[test]
    fn every_triangle_is_in_exactly_one_leaf_inside_its_box() {
        let mut rng = Rng(7);
        let tris = leaves(500, &mut rng);
        let bvh = Bvh::build(&tris);
        let mut seen = vec![0u32; tris.len()];
        for n in bvh.nodes.iter().filter(|n| n.count > 0) {
            for t in &bvh.triangles[n.first as usize..(n.first + n.count) as usize] {
                seen[t.id as usize] += 1;
                let b = triangle_bounds(&t.triangle());
                assert!(b.min.cmpge(n.min.into()).all() && b.max.cmple(n.max.into()).all());
            }
        }
        assert!(seen.iter().all(|&s| s == 1));
        assert_eq!(Bvh::build(&tris), bvh, "deterministic");
    }

    #[test]
    fn degenerate_meshes_build_and_miss_cleanly() {
        assert!(Bvh::build(&[]).intersect(&Ray { origin: Vec3::ZERO, dir: Vec3::X, t_max: 1.0 }).is_none());
        // A thousand copies of one triangle: no split separates them.
        let one = Triangle::new(Vec3::ZERO, Vec3::X, Vec3::Y);
        let bvh = Bvh::build(&vec![one; 1000]);
        assert_eq!(bvh.nodes.len(), 1);
        let hit = bvh.intersect(&Ray { origin: Vec3::new(0.2, 0.2, 1.0), dir: -Vec3::Z, t_max: 10.0 });
        assert_eq!(hit.map(|h| (h.t, h.triangle)), Some((1.0, 0)));
    }
}

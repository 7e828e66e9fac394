//! The tracer's two levels (Dietrich et al. 2005, §4.1): each species' BVH
//! ([`Bvh`], in model space) once, and a top-level hierarchy over the trees —
//! instances that place a species with the raster path's own transform
//! (`shaders/mesh.wgsl`: model xy scaled by scale × crown aspect, z by scale,
//! turned by yaw about +Z, then moved to the tree's position). A ray that
//! enters a tree's box is carried into the species' model space and walked
//! there; its parameter `t` is the same in both spaces (the map is affine and
//! the direction is not renormalised).
//!
//! [`TraceScene::intersect`] is the twin of `trace_scene` in `shaders/trace.wgsl`.

use glam::Vec3;

use super::bvh::{build_nodes, walk, Bvh, BvhNode};
use super::{Hit, Ray};

/// A tree as the tracer places it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Instance {
    /// Where the trunk's base stands (the scene's frame, metres).
    pub position: Vec3,
    /// Turn about +Z, radians.
    pub yaw: f32,
    /// Height scale of the species model.
    pub scale: f32,
    /// Horizontal over vertical scale (1 without crown data).
    pub aspect: f32,
    /// Index into the scene's species.
    pub species: u32,
}

/// An instance as the GPU reads it. Must match `TraceInstance` in `shaders/trace.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuInstance {
    /// Where the trunk's base stands.
    pub position: [f32; 3],
    /// Turn about +Z, radians.
    pub yaw: f32,
    /// Model xy → scene: scale × aspect.
    pub scale_xy: f32,
    /// Model z → scene: scale.
    pub scale_z: f32,
    /// Index into the species table.
    pub species: u32,
    /// The instance's index in the list it was built from.
    pub id: u32,
}

/// Where a species' hierarchy starts in the concatenated arrays. Must match
/// `TraceSpecies` in `shaders/trace.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuSpeciesBvh {
    /// First node.
    pub node_base: u32,
    /// First triangle.
    pub tri_base: u32,
    /// Nodes (0: a species without triangles; its trees are never hit).
    pub node_count: u32,
    /// Padding (0).
    pub pad: u32,
}

/// The nearest hit in a scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneHit {
    /// The instance hit (its index in the list the scene was built from).
    pub instance: u32,
    /// The hit on its species' mesh.
    pub hit: Hit,
}

/// Both levels, in the arrays the GPU reads.
#[derive(Debug, Clone, Default)]
pub struct TraceScene {
    /// Per species its hierarchy (model space).
    pub species: Vec<Bvh>,
    /// The top level over the instances; a leaf's `first..first + count` index `instances`.
    pub top: Vec<BvhNode>,
    /// The instances in the top level's leaf order.
    pub instances: Vec<GpuInstance>,
}

impl GpuInstance {
    /// `inst` as the GPU reads it, with its index `id`.
    #[must_use]
    pub fn of(inst: &Instance, id: u32) -> Self {
        Self {
            position: inst.position.into(),
            yaw: inst.yaw,
            scale_xy: inst.scale * inst.aspect,
            scale_z: inst.scale,
            species: inst.species,
            id,
        }
    }

    /// A scene-space ray carried into the species' model space: the same `t`
    /// reaches the same point. Twin: `to_model` in `shaders/trace.wgsl`.
    #[must_use]
    pub fn to_model(&self, ray: &Ray) -> Ray {
        let (s, c) = self.yaw.sin_cos();
        let inv_scale = Vec3::new(1.0 / self.scale_xy, 1.0 / self.scale_xy, 1.0 / self.scale_z);
        // The inverse turn (by −yaw), then the inverse scale.
        let unturn = |v: Vec3| Vec3::new(c * v.x + s * v.y, -s * v.x + c * v.y, v.z) * inv_scale;
        Ray { origin: unturn(ray.origin - Vec3::from(self.position)), dir: unturn(ray.dir), t_max: ray.t_max }
    }

    /// A model-space point placed in the scene (the raster path's transform).
    #[must_use]
    pub fn to_scene(&self, p: Vec3) -> Vec3 {
        let (s, c) = self.yaw.sin_cos();
        let v = Vec3::new(p.x * self.scale_xy, p.y * self.scale_xy, p.z * self.scale_z);
        Vec3::new(c * v.x - s * v.y, s * v.x + c * v.y, v.z) + Vec3::from(self.position)
    }
}

impl TraceScene {
    /// Builds the top level over `instances` of `species` (instances of a
    /// species index past the list, or with a non-finite or non-positive
    /// transform, are left out).
    #[must_use]
    pub fn build(species: Vec<Bvh>, instances: &[Instance]) -> Self {
        let mut kept = Vec::new();
        let mut boxes = Vec::new();
        for (i, inst) in instances.iter().enumerate() {
            let Some(root) = species.get(inst.species as usize).and_then(|b| b.nodes.first()) else { continue };
            let g = GpuInstance::of(inst, i as u32);
            let scaled = g.scale_xy > 0.0 && g.scale_z > 0.0 && g.scale_xy.is_finite() && g.scale_z.is_finite();
            if !(inst.position.is_finite() && inst.yaw.is_finite() && scaled) {
                continue;
            }
            // The species' box placed: the box around its eight corners.
            let (lo, hi) = (Vec3::from(root.min), Vec3::from(root.max));
            let (mut min, mut max) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
            for k in 0..8 {
                let corner = Vec3::new(
                    if k & 1 == 0 { lo.x } else { hi.x },
                    if k & 2 == 0 { lo.y } else { hi.y },
                    if k & 4 == 0 { lo.z } else { hi.z },
                );
                let p = g.to_scene(corner);
                min = min.min(p);
                max = max.max(p);
            }
            kept.push(g);
            boxes.push((min, max));
        }
        let (top, order) = build_nodes(&boxes);
        let instances = order.iter().map(|&i| kept[i as usize]).collect();
        Self { species, top, instances }
    }

    /// The nearest hit of a scene-space `ray`: the top level walked front to
    /// back, each tree entered walked in its species' model space.
    /// Twin: `trace_scene` in `shaders/trace.wgsl`.
    #[must_use]
    pub fn intersect(&self, ray: &Ray) -> Option<SceneHit> {
        let mut best = None;
        walk(&self.top, ray, |first, count, closest| {
            let mut nearer = None;
            for inst in &self.instances[first as usize..(first + count) as usize] {
                let mut model = inst.to_model(ray);
                model.t_max = nearer.unwrap_or(closest);
                if let Some(hit) = self.species[inst.species as usize].intersect(&model) {
                    nearer = Some(hit.t);
                    best = Some(SceneHit { instance: inst.id, hit });
                }
            }
            nearer
        });
        best
    }

    /// The species' hierarchies concatenated (nodes, triangles) with each
    /// one's offsets, as the GPU reads them.
    #[must_use]
    pub fn species_arrays(&self) -> (Vec<BvhNode>, Vec<super::bvh::GpuTriangle>, Vec<GpuSpeciesBvh>) {
        let (mut nodes, mut tris, mut table) = (Vec::new(), Vec::new(), Vec::new());
        for b in &self.species {
            table.push(GpuSpeciesBvh {
                node_base: nodes.len() as u32,
                tri_base: tris.len() as u32,
                node_count: b.nodes.len() as u32,
                pad: 0,
            });
            nodes.extend_from_slice(&b.nodes);
            tris.extend_from_slice(&b.triangles);
        }
        (nodes, tris, table)
    }
}

#[cfg(test)]
mod tests {
    use super::super::Triangle;
    use super::*;

    /// A unit "tree": one upright triangle in the xz plane, 1 m wide, 2 m tall.
    fn tree() -> Bvh {
        Bvh::build(&[Triangle::new(Vec3::new(-0.5, 0.0, 0.0), Vec3::new(0.5, 0.0, 0.0), Vec3::new(0.0, 0.0, 2.0))])
    }

    #[test]
    fn a_ray_meets_a_placed_tree_where_the_raster_path_draws_it() {
        let inst = Instance { position: Vec3::new(10.0, 5.0, 1.0), yaw: 0.3, scale: 2.0, aspect: 1.5, species: 0 };
        let scene = TraceScene::build(vec![tree()], &[inst]);
        // The model point (0.1, 0, 1) placed as mesh.wgsl places it.
        let g = scene.instances[0];
        let target = g.to_scene(Vec3::new(0.1, 0.0, 1.0));
        let origin = target + Vec3::new(-3.0, -7.0, 0.5);
        let hit = scene.intersect(&Ray { origin, dir: target - origin, t_max: 2.0 }).expect("hit");
        assert_eq!(hit.instance, 0);
        assert!((hit.hit.t - 1.0).abs() < 1e-5, "t {}", hit.hit.t);
        // Beside the crown (model x 0.6 > its half width 0.5 at that height): a miss.
        let beside = g.to_scene(Vec3::new(0.6, 0.0, 1.0));
        assert!(scene.intersect(&Ray { origin, dir: beside - origin, t_max: 2.0 }).is_none());
    }

    #[test]
    fn the_nearest_of_many_trees_is_found_as_a_scan_finds_it() {
        let mut state = 0x2545_f491u32;
        let mut unit = move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            (state >> 8) as f32 / (1u32 << 24) as f32
        };
        let trees: Vec<Instance> = (0..400)
            .map(|i| Instance {
                position: Vec3::new(unit() * 60.0, unit() * 60.0, unit()),
                yaw: unit() * std::f32::consts::TAU,
                scale: 0.5 + unit() * 3.0,
                aspect: 0.7 + unit() * 0.6,
                species: i % 2,
            })
            .collect();
        let scene = TraceScene::build(vec![tree(), tree()], &trees);
        assert_eq!(scene.instances.len(), 400);
        let mut hits = 0;
        let one = tree();
        for _ in 0..1000 {
            let origin = Vec3::new(unit() * 80.0 - 10.0, unit() * 80.0 - 10.0, 0.5 + unit() * 4.0);
            let target = Vec3::new(unit() * 60.0, unit() * 60.0, unit() * 3.0);
            let ray = Ray { origin, dir: target - origin, t_max: 3.0 };
            // The scan: every tree, in its model space.
            let mut scan: Option<(f32, u32)> = None;
            for (i, t) in trees.iter().enumerate() {
                let mut m = GpuInstance::of(t, i as u32).to_model(&ray);
                m.t_max = scan.map_or(ray.t_max, |s| s.0);
                if let Some(h) = one.intersect(&m) {
                    scan = Some((h.t, i as u32));
                }
            }
            let found = scene.intersect(&ray).map(|h| (h.hit.t, h.instance));
            assert_eq!(found, scan, "{ray:?}");
            hits += usize::from(found.is_some());
        }
        assert!(hits > 50, "{hits} of 1000 rays hit a tree");
    }

    #[test]
    fn bad_instances_are_left_out() {
        let ok = Instance { position: Vec3::ZERO, yaw: 0.0, scale: 1.0, aspect: 1.0, species: 0 };
        let scene = TraceScene::build(
            vec![tree()],
            &[
                ok,
                Instance { species: 7, ..ok },
                Instance { scale: 0.0, ..ok },
                Instance { position: Vec3::new(f32::NAN, 0.0, 0.0), ..ok },
                Instance { aspect: f32::INFINITY, ..ok },
            ],
        );
        assert_eq!(scene.instances.iter().map(|i| i.id).collect::<Vec<_>>(), vec![0]);
        assert!(TraceScene::build(vec![tree()], &[])
            .intersect(&Ray { origin: Vec3::ZERO, dir: Vec3::X, t_max: 1.0 })
            .is_none());
    }
}

//! The parametric tree of Weber & Penn 1995 ("Creation and Rendering of
//! Realistic Trees", SIGGRAPH '95), written from the paper: a trunk and up to
//! three levels of stems grown recursively, each stem a chain of `curve_res`
//! segments bent by `curve` (an S-curve with `curve_back`) and at random by
//! `curve_v`, optionally split into clones, tapered (the trunk flared at the
//! ground), carrying children spaced along it whose length follows the
//! crown's shape (`shape_ratio`), leaning away from their parent by the down
//! angle and turning around it by the rotate angle, with leaves on the last
//! level and the stems bending up towards the light (`attraction_up`).
//! Pruning to an envelope is left out.
//!
//! Units: metres, Z up. Deterministic for a seed on one platform (one
//! sequential random stream, no parallel reductions; the platform's `sin`,
//! `cos`, `powf` may round differently elsewhere).

use glam::{Quat, Vec2, Vec3};

use crate::rng::Rng;

/// The crown's shape: how a child's length varies with its height along the
/// trunk.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shape {
    /// Longest at the base: spruce, fir.
    Conical,
    /// Longest in the middle: most broadleaves.
    Spherical,
    /// Longest low, rounded top.
    Hemispherical,
    /// Even lengths: columnar trees.
    Cylindrical,
    /// Lengths from whole at the crown's base to half at its top.
    TaperedCylindrical,
    /// Longest 30 % up the crown.
    Flame,
    /// Longest at the top: umbrella crowns.
    InverseConical,
    /// As flame, never shorter than half.
    TendFlame,
}

/// The shape ratio: `ratio` 0 at the top of the branched trunk, 1 at its base.
#[must_use]
pub fn shape_ratio(shape: Shape, ratio: f32) -> f32 {
    let r = ratio.clamp(0.0, 1.0);
    match shape {
        Shape::Conical => 0.2 + 0.8 * r,
        Shape::Spherical => 0.2 + 0.8 * (std::f32::consts::PI * r).sin(),
        Shape::Hemispherical => 0.2 + 0.8 * (0.5 * std::f32::consts::PI * r).sin(),
        Shape::Cylindrical => 1.0,
        Shape::TaperedCylindrical => 0.5 + 0.5 * r,
        Shape::Flame => {
            if r <= 0.7 {
                r / 0.7
            } else {
                (1.0 - r) / 0.3
            }
        }
        Shape::InverseConical => 1.0 - 0.8 * r,
        Shape::TendFlame => {
            if r <= 0.7 {
                0.5 + 0.5 * r / 0.7
            } else {
                0.5 + 0.5 * (1.0 - r) / 0.3
            }
        }
    }
}

/// One level's parameters (`n…` in the paper; angles in degrees).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Level {
    /// Segments per stem.
    pub curve_res: u32,
    /// Bend over the stem (the first half's with `curve_back`).
    pub curve: f32,
    /// Bend of the stem's second half (0: one bend).
    pub curve_back: f32,
    /// Random bend per stem.
    pub curve_v: f32,
    /// Clones per segment (fractions carried over; at most 4).
    pub seg_splits: f32,
    /// Angle between clones.
    pub split_angle: f32,
    /// Its variation.
    pub split_angle_v: f32,
    /// Children per stem (for the trunk's children: the whole count).
    pub branches: u32,
    /// Angle between a child and its parent.
    pub down_angle: f32,
    /// Its variation (negative: varies with the position along the parent).
    pub down_angle_v: f32,
    /// Turn around the parent from one child to the next (negative: children
    /// alternate sides by `±(180 + rotate)`, in one plane).
    pub rotate: f32,
    /// Its variation.
    pub rotate_v: f32,
    /// Length relative to the parent's.
    pub length: f32,
    /// Its variation.
    pub length_v: f32,
    /// Taper: 0 a cylinder, 1 a cone (to 2 % of the base radius).
    pub taper: f32,
}

impl Level {
    /// A level with the common defaults: `branches` children leaning `down`
    /// degrees, `length` of their parent, `curve_res` segments.
    #[must_use]
    pub const fn new(branches: u32, down: f32, length: f32, curve_res: u32) -> Self {
        Self {
            curve_res,
            curve: 0.0,
            curve_back: 0.0,
            curve_v: 30.0,
            seg_splits: 0.0,
            split_angle: 0.0,
            split_angle_v: 0.0,
            branches,
            down_angle: down,
            down_angle_v: 10.0,
            rotate: 140.0,
            rotate_v: 30.0,
            length,
            length_v: 0.08,
            taper: 1.0,
        }
    }
}

/// A whole tree's parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct Params {
    /// The crown's shape.
    pub shape: Shape,
    /// Share of the trunk without branches.
    pub base_size: f32,
    /// Tree height scale (m) and its variation.
    pub scale: f32,
    /// Variation of the scale (m).
    pub scale_v: f32,
    /// Trunk radius over trunk length.
    pub ratio: f32,
    /// How much thinner children are: `r_child = r_parent (l_child / l_parent)^ratio_power`.
    pub ratio_power: f32,
    /// Trunk flare at the ground (0: none; 1: twice the radius).
    pub flare: f32,
    /// Clones of the trunk at its base (a multi-stem tree).
    pub base_splits: u32,
    /// Upward bending of the stems (negative: drooping, as weeping trees).
    pub attraction_up: f32,
    /// Leaves per stem of the last level.
    pub leaves: u32,
    /// Leaf length (m) and width over length.
    pub leaf_scale: f32,
    /// Leaf width over length.
    pub leaf_scale_x: f32,
    /// Leaves' down angle from their stem (degrees).
    pub leaf_down_angle: f32,
    /// The trunk (0) and each level of children.
    pub levels: Vec<Level>,
}

/// A stem as grown: its points (position, radius), base first, and level.
#[derive(Debug, Clone, PartialEq)]
pub struct Stem {
    /// 0 the trunk.
    pub level: u8,
    /// Positions and radii along the stem.
    pub points: Vec<(Vec3, f32)>,
    /// How many times a bark tile as wide as the stem's circumference
    /// repeats along it (of its length and radius without the variations: the
    /// same in every variant).
    pub bark_repeats: f32,
}

/// A leaf: its centre, the normal of its blade, the direction of its tip and
/// its size (length, width).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Leaf {
    /// Blade centre.
    pub centre: Vec3,
    /// Blade normal.
    pub normal: Vec3,
    /// From stalk to tip.
    pub tip: Vec3,
    /// Length and width (m).
    pub size: Vec2,
}

/// A grown tree.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Skeleton {
    /// Every stem (a stem after its clones and children).
    pub stems: Vec<Stem>,
    /// Every leaf.
    pub leaves: Vec<Leaf>,
}

/// Most stems one tree may grow (a parameter set that would grow more is cut
/// short: children past it are not grown).
pub const MAX_STEMS: usize = 20_000;

/// Most clones one segment splits into.
const MAX_CLONES: f32 = 4.0;

/// Most leaves one tree may carry.
pub const MAX_LEAVES: usize = 200_000;

/// Grows the tree of `p` for `seed`.
#[must_use]
pub fn grow(p: &Params, seed: u64) -> Skeleton {
    grow_variant(p, seed, seed)
}

/// Grows a variant of the tree of `p`: where its stems and leaves sit along
/// their parents, and so how many there are, from `structure`; their angles,
/// bends and lengths from `shape`. Variants of one structure have the same
/// stems with the same points and the same leaves, in the same order — the
/// same mesh topology, different shapes.
#[must_use]
pub fn grow_variant(p: &Params, structure: u64, shape: u64) -> Skeleton {
    let mut g = Grower {
        p,
        rng: Rng::new(shape),
        structure: Rng::new(structure ^ 0x5_7c0c),
        out: Skeleton::default(),
        split_error: vec![0.0; p.levels.len()],
    };
    let Some(trunk) = p.levels.first() else { return g.out };
    let scale = (p.scale + g.var(p.scale_v)).max(0.1);
    let length = scale * (trunk.length + g.var(trunk.length_v)).max(0.05);
    let radius = length * p.ratio;
    let clones = p.base_splits.max(1);
    for c in 0..clones {
        // Base splits lean apart evenly around the base.
        let frame = if clones == 1 {
            Quat::IDENTITY
        } else {
            let azimuth = c as f32 / clones as f32 * std::f32::consts::TAU + g.var(0.3);
            Quat::from_rotation_z(azimuth) * Quat::from_rotation_x(trunk.split_angle.to_radians() * 0.5)
        };
        g.stem(StemStart {
            level: 0,
            origin: Vec3::ZERO,
            frame,
            length,
            radius,
            offset: 0.0,
            along: 0.0,
            parent_length: length,
            nominal: p.scale * trunk.length,
            nominal_radius: p.scale * trunk.length * p.ratio,
            splits: true,
        });
    }
    g.out
}

/// Where and how a stem starts.
#[derive(Debug, Clone, Copy)]
struct StemStart {
    level: usize,
    origin: Vec3,
    /// Orientation: the stem grows along `frame * Z`.
    frame: Quat,
    length: f32,
    radius: f32,
    /// How far along its parent it starts (m; 0 for the trunk).
    offset: f32,
    /// The same as a share of its parent's length (the same in every variant).
    along: f32,
    /// Its parent's length (the trunk's own for the trunk).
    parent_length: f32,
    /// Its length without the variations (m): what decides whether it grows.
    nominal: f32,
    /// Its base radius without the variations (m).
    nominal_radius: f32,
    /// Whether it may split into clones.
    splits: bool,
}

struct Grower<'a> {
    p: &'a Params,
    /// The shape's stream: angles, bends, lengths.
    rng: Rng,
    /// The structure's stream: where children sit along their parents.
    structure: Rng,
    out: Skeleton,
    /// Fractions of clones carried from segment to segment, per level.
    split_error: Vec<f32>,
}

impl Grower<'_> {
    /// A uniform variation in `[-v, v]`.
    fn var(&mut self, v: f32) -> f32 {
        if v == 0.0 {
            0.0
        } else {
            self.rng.range(-v, v)
        }
    }

    fn stem(&mut self, s: StemStart) {
        if self.out.stems.len() >= MAX_STEMS {
            return;
        }
        let p = self.p;
        let l = p.levels[s.level];
        let segs = l.curve_res.max(1);
        let seg_len = s.length / segs as f32;
        let curve_v = self.var(l.curve_v) / segs as f32;
        let mut frame = s.frame;
        let mut pos = s.origin;
        let radius_at = |z: f32| {
            // taper from the base radius towards the tip; the trunk flares.
            let mut r = s.radius * (1.0 - l.taper.clamp(0.0, 1.0) * z).max(0.02);
            if s.level == 0 {
                let y = (1.0 - 8.0 * z).max(0.0);
                r *= 1.0 + p.flare * (100f32.powf(y) - 1.0) / 100.0;
            }
            r
        };
        let mut points = vec![(pos, radius_at(0.0))];
        // Frames at each point (children take their parent's there).
        let mut frames = vec![frame];
        for i in 0..segs {
            // The bend of this segment (an S-curve: `curve` over the first half,
            // `curve_back` over the second).
            let bend = if l.curve_back == 0.0 {
                l.curve / segs as f32
            } else if i < segs.div_ceil(2) {
                l.curve / (segs as f32 / 2.0)
            } else {
                l.curve_back / (segs as f32 / 2.0)
            };
            frame *= Quat::from_rotation_x((bend + curve_v).to_radians());
            // Stems bend towards the light (the trunk stays as bent); a negative
            // attraction droops them, at most to straight down.
            if s.level > 0 && p.attraction_up != 0.0 {
                let dir = frame * Vec3::Z;
                let declination = dir.z.clamp(-1.0, 1.0).acos();
                let axis = dir.cross(Vec3::Z);
                if axis.length_squared() > 1e-8 {
                    let turn = p.attraction_up * declination / segs as f32;
                    let turn = turn.clamp(-(std::f32::consts::PI - declination), declination);
                    frame = Quat::from_axis_angle(axis.normalize(), turn) * frame;
                }
            }
            pos += frame * Vec3::Z * seg_len;
            let z = (i + 1) as f32 / segs as f32;
            points.push((pos, radius_at(z)));
            frames.push(frame);
            // Clones split off at this segment's end (not the stem's tip); the
            // stem leans away from them from the next segment on.
            if l.seg_splits > 0.0 && s.splits && i + 1 < segs {
                let want = l.seg_splits + self.split_error[s.level];
                let clones = want.floor().clamp(0.0, MAX_CLONES);
                self.split_error[s.level] = want - clones;
                for _ in 0..clones as u32 {
                    let angle = (l.split_angle + self.var(l.split_angle_v)).to_radians();
                    let around = self.rng.range(0.0, std::f32::consts::TAU);
                    let clone = StemStart {
                        level: s.level,
                        origin: pos,
                        frame: frame * Quat::from_rotation_z(around) * Quat::from_rotation_x(angle),
                        length: s.length - (i + 1) as f32 * seg_len,
                        radius: radius_at(z) * 0.8,
                        offset: s.offset,
                        along: s.along,
                        parent_length: s.parent_length,
                        nominal: s.nominal * (1.0 - (i + 1) as f32 / segs as f32),
                        nominal_radius: s.nominal_radius * (1.0 - l.taper.clamp(0.0, 1.0) * z).max(0.02) * 0.8,
                        // (A clone does not split again.)
                        splits: false,
                    };
                    self.stem(clone);
                    frame = frame
                        * Quat::from_rotation_z(around)
                        * Quat::from_rotation_x(-angle * 0.5)
                        * Quat::from_rotation_z(-around);
                }
            }
        }
        self.children(&s, &points, &frames);
        let bark_repeats = s.nominal / (std::f32::consts::TAU * s.nominal_radius).max(1e-3);
        self.out.stems.push(Stem { level: s.level as u8, points, bark_repeats });
    }

    /// The children (or leaves) of stem `s` along `points`.
    fn children(&mut self, s: &StemStart, points: &[(Vec3, f32)], frames: &[Quat]) {
        let p = self.p;
        let child_level = s.level + 1;
        let leaves = child_level >= p.levels.len();
        let (count, from) = if leaves {
            // leaves on the last level's stems, more where the stem sits
            // farther out along its parent.
            let n = p.leaves as f32 * shape_ratio(Shape::TaperedCylindrical, s.along);
            (n.round() as u32, 0.0)
        } else if s.level == 0 {
            (p.levels[child_level].branches, p.base_size.clamp(0.0, 0.95))
        } else {
            let n = p.levels[child_level].branches as f32 * (1.0 - 0.5 * s.along);
            (n.round().max(0.0) as u32, 0.0)
        };
        if count == 0 || s.length <= 0.0 {
            return;
        }
        let lc = if leaves { p.levels[s.level] } else { p.levels[child_level] };
        let mut turn_acc = self.rng.range(0.0, 360.0);
        let segs = points.len() - 1;
        for k in 0..count {
            // Where a child sits, as shares of its parent (`from` the bare
            // share below the first): the same in every variant.
            let jitter = self.structure.range(-0.3, 0.3);
            let t = ((k as f32 + 0.5 + jitter) / count as f32).clamp(0.0, 1.0);
            let along = from + (1.0 - from) * t;
            let offset = s.length * along;
            // The point and frame of the parent there.
            let at_seg = along * segs as f32;
            let i = (at_seg.floor() as usize).min(segs - 1);
            let f = at_seg - i as f32;
            let at = points[i].0.lerp(points[i + 1].0, f);
            let parent_r = points[i].1 + (points[i + 1].1 - points[i].1) * f;
            let frame = frames[i + 1];
            // the rotate and down angles.
            // A negative rotate alternates sides by ±(180 + rotate) around a base:
            // children in one plane (flat sprays, opposite pairs at −180... 0).
            let step = lc.rotate + self.var(lc.rotate_v);
            let turn = if lc.rotate >= 0.0 {
                turn_acc += step;
                turn_acc
            } else {
                let side = if k % 2 == 0 { 1.0 } else { -1.0 };
                turn_acc + side * (180.0 + step)
            };
            if leaves {
                if self.out.leaves.len() >= MAX_LEAVES {
                    return;
                }
                let down = (p.leaf_down_angle + self.var(15.0)).to_radians();
                let leaf_frame = frame * Quat::from_rotation_z(turn.to_radians()) * Quat::from_rotation_x(down);
                let tip = (leaf_frame * Vec3::Z).normalize();
                let len = p.leaf_scale * self.rng.range(0.85, 1.15);
                let size = Vec2::new(len, len * p.leaf_scale_x);
                // Blades turn their faces up towards the light.
                let side = tip.cross(Vec3::Z);
                let normal = if side.length_squared() > 1e-6 { side.cross(tip).normalize() } else { Vec3::X };
                self.out.leaves.push(Leaf { centre: at + tip * (parent_r + len * 0.5), normal, tip, size });
                continue;
            }
            // How far from the top of the branched part (1 at its base).
            let r = 1.0 - t;
            let down = if lc.down_angle_v >= 0.0 {
                lc.down_angle + self.var(lc.down_angle_v)
            } else {
                lc.down_angle + lc.down_angle_v * (1.0 - 2.0 * shape_ratio(Shape::Conical, r))
            };
            let length_max = (lc.length + self.var(lc.length_v)).max(0.0);
            let (length, nominal) = if s.level == 0 {
                let shape = shape_ratio(p.shape, r);
                (s.length * length_max * shape, s.nominal * lc.length * shape)
            } else {
                let share = 1.0 - 0.6 * along;
                (length_max * s.length * share, lc.length * s.nominal * share)
            };
            // Whether it grows is the structure's (its length without the
            // variations); a variant's grows at least a centimetre.
            if nominal <= 0.01 {
                continue;
            }
            let length = length.max(0.01);
            let radius = (s.radius * (length / s.length).powf(p.ratio_power)).min(parent_r * 0.9);
            let child_frame =
                frame * Quat::from_rotation_z(turn.to_radians()) * Quat::from_rotation_x(down.to_radians());
            self.stem(StemStart {
                level: child_level,
                origin: at,
                frame: child_frame,
                length,
                radius,
                offset,
                along,
                parent_length: s.length,
                nominal,
                nominal_radius: s.nominal_radius * (nominal / s.nominal.max(1e-6)).powf(p.ratio_power),
                splits: true,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(shape: Shape) -> Params {
        // The library's level, with this test's variations.
        let level = |branches, down, length| Level {
            curve_v: 20.0,
            rotate_v: 20.0,
            length_v: 0.05,
            ..Level::new(branches, down, length, 4)
        };
        Params {
            shape,
            base_size: 0.3,
            scale: 20.0,
            scale_v: 0.0,
            ratio: 0.02,
            ratio_power: 1.3,
            flare: 0.5,
            base_splits: 0,
            attraction_up: 0.5,
            leaves: 10,
            leaf_scale: 0.2,
            leaf_scale_x: 0.6,
            leaf_down_angle: 50.0,
            levels: vec![Level { curve_v: 5.0, ..level(0, 0.0, 1.0) }, level(30, 60.0, 0.35), level(8, 45.0, 0.5)],
        }
    }

    #[test]
    fn shape_ratios_match_the_paper() {
        assert_eq!(shape_ratio(Shape::Conical, 1.0), 1.0);
        assert!((shape_ratio(Shape::Spherical, 0.5) - 1.0).abs() < 1e-6);
        assert!((shape_ratio(Shape::Flame, 0.7) - 1.0).abs() < 1e-6);
        assert!((shape_ratio(Shape::InverseConical, 0.0) - 1.0).abs() < 1e-6);
        assert_eq!(shape_ratio(Shape::Cylindrical, 0.3), 1.0);
    }

    #[test]
    fn a_tree_grows_the_same_for_a_seed_and_differs_for_another() {
        let p = params(Shape::Spherical);
        let a = grow(&p, 7);
        assert_eq!(a, grow(&p, 7));
        assert_ne!(a, grow(&p, 8));
        // A trunk, 30 branches with their twigs, leaves on the twigs.
        assert_eq!(a.stems.iter().filter(|s| s.level == 0).count(), 1);
        assert_eq!(a.stems.iter().filter(|s| s.level == 1).count(), 30);
        assert!(a.stems.iter().filter(|s| s.level == 2).count() > 100);
        assert!(a.leaves.len() > 500, "{} leaves", a.leaves.len());
        // The trunk is about 20 m tall; the crown starts above its base share.
        let trunk = a.stems.iter().find(|s| s.level == 0).unwrap();
        let top = trunk.points.last().unwrap().0;
        assert!((top.z - 20.0).abs() < 2.0, "trunk top {top}");
        let lowest_branch = a.stems.iter().filter(|s| s.level == 1).map(|s| s.points[0].0.z).fold(f32::MAX, f32::min);
        assert!(lowest_branch > 0.25 * 20.0, "lowest branch at {lowest_branch}");
    }

    #[test]
    fn a_conical_crown_is_widest_low_and_a_spherical_in_the_middle() {
        // Half width of the branches' reach in the crown's lower and upper third.
        let reach = |shape| {
            let t = grow(&params(shape), 3);
            let mut low: f32 = 0.0;
            let mut high: f32 = 0.0;
            for s in t.stems.iter().filter(|s| s.level == 1) {
                let base = s.points[0].0;
                let tip = s.points.last().unwrap().0;
                let r = (tip - base).truncate().length();
                if base.z < 6.0 + 14.0 / 3.0 {
                    low = low.max(r);
                } else if base.z > 6.0 + 28.0 / 3.0 {
                    high = high.max(r);
                }
            }
            (low, high)
        };
        let (low, high) = reach(Shape::Conical);
        assert!(low > 2.0 * high, "conical: low {low}, high {high}");
        let (low, high) = reach(Shape::InverseConical);
        assert!(high > 1.5 * low, "inverse conical: low {low}, high {high}");
    }
}

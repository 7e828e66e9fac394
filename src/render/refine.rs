//! Progressive refinement while the camera rests (Dietrich et al. 2005): frames jittered
//! by sub-pixel offsets accumulate into an anti-aliased image, and the
//! level-of-detail quality rises step by step (projected sizes ×2, ×4, …,
//! leaves alpha-tested at full resolution) up to full meshes for what is in
//! view (the last level draws every tree in view as its full mesh). Any change of camera or settings starts over at once; new data
//! restarts the level being accumulated. When the last level has converged
//! the host stops drawing (an idle GPU).
//!
//! Level 0 is the normal frame: its first step is exactly what a frame
//! without refinement draws, and its jittered steps accumulate on the image
//! shown. A finer level accumulates apart (the *pending* image) while the
//! converged coarser one stays on screen, and replaces it only once it has
//! converged too, so what is shown never gets noisier on the way. A level whose
//! frames lost draw items to full pool segments (the memory budget) is
//! dropped: the refinement ends at the level before.
//!
//! [`Refinement`] is the CPU state machine (tested without a GPU);
//! [`Accumulator`] the two passes (blend into a linear `rgba16float` image,
//! resolve it into the target) and their textures.

use glam::{Mat4, Vec2, Vec3};

use super::settings::RenderSettings;
use crate::camera::ViewData;

/// How a resting camera refines its image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RefineConfig {
    /// Refine at all (off: every frame is a plain frame).
    pub enabled: bool,
    /// Jittered frames accumulated per level (≥ 1).
    pub jitter_frames: u32,
    /// Quality levels above the normal frame: level `k` scales projected sizes
    /// by `2^k` before LoD selection, and the last one draws every tree in view
    /// as its full mesh (0: jitter only).
    pub levels: u32,
}

/// The most quality levels a refinement climbs.
pub const MAX_REFINE_LEVELS: u32 = 4;

/// Factor on projected sizes so large that every tree in view is above its
/// full mesh's threshold: the last level's (and the accuracy reference's).
pub const FULL_MESH_QUALITY: f32 = 1.0e6;

impl Default for RefineConfig {
    fn default() -> Self {
        Self { enabled: false, jitter_frames: 16, levels: 3 }
    }
}

impl RefineConfig {
    /// The steps from rest to converged: `jitter_frames × (levels + 1)`.
    #[must_use]
    pub fn total_steps(&self) -> u32 {
        self.jitter_frames.max(1) * (self.levels.min(MAX_REFINE_LEVELS) + 1)
    }
}

/// What one refinement step draws.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plan {
    /// Draw the scene at all (false once converged: only the image is shown).
    pub render: bool,
    /// Sub-pixel offset of the projection (pixels, within ±½).
    pub jitter_px: Vec2,
    /// Factor on projected sizes before LoD selection.
    pub quality_scale: f32,
    /// Alpha tests at the textures' full resolution (see
    /// [`RenderSettings::full_res_alpha`]): on at the finer levels, whose
    /// accumulation does the filtering the texture's mips would.
    pub full_res_alpha: bool,
    /// Rotates the cross-fade dither so the accumulation blends both sides.
    pub seed: u32,
    /// Accumulate into the pending image (finer levels) rather than the shown one.
    pub into_pending: bool,
    /// Weight of this frame in its accumulation (1: replaces it).
    pub blend: f32,
}

/// What a refinement compares to know the camera or settings changed.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Key {
    clip: Mat4,
    eye_hi: Vec3,
    eye_lo: Vec3,
    viewport: [u32; 2],
    settings: RenderSettings,
    config: RefineConfig,
}

/// The refinement's state (see the module docs).
#[derive(Debug, Clone, Default)]
pub struct Refinement {
    /// How to refine.
    pub config: RefineConfig,
    key: Option<Key>,
    /// What the drawn data was the last time (see [`Self::observe`]).
    data: u64,
    settled: bool,
    level: u32,
    n: u32,
    converged: bool,
    dropped: bool,
    /// Counters of a frame of the current level have been seen.
    counted: bool,
    level_start_frame: u64,
}

/// The `i`-th element (from 1) of the van der Corput sequence in `base`.
fn radical_inverse(mut i: u32, base: u32) -> f32 {
    let (mut f, mut r) = (1.0f32, 0.0f32);
    while i > 0 {
        f /= base as f32;
        r += f * (i % base) as f32;
        i /= base;
    }
    r
}

/// Sub-pixel offset `i` (from 1) of the Halton (2, 3) sequence, in ±½ px.
#[must_use]
pub fn halton_jitter(i: u32) -> Vec2 {
    Vec2::new(radical_inverse(i, 2), radical_inverse(i, 3)) - 0.5
}

/// `view` with its projection shifted by `jitter_px` pixels (right, down).
/// The frustum planes stay the unshifted ones: what is culled does not change.
#[must_use]
pub fn jittered(view: &ViewData, jitter_px: Vec2) -> ViewData {
    if jitter_px == Vec2::ZERO {
        return *view;
    }
    let [w, h] = view.viewport.map(|v| v.max(1) as f32);
    let shift = Mat4::from_translation(Vec3::new(2.0 * jitter_px.x / w, -2.0 * jitter_px.y / h, 0.0));
    ViewData { clip_from_eye: shift * view.clip_from_eye, ..*view }
}

impl Refinement {
    /// A refinement configured by `config`.
    #[must_use]
    pub fn new(config: RefineConfig) -> Self {
        Self { config, ..Self::default() }
    }

    fn levels(&self) -> u32 {
        self.config.levels.min(MAX_REFINE_LEVELS)
    }

    fn frames_per_level(&self) -> u32 {
        self.config.jitter_frames.max(1)
    }

    /// Looks at the frame about to be drawn: a different camera, viewport or
    /// settings start over; data still loading (`settled` false) or changed
    /// (`data`, a digest of what is resident: bytes fetched, tiles, terrain
    /// and imagery, trees) restart the level being accumulated. Returns
    /// whether it started over.
    pub fn observe(&mut self, view: &ViewData, settings: &RenderSettings, settled: bool, data: u64) -> bool {
        let key = Key {
            clip: view.clip_from_eye,
            eye_hi: view.eye_hi,
            eye_lo: view.eye_lo,
            viewport: view.viewport,
            settings: *settings,
            config: self.config,
        };
        let moved = self.key != Some(key);
        if moved {
            self.key = Some(key);
            self.restart_all();
        } else if !settled || data != self.data {
            if self.converged {
                // The data changed under a converged image: start over.
                self.restart_all();
            }
            self.n = 0;
        }
        self.data = data;
        self.settled = settled;
        moved
    }

    /// Starts over from the plain frame: something the refinement cannot see
    /// changed what is drawn (a host's stream or imagery settings).
    pub fn invalidate(&mut self) {
        self.key = None;
        self.restart_all();
    }

    fn restart_all(&mut self) {
        self.level = 0;
        self.n = 0;
        self.converged = false;
        self.dropped = false;
        self.counted = false;
    }

    /// What the next step draws.
    #[must_use]
    pub fn plan(&self) -> Plan {
        let level = self.level.min(self.levels());
        Plan {
            render: !self.converged,
            // A level's first step is unjittered: the first step at rest is the plain frame.
            jitter_px: if self.n == 0 { Vec2::ZERO } else { halton_jitter(self.n) },
            quality_scale: if level > 0 && level == self.levels() { FULL_MESH_QUALITY } else { (1u32 << level) as f32 },
            full_res_alpha: level > 0,
            seed: self.step(),
            into_pending: level > 0,
            blend: 1.0 / (self.n + 1) as f32,
        }
    }

    /// The step just planned was drawn as frame `frame` (the host's count).
    /// Returns true when the pending image has converged and is now the one
    /// to show (the host swaps its images). A frame drawn while data was still
    /// loading counts for nothing. A finer level is shown once counters of one
    /// of its frames came back without dropped draw items (in the browser they
    /// arrive a few frames late: it accumulates on meanwhile), or after four
    /// times its frames without any (a host that reads no counters).
    pub fn advance(&mut self, frame: u64) -> bool {
        if self.converged || !self.config.enabled || !self.settled {
            return false;
        }
        if self.n == 0 && self.level > 0 {
            // A finer level (re)starts: only its own frames' counters count.
            self.level_start_frame = frame;
            self.counted = false;
        }
        self.n += 1;
        let per_level = self.frames_per_level();
        if self.n < per_level || (self.level > 0 && !self.counted && self.n < 4 * per_level) {
            return false;
        }
        let finished = self.level;
        if finished >= self.levels() {
            self.converged = true;
        } else {
            self.level += 1;
            self.n = 0;
            self.counted = false;
            self.level_start_frame = frame + 1;
        }
        finished > 0
    }

    /// The counters of frame `frame` came back with `items_dropped` items lost
    /// to full segments: a finer level that drops trees is given up at once,
    /// and the refinement ends at the level before (the image shown).
    pub fn note_counters(&mut self, frame: u64, items_dropped: u32) {
        if self.converged || self.level == 0 || frame < self.level_start_frame {
            return;
        }
        self.counted = true;
        if items_dropped > 0 {
            self.dropped = true;
            self.level -= 1;
            self.converged = true;
        }
    }

    /// A finer level was given up because it dropped trees (the memory budget).
    #[must_use]
    pub fn dropped(&self) -> bool {
        self.dropped
    }

    /// Steps done since the camera came to rest (`level × jitter_frames + n`;
    /// `(level + 1) × jitter_frames` when converged, [`RefineConfig::total_steps`]
    /// unless a level was given up).
    #[must_use]
    pub fn step(&self) -> u32 {
        if self.converged {
            return (self.level + 1) * self.frames_per_level();
        }
        self.level * self.frames_per_level() + self.n.min(self.frames_per_level())
    }

    /// The quality level being accumulated (once converged: the one shown).
    #[must_use]
    pub fn level(&self) -> u32 {
        self.level
    }

    /// Nothing left to refine: the host may stop drawing.
    #[must_use]
    pub fn converged(&self) -> bool {
        self.converged
    }

    /// `settings` as the planned step draws them.
    #[must_use]
    pub fn settings(&self, settings: &RenderSettings, plan: &Plan) -> RenderSettings {
        RenderSettings {
            quality: settings.quality * plan.quality_scale,
            full_res_alpha: settings.full_res_alpha || plan.full_res_alpha,
            refine_seed: plan.seed,
            ..*settings
        }
    }
}

/// The accumulation format: linear, blendable, 16-bit float.
pub const ACCUM_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

/// The passes and images of a refinement: the scene is drawn into `scene`,
/// blended into one of two linear images (shown / pending) and resolved from
/// the shown one into the host's target.
pub struct Accumulator {
    layout: wgpu::BindGroupLayout,
    blend: wgpu::RenderPipeline,
    resolve: wgpu::RenderPipeline,
    images: Option<Images>,
    color_format: wgpu::TextureFormat,
}

struct Images {
    size: [u32; 2],
    scene: wgpu::TextureView,
    scene_group: wgpu::BindGroup,
    accum: [wgpu::TextureView; 2],
    accum_groups: [wgpu::BindGroup; 2],
    /// Which of `accum` is shown.
    shown: usize,
}

impl Accumulator {
    /// The passes for a host drawing into `color_format` targets.
    #[must_use]
    pub fn new(device: &wgpu::Device, color_format: wgpu::TextureFormat) -> Self {
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("accumulate"),
            entries: &[super::layouts::texture_entry(0, wgpu::TextureViewDimension::D2)],
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("accumulate"),
            source: wgpu::ShaderSource::Wgsl(super::shaders::ACCUMULATE.source().into()),
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("accumulate"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = |label: &str, target: wgpu::ColorTargetState| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(&pipeline_layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                primitive: wgpu::PrimitiveState::default(),
                depth_stencil: None,
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs_main"),
                    compilation_options: Default::default(),
                    targets: &[Some(target)],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        // new = frame × c + accumulated × (1 − c), c the blend constant.
        let mix = wgpu::BlendComponent {
            src_factor: wgpu::BlendFactor::Constant,
            dst_factor: wgpu::BlendFactor::OneMinusConstant,
            operation: wgpu::BlendOperation::Add,
        };
        let blend = pipeline(
            "accumulate blend",
            wgpu::ColorTargetState {
                format: ACCUM_FORMAT,
                blend: Some(wgpu::BlendState { color: mix, alpha: mix }),
                write_mask: wgpu::ColorWrites::ALL,
            },
        );
        let resolve = pipeline("accumulate resolve", color_format.into());
        Self { layout, blend, resolve, images: None, color_format }
    }

    /// The texture the scene is drawn into (resized to `size` first).
    pub fn scene_target(&mut self, device: &wgpu::Device, size: [u32; 2]) -> wgpu::TextureView {
        let size = size.map(|v| v.max(1));
        if self.images.as_ref().is_none_or(|i| i.size != size) {
            self.images = Some(self.make_images(device, size));
        }
        self.images.as_ref().map(|i| i.scene.clone()).expect("images were just made")
    }

    fn make_images(&self, device: &wgpu::Device, size: [u32; 2]) -> Images {
        let texture = |label: &str, format| {
            device
                .create_texture(&wgpu::TextureDescriptor {
                    label: Some(label),
                    size: wgpu::Extent3d { width: size[0], height: size[1], depth_or_array_layers: 1 },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
                    view_formats: &[],
                })
                .create_view(&Default::default())
        };
        let group = |view: &wgpu::TextureView| {
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("accumulate"),
                layout: &self.layout,
                entries: &[wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(view) }],
            })
        };
        let scene = texture("refine scene", self.color_format);
        let accum = [texture("refine shown", ACCUM_FORMAT), texture("refine pending", ACCUM_FORMAT)];
        Images {
            size,
            scene_group: group(&scene),
            accum_groups: [group(&accum[0]), group(&accum[1])],
            scene,
            accum,
            shown: 0,
        }
    }

    /// GPU bytes of the images (0 before the first refined frame).
    #[must_use]
    pub fn bytes(&self) -> u64 {
        self.images.as_ref().map_or(0, |i| u64::from(i.size[0]) * u64::from(i.size[1]) * (4 + 2 * 8))
    }

    /// Records the step `plan` after the scene was drawn into
    /// [`Self::scene_target`]: blends it in (when drawn), swaps the images when
    /// `swap`, then resolves the shown image into `target`.
    pub fn encode(&mut self, encoder: &mut wgpu::CommandEncoder, plan: &Plan, swap: bool, target: &wgpu::TextureView) {
        let Some(images) = self.images.as_mut() else { return };
        if plan.render {
            let into = if plan.into_pending { 1 - images.shown } else { images.shown };
            let load = if plan.blend >= 1.0 { wgpu::LoadOp::Clear(wgpu::Color::BLACK) } else { wgpu::LoadOp::Load };
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("accumulate"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &images.accum[into],
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations { load, store: wgpu::StoreOp::Store },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&self.blend);
            let c = f64::from(plan.blend.clamp(0.0, 1.0));
            pass.set_blend_constant(wgpu::Color { r: c, g: c, b: c, a: c });
            pass.set_bind_group(0, &images.scene_group, &[]);
            pass.draw(0..3, 0..1);
        }
        if swap {
            images.shown = 1 - images.shown;
        }
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("resolve"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: target,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color::BLACK), store: wgpu::StoreOp::Store },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&self.resolve);
        pass.set_bind_group(0, &images.accum_groups[images.shown], &[]);
        pass.draw(0..3, 0..1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;

    fn view() -> ViewData {
        Camera::look_at(glam::DVec3::new(0.0, -50.0, 20.0), glam::DVec3::ZERO).view_data(64, 48)
    }

    /// Runs steps until converged (at most `limit`), returning the plans; the
    /// counters of each frame come back before the next (as natively).
    fn run(r: &mut Refinement, view: &ViewData, limit: usize) -> Vec<(Plan, bool)> {
        let s = RenderSettings::default();
        let mut out = Vec::new();
        for f in 0..limit as u64 {
            r.observe(view, &s, true, 7);
            r.note_counters(f, 0);
            let plan = r.plan();
            if !plan.render {
                break;
            }
            out.push((plan, r.advance(f + 1)));
        }
        out
    }

    #[test]
    fn steps_rise_through_the_levels_and_converge() {
        let mut r = Refinement::new(RefineConfig { enabled: true, jitter_frames: 4, levels: 2 });
        let plans = run(&mut r, &view(), 100);
        assert_eq!(plans.len(), 12);
        assert!(r.converged() && r.step() == 12);
        // The first step is the plain frame.
        let (first, _) = plans[0];
        assert_eq!(
            (first.jitter_px, first.quality_scale, first.blend, first.into_pending),
            (Vec2::ZERO, 1.0, 1.0, false)
        );
        // Within a level: jittered within ±½ px, running-mean weights.
        for (i, (p, _)) in plans.iter().enumerate() {
            let n = (i % 4) as f32;
            assert!((p.blend - 1.0 / (n + 1.0)).abs() < 1e-6, "step {i}: {}", p.blend);
            assert!(p.jitter_px.abs().max_element() <= 0.5);
            assert_eq!(p.quality_scale, [1.0, 2.0, FULL_MESH_QUALITY][i / 4]);
            assert_eq!(p.into_pending, i >= 4);
        }
        // The pending image is shown once its level has converged.
        let swaps: Vec<usize> = plans.iter().enumerate().filter(|(_, (_, s))| *s).map(|(i, _)| i).collect();
        assert_eq!(swaps, [7, 11]);
        // Distinct jitters within a level.
        let j: Vec<Vec2> = plans[1..4].iter().map(|(p, _)| p.jitter_px).collect();
        assert!(j[0] != j[1] && j[1] != j[2] && j[0] != j[2]);
    }

    #[test]
    fn a_move_starts_over_and_new_data_restarts_the_level() {
        let mut r = Refinement::new(RefineConfig { enabled: true, jitter_frames: 4, levels: 1 });
        let v = view();
        let s = RenderSettings::default();
        run(&mut r, &v, 6);
        assert_eq!((r.level(), r.step()), (1, 6));
        // New data at level 1: that level starts again.
        r.observe(&v, &s, true, 8);
        assert_eq!((r.level(), r.step()), (1, 4));
        // Still loading: no accumulation.
        r.observe(&v, &s, false, 8);
        assert_eq!(r.plan().blend, 1.0);
        // A camera move: back to the plain frame.
        let moved = jittered(&v, Vec2::new(0.3, 0.0));
        assert!(r.observe(&moved, &s, true, 8));
        assert_eq!((r.level(), r.step(), r.plan().jitter_px), (0, 0, Vec2::ZERO));
        // So does a change of settings.
        run(&mut r, &moved, 3);
        assert!(r.observe(&moved, &RenderSettings { quality: 0.5, ..s }, true, 8));
        assert_eq!(r.step(), 0);
    }

    #[test]
    fn a_level_that_drops_trees_is_given_up() {
        let mut r = Refinement::new(RefineConfig { enabled: true, jitter_frames: 3, levels: 2 });
        let v = view();
        let s = RenderSettings::default();
        for f in 1..=4 {
            r.observe(&v, &s, true, 0);
            r.advance(f);
        }
        assert_eq!((r.level(), r.step()), (1, 4));
        // Counters of a level-0 frame do not count against level 1.
        r.note_counters(2, 50);
        assert!(!r.converged());
        // Level 1's first frame dropped trees: it is given up at once, and the
        // refinement ends with level 0's image.
        r.note_counters(4, 50);
        assert!(r.converged() && r.dropped());
        assert_eq!((r.level(), r.step()), (0, 3));
        assert!(!r.plan().render);
    }

    #[test]
    fn a_finer_level_waits_for_its_counters_and_loading_frames_count_for_nothing() {
        let mut r = Refinement::new(RefineConfig { enabled: true, jitter_frames: 2, levels: 1 });
        let v = view();
        let s = RenderSettings::default();
        // Still loading: frames are drawn, nothing accumulates.
        r.observe(&v, &s, false, 0);
        assert!(!r.advance(1));
        assert_eq!(r.step(), 0);
        for f in 2..=3 {
            r.observe(&v, &s, true, 0);
            r.advance(f);
        }
        assert_eq!(r.level(), 1);
        // Level 1 has its frames but no counters yet (the browser's lag): it
        // accumulates on rather than being shown unchecked.
        for f in 4..=5 {
            r.observe(&v, &s, true, 0);
            assert!(!r.advance(f));
        }
        r.note_counters(4, 0);
        r.observe(&v, &s, true, 0);
        assert!(r.advance(6), "shown once its counters came back clean");
        assert!(r.converged() && !r.dropped());
        assert_eq!((r.level(), r.step()), (1, 4));
        // Something the refinement cannot see changed: start over.
        r.invalidate();
        r.observe(&v, &s, true, 0);
        assert_eq!((r.level(), r.step(), r.converged()), (0, 0, false));
    }

    #[test]
    fn jitter_shifts_the_projection_by_sub_pixels() {
        let v = view();
        let j = jittered(&v, Vec2::new(0.5, -0.25));
        let p = glam::Vec4::new(1.0, 30.0, -2.0, 1.0);
        let (a, b) = (v.clip_from_eye * p, j.clip_from_eye * p);
        let px = |c: glam::Vec4| Vec2::new((c.x / c.w * 0.5 + 0.5) * 64.0, (0.5 - c.y / c.w * 0.5) * 48.0);
        let d = px(b) - px(a);
        assert!((d - Vec2::new(0.5, -0.25)).length() < 1e-3, "{d}");
        assert_eq!(j.frustum, v.frustum);
    }
}

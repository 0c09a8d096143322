//! Mixed reality (docs/design.md §6): virtual content lit by a real room's RGB-D frames, rendered
//! from each frame's camera and composited over its colour image, the real depth hiding the
//! virtual object where real surfaces are nearer.
//!
//! [`MrPipeline`] is the per-frame pipeline (VALs, environment, render, differential
//! relighting of the real surfaces, composite) on a renderer it is given; [`MrRenderer`] runs it
//! for `relume replay` (frame in, composited image + indirect image + timings out), and the
//! service's streams run it on the scene's shared renderer (`service::gpu_worker`).

pub mod crop;
pub mod differential;
pub mod environment;
pub mod replay;
pub mod synthetic;

use crate::gpu::differential::Differential;
use crate::gpu::timing::StageTimings;
use crate::gpu::{Gpu, GpuError};
use crate::image::{LinearImage, encode_srgb};
use crate::renderer::{Method, Rendered, Renderer};
use crate::rgbd::accumulate::ValAccumulator;
use crate::rgbd::{RgbdFrame, RgbdSettings};
use crate::scene::Scene;
use crate::scene::settings::{DifferentialDevice, DifferentialMethod};
use crate::twin::Val;
use crop::Crop;
use differential::{Emitter, LightField, MrSettings, ReceiverGrid};
use environment::Environment;
use glam::{DAffine3, Mat4, Vec3};
use std::time::Instant;

/// How replayed frames are lit and rendered.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MrOptions {
    /// Output size; the frame's intrinsics are scaled to it.
    pub width: u32,
    pub height: u32,
    /// Exposure of the virtual object in the composite, on the camera's scale: its radiance is
    /// divided by `radiance_scale` (camera value = radiance / `radiance_scale`, as the room's
    /// VALs were made) and multiplied by this before sRGB encoding ([`display_scale`]). The
    /// default 1 shows a virtual surface as the camera would show a real one of the same
    /// radiance, whatever `radiance_scale` is.
    pub exposure: f32,
    /// Accumulate VALs across frames into a world-space set (None: each frame's VALs only).
    pub accumulate: Option<AccumulateOptions>,
}

/// The persistent VAL set of [`ValAccumulator`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AccumulateOptions {
    /// Grid cell (m): one VAL per cell, the newest.
    pub cell_size: f32,
    /// Memory bound: VALs kept at most (the oldest go first).
    pub max_vals: usize,
    /// VALs older than this many frames are dropped.
    pub max_age_frames: u32,
}

impl Default for AccumulateOptions {
    fn default() -> Self {
        Self { cell_size: 0.05, max_vals: 65_536, max_age_frames: 300 }
    }
}

/// One relit frame.
pub struct MrFrame {
    /// The camera image with the virtual object composited in (sRGB, row-major).
    pub composited: Vec<[u8; 3]>,
    /// Indirect light on the virtual object alone (linear radiance; alpha = coverage).
    pub indirect: LinearImage,
    /// Direct light of the scene's own spot light, if it has one.
    pub direct: LinearImage,
    pub timings: StageTimings,
    /// VALs that lit the frame (the frame's, or the accumulated set, plus the spot's).
    pub val_count: u32,
    /// Diffuse irradiance (W/m²) at each sparse point of the virtual object: view-independent,
    /// so its change between frames measures how steady the light is.
    pub sparse_irradiance: Vec<Vec3>,
    /// The frame's estimated indirect error, when the renderer estimates it
    /// (`Renderer::set_error_estimate`).
    pub error_estimate: Option<crate::renderer::estimate::ErrorEstimate>,
    /// The differential pass's receivers and their light, when it ran.
    pub differential: Option<DifferentialFrame>,
}

/// One frame's differential pass: its receivers, their light and how much of it was computed.
#[derive(Clone, Debug)]
pub struct DifferentialFrame {
    /// How the pass summed: the scene's `settings.mr.differential_method`, else the frame's
    /// ([`DifferentialMethod::for_frames`]).
    pub method: DifferentialMethod,
    pub grid: ReceiverGrid,
    pub light: Vec<crate::gpu::differential::ReceiverLight>,
    pub counts: differential::AdaptiveCounts,
    /// Per receiver, whether the composite shows it (the virtual content does not hide it).
    pub visible: Vec<bool>,
    /// The VALs it summed: `vals[.. real_count]` the real ones, the rest the re-emitters.
    pub vals: Vec<Val>,
    pub real_count: usize,
    /// The virtual content's box (min, max corners, the scene's frame).
    pub bounds: (Vec3, Vec3),
}

/// `relume replay`'s renderer: one scene's [`Renderer`] and [`MrPipeline`], the replay's
/// options and its VAL accumulator.
pub struct MrRenderer {
    renderer: Renderer,
    pipeline: MrPipeline,
    settings: FrameSettings,
    accumulator: Option<ValAccumulator>,
    frames: u64,
}

/// Stage name of the differential rendering in a replay's timings (wall time: receivers on the
/// CPU, the GPU rounds, the composite's relighting, and a rebuild of the pass's BVH when the
/// meshes moved since the last frame).
pub const DIFFERENTIAL_STAGE: &str = "differential";

/// Stage name of the environment's VALs (CPU: the `auto` estimate and the VALs' upload).
pub const ENVIRONMENT_STAGE: &str = "environment";

/// Stage name of the composite: the virtual content's depth read back, the relit real surfaces
/// and the virtual image laid over the camera image (CPU).
pub const COMPOSITE_STAGE: &str = "composite";

impl MrRenderer {
    pub fn new(gpu: &Gpu, scene: &Scene, options: MrOptions) -> anyhow::Result<Self> {
        let accumulator = match options.accumulate {
            Some(a) => Some(ValAccumulator::new(a.cell_size, a.max_vals, a.max_age_frames)?),
            None => None,
        };
        let mut renderer = Renderer::new(gpu, scene)?;
        let mut pipeline = MrPipeline::new(scene.settings.mr, Environment::None);
        let placement = renderer.placement().to_vec();
        pipeline.place(gpu, &mut renderer, scene, &placement)?;
        // Built before the first frame: not a frame's time.
        pipeline.build_ms = 0.0;
        let settings = FrameSettings {
            width: options.width,
            height: options.height,
            exposure: options.exposure,
            rgbd: scene.settings.rgbd,
            receivers_step: 1,
            method: scene.resolved.method.into(),
        };
        Ok(Self { renderer, pipeline, settings, accumulator, frames: 0 })
    }

    /// Light the following frames with `environment` too (`settings.environment`, read by
    /// [`Environment::from_settings`]).
    pub fn set_environment(&mut self, environment: Environment) {
        self.pipeline.set_environment(environment);
    }

    /// Render each following frame over the whole image (`false`) or over the pixels the
    /// virtual content's box projects to (`true`, the default; [`Crop`]): the same image, the
    /// switch is for measuring and testing the crop.
    pub fn set_crop_to_content(&mut self, crop: bool) {
        self.pipeline.crop_to_content = crop;
    }

    /// Relight `frame` ([`MrPipeline::render_frame`]): its VALs (or the accumulated set), the
    /// environment, the scene's spot light if any, the virtual object seen from the frame's
    /// camera and composited over its colour, relit by the differential pass.
    pub fn render_frame(&mut self, gpu: &Gpu, frame: &RgbdFrame) -> Result<MrFrame, GpuError> {
        let accumulate = self.accumulator.as_mut().map(|a| (a, self.frames));
        let input = FrameInput { frame, settings: &self.settings, accumulate };
        let relit = self.pipeline.render_frame(gpu, &mut self.renderer, input)?;
        self.frames += 1;
        let mut timings = relit.rendered.timings;
        timings.stages.push((COMPOSITE_STAGE.to_owned(), relit.composite_ms));
        Ok(MrFrame {
            composited: relit.composited,
            indirect: relit.rendered.indirect,
            direct: relit.rendered.direct,
            timings,
            val_count: relit.rendered.val_count,
            sparse_irradiance: relit.sparse_irradiance,
            error_estimate: relit.rendered.error_estimate,
            differential: relit.differential,
        })
    }

    /// The renderer, to change what the next frames run at (a budget's parameters).
    pub fn renderer_mut(&mut self) -> &mut Renderer {
        &mut self.renderer
    }

    /// How the next frames are rendered (their size, RGB-D settings), to change them.
    pub fn frame_settings_mut(&mut self) -> &mut FrameSettings {
        &mut self.settings
    }
}

/// How one frame is rendered: what [`MrOptions`] gives a replay, and a stream's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameSettings {
    /// Output size; the frame's intrinsics are scaled to it.
    pub width: u32,
    pub height: u32,
    /// Exposure of the virtual object in the composite ([`MrOptions::exposure`]).
    pub exposure: f32,
    /// How the frame's pixels become VALs and receivers, and its `radiance_scale`.
    pub rgbd: RgbdSettings,
    /// Multiplier of `settings.mr.receiver_step` (the product at most 64): a frame budget's
    /// cheap rungs take one receiver in 4, its half-size rungs one in 16
    /// (`FrameParameters::receivers_step`).
    pub receivers_step: u32,
    /// The indirect method. The differential pass's re-emitters take what the sparse method
    /// gathered at the sparse points: with another method they add no light (the virtual
    /// content's shadow alone).
    pub method: Method,
}

/// One RGB-D frame for [`MrPipeline::light`] and [`MrPipeline::render_frame`]: the frame, how it
/// is rendered, and with accumulation the accumulator and the frame's index in it.
pub struct FrameInput<'a> {
    pub frame: &'a RgbdFrame,
    pub settings: &'a FrameSettings,
    pub accumulate: Option<(&'a mut ValAccumulator, u64)>,
}

/// The mixed-reality pipeline of one scene (docs/design.md §6), shared by `relume replay`
/// ([`MrRenderer`]) and the service's streams (`service::gpu_worker`): a frame's VALs, the
/// environment (`settings.environment`, the `auto` level raised by the differential pass's
/// receivers), the render from the frame's camera, the differential relighting of the real
/// surfaces (`settings.mr`) and the composite. It drives a [`Renderer`] it is given and holds
/// what outlives a frame: the settings, the environment and, for the meshes' placement, the
/// differential pass (its BVH of the virtual meshes) and the content's re-emitters, bounds and
/// centre, rebuilt by [`MrPipeline::place`] only when the placement changes.
pub struct MrPipeline {
    mr: MrSettings,
    environment: Environment,
    placed: Option<Placed>,
    /// Time (ms) of a rebuild of the differential pass not yet counted in a frame's stage.
    build_ms: f64,
    /// Whether frames are rendered over the content's pixels only ([`Crop::of_box`]).
    crop_to_content: bool,
}

/// What depends on where the meshes are.
struct Placed {
    /// Model-to-world of each mesh it was built for ([`Renderer::placement`]).
    placement: Vec<Mat4>,
    /// Centre of the virtual content's bounding sphere: the environment's VALs surround it.
    centre: Vec3,
    /// The virtual content's box (min, max corners, the scene's frame): the render covers the
    /// pixels it projects to ([`Crop::of_box`]).
    bounds: (Vec3, Vec3),
    /// Only with `settings.mr.differential`.
    differential: Option<DifferentialState>,
}

impl Placed {
    /// Whether `renderer`'s meshes are placed as this state was built for.
    fn is_for(&self, renderer: &Renderer) -> bool {
        self.placement == renderer.placement()
    }
}

/// The differential pass (its BVH of the virtual meshes as placed) and the virtual content's
/// re-emitters and bounds.
struct DifferentialState {
    pass: Differential,
    emitters: Vec<Emitter>,
    bounds: (Vec3, Vec3),
}

/// A frame's light, set on the renderer by [`MrPipeline::light`]: what the rest of the frame
/// needs of it, and its stages' times.
pub struct Lighting {
    /// The real VALs (the frame's, or the accumulated set), read back when the environment or
    /// the differential pass need them on the CPU; `None` when they stayed on the GPU.
    real_vals: Option<Vec<Val>>,
    /// The differential pass's receivers.
    grid: Option<ReceiverGrid>,
    /// `rgbd_vals` with the VALs' readback (ms), when they were read back.
    rgbd_ms: f64,
    /// The receivers (ms), counted in the differential stage.
    receivers_ms: f64,
    /// The environment's VALs (ms), when the scene has an environment.
    environment_ms: Option<f64>,
}

impl Lighting {
    /// Put the lighting's stages at the front of a frame's `timings`: `rgbd_vals` (when the
    /// VALs were made and read back here rather than in the frame) and `environment`.
    pub fn add_stages(&self, timings: &mut StageTimings) {
        if self.real_vals.is_some() {
            timings.stages.insert(0, (crate::renderer::stage::RGBD_VALS.to_owned(), self.rgbd_ms));
        }
        if let Some(ms) = self.environment_ms {
            timings.stages.insert(1.min(timings.stages.len()), (ENVIRONMENT_STAGE.to_owned(), ms));
        }
    }
}

/// One frame through the whole pipeline.
pub struct Relit {
    /// The virtual content from the frame's camera, with the lighting's and the differential
    /// pass's stages in its timings.
    pub rendered: Rendered,
    /// The camera image (relit by the differential pass) with the virtual content composited
    /// in (sRGB, row-major).
    pub composited: Vec<[u8; 3]>,
    /// Time of the virtual depth's readback and the composite (ms).
    pub composite_ms: f64,
    /// Diffuse irradiance (W/m²) at each sparse point ([`MrFrame::sparse_irradiance`]); empty
    /// with a method other than the sparse one.
    pub sparse_irradiance: Vec<Vec3>,
    /// The differential pass's receivers and their light, when it ran.
    pub differential: Option<DifferentialFrame>,
}

impl MrPipeline {
    /// The pipeline of a scene with `mr` settings, lit by `environment` too. Call
    /// [`MrPipeline::place`] before the first frame.
    pub fn new(mr: MrSettings, environment: Environment) -> Self {
        Self { mr, environment, placed: None, build_ms: 0.0, crop_to_content: true }
    }

    /// Light the following frames with `environment` too.
    pub fn set_environment(&mut self, environment: Environment) {
        self.environment = environment;
    }

    /// Place the meshes of `scene` (the scene `renderer` was built from) by `model_to_world`
    /// ([`Renderer::place_meshes`]) and, when that is not the placement the differential pass
    /// was built for, rebuild the pass's BVH, the re-emitters, bounds and centre. Placing the
    /// meshes as they already are costs a comparison.
    pub fn place(
        &mut self,
        gpu: &Gpu,
        renderer: &mut Renderer,
        scene: &Scene,
        model_to_world: &[Mat4],
    ) -> Result<(), GpuError> {
        renderer.place_meshes(gpu, scene, model_to_world);
        if self.placed.as_ref().is_some_and(|p| p.placement == model_to_world) {
            return Ok(());
        }
        let start = Instant::now();
        let bounds = differential::bounds(renderer.scene.flat.vertices.iter().map(|v| Vec3::from(v.position)));
        let differential = match self.mr.differential {
            false => None,
            true => Some(DifferentialState {
                pass: Differential::on(gpu, &renderer.scene, self.mr.device)?,
                emitters: differential::emitters_placed(scene, model_to_world),
                bounds,
            }),
        };
        if differential.is_some() {
            self.build_ms += start.elapsed().as_secs_f64() * 1e3;
            tracing::debug!(ms = self.build_ms, "differential pass built for a new placement");
        }
        let centre = renderer.scene.flat.bounding_sphere().0;
        self.placed = Some(Placed { placement: model_to_world.to_vec(), centre, bounds, differential });
        Ok(())
    }

    /// Forget the placement's state (its GPU buffers belong to a device that was lost): the
    /// next [`MrPipeline::place`] rebuilds it.
    pub fn forget_placement(&mut self) {
        self.placed = None;
    }

    /// The placement's state, when it is the renderer's (a renderer placed otherwise since the
    /// last [`MrPipeline::place`] gets no differential pass and its own centre).
    fn placed(&self, renderer: &Renderer) -> Option<&Placed> {
        let placed = self.placed.as_ref().filter(|p| p.is_for(renderer));
        if placed.is_none() && self.mr.differential {
            tracing::warn!("the meshes moved without MrPipeline::place: no differential pass this frame");
        }
        placed
    }

    /// Set `frame`'s light on `renderer`: its VALs (made on the GPU; with `accumulate`, the
    /// accumulator and this frame's index, inserted into it and the accumulated set used), the
    /// environment's VALs around the content, and with the differential pass, its receivers
    /// (which raise the `auto` environment's level). The spot light, occlusion and glossy
    /// settings are the renderer's.
    pub fn light(&mut self, gpu: &Gpu, renderer: &mut Renderer, input: FrameInput<'_>) -> Result<Lighting, GpuError> {
        let FrameInput { frame, settings, accumulate } = input;
        let rgbd = settings.rgbd;
        let (centre, bounds) = match self.placed(renderer) {
            Some(p) => (p.centre, p.differential.as_ref().map(|d| d.bounds)),
            None => (renderer.scene.flat.bounding_sphere().0, None),
        };
        // The differential pass and the environment need the real VALs on the CPU: they are
        // read back, and the readback is timed as the `rgbd_vals` stage; the environment's VALs
        // follow them.
        let start = Instant::now();
        let on_cpu = bounds.is_some() || self.environment != Environment::None;
        let real_vals = match (accumulate, on_cpu) {
            (None, false) => {
                renderer.set_rgbd_frame(gpu, frame, &rgbd)?;
                None
            }
            (None, true) => Some(renderer.rgbd_frame_vals(gpu, frame, &rgbd)?),
            (Some((acc, index)), _) => {
                let vals = renderer.rgbd_frame_vals(gpu, frame, &rgbd)?;
                acc.insert(index, &vals);
                Some(acc.vals())
            }
        };
        let rgbd_ms = start.elapsed().as_secs_f64() * 1e3;
        // The differential pass's receivers: its stage, and the `auto` environment's level.
        let start = Instant::now();
        let grid = bounds.map(|bounds| {
            let pose = renderer.local_pose(&frame.camera_to_world);
            let step = (self.mr.receiver_step * settings.receivers_step.max(1)).min(64);
            differential::receivers(frame, &pose, &rgbd, &MrSettings { receiver_step: step, ..self.mr }, bounds)
        });
        let receivers_ms = start.elapsed().as_secs_f64() * 1e3;
        let start = Instant::now();
        // The differential pass takes every VAL but the re-emitters as real light: the
        // environment's too.
        let real_vals = real_vals.map(|mut vals| {
            let environment = self.environment.vals(centre, frame, &rgbd, &vals, grid.as_ref());
            vals.extend(environment);
            vals
        });
        if let Some(vals) = &real_vals {
            renderer.set_vals(gpu, vals)?;
        }
        let environment_ms = (self.environment != Environment::None).then(|| start.elapsed().as_secs_f64() * 1e3);
        Ok(Lighting { real_vals, grid, rgbd_ms, receivers_ms, environment_ms })
    }

    /// Relight `frame` on `renderer` (placed by [`MrPipeline::place`]): [`MrPipeline::light`],
    /// the virtual content seen from the frame's camera at the settings' size, the differential
    /// pass on the real surfaces near it, and the composite.
    pub fn render_frame(
        &mut self,
        gpu: &Gpu,
        renderer: &mut Renderer,
        input: FrameInput<'_>,
    ) -> Result<Relit, GpuError> {
        let (frame, settings) = (input.frame, input.settings);
        let lighting = self.light(gpu, renderer, input)?;
        let (w, h) = (settings.width, settings.height);
        // The render covers the pixels the content's box projects to, pasted back at their place.
        let k = frame.intrinsics.scaled_to(w, h);
        let crop = match self.placed.as_ref().filter(|p| p.is_for(renderer) && self.crop_to_content) {
            Some(p) => Crop::of_box(&k, &renderer.local_pose(&frame.camera_to_world), p.bounds),
            None => Crop::full(w, h),
        };
        renderer.set_pinhole_view(crop.intrinsics(&k), &frame.camera_to_world);
        let mut rendered = renderer.render(gpu, settings.method, crop.width, crop.height)?;
        lighting.add_stages(&mut rendered.timings);
        let start = Instant::now();
        let virtual_depth = crop.paste(virtual_depth(gpu, renderer, &frame.camera_to_world)?, w, h, None);
        for image in [&mut rendered.indirect, &mut rendered.direct] {
            let pixels = crop.paste(std::mem::take(&mut image.pixels), w, h, [0.0; 4]);
            *image = LinearImage { width: w, height: h, pixels };
        }
        let depth_ms = start.elapsed().as_secs_f64() * 1e3;
        let sparse_irradiance = match settings.method {
            Method::Sparse => renderer.read_gathered_irradiance(gpu)?,
            Method::BruteForce
            | Method::BruteForceIsm
            | Method::BruteForceClusters
            | Method::Exact
            | Method::Estimator => Vec::new(),
        };
        let build_ms = std::mem::take(&mut self.build_ms);
        let differential = self.placed.as_mut().filter(|p| p.is_for(renderer)).and_then(|p| p.differential.as_mut());
        let (background, differential) = match (differential, &lighting.real_vals, lighting.grid) {
            (Some(d), Some(vals), Some(grid)) => {
                let start = Instant::now();
                let mut all = vals.clone();
                all.extend(differential::emitter_vals(&d.emitters, &sparse_irradiance));
                let method = DifferentialMethod::for_frames(
                    self.mr.differential_method,
                    settings.method == Method::Exact,
                    d.pass.device() == DifferentialDevice::Gpu,
                );
                let (light, counts) = differential::receiver_light(
                    &mut d.pass,
                    gpu,
                    &renderer.scene,
                    &grid,
                    &all,
                    vals.len(),
                    d.bounds,
                    (method, &differential::FastSettings::default()),
                )?;
                let sums_ms = start.elapsed().as_secs_f64() * 1e3;
                let visible = visible_receivers(&grid, frame, &virtual_depth, w, h);
                log_differential(&light, &visible);
                let relight = Instant::now();
                let field = LightField { grid: &grid, light: &light };
                let background = differential::relight_camera(frame, &field, w, h, settings.rgbd.radiance_scale);
                let relight_ms = relight.elapsed().as_secs_f64() * 1e3;
                let receivers_ms = lighting.receivers_ms;
                tracing::debug!(
                    ?method,
                    ?counts,
                    receivers_ms,
                    sums_ms,
                    relight_ms,
                    build_ms,
                    "differential receivers"
                );
                let ms = build_ms + receivers_ms + start.elapsed().as_secs_f64() * 1e3;
                rendered.timings.stages.push((DIFFERENTIAL_STAGE.to_owned(), ms));
                let (vals, real_count, bounds) = (all, vals.len(), d.bounds);
                let summed = DifferentialFrame { method, grid, light, counts, visible, vals, real_count, bounds };
                (Some(background), Some(summed))
            }
            _ => (None, None),
        };
        let start = Instant::now();
        let virtual_rgb = rendered.direct.add(&rendered.indirect);
        let composited = composite_over(
            frame,
            background.as_deref(),
            &virtual_rgb,
            &virtual_depth,
            display_scale(settings.exposure, settings.rgbd.radiance_scale),
        );
        let composite_ms = depth_ms + start.elapsed().as_secs_f64() * 1e3;
        Ok(Relit { rendered, composited, composite_ms, sparse_irradiance, differential })
    }
}

/// At debug level: how many receivers the virtual content shadows and darkens, over all of them
/// and over those the composite shows (`shown`, per receiver: the shadow one can see).
fn log_differential(light: &[crate::gpu::differential::ReceiverLight], shown: &[bool]) {
    if !tracing::enabled!(tracing::Level::DEBUG) {
        return;
    }
    let fraction =
        |l: &crate::gpu::differential::ReceiverLight| l.blocked.max_element() / l.unoccluded.max_element().max(1e-12);
    let net =
        |l: &crate::gpu::differential::ReceiverLight| l.change().element_sum() / l.unoccluded.element_sum().max(1e-12);
    let shadowed = light.iter().filter(|l| fraction(l) > 0.1).count();
    let darkened = light.iter().filter(|l| net(l) < -0.1).count();
    let most = light.iter().map(fraction).fold(0.0f32, f32::max);
    let darkest = light.iter().map(net).fold(0.0f32, f32::min);
    let visible = light.iter().zip(shown).filter(|(_, v)| **v).map(|(l, _)| l);
    let visible_darkened = visible.clone().filter(|l| net(l) < -0.1).count();
    let visible_darkest = visible.map(net).fold(0.0f32, f32::min);
    tracing::debug!(
        receivers = light.len(),
        shadowed,
        darkened,
        most,
        darkest,
        visible = shown.iter().filter(|v| **v).count(),
        visible_darkened,
        visible_darkest,
        "differential: blocked fraction (over 10 %: shadowed) and net change (under -10 %: darkened)"
    );
}

/// Per receiver of `grid`, whether the composite shows it: the virtual content (its optical
/// depth per output pixel, `width` x `height`) is absent or behind the real surface at the
/// receiver's cell centre, as [`composite_over`] decides.
fn visible_receivers(
    grid: &differential::ReceiverGrid,
    frame: &RgbdFrame,
    virtual_depth: &[Option<f32>],
    width: u32,
    height: u32,
) -> Vec<bool> {
    let (fw, fh) = (frame.intrinsics.width, frame.intrinsics.height);
    let step = grid.settings.grid_step.max(1);
    let mut shown = vec![true; grid.receivers.len()];
    for (cell, r) in grid.cells.iter().enumerate() {
        let Some(r) = r else { continue };
        let (cx, cy) = (cell as u32 % grid.size.x, cell as u32 / grid.size.x);
        let (u, v) = ((cx * step + (step - 1) / 2).min(fw - 1), (cy * step + (step - 1) / 2).min(fh - 1));
        let (x, y) = ((u * width / fw).min(width - 1), (v * height / fh).min(height - 1));
        if let Some(Some(z)) = virtual_depth.get((y * width + x) as usize) {
            shown[*r as usize] = !virtual_in_front(*z, frame.depth[(v * fw + u) as usize]);
        }
    }
    shown
}

/// Optical depth (m, along `camera_to_world`'s z) of the virtual content at each pixel of the
/// last frame `renderer` rendered (from that camera, given in the user's world coordinates);
/// `None` where no geometry covers it.
pub fn virtual_depth(gpu: &Gpu, renderer: &Renderer, camera_to_world: &DAffine3) -> Result<Vec<Option<f32>>, GpuError> {
    let Some(view) = renderer.camera_view() else {
        return Ok(Vec::new());
    };
    // The flat scene is relative to the scene's origin: so must the pose be.
    let world_to_camera = renderer.local_pose(camera_to_world).inverse();
    let flat = &renderer.scene.flat;
    Ok(view
        .read(gpu)?
        .iter()
        .map(|hit| hit.map(|h| world_to_camera.transform_point3(flat.surface_at(h.triangle, h.barycentrics).0).z))
        .collect())
}

/// The factor from the virtual object's radiance (W/(m² sr)) to the camera's linear value in
/// the composite: `exposure / radiance_scale`, the inverse of the calibration that made the
/// room's VALs (`L = radiance_scale * srgb_to_linear(rgb)`), so the object and the room are on
/// one scale; `exposure` alone when `radiance_scale` is 0 (a room that emits nothing).
pub fn display_scale(exposure: f32, radiance_scale: f32) -> f32 {
    if radiance_scale > 0.0 { exposure / radiance_scale } else { exposure }
}

/// The camera image with the virtual object drawn where it is visible: where it covers the
/// pixel and is nearer than the real surface (or the real depth is missing). `virtual_rgb` is
/// linear radiance at the output size, `virtual_depth` its optical depth per pixel (m), and
/// the colour and depth of `frame` are sampled at the nearest pixel when the sizes differ.
pub fn composite(
    frame: &RgbdFrame,
    virtual_rgb: &LinearImage,
    virtual_depth: &[Option<f32>],
    exposure: f32,
) -> Vec<[u8; 3]> {
    composite_over(frame, None, virtual_rgb, virtual_depth, exposure)
}

/// [`composite`] over `background` (sRGB at the output size, e.g. the camera image relit by
/// [`differential::relight_camera`]) instead of the frame's colour where it is given.
pub fn composite_over(
    frame: &RgbdFrame,
    background: Option<&[[u8; 3]]>,
    virtual_rgb: &LinearImage,
    virtual_depth: &[Option<f32>],
    exposure: f32,
) -> Vec<[u8; 3]> {
    use rayon::prelude::*;
    let (w, h) = (virtual_rgb.width as usize, virtual_rgb.height as usize);
    let (fw, fh) = (frame.intrinsics.width as usize, frame.intrinsics.height as usize);
    // Each pixel on its own: over the cores, as the relit camera image is.
    (0..w * h)
        .into_par_iter()
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let source = (y * fh / h) * fw + x * fw / w;
            match virtual_depth[i] {
                Some(z) if virtual_in_front(z, frame.depth[source]) => {
                    let c = virtual_rgb.rgb(i) * exposure;
                    [encode_srgb(c.x), encode_srgb(c.y), encode_srgb(c.z)]
                }
                _ => background.map_or(frame.color[source], |b| b[i]),
            }
        })
        .collect()
}

/// Whether virtual content at optical depth `virtual_z` hides the real surface at `real_depth`
/// (no valid real depth: nothing to hide behind).
fn virtual_in_front(virtual_z: f32, real_depth: f32) -> bool {
    let real_valid = real_depth.is_finite() && real_depth > 0.0;
    !real_valid || virtual_z < real_depth
}

/// Mean relative change between two frames' per-point irradiance:
/// `sum |E_t - E_{t-1}| / sum |E_{t-1}|` over points and channels (0 = identical).
pub fn relative_change(previous: &[Vec3], current: &[Vec3]) -> f64 {
    let (mut diff, mut total) = (0.0f64, 0.0f64);
    for (p, c) in previous.iter().zip(current) {
        diff += f64::from((*c - *p).abs().element_sum());
        total += f64::from(p.abs().element_sum());
    }
    if total > 0.0 { diff / total } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rgbd::Intrinsics;

    fn frame(w: u32, h: u32, depth: f32) -> RgbdFrame {
        RgbdFrame {
            timestamp: 0.0,
            intrinsics: Intrinsics { width: w, height: h, fx: 10.0, fy: 10.0, cx: 1.5, cy: 1.5 },
            color: (0..w * h).map(|i| [i as u8, 7, 9]).collect(),
            depth: vec![depth; (w * h) as usize],
            camera_to_world: DAffine3::IDENTITY,
        }
    }

    /// A virtual surface of the radiance a room pixel was calibrated to (`L = radiance_scale *
    /// linear(rgb)`) is shown at that pixel's own value at exposure 1, whatever the scale.
    #[test]
    fn the_composite_shows_radiance_on_the_cameras_scale() {
        for radiance_scale in [0.5f32, 1.0, 3.0, 40.0] {
            let linear = crate::twin::rgbd::srgb_to_linear(Vec3::new(0.6, 0.3, 0.9));
            let shown = display_scale(1.0, radiance_scale) * (radiance_scale * linear);
            assert!(shown.abs_diff_eq(linear, 1e-6), "scale {radiance_scale}: {shown} vs {linear}");
            assert_eq!(display_scale(2.0, radiance_scale), 2.0 * display_scale(1.0, radiance_scale));
        }
        assert_eq!(display_scale(0.7, 0.0), 0.7, "a room that emits nothing leaves the exposure as it is");
    }

    /// The camera image passes through where the virtual object is absent or behind the real
    /// surface; the object shows where it is nearer or the real depth is missing.
    #[test]
    fn composite_respects_real_depth() {
        let mut f = frame(4, 4, 2.0);
        f.depth[5] = 0.0;
        let image = LinearImage { width: 4, height: 4, pixels: vec![[1.0, 0.0, 0.0, 1.0]; 16] };
        let mut depth = vec![None; 16];
        depth[1] = Some(1.0); // in front
        depth[2] = Some(3.0); // behind
        depth[5] = Some(9.0); // no real depth
        let out = composite(&f, &image, &depth, 1.0);
        for (i, (got, camera)) in out.iter().zip(&f.color).enumerate() {
            let expected = if i == 1 || i == 5 { [255, 0, 0] } else { *camera };
            assert_eq!(*got, expected, "pixel {i}");
        }
    }

    #[test]
    fn relative_change_of_identical_and_doubled() {
        let a = vec![Vec3::ONE, Vec3::splat(2.0)];
        assert_eq!(relative_change(&a, &a), 0.0);
        let b: Vec<Vec3> = a.iter().map(|v| *v * 2.0).collect();
        assert!((relative_change(&a, &b) - 1.0).abs() < 1e-12);
        assert_eq!(relative_change(&[], &[]), 0.0);
    }
}

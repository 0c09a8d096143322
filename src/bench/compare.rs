//! What `relume compare` and `relume bench` both measure: a timed sparse frame, the references,
//! and the indirect image's error against a reference. One code path, so the sweep's figures
//! are the figures `compare` prints; [`CompareReport`] is what `compare` prints.

use super::BenchError;
use crate::gpu::timing::TimingSource;
use crate::gpu::{Gpu, GpuError};
use crate::image::{LinearImage, flip_mean, noise_corrected_relative_rmse, relative_rmse, relative_stderr};
use crate::renderer::{Components, Method, Rendered, Renderer, stage};
use crate::scene::{Occlusion, OcclusionRule, Scene};
use std::path::Path;
use std::time::Instant;

/// Error of an indirect image against a reference image.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct IndirectError {
    /// `sqrt(sum |test - reference|² / sum |reference|²)` over RGB of covered pixels.
    pub rel_rmse: f64,
    /// Mean FLIP error of the tone-mapped images, both at `exposure`, over covered pixels.
    pub flip_mean: f64,
    /// The reference image's automatic exposure, at which both were tone-mapped for FLIP.
    pub exposure: f32,
}

/// Error of `test` against `reference` (both indirect light), tone-mapped for FLIP at the
/// reference's automatic exposure.
pub fn indirect_error(test: &LinearImage, reference: &LinearImage) -> IndirectError {
    let exposure = reference.auto_exposure();
    IndirectError {
        rel_rmse: relative_rmse(test, reference),
        flip_mean: flip_mean(test, reference, exposure),
        exposure,
    }
}

/// A sparse frame timed after a warm-up frame that settles first-use allocations and
/// pipeline creation.
pub fn sparse_frame(gpu: &Gpu, renderer: &mut Renderer, width: u32, height: u32) -> Result<Rendered, GpuError> {
    renderer.render(gpu, Method::Sparse, width, height)?;
    renderer.render(gpu, Method::Sparse, width, height)
}

/// The brute-force reference, one frame: it is too slow to repeat and its single frame is
/// dominated by its own arithmetic.
pub fn brute_force_frame(gpu: &Gpu, renderer: &mut Renderer, width: u32, height: u32) -> Result<Rendered, GpuError> {
    renderer.render(gpu, Method::BruteForce, width, height)
}

/// The exact-visibility reference over every `val_stride`-th VAL, one frame (no error
/// estimate: it is what the estimate compares with).
pub fn exact_frame(
    gpu: &Gpu,
    renderer: &mut Renderer,
    width: u32,
    height: u32,
    val_stride: u32,
) -> Result<Rendered, GpuError> {
    renderer.set_exact_val_stride(val_stride);
    renderer.render_unestimated(gpu, Method::Exact, width, height)
}

/// A frame of a level whose technique traces a shadow ray per pixel and VAL drawn: the exact
/// reference (at `reference` the reference itself; below it over the level's coarser VALs,
/// `settings.levels.<level>.technique: "exact"`) or, with `options.estimator`, the estimator
/// (`"estimator"`, the renderer's draws). `options.device` `auto` runs the CPU's on a CPU
/// adapter (lavapipe: about 15x faster than the GPU pass there). The frame carries the error
/// estimate every level's frame has ([`Renderer::estimate_error`]), except the exact reference
/// at `reference`, which is what the estimate compares with.
pub fn traced_level_frame(
    gpu: &Gpu,
    renderer: &mut Renderer,
    width: u32,
    height: u32,
    options: &ExactOptions,
    level: crate::scene::Quality,
) -> Result<Rendered, GpuError> {
    let mut frame = exact_reference(gpu, renderer, width, height, options)?.frame;
    if level != crate::scene::Quality::Reference || options.estimator {
        renderer.estimate_error(gpu, &mut frame)?;
    }
    Ok(frame)
}

/// Where `compare --reference exact` computes its reference.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ReferenceDevice {
    /// The CPU on CPU adapters (lavapipe) or when an option only the CPU reference has is given
    /// (`--reference-samples`, `--spp` > 1); the GPU pass otherwise.
    Auto,
    /// `twin::exact_cpu` over rayon's threads.
    Cpu,
    /// The GPU pass (`gpu::references::exact`).
    Gpu,
}

impl ReferenceDevice {
    pub fn as_str(self) -> &'static str {
        match self {
            ReferenceDevice::Auto => "auto",
            ReferenceDevice::Cpu => "cpu",
            ReferenceDevice::Gpu => "gpu",
        }
    }
}

/// How the exact-visibility reference is computed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExactOptions {
    pub device: ReferenceDevice,
    /// Every n-th VAL, flux x n (1: all).
    pub val_stride: u32,
    /// Importance-sampled VALs per receiver instead of a sum (CPU only).
    pub samples: Option<u32>,
    /// Jittered samples per pixel (CPU only beyond 1).
    pub spp: u32,
    /// Shadow rays ignore blockers nearer the receiver than this (m; CPU only beyond 0):
    /// 0 for every reference, an analysis otherwise (`twin::exact_cpu::ExactScene::blockers_from`).
    pub blockers_from: f32,
    /// The renderer's estimator ([`Renderer::set_estimator`]: its draws per pixel and seed)
    /// instead of a sum over the VALs: on the GPU the estimator pass, on the CPU its twin's
    /// systematic draws (`ValSampling::Systematic`), the level technique `"estimator"`.
    pub estimator: bool,
}

/// Seed of the CPU reference's random numbers (VAL draws, sub-pixel positions): fixed, so a
/// figure can be reproduced.
pub const REFERENCE_SEED: u64 = 0x5eed;

impl ExactOptions {
    /// The reference: every VAL summed at each pixel's centre past every blocker, on `device`.
    pub const fn every_val(device: ReferenceDevice) -> ExactOptions {
        ExactOptions { device, val_stride: 1, samples: None, spp: 1, blockers_from: 0.0, estimator: false }
    }

    /// The renderer's estimator ([`Self::estimator`]) on `device`.
    pub const fn estimator_on(device: ReferenceDevice) -> ExactOptions {
        ExactOptions { estimator: true, ..ExactOptions::every_val(device) }
    }

    /// What `method` renders with on `device` where it traces shadow rays: the exact reference
    /// over every VAL, or the renderer's estimator; `None` for the other methods.
    pub const fn traced(method: Method, device: ReferenceDevice) -> Option<ExactOptions> {
        match method {
            Method::Exact => Some(ExactOptions::every_val(device)),
            Method::Estimator => Some(ExactOptions::estimator_on(device)),
            _ => None,
        }
    }

    /// Check the options: `Err` names the flag (`--reference-samples: ...`).
    pub fn check(&self) -> Result<(), String> {
        use crate::twin::exact_cpu::{MAX_SPP, MAX_VAL_SAMPLES};
        if self.val_stride < 1 {
            return Err(format!("--val-stride: must be at least 1, got {}", self.val_stride));
        }
        if !(1..=MAX_SPP).contains(&self.spp) {
            return Err(format!("--spp: must be in 1..={MAX_SPP}, got {}", self.spp));
        }
        if let Some(n) = self.samples {
            if !(2..=MAX_VAL_SAMPLES).contains(&n) {
                return Err(format!("--reference-samples: must be in 2..={MAX_VAL_SAMPLES}, got {n}"));
            }
            if self.val_stride != 1 {
                return Err("--reference-samples: replaces --val-stride; give one of them".into());
            }
        }
        if self.estimator && (self.samples.is_some() || self.val_stride != 1) {
            return Err("the estimator draws its own VALs: not with --reference-samples or --val-stride".into());
        }
        if !(self.blockers_from >= 0.0 && self.blockers_from.is_finite()) {
            return Err(format!("blockers_from: must be finite and >= 0, got {}", self.blockers_from));
        }
        if self.device == ReferenceDevice::Gpu && (self.samples.is_some() || self.spp > 1 || self.blockers_from > 0.0) {
            return Err("--reference-device: gpu computes every VAL (or a stride) at the pixel centre, past every \
                        blocker; --reference-samples, --spp and blockers_from need cpu"
                .into());
        }
        Ok(())
    }

    /// The device `Auto` stands for on `gpu`.
    pub fn device_on(&self, gpu: &Gpu) -> ReferenceDevice {
        match self.device {
            ReferenceDevice::Auto
                if gpu.is_cpu() || self.samples.is_some() || self.spp > 1 || self.blockers_from > 0.0 =>
            {
                ReferenceDevice::Cpu
            }
            ReferenceDevice::Auto => ReferenceDevice::Gpu,
            d => d,
        }
    }

    /// How the reference treats the VALs (as reported: "all", "stride", "importance" or
    /// "systematic").
    pub fn estimator(&self) -> &'static str {
        match (self.samples, self.val_stride) {
            _ if self.estimator => "systematic",
            (Some(_), _) => "importance",
            (None, 1) => "all",
            _ => "stride",
        }
    }
}

/// An exact-visibility reference frame with its noise and cost.
pub struct ExactReference {
    /// The frame: its indirect image is the reference; its direct image and stage timings are
    /// the frame's (on the CPU, a direct-only GPU frame that made the VALs and the visibility
    /// buffer, with the CPU reference as its indirect stage `exact_cpu::STAGE`).
    pub frame: Rendered,
    /// Per pixel and channel the variance of the reference's estimate; `None` for a stride.
    pub variance: Option<Vec<glam::Vec3>>,
    pub device: ReferenceDevice,
    /// CPU: shadow rays cast.
    pub shadow_rays: Option<u64>,
    /// CPU: how they were traced (the pilot's choice; the image does not depend on it).
    pub traversal: Option<crate::twin::bvh::ShadowTraversal>,
}

impl ExactReference {
    /// The reference image (indirect light).
    pub fn indirect(&self) -> &LinearImage {
        &self.frame.indirect
    }

    /// Wall time of the reference itself (ms): the GPU pass's stage time, or the CPU's BVH build
    /// and tracing (not the GPU frame that made the VALs and the visibility buffer).
    pub fn ms(&self) -> f64 {
        self.frame.indirect_ms()
    }

    /// `sqrt(sum s² / sum |g|²)`: the reference's own relative noise (`None` for a stride).
    pub fn rel_stderr(&self) -> Option<f64> {
        self.variance.as_deref().map(|v| relative_stderr(self.indirect(), v))
    }

    /// `test`'s relative RMSE against this reference, corrected for its noise (`None` for a
    /// stride).
    pub fn corrected_rel_rmse(&self, test: &LinearImage) -> Option<f64> {
        self.variance.as_deref().map(|v| noise_corrected_relative_rmse(test, self.indirect(), v))
    }

    /// CPU: shadow rays per second of wall time (BVH build included).
    pub fn rays_per_s(&self) -> Option<f64> {
        self.shadow_rays.map(|n| n as f64 / (self.ms() * 1e-3))
    }
}

/// The exact-visibility reference of `renderer`'s scene at `width` x `height` per `options`
/// (checked with [`ExactOptions::check`]). The CPU path takes the VALs and the camera's
/// visibility buffer from a direct-only frame rendered first (no indirect technique runs):
/// with one sample per pixel its receivers are that buffer's pixels (exactly those the GPU
/// methods shade); with more it traces primary rays at jittered positions through the same BVH
/// as its shadow rays.
pub fn exact_reference(
    gpu: &Gpu,
    renderer: &mut Renderer,
    width: u32,
    height: u32,
    options: &ExactOptions,
) -> Result<ExactReference, GpuError> {
    exact_reference_seeded(gpu, renderer, width, height, options, REFERENCE_SEED)
}

/// [`exact_reference`] with the CPU reference's random numbers drawn from `seed`: an estimate
/// independent of the one [`REFERENCE_SEED`] gives (the equal-error curve's,
/// [`super::equal_error`]).
pub fn exact_reference_seeded(
    gpu: &Gpu,
    renderer: &mut Renderer,
    width: u32,
    height: u32,
    options: &ExactOptions,
    seed: u64,
) -> Result<ExactReference, GpuError> {
    use crate::twin::exact_cpu::{self as cpu, CameraRays, PixelSampling, Receiver, Receivers, ValSampling};
    let device = options.device_on(gpu);
    if device == ReferenceDevice::Gpu {
        let frame = match options.estimator {
            true => renderer.render_unestimated(gpu, Method::Estimator, width, height)?,
            false => exact_frame(gpu, renderer, width, height, options.val_stride)?,
        };
        let exact = options.val_stride == 1 && !options.estimator;
        return Ok(ExactReference {
            variance: exact.then(|| vec![glam::Vec3::ZERO; frame.indirect.pixels.len()]),
            frame,
            device,
            shadow_rays: None,
            traversal: None,
        });
    }
    let mut frame = renderer.render_components(gpu, Method::Sparse, width, height, Components::DIRECT)?;
    let mut vals = renderer.read_vals(gpu)?;
    let hits = match renderer.camera_view() {
        Some(view) if options.spp == 1 => view.read(gpu)?,
        _ => Vec::new(),
    };
    let start = std::time::Instant::now();
    let flat = &renderer.scene.flat;
    let eye = renderer.view().eye();
    let bvh = flat.trace_bvh();
    let surface = |t: u32, b: glam::Vec2| flat.receiver_at(t, b, eye);
    let camera = CameraRays::new(renderer.camera_to_clip(width, height), width, height);
    let resolved: Vec<Option<Receiver>> = hits.iter().map(|h| h.map(|h| surface(h.triangle, h.barycentrics))).collect();
    let receivers = if options.spp == 1 {
        Receivers::Hits(&resolved)
    } else {
        Receivers::Traced { camera: &camera, sampling: PixelSampling { spp: options.spp, seed }, surface: &surface }
    };
    let (draws, draws_seed) = renderer.estimator();
    let sampling = match (options.samples, options.val_stride) {
        _ if options.estimator => ValSampling::Systematic { samples: draws, seed: draws_seed },
        (Some(samples), _) => ValSampling::Importance { samples, seed },
        (None, 1) => ValSampling::All,
        (None, s) => ValSampling::Stride(s),
    };
    // The second bounce, its points lit through shadow rays (the GPU frame above, direct only,
    // made the first bounce's VALs alone).
    if let Some(bounce) = renderer.second_bounce() {
        vals.extend(second_bounce_exact(flat, bounce, &vals, &bvh));
    }
    let scene =
        cpu::ExactScene { bvh: &bvh, vals: &vals, glossy: renderer.glossy(), blockers_from: options.blockers_from };
    let out = cpu::render(&scene, &receivers, width, height, sampling);
    frame.indirect = out.image;
    frame.timings.stages.push((cpu::STAGE.to_owned(), start.elapsed().as_secs_f64() * 1e3));
    frame.indirect_stages = vec![cpu::STAGE];
    Ok(ExactReference {
        frame,
        variance: out.variance,
        device,
        shadow_rays: Some(out.shadow_rays),
        traversal: Some(out.traversal),
    })
}

/// The exact reference's second bounce (`settings.bounces: 2`): `bounce`'s points on `flat`
/// lit by `vals` through shadow rays in `bvh`, then drawn as the GPU's are (`twin::bounce`).
pub fn second_bounce_exact(
    flat: &crate::gpu::scene::FlatScene,
    bounce: &crate::gpu::lights::bounce::SecondBounce,
    vals: &[crate::twin::Val],
    bvh: &crate::twin::bvh::TraceBvh,
) -> Vec<crate::twin::Val> {
    use crate::twin::bounce as twin;
    let surfaces: Vec<twin::BounceSurface> = bounce.points.iter().map(|p| twin::BounceSurface::at(flat, p)).collect();
    let candidates = twin::candidate_vals(&surfaces, vals, Some(bvh));
    twin::draw_vals(&candidates, bounce.settings.vals, bounce.drawn_area)
}

/// `relume compare`'s report: sparse against the brute force (both without visibility), and
/// with `--reference exact` every occlusion mode against exact visibility.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CompareReport {
    /// The meshes' names, joined by `+`.
    pub scene: String,
    pub adapter: String,
    pub timing: TimingSource,
    pub width: u32,
    pub height: u32,
    pub pixels: u64,
    pub covered_pixels: usize,
    pub vals: u32,
    pub rsm_resolution: u32,
    pub sparse_points: usize,
    pub triangles: usize,
    pub vertices: usize,
    pub glossy: bool,
    pub occlusion_setting: Occlusion,
    pub occlusion_rule_setting: OcclusionRule,
    /// The sparse frame's indirect stages (ms).
    pub sparse_ms: f64,
    /// The brute force's indirect stage (ms).
    pub brute_force_ms: f64,
    pub speedup: f64,
    pub indirect_rel_rmse: f64,
    pub indirect_flip_mean: f64,
    /// Sparse / brute force, summed luminance: the energy the sparse method adds (> 1) or
    /// loses (< 1), e.g. to `settings.sparse.bound`.
    pub indirect_energy_ratio: f64,
    /// Sparse / brute force, brightest pixel's luminance: fireflies show as ratios above 1.
    pub indirect_peak_ratio: f64,
    /// The brute force's automatic exposure, at which FLIP tone-maps both.
    pub exposure: f32,
    /// Scene upload and pipeline creation (ms).
    pub setup_ms: f64,
    pub sparse_stages_ms: Vec<(String, f64)>,
    pub brute_force_stages_ms: Vec<(String, f64)>,
    /// `settings.bounces`.
    pub bounces: u32,
    /// With two bounces, the second bounce's stages of the sparse frame (`bounce2_points` +
    /// `bounce2_vals`, ms; the brute force runs the same); 0 with one.
    pub second_bounce_ms: f64,
    #[serde(flatten)]
    pub exact: Option<ExactComparison>,
}

/// One visibility mode of the sparse method against the exact-visibility reference.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ModeVsExact {
    /// `off`, `sum`, `product` (the disks' rules), `clusters` or `ism`.
    pub mode: &'static str,
    pub rel_rmse: f64,
    /// The error with the reference's own noise taken out (`None` for a stride, whose noise
    /// is not estimated).
    pub rel_rmse_corrected: Option<f64>,
    /// Mean FLIP at the exact image's exposure.
    pub flip_mean: f64,
    /// Summed indirect luminance over the exact image's: above 1 light leaks, below 1 the
    /// mode occludes too much.
    pub energy_ratio: f64,
    /// The mode's own stages (ms; 0 for `off`).
    pub visibility_ms: f64,
    /// The gather of the same frame (ms): with a group mode it applies the per-VAL visibility.
    pub gather_ms: f64,
    /// Every stage of that frame.
    pub stages_ms: Vec<(String, f64)>,
}

impl ModeVsExact {
    /// `rendered`'s indirect image, from the method or mode named `mode`, against `exact`'s
    /// (whose luminance sums to `exact_sum`), with its visibility and gather (or brute-force)
    /// times.
    fn against(
        exact: &ExactReference,
        exact_sum: f64,
        mode: &'static str,
        rendered: &Rendered,
        visibility_ms: f64,
        gather_ms: f64,
    ) -> Self {
        let error = indirect_error(&rendered.indirect, exact.indirect());
        Self {
            mode,
            rel_rmse: error.rel_rmse,
            rel_rmse_corrected: exact.corrected_rel_rmse(&rendered.indirect),
            flip_mean: error.flip_mean,
            energy_ratio: rendered.indirect.luminance_sum_and_peak().0 / exact_sum,
            visibility_ms,
            gather_ms,
            stages_ms: rendered.timings.stages.clone(),
        }
    }
}

/// The sparse method's visibility modes against the exact-visibility reference.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ExactComparison {
    pub exact_ms: f64,
    pub exact_device: ReferenceDevice,
    /// "all", "stride" or "importance".
    pub exact_estimator: &'static str,
    pub exact_val_stride: u32,
    pub exact_samples: Option<u32>,
    pub exact_spp: u32,
    pub exact_vals_used: u32,
    pub exact_rounds: u32,
    pub exact_shadow_rays: Option<u64>,
    pub exact_rays_per_s: Option<f64>,
    /// CPU: the shadow-ray traversal the pilot chose (`single` or `packets`).
    pub exact_traversal: Option<crate::twin::bvh::ShadowTraversal>,
    /// `sqrt(sum s² / sum |g|²)`: the reference's own relative noise.
    pub exact_rel_stderr: Option<f64>,
    /// The brute force (no visibility) against the reference (`mode` `brute_force`; its
    /// `visibility_ms` and `gather_ms` 0): what visibility changes, the sparse method aside.
    pub brute_force_vs_exact: ModeVsExact,
    /// The brute force with every VAL weighted by its group's imperfect-shadow-map lookup at the
    /// pixel (`brute_force_ism`, the scene's `settings.ism`; `visibility_ms` its ISM stages,
    /// `gather_ms` its `brute_force` stage): the ISMs' error against exact without the sparse
    /// interpolation's, beside `modes_vs_exact`'s `ism`.
    /// `None` when its table would not fit the device's largest storage binding (large images
    /// with many maps): `brute_force_ism_skipped` says why, and the rest of the comparison runs.
    pub brute_force_ism_vs_exact: Option<ModeVsExact>,
    pub brute_force_ism_skipped: Option<String>,
    /// The same with the clusters' shadow maps (`brute_force_clusters`, the scene's
    /// `settings.tuning.clusters`, rasterised maps unless `shadow_maps` says `"ism"`): the
    /// clusters' visibility where the light lands, beside `modes_vs_exact`'s `clusters` at the
    /// sparse points. `None` with `brute_force_clusters_skipped` as above.
    pub brute_force_clusters_vs_exact: Option<ModeVsExact>,
    pub brute_force_clusters_skipped: Option<String>,
    /// Sparse with each visibility mode against the reference, in this order: `off`, the disks
    /// with the `sum` and the `product` rule, `clusters` (the scene's `settings.clusters`) and
    /// `ism` (its `settings.ism`).
    pub modes_vs_exact: Vec<ModeVsExact>,
    /// The scene's own configuration (what a user gets without choosing anything) against the
    /// reference, with the error estimate a frame reports beside it.
    pub default_vs_exact: DefaultVsExact,
}

/// The scene's own configuration against the exact reference: the figures a user's frame
/// would be judged by, and the estimate it reports of them.
#[derive(Clone, Debug, serde::Serialize)]
pub struct DefaultVsExact {
    /// The visibility mode it resolved to.
    pub visibility: Occlusion,
    pub rel_rmse: f64,
    /// The error with the reference's own noise taken out (`None` for a stride).
    pub rel_rmse_corrected: Option<f64>,
    /// The relative RMSE over the pixels left after dropping the 1 % with the largest squared
    /// error (from both sums): how much of the error a few pixels hold.
    pub rel_rmse_without_worst_1pct: f64,
    /// Summed indirect luminance over the reference's.
    pub mean_ratio: f64,
    /// Brightest pixel's luminance over the reference's brightest.
    pub max_ratio: f64,
    /// The frame's own estimate of `rel_rmse` (`crate::renderer::estimate`, default options, over
    /// the frame's own VALs as the exact reference here), or `None` when the frame has no pixel
    /// to estimate at.
    pub error_estimate: Option<crate::renderer::estimate::ErrorEstimate>,
    /// `error_estimate.rel_rmse` over the measured error (`rel_rmse_corrected`, else
    /// `rel_rmse`).
    pub estimate_ratio: Option<f64>,
    pub stages_ms: Vec<(String, f64)>,
}

/// Measure `scene` at `width` x `height` as `relume compare` does; with `exact`, also against
/// exact visibility computed as it says. `images`: a directory for the indirect images and
/// their difference.
pub fn compare(
    gpu: &Gpu,
    scene: &Scene,
    (w, h): (u32, u32),
    exact: Option<&ExactOptions>,
    images: Option<&Path>,
) -> Result<CompareReport, BenchError> {
    let start = Instant::now();
    let mut renderer = Renderer::new(gpu, scene)?;
    let setup_ms = start.elapsed().as_secs_f64() * 1e3;
    // The brute force has no visibility, so it is compared with sparse without occlusion;
    // `exact` measures occlusion.
    renderer.set_occlusion(Occlusion::Off, scene.settings.visibility.rule);
    let sparse = sparse_frame(gpu, &mut renderer, w, h)?;
    let brute = brute_force_frame(gpu, &mut renderer, w, h)?;
    let error = indirect_error(&sparse.indirect, &brute.indirect);
    if let Some(dir) = images {
        write_comparison(dir, &sparse.indirect, &brute.indirect, error.exposure)?;
    }
    let (sparse_ms, brute_force_ms) = (sparse.indirect_ms(), brute.indirect_ms());
    let ((sparse_sum, sparse_peak), (brute_sum, brute_peak)) =
        (sparse.indirect.luminance_sum_and_peak(), brute.indirect.luminance_sum_and_peak());
    let exact = match exact {
        Some(options) => Some(exact_comparison(gpu, &mut renderer, scene, (w, h), options, images, &brute)?),
        None => None,
    };
    let bounce_stages = renderer.bounce_stages();
    let second_bounce_ms = if bounce_stages.is_empty() { 0.0 } else { sparse.timings.total_of(&bounce_stages) };
    Ok(CompareReport {
        scene: scene.meshes.iter().map(|m| m.name.as_str()).collect::<Vec<_>>().join("+"),
        adapter: gpu.adapter_name(),
        timing: sparse.timings.source,
        width: w,
        height: h,
        pixels: w as u64 * h as u64,
        covered_pixels: brute.indirect.coverage(),
        vals: sparse.val_count,
        rsm_resolution: scene.settings.rsm_resolution,
        sparse_points: scene.sparse_point_count(),
        triangles: scene.triangle_count(),
        vertices: scene.vertex_count(),
        glossy: renderer.glossy(),
        occlusion_setting: scene.settings.visibility.mode,
        occlusion_rule_setting: scene.settings.visibility.rule,
        sparse_ms,
        brute_force_ms,
        speedup: brute_force_ms / sparse_ms,
        indirect_rel_rmse: error.rel_rmse,
        indirect_flip_mean: error.flip_mean,
        indirect_energy_ratio: sparse_sum / brute_sum,
        indirect_peak_ratio: sparse_peak / brute_peak,
        exposure: error.exposure,
        setup_ms,
        sparse_stages_ms: sparse.timings.stages,
        brute_force_stages_ms: brute.timings.stages,
        bounces: scene.settings.bounces,
        second_bounce_ms,
        exact,
    })
}

/// Sparse with every visibility mode against the exact-visibility reference.
fn exact_comparison(
    gpu: &Gpu,
    renderer: &mut Renderer,
    scene: &Scene,
    (w, h): (u32, u32),
    options: &ExactOptions,
    images: Option<&Path>,
    brute: &Rendered,
) -> Result<ExactComparison, BenchError> {
    let exact = exact_reference(gpu, renderer, w, h, options)?;
    let exposure = exact.indirect().auto_exposure();
    let exact_sum = exact.indirect().luminance_sum_and_peak().0;
    let brute_force_vs_exact = ModeVsExact::against(&exact, exact_sum, "brute_force", brute, 0.0, 0.0);
    if let Some(dir) = images {
        write_png(exact.indirect(), &dir.join("indirect_exact.png"), exposure)?;
        write_exr(exact.indirect(), &dir.join("indirect_exact.exr"))?;
    }
    let mut modes = Vec::new();
    // Every mode of the registry; the disks under both rules.
    let mut runs = vec![
        ("off", Occlusion::Off, OcclusionRule::Sum),
        ("sum", Occlusion::Disks, OcclusionRule::Sum),
        ("product", Occlusion::Disks, OcclusionRule::Product),
    ];
    runs.extend(
        Occlusion::ALL
            .iter()
            .filter(|m| !matches!(m, Occlusion::Off | Occlusion::Disks))
            .map(|&m| (m.name(), m, OcclusionRule::Product)),
    );
    for (key, occlusion, rule) in runs {
        renderer.set_occlusion(occlusion, rule);
        let sparse = renderer.render(gpu, Method::Sparse, w, h)?;
        if let Some(dir) = images {
            write_png(&sparse.indirect, &dir.join(format!("indirect_sparse_occlusion_{key}.png")), exposure)?;
            write_exr(&sparse.indirect, &dir.join(format!("indirect_sparse_occlusion_{key}.exr")))?;
        }
        let visibility_stages = renderer.visibility_stages();
        // `off` has no stage of its own: 0, not the empty sum's -0.
        let visibility_ms =
            if visibility_stages.is_empty() { 0.0 } else { sparse.timings.total_of(&visibility_stages) };
        let gather_ms = sparse.timings.total_of(&[stage::GATHER]);
        modes.push(ModeVsExact::against(&exact, exact_sum, key, &sparse, visibility_ms, gather_ms));
    }
    let grouped = |renderer: &mut Renderer, method, key| -> Result<(Option<ModeVsExact>, Option<String>), BenchError> {
        match renderer.render(gpu, method, w, h) {
            Ok(frame) => {
                if let Some(dir) = images {
                    write_png(&frame.indirect, &dir.join(format!("indirect_{key}.png")), exposure)?;
                    write_exr(&frame.indirect, &dir.join(format!("indirect_{key}.exr")))?;
                }
                let groups: Vec<&str> =
                    frame.indirect_stages.iter().copied().filter(|s| *s != stage::BRUTE_FORCE).collect();
                let (visibility_ms, brute_ms) =
                    (frame.timings.total_of(&groups), frame.timings.total_of(&[stage::BRUTE_FORCE]));
                Ok((Some(ModeVsExact::against(&exact, exact_sum, key, &frame, visibility_ms, brute_ms)), None))
            }
            // Its (pixel, group) table outgrows one storage binding at large sizes; the entry is
            // optional, the rest of the comparison is not.
            Err(e @ GpuError::TooLarge { .. }) => Ok((None, Some(format!("skipped: {e}")))),
            Err(e) => Err(e.into()),
        }
    };
    let (brute_force_ism_vs_exact, brute_force_ism_skipped) =
        grouped(renderer, Method::BruteForceIsm, "brute_force_ism")?;
    let (brute_force_clusters_vs_exact, brute_force_clusters_skipped) =
        grouped(renderer, Method::BruteForceClusters, "brute_force_clusters")?;
    renderer.set_occlusion(scene.settings.visibility.mode, scene.settings.visibility.rule);
    // What a user gets: the level's technique (the sparse method, or the GPU estimator, the
    // brute force through the clusters' maps or the exact reference over the level's VALs
    // where the scene's measured level names it, the last then the reference itself, which is
    // over the same VALs; at `reference`, the sparse method with accurate's parameters, the
    // reference being what it is compared with).
    let default = match Method::from(scene.resolved.method) {
        Method::Exact if scene.resolved.quality != crate::scene::Quality::Reference => exact.frame.clone(),
        Method::Exact => renderer.render(gpu, Method::Sparse, w, h)?,
        method => renderer.render(gpu, method, w, h)?,
    };
    let estimate = crate::renderer::estimate::Estimator::new().estimate(
        gpu,
        renderer,
        &default,
        // Its exact reference sums over the scene's VALs at its own level: so does the estimate.
        &crate::renderer::estimate::EstimateOptions { own_vals: true, ..Default::default() },
    )?;
    let default_vs_exact = default_vs_exact(&exact, scene.settings.visibility.mode, &default, estimate);
    Ok(ExactComparison {
        exact_ms: exact.ms(),
        exact_device: exact.device,
        exact_estimator: options.estimator(),
        exact_val_stride: options.val_stride,
        exact_samples: options.samples,
        exact_spp: options.spp,
        exact_vals_used: options.samples.unwrap_or(exact.frame.val_count / options.val_stride),
        exact_rounds: exact.frame.exact_rounds,
        exact_shadow_rays: exact.shadow_rays,
        exact_rays_per_s: exact.rays_per_s(),
        exact_traversal: exact.traversal,
        exact_rel_stderr: exact.rel_stderr(),
        brute_force_vs_exact,
        brute_force_ism_vs_exact,
        brute_force_ism_skipped,
        brute_force_clusters_vs_exact,
        brute_force_clusters_skipped,
        modes_vs_exact: modes,
        default_vs_exact,
    })
}

/// [`DefaultVsExact`] of `rendered` (the scene's own configuration, `visibility`) against
/// `exact`.
fn default_vs_exact(
    exact: &ExactReference,
    visibility: Occlusion,
    rendered: &Rendered,
    error_estimate: Option<crate::renderer::estimate::ErrorEstimate>,
) -> DefaultVsExact {
    let (test, reference) = (&rendered.indirect, exact.indirect());
    let error = indirect_error(test, reference);
    let rel_rmse_corrected = exact.corrected_rel_rmse(test);
    let ((test_sum, test_peak), (reference_sum, reference_peak)) =
        (test.luminance_sum_and_peak(), reference.luminance_sum_and_peak());
    let measured = rel_rmse_corrected.unwrap_or(error.rel_rmse);
    DefaultVsExact {
        visibility,
        rel_rmse: error.rel_rmse,
        rel_rmse_corrected,
        rel_rmse_without_worst_1pct: rel_rmse_without_worst(test, reference, 0.01),
        mean_ratio: test_sum / reference_sum,
        max_ratio: test_peak / reference_peak,
        estimate_ratio: error_estimate.map(|e| e.rel_rmse / measured),
        error_estimate,
        stages_ms: rendered.timings.stages.clone(),
    }
}

/// The relative RMSE of `test` against `reference` over the covered pixels left after dropping
/// the `fraction` of them with the largest squared error (from both sums).
pub fn rel_rmse_without_worst(test: &LinearImage, reference: &LinearImage, fraction: f64) -> f64 {
    let mut terms: Vec<(f64, f64)> = (0..reference.pixels.len())
        .filter(|&i| reference.covered(i))
        .map(|i| {
            let (t, r) = (test.rgb(i), reference.rgb(i));
            ((t - r).length_squared() as f64, r.length_squared() as f64)
        })
        .collect();
    terms.sort_by(|a, b| b.0.total_cmp(&a.0));
    let dropped = (terms.len() as f64 * fraction).floor() as usize;
    let (num, den) = terms[dropped..].iter().fold((0.0, 0.0), |(n, d), (e, r)| (n + e, d + r));
    if den > 0.0 { (num / den).sqrt() } else { 0.0 }
}

fn write_png(image: &LinearImage, path: &Path, exposure: f32) -> Result<(), BenchError> {
    image.write_png(path, exposure).map_err(|e| BenchError::Write { path: path.to_owned(), message: e.to_string() })
}

fn write_exr(image: &LinearImage, path: &Path) -> Result<(), BenchError> {
    image.write_exr(path).map_err(|e| BenchError::Write { path: path.to_owned(), message: e.to_string() })
}

/// The sparse and brute-force indirect images (tone-mapped PNG, and linear EXR for measurement)
/// and their difference (at 4x the exposure).
fn write_comparison(dir: &Path, sparse: &LinearImage, brute: &LinearImage, exposure: f32) -> Result<(), BenchError> {
    std::fs::create_dir_all(dir)
        .map_err(|e| BenchError::Write { path: dir.to_owned(), message: format!("creating the directory: {e}") })?;
    write_png(sparse, &dir.join("indirect_sparse.png"), exposure)?;
    write_png(brute, &dir.join("indirect_brute_force.png"), exposure)?;
    write_exr(sparse, &dir.join("indirect_sparse.exr"))?;
    write_exr(brute, &dir.join("indirect_brute_force.exr"))?;
    let diff = LinearImage {
        width: sparse.width,
        height: sparse.height,
        pixels: sparse
            .pixels
            .iter()
            .zip(&brute.pixels)
            .map(|(s, b)| [(s[0] - b[0]).abs(), (s[1] - b[1]).abs(), (s[2] - b[2]).abs(), b[3]])
            .collect(),
    };
    write_png(&diff, &dir.join("indirect_difference.png"), exposure * 4.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_worst_percent_is_dropped_from_both_sums() {
        let flat = |v: f32| [v, v, v, 1.0];
        let reference = LinearImage { width: 100, height: 1, pixels: vec![flat(1.0); 100] };
        let mut test = reference.clone();
        test.pixels[7] = flat(5.0);
        test.pixels[8] = flat(1.5);
        // One pixel of 100 is 1 %: the outlier goes, the smaller error stays.
        let kept = rel_rmse_without_worst(&test, &reference, 0.01);
        assert!((kept - (0.25f64 / 99.0).sqrt()).abs() < 1e-6, "{kept}");
        assert!(relative_rmse(&test, &reference) > kept);
        assert_eq!(rel_rmse_without_worst(&reference, &reference, 0.01), 0.0);
    }
}

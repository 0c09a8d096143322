//! What `relume compare` and `relume bench` both measure: a timed sparse frame, the references,
//! and the indirect image's error against a reference. One code path, so the sweep's figures
//! are the figures `compare` prints.

use crate::gpu::{Gpu, GpuError};
use crate::image::{LinearImage, flip_mean, relative_rmse};
use crate::renderer::{Method, Rendered, Renderer};

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

/// The exact-visibility reference over every `val_stride`-th VAL, one frame.
pub fn exact_frame(
    gpu: &Gpu,
    renderer: &mut Renderer,
    width: u32,
    height: u32,
    val_stride: u32,
) -> Result<Rendered, GpuError> {
    renderer.set_exact_val_stride(val_stride);
    renderer.render(gpu, Method::Exact, width, height)
}

/// Where `compare --reference exact` computes its reference.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ReferenceDevice {
    /// The CPU on CPU adapters (lavapipe) or when an option only the CPU reference has is given
    /// (`--reference-samples`, `--spp` > 1); the GPU pass otherwise.
    Auto,
    /// `reference::exact_cpu` over rayon's threads.
    Cpu,
    /// The GPU pass (`gpu::exact`).
    Gpu,
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
}

/// Seed of the CPU reference's random numbers (VAL draws, sub-pixel positions): fixed, so a
/// figure can be reproduced.
pub const REFERENCE_SEED: u64 = 0x5eed;

impl ExactOptions {
    /// Check the options: `Err` names the flag (`--reference-samples: ...`).
    pub fn check(&self) -> Result<(), String> {
        use crate::reference::exact_cpu::{MAX_SPP, MAX_VAL_SAMPLES};
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
        if self.device == ReferenceDevice::Gpu && (self.samples.is_some() || self.spp > 1) {
            return Err("--reference-device: gpu computes every VAL (or a stride) at the pixel centre; \
                        --reference-samples and --spp need cpu"
                .into());
        }
        Ok(())
    }

    /// The device `Auto` stands for on `gpu`.
    pub fn device_on(&self, gpu: &Gpu) -> ReferenceDevice {
        match self.device {
            ReferenceDevice::Auto if gpu.is_cpu() || self.samples.is_some() || self.spp > 1 => ReferenceDevice::Cpu,
            ReferenceDevice::Auto => ReferenceDevice::Gpu,
            d => d,
        }
    }

    /// How the reference treats the VALs (as reported: "all", "stride" or "importance").
    pub fn estimator(&self) -> &'static str {
        match (self.samples, self.val_stride) {
            (Some(_), _) => "importance",
            (None, 1) => "all",
            _ => "stride",
        }
    }
}

/// An exact-visibility reference image with its noise and cost.
pub struct ExactReference {
    pub indirect: LinearImage,
    /// Per pixel and channel the variance of the reference's estimate; `None` for a stride.
    pub variance: Option<Vec<glam::Vec3>>,
    pub device: ReferenceDevice,
    /// Wall time of the reference itself (ms): the GPU pass's stage time, or the CPU's BVH build
    /// and tracing (not the GPU frame that made the VALs and the visibility buffer).
    pub ms: f64,
    /// CPU: shadow rays cast.
    pub shadow_rays: Option<u64>,
    /// GPU: the pass's rounds.
    pub rounds: u32,
    /// VALs in the frame.
    pub val_count: u32,
}

/// The exact-visibility reference of `renderer`'s scene at `width` x `height` per `options`
/// (checked with [`ExactOptions::check`]). The CPU path takes the VALs and the camera's
/// visibility buffer from a sparse frame rendered first: with one sample per pixel its receivers
/// are that buffer's pixels (exactly those the GPU methods shade); with more it traces primary
/// rays at jittered positions through the same BVH as its shadow rays.
pub fn exact_reference(
    gpu: &Gpu,
    renderer: &mut Renderer,
    width: u32,
    height: u32,
    options: &ExactOptions,
) -> Result<ExactReference, GpuError> {
    use crate::reference::bvh::Bvh;
    use crate::reference::exact_cpu::{self as cpu, CameraRays, PixelSampling, Receiver, Receivers, ValSampling};
    let device = options.device_on(gpu);
    if device == ReferenceDevice::Gpu {
        let frame = exact_frame(gpu, renderer, width, height, options.val_stride)?;
        let exact = options.val_stride == 1;
        return Ok(ExactReference {
            variance: exact.then(|| vec![glam::Vec3::ZERO; frame.indirect.pixels.len()]),
            ms: frame.timings.total_of(&[crate::renderer::stage::EXACT]),
            indirect: frame.indirect,
            device,
            shadow_rays: None,
            rounds: frame.exact_rounds,
            val_count: frame.val_count,
        });
    }
    let frame = renderer.render(gpu, Method::Sparse, width, height)?;
    let vals = renderer.read_vals(gpu)?;
    let hits = match renderer.camera_view() {
        Some(view) if options.spp == 1 => view.read(gpu)?,
        _ => Vec::new(),
    };
    let start = std::time::Instant::now();
    let flat = &renderer.scene.flat;
    let eye = renderer.view().eye();
    let positions: Vec<glam::Vec3> = flat.vertices.iter().map(|v| v.position.into()).collect();
    let triangles: Vec<[u32; 3]> = flat.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
    let bvh = Bvh::build(&positions, &triangles);
    let surface = |t: u32, b: glam::Vec2| {
        let (p, n, s) = flat.surface_at(t, b);
        Receiver::new(p, n, s, eye)
    };
    let camera = CameraRays::new(renderer.view_transforms(width, height).0, width, height);
    let resolved: Vec<Option<Receiver>> = hits.iter().map(|h| h.map(|h| surface(h.triangle, h.barycentrics))).collect();
    let receivers = if options.spp == 1 {
        Receivers::Hits(&resolved)
    } else {
        Receivers::Traced {
            camera: &camera,
            sampling: PixelSampling { spp: options.spp, seed: REFERENCE_SEED },
            surface: &surface,
        }
    };
    let sampling = match (options.samples, options.val_stride) {
        (Some(samples), _) => ValSampling::Importance { samples, seed: REFERENCE_SEED },
        (None, 1) => ValSampling::All,
        (None, s) => ValSampling::Stride(s),
    };
    let scene = cpu::ExactScene { bvh: &bvh, vals: &vals, glossy: renderer.glossy() };
    let out = cpu::render(&scene, &receivers, width, height, sampling);
    Ok(ExactReference {
        indirect: out.image,
        variance: out.variance,
        device,
        ms: start.elapsed().as_secs_f64() * 1e3,
        shadow_rays: Some(out.shadow_rays),
        rounds: 0,
        val_count: frame.val_count,
    })
}

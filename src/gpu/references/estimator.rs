//! The importance-sampled estimator of the exact reference on the GPU (`estimator.wgsl` after
//! the brute force, docs/design.md §5): the brute force's unoccluded sum at every pixel is the
//! distribution's total, then a walk over the VALs draws `samples` of them systematically in
//! proportion to their unoccluded luminance and casts one shadow ray through the BVH for each.
//! An unbiased estimate of the exact image whose cost is two unoccluded sums and `samples` rays
//! per pixel instead of a ray per VAL. Rust twin: `twin::exact_cpu` with
//! `ValSampling::Systematic`.

use super::rounds::{BVH_WGSL, PixelRounds};
use crate::gpu::pass::{Entry, PassDesc, buffer, read, read_write, texture};
use crate::gpu::references::brute_force::BruteForce;
use crate::gpu::references::exact::EXACT_LOOP_BUDGET;
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::Wgsl;
use crate::gpu::shader::{IMAGE_TILE, ROUNDS};
use crate::gpu::technique::{Frame, Technique};
use crate::gpu::timing::{Recorder, StageTimings};
use crate::gpu::{Gpu, GpuError};

pub const WGSL: &str = include_str!("estimator.wgsl");

/// Draws (shadow rays) per pixel at most (`render --draws`, a measured level's `draws`): each
/// invocation notes its draws in arrays of this many entries before it traces them.
pub const MAX_SAMPLES: u32 = crate::scene::settings::MAX_ESTIMATOR_DRAWS;
/// Shadow rays per pixel unless set.
pub const DEFAULT_SAMPLES: u32 = crate::scene::settings::DEFAULT_ESTIMATOR_DRAWS;

/// VALs one invocation walks per round, and BVH steps it traces: together under llvmpipe's loop
/// limit, as the exact pass's [`EXACT_LOOP_BUDGET`].
const WALK_BUDGET: u32 = EXACT_LOOP_BUDGET / 2;
const TRACE_BUDGET: u32 = EXACT_LOOP_BUDGET - WALK_BUDGET;

/// The pass's own WGSL: `samples` draws per pixel, their offsets from `seed`.
pub fn body(samples: u32, seed: u32) -> String {
    Wgsl::new()
        .u32("SAMPLES", samples.clamp(1, MAX_SAMPLES))
        .u32("SEED", seed)
        .u32("WALK_BUDGET", WALK_BUDGET)
        .u32("TRACE_BUDGET", TRACE_BUDGET)
        .include(BVH_WGSL)
        .include(ROUNDS)
        .include(WGSL)
        .finish()
}

/// One invocation per pixel, in rounds (see [`Estimator::finish`]).
pub const PASS: PassDesc = PassDesc {
    label: "estimator",
    bindings: &[
        texture("visibility"),
        read_write("indirect"),
        read("vals"),
        read("val_count"),
        read("bvh_nodes"),
        read("bvh_triangles"),
        read_write("progress"),
        read_write("status"),
        read_write("walk"),
    ],
    entries: &[Entry::first("main", 9), Entry::first("main_glossy", 9)],
    workgroup: IMAGE_TILE,
    default_source: |textured| PASS.source(&body(DEFAULT_SAMPLES, 1), textured),
};

/// Workgroups: [`IMAGE_TILE`] everywhere. The exact pass runs 1x1 on CPU adapters because
/// llvmpipe counts its loop limit per SIMD vector, which its nested loops with diverging lanes
/// exceed; this pass's two flat loops run at most their budgets in every lane, so a vector
/// does too, and its lanes share the walk's VAL loads (1x1 was 92 s a frame on sponza_bunny
/// at 256x256 with 8 draws, 8x8 18 s).
fn workgroup(_gpu: &Gpu) -> [u32; 3] {
    IMAGE_TILE
}

pub struct Estimator {
    brute_force: BruteForce,
    rounds: PixelRounds,
    /// Per pixel: total, running sum, thresholds passed (`walk` in the WGSL), sized as the
    /// rounds' progress.
    walk: wgpu::Buffer,
}

impl Estimator {
    /// Build the BVH of `scene`, the brute force and the pass drawing `samples` VALs per pixel
    /// (1..=[`MAX_SAMPLES`]) with offsets from `seed`.
    pub fn new(gpu: &Gpu, scene: &GpuScene, glossy: bool, samples: u32, seed: u32) -> Result<Self, GpuError> {
        Ok(Self {
            brute_force: BruteForce::new(gpu, scene, glossy, None)?,
            rounds: PixelRounds::new(gpu, scene, &PASS, &body(samples, seed), glossy, workgroup(gpu))?,
            walk: gpu.storage_buffer_sized::<[f32; 4]>("estimator.walk", 0)?,
        })
    }

    /// Cover frames of up to `max_vals` VALs and images of `pixels` pixels.
    pub fn fit(&mut self, gpu: &Gpu, scene: &GpuScene, max_vals: u32, pixels: usize) -> Result<(), GpuError> {
        self.brute_force.fit(gpu, scene, max_vals, pixels as u32)?;
        if self.rounds.fit(gpu, pixels)? {
            self.walk = gpu.storage_buffer_sized::<[f32; 4]>("estimator.walk", pixels)?;
        }
        Ok(())
    }

    fn bind(&self, gpu: &Gpu, frame: &Frame<'_>) -> wgpu::BindGroup {
        self.rounds.bind(gpu, frame, vec![buffer("walk", &self.walk)])
    }
}

impl Technique for Estimator {
    fn stages(&self) -> Vec<&'static str> {
        let mut stages = self.brute_force.stages();
        stages.push(PASS.label);
        stages
    }

    /// The brute force, then the first round (after [`Estimator::fit`] for this image);
    /// [`Technique::finish`] runs the rest once it has been submitted.
    fn record(&self, gpu: &Gpu, frame: &Frame<'_>, rec: &mut Recorder<'_>) -> Result<(), GpuError> {
        self.brute_force.record(gpu, frame, rec)?;
        let group = self.bind(gpu, frame);
        rec.stage(PASS.label, |e, s| self.rounds.first_round(e, frame, &group, s))
    }

    /// Dispatch further rounds until every pixel has passed its thresholds or walked every
    /// VAL; their wall time is added to the stage.
    fn finish(&self, gpu: &Gpu, frame: &Frame<'_>, timings: &mut StageTimings) -> Result<u32, GpuError> {
        let group = self.bind(gpu, frame);
        self.rounds.finish(gpu, frame, &group, timings, "estimator: pixels", TRACE_BUDGET)
    }
}

//! The importance-sampled estimator of the exact reference on the GPU (`estimator.wgsl` after
//! the brute force, docs/design.md §5): the brute force's unoccluded sum at every pixel is the
//! distribution's total, then a walk over the VALs draws `samples` of them systematically in
//! proportion to their unoccluded luminance and casts one shadow ray through the BVH for each.
//! An unbiased estimate of the exact image whose cost is two unoccluded sums and `samples` rays
//! per pixel instead of a ray per VAL. Rust twin: `twin::exact_cpu` with
//! `ValSampling::Systematic`.

use crate::gpu::pass::{Entry, Kernel, PassDesc, buffer, module_from_source, read, read_write, texture, view};
use crate::gpu::references::brute_force::BruteForce;
use crate::gpu::references::exact::EXACT_LOOP_BUDGET;
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::Wgsl;
use crate::gpu::shader::{IMAGE_TILE, ROUNDS, TILE_SIZE};
use crate::gpu::technique::{Frame, Technique};
use crate::gpu::timing::{Recorder, Span, StageTimings};
use crate::gpu::{Gpu, GpuError};
use crate::twin::bvh::Bvh;
use std::time::Instant;

pub const WGSL: &str = include_str!("estimator.wgsl");
const BVH: &str = include_str!("bvh.wgsl");

/// Draws (shadow rays) per pixel at most (`render --draws`): each invocation notes its draws
/// in arrays of this many entries before it traces them.
pub const MAX_SAMPLES: u32 = 256;
/// Shadow rays per pixel unless set.
pub const DEFAULT_SAMPLES: u32 = 32;

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
        .include(BVH)
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
    kernel: Kernel,
    nodes: wgpu::Buffer,
    order: wgpu::Buffer,
    /// Per pixel: 0 before the first round, then 1 + the next VAL (`progress` in the WGSL).
    progress: wgpu::Buffer,
    /// Per pixel: total, running sum, thresholds passed (`walk` in the WGSL).
    walk: wgpu::Buffer,
    pixels: usize,
    /// [pixels left after a round, pixels that made no progress in it].
    status: wgpu::Buffer,
}

impl Estimator {
    /// Build the BVH of `scene`, the brute force and the pass drawing `samples` VALs per pixel
    /// (1..=[`MAX_SAMPLES`]) with offsets from `seed`.
    pub fn new(gpu: &Gpu, scene: &GpuScene, glossy: bool, samples: u32, seed: u32) -> Result<Self, GpuError> {
        let flat = &scene.flat;
        let positions: Vec<glam::Vec3> = flat.vertices.iter().map(|v| v.position.into()).collect();
        let triangles: Vec<[u32; 3]> = flat.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
        let bvh = Bvh::build(&positions, &triangles);
        let none = wgpu::BufferUsages::empty();
        let nodes = gpu.storage_buffer("estimator.bvh_nodes", &bvh.nodes, none)?;
        let order = gpu.storage_buffer("estimator.bvh_triangles", &bvh.order, none)?;
        let workgroup = workgroup(gpu);
        let source = PASS.source_with(&body(samples, seed), scene.textured(), workgroup, TILE_SIZE);
        let module = module_from_source(gpu, PASS.label, source)?;
        let kernel = Kernel::build(gpu, scene, &PASS, &module, PASS.lobe_entry(glossy), &[], workgroup)?;
        Ok(Self {
            brute_force: BruteForce::new(gpu, scene, glossy, None)?,
            kernel,
            nodes,
            order,
            progress: gpu.storage_buffer_sized::<u32>("estimator.progress", 0)?,
            walk: gpu.storage_buffer_sized::<[f32; 4]>("estimator.walk", 0)?,
            pixels: 0,
            status: gpu.storage_buffer_sized::<u32>("estimator.status", 2)?,
        })
    }

    /// Cover frames of up to `max_vals` VALs and images of `pixels` pixels.
    pub fn fit(&mut self, gpu: &Gpu, scene: &GpuScene, max_vals: u32, pixels: usize) -> Result<(), GpuError> {
        self.brute_force.fit(gpu, scene, max_vals, pixels as u32)?;
        if pixels > self.pixels {
            self.progress = gpu.storage_buffer_sized::<u32>("estimator.progress", pixels)?;
            self.walk = gpu.storage_buffer_sized::<[f32; 4]>("estimator.walk", pixels)?;
            self.pixels = pixels;
        }
        Ok(())
    }

    fn bind(&self, gpu: &Gpu, frame: &Frame<'_>) -> wgpu::BindGroup {
        self.kernel.bind(
            gpu,
            &[
                view("visibility", &frame.camera.view.view),
                buffer("indirect", &frame.camera.indirect),
                buffer("vals", &frame.vals.buffer),
                buffer("val_count", &frame.vals.count),
                buffer("bvh_nodes", &self.nodes),
                buffer("bvh_triangles", &self.order),
                buffer("progress", &self.progress),
                buffer("status", &self.status),
                buffer("walk", &self.walk),
            ],
        )
    }

    /// One round over the image.
    fn dispatch(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        frame: &Frame<'_>,
        group: &wgpu::BindGroup,
        span: Option<Span<'_>>,
    ) {
        encoder.clear_buffer(&self.status, 0, None);
        let camera = &frame.camera.view;
        let invocations = [camera.width, camera.height, 1];
        self.kernel.dispatch(encoder, group, frame.scene, invocations, span.as_ref().map(Span::compute));
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
        let camera = &frame.camera.view;
        let pixels = u64::from(camera.width * camera.height) * 4;
        let group = self.bind(gpu, frame);
        rec.stage(PASS.label, |e, s| {
            e.clear_buffer(&self.progress, 0, Some(pixels));
            self.dispatch(e, frame, &group, s);
        })
    }

    /// Dispatch further rounds until every pixel has passed its thresholds or walked every
    /// VAL; their wall time is added to the stage.
    fn finish(&self, gpu: &Gpu, frame: &Frame<'_>, timings: &mut StageTimings) -> Result<u32, GpuError> {
        let start = Instant::now();
        let group = self.bind(gpu, frame);
        let mut count = 1;
        loop {
            if crate::gpu::rounds_done(gpu, &self.status, count, "estimator: pixels", TRACE_BUDGET)? {
                break;
            }
            let mut encoder =
                gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("estimator.round") });
            self.dispatch(&mut encoder, frame, &group, None);
            gpu.submit_and_wait(encoder)?;
            count += 1;
        }
        if count > 1 {
            timings.add(PASS.label, start.elapsed().as_secs_f64() * 1e3);
        }
        Ok(count)
    }
}

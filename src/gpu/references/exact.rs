//! Exact-visibility reference (`exact.wgsl` + `bvh.wgsl`, docs/design.md §5): the
//! brute force with a shadow ray per pixel and VAL through a BVH built on the CPU. Rust twins:
//! `twin::shade_brute_force` over the VALs `twin::bvh::Bvh::occluded` lets through.

use crate::gpu::pass::{Entry, Kernel, PassDesc, buffer, module_from_source, read, read_write, texture, view};
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::Wgsl;
use crate::gpu::shader::{IMAGE_TILE, ROUNDS, TILE_SIZE};
use crate::gpu::technique::{Frame, Technique};
use crate::gpu::timing::{Recorder, Span, StageTimings};
use crate::gpu::{Gpu, GpuError, LLVMPIPE_LOOP_LIMIT};
use crate::twin::bvh::Bvh;
use std::time::Instant;

pub const WGSL: &str = include_str!("exact.wgsl");
const BVH: &str = include_str!("bvh.wgsl");

/// Loop iterations (VAL loop and BVH traversal together) one invocation runs per round.
/// llvmpipe silently ends all loops of an invocation after [`LLVMPIPE_LOOP_LIMIT`] iterations
/// in total, which cut the VAL loop short on pixels with many or long shadow rays; this stays
/// below it with a margin. GPUs have no such limit but are just as right in rounds.
pub const EXACT_LOOP_BUDGET: u32 = 60_000;
const _: () = assert!(EXACT_LOOP_BUDGET < LLVMPIPE_LOOP_LIMIT);

/// The pass's own WGSL using every `val_stride`-th VAL.
pub fn body(val_stride: u32) -> String {
    Wgsl::new()
        .u32("VAL_STRIDE", val_stride)
        .u32("EXACT_LOOP_BUDGET", EXACT_LOOP_BUDGET)
        .include(BVH)
        .include(ROUNDS)
        .include(WGSL)
        .finish()
}

/// One invocation per pixel, in rounds (see [`Exact::finish`]).
pub const PASS: PassDesc = PassDesc {
    label: "exact",
    bindings: &[
        texture("visibility"),
        read_write("indirect"),
        read("vals"),
        read("val_count"),
        read("bvh_nodes"),
        read("bvh_triangles"),
        read_write("progress"),
        read_write("status"),
    ],
    entries: &[Entry::first("main", 8), Entry::first("main_glossy", 8)],
    workgroup: IMAGE_TILE,
    default_source: |textured| PASS.source(&body(4), textured),
};

/// Workgroups: [`IMAGE_TILE`] on GPUs. On CPU adapters 1x1: llvmpipe runs a workgroup's invocations as
/// SIMD lanes, and with lanes diverging in the BVH traversal whole 8x8 blocks came out wrong
/// (bright squares on the bunny at 192x192). Most likely
/// the same loop limit as [`EXACT_LOOP_BUDGET`]: llvmpipe counts it per SIMD vector, so lanes
/// that diverge use up one limit together, which a per-invocation budget cannot account for.
/// With one invocation per workgroup the budget is that invocation's own.
fn workgroup(gpu: &Gpu) -> [u32; 3] {
    if gpu.is_cpu() { [1, 1, 1] } else { IMAGE_TILE }
}

pub struct Exact {
    kernel: Kernel,
    nodes: wgpu::Buffer,
    order: wgpu::Buffer,
    /// Per pixel: the next VAL to cast toward (`progress` in `exact.wgsl`), sized to the largest
    /// image rendered so far.
    progress: wgpu::Buffer,
    progress_pixels: usize,
    /// [pixels left after a round, pixels that made no progress in it].
    status: wgpu::Buffer,
}

impl Exact {
    /// Build the BVH of `scene` and the pass over every `val_stride`-th VAL (>= 1).
    pub fn new(gpu: &Gpu, scene: &GpuScene, glossy: bool, val_stride: u32) -> Result<Self, GpuError> {
        let flat = &scene.flat;
        let positions: Vec<glam::Vec3> = flat.vertices.iter().map(|v| v.position.into()).collect();
        let triangles: Vec<[u32; 3]> = flat.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
        let bvh = Bvh::build(&positions, &triangles);
        let none = wgpu::BufferUsages::empty();
        let nodes = gpu.storage_buffer("exact.bvh_nodes", &bvh.nodes, none)?;
        let order = gpu.storage_buffer("exact.bvh_triangles", &bvh.order, none)?;
        let workgroup = workgroup(gpu);
        let source = PASS.source_with(&body(val_stride.max(1)), scene.textured(), workgroup, TILE_SIZE);
        let module = module_from_source(gpu, PASS.label, source)?;
        let kernel = Kernel::build(gpu, scene, &PASS, &module, PASS.lobe_entry(glossy), &[], workgroup)?;
        let progress = gpu.storage_buffer_sized::<u32>("exact.progress", 0)?;
        let status = gpu.storage_buffer_sized::<u32>("exact.status", 2)?;
        Ok(Self { kernel, nodes, order, progress, progress_pixels: 0, status })
    }

    /// Make room for an image of `pixels` pixels.
    pub fn fit(&mut self, gpu: &Gpu, pixels: usize) -> Result<(), GpuError> {
        if pixels > self.progress_pixels {
            self.progress = gpu.storage_buffer_sized::<u32>("exact.progress", pixels)?;
            self.progress_pixels = pixels;
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

impl Technique for Exact {
    fn stages(&self) -> Vec<&'static str> {
        vec![PASS.label]
    }

    /// The first round (after [`Exact::fit`] for this image); [`Technique::finish`] runs the
    /// rest once it has been submitted.
    fn record(&self, gpu: &Gpu, frame: &Frame<'_>, rec: &mut Recorder<'_>) -> Result<(), GpuError> {
        let camera = &frame.camera.view;
        let pixels = u64::from(camera.width * camera.height) * 4;
        let group = self.bind(gpu, frame);
        rec.stage(PASS.label, |e, s| {
            e.clear_buffer(&self.progress, 0, Some(pixels));
            self.dispatch(e, frame, &group, s);
        })
    }

    /// Dispatch further rounds, each submitted and waited for, until every pixel has seen every
    /// VAL; their wall time is added to the stage, whatever timed the first round.
    fn finish(&self, gpu: &Gpu, frame: &Frame<'_>, timings: &mut StageTimings) -> Result<u32, GpuError> {
        let start = Instant::now();
        let group = self.bind(gpu, frame);
        let mut count = 1;
        loop {
            if crate::gpu::rounds_done(gpu, &self.status, count, "exact visibility: pixels", EXACT_LOOP_BUDGET)? {
                break;
            }
            let mut encoder =
                gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("exact.round") });
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

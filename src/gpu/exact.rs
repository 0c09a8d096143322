//! Exact-visibility reference (`shaders/exact.wgsl` + `shaders/bvh.wgsl`, DESIGN.md §5): the
//! brute force with a shadow ray per pixel and VAL through a BVH built on the CPU. Rust twins:
//! `reference::shade_brute_force` over the VALs `reference::bvh::Bvh::occluded` lets through.

use super::kernel::{Kernel, Slot, groups};
use super::scene::GpuScene;
use super::timing::Span;
use super::visibility::VisibilityTarget;
use super::{Gpu, GpuError, LLVMPIPE_LOOP_LIMIT};
use crate::reference::bvh::Bvh;
use std::time::Instant;

pub const WGSL: &str = include_str!("../../shaders/exact.wgsl");
const BVH: &str = include_str!("../../shaders/bvh.wgsl");

/// Loop iterations (VAL loop and BVH traversal together) one invocation runs per round.
/// llvmpipe silently ends all loops of an invocation after [`LLVMPIPE_LOOP_LIMIT`] iterations
/// in total, which cut the VAL loop short on pixels with many or long shadow rays; this stays
/// below it with a margin. GPUs have no such limit but are just as right in rounds.
pub const EXACT_LOOP_BUDGET: u32 = 60_000;
const _: () = assert!(EXACT_LOOP_BUDGET < LLVMPIPE_LOOP_LIMIT);

/// Rounds at most before [`Exact::finish`] gives up (each makes progress on every unfinished
/// pixel, so only a driver that ignores the budget could need this many).
const MAX_ROUNDS: u32 = 1 << 16;

/// The pass's WGSL using every `val_stride`-th VAL, with `side x side` workgroups.
pub fn source(val_stride: u32, side: u32) -> String {
    format!(
        "const VAL_STRIDE: u32 = {val_stride}u;\nconst EXACT_WORKGROUP_SIDE: u32 = {side}u;\n\
         const EXACT_LOOP_BUDGET: u32 = {EXACT_LOOP_BUDGET}u;\n{BVH}\n{WGSL}"
    )
}

/// Workgroup side: 8 on GPUs. On CPU adapters 1: llvmpipe runs a workgroup's invocations as
/// SIMD lanes, and with lanes diverging in the BVH traversal whole 8x8 blocks came out wrong
/// (bright squares on the bunny at 192x192). Most likely
/// the same loop limit as [`EXACT_LOOP_BUDGET`]: llvmpipe counts it per SIMD vector, so lanes
/// that diverge use up one limit together, which a per-invocation budget cannot account for.
/// With one invocation per workgroup the budget is that invocation's own.
fn workgroup_side(gpu: &Gpu) -> u32 {
    if gpu.is_cpu() { 1 } else { 8 }
}

pub struct Exact {
    kernel: Kernel,
    side: u32,
    nodes: wgpu::Buffer,
    order: wgpu::Buffer,
    /// Per pixel: the next VAL to cast toward (`progress` in `exact.wgsl`), sized to the largest
    /// image rendered so far.
    progress: wgpu::Buffer,
    progress_pixels: usize,
    /// [pixels left after a round, pixels that made no progress in it].
    status: wgpu::Buffer,
}

/// What one exact frame took beyond its first round.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Rounds {
    /// Dispatches over the image, the first included.
    pub count: u32,
    /// Wall time of the rounds after the first (ms).
    pub extra_ms: f64,
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
        let slots = [
            Slot::TextureUint,
            Slot::StorageReadWrite,
            Slot::Storage,
            Slot::Storage,
            Slot::Storage,
            Slot::Storage,
            Slot::StorageReadWrite,
            Slot::StorageReadWrite,
        ];
        let side = workgroup_side(gpu);
        let kernel = Kernel::pass(gpu, scene, "exact", &source(val_stride.max(1), side), &slots, &[], glossy)?;
        let progress = gpu.storage_buffer_sized::<u32>("exact.progress", 0)?;
        let status = gpu.storage_buffer_sized::<u32>("exact.status", 2)?;
        Ok(Self { kernel, side, nodes, order, progress, progress_pixels: 0, status })
    }

    /// Make room for an image of `pixels` pixels.
    pub fn fit(&mut self, gpu: &Gpu, pixels: usize) -> Result<(), GpuError> {
        if pixels > self.progress_pixels {
            self.progress = gpu.storage_buffer_sized::<u32>("exact.progress", pixels)?;
            self.progress_pixels = pixels;
        }
        Ok(())
    }

    fn bind(
        &self,
        gpu: &Gpu,
        camera: &VisibilityTarget,
        vals: &wgpu::Buffer,
        val_count: &wgpu::Buffer,
        indirect: &wgpu::Buffer,
    ) -> wgpu::BindGroup {
        self.kernel.bind(
            gpu,
            &[
                wgpu::BindingResource::TextureView(&camera.view),
                indirect.as_entire_binding(),
                vals.as_entire_binding(),
                val_count.as_entire_binding(),
                self.nodes.as_entire_binding(),
                self.order.as_entire_binding(),
                self.progress.as_entire_binding(),
                self.status.as_entire_binding(),
            ],
        )
    }

    fn dispatch(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        scene: &GpuScene,
        camera: &VisibilityTarget,
        group: &wgpu::BindGroup,
        span: Option<Span<'_>>,
    ) {
        encoder.clear_buffer(&self.status, 0, None);
        let wg = [groups(camera.width, self.side), groups(camera.height, self.side), 1];
        self.kernel.dispatch(encoder, group, &scene.bind_group, wg, span.as_ref().map(Span::compute));
    }

    /// Record the first round (after [`Exact::fit`] for this image); [`Exact::finish`] runs the
    /// rest once it has been submitted.
    pub fn record(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        scene: &GpuScene,
        camera: &VisibilityTarget,
        vals: &wgpu::Buffer,
        val_count: &wgpu::Buffer,
        indirect: &wgpu::Buffer,
        span: Option<Span<'_>>,
    ) {
        let pixels = u64::from(camera.width * camera.height) * 4;
        encoder.clear_buffer(&self.progress, 0, Some(pixels));
        let group = self.bind(gpu, camera, vals, val_count, indirect);
        self.dispatch(encoder, scene, camera, &group, span);
    }

    /// Dispatch further rounds, each submitted and waited for, until every pixel has seen every
    /// VAL; call after the first round (recorded by [`Exact::record`]) has completed.
    pub fn finish(
        &self,
        gpu: &Gpu,
        scene: &GpuScene,
        camera: &VisibilityTarget,
        vals: &wgpu::Buffer,
        val_count: &wgpu::Buffer,
        indirect: &wgpu::Buffer,
    ) -> Result<Rounds, GpuError> {
        let start = Instant::now();
        let group = self.bind(gpu, camera, vals, val_count, indirect);
        let mut count = 1;
        loop {
            let [left, stuck] = gpu.read_buffer::<u32>(&self.status, 2)?[..] else {
                unreachable!("read_buffer returns the 2 elements asked for")
            };
            if left == 0 {
                break;
            }
            if stuck > 0 || count >= MAX_ROUNDS {
                return Err(GpuError::Incomplete(format!(
                    "exact visibility: {left} pixels unfinished after {count} rounds, {stuck} of them made no \
                     progress (a shadow ray longer than {EXACT_LOOP_BUDGET} BVH steps)"
                )));
            }
            let mut encoder =
                gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("exact.round") });
            self.dispatch(&mut encoder, scene, camera, &group, None);
            gpu.submit_and_wait(encoder)?;
            count += 1;
        }
        let extra_ms = if count > 1 { start.elapsed().as_secs_f64() * 1e3 } else { 0.0 };
        Ok(Rounds { count, extra_ms })
    }
}

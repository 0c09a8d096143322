//! Exact-visibility reference (`shaders/exact.wgsl` + `shaders/bvh.wgsl`, DESIGN.md §5): the
//! brute force with a shadow ray per pixel and VAL through a BVH built on the CPU. Rust twins:
//! `reference::shade_brute_force` over the VALs `reference::bvh::Bvh::occluded` lets through.

use super::kernel::{Kernel, Slot, groups};
use super::scene::GpuScene;
use super::timing::Span;
use super::visibility::VisibilityTarget;
use super::{Gpu, GpuError};
use crate::reference::bvh::Bvh;

pub const WGSL: &str = include_str!("../../shaders/exact.wgsl");
const BVH: &str = include_str!("../../shaders/bvh.wgsl");

/// The pass's WGSL using every `val_stride`-th VAL, with `side x side` workgroups.
pub fn source(val_stride: u32, side: u32) -> String {
    format!("const VAL_STRIDE: u32 = {val_stride}u;\nconst EXACT_WORKGROUP_SIDE: u32 = {side}u;\n{BVH}\n{WGSL}")
}

/// Workgroup side: 8 on GPUs. On CPU adapters 1: llvmpipe runs a workgroup's invocations as
/// SIMD lanes, and with lanes diverging in the BVH traversal whole 8x8 blocks came out wrong
/// (bright squares on the bunny at 192x192; single invocations were always right).
fn workgroup_side(gpu: &Gpu) -> u32 {
    if gpu.is_cpu() { 1 } else { 8 }
}

pub struct Exact {
    kernel: Kernel,
    side: u32,
    nodes: wgpu::Buffer,
    order: wgpu::Buffer,
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
        let slots =
            [Slot::TextureUint, Slot::StorageReadWrite, Slot::Storage, Slot::Storage, Slot::Storage, Slot::Storage];
        let side = workgroup_side(gpu);
        let kernel = Kernel::pass(gpu, scene, "exact", &source(val_stride.max(1), side), &slots, &[], glossy)?;
        Ok(Self { kernel, side, nodes, order })
    }

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
        let group = self.kernel.bind(
            gpu,
            &[
                wgpu::BindingResource::TextureView(&camera.view),
                indirect.as_entire_binding(),
                vals.as_entire_binding(),
                val_count.as_entire_binding(),
                self.nodes.as_entire_binding(),
                self.order.as_entire_binding(),
            ],
        );
        let wg = [groups(camera.width, self.side), groups(camera.height, self.side), 1];
        self.kernel.dispatch(encoder, &group, &scene.bind_group, wg, span.as_ref().map(Span::compute));
    }
}

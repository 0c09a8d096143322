//! Brute-force reference (`shaders/brute_force.wgsl`, DESIGN.md §5). Rust twin:
//! `reference::shade_brute_force`. On CPU adapters the VALs go in ranges, one dispatch each,
//! each adding to the radiance of the ones before ([`ValRangeKernels`]).

use super::kernel::{self, Slot, ValRangeKernels, groups};
use super::scene::GpuScene;
use super::shader::TILE_SIZE;
use super::timing::Span;
use super::visibility::VisibilityTarget;
use super::{Gpu, GpuError};

pub const WGSL: &str = include_str!("../../shaders/brute_force.wgsl");

pub struct BruteForce {
    kernels: ValRangeKernels,
}

impl BruteForce {
    pub fn new(gpu: &Gpu, scene: &GpuScene, glossy: bool) -> Result<Self, GpuError> {
        let module = kernel::module(gpu, scene, "brute_force", WGSL)?;
        let slots = vec![Slot::TextureUint, Slot::StorageReadWrite, Slot::Storage, Slot::Storage];
        let entry = if glossy { "main_glossy" } else { "main" };
        let kernels = ValRangeKernels::new(gpu, scene, module, "brute_force", entry, slots, TILE_SIZE)?;
        Ok(Self { kernels })
    }

    /// Cover frames of up to `max_vals` VALs (see [`ValRangeKernels::fit`]).
    pub fn fit(&mut self, gpu: &Gpu, scene: &GpuScene, max_vals: u32) -> Result<(), GpuError> {
        self.kernels.fit(gpu, scene, max_vals)
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
        let resources = [
            wgpu::BindingResource::TextureView(&camera.view),
            indirect.as_entire_binding(),
            vals.as_entire_binding(),
            val_count.as_entire_binding(),
        ];
        let wg = [groups(camera.width, 8), groups(camera.height, TILE_SIZE / 8), 1];
        self.kernels.dispatch(gpu, encoder, scene, &resources, wg, span);
    }
}

//! Brute-force reference (`shaders/brute_force.wgsl`, DESIGN.md §5). Rust twin:
//! `reference::shade_brute_force`.

use super::kernel::{Kernel, Slot, groups};
use super::scene::GpuScene;
use super::shader::TILE_SIZE;
use super::timing::Span;
use super::visibility::VisibilityTarget;
use super::{Gpu, GpuError};

pub const WGSL: &str = include_str!("../../shaders/brute_force.wgsl");

pub struct BruteForce {
    kernel: Kernel,
}

impl BruteForce {
    pub fn new(gpu: &Gpu, scene: &GpuScene, glossy: bool) -> Result<Self, GpuError> {
        let kernel = Kernel::pass(
            gpu,
            scene,
            "brute_force",
            WGSL,
            &[Slot::TextureUint, Slot::StorageReadWrite, Slot::Storage, Slot::Storage],
            &[],
            glossy,
        )?;
        Ok(Self { kernel })
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
            ],
        );
        let wg = [groups(camera.width, 8), groups(camera.height, TILE_SIZE / 8), 1];
        self.kernel.dispatch(encoder, &group, &scene.bind_group, wg, span.as_ref().map(Span::compute));
    }
}

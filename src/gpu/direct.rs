//! Direct spot light with the RSM shadow map (`shaders/direct.wgsl`, DESIGN.md §4 step 6).
//! Rust twin (without the shadow test): `reference::rsm::direct_radiance`.

use super::kernel::{Kernel, Slot, groups};
use super::scene::GpuScene;
use super::timing::Span;
use super::visibility::VisibilityTarget;
use super::{Gpu, GpuError};

pub const WGSL: &str = include_str!("../../shaders/direct.wgsl");

pub struct Direct {
    kernel: Kernel,
}

impl Direct {
    pub fn new(gpu: &Gpu, scene: &GpuScene) -> Result<Self, GpuError> {
        let kernel = Kernel::pass(
            gpu,
            scene,
            "direct",
            WGSL,
            &[Slot::TextureUint, Slot::StorageReadWrite, Slot::Storage],
            &[],
            false,
        )?;
        Ok(Self { kernel })
    }

    pub fn record(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        scene: &GpuScene,
        camera: &VisibilityTarget,
        light_distance: &wgpu::Buffer,
        direct: &wgpu::Buffer,
        span: Option<Span<'_>>,
    ) {
        let group = self.kernel.bind(
            gpu,
            &[
                wgpu::BindingResource::TextureView(&camera.view),
                direct.as_entire_binding(),
                light_distance.as_entire_binding(),
            ],
        );
        let wg = [groups(camera.width, 8), groups(camera.height, 8), 1];
        self.kernel.dispatch(encoder, &group, &scene.bind_group, wg, span.as_ref().map(Span::compute));
    }
}

//! Per-pixel sparse shading (`shaders/shade.wgsl`, DESIGN.md §4 step 5). Rust twin:
//! `reference::shade_sparse`.

use super::kernel::{Kernel, Slot, groups};
use super::scene::GpuScene;
use super::timing::Span;
use super::visibility::VisibilityTarget;
use super::{Gpu, GpuError, Lobes};

pub const WGSL: &str = include_str!("../../shaders/shade.wgsl");

pub struct Shade {
    kernel: Kernel,
}

impl Shade {
    pub fn new(gpu: &Gpu, scene: &GpuScene, glossy: bool) -> Result<Self, GpuError> {
        let kernel = Kernel::pass(
            gpu,
            scene,
            "shade",
            WGSL,
            &[Slot::TextureUint, Slot::StorageReadWrite, Slot::Storage],
            &[Slot::Storage],
            glossy,
        )?;
        Ok(Self { kernel })
    }

    /// Shade every pixel of `camera` with the per-vertex lights into `indirect` (RGBA f32).
    pub fn record(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        scene: &GpuScene,
        camera: &VisibilityTarget,
        vertex_lights: &Lobes,
        indirect: &wgpu::Buffer,
        span: Option<Span<'_>>,
    ) {
        let mut resources = vec![
            wgpu::BindingResource::TextureView(&camera.view),
            indirect.as_entire_binding(),
            vertex_lights.diffuse.as_entire_binding(),
        ];
        resources.extend(vertex_lights.glossy.as_ref().map(|b| b.as_entire_binding()));
        let group = self.kernel.bind(gpu, &resources);
        let wg = [groups(camera.width, 8), groups(camera.height, 8), 1];
        self.kernel.dispatch(encoder, &group, &scene.bind_group, wg, span.as_ref().map(Span::compute));
    }
}

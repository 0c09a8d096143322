//! RSM to VALs (`shaders/rsm.wgsl`): the light's visibility buffer becomes a compacted VAL list
//! and a distance-to-light shadow map. Rust twin: `reference::rsm::rsm_texel_val`.

use super::kernel::{Kernel, Slot, groups};
use super::scene::GpuScene;
use super::timing::Span;
use super::visibility::VisibilityTarget;
use super::{Gpu, GpuError};

pub const WGSL: &str = include_str!("../../shaders/rsm.wgsl");

pub struct Rsm {
    kernel: Kernel,
}

/// Outputs of the RSM pass.
pub struct RsmOutputs<'a> {
    /// `array<Val>`; appends stop at its capacity.
    pub vals: &'a wgpu::Buffer,
    /// One `u32`: VALs appended after those already counted (the caller clears it).
    pub val_count: &'a wgpu::Buffer,
    /// `array<f32>`, R²: distance from the light to the surface each texel sees (m).
    pub light_distance: &'a wgpu::Buffer,
}

impl Rsm {
    pub fn new(gpu: &Gpu, scene: &GpuScene) -> Result<Self, GpuError> {
        let kernel = Kernel::pass(
            gpu,
            scene,
            "rsm",
            WGSL,
            &[Slot::TextureUint, Slot::StorageReadWrite, Slot::StorageReadWrite, Slot::StorageReadWrite],
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
        light_view: &VisibilityTarget,
        out: &RsmOutputs<'_>,
        span: Option<Span<'_>>,
    ) {
        let group = self.kernel.bind(
            gpu,
            &[
                wgpu::BindingResource::TextureView(&light_view.view),
                out.vals.as_entire_binding(),
                out.val_count.as_entire_binding(),
                out.light_distance.as_entire_binding(),
            ],
        );
        let r = light_view.width;
        self.kernel.dispatch(
            encoder,
            &group,
            &scene.bind_group,
            [groups(r, 8), groups(r, 8), 1],
            span.as_ref().map(Span::compute),
        );
    }
}

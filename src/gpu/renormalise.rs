//! Renormalisation (`shaders/renormalise.wgsl`, DESIGN.md §4 step 2). Rust twins:
//! `reference::renormalise_diffuse`, `reference::renormalise_glossy`.

use super::kernel::{Kernel, Slot, groups};
use super::scene::GpuScene;
use super::shader::WORKGROUP_SIZE;
use super::timing::Span;
use super::{Gpu, GpuError, Lobes};

pub const WGSL: &str = include_str!("../../shaders/renormalise.wgsl");

pub struct Renormalise {
    kernel: Kernel,
}

impl Renormalise {
    pub fn new(gpu: &Gpu, scene: &GpuScene, glossy: bool) -> Result<Self, GpuError> {
        let kernel = Kernel::pass(
            gpu,
            scene,
            "renormalise",
            WGSL,
            &[Slot::Storage, Slot::Storage, Slot::StorageReadWrite],
            &[Slot::Storage, Slot::StorageReadWrite],
            glossy,
        )?;
        Ok(Self { kernel })
    }

    /// Turn `gathered` sums into per-sparse-point point lights `lights`.
    pub fn record(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        scene: &GpuScene,
        gathered: &Lobes,
        lights: &Lobes,
        span: Option<Span<'_>>,
    ) {
        let mut resources = vec![
            scene.sparse_points.as_entire_binding(),
            gathered.diffuse.as_entire_binding(),
            lights.diffuse.as_entire_binding(),
        ];
        if let (Some(g), Some(l)) = (&gathered.glossy, &lights.glossy) {
            resources.extend([g.as_entire_binding(), l.as_entire_binding()]);
        }
        let group = self.kernel.bind(gpu, &resources);
        let n = scene.flat.sparse_count();
        self.kernel.dispatch(
            encoder,
            &group,
            &scene.bind_group,
            [groups(n, WORKGROUP_SIZE), 1, 1],
            span.as_ref().map(Span::compute),
        );
    }
}

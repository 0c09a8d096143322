//! Gather at sparse points (`shaders/gather.wgsl`, DESIGN.md §4 step 1). Rust twin:
//! `reference::gather_point`.

use super::kernel::{Kernel, Slot, groups};
use super::scene::GpuScene;
use super::shader::TILE_SIZE;
use super::timing::Span;
use super::{Gpu, GpuError, Lobes};

pub const WGSL: &str = include_str!("../../shaders/gather.wgsl");

pub struct Gather {
    kernel: Kernel,
}

impl Gather {
    /// `glossy` builds the entry point that also gathers the Phong lobe.
    pub fn new(gpu: &Gpu, scene: &GpuScene, glossy: bool) -> Result<Self, GpuError> {
        let kernel = Kernel::pass(
            gpu,
            scene,
            "gather",
            WGSL,
            &[Slot::Storage, Slot::Storage, Slot::Storage, Slot::StorageReadWrite],
            &[Slot::StorageReadWrite],
            glossy,
        )?;
        Ok(Self { kernel })
    }

    /// Gather `vals` (`val_count` of them) at every sparse point into `gathered`.
    pub fn record(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        scene: &GpuScene,
        vals: &wgpu::Buffer,
        val_count: &wgpu::Buffer,
        gathered: &Lobes,
        span: Option<Span<'_>>,
    ) {
        let mut resources = vec![
            scene.sparse_points.as_entire_binding(),
            vals.as_entire_binding(),
            val_count.as_entire_binding(),
            gathered.diffuse.as_entire_binding(),
        ];
        resources.extend(gathered.glossy.as_ref().map(|b| b.as_entire_binding()));
        let group = self.kernel.bind(gpu, &resources);
        let n = scene.flat.sparse_count();
        self.kernel.dispatch(
            encoder,
            &group,
            &scene.bind_group,
            [groups(n, TILE_SIZE), 1, 1],
            span.as_ref().map(Span::compute),
        );
    }
}

//! Gather at sparse points (`shaders/gather.wgsl`, DESIGN.md §4 step 1). Rust twin:
//! `reference::gather_point`.

use super::kernel::{self, Kernel, Slot, groups};
use super::scene::GpuScene;
use super::shader::TILE_SIZE;
use super::timing::Span;
use super::{Gpu, GpuError, Lobes};

pub const WGSL: &str = include_str!("../../shaders/gather.wgsl");

pub struct Gather {
    kernel: Kernel,
    /// VALs per workgroup-memory tile, also the workgroup size.
    tile_size: u32,
}

impl Gather {
    /// `glossy` builds the entry point that also gathers the Phong lobe.
    pub fn new(gpu: &Gpu, scene: &GpuScene, glossy: bool) -> Result<Self, GpuError> {
        Self::with_tile_size(gpu, scene, glossy, TILE_SIZE)
    }

    /// The pass with `tile_size` VALs per tile and threads per workgroup instead of
    /// [`TILE_SIZE`] (the bench compares them; the device must allow the workgroup size).
    pub fn with_tile_size(gpu: &Gpu, scene: &GpuScene, glossy: bool, tile_size: u32) -> Result<Self, GpuError> {
        let source = super::shader::source_with_tile_size(WGSL, scene.textured(), tile_size);
        let module = kernel::module_from_source(gpu, "gather", source)?;
        let mut slots = vec![Slot::Storage, Slot::Storage, Slot::Storage, Slot::StorageReadWrite];
        if glossy {
            slots.push(Slot::StorageReadWrite);
        }
        let entry = if glossy { "main_glossy" } else { "main" };
        let kernel = Kernel::new(gpu, &scene.layout, &module, "gather", entry, &slots)?;
        Ok(Self { kernel, tile_size })
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
            [groups(n, self.tile_size), 1, 1],
            span.as_ref().map(Span::compute),
        );
    }
}

//! Gather at sparse points (`shaders/gather.wgsl`, DESIGN.md §4 step 1). Rust twin:
//! `reference::gather_point`.
//!
//! On a CPU adapter one invocation may not loop over more than about
//! [`Gpu::CPU_MAX_GATHERED_VALS`] VALs (llvmpipe ends a shader's loops after
//! [`super::LLVMPIPE_LOOP_LIMIT`] iterations, silently), so there the VALs are gathered in
//! ranges, one dispatch each, every range merging into the sums of the ones before
//! ([`ValRangeKernels`]). GPUs take every VAL in one dispatch.

use super::kernel::{self, Slot, ValRangeKernels, groups};
use super::scene::GpuScene;
use super::shader::TILE_SIZE;
use super::timing::Span;
use super::{Gpu, GpuError, Lobes};

pub const WGSL: &str = include_str!("../../shaders/gather.wgsl");

pub struct Gather {
    kernels: ValRangeKernels,
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
        let kernels = ValRangeKernels::new(gpu, scene, module, "gather", entry, slots, tile_size)?;
        Ok(Self { kernels, tile_size })
    }

    /// Cover frames of up to `max_vals` VALs (see [`ValRangeKernels::fit`]).
    pub fn fit(&mut self, gpu: &Gpu, scene: &GpuScene, max_vals: u32) -> Result<(), GpuError> {
        self.kernels.fit(gpu, scene, max_vals)
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
        let n = scene.flat.sparse_count();
        self.kernels.dispatch(gpu, encoder, scene, &resources, [groups(n, self.tile_size), 1, 1], span);
    }
}

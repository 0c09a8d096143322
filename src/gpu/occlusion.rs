//! Disc-occluder visibility (`shaders/occlusion.wgsl`, DESIGN.md §4 step 3): scales the
//! gathered irradiance of every sparse point by the fraction of its light sphere that the other
//! sparse points, as discs, leave visible. Rust twins: `reference::occlusion`.

use super::kernel::{Kernel, Slot, groups};
use super::scene::GpuScene;
use super::shader::TILE_SIZE;
use super::timing::Span;
use super::{Gpu, GpuError, Lobes};

pub const WGSL: &str = include_str!("../../shaders/occlusion.wgsl");

pub struct Occlusion {
    kernel: Kernel,
}

impl Occlusion {
    /// `product` selects `1 - prod(1 - o_i)` over the paper's `clamp(sum o_i)`.
    pub fn new(gpu: &Gpu, scene: &GpuScene, glossy: bool, product: bool) -> Result<Self, GpuError> {
        let source = source(product);
        let slots = [Slot::Storage, Slot::StorageReadWrite];
        let kernel = Kernel::pass(gpu, scene, "occlusion", &source, &slots, &[Slot::StorageReadWrite], glossy)?;
        Ok(Self { kernel })
    }

    /// Scale `gathered` (both lobes) in place.
    pub fn record(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        scene: &GpuScene,
        gathered: &Lobes,
        span: Option<Span<'_>>,
    ) {
        let mut resources = vec![scene.sparse_points.as_entire_binding(), gathered.diffuse.as_entire_binding()];
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

/// The pass's WGSL with its combination rule.
pub fn source(product: bool) -> String {
    format!("const OCCLUSION_PRODUCT: bool = {product};\n{WGSL}")
}

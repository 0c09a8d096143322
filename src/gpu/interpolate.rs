//! Per-vertex interpolation (`shaders/interpolate.wgsl`, DESIGN.md §4 step 4). Rust twins:
//! `reference::interpolation_weights`, `reference::interpolate_lights`.

use super::kernel::{Kernel, Slot, groups};
use super::scene::GpuScene;
use super::shader::WORKGROUP_SIZE;
use super::timing::Span;
use super::{Gpu, GpuError, Lobes};

pub const WGSL: &str = include_str!("../../shaders/interpolate.wgsl");

/// The pass's WGSL for `neighbours` sparse points per vertex.
pub fn source(neighbours: u32) -> String {
    format!("const NEIGHBOURS: u32 = {neighbours}u;\n{WGSL}")
}

pub struct Interpolate {
    kernel: Kernel,
}

impl Interpolate {
    pub fn new(gpu: &Gpu, scene: &GpuScene, glossy: bool) -> Result<Self, GpuError> {
        let kernel = Kernel::pass(
            gpu,
            scene,
            "interpolate",
            &source(scene.flat.neighbours),
            &[Slot::Storage, Slot::Storage, Slot::Storage, Slot::StorageReadWrite],
            &[Slot::Storage, Slot::StorageReadWrite],
            glossy,
        )?;
        Ok(Self { kernel })
    }

    /// Interpolate per-sparse-point `sparse` lights to per-vertex `vertex` lights.
    pub fn record(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        scene: &GpuScene,
        sparse: &Lobes,
        vertex: &Lobes,
        span: Option<Span<'_>>,
    ) {
        let mut resources = vec![
            scene.sparse_points.as_entire_binding(),
            scene.vertex_neighbours.as_entire_binding(),
            sparse.diffuse.as_entire_binding(),
            vertex.diffuse.as_entire_binding(),
        ];
        if let (Some(s), Some(v)) = (&sparse.glossy, &vertex.glossy) {
            resources.extend([s.as_entire_binding(), v.as_entire_binding()]);
        }
        let group = self.kernel.bind(gpu, &resources);
        let n = scene.flat.vertex_count();
        self.kernel.dispatch(
            encoder,
            &group,
            &scene.bind_group,
            [groups(n, WORKGROUP_SIZE), 1, 1],
            span.as_ref().map(Span::compute),
        );
    }
}

//! Disc-occluder visibility (`disks.wgsl`, docs/design.md §4 step 3, the paper's §3.3): scales the
//! gathered irradiance of every sparse point by the fraction of its light sphere that the other
//! sparse points, as discs, leave visible. Rust twin: [`twin`].

pub mod twin;

use super::{Mode, SparseVisibility, VisibilitySettings};
use crate::scene::OcclusionRule;
use crate::gpu::pass::{Entry, Kernels, PassDesc, buffer, read, read_write, with_lobes};
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::TILE_SIZE;
use crate::gpu::shader::Wgsl;
use crate::gpu::timing::Span;
use crate::gpu::{Gpu, GpuError, Lobes};

pub const WGSL: &str = include_str!("disks.wgsl");
/// The discs' lookup of a light sphere, shared with the second bounce's `bounce2_occlusion`.
pub const LOOKUP_WGSL: &str = include_str!("disk_lookup.wgsl");

/// The combination rule and the discs' lookup, for a pass that binds `sparse_points`.
pub fn lookup(product: bool) -> String {
    Wgsl::new().bool("OCCLUSION_PRODUCT", product).include(LOOKUP_WGSL).finish()
}

/// The pass's own WGSL with its combination rule.
pub fn body(product: bool) -> String {
    Wgsl::new().include(&lookup(product)).include(WGSL).finish()
}

/// Every compute pass of the mode, for the layout test (`crate::gpu::passes`).
pub const PASSES: &[&PassDesc] = &[&PASS];

/// One invocation per sparse point; occluders stream through workgroup memory in tiles.
pub const PASS: PassDesc = PassDesc {
    label: "occlusion",
    bindings: &[read("sparse_points"), read_write("gathered_diffuse"), read_write("gathered_glossy")],
    entries: &[Entry::first("main", 2), Entry::first("main_glossy", 3)],
    workgroup: [TILE_SIZE, 1, 1],
    default_source: |textured| PASS.source(&body(false), textured),
};

/// The `"disks"` visibility mode for a scene: disc occluders combined as `settings.rule` says.
pub fn mode(gpu: &Gpu, scene: &GpuScene, settings: &VisibilitySettings, glossy: bool) -> Result<Mode, GpuError> {
    Ok(Mode::Scale(Box::new(Disks::new(gpu, scene, glossy, settings.rule == OcclusionRule::Product)?)))
}

pub struct Disks {
    kernel: Kernels,
}

impl Disks {
    /// `product` selects `1 - prod(1 - o_i)` over the paper's `clamp(sum o_i)`.
    pub fn new(gpu: &Gpu, scene: &GpuScene, glossy: bool, product: bool) -> Result<Self, GpuError> {
        Ok(Self { kernel: Kernels::lobes(gpu, scene, &PASS, &body(product), glossy)? })
    }
}

impl SparseVisibility for Disks {
    fn stage(&self) -> &'static str {
        PASS.label
    }

    fn record(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        scene: &GpuScene,
        gathered: &Lobes,
        span: Option<Span<'_>>,
    ) {
        let resources = with_lobes(
            vec![buffer("sparse_points", &scene.sparse_points)],
            &[(gathered, "gathered_diffuse", "gathered_glossy")],
        );
        let n = scene.flat.sparse_count();
        self.kernel.run(gpu, encoder, scene, &resources, [n, 1, 1], span);
    }
}

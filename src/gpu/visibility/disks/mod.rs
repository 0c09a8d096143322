//! Disc-occluder visibility (`disks.wgsl`, docs/design.md §4 step 3, the paper's §3.3): scales the
//! gathered irradiance of every sparse point by the fraction of its light sphere that the other
//! sparse points, as discs, leave visible. The pass takes the sparse points in a Morton order,
//! in groups of [`DISC_GROUP`] with their bounds ([`DiscOccluders`], uploaded with the scene),
//! and a workgroup skips every group none of its receivers can be occluded by. Rust twin:
//! [`twin`].

pub mod twin;

use super::{Mode, SparseVisibility, VisibilitySettings};
use crate::scene::OcclusionRule;
use crate::gpu::pass::{Entry, Kernels, PassDesc, buffer, read, read_write, with_lobes};
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::TILE_SIZE;
use crate::gpu::shader::Wgsl;
use crate::gpu::timing::Span;
use crate::gpu::{Gpu, GpuError, Lobes};
use crate::twin::raw::RawSparsePoint;
use glam::Vec3;

pub const WGSL: &str = include_str!("disks.wgsl");
/// The light sphere, the projected squares and one disc's occlusion, shared by both lookups.
pub const TERMS_WGSL: &str = include_str!("disc_terms.wgsl");
/// The discs' lookup of a light sphere over every sparse point, for the second bounce's
/// `bounce2_occlusion`.
pub const LOOKUP_WGSL: &str = include_str!("disk_lookup.wgsl");

/// Discs per group of the `occlusion` pass: a tile of [`TILE_SIZE`] holds several, so that a
/// receiver walks only the groups it needs of a tile its workgroup loads.
pub const DISC_GROUP: u32 = 16;
const _: () = assert!(TILE_SIZE.is_multiple_of(DISC_GROUP) && TILE_SIZE / DISC_GROUP <= 32);

/// The combination rule and the discs' terms.
fn terms(product: bool) -> String {
    Wgsl::new().bool("OCCLUSION_PRODUCT", product).include(TERMS_WGSL).finish()
}

/// The combination rule and the discs' lookup, for a pass that binds `sparse_points`.
pub fn lookup(product: bool) -> String {
    Wgsl::new().include(&terms(product)).include(LOOKUP_WGSL).finish()
}

/// The pass's own WGSL with its combination rule and its groups' size and slack.
pub fn body(product: bool) -> String {
    Wgsl::new()
        .f32("GROUP_CULL_SLACK", twin::GROUP_CULL_SLACK)
        .u32("DISC_GROUP", DISC_GROUP)
        .include(&terms(product))
        .include(WGSL)
        .finish()
}

/// WGSL `Occluder`: a sparse point as a disc, with its index.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct RawOccluder {
    pub position: [f32; 3],
    pub radius: f32,
    pub normal: [f32; 3],
    pub index: u32,
}

/// WGSL `DiscGroup`: the bounds of [`DISC_GROUP`] consecutive occluders.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct RawDiscGroup {
    pub centre: [f32; 3],
    pub radius: f32,
    pub largest_disc: f32,
    pub _pad: [f32; 3],
}

/// The sparse points as the `occlusion` pass reads them: in a Morton order, cut into groups of
/// [`DISC_GROUP`] with their bounds.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DiscOccluders {
    pub occluders: Vec<RawOccluder>,
    pub groups: Vec<RawDiscGroup>,
}

impl DiscOccluders {
    pub fn new(points: &[RawSparsePoint]) -> Self {
        let discs: Vec<twin::Disc> = points
            .iter()
            .map(|p| twin::Disc { position: p.position.into(), normal: p.normal.into(), radius: p.occluder_radius })
            .collect();
        let positions: Vec<Vec3> = discs.iter().map(|d| d.position).collect();
        let order = twin::morton_order(&positions);
        let occluders = order
            .iter()
            .map(|&i| {
                let p = &points[i as usize];
                RawOccluder { position: p.position, radius: p.occluder_radius, normal: p.normal, index: i }
            })
            .collect();
        let groups = twin::disc_groups(&discs, &order, DISC_GROUP as usize)
            .into_iter()
            .map(|g| RawDiscGroup {
                centre: g.centre.into(),
                radius: g.radius,
                largest_disc: g.largest_disc,
                _pad: [0.0; 3],
            })
            .collect();
        DiscOccluders { occluders, groups }
    }
}

/// Every compute pass of the mode, for the layout test (`crate::gpu::passes`).
pub const PASSES: &[&PassDesc] = &[&PASS];

/// One invocation per sparse point, in Morton order; the groups of occluders a receiver of the
/// workgroup needs stream through workgroup memory.
pub const PASS: PassDesc = PassDesc {
    label: "occlusion",
    bindings: &[
        read("disc_occluders"),
        read("disc_groups"),
        read_write("gathered_diffuse"),
        read_write("gathered_glossy"),
    ],
    entries: &[Entry::first("main", 3), Entry::first("main_glossy", 4)],
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
            vec![buffer("disc_occluders", &scene.disc_occluders), buffer("disc_groups", &scene.disc_groups)],
            &[(gathered, "gathered_diffuse", "gathered_glossy")],
        );
        let n = scene.flat.sparse_count();
        self.kernel.run(gpu, encoder, scene, &resources, [n, 1, 1], span);
    }
}

//! The second bounce of indirect light (paper 004 §4.1, imperfect reflective shadow maps), one
//! technique run after the first bounce's VAL sources and before the indirect technique: points
//! spread over the meshes by area (`twin::bounce::bounce_points`, at build) are lit by the
//! first-bounce VALs and become candidate VALs (`bounce2_points`, `bounce_points.wgsl`); then
//! `settings.second_bounce.vals` of them are drawn by flux, stratified (the imperfect shadow
//! maps' draw, `visibility/ism/flux_draw.wgsl`), and appended to the frame's VALs with their
//! flux divided by their probability (`bounce2_vals`, `bounce_draw.wgsl`). Every later stage
//! (the sparse method with its visibility mode, the brute force) lights with them unchanged.
//!
//! **Visibility at the bounce points.** With the sparse method's visibility mode `ism` or
//! `clusters` (a group visibility mode), the bounce points see the first bounce's VALs through
//! that mode's maps, as paper 004's IRSMs light the second-bounce VPLs through the first-bounce
//! VPLs' imperfect maps. The order of the stages:
//!
//! 1. the mode's grouping and maps over the first bounce's VALs alone (the VALs appended so far:
//!    `bounce2_ism_sampling`, `bounce2_ism_splat`, `bounce2_ism_pull_push`, or
//!    `bounce2_clustering`, `bounce2_cluster_shadow_maps`), an instance of its own
//!    ([`Clusters`] with [`Receivers::BouncePoints`]);
//! 2. `bounce2_visibility`: its lookup at every (bounce point, group), the sparse points' lookup
//!    (`bounce_visibility.wgsl`);
//! 3. `bounce2_points` scales each first-bounce VAL by its group's entry at the point
//!    (`visibility/group.wgsl`), then `bounce2_vals` draws as before;
//! 4. the sparse method's own instance of the mode then groups *every* VAL of the frame, second
//!    bounce included, draws their maps and looks them up at the sparse points for the gather,
//!    as with one bounce.
//!
//! The maps cannot be built once for both: the sparse points' groups must cover the
//! second-bounce VALs, which exist only once the bounce points are lit; and giving the
//! second-bounce VALs the first bounce's groups instead would shadow a VAL on the ceiling from a
//! map centred on the lit wall. The paper also renders two sets (IRSMs of the first-bounce VPLs,
//! then ISMs of all VPLs); the cost is the mode's stages twice, minus the lookup's share for
//! the fewer bounce points (measured in docs/measurements/two-bounces.md).
//!
//! **With `disks`** (a scaling mode: no per-VAL visibility to give a point), each point gets
//! what a sparse point gets: `bounce2_points` also keeps its light sphere's moments (the
//! gather's luminance-weighted first and second moments of the VAL positions,
//! `bounce_moments.wgsl`), and `bounce2_occlusion` (`bounce_occlusion.wgsl`) scales its
//! candidate by the sparse points' discs' visibility of that sphere (the sparse points'
//! `occlusion` lookup, `visibility/disks/disk_lookup.wgsl`, with the scene's rule).
//!
//! With visibility off, and for the brute force (the no-visibility reference), the candidates
//! see the first bounce's VALs unoccluded. The CPU exact reference makes its own second bounce through shadow
//! rays (`twin::bounce::candidate_vals` with its BVH). Built only when `settings.bounces` is 2.
//! Rust twin: [`crate::twin::bounce`].

use crate::gpu::pass::{
    Binding, Entry, Kernel, Kernels, PassDesc, buffer, depth_texture, module_from_source, read, read_write,
};
use crate::gpu::raw::{RawGathered, RawVal};
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::Wgsl;
use crate::gpu::shader::{TILE_SIZE, VAL_TILES, WORKGROUP_SIZE};
use crate::gpu::technique::{Frame, Technique};
use crate::gpu::timing::Recorder;
use crate::gpu::visibility::clusters::{self, Clusters, Receivers, SceneScale, StageNames};
use crate::gpu::visibility::ism::{self, FLUX_DRAW_WGSL, SAMPLE_BLOCK};
use crate::gpu::visibility::{GroupVisibility, VisibilitySettings, disks, group_wgsl};
use crate::gpu::{Gpu, GpuError};
use crate::scene::{ClusterSettings, IsmSettings, Occlusion, OcclusionRule, SecondBounceSettings};
use crate::twin::bounce::{self as twin, BouncePoint};
use bytemuck::{Pod, Zeroable};
use glam::Vec3;

pub const POINT_WGSL: &str = include_str!("bounce_point.wgsl");
pub const POINTS_WGSL: &str = include_str!("bounce_points.wgsl");
pub const VISIBILITY_WGSL: &str = include_str!("bounce_visibility.wgsl");
pub const DRAW_WGSL: &str = include_str!("bounce_draw.wgsl");
pub const MOMENTS_WGSL: &str = include_str!("bounce_moments.wgsl");
pub const OCCLUSION_WGSL: &str = include_str!("bounce_occlusion.wgsl");

/// Stage names in the frame's timings.
pub const POINTS_STAGE: &str = "bounce2_points";
pub const DRAW_STAGE: &str = "bounce2_vals";
pub const VISIBILITY_STAGE: &str = "bounce2_visibility";
/// The disks' occlusion of the candidates (`disks` only).
pub const OCCLUSION_STAGE: &str = "bounce2_occlusion";

/// The stages of the first bounce's groups and maps for the bounce points (the sparse method's
/// own instance of the mode keeps the mode's names).
pub const STAGES: StageNames = StageNames {
    clustering: "bounce2_clustering",
    shadow_maps: "bounce2_cluster_shadow_maps",
    ism_sampling: "bounce2_ism_sampling",
    ism_splat: "bounce2_ism_splat",
    ism_pull_push: "bounce2_ism_pull_push",
    cluster_visibility: VISIBILITY_STAGE,
    ism_visibility: VISIBILITY_STAGE,
};

/// WGSL `BouncePoint`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RawBouncePoint {
    pub triangle: u32,
    pub u: f32,
    pub v: f32,
    pub area: f32,
}

impl From<&BouncePoint> for RawBouncePoint {
    fn from(p: &BouncePoint) -> Self {
        Self { triangle: p.triangle, u: p.barycentrics.x, v: p.barycentrics.y, area: p.area }
    }
}

/// The points pass's own WGSL: the VAL tiles, the point, `val_visibility` for `groups`
/// groups (or none), `store_moments` (keeping the light spheres' moments with `moments`, for
/// `disks`; else dropping them), then `bounce_points.wgsl`.
pub fn points_body(groups: Option<u32>, moments: bool) -> String {
    let store = match moments {
        true => MOMENTS_WGSL,
        false => "fn store_moments(index: u32, e: vec3<f32>, w: f32, l: vec3<f32>, l2: vec3<f32>) {}\n",
    };
    Wgsl::new()
        .include(VAL_TILES)
        .include(POINT_WGSL)
        .include(&group_wgsl(groups, 4))
        .include(store)
        .include(POINTS_WGSL)
        .finish()
}

/// The bindings of [`GROUPED_POINTS`]; [`POINTS`] has the first four (no group table).
const POINTS_BINDINGS: &[Binding] = &[
    read("bounce_points"),
    read("vals"),
    read("val_count"),
    read_write("candidates"),
    read("group_of_val"),
    read("group_visibility"),
];

/// Every bounce point lit by every first-bounce VAL: one invocation per point, the VALs in
/// tiles of `TILE_SIZE` (and in ranges on CPU adapters).
pub const POINTS: PassDesc = PassDesc {
    label: POINTS_STAGE,
    bindings: POINTS_BINDINGS.split_at(4).0,
    entries: &[Entry::first("main", 4)],
    workgroup: [TILE_SIZE, 1, 1],
    default_source: |textured| POINTS.source(&points_body(None, false), textured),
};

/// [`POINTS`] through the first bounce's groups (`clusters` or `ism`): plus the group table.
pub const GROUPED_POINTS: PassDesc = PassDesc {
    bindings: POINTS_BINDINGS,
    entries: &[Entry::first("main", 6)],
    default_source: |textured| GROUPED_POINTS.source(&points_body(Some(64), false), textured),
    ..POINTS
};

/// [`POINTS`] with `disks`: plus the points' irradiance and light-sphere moments.
pub const DISK_POINTS: PassDesc = PassDesc {
    bindings: &[
        read("bounce_points"),
        read("vals"),
        read("val_count"),
        read_write("candidates"),
        read_write("bounce_moments"),
    ],
    entries: &[Entry::first("main", 5)],
    default_source: |textured| DISK_POINTS.source(&points_body(None, true), textured),
    ..POINTS
};

/// With `disks`: each candidate scaled by the sparse points' discs' visibility of its point's
/// light sphere. One invocation per point; the discs stream through workgroup memory in tiles.
pub const OCCLUSION: PassDesc = PassDesc {
    label: OCCLUSION_STAGE,
    bindings: &[read("bounce_points"), read("sparse_points"), read("bounce_moments"), read_write("candidates")],
    entries: &[Entry::first("main", 4)],
    workgroup: [TILE_SIZE, 1, 1],
    default_source: |textured| OCCLUSION.source(&occlusion_body(true), textured),
};

/// The occlusion pass's WGSL: the point, the discs' lookup with the combination rule
/// (`product`, else `sum`), then `bounce_occlusion.wgsl`.
fn occlusion_body(product: bool) -> String {
    Wgsl::new().include(POINT_WGSL).include(&disks::lookup(product)).include(OCCLUSION_WGSL).finish()
}

/// The second bounce's disks: the points' moments and the occlusion pass.
struct BounceDisks {
    kernel: Kernel,
    /// `array<Gathered>`, one per point: irradiance and light-sphere moments.
    moments: wgpu::Buffer,
}

impl BounceDisks {
    fn new(gpu: &Gpu, scene: &GpuScene, product: bool, points: usize) -> Result<Self, GpuError> {
        let source = OCCLUSION.source(&occlusion_body(product), scene.textured());
        let module = module_from_source(gpu, OCCLUSION.label, source)?;
        let kernel = Kernel::build(gpu, scene, &OCCLUSION, &module, OCCLUSION.entry("main"), &[], OCCLUSION.workgroup)?;
        let moments = gpu.storage_buffer_sized::<RawGathered>("bounce2_points.bounce_moments", points.max(1))?;
        Ok(Self { kernel, moments })
    }
}

/// The lookup at the bounce points, reading rasterised maps (`clusters`).
pub const VISIBILITY: PassDesc = PassDesc {
    label: VISIBILITY_STAGE,
    bindings: &[read("bounce_points"), read("clusters"), depth_texture("shadow_atlas"), read_write("group_visibility")],
    entries: &[Entry::first("main", 4)],
    workgroup: [WORKGROUP_SIZE, 1, 1],
    default_source: |textured| {
        let head = clusters::header(&ClusterSettings::default(), SceneScale { diagonal: 1.0 });
        VISIBILITY.source(&visibility_body(&head, false), textured)
    },
};

/// The lookup at the bounce points, reading imperfect shadow maps (`ism`, or `clusters` with
/// `shadow_maps: "ism"`).
pub const ISM_VISIBILITY: PassDesc = PassDesc {
    bindings: &[read("bounce_points"), read("clusters"), read("ism_atlas"), read_write("group_visibility")],
    default_source: |textured| {
        let head = ism::header(&IsmSettings::default(), SceneScale { diagonal: 1.0 });
        ISM_VISIBILITY.source(&visibility_body(&head, true), textured)
    },
    ..VISIBILITY
};

/// The lookup pass's WGSL after `head` (the mode's header), reading `imperfect` maps or
/// rasterised ones.
fn visibility_body(head: &str, imperfect: bool) -> String {
    clusters::lookup_pass_body(head, imperfect, [1, 2], &[POINT_WGSL, VISIBILITY_WGSL])
}

/// The lookup pass at the bounce points and its WGSL after `head`, for `imperfect` maps or
/// rasterised ones ([`Clusters`] with [`Receivers::BouncePoints`] builds it).
pub fn visibility_pass(head: &str, imperfect: bool) -> (&'static PassDesc, String) {
    (if imperfect { &ISM_VISIBILITY } else { &VISIBILITY }, visibility_body(head, imperfect))
}

/// The draw: the flux sums over the candidates (the draw's `vals`), the draw appending to the
/// frame's VALs, and the count.
pub const DRAW: PassDesc = PassDesc {
    label: DRAW_STAGE,
    bindings: &[
        read("vals"),
        read("val_count"),
        read_write("flux_prefix"),
        read_write("all_vals"),
        read_write("all_val_count"),
    ],
    entries: &[
        Entry::first("flux_blocks", 3),
        Entry::first("flux_scan", 3),
        Entry::first("bounce_sample", 5),
        Entry { name: "bounce_count", bindings: 5, except: &["vals", "val_count", "flux_prefix", "all_vals"] },
    ],
    workgroup: [WORKGROUP_SIZE, 1, 1],
    default_source: |textured| DRAW.source(&draw_body(&SecondBounceSettings::default(), 1.0), textured),
};

/// The draw's WGSL: its constants, the shared flux draw, then `bounce_draw.wgsl`.
fn draw_body(settings: &SecondBounceSettings, area: f32) -> String {
    Wgsl::new()
        .u32("SAMPLE_BLOCK", SAMPLE_BLOCK)
        .u32("SECOND_BOUNCE_VALS", settings.vals)
        .f32("SECOND_BOUNCE_AREA", area)
        .include(FLUX_DRAW_WGSL)
        .include(DRAW_WGSL)
        .finish()
}

/// The second bounce's passes, its points and the candidates between them.
pub struct SecondBounce {
    pub settings: SecondBounceSettings,
    /// The points as built (world space of the scene as uploaded; they follow its vertices).
    pub points: Vec<BouncePoint>,
    /// Area (m²) of each drawn VAL.
    pub drawn_area: f32,
    /// The visibility the points see the first bounce through: `Some` for the sparse method
    /// with `clusters`, `ism` or `disks`, else `None` (unoccluded).
    visibility_key: Option<VisibilitySettings>,
    /// The first bounce's groups and maps, looked up at the points (with `visibility_key`).
    visibility: Option<Clusters>,
    /// With `disks` (`visibility_key`): the points' light spheres and their occlusion.
    disks: Option<BounceDisks>,
    light_points: Kernels,
    blocks: Kernel,
    scan: Kernel,
    sample: Kernel,
    count: Kernel,
    bounce_points: wgpu::Buffer,
    /// `array<Val>`, one per point: the candidates.
    pub candidates: wgpu::Buffer,
    /// One `u32`: how many candidates (the draw's `val_count`).
    candidate_count: wgpu::Buffer,
    /// `array<f32>`: block sums, then their running sums.
    flux_prefix: wgpu::Buffer,
}

impl SecondBounce {
    pub fn new(gpu: &Gpu, scene: &GpuScene, settings: SecondBounceSettings, seed: u64) -> Result<Self, GpuError> {
        let flat = &scene.flat;
        let positions: Vec<Vec3> = flat.vertices.iter().map(|v| Vec3::from(v.position)).collect();
        let points = twin::bounce_points(&positions, &flat.indices, settings.points, seed);
        let drawn_area = twin::drawn_area(&points);
        let raw: Vec<RawBouncePoint> = points.iter().map(RawBouncePoint::from).collect();
        let n = raw.len().max(1);
        let empty = [RawBouncePoint::default()];
        let textured = scene.textured();
        let light_points = points_kernels(gpu, scene, None, false)?;
        let module = module_from_source(gpu, DRAW.label, DRAW.source(&draw_body(&settings, drawn_area), textured))?;
        let kernel = |name: &str| Kernel::build(gpu, scene, &DRAW, &module, DRAW.entry(name), &[], DRAW.workgroup);
        let blocks = (raw.len() as u32).div_ceil(SAMPLE_BLOCK).max(1) as usize;
        Ok(Self {
            settings,
            drawn_area,
            visibility_key: None,
            visibility: None,
            disks: None,
            light_points,
            blocks: kernel("flux_blocks")?,
            scan: kernel("flux_scan")?,
            sample: kernel("bounce_sample")?,
            count: kernel("bounce_count")?,
            bounce_points: gpu.storage_buffer(
                "bounce2_points.bounce_points",
                if raw.is_empty() { &empty[..] } else { &raw },
                wgpu::BufferUsages::empty(),
            )?,
            candidates: gpu.storage_buffer_sized::<RawVal>("bounce2_points.candidates", n)?,
            candidate_count: gpu.storage_buffer(
                "bounce2_vals.candidate_count",
                &[raw.len() as u32],
                wgpu::BufferUsages::empty(),
            )?,
            flux_prefix: gpu.storage_buffer_sized::<f32>("bounce2_vals.flux_prefix", blocks + 1)?,
            points,
        })
    }

    /// See the first bounce through `visibility` from the next frame on: `Some` (a `clusters`
    /// or `ism` mode, for the sparse method) builds the first bounce's groups, maps and lookup
    /// at the points; `Some` with `disks` keeps the points' light spheres and occludes them by
    /// the sparse points' discs; `None` (or `off`) lights the points unoccluded. Nothing is
    /// rebuilt when unchanged; call [`SecondBounce::fit`] after.
    pub fn set_visibility(
        &mut self,
        gpu: &Gpu,
        scene: &GpuScene,
        visibility: Option<VisibilitySettings>,
    ) -> Result<(), GpuError> {
        if visibility == self.visibility_key {
            return Ok(());
        }
        let receivers = Receivers::BouncePoints { count: self.points.len() as u32 };
        (self.visibility, self.disks) = (None, None);
        match &visibility {
            Some(v) if v.mode == Occlusion::Disks => {
                let product = v.rule == OcclusionRule::Product;
                self.disks = Some(BounceDisks::new(gpu, scene, product, self.points.len())?);
            }
            Some(v) => self.visibility = Clusters::for_receivers(gpu, scene, v, receivers, STAGES)?,
            None => {}
        }
        let groups = self.visibility.as_ref().map(|v| v.table().groups);
        self.light_points = points_kernels(gpu, scene, groups, self.disks.is_some())?;
        let built = self.visibility.is_some() || self.disks.is_some();
        self.visibility_key = if built { visibility } else { None };
        Ok(())
    }

    /// The first bounce's groups the points see it through, when [`SecondBounce::set_visibility`]
    /// gave a group visibility mode (tests and tools read them back).
    pub fn visibility(&self) -> Option<&Clusters> {
        self.visibility.as_ref()
    }

    /// Cover frames of up to `max_vals` first-bounce VALs.
    pub fn fit(&mut self, gpu: &Gpu, scene: &GpuScene, max_vals: u32) -> Result<(), GpuError> {
        if let Some(v) = &mut self.visibility {
            v.fit(gpu, max_vals)?;
        }
        self.light_points.fit(gpu, scene, max_vals)
    }

    /// With `disks`: each point's irradiance and light-sphere moments of the last frame (for
    /// the twins); `None` otherwise.
    pub fn read_moments(&self, gpu: &Gpu) -> Result<Option<Vec<RawGathered>>, GpuError> {
        let Some(d) = &self.disks else {
            return Ok(None);
        };
        Ok(Some(gpu.read_buffer::<RawGathered>(&d.moments, self.points.len())?))
    }

    /// The candidates of the last frame (for the twins).
    pub fn read_candidates(&self, gpu: &Gpu) -> Result<Vec<crate::twin::Val>, GpuError> {
        Ok(gpu.read_buffer::<RawVal>(&self.candidates, self.points.len())?.iter().map(Into::into).collect())
    }
}

/// The points pass, unoccluded, (with `groups`) through the first bounce's groups, or (with
/// `moments`, for `disks`) keeping the points' light spheres.
fn points_kernels(gpu: &Gpu, scene: &GpuScene, groups: Option<u32>, moments: bool) -> Result<Kernels, GpuError> {
    let desc = match (groups, moments) {
        (Some(_), _) => &GROUPED_POINTS,
        (None, true) => &DISK_POINTS,
        (None, false) => &POINTS,
    };
    let source = desc.source(&points_body(groups, moments), scene.textured());
    Kernels::val_ranges(gpu, scene, desc, source, desc.entry("main"), desc.workgroup, TILE_SIZE)
}

impl Technique for SecondBounce {
    fn stages(&self) -> Vec<&'static str> {
        let mut stages = self.visibility.as_ref().map_or_else(Vec::new, |v| v.stage_names());
        stages.push(POINTS_STAGE);
        if self.disks.is_some() {
            stages.push(OCCLUSION_STAGE);
        }
        stages.push(DRAW_STAGE);
        stages
    }

    fn record(&self, gpu: &Gpu, frame: &Frame<'_>, rec: &mut Recorder<'_>) -> Result<(), GpuError> {
        let (scene, vals) = (frame.scene, frame.vals);
        let points = self.points.len() as u32;
        // The first bounce's groups and maps (the VALs appended so far), looked up at the points.
        if let Some(v) = &self.visibility {
            v.record_at(gpu, frame, rec, buffer("bounce_points", &self.bounce_points), points)?;
        }
        let mut resources = vec![
            buffer("bounce_points", &self.bounce_points),
            buffer("vals", &vals.buffer),
            buffer("val_count", &vals.count),
            buffer("candidates", &self.candidates),
        ];
        let table = self.visibility.as_ref().map(|v| v.table());
        if let Some(t) = &table {
            resources.extend([buffer("group_of_val", t.group_of_val), buffer("group_visibility", t.visibility)]);
        }
        if let Some(d) = &self.disks {
            resources.push(buffer("bounce_moments", &d.moments));
        }
        rec.stage(POINTS_STAGE, |e, s| self.light_points.run(gpu, e, scene, &resources, [points, 1, 1], s))?;
        if let Some(d) = &self.disks {
            let group = d.kernel.bind(
                gpu,
                &[
                    buffer("bounce_points", &self.bounce_points),
                    buffer("sparse_points", &scene.sparse_points),
                    buffer("bounce_moments", &d.moments),
                    buffer("candidates", &self.candidates),
                ],
            );
            rec.stage(OCCLUSION_STAGE, |e, s| {
                let timestamps = s.as_ref().and_then(|s| s.compute_part(0, 1));
                d.kernel.dispatch(e, &group, scene, [points, 1, 1], timestamps);
            })?;
        }
        let all = [
            buffer("vals", &self.candidates),
            buffer("val_count", &self.candidate_count),
            buffer("flux_prefix", &self.flux_prefix),
            buffer("all_vals", &vals.buffer),
            buffer("all_val_count", &vals.count),
        ];
        let blocks = points.div_ceil(SAMPLE_BLOCK).max(1);
        let steps = [
            (&self.blocks, self.blocks.bind(gpu, &all[..3]), blocks),
            (&self.scan, self.scan.bind(gpu, &all[..3]), 1),
            (&self.sample, self.sample.bind(gpu, &all), self.settings.vals),
            (&self.count, self.count.bind(gpu, &all[4..]), 1),
        ];
        rec.stage(DRAW_STAGE, |e, s| {
            for (part, (kernel, group, invocations)) in steps.iter().enumerate() {
                let timestamps = s.as_ref().and_then(|s| s.compute_part(part, steps.len()));
                kernel.dispatch(e, group, scene, [*invocations, 1, 1], timestamps);
            }
        })
    }
}

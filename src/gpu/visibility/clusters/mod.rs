//! Clustered visibility (papers 000 §4-5 and 001), a group visibility mode
//! ([`super::GroupVisibility`]): every frame the VALs are grouped by k-means on position and
//! normal angle (`clustering.wgsl`, started from the previous frame's centres), every cluster
//! gets one paraboloid shadow map around its normal (`shadow_maps.wgsl`, all maps in one depth
//! atlas), and every (sparse point, cluster) pair a soft-shadow visibility
//! (`cluster_visibility.wgsl`: PCSS, PCF or hard), which the gather applies to each of the
//! cluster's VALs. Rust twin: [`twin`].
//!
//! The lookup's receivers are the sparse points for the sparse method's mode, and for the
//! instances other techniques build ([`Receivers`]) the second bounce's points or the camera's
//! pixels; each instance names its stages ([`StageNames`]) so that two can run in one frame.

pub mod rays;
pub mod settings;
mod shadow_maps;
pub mod twin;

pub(crate) use shadow_maps::ShadowMaps;

use super::ism;
use super::{GroupTable, GroupVisibility, Mode, VisibilitySettings};
use crate::gpu::lights::bounce;
use crate::gpu::pass::{Entry, Kernel, PassDesc, buffer, depth_texture, module_from_source, read, read_write, view};
use crate::gpu::references::brute_force;
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::WORKGROUP_SIZE;
use crate::gpu::shader::Wgsl;
use crate::gpu::technique::Frame;
use crate::gpu::timing::Recorder;
use crate::gpu::{Gpu, GpuError};
use crate::scene::{ClusterSettings, IsmSettings, ShadowMapSource, SoftShadows};
use bytemuck::{Pod, Zeroable};
use glam::Vec3;

const PARABOLOID: &str = include_str!("paraboloid.wgsl");
pub const CLUSTERING_WGSL: &str = include_str!("clustering.wgsl");
pub const SHADOW_MAPS_WGSL: &str = include_str!("shadow_maps.wgsl");
/// The visibility pass: the lookup (`cluster_visibility.wgsl`), then its entry point.
pub const VISIBILITY_WGSL: &str =
    concat!(include_str!("cluster_visibility.wgsl"), include_str!("cluster_visibility_main.wgsl"));
/// The soft-shadow lookup alone (binding 1 `clusters`, binding 2 the maps), for other passes.
pub const VISIBILITY_LOOKUP_WGSL: &str = include_str!("cluster_visibility.wgsl");
/// The rasterised atlas as the visibility pass reads it (`map_depth`).
pub const RASTER_DEPTH_WGSL: &str = include_str!("raster_depth.wgsl");

/// VALs per block of the k-means update's partial sums (one invocation per cluster and block
/// loops over them: far under llvmpipe's loop limit).
pub const PARTIAL_BLOCK: u32 = 256;
// The atlas is rasterised by [`crate::gpu::raster::scene_raster_pipeline`], so it has its depth format.

/// Stage names in the frame's timings.
pub const CLUSTERING_STAGE: &str = "clustering";
pub const SHADOW_MAPS_STAGE: &str = "cluster_shadow_maps";

/// WGSL `Cluster`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RawCluster {
    pub position: [f32; 3],
    pub count: f32,
    pub normal: [f32; 3],
    pub radius: f32,
}

impl From<&RawCluster> for twin::Cluster {
    fn from(c: &RawCluster) -> Self {
        Self { position: c.position.into(), count: c.count, normal: c.normal.into(), radius: c.radius }
    }
}

/// WGSL `ClusterSums`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RawClusterSums {
    pub offset: [f32; 3],
    pub count: f32,
    pub normal: [f32; 3],
    pub offset_sq: f32,
}

/// The scene-dependent length of the mode, the meshes' bounding diagonal: 1 / it scales the
/// clustering distance, and the rasterised maps store distances in units of it
/// ([`twin::encode_map_depth`]: every distance from 0 to infinity, since the cluster centres are
/// the VALs', which may lie anywhere, e.g. metres away from a small virtual object in a real room).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneScale {
    pub diagonal: f32,
}

impl SceneScale {
    pub fn of(scene: &GpuScene) -> Self {
        let (lo, hi) = scene.flat.vertices.iter().fold((Vec3::MAX, Vec3::MIN), |(lo, hi), v| {
            let p = Vec3::from(v.position);
            (lo.min(p), hi.max(p))
        });
        let diagonal = (hi - lo).length();
        Self { diagonal: if diagonal.is_finite() && diagonal > 0.0 { diagonal } else { 1.0 } }
    }

    pub fn kmeans(&self, settings: &ClusterSettings) -> twin::KmeansParams {
        twin::KmeansParams { position_scale: 1.0 / self.diagonal, normal_weight: settings.normal_weight }
    }
}

/// The constants every shader of the mode starts with, then `paraboloid.wgsl`; the rasterised
/// maps hold exact depths per texel, so no slope-scaled bias.
pub fn header(settings: &ClusterSettings, scale: SceneScale) -> String {
    header_with_slope_bias(settings, scale, 0.0)
}

/// [`header`] with `slope_bias_texels` of slope-scaled bias (`twin::slope_bias`).
pub fn header_with_slope_bias(settings: &ClusterSettings, scale: SceneScale, slope_bias_texels: f32) -> String {
    header_focused(settings, scale, slope_bias_texels, false)
}

/// [`header_with_slope_bias`], with `focus` the maps focused on the meshes' bounding sphere
/// (`twin::map_frame`), which the clusters buffer then holds after its clusters ([`Clusters`]).
pub fn header_focused(settings: &ClusterSettings, scale: SceneScale, slope_bias_texels: f32, focus: bool) -> String {
    let soft = match settings.soft {
        SoftShadows::Pcss => 0,
        SoftShadows::Pcf => 1,
        SoftShadows::Hard => 2,
    };
    Wgsl::new()
        .u32("CLUSTER_COUNT", settings.count)
        .f32("POSITION_SCALE", 1.0 / scale.diagonal)
        .f32("NORMAL_WEIGHT", settings.normal_weight)
        .u32("PARTIAL_BLOCK", PARTIAL_BLOCK)
        .u32("MAP_RESOLUTION", settings.shadow_map_resolution)
        .u32("ATLAS_COLUMNS", settings.atlas_columns())
        .f32("DEPTH_SCALE", scale.diagonal)
        .u32("SOFT_PCSS", 0)
        .u32("SOFT_PCF", 1)
        .u32("SOFT_HARD", 2)
        .u32("SOFT_SHADOWS", soft)
        .u32("SHADOW_TAPS", twin::SHADOW_TAPS)
        .f32("PCF_RADIUS_TEXELS", twin::PCF_RADIUS_TEXELS)
        .f32("MAX_SHADOW_FILTER_ANGLE", twin::MAX_SHADOW_FILTER_ANGLE)
        .f32("CLUSTER_NEAR_FRACTION", twin::CLUSTER_NEAR_FRACTION)
        .f32("SHADOW_RELATIVE_BIAS", twin::SHADOW_RELATIVE_BIAS)
        .f32("SLOPE_BIAS_TEXELS", slope_bias_texels)
        .f32("MAX_SLOPE", twin::MAX_SLOPE)
        .f32("SHADOW_RASTER_SLACK", twin::SHADOW_RASTER_SLACK)
        .u32("FOCUS_BOUNDS", u32::from(focus))
        .f32("FOCUS_MARGIN", twin::FOCUS_MARGIN)
        .include(PARABOLOID)
        .finish()
}

fn default_header() -> String {
    header(&ClusterSettings::default(), SceneScale { diagonal: 1.0 })
}

/// Every compute pass of the mode, for the layout test (`crate::gpu::passes`).
pub const PASSES: &[&PassDesc] = &[&CLUSTERING, &VISIBILITY, &rays::MEMBERS, &rays::VISIBILITY];

/// k-means: four entry points over one set of bindings.
pub const CLUSTERING: PassDesc = PassDesc {
    label: CLUSTERING_STAGE,
    bindings: &[
        read("vals"),
        read("val_count"),
        read_write("clusters"),
        read_write("group_of_val"),
        read_write("cluster_partials"),
    ],
    entries: &[
        Entry::first("kmeans_seed", 3),
        Entry::first("kmeans_assign", 4),
        Entry::first("kmeans_partial", 5),
        Entry { name: "kmeans_reduce", bindings: 5, except: &["group_of_val"] },
    ],
    workgroup: [WORKGROUP_SIZE, 1, 1],
    default_source: |textured| {
        CLUSTERING.source(&Wgsl::new().include(&default_header()).include(CLUSTERING_WGSL).finish(), textured)
    },
};

/// Per (sparse point, cluster) visibility.
pub const VISIBILITY: PassDesc = PassDesc {
    label: "cluster_visibility",
    bindings: &[read("sparse_points"), read("clusters"), depth_texture("shadow_atlas"), read_write("group_visibility")],
    entries: &[Entry::first("main", 4)],
    workgroup: [WORKGROUP_SIZE, 1, 1],
    default_source: |textured| VISIBILITY.source(&visibility_body(&default_header()), textured),
};

/// The bindings of the lookup's `clusters` and maps (`LOOKUP_CLUSTERS_BINDING`,
/// `LOOKUP_MAPS_BINDING`): 1 and 2 in the lookup passes, after its own in the brute force that
/// looks the maps up inside its pass (`gpu::references::brute_force`).
pub fn lookup_bindings(clusters: u32, maps: u32) -> String {
    Wgsl::new().u32("LOOKUP_CLUSTERS_BINDING", clusters).u32("LOOKUP_MAPS_BINDING", maps).finish()
}

/// The visibility pass's WGSL after `head`, reading the rasterised atlas.
pub fn visibility_body(head: &str) -> String {
    Wgsl::new()
        .include(head)
        .include(&lookup_bindings(1, 2))
        .include(RASTER_DEPTH_WGSL)
        .include(VISIBILITY_WGSL)
        .finish()
}

/// A lookup pass's WGSL after `head` for receivers other than the sparse points: the maps
/// (`imperfect` ones or the rasterised atlas), the lookup (its clusters and maps at
/// `bindings`), then `parts` (the receivers and the pass's entry point).
pub fn lookup_pass_body(head: &str, imperfect: bool, bindings: [u32; 2], parts: &[&str]) -> String {
    let maps = if imperfect { ism::LOOKUP_WGSL } else { RASTER_DEPTH_WGSL };
    let mut wgsl = Wgsl::new()
        .include(head)
        .include(&lookup_bindings(bindings[0], bindings[1]))
        .include(maps)
        .include(VISIBILITY_LOOKUP_WGSL);
    for part in parts {
        wgsl = wgsl.include(part);
    }
    wgsl.finish()
}

/// The lookup's WGSL after `head`, reading the rasterised atlas (its clusters and maps at
/// `bindings`), without the pass's entry point.
pub fn lookup_body(head: &str, bindings: [u32; 2]) -> String {
    Wgsl::new()
        .include(head)
        .include(&lookup_bindings(bindings[0], bindings[1]))
        .include(RASTER_DEPTH_WGSL)
        .include(VISIBILITY_LOOKUP_WGSL)
        .finish()
}

/// The shadow-map raster's complete WGSL (vertex and fragment stages).
pub fn shadow_maps_source(settings: &ClusterSettings, scale: SceneScale, textured: bool) -> String {
    shadow_maps_source_after(&header(settings, scale), textured)
}

/// The shadow-map raster's complete WGSL after the constants `head`.
fn shadow_maps_source_after(head: &str, textured: bool) -> String {
    crate::gpu::shader::source(&Wgsl::new().include(head).include(SHADOW_MAPS_WGSL).finish(), textured)
}

/// The shadow-map raster at the default settings (for the compilation test).
pub fn default_shadow_maps_source(textured: bool) -> String {
    shadow_maps_source(&ClusterSettings::default(), SceneScale { diagonal: 1.0 }, textured)
}

/// Where a group visibility instance looks its maps up: the sparse points (the sparse method's
/// mode, its table read by the gather) or the second bounce's points (`gpu::lights::bounce`: the
/// first bounce's groups seen from the bounce points, its table read by `bounce2_points`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Receivers {
    SparsePoints,
    /// `count` bounce points (`array<BouncePoint>`, bound as `bounce_points`).
    BouncePoints {
        count: u32,
    },
    /// The camera's pixels (its visibility buffer, bound as `visibility`): the brute force with
    /// per-pixel visibility (`gpu::references::brute_force`); the table grows with the image
    /// ([`Clusters::fit_receivers`]).
    Pixels,
    /// No lookup pass and no table: another pass looks the maps up itself, through
    /// [`Clusters::lookup_resources`] and [`Clusters::lookup_header`] (the brute force through
    /// the clusters' maps, `gpu::references::brute_force`). Rasterised or imperfect maps.
    InPass,
}

/// The names of an instance's stages in the frame's timings: the sparse method's mode has the
/// mode's own, the second bounce's instance its `bounce2_*` ones (both can run in one frame).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StageNames {
    pub clustering: &'static str,
    pub shadow_maps: &'static str,
    pub ism_sampling: &'static str,
    pub ism_splat: &'static str,
    pub ism_pull_push: &'static str,
    /// The lookup, with rasterised maps and with imperfect ones.
    pub cluster_visibility: &'static str,
    pub ism_visibility: &'static str,
}

/// The sparse method's mode's stages.
pub const SPARSE_STAGES: StageNames = StageNames {
    clustering: CLUSTERING_STAGE,
    shadow_maps: SHADOW_MAPS_STAGE,
    ism_sampling: ism::SAMPLING_STAGE,
    ism_splat: ism::SPLAT_STAGE,
    ism_pull_push: ism::PULL_PUSH_STAGE,
    cluster_visibility: VISIBILITY.label,
    ism_visibility: ism::VISIBILITY.label,
};

/// How the groups are seeded each frame.
enum Seeding {
    /// k-means from the last frame's centres, empty clusters reseeded (`kmeans_seed`).
    Kmeans { seed: Kernel },
    /// VALs drawn by flux (the imperfect shadow maps').
    Flux(ism::FluxSampling),
}

/// Where the groups' shadow maps come from.
enum Maps {
    /// Rasterised from the triangles (exact depths).
    Raster(ShadowMaps),
    /// Imperfect shadow maps splatted from points, with pull-push.
    Ism(ism::Maps),
    /// No maps: shadow rays through the BVH to the clusters' members (the sparse points only).
    Rays(rays::Rays),
}

/// The clustered visibility mode, and with flux seeding and imperfect shadow maps the `"ism"`
/// mode: its passes, the groups (kept from frame to frame) and the group table it hands to the
/// gather.
pub struct Clusters {
    settings: ClusterSettings,
    scale: SceneScale,
    receivers: Receivers,
    names: StageNames,
    seeding: Seeding,
    assign: Kernel,
    partial: Kernel,
    reduce: Kernel,
    maps: Maps,
    /// The lookup pass (none for [`Receivers::InPass`]).
    visibility: Option<Kernel>,
    /// The WGSL header of its passes (the lookup's constants), for a pass that looks the maps
    /// up itself.
    head: String,
    /// `array<Cluster>`: this frame's centres, the next frame's start.
    clusters: wgpu::Buffer,
    /// `array<u32>`, one per VAL of [`Clusters::capacity`].
    group_of_val: wgpu::Buffer,
    /// `array<ClusterSums>`, clusters x blocks of [`PARTIAL_BLOCK`] VALs.
    partials: wgpu::Buffer,
    /// VALs the per-VAL buffers hold.
    capacity: u32,
    /// `array<f32>`, receivers (sparse or bounce points) x clusters.
    group_visibility: wgpu::Buffer,
}

/// The `"clusters"` visibility mode for a scene (see [`Clusters::new`]).
pub fn mode(gpu: &Gpu, scene: &GpuScene, settings: &VisibilitySettings, _glossy: bool) -> Result<Mode, GpuError> {
    Ok(Mode::Groups(Box::new(Clusters::new(gpu, scene, &settings.clusters, &settings.ism)?)))
}

impl Clusters {
    /// The `"clusters"` mode: k-means, rasterised maps or (`shadow_maps: "ism"`) imperfect
    /// ones as `ism` says for points, pull-push and bias.
    pub fn new(gpu: &Gpu, scene: &GpuScene, settings: &ClusterSettings, ism: &IsmSettings) -> Result<Self, GpuError> {
        let maps = (settings.shadow_maps == ShadowMapSource::Ism).then(|| ism::for_clusters(settings, ism));
        Self::build(gpu, scene, settings, false, maps.as_ref(), Receivers::SparsePoints, SPARSE_STAGES)
    }

    /// The `"ism"` mode: VALs drawn by flux, one assignment and update, imperfect shadow maps.
    pub fn imperfect(gpu: &Gpu, scene: &GpuScene, ism: &IsmSettings) -> Result<Self, GpuError> {
        Self::build(gpu, scene, &ism::cluster_settings(ism), true, Some(ism), Receivers::SparsePoints, SPARSE_STAGES)
    }

    /// The group visibility mode `settings` asks for (`"clusters"` or `"ism"`; `None` for the
    /// others), looked up at `receivers`, its stages named `names`.
    pub fn for_receivers(
        gpu: &Gpu,
        scene: &GpuScene,
        settings: &super::VisibilitySettings,
        receivers: Receivers,
        names: StageNames,
    ) -> Result<Option<Self>, GpuError> {
        use crate::scene::Occlusion;
        Ok(match settings.mode {
            Occlusion::Clusters => {
                let c = &settings.clusters;
                let maps = (c.shadow_maps == ShadowMapSource::Ism).then(|| ism::for_clusters(c, &settings.ism));
                Some(Self::build(gpu, scene, c, false, maps.as_ref(), receivers, names)?)
            }
            Occlusion::Ism => {
                let c = ism::cluster_settings(&settings.ism);
                Some(Self::build(gpu, scene, &c, true, Some(&settings.ism), receivers, names)?)
            }
            // Every other mode has no groups.
            _ => None,
        })
    }

    /// Groups seeded by flux (else by k-means), with imperfect maps when `ism` is given.
    fn build(
        gpu: &Gpu,
        scene: &GpuScene,
        settings: &ClusterSettings,
        flux: bool,
        ism: Option<&IsmSettings>,
        receivers: Receivers,
        names: StageNames,
    ) -> Result<Self, GpuError> {
        let scale = SceneScale::of(scene);
        // The maps are focused on the meshes: the clusters buffer holds their bounding sphere
        // after the clusters (written every frame, [`Clusters::record_at`]).
        let head = match ism {
            Some(ism) => ism::focused_header_with(settings, ism, scale),
            None => header_focused(settings, scale, 0.0, true),
        };
        let textured = scene.textured();
        let module = module_from_source(
            gpu,
            CLUSTERING.label,
            CLUSTERING.source(&Wgsl::new().include(&head).include(CLUSTERING_WGSL).finish(), textured),
        )?;
        let kernel = |name: &str| {
            Kernel::build(gpu, scene, &CLUSTERING, &module, CLUSTERING.entry(name), &[], CLUSTERING.workgroup)
        };
        let seeding = match flux {
            true => Seeding::Flux(ism::FluxSampling::new(gpu, scene, &head)?),
            false => Seeding::Kmeans { seed: kernel("kmeans_seed")? },
        };
        // Rays serve the sparse points; the second bounce's points and the brute force's pixels
        // look the clusters up in rasterised maps (or imperfect ones).
        let rays = settings.shadow_maps == ShadowMapSource::Rays && receivers == Receivers::SparsePoints;
        let maps = match ism {
            Some(ism) => Maps::Ism(ism::Maps::new(gpu, scene, &head, settings.count, ism::IsmParams::of(ism, scale))?),
            None if rays => Maps::Rays(rays::Rays::new(gpu, scene, settings, &head)?),
            None => Maps::Raster(ShadowMaps::after(gpu, scene, settings, &head)?),
        };
        let imperfect = ism.is_some();
        let lookup = match (receivers, imperfect) {
            (Receivers::SparsePoints, false) if rays => {
                Some((&rays::VISIBILITY, rays::visibility_body(&head, settings)))
            }
            (Receivers::SparsePoints, true) => Some((&ism::VISIBILITY, ism::visibility_body(&head))),
            (Receivers::SparsePoints, false) => Some((&VISIBILITY, visibility_body(&head))),
            (Receivers::BouncePoints { .. }, _) => Some(bounce::visibility_pass(&head, imperfect)),
            (Receivers::Pixels, _) => Some(brute_force::visibility_pass(&head, imperfect)),
            (Receivers::InPass, _) => None,
        };
        let visibility = match lookup {
            Some((desc, body)) => {
                let module = module_from_source(gpu, desc.label, desc.source(&body, textured))?;
                Some(Kernel::build(gpu, scene, desc, &module, desc.entry("main"), &[], desc.workgroup)?)
            }
            None => None,
        };
        let m = settings.count as usize;
        let points = match receivers {
            Receivers::SparsePoints => scene.flat.sparse_count(),
            Receivers::BouncePoints { count } => count,
            Receivers::Pixels | Receivers::InPass => 1,
        } as usize;
        let table = table_label(receivers);
        Ok(Self {
            settings: *settings,
            scale,
            receivers,
            names,
            seeding,
            assign: kernel("kmeans_assign")?,
            partial: kernel("kmeans_partial")?,
            reduce: kernel("kmeans_reduce")?,
            maps,
            visibility,
            head,
            clusters: gpu.storage_buffer_sized::<RawCluster>("clustering.clusters", m + 1)?,
            group_of_val: gpu.storage_buffer_sized::<u32>("clustering.group_of_val", 1)?,
            partials: gpu.storage_buffer_sized::<RawClusterSums>("clustering.cluster_partials", m)?,
            capacity: 1,
            group_visibility: gpu.storage_buffer_sized::<f32>(table, points.max(1) * m)?,
        })
    }

    /// The stage that seeds and updates the groups.
    fn grouping_stage(&self) -> &'static str {
        match self.seeding {
            Seeding::Kmeans { .. } => self.names.clustering,
            Seeding::Flux(_) => self.names.ism_sampling,
        }
    }

    /// The lookup's stage: its pass's label.
    fn visibility_stage(&self) -> &'static str {
        match self.maps {
            Maps::Raster(_) => self.names.cluster_visibility,
            Maps::Ism(_) => self.names.ism_visibility,
            Maps::Rays(_) => rays::VISIBILITY.label,
        }
    }

    /// Its stages, in order.
    pub fn stage_names(&self) -> Vec<&'static str> {
        let mut stages = vec![self.grouping_stage()];
        match &self.maps {
            Maps::Raster(_) => stages.push(self.names.shadow_maps),
            Maps::Ism(maps) => stages.extend(maps.stages(&self.names)),
            Maps::Rays(_) => stages.push(rays::MEMBERS_STAGE),
        }
        if self.visibility.is_some() {
            stages.push(self.visibility_stage());
        }
        stages
    }

    /// Whether another pass looks its maps up ([`Receivers::InPass`]).
    pub fn lookup_in_pass(&self) -> bool {
        self.receivers == Receivers::InPass
    }

    /// The lookup's header, for a pass that looks the maps up itself ([`Receivers::InPass`]).
    pub fn lookup_header(&self) -> &str {
        &self.head
    }

    /// Whether its maps are imperfect ones (`ism_lookup.wgsl`) rather than rasterised
    /// (`raster_depth.wgsl`); `None` with shadow rays.
    pub fn imperfect_maps(&self) -> Option<bool> {
        match self.maps {
            Maps::Raster(_) => Some(false),
            Maps::Ism(_) => Some(true),
            Maps::Rays(_) => None,
        }
    }

    /// The clusters and their maps as a pass that looks them up itself binds them (`clusters`,
    /// then `shadow_atlas` or `ism_atlas`); `None` with shadow rays.
    pub fn lookup_resources(&self) -> Option<[crate::gpu::pass::Res<'_>; 2]> {
        let maps = match &self.maps {
            Maps::Raster(maps) => view("shadow_atlas", &maps.atlas_view),
            Maps::Ism(maps) => buffer("ism_atlas", &maps.levels[0]),
            Maps::Rays(_) => return None,
        };
        Some([buffer("clusters", &self.clusters), maps])
    }

    /// Record its stages for the frame's VALs (those appended so far): seed and update the
    /// groups, draw their maps, and look them up at `receivers` (bound as `sparse_points` or
    /// `bounce_points`, `count` of them) into its table.
    pub fn record_at(
        &self,
        gpu: &Gpu,
        frame: &Frame<'_>,
        rec: &mut Recorder<'_>,
        receivers: crate::gpu::pass::Res<'_>,
        count: u32,
    ) -> Result<(), GpuError> {
        let scene = frame.scene;
        let m = self.settings.count;
        // The meshes' bounding sphere (as they are placed now) after the clusters: the maps'
        // focus (`paraboloid.wgsl`, `cluster_map_frame`).
        let (centre, radius) = scene.flat.bounding_sphere();
        let bounds = RawCluster { position: centre.into(), count: 0.0, normal: [0.0, 0.0, 1.0], radius };
        let offset = u64::from(m) * std::mem::size_of::<RawCluster>() as u64;
        gpu.queue.write_buffer(&self.clusters, offset, bytemuck::bytes_of(&bounds));
        let resources = [
            buffer("vals", &frame.vals.buffer),
            buffer("val_count", &frame.vals.count),
            buffer("clusters", &self.clusters),
            buffer("group_of_val", &self.group_of_val),
            buffer("cluster_partials", &self.partials),
        ];
        let bind = |k: &Kernel, names: usize, except: &str| {
            let r: Vec<_> = resources[..names]
                .iter()
                .filter(|r| r.name != except)
                .map(|r| crate::gpu::pass::Res { name: r.name, resource: r.resource.clone() })
                .collect();
            k.bind(gpu, &r)
        };
        let update = [
            (&self.assign, bind(&self.assign, 4, ""), [self.capacity, 1, 1]),
            (&self.partial, bind(&self.partial, 5, ""), [m, self.blocks(), 1]),
            (&self.reduce, bind(&self.reduce, 5, "group_of_val"), [m, 1, 1]),
        ];
        // Seed and update: k-means `iterations` times, or the flux draw and one update.
        let (steps, rounds) = match &self.seeding {
            Seeding::Kmeans { seed } => {
                let mut steps = vec![(seed, bind(seed, 3, ""), [m, 1, 1])];
                steps.extend(update);
                (steps, self.settings.iterations as usize)
            }
            Seeding::Flux(flux) => {
                let mut steps: Vec<_> = flux.steps(gpu, frame.vals, &self.clusters, m).into();
                steps.extend(update);
                (steps, 1)
            }
        };
        rec.stage(self.grouping_stage(), |e, s| {
            let parts = rounds * steps.len();
            for i in 0..rounds {
                for (j, (kernel, group, invocations)) in steps.iter().enumerate() {
                    let timestamps = s.as_ref().and_then(|s| s.compute_part(i * steps.len() + j, parts));
                    kernel.dispatch(e, group, scene, *invocations, timestamps);
                }
            }
        })?;
        match &self.maps {
            Maps::Raster(maps) => {
                maps.record(gpu, scene, &self.clusters, &self.settings, None, self.names.shadow_maps, rec)?
            }
            Maps::Ism(maps) => maps.record(gpu, scene, &self.clusters, &self.names, rec)?,
            Maps::Rays(rays) => rays.record(gpu, frame, &self.group_of_val, rec)?,
        }
        let Some(lookup) = &self.visibility else {
            return Ok(());
        };
        let table = buffer("group_visibility", &self.group_visibility);
        let resources = match &self.maps {
            Maps::Rays(rays) => {
                let [vals, members] = rays.resources(frame);
                let [nodes, order] = rays.bvh();
                vec![receivers, vals, members, table, nodes, order]
            }
            Maps::Raster(_) | Maps::Ism(_) => {
                let [clusters, maps] = self.lookup_resources().expect("maps");
                vec![receivers, clusters, maps, table]
            }
        };
        let group = lookup.bind(gpu, &resources);
        rec.stage(self.visibility_stage(), |e, s| {
            lookup.dispatch(e, &group, scene, [count, m, 1], s.as_ref().map(|s| s.compute()))
        })
    }

    /// Make the table hold `count` receivers (the pixels of a frame) x groups.
    pub fn fit_receivers(&mut self, gpu: &Gpu, count: u32) -> Result<(), GpuError> {
        if self.receivers == Receivers::InPass {
            return Ok(());
        }
        let needed = count as u64 * u64::from(self.settings.count) * 4;
        if needed > self.group_visibility.size() {
            let n = count as usize * self.settings.count as usize;
            self.group_visibility = gpu.storage_buffer_sized::<f32>(table_label(self.receivers), n)?;
        }
        Ok(())
    }

    fn blocks(&self) -> u32 {
        self.capacity.div_ceil(PARTIAL_BLOCK)
    }

    /// Read back what the last frame computed (tests and tools): the clusters, each of the
    /// first `vals` VALs' cluster, the visibility table (empty for [`Receivers::InPass`]) and
    /// the shadow maps.
    pub fn read(&self, gpu: &Gpu, vals: usize, points: usize) -> Result<ClusterReadback, GpuError> {
        let m = self.settings.count as usize;
        // Looked up in another pass: no table.
        let points = if self.receivers == Receivers::InPass { 0 } else { points };
        let mut clusters: Vec<RawCluster> = gpu.read_buffer(&self.clusters, m + 1)?;
        let bounds = clusters.pop().map(|b| (Vec3::from(b.position), b.radius));
        let clusters: Vec<twin::Cluster> = clusters.iter().map(Into::into).collect();
        let frames: Vec<twin::MapFrame> = clusters.iter().map(|c| twin::map_frame(c, bounds)).collect();
        let maps = match &self.maps {
            // The atlas holds the depths beyond each map's near distance (`raster_depth.wgsl`).
            Maps::Raster(maps) => maps
                .read(gpu, &self.settings, self.scale)?
                .into_iter()
                .zip(&frames)
                .map(|(map, f)| map.into_iter().map(|d| d + f.near).collect())
                .collect(),
            Maps::Ism(maps) => maps.read(gpu)?,
            Maps::Rays(_) => Vec::new(),
        };
        Ok(ClusterReadback {
            frames,
            clusters,
            group_of_val: gpu.read_buffer(&self.group_of_val, vals.min(self.capacity as usize))?,
            visibility: gpu.read_buffer(&self.group_visibility, points * m)?,
            maps,
            kmeans: self.scale.kmeans(&self.settings),
            settings: self.settings,
            ism: match &self.maps {
                Maps::Ism(maps) => Some(maps.params()),
                Maps::Raster(_) | Maps::Rays(_) => None,
            },
            members: match &self.maps {
                Maps::Rays(rays) => Some(rays.read(gpu, vals)?),
                Maps::Raster(_) | Maps::Ism(_) => None,
            },
        })
    }
}

/// The label of the table of `receivers`.
fn table_label(receivers: Receivers) -> &'static str {
    match receivers {
        Receivers::SparsePoints => "group_visibility",
        Receivers::BouncePoints { .. } => "bounce2_visibility.bounce_visibility",
        Receivers::Pixels => "brute_force_ism_visibility.pixel_visibility",
        Receivers::InPass => "brute_force_clusters.no_table",
    }
}

/// What [`Clusters::read`] returns.
pub struct ClusterReadback {
    pub clusters: Vec<twin::Cluster>,
    /// Each cluster's map frame, focused on the meshes' bounding sphere as the frame's was
    /// (`twin::map_frame`).
    pub frames: Vec<twin::MapFrame>,
    pub group_of_val: Vec<u32>,
    /// Sparse points x clusters.
    pub visibility: Vec<f32>,
    /// Per cluster, its shadow map: distances (m), `f32::INFINITY` where nothing was drawn.
    pub maps: Vec<Vec<f32>>,
    pub kmeans: twin::KmeansParams,
    pub settings: ClusterSettings,
    /// The imperfect shadow maps' lengths, in the `"ism"` mode.
    pub ism: Option<ism::IsmParams>,
    /// The clusters' member lists, with `shadow_maps: "rays"`.
    pub members: Option<twin::MemberLists>,
}

impl GroupVisibility for Clusters {
    fn stages(&self) -> Vec<&'static str> {
        self.stage_names()
    }

    fn table(&self) -> GroupTable<'_> {
        GroupTable { groups: self.settings.count, group_of_val: &self.group_of_val, visibility: &self.group_visibility }
    }

    fn fit(&mut self, gpu: &Gpu, max_vals: u32) -> Result<(), GpuError> {
        if let Seeding::Flux(flux) = &mut self.seeding {
            flux.fit(gpu, max_vals)?;
        }
        if let Maps::Rays(rays) = &mut self.maps {
            rays.fit(gpu, max_vals)?;
        }
        if max_vals > self.capacity {
            self.capacity = max_vals;
            self.group_of_val = gpu.storage_buffer_sized::<u32>("clustering.group_of_val", max_vals as usize)?;
            let partials = self.settings.count as usize * self.blocks() as usize;
            self.partials = gpu.storage_buffer_sized::<RawClusterSums>("clustering.cluster_partials", partials)?;
        }
        Ok(())
    }

    fn record(&self, gpu: &Gpu, frame: &Frame<'_>, rec: &mut Recorder<'_>) -> Result<(), GpuError> {
        debug_assert_eq!(self.receivers, Receivers::SparsePoints);
        let points = frame.scene.flat.sparse_count();
        self.record_at(gpu, frame, rec, buffer("sparse_points", &frame.scene.sparse_points), points)
    }

    fn as_any(&self) -> &dyn std::any::Any {
        self
    }
}

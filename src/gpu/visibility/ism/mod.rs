//! Imperfect shadow maps (paper 004), a group visibility mode ([`super::GroupVisibility`])
//! built from the clusters' machinery with two parts of its own:
//!
//! - **which lights get a map** (`sampling.wgsl`): `count` VALs drawn by flux, stratified, as
//!   the paper draws its VPLs from the RSM; every VAL then joins the nearest drawn one and each
//!   group takes its mean position, normal and spread (the clusters' assign and update, once);
//! - **the maps** (`splat.wgsl`, `pull_push.wgsl`): low-resolution paraboloid maps splatted
//!   from points on the meshes (a random subset of its own per map, drawn by area from a hash,
//!   as triangle + barycentrics so they follow moving meshes), nearest distance by `atomicMax`
//!   on an encoded `u32` (`ism.wgsl`), then pull-push with the paper's outlier thresholds.
//!
//! The visibility of every (sparse point, group) is the clusters' filtered lookup
//! (`../clusters/cluster_visibility.wgsl`) reading these maps (`ism_lookup.wgsl`). Rust twin:
//! [`twin`].

pub mod settings;
pub mod twin;

use super::clusters::{self, Clusters, SceneScale, StageNames};
use super::{Mode, VisibilitySettings};
use crate::gpu::pass::{Entry, Kernel, PassDesc, buffer, module_from_source, read, read_write};
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::WORKGROUP_SIZE;
use crate::gpu::shader::Wgsl;
use crate::gpu::technique::Vals;
use crate::gpu::timing::Recorder;
use crate::gpu::{Gpu, GpuError};
use crate::scene::{ClusterMethod, ClusterSettings, IsmSettings};
use glam::Vec3;

pub const ISM_WGSL: &str = include_str!("ism.wgsl");
/// The stratified draw by flux (`flux_draw.wgsl`), shared with the second bounce's VALs.
pub const FLUX_DRAW_WGSL: &str = include_str!("flux_draw.wgsl");
pub const SAMPLING_WGSL: &str = include_str!("sampling.wgsl");
pub const SPLAT_WGSL: &str = include_str!("splat.wgsl");
pub const PULL_PUSH_WGSL: &str = include_str!("pull_push.wgsl");
pub const LOOKUP_WGSL: &str = include_str!("ism_lookup.wgsl");

/// The constants and lengths the twin shares with the passes (defined in [`twin`]).
pub use twin::{IsmParams, POINT_SEED, SAMPLE_BLOCK};

/// Stage names in the frame's timings.
pub const SAMPLING_STAGE: &str = "ism_sampling";
pub const SPLAT_STAGE: &str = "ism_splat";
pub const PULL_PUSH_STAGE: &str = "ism_pull_push";

/// The clusters' settings the mode runs their machinery with: one group per map, one update.
pub fn cluster_settings(ism: &IsmSettings) -> ClusterSettings {
    ClusterSettings {
        method: ClusterMethod::Kmeans,
        count: ism.count,
        shadow_map_resolution: ism.resolution,
        soft: ism.soft,
        normal_weight: ClusterSettings::default().normal_weight,
        iterations: 1,
        shadow_maps: crate::scene::ShadowMapSource::Ism,
        rays: ClusterSettings::default().rays,
        // Splatted from points: nothing rasterised.
        proxy_error: 0.0,
    }
}

impl IsmParams {
    /// The lengths for `ism`'s settings in a scene of `scale`.
    pub fn of(ism: &IsmSettings, scale: SceneScale) -> Self {
        Self {
            resolution: ism.resolution,
            points: ism.points_per_map(),
            levels: ism.pull_push_levels,
            pull_threshold: ism.pull_threshold * scale.diagonal,
            push_threshold: ism.push_threshold * scale.diagonal,
            slope_bias_texels: ism.slope_bias,
        }
    }
}

/// The constants of every shader of the mode: the clusters' header, then the mode's own and
/// `ism.wgsl`.
pub fn header(ism: &IsmSettings, scale: SceneScale) -> String {
    header_with(&cluster_settings(ism), ism, scale)
}

/// The `ism` settings of imperfect shadow maps for `clusters` (`clusters.shadow_maps: "ism"`):
/// one map per cluster at its resolution, with its filter.
pub fn for_clusters(clusters: &ClusterSettings, ism: &IsmSettings) -> IsmSettings {
    IsmSettings { count: clusters.count, resolution: clusters.shadow_map_resolution, soft: clusters.soft, ..*ism }
}

/// [`header`] for the groups of `clusters`, with imperfect maps as `ism` says.
pub fn header_with(clusters: &ClusterSettings, ism: &IsmSettings, scale: SceneScale) -> String {
    header_for(clusters, ism, scale, false)
}

/// [`header_with`] with the maps focused on the meshes (`clusters::header_focused`).
pub fn focused_header_with(clusters: &ClusterSettings, ism: &IsmSettings, scale: SceneScale) -> String {
    header_for(clusters, ism, scale, true)
}

fn header_for(clusters: &ClusterSettings, ism: &IsmSettings, scale: SceneScale, focus: bool) -> String {
    let p = IsmParams::of(ism, scale);
    Wgsl::new()
        .include(&clusters::header_focused(clusters, scale, p.slope_bias_texels, focus))
        .u32("ISM_POINTS", p.points)
        .f32("PULL_THRESHOLD", p.pull_threshold)
        .f32("PUSH_THRESHOLD", p.push_threshold)
        .u32("SAMPLE_BLOCK", SAMPLE_BLOCK)
        .u32("POINT_SEED", POINT_SEED)
        .include(ISM_WGSL)
        .finish()
}

fn default_header() -> String {
    header(&IsmSettings::default(), SceneScale { diagonal: 1.0 })
}

/// Every compute pass of the mode, for the layout test (`crate::gpu::passes`).
pub const PASSES: &[&PassDesc] = &[&SAMPLING, &SPLAT, &PULL_PUSH, &VISIBILITY];

/// Drawing the VALs by flux: three entry points over one set of bindings.
pub const SAMPLING: PassDesc = PassDesc {
    label: SAMPLING_STAGE,
    bindings: &[read("vals"), read("val_count"), read_write("flux_prefix"), read_write("clusters")],
    entries: &[Entry::first("flux_blocks", 3), Entry::first("flux_scan", 3), Entry::first("flux_sample", 4)],
    workgroup: [WORKGROUP_SIZE, 1, 1],
    default_source: |textured| {
        SAMPLING.source(
            &Wgsl::new().include(&default_header()).include(FLUX_DRAW_WGSL).include(SAMPLING_WGSL).finish(),
            textured,
        )
    },
};

/// Splatting every map's points.
pub const SPLAT: PassDesc = PassDesc {
    label: SPLAT_STAGE,
    bindings: &[read("clusters"), read("triangle_cdf"), read_write("ism_atlas")],
    entries: &[Entry::first("splat", 3)],
    workgroup: [WORKGROUP_SIZE, 1, 1],
    default_source: |textured| {
        SPLAT.source(&Wgsl::new().include(&default_header()).include(SPLAT_WGSL).finish(), textured)
    },
};

/// One pull or push between two levels.
pub const PULL_PUSH: PassDesc = PassDesc {
    label: PULL_PUSH_STAGE,
    bindings: &[read_write("fine"), read_write("coarse")],
    entries: &[Entry::first("pull", 2), Entry::first("push", 2)],
    workgroup: [WORKGROUP_SIZE, 1, 1],
    default_source: |textured| {
        PULL_PUSH.source(&Wgsl::new().include(&default_header()).include(PULL_PUSH_WGSL).finish(), textured)
    },
};

/// Per (sparse point, group) visibility through the maps: the clusters' lookup.
pub const VISIBILITY: PassDesc = PassDesc {
    label: "ism_visibility",
    bindings: &[read("sparse_points"), read("clusters"), read("ism_atlas"), read_write("group_visibility")],
    entries: &[Entry::first("main", 4)],
    workgroup: [WORKGROUP_SIZE, 1, 1],
    default_source: |textured| VISIBILITY.source(&visibility_body(&default_header()), textured),
};

/// The visibility pass's WGSL after `head`.
pub fn visibility_body(head: &str) -> String {
    Wgsl::new()
        .include(head)
        .include(&clusters::lookup_bindings(1, 2))
        .include(LOOKUP_WGSL)
        .include(clusters::VISIBILITY_WGSL)
        .finish()
}

/// The `"ism"` visibility mode for a scene: imperfect shadow maps of VALs drawn by flux.
pub fn mode(gpu: &Gpu, scene: &GpuScene, settings: &VisibilitySettings, _glossy: bool) -> Result<Mode, GpuError> {
    Ok(Mode::Groups(Box::new(Clusters::imperfect(gpu, scene, &settings.ism)?)))
}

/// The flux draw's kernels and its running sums.
pub struct FluxSampling {
    blocks: Kernel,
    scan: Kernel,
    sample: Kernel,
    /// `array<f32>`: block sums, then their running sums (one more than the blocks).
    prefix: wgpu::Buffer,
    /// Blocks `prefix` holds.
    capacity: u32,
}

impl FluxSampling {
    pub fn new(gpu: &Gpu, scene: &GpuScene, head: &str) -> Result<Self, GpuError> {
        let module = module_from_source(
            gpu,
            SAMPLING.label,
            SAMPLING.source(
                &Wgsl::new().include(head).include(FLUX_DRAW_WGSL).include(SAMPLING_WGSL).finish(),
                scene.textured(),
            ),
        )?;
        let kernel =
            |name: &str| Kernel::build(gpu, scene, &SAMPLING, &module, SAMPLING.entry(name), &[], SAMPLING.workgroup);
        Ok(Self {
            blocks: kernel("flux_blocks")?,
            scan: kernel("flux_scan")?,
            sample: kernel("flux_sample")?,
            prefix: gpu.storage_buffer_sized::<f32>("ism_sampling.flux_prefix", 2)?,
            capacity: 1,
        })
    }

    /// Cover frames of up to `max_vals` VALs.
    pub fn fit(&mut self, gpu: &Gpu, max_vals: u32) -> Result<(), GpuError> {
        let blocks = max_vals.div_ceil(SAMPLE_BLOCK).max(1);
        if blocks > self.capacity {
            self.capacity = blocks;
            self.prefix = gpu.storage_buffer_sized::<f32>("ism_sampling.flux_prefix", blocks as usize + 1)?;
        }
        Ok(())
    }

    /// Its three dispatches, each with its invocations, for `vals` into `clusters`.
    pub fn steps<'a>(
        &'a self,
        gpu: &Gpu,
        vals: &Vals,
        clusters: &wgpu::Buffer,
        count: u32,
    ) -> [(&'a Kernel, wgpu::BindGroup, [u32; 3]); 3] {
        let all = [
            buffer("vals", &vals.buffer),
            buffer("val_count", &vals.count),
            buffer("flux_prefix", &self.prefix),
            buffer("clusters", clusters),
        ];
        let bind = |k: &Kernel, n: usize| k.bind(gpu, &all[..n]);
        [
            (&self.blocks, bind(&self.blocks, 3), [self.capacity, 1, 1]),
            (&self.scan, bind(&self.scan, 3), [1, 1, 1]),
            (&self.sample, bind(&self.sample, 4), [count, 1, 1]),
        ]
    }
}

/// The maps: the splat, pull and push kernels, every level's buffer and the triangles' running
/// areas the points are drawn from.
pub struct Maps {
    params: IsmParams,
    count: u32,
    splat: Kernel,
    /// Per level l < levels: the pull from l to l + 1 and the push from l + 1 to l.
    pulls: Vec<Kernel>,
    pushes: Vec<Kernel>,
    /// `array<u32>` per level, encoded depths (`ism.wgsl`); level 0 is what the lookup reads.
    pub levels: Vec<wgpu::Buffer>,
    triangle_cdf: wgpu::Buffer,
}

impl Maps {
    pub fn new(gpu: &Gpu, scene: &GpuScene, head: &str, count: u32, params: IsmParams) -> Result<Self, GpuError> {
        let textured = scene.textured();
        let splat_module = module_from_source(
            gpu,
            SPLAT.label,
            SPLAT.source(&Wgsl::new().include(head).include(SPLAT_WGSL).finish(), textured),
        )?;
        let splat = Kernel::build(gpu, scene, &SPLAT, &splat_module, SPLAT.entry("splat"), &[], SPLAT.workgroup)?;
        let module = module_from_source(
            gpu,
            PULL_PUSH.label,
            PULL_PUSH.source(&Wgsl::new().include(head).include(PULL_PUSH_WGSL).finish(), textured),
        )?;
        let (mut pulls, mut pushes) = (Vec::new(), Vec::new());
        for level in 0..params.levels {
            let constants = [("LEVEL", f64::from(level))];
            let build = |name: &str| {
                Kernel::build(gpu, scene, &PULL_PUSH, &module, PULL_PUSH.entry(name), &constants, PULL_PUSH.workgroup)
            };
            pulls.push(build("pull")?);
            pushes.push(build("push")?);
        }
        let levels = (0..=params.levels)
            .map(|l| {
                let side = (params.resolution >> l) as usize;
                gpu.storage_buffer_sized::<u32>(&format!("ism_splat.level{l}"), count as usize * side * side)
            })
            .collect::<Result<Vec<_>, _>>()?;
        let positions: Vec<Vec3> = scene.flat.vertices.iter().map(|v| Vec3::from(v.position)).collect();
        let cdf = twin::triangle_cdf(&positions, &scene.flat.indices, &scene.flat.triangle_sparse_density);
        Ok(Self {
            params,
            count,
            splat,
            pulls,
            pushes,
            levels,
            triangle_cdf: gpu.storage_buffer("ism_splat.triangle_cdf", &cdf, wgpu::BufferUsages::empty())?,
        })
    }

    pub fn params(&self) -> IsmParams {
        self.params
    }

    /// The stages it records, named as `names` says.
    pub fn stages(&self, names: &StageNames) -> Vec<&'static str> {
        if self.params.levels == 0 { vec![names.ism_splat] } else { vec![names.ism_splat, names.ism_pull_push] }
    }

    /// Splat every map around `clusters`' centres, then pull and push, in the stages `names`
    /// says.
    pub fn record(
        &self,
        gpu: &Gpu,
        scene: &GpuScene,
        clusters: &wgpu::Buffer,
        names: &StageNames,
        rec: &mut Recorder<'_>,
    ) -> Result<(), GpuError> {
        let group = self.splat.bind(
            gpu,
            &[
                buffer("clusters", clusters),
                buffer("triangle_cdf", &self.triangle_cdf),
                buffer("ism_atlas", &self.levels[0]),
            ],
        );
        let (count, points) = (self.count, self.params.points);
        rec.stage(names.ism_splat, |e, s| {
            e.clear_buffer(&self.levels[0], 0, None);
            self.splat.dispatch(e, &group, scene, [points, count, 1], s.as_ref().map(|s| s.compute()));
        })?;
        if self.params.levels == 0 {
            return Ok(());
        }
        let side = |l: u32| self.params.resolution >> l;
        let pairs = |k: &Kernel, l: usize| {
            k.bind(gpu, &[buffer("fine", &self.levels[l]), buffer("coarse", &self.levels[l + 1])])
        };
        let pull_groups: Vec<_> = self.pulls.iter().enumerate().map(|(l, k)| pairs(k, l)).collect();
        let push_groups: Vec<_> = self.pushes.iter().enumerate().map(|(l, k)| pairs(k, l)).collect();
        let levels = self.params.levels as usize;
        rec.stage(names.ism_pull_push, |e, s| {
            let parts = 2 * levels;
            for (l, (pull, group)) in self.pulls.iter().zip(&pull_groups).enumerate() {
                let texels = side(l as u32 + 1).pow(2);
                let timestamps = s.as_ref().and_then(|s| s.compute_part(l, parts));
                pull.dispatch(e, group, scene, [texels, count, 1], timestamps);
            }
            for (i, l) in (0..levels).rev().enumerate() {
                let texels = side(l as u32).pow(2);
                let timestamps = s.as_ref().and_then(|s| s.compute_part(levels + i, parts));
                self.pushes[l].dispatch(e, &push_groups[l], scene, [texels, count, 1], timestamps);
            }
        })
    }

    /// The finest level after pull-push, per map: distances (m), `f32::INFINITY` where empty.
    pub fn read(&self, gpu: &Gpu) -> Result<Vec<Vec<f32>>, GpuError> {
        let side = self.params.resolution as usize;
        let words: Vec<u32> = gpu.read_buffer(&self.levels[0], self.count as usize * side * side)?;
        Ok(words.chunks(side * side).map(|map| map.iter().map(|&e| twin::decode_depth(e)).collect()).collect())
    }
}

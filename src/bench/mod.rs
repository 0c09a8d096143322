//! `relume bench`: a sweep over quality settings measuring, per configuration, what each stage
//! costs, the device memory the renderer holds and how far the indirect image is from the
//! references. Error figures come from [`crate::bench::compare`], the code path of `relume compare`.
//!
//! Axes: sparse points per mesh, interpolation neighbours per vertex, RSM resolution (the VAL
//! count is at most its square), occlusion (off / disks), glossy (on / off) and output
//! resolution.
//!
//! By default each axis is varied alone around a base configuration (the scene's settings);
//! `grid` takes the Cartesian product instead.

pub mod compare;
pub mod equal_error;
pub mod fma;
pub mod plot;
pub mod table1;
pub mod temporal;

use self::compare::IndirectError;
use crate::gpu::timing::TimingSource;
use crate::gpu::visibility::VisibilitySettings;
use crate::gpu::{Gpu, GpuError, MemoryInUse};
use crate::renderer::{Method, Rendered, Renderer, stage};
use crate::scene::{
    ClusterSettings, GlossyInterpolation, InterpolationKernel, IsmSettings, LightBound, MAX_CLUSTERS,
    MAX_SPARSE_POINTS, Occlusion, RSM_RESOLUTION_RANGE, Scene, SceneDescription, SceneError, ShadowMapSource,
    SoftShadows,
};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Errors of a bench run: bad flags name the flag and the value.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error("{flag}: {message}")]
    Flag { flag: String, message: String },
    #[error("reading scene {path}: {source}")]
    Read { path: PathBuf, source: std::io::Error },
    #[error("scene {path}: {source}")]
    Scene { path: PathBuf, source: SceneError },
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error("writing {path}: {message}")]
    Write { path: PathBuf, message: String },
}

fn flag_error(flag: &str, message: impl Into<String>) -> BenchError {
    BenchError::Flag { flag: flag.to_owned(), message: message.into() }
}

/// Most pixels on one side of a bench image (as `render`'s `--width`).
const MAX_SIDE: u32 = 8192;

/// One configuration of the sweep.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Config {
    /// Sparse points on every mesh; `None`: each mesh's own count from the scene file.
    pub sparse_points_per_mesh: Option<u32>,
    /// Sparse points each vertex interpolates from; `None`: the scene's
    /// `settings.interpolation_neighbours`.
    pub neighbours: Option<u32>,
    /// Near-field radius in whole sparse point spacings; `None`: the scene's
    /// `settings.sparse.near_field`.
    pub near_field: Option<u32>,
    /// `settings.sparse.glossy_interpolation`; `None`: the scene's.
    pub glossy_interpolation: Option<GlossyInterpolation>,
    /// `settings.sparse.adaptive` in hundredths (adaptive points per 100 sparse points);
    /// `None`: the scene's.
    pub adaptive_percent: Option<u32>,
    /// `settings.sparse.kernel`, `bound` and `subdivision` (whole spacings); `None`: the scene's.
    pub kernel: Option<InterpolationKernel>,
    pub bound: Option<LightBound>,
    pub subdivision: Option<u32>,
    /// RSM side R: at most R² VALs (only lit texels become VALs).
    pub rsm_resolution: u32,
    pub occlusion: Occlusion,
    /// Whether the glossy gather may run (it runs only when the scene has a glossy material).
    pub glossy: bool,
    pub width: u32,
    pub height: u32,
    /// The `ism` mode's settings where they differ from the scene's `settings.ism` (set only
    /// when `occlusion` is `ism`).
    pub ism_count: Option<u32>,
    pub ism_resolution: Option<u32>,
    pub ism_points: Option<u32>,
    pub ism_pull_push_levels: Option<u32>,
    /// The `clusters` mode's settings where they differ from the scene's `settings.clusters`
    /// (set only when `occlusion` is `clusters`).
    pub clusters: ClusterOverrides,
}

/// Overrides of `settings.clusters` (`None`: the scene's).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct ClusterOverrides {
    pub count: Option<u32>,
    pub shadow_map_resolution: Option<u32>,
    pub soft: Option<SoftShadows>,
    pub shadow_maps: Option<ShadowMapSource>,
}

impl ClusterOverrides {
    /// No override.
    pub const NONE: Self = Self { count: None, shadow_map_resolution: None, soft: None, shadow_maps: None };

    /// `base` with these overrides.
    pub fn apply(&self, base: &ClusterSettings) -> ClusterSettings {
        ClusterSettings {
            count: self.count.unwrap_or(base.count),
            shadow_map_resolution: self.shadow_map_resolution.unwrap_or(base.shadow_map_resolution),
            soft: self.soft.unwrap_or(base.soft),
            shadow_maps: self.shadow_maps.unwrap_or(base.shadow_maps),
            ..*base
        }
    }

    fn is_none(&self) -> bool {
        *self == Self::NONE
    }
}

/// `soft`'s name in settings, CSV and labels.
fn soft_name(s: SoftShadows) -> &'static str {
    match s {
        SoftShadows::Pcss => "pcss",
        SoftShadows::Pcf => "pcf",
        SoftShadows::Hard => "hard",
    }
}

/// `kernel`'s name in settings, CSV and labels.
fn kernel_name(k: InterpolationKernel) -> &'static str {
    match k {
        InterpolationKernel::Paper => "paper",
        InterpolationKernel::Smooth => "smooth",
    }
}

/// `bound`'s name in settings, CSV and labels.
fn bound_name(b: LightBound) -> &'static str {
    match b {
        LightBound::Off => "off",
        LightBound::Gathered => "gathered",
    }
}

/// `glossy_interpolation`'s name in settings, CSV and labels.
fn glossy_interpolation_name(g: GlossyInterpolation) -> &'static str {
    match g {
        GlossyInterpolation::Lights => "lights",
        GlossyInterpolation::Radiance => "radiance",
    }
}

/// `shadow_maps`' name in settings, CSV and labels.
fn maps_name(m: ShadowMapSource) -> &'static str {
    match m {
        ShadowMapSource::Raster => "raster",
        ShadowMapSource::Ism => "ism",
    }
}

impl Config {
    /// The `ism` settings of this configuration: `base` with its overrides.
    pub fn ism_settings(&self, base: &crate::scene::IsmSettings) -> crate::scene::IsmSettings {
        crate::scene::IsmSettings {
            count: self.ism_count.unwrap_or(base.count),
            resolution: self.ism_resolution.unwrap_or(base.resolution),
            points: self.ism_points.or(base.points),
            pull_push_levels: self.ism_pull_push_levels.unwrap_or(base.pull_push_levels),
            ..*base
        }
    }

    /// Whether any `ism` setting is overridden.
    fn has_ism(&self) -> bool {
        self.ism_count.is_some()
            || self.ism_resolution.is_some()
            || self.ism_points.is_some()
            || self.ism_pull_push_levels.is_some()
    }
}

/// The values given for each axis (`None`: the axis is not swept).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Sweep {
    pub sparse_points: Option<Vec<u32>>,
    pub neighbours: Option<Vec<u32>>,
    pub near_field: Option<Vec<u32>>,
    pub glossy_interpolation: Option<Vec<GlossyInterpolation>>,
    /// `settings.sparse.adaptive`, in hundredths.
    pub adaptive: Option<Vec<u32>>,
    pub kernel: Option<Vec<InterpolationKernel>>,
    pub bound: Option<Vec<LightBound>>,
    pub subdivision: Option<Vec<u32>>,
    pub rsm_resolution: Option<Vec<u32>>,
    pub occlusion: Option<Vec<Occlusion>>,
    pub glossy: Option<Vec<bool>>,
    pub resolution: Option<Vec<(u32, u32)>>,
    /// The `ism` mode's axes: each value is measured with `occlusion` `ism`.
    pub ism_count: Option<Vec<u32>>,
    pub ism_resolution: Option<Vec<u32>>,
    pub ism_points: Option<Vec<u32>>,
    pub ism_pull_push_levels: Option<Vec<u32>>,
    /// The `clusters` mode's axes: each value is measured with `occlusion` `clusters`.
    pub cluster_count: Option<Vec<u32>>,
    pub cluster_resolution: Option<Vec<u32>>,
    pub cluster_soft: Option<Vec<SoftShadows>>,
    pub cluster_maps: Option<Vec<ShadowMapSource>>,
}

/// The axis names `--sweep` accepts.
pub const AXES: &[&str] = &[
    "sparse_points",
    "neighbours",
    "near_field",
    "glossy_interpolation",
    "adaptive",
    "kernel",
    "bound",
    "subdivision",
    "rsm_resolution",
    "occlusion",
    "glossy",
    "resolution",
    "ism_count",
    "ism_resolution",
    "ism_points",
    "ism_pull_push_levels",
    "cluster_count",
    "cluster_resolution",
    "cluster_soft",
    "cluster_maps",
];

impl Sweep {
    /// Parse `--sweep axis=v1,v2,...` arguments; each axis at most once.
    pub fn parse(args: &[String]) -> Result<Self, BenchError> {
        let mut sweep = Sweep::default();
        for arg in args {
            let Some((axis, values)) = arg.split_once('=') else {
                return Err(flag_error("--sweep", format!("expected AXIS=V1,V2,..., got `{arg}`")));
            };
            let axis = axis.trim();
            let flag = format!("--sweep {axis}");
            let values: Vec<&str> = values.split(',').map(str::trim).collect();
            if values.iter().any(|v| v.is_empty()) {
                return Err(flag_error(&flag, format!("empty value in `{arg}`")));
            }
            let duplicate = |given: bool| {
                if given { Err(flag_error(&flag, "given more than once")) } else { Ok(()) }
            };
            match axis {
                "sparse_points" => {
                    duplicate(sweep.sparse_points.is_some())?;
                    sweep.sparse_points = Some(parse_each(&flag, &values, |v| int_in(v, 1, MAX_SPARSE_POINTS))?);
                }
                "rsm_resolution" => {
                    duplicate(sweep.rsm_resolution.is_some())?;
                    let (lo, hi) = RSM_RESOLUTION_RANGE;
                    sweep.rsm_resolution = Some(parse_each(&flag, &values, |v| int_in(v, lo, hi))?);
                }
                "occlusion" => {
                    duplicate(sweep.occlusion.is_some())?;
                    sweep.occlusion = Some(parse_each(&flag, &values, |v| match v {
                        "off" => Ok(Occlusion::Off),
                        "disks" => Ok(Occlusion::Disks),
                        "clusters" => Ok(Occlusion::Clusters),
                        "ism" => Ok(Occlusion::Ism),
                        _ => Err("expected `off`, `disks`, `clusters` or `ism`".to_owned()),
                    })?);
                }
                "glossy" => {
                    duplicate(sweep.glossy.is_some())?;
                    sweep.glossy = Some(parse_each(&flag, &values, |v| match v {
                        "on" | "true" => Ok(true),
                        "off" | "false" => Ok(false),
                        _ => Err("expected `on` or `off`".to_owned()),
                    })?);
                }
                "resolution" => {
                    duplicate(sweep.resolution.is_some())?;
                    sweep.resolution = Some(parse_each(&flag, &values, parse_resolution)?);
                }
                "ism_count" => {
                    duplicate(sweep.ism_count.is_some())?;
                    sweep.ism_count = Some(parse_each(&flag, &values, |v| int_in(v, 1, crate::scene::MAX_ISMS))?);
                }
                "ism_resolution" => {
                    duplicate(sweep.ism_resolution.is_some())?;
                    sweep.ism_resolution = Some(parse_each(&flag, &values, |v| {
                        let n = int_in(v, 16, 512)?;
                        if n.is_power_of_two() { Ok(n) } else { Err("must be a power of two in 16..=512".to_owned()) }
                    })?);
                }
                "ism_points" => {
                    duplicate(sweep.ism_points.is_some())?;
                    let max = crate::scene::MAX_ISM_POINTS;
                    sweep.ism_points = Some(parse_each(&flag, &values, |v| int_in(v, 16, max))?);
                }
                "ism_pull_push_levels" => {
                    duplicate(sweep.ism_pull_push_levels.is_some())?;
                    sweep.ism_pull_push_levels = Some(parse_each(&flag, &values, |v| int_in(v, 0, 4))?);
                }
                "near_field" => {
                    duplicate(sweep.near_field.is_some())?;
                    let max = crate::scene::NEAR_FIELD_RANGE.1 as u32;
                    sweep.near_field = Some(parse_each(&flag, &values, |v| int_in(v, 0, max))?);
                }
                "adaptive" => {
                    duplicate(sweep.adaptive.is_some())?;
                    sweep.adaptive = Some(parse_each(&flag, &values, hundredths)?);
                }
                "kernel" => {
                    duplicate(sweep.kernel.is_some())?;
                    let all = [InterpolationKernel::Paper, InterpolationKernel::Smooth];
                    sweep.kernel = Some(parse_each(&flag, &values, |v| named(v, &all, kernel_name))?);
                }
                "bound" => {
                    duplicate(sweep.bound.is_some())?;
                    let all = [LightBound::Off, LightBound::Gathered];
                    sweep.bound = Some(parse_each(&flag, &values, |v| named(v, &all, bound_name))?);
                }
                "subdivision" => {
                    duplicate(sweep.subdivision.is_some())?;
                    let (lo, hi) = crate::scene::SUBDIVISION_RANGE;
                    sweep.subdivision = Some(parse_each(&flag, &values, |v| int_in(v, lo as u32, hi as u32))?);
                }
                "glossy_interpolation" => {
                    duplicate(sweep.glossy_interpolation.is_some())?;
                    let all = [GlossyInterpolation::Lights, GlossyInterpolation::Radiance];
                    sweep.glossy_interpolation =
                        Some(parse_each(&flag, &values, |v| named(v, &all, glossy_interpolation_name))?);
                }
                "cluster_count" => {
                    duplicate(sweep.cluster_count.is_some())?;
                    sweep.cluster_count = Some(parse_each(&flag, &values, |v| int_in(v, 1, MAX_CLUSTERS))?);
                }
                "cluster_resolution" => {
                    duplicate(sweep.cluster_resolution.is_some())?;
                    sweep.cluster_resolution = Some(parse_each(&flag, &values, |v| int_in(v, 16, 1024))?);
                }
                "cluster_soft" => {
                    duplicate(sweep.cluster_soft.is_some())?;
                    let all = [SoftShadows::Pcss, SoftShadows::Pcf, SoftShadows::Hard];
                    sweep.cluster_soft = Some(parse_each(&flag, &values, |v| named(v, &all, soft_name))?);
                }
                "cluster_maps" => {
                    duplicate(sweep.cluster_maps.is_some())?;
                    let all = [ShadowMapSource::Raster, ShadowMapSource::Ism];
                    sweep.cluster_maps = Some(parse_each(&flag, &values, |v| named(v, &all, maps_name))?);
                }
                "neighbours" | "neighbors" => {
                    duplicate(sweep.neighbours.is_some())?;
                    let max = crate::scene::MAX_NEIGHBOURS;
                    sweep.neighbours = Some(parse_each(&flag, &values, |v| int_in(v, 1, max))?);
                }
                _ => {
                    return Err(flag_error(&flag, format!("unknown axis; the axes are {}", AXES.join(", "))));
                }
            }
        }
        Ok(sweep)
    }

    /// The configurations: each swept axis varied alone around `base` (duplicates dropped), or
    /// with `grid` every combination.
    pub fn configs(&self, base: &Config, grid: bool) -> Vec<Config> {
        let mut out: Vec<Config> = Vec::new();
        let mut push = |c: Config| {
            if !out.contains(&c) {
                out.push(c);
            }
        };
        if grid {
            let neighbours_values =
                self.neighbours.clone().map_or(vec![base.neighbours], |v| v.into_iter().map(Some).collect());
            let sparse_values = self
                .sparse_points
                .clone()
                .map_or(vec![base.sparse_points_per_mesh], |v| v.into_iter().map(Some).collect());
            let interpolation: Vec<_> = opts(&self.kernel, base.kernel)
                .into_iter()
                .flat_map(|k| opts(&self.bound, base.bound).into_iter().map(move |b| (k, b)))
                .flat_map(|(k, b)| opts(&self.subdivision, base.subdivision).into_iter().map(move |d| (k, b, d)))
                .collect();
            let placements: Vec<_> = sparse_values
                .into_iter()
                .flat_map(|n| opts(&self.adaptive, base.adaptive_percent).into_iter().map(move |a| (n, a)))
                .flat_map(|(n, a)| interpolation.iter().map(move |&(k, b, d)| (n, a, k, b, d)))
                .collect();
            for (sparse, adaptive_percent, kernel, bound, subdivision) in placements {
                for (&neighbours, near_field) in neighbours_values
                    .iter()
                    .flat_map(|k| opts(&self.near_field, base.near_field).into_iter().map(move |n| (k, n)))
                {
                    for (&rsm, glossy_interpolation) in
                        one(&self.rsm_resolution, base.rsm_resolution).iter().flat_map(|r| {
                            opts(&self.glossy_interpolation, base.glossy_interpolation).into_iter().map(move |g| (r, g))
                        })
                    {
                        for &glossy in &one(&self.glossy, base.glossy) {
                            for &(width, height) in &one(&self.resolution, (base.width, base.height)) {
                                for &occlusion in &one(&self.occlusion, base.occlusion) {
                                    for ism in self.mode_variants(base) {
                                        let c = Config {
                                            sparse_points_per_mesh: sparse,
                                            adaptive_percent,
                                            kernel,
                                            bound,
                                            subdivision,
                                            neighbours,
                                            near_field,
                                            glossy_interpolation,
                                            rsm_resolution: rsm,
                                            occlusion,
                                            glossy,
                                            width,
                                            height,
                                            ..ism
                                        };
                                        // A mode's values only mean something in that mode.
                                        let c = if occlusion == Occlusion::Ism { c } else { c.without_ism() };
                                        push(if occlusion == Occlusion::Clusters {
                                            c
                                        } else {
                                            Config { clusters: ClusterOverrides::NONE, ..c }
                                        });
                                    }
                                }
                            }
                        }
                    }
                }
            }
            return out;
        }
        push(*base);
        for &v in self.sparse_points.iter().flatten() {
            push(Config { sparse_points_per_mesh: Some(v), ..*base });
        }
        for &v in self.neighbours.iter().flatten() {
            push(Config { neighbours: Some(v), ..*base });
        }
        for &v in self.near_field.iter().flatten() {
            push(Config { near_field: Some(v), ..*base });
        }
        for &v in self.glossy_interpolation.iter().flatten() {
            push(Config { glossy_interpolation: Some(v), ..*base });
        }
        for &v in self.adaptive.iter().flatten() {
            push(Config { adaptive_percent: Some(v), ..*base });
        }
        for &v in self.kernel.iter().flatten() {
            push(Config { kernel: Some(v), ..*base });
        }
        for &v in self.bound.iter().flatten() {
            push(Config { bound: Some(v), ..*base });
        }
        for &v in self.subdivision.iter().flatten() {
            push(Config { subdivision: Some(v), ..*base });
        }
        for &v in self.rsm_resolution.iter().flatten() {
            push(Config { rsm_resolution: v, ..*base });
        }
        for &v in self.occlusion.iter().flatten() {
            push(Config { occlusion: v, ..*base });
        }
        for &v in self.glossy.iter().flatten() {
            push(Config { glossy: v, ..*base });
        }
        for &(width, height) in self.resolution.iter().flatten() {
            push(Config { width, height, ..*base });
        }
        let ism = Config { occlusion: Occlusion::Ism, ..*base };
        for &v in self.ism_count.iter().flatten() {
            push(Config { ism_count: Some(v), ..ism });
        }
        for &v in self.ism_resolution.iter().flatten() {
            push(Config { ism_resolution: Some(v), ..ism });
        }
        for &v in self.ism_points.iter().flatten() {
            push(Config { ism_points: Some(v), ..ism });
        }
        for &v in self.ism_pull_push_levels.iter().flatten() {
            push(Config { ism_pull_push_levels: Some(v), ..ism });
        }
        let clusters = Config { occlusion: Occlusion::Clusters, ..*base };
        let with = |o: ClusterOverrides| Config { clusters: o, ..clusters };
        for &v in self.cluster_count.iter().flatten() {
            push(with(ClusterOverrides { count: Some(v), ..base.clusters }));
        }
        for &v in self.cluster_resolution.iter().flatten() {
            push(with(ClusterOverrides { shadow_map_resolution: Some(v), ..base.clusters }));
        }
        for &v in self.cluster_soft.iter().flatten() {
            push(with(ClusterOverrides { soft: Some(v), ..base.clusters }));
        }
        for &v in self.cluster_maps.iter().flatten() {
            push(with(ClusterOverrides { shadow_maps: Some(v), ..base.clusters }));
        }
        out
    }

    /// Every combination of the ISM and cluster axes' values as overrides on `base` (the grid).
    fn mode_variants(&self, base: &Config) -> Vec<Config> {
        let mut out = Vec::new();
        for ism_count in opts(&self.ism_count, base.ism_count) {
            for ism_resolution in opts(&self.ism_resolution, base.ism_resolution) {
                for ism_points in opts(&self.ism_points, base.ism_points) {
                    for ism_pull_push_levels in opts(&self.ism_pull_push_levels, base.ism_pull_push_levels) {
                        for clusters in self.cluster_variants(&base.clusters) {
                            out.push(Config {
                                ism_count,
                                ism_resolution,
                                ism_points,
                                ism_pull_push_levels,
                                clusters,
                                ..*base
                            });
                        }
                    }
                }
            }
        }
        out
    }

    /// Every combination of the cluster axes' values as overrides on `base`.
    fn cluster_variants(&self, base: &ClusterOverrides) -> Vec<ClusterOverrides> {
        let mut out = Vec::new();
        for count in opts(&self.cluster_count, base.count) {
            for shadow_map_resolution in opts(&self.cluster_resolution, base.shadow_map_resolution) {
                for soft in opts(&self.cluster_soft, base.soft) {
                    for shadow_maps in opts(&self.cluster_maps, base.shadow_maps) {
                        out.push(ClusterOverrides { count, shadow_map_resolution, soft, shadow_maps });
                    }
                }
            }
        }
        out
    }
}

impl Config {
    fn without_ism(self) -> Config {
        Config { ism_count: None, ism_resolution: None, ism_points: None, ism_pull_push_levels: None, ..self }
    }
}

/// The values of an override axis as overrides, or the base override alone when it is not swept.
fn opts<T: Copy>(values: &Option<Vec<T>>, base: Option<T>) -> Vec<Option<T>> {
    values.as_ref().map_or(vec![base], |v| v.iter().copied().map(Some).collect())
}

/// The values of an axis, or the base value alone when it is not swept.
fn one<T: Clone>(values: &Option<Vec<T>>, base: T) -> Vec<T> {
    values.clone().unwrap_or_else(|| vec![base])
}

fn parse_each<T>(flag: &str, values: &[&str], f: impl Fn(&str) -> Result<T, String>) -> Result<Vec<T>, BenchError> {
    values.iter().map(|v| f(v).map_err(|m| flag_error(flag, format!("`{v}`: {m}")))).collect()
}

/// The one of `all` whose `name` is `v`; the error lists the names (`expected `a`, `b` or `c``).
fn named<T: Copy>(v: &str, all: &[T], name: fn(T) -> &'static str) -> Result<T, String> {
    all.iter().copied().find(|x| name(*x) == v).ok_or_else(|| {
        let names: Vec<String> = all.iter().map(|x| format!("`{}`", name(*x))).collect();
        match names.split_last() {
            Some((last, [])) => format!("expected {last}"),
            Some((last, rest)) => format!("expected {} or {last}", rest.join(", ")),
            None => "no value is accepted".to_owned(),
        }
    })
}

/// An `adaptive` value: a fraction in [`crate::scene::ADAPTIVE_RANGE`] in steps of 0.01, as
/// hundredths.
fn hundredths(v: &str) -> Result<u32, String> {
    let (lo, hi) = crate::scene::ADAPTIVE_RANGE;
    let x: f64 = v.trim().parse().map_err(|_| format!("`{v}` is not a number"))?;
    let n = (x * 100.0).round();
    if !(f64::from(lo)..=f64::from(hi)).contains(&x) || (x * 100.0 - n).abs() > 1e-6 {
        return Err(format!("must be in [{lo}, {hi}] in steps of 0.01"));
    }
    Ok(n as u32)
}

fn int_in(v: &str, lo: u32, hi: u32) -> Result<u32, String> {
    let n: u32 = v.parse().map_err(|_| format!("not a whole number in {lo}..={hi}"))?;
    if (lo..=hi).contains(&n) { Ok(n) } else { Err(format!("must be in {lo}..={hi}")) }
}

/// `WxH` or `N` (square).
fn parse_resolution(v: &str) -> Result<(u32, u32), String> {
    match v.split_once(['x', 'X']) {
        Some((w, h)) => Ok((int_in(w, 1, MAX_SIDE)?, int_in(h, 1, MAX_SIDE)?)),
        None => {
            let n = int_in(v, 1, MAX_SIDE)?;
            Ok((n, n))
        }
    }
}

/// What `relume bench` was asked to do.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    pub scene: PathBuf,
    pub sweep: Sweep,
    pub grid: bool,
    /// A tiny sweep at a tiny resolution that runs in seconds (CI's smoke test).
    pub quick: bool,
    /// Also compare against exact visibility, computed as these options say (checked with
    /// [`compare::ExactOptions::check`]); on the device `compare` would choose.
    pub exact: Option<compare::ExactOptions>,
    /// With `exact`: the converging estimator's sample counts for the speed at equal error
    /// ([`equal_error`]), each in `2..=MAX_VAL_SAMPLES`.
    pub equal_error: Option<Vec<u32>>,
    /// Render the brute-force reference and report the error against it.
    pub references: bool,
    /// The paper's Table 1 configurations on scenes built from this one ([`table1`]); the
    /// sweep axes do not apply.
    pub table1: bool,
    pub out: PathBuf,
    /// Also measure the FMA-bound kernel against the gather ([`fma::measure`]).
    pub fma: bool,
    /// Also measure temporal stability ([`temporal::measure`]).
    pub temporal: bool,
    pub plots: bool,
}

/// The quick sweep's base resolution and the axes it sweeps when none are given.
const QUICK_SIDE: u32 = 32;
const QUICK_SPARSE: [u32; 2] = [32, 128];
const QUICK_RSM: [u32; 2] = [8, 16];

impl BenchOptions {
    /// The base configuration (the scene's settings; with `quick`, 32 sparse points per mesh,
    /// R = 8 and 32x32 unless the sweep gives a resolution) and the configurations.
    pub fn configs(&self, description: &SceneDescription, scene: &Scene) -> Vec<Config> {
        let mut base = Config {
            sparse_points_per_mesh: None,
            neighbours: None,
            near_field: None,
            glossy_interpolation: None,
            adaptive_percent: None,
            kernel: None,
            bound: None,
            subdivision: None,
            rsm_resolution: scene.settings.rsm_resolution,
            occlusion: scene.settings.occlusion,
            glossy: scene.settings.glossy,
            width: description.camera.width,
            height: description.camera.height,
            ism_count: None,
            ism_resolution: None,
            ism_points: None,
            ism_pull_push_levels: None,
            clusters: ClusterOverrides::NONE,
        };
        let mut sweep = self.sweep.clone();
        if self.quick {
            base.sparse_points_per_mesh = Some(QUICK_SPARSE[0]);
            base.rsm_resolution = QUICK_RSM[0];
            (base.width, base.height) = (QUICK_SIDE, QUICK_SIDE);
            if sweep == Sweep::default() {
                sweep.sparse_points = Some(QUICK_SPARSE.to_vec());
                sweep.rsm_resolution = Some(QUICK_RSM.to_vec());
                sweep.occlusion = Some(vec![Occlusion::Off, Occlusion::Disks]);
            }
        }
        sweep.configs(&base, self.grid)
    }
}

/// Everything measured for one configuration.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ConfigResult {
    /// `scene` (the scene file), or the built scene (`--table1`: `table1_200k`, `table1_730k`).
    pub variant: String,
    #[serde(flatten)]
    pub config: Config,
    /// Whether the glossy stages ran (glossy allowed and a glossy material present).
    pub glossy_active: bool,
    /// Sparse points each vertex interpolated from (the configuration's, or the scene's).
    pub interpolation_neighbours: u32,
    pub sparse_points: usize,
    pub triangles: usize,
    pub vertices: usize,
    /// VALs with non-zero flux in the frame.
    pub vals: u32,
    pub pixels: u64,
    pub covered_pixels: usize,
    pub timing: TimingSource,
    /// Every stage of the sparse frame (after a warm-up frame), ms.
    pub stages_ms: Vec<(String, f64)>,
    /// `gather + occlusion + renormalise + interpolate + shade` (as `compare`'s `sparse_ms`).
    pub sparse_indirect_ms: f64,
    /// Every stage of the frame, RSM, visibility and direct light included.
    pub frame_ms: f64,
    /// `None` without references (`--table1`).
    pub brute_force_ms: Option<f64>,
    /// `brute_force_ms / sparse_indirect_ms`.
    pub speedup: Option<f64>,
    /// VAL-receiver interactions of the gather per second (VALs x sparse points / gather time).
    pub gather_interactions_per_s: f64,
    /// Device memory in buffers and textures after the sparse frame ([`Gpu::memory_in_use`]).
    pub gpu_memory: MemoryInUse,
    pub gpu_memory_bytes: u64,
    /// The sparse indirect image against the brute force (as `compare`'s `indirect_rel_rmse`
    /// and `indirect_flip_mean`). With occlusion on this includes the occlusion's darkening,
    /// which the brute force (no visibility) lacks: compare against exact for occlusion.
    pub vs_brute_force: Option<IndirectError>,
    /// Against exact visibility, with `--reference exact`.
    pub vs_exact: Option<IndirectError>,
    /// `--table1`: the paper's frames per second for this configuration (AMD Radeon 7870).
    pub paper_fps: Option<u32>,
    pub exact_ms: Option<f64>,
    /// Where the exact reference ran (`cpu` or `gpu`).
    pub exact_device: Option<compare::ReferenceDevice>,
    /// The exact reference's own relative noise `sqrt(sum s² / sum |g|²)` (0 with every VAL at
    /// the pixel centre; `None` for a stride, whose noise is not estimated).
    pub exact_rel_stderr: Option<f64>,
    /// `vs_exact`'s relative RMSE corrected for the reference's noise.
    pub rel_rmse_vs_exact_corrected: Option<f64>,
    /// CPU reference: shadow rays per second (BVH build included).
    pub exact_rays_per_s: Option<f64>,
    /// With `--equal-error`: the time the converging estimator needs for this configuration's
    /// error against exact, and the speed-up (`equal_error_curves` holds the estimator's curve).
    pub at_equal_error: Option<equal_error::AtEqualError>,
}

/// `brute_force_ism` ([`Method::BruteForceIsm`]: the brute force with every VAL weighted by
/// its group's imperfect-shadow-map lookup at the pixel) at one size with one set of `ism`
/// settings: the ISMs' own error without the sparse interpolation, the per-pixel ISM point
/// beside the sparse `ism` configurations. Rendered once per (renderer, size, `ism` settings)
/// that the sweep's `ism` configurations use, with the references (one frame, as the brute
/// force).
#[derive(Clone, Debug, serde::Serialize)]
pub struct BruteForceIsmResult {
    pub variant: String,
    /// The first `ism` configuration measured with these settings (its label names them).
    pub config: Config,
    /// The settings the maps were built with (the scene's with the configuration's overrides).
    pub ism: IsmSettings,
    pub timing: TimingSource,
    /// Every stage of its frame, ms.
    pub stages_ms: Vec<(String, f64)>,
    /// Its groups', maps' and lookup's stages (`brute_force_ism_sampling`, `_splat`,
    /// `_pull_push`, `_visibility`), ms.
    pub ism_ms: f64,
    /// Its indirect stages: the ISM stages and `brute_force`, ms.
    pub indirect_ms: f64,
    /// Against the brute force (no visibility): the darkening the maps add.
    pub vs_brute_force: Option<IndirectError>,
    /// Against exact visibility, with `--reference exact`.
    pub vs_exact: Option<IndirectError>,
    /// `vs_exact`'s relative RMSE corrected for the reference's noise.
    pub rel_rmse_vs_exact_corrected: Option<f64>,
}

impl BruteForceIsmResult {
    /// As [`ConfigResult::error_vs_exact`].
    pub fn error_vs_exact(&self) -> Option<f64> {
        self.rel_rmse_vs_exact_corrected.or(self.vs_exact.map(|e| e.rel_rmse))
    }
}

impl ConfigResult {
    /// The error against exact visibility with the reference's noise taken out where it is
    /// known (`rel_rmse_vs_exact_corrected`), else the raw one; `None` without the reference.
    pub fn error_vs_exact(&self) -> Option<f64> {
        self.rel_rmse_vs_exact_corrected.or(self.vs_exact.map(|e| e.rel_rmse))
    }
}

/// A bench run's results (`results.json`).
#[derive(Clone, Debug, serde::Serialize)]
pub struct BenchResults {
    pub scene: String,
    pub adapter: String,
    /// Where stage times come from: `gpu_timestamps` or `wall_clock` (each stage submitted and
    /// waited for alone; lavapipe's timestamps are not trusted).
    pub timing: TimingSource,
    pub gpu_memory_note: &'static str,
    pub mode: &'static str,
    pub quick: bool,
    /// With `--reference exact`: every n-th VAL (1: all).
    pub exact_val_stride: Option<u32>,
    /// With `--reference exact`: "all", "stride" or "importance".
    pub exact_estimator: Option<&'static str>,
    pub configs: Vec<ConfigResult>,
    /// `brute_force_ism` at each size and `ism` settings the configurations used (with the
    /// references; `brute_force_ism.csv`).
    pub brute_force_ism: Vec<BruteForceIsmResult>,
    /// With `--equal-error`: the converging estimator's error against time, per image size.
    pub equal_error_curves: Vec<equal_error::EqualErrorCurve>,
    /// The gather's throughput against an FMA-bound kernel, on the base configuration.
    pub fma: Option<fma::FmaReport>,
    /// Temporal stability on the base configuration.
    pub temporal: Option<temporal::TemporalReport>,
}

pub const GPU_MEMORY_NOTE: &str = "live device memory of every buffer and texture relume holds after the timed sparse \
     frame (wgpu's internal counters: the sizes of the driver allocations, alignment included; pipelines and driver \
     overhead not counted); the reference passes' buffers are released before";

/// What a renderer is built for: sparse points per mesh, RSM resolution, glossy.
/// What is decided when the scene loads: sparse points per mesh, neighbours, adaptive
/// hundredths, subdivision.
type Placement = (Option<u32>, Option<u32>, Option<u32>, Option<u32>);

/// The sparse method's settings that need a new renderer but not a new scene: near field,
/// glossy interpolation, kernel, bound.
type Shading = (Option<u32>, Option<GlossyInterpolation>, Option<InterpolationKernel>, Option<LightBound>);

/// What needs a new renderer: the placement, the shading, RSM size, glossy.
type RendererKey = (Placement, Shading, u32, bool);

/// Run the sweep and write `results.json`, `results.csv` and (with `plots`) the plots into
/// `options.out`. `progress` is told each configuration as it starts.
pub fn run(gpu: &Gpu, options: &BenchOptions, progress: &mut dyn FnMut(&str)) -> Result<BenchResults, BenchError> {
    if let Some(exact) = &options.exact {
        exact.check().map_err(|message| {
            let (flag, why) = message.split_once(": ").unwrap_or(("--reference", message.as_str()));
            flag_error(flag, why)
        })?;
    }
    match (&options.equal_error, &options.exact) {
        (Some(_), None) => return Err(flag_error("--equal-error", "needs --reference exact")),
        (Some(samples), Some(_)) => {
            let max = crate::twin::exact_cpu::MAX_VAL_SAMPLES;
            if let Some(n) = samples.iter().find(|n| !(2..=max).contains(*n)) {
                return Err(flag_error("--equal-error", format!("sample counts must be in 2..={max}, got {n}")));
            }
            if samples.is_empty() {
                return Err(flag_error("--equal-error", "needs at least one sample count"));
            }
        }
        _ => {}
    }
    let path = &options.scene;
    let text = std::fs::read_to_string(path).map_err(|source| BenchError::Read { path: path.clone(), source })?;
    let scene_error = |source| BenchError::Scene { path: path.clone(), source };
    let description = SceneDescription::from_json_str(&text).map_err(scene_error)?;
    let base_dir = path.parent().unwrap_or_else(|| Path::new(".")).to_path_buf();
    let scene = Scene::from_description(&description, &base_dir).map_err(scene_error)?;
    if scene.light.is_none() {
        return Err(flag_error(
            &path.display().to_string(),
            "light: required by `bench` (its VALs come from the spot light's RSM)",
        ));
    }
    std::fs::create_dir_all(&options.out)
        .map_err(|e| flag_error("--out", format!("creating {}: {e}", options.out.display())))?;
    let jobs = if options.table1 {
        let jobs = table1::jobs(&description, &scene, options.quick);
        // The built scenes, for runs of single configurations (`bench <file> --no-references`).
        for job in &jobs {
            let file = options.out.join(format!("{}.json", job.variant));
            let d = table1::with_absolute_paths(&job.description, &base_dir);
            write_file(&file, serde_json::to_string_pretty(&d).expect("scenes serialise").as_bytes())?;
        }
        jobs
    } else {
        vec![Job { variant: "scene".to_owned(), configs: options.configs(&description, &scene), description }]
    };
    let mut results = Vec::new();
    let mut per_pixel_ism = Vec::new();
    let mut curves = Vec::new();
    let mut timing = None;
    let mut base_scene = None;
    for job in &jobs {
        let mut out = JobOutputs { results: &mut results, brute_force_ism: &mut per_pixel_ism, curves: &mut curves };
        let base = run_job(gpu, options, job, &base_dir, &mut out, progress).map_err(|e| match e {
            BenchError::Scene { source, .. } => BenchError::Scene { path: path.clone(), source },
            e => e,
        })?;
        base_scene.get_or_insert(base);
    }
    for r in &results {
        timing.get_or_insert(r.timing);
    }
    // The extra measurements use the first job's base configuration (its first).
    let base_scene = base_scene.unwrap_or(scene);
    // The extra measurements use the base configuration (the first).
    let fma = if options.fma {
        progress("FMA-bound kernel and gather variants");
        Some(fma::measure(gpu, &base_scene, options.quick)?)
    } else {
        None
    };
    let temporal = if options.temporal {
        progress("temporal stability");
        Some(temporal::measure(gpu, &base_scene, options.quick)?)
    } else {
        None
    };
    let results = BenchResults {
        scene: base_scene.meshes.iter().map(|m| m.name.as_str()).collect::<Vec<_>>().join("+"),
        adapter: gpu.adapter_name(),
        timing: timing.unwrap_or(if gpu.timestamps { TimingSource::GpuTimestamps } else { TimingSource::WallClock }),
        gpu_memory_note: GPU_MEMORY_NOTE,
        mode: if options.table1 {
            "table1"
        } else if options.grid {
            "grid"
        } else {
            "one_axis_at_a_time"
        },
        quick: options.quick,
        exact_val_stride: options.exact.map(|e| e.val_stride),
        exact_estimator: options.exact.map(|e| e.estimator()),
        configs: results,
        brute_force_ism: per_pixel_ism,
        equal_error_curves: curves,
        fma,
        temporal,
    };
    write_results(&options.out, &results)?;
    if options.plots {
        plot::write_all(&options.out, &results)
            .map_err(|message| BenchError::Write { path: options.out.clone(), message })?;
    }
    Ok(results)
}

/// Scenes and configurations to run: the scene file with the sweep's configurations, or the
/// scenes [`table1`] builds.
pub struct Job {
    /// `scene`, or which built scene (e.g. `table1_200k`).
    pub variant: String,
    pub description: SceneDescription,
    pub configs: Vec<Config>,
}

/// What [`run_job`] appends to.
struct JobOutputs<'a> {
    results: &'a mut Vec<ConfigResult>,
    brute_force_ism: &'a mut Vec<BruteForceIsmResult>,
    curves: &'a mut Vec<equal_error::EqualErrorCurve>,
}

/// Run `job`'s configurations, appending to `out`; returns the scene of its first
/// configuration (the base of the extra measurements).
fn run_job(
    gpu: &Gpu,
    options: &BenchOptions,
    job: &Job,
    base_dir: &Path,
    out: &mut JobOutputs<'_>,
    progress: &mut dyn FnMut(&str),
) -> Result<Scene, BenchError> {
    let JobOutputs { results, brute_force_ism, curves } = out;
    let scene_error = |source| BenchError::Scene { path: PathBuf::new(), source };
    // Group by what needs a new renderer (sparse points, RSM size, glossy), then by size.
    let mut groups: Vec<(RendererKey, Vec<Config>)> = Vec::new();
    for c in &job.configs {
        let key = (
            (c.sparse_points_per_mesh, c.neighbours, c.adaptive_percent, c.subdivision),
            (c.near_field, c.glossy_interpolation, c.kernel, c.bound),
            c.rsm_resolution,
            c.glossy,
        );
        match groups.iter_mut().find(|(k, _)| *k == key) {
            Some((_, g)) => g.push(*c),
            None => groups.push((key, vec![*c])),
        }
    }
    // Scenes by what is decided at load: sparse points, neighbours, adaptive candidates.
    let mut scenes: HashMap<Placement, Scene> = HashMap::new();
    let mut base_scene = None;
    for ((placement, shading, rsm, glossy), group) in groups {
        let (sparse, neighbours, adaptive, subdivision) = placement;
        let (near_field, glossy_interpolation, kernel, bound) = shading;
        let mut scene = match scenes.get(&placement) {
            Some(s) => s.clone(),
            None => {
                let mut d = job.description.clone();
                if let Some(n) = sparse {
                    d.meshes.iter_mut().for_each(|m| m.sparse_points = n);
                }
                if let Some(k) = neighbours {
                    d.settings.tuning.interpolation_neighbours = Some(k);
                }
                if let Some(a) = adaptive {
                    d.settings.tuning.sparse.get_or_insert_default().adaptive = Some(a as f32 / 100.0);
                }
                if let Some(n) = subdivision {
                    d.settings.tuning.sparse.get_or_insert_default().subdivision = Some(n as f32);
                }
                let s = Scene::from_description(&d, base_dir).map_err(scene_error)?;
                scenes.insert(placement, s.clone());
                s
            }
        };
        scene.settings.rsm_resolution = rsm;
        scene.settings.glossy = glossy;
        if let Some(n) = near_field {
            scene.settings.sparse.near_field = n as f32;
        }
        if let Some(g) = glossy_interpolation {
            scene.settings.sparse.glossy_interpolation = g;
        }
        if let Some(k) = kernel {
            scene.settings.sparse.kernel = k;
        }
        if let Some(b) = bound {
            scene.settings.sparse.bound = b;
        }
        scene.settings.occlusion = group[0].occlusion;
        base_scene.get_or_insert_with(|| scene.clone());
        let mut renderer = Renderer::new(gpu, &scene)?;
        let mut sizes: Vec<(u32, u32)> = group.iter().map(|c| (c.width, c.height)).collect();
        sizes.dedup();
        for (w, h) in sizes {
            let mut sparse_frames = Vec::new();
            for c in group.iter().filter(|c| (c.width, c.height) == (w, h)) {
                progress(&format!("{}: {}", job.variant, describe(c)));
                let ism = c.ism_settings(&scene.settings.ism);
                ism.validate("settings.ism").map_err(|e| flag_error("--sweep", format!("{}: {e}", describe(c))))?;
                let clusters = c.clusters.apply(&scene.settings.clusters);
                clusters
                    .validate("settings.clusters")
                    .map_err(|e| flag_error("--sweep", format!("{}: {e}", describe(c))))?;
                renderer.set_visibility(VisibilitySettings {
                    mode: c.occlusion,
                    rule: scene.settings.occlusion_rule,
                    clusters,
                    ism,
                });
                let frame = compare::sparse_frame(gpu, &mut renderer, w, h)?;
                sparse_frames.push((*c, frame, gpu.memory_in_use()));
            }
            let brute = match options.references {
                true => Some(compare::brute_force_frame(gpu, &mut renderer, w, h)?),
                false => None,
            };
            let exact = match &options.exact {
                Some(exact) => Some(compare::exact_reference(gpu, &mut renderer, w, h, exact)?),
                None => None,
            };
            // The per-pixel ISM point: once per `ism` settings the sparse `ism` configurations
            // of this size used.
            if options.references {
                let mut seen: Vec<IsmSettings> = Vec::new();
                for c in group.iter().filter(|c| (c.width, c.height) == (w, h) && c.occlusion == Occlusion::Ism) {
                    let ism = c.ism_settings(&scene.settings.ism);
                    if seen.contains(&ism) {
                        continue;
                    }
                    seen.push(ism);
                    progress(&format!("{}: brute_force_ism for {}", job.variant, describe(c)));
                    renderer.set_visibility(VisibilitySettings { mode: Occlusion::Ism, ism, ..renderer.visibility() });
                    let frame = renderer.render(gpu, Method::BruteForceIsm, w, h)?;
                    let ism_stages: Vec<&str> =
                        frame.indirect_stages.iter().copied().filter(|s| *s != stage::BRUTE_FORCE).collect();
                    brute_force_ism.push(BruteForceIsmResult {
                        variant: job.variant.clone(),
                        config: *c,
                        ism,
                        timing: frame.timings.source,
                        stages_ms: frame.timings.stages.clone(),
                        ism_ms: frame.timings.total_of(&ism_stages),
                        indirect_ms: frame.indirect_ms(),
                        vs_brute_force: brute.as_ref().map(|b| compare::indirect_error(&frame.indirect, &b.indirect)),
                        vs_exact: exact.as_ref().map(|x| compare::indirect_error(&frame.indirect, x.indirect())),
                        rel_rmse_vs_exact_corrected: exact.as_ref().and_then(|x| x.corrected_rel_rmse(&frame.indirect)),
                    });
                }
            }
            let curve = match (&options.equal_error, &exact) {
                (Some(samples), Some(reference)) => {
                    let label = format!("{}: R {rsm}, glossy {glossy}, {w}x{h}", job.variant);
                    progress(&format!("{label}: converging estimator, samples {samples:?}"));
                    curves.push(equal_error::measure(label, gpu, &mut renderer, w, h, reference, samples)?);
                    curves.last()
                }
                _ => None,
            };
            renderer.release_reference_passes();
            for (config, frame, memory) in sparse_frames {
                let sparse_indirect_ms = frame.indirect_ms();
                let brute_force_ms = brute.as_ref().map(Rendered::indirect_ms);
                let gather_ms = frame.timings.total_of(&[stage::GATHER]);
                let interactions = frame.val_count as f64 * scene.sparse_point_count() as f64;
                let mut result = ConfigResult {
                    variant: job.variant.clone(),
                    config,
                    glossy_active: renderer.glossy(),
                    interpolation_neighbours: scene.settings.interpolation_neighbours,
                    sparse_points: scene.sparse_point_count(),
                    triangles: scene.triangle_count(),
                    vertices: scene.vertex_count(),
                    vals: frame.val_count,
                    pixels: w as u64 * h as u64,
                    covered_pixels: frame.indirect.coverage(),
                    timing: frame.timings.source,
                    frame_ms: frame.timings.stages.iter().map(|(_, ms)| ms).sum(),
                    stages_ms: frame.timings.stages.clone(),
                    sparse_indirect_ms,
                    brute_force_ms,
                    speedup: brute_force_ms.map(|b| b / sparse_indirect_ms),
                    gather_interactions_per_s: interactions / (gather_ms * 1e-3),
                    gpu_memory: memory,
                    gpu_memory_bytes: memory.total_bytes(),
                    vs_brute_force: brute.as_ref().map(|b| compare::indirect_error(&frame.indirect, &b.indirect)),
                    vs_exact: exact.as_ref().map(|x| compare::indirect_error(&frame.indirect, x.indirect())),
                    exact_ms: exact.as_ref().map(|x| x.ms()),
                    exact_device: exact.as_ref().map(|x| x.device),
                    exact_rel_stderr: exact.as_ref().and_then(|x| x.rel_stderr()),
                    rel_rmse_vs_exact_corrected: exact.as_ref().and_then(|x| x.corrected_rel_rmse(&frame.indirect)),
                    exact_rays_per_s: exact.as_ref().and_then(|x| x.rays_per_s()),
                    at_equal_error: None,
                    paper_fps: table1::paper_fps(&job.variant, &config, scene.sparse_point_count()),
                };
                result.at_equal_error =
                    curve.and_then(|c| equal_error::at_error(&c.points, result.error_vs_exact()?, sparse_indirect_ms));
                results.push(result);
            }
        }
    }
    Ok(base_scene.expect("a job has configurations"))
}

/// A configuration in words, for progress lines and plot labels.
pub fn describe(c: &Config) -> String {
    let sparse = c.sparse_points_per_mesh.map_or("scene".to_owned(), |n| n.to_string());
    let neighbours = c.neighbours.map_or(String::new(), |k| format!(", {k} neighbours"));
    let near = c.near_field.map_or(String::new(), |n| format!(", near field {n}"));
    let adaptive = c.adaptive_percent.map_or(String::new(), |a| format!(", adaptive {}", f64::from(a) / 100.0));
    let kernel = c.kernel.map_or(String::new(), |k| format!(", kernel {}", kernel_name(k)));
    let bound = c.bound.map_or(String::new(), |b| format!(", bound {}", bound_name(b)));
    let subdivision = c.subdivision.map_or(String::new(), |d| format!(", subdivision {d}"));
    let glossy_interpolation =
        c.glossy_interpolation.map_or(String::new(), |g| format!(", glossy {}", glossy_interpolation_name(g)));
    format!(
        "sparse/mesh {sparse}{neighbours}{near}{adaptive}{kernel}{bound}{subdivision}{glossy_interpolation}, R {}, occlusion {}, glossy {}, {}x{}",
        c.rsm_resolution,
        match c.occlusion {
            Occlusion::Off => "off",
            Occlusion::Disks => "disks",
            Occlusion::Clusters => "clusters",
            Occlusion::Ism => "ism",
        },
        if c.glossy { "on" } else { "off" },
        c.width,
        c.height
    ) + &if c.has_ism() {
        let v = |o: Option<u32>| o.map_or("scene".to_owned(), |n| n.to_string());
        format!(
            ", ism {} maps of {}, {} points, {} pull-push levels",
            v(c.ism_count),
            v(c.ism_resolution),
            v(c.ism_points),
            v(c.ism_pull_push_levels)
        )
    } else {
        String::new()
    } + &if c.clusters.is_none() {
        String::new()
    } else {
        let o = &c.clusters;
        let v = |o: Option<String>| o.unwrap_or_else(|| "scene".to_owned());
        format!(
            ", clusters {} maps of {}, soft {}, {} maps",
            v(o.count.map(|n| n.to_string())),
            v(o.shadow_map_resolution.map(|n| n.to_string())),
            v(o.soft.map(|s| soft_name(s).to_owned())),
            v(o.shadow_maps.map(|m| maps_name(m).to_owned()))
        )
    }
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<(), BenchError> {
    std::fs::write(path, bytes).map_err(|e| BenchError::Write { path: path.to_path_buf(), message: e.to_string() })
}

/// `results.json`, `results.csv` (one row per configuration, a column per stage) and, when
/// `brute_force_ism` ran, `brute_force_ism.csv` (one row per size and `ism` settings).
pub fn write_results(dir: &Path, results: &BenchResults) -> Result<(), BenchError> {
    let json = serde_json::to_string_pretty(results).expect("results serialise");
    write_file(&dir.join("results.json"), json.as_bytes())?;
    write_file(&dir.join("results.csv"), csv(results).as_bytes())?;
    if !results.brute_force_ism.is_empty() {
        write_file(&dir.join("brute_force_ism.csv"), brute_force_ism_csv(results).as_bytes())?;
    }
    Ok(())
}

/// `brute_force_ism.csv`: per size and `ism` settings, the ISM settings, the stages' times and
/// the errors (empty where a reference did not run).
pub fn brute_force_ism_csv(results: &BenchResults) -> String {
    let mut out = "variant,width,height,ism_count,ism_resolution,ism_points,ism_pull_push_levels,timing,ism_ms,\
                   indirect_ms,rel_rmse_vs_brute_force,flip_mean_vs_brute_force,rel_rmse_vs_exact,\
                   rel_rmse_vs_exact_corrected,flip_mean_vs_exact\n"
        .to_owned();
    let opt = |v: Option<f64>| v.map_or(String::new(), |x| x.to_string());
    for r in &results.brute_force_ism {
        let row = [
            r.variant.clone(),
            r.config.width.to_string(),
            r.config.height.to_string(),
            r.ism.count.to_string(),
            r.ism.resolution.to_string(),
            r.ism.points.map_or_else(|| "auto".to_owned(), |n| n.to_string()),
            r.ism.pull_push_levels.to_string(),
            r.timing.as_str().to_owned(),
            r.ism_ms.to_string(),
            r.indirect_ms.to_string(),
            opt(r.vs_brute_force.map(|e| e.rel_rmse)),
            opt(r.vs_brute_force.map(|e| e.flip_mean)),
            opt(r.vs_exact.map(|e| e.rel_rmse)),
            opt(r.rel_rmse_vs_exact_corrected),
            opt(r.vs_exact.map(|e| e.flip_mean)),
        ];
        out += &(row.join(",") + "\n");
    }
    out
}

/// The CSV table: fixed columns, then `<stage>_ms` for every stage any configuration ran.
pub fn csv(results: &BenchResults) -> String {
    let mut stages: Vec<&str> = Vec::new();
    for r in &results.configs {
        for (name, _) in &r.stages_ms {
            if !stages.contains(&name.as_str()) {
                stages.push(name);
            }
        }
    }
    let mut header: Vec<String> = [
        "variant",
        "sparse_points_per_mesh",
        "neighbours",
        "sparse_points",
        "rsm_resolution",
        "vals",
        "occlusion",
        "glossy",
        "glossy_active",
        "width",
        "height",
        "pixels",
        "covered_pixels",
        "triangles",
        "timing",
        "sparse_indirect_ms",
        "frame_ms",
        "brute_force_ms",
        "speedup",
        "gather_interactions_per_s",
        "gpu_memory_bytes",
        "rel_rmse_vs_brute_force",
        "flip_mean_vs_brute_force",
        "rel_rmse_vs_exact",
        "rel_rmse_vs_exact_corrected",
        "exact_rel_stderr",
        "flip_mean_vs_exact",
        "exact_ms",
        "exact_device",
        "exact_rays_per_s",
        "equal_error_estimator_ms",
        "speedup_at_equal_error",
        "equal_error_extrapolated",
        "paper_fps",
        "ism_count",
        "ism_resolution",
        "ism_points",
        "ism_pull_push_levels",
        "cluster_count",
        "cluster_resolution",
        "cluster_soft",
        "cluster_maps",
        "near_field",
        "glossy_interpolation",
        "adaptive",
        "kernel",
        "bound",
        "subdivision",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    header.extend(stages.iter().map(|s| format!("{s}_ms")));
    let mut out = header.join(",") + "\n";
    let opt = |v: Option<f64>| v.map_or(String::new(), |x| x.to_string());
    for r in &results.configs {
        let c = &r.config;
        let mut row = vec![
            r.variant.clone(),
            c.sparse_points_per_mesh.map_or(String::new(), |n| n.to_string()),
            r.interpolation_neighbours.to_string(),
            r.sparse_points.to_string(),
            c.rsm_resolution.to_string(),
            r.vals.to_string(),
            format!("{:?}", c.occlusion).to_lowercase(),
            c.glossy.to_string(),
            r.glossy_active.to_string(),
            c.width.to_string(),
            c.height.to_string(),
            r.pixels.to_string(),
            r.covered_pixels.to_string(),
            r.triangles.to_string(),
            r.timing.as_str().to_owned(),
            r.sparse_indirect_ms.to_string(),
            r.frame_ms.to_string(),
            opt(r.brute_force_ms),
            opt(r.speedup),
            r.gather_interactions_per_s.to_string(),
            r.gpu_memory_bytes.to_string(),
            opt(r.vs_brute_force.map(|e| e.rel_rmse)),
            opt(r.vs_brute_force.map(|e| e.flip_mean)),
            opt(r.vs_exact.map(|e| e.rel_rmse)),
            opt(r.rel_rmse_vs_exact_corrected),
            opt(r.exact_rel_stderr),
            opt(r.vs_exact.map(|e| e.flip_mean)),
            opt(r.exact_ms),
            r.exact_device.map_or(String::new(), |d| d.as_str().to_owned()),
            opt(r.exact_rays_per_s),
            opt(r.at_equal_error.map(|a| a.estimator_ms)),
            opt(r.at_equal_error.map(|a| a.speedup)),
            r.at_equal_error.map_or(String::new(), |a| a.extrapolated.to_string()),
            r.paper_fps.map_or(String::new(), |f| f.to_string()),
        ];
        let ism = |o: Option<u32>| o.map_or(String::new(), |n| n.to_string());
        row.extend([ism(c.ism_count), ism(c.ism_resolution), ism(c.ism_points), ism(c.ism_pull_push_levels)]);
        let o = &c.clusters;
        row.extend([
            ism(o.count),
            ism(o.shadow_map_resolution),
            o.soft.map_or(String::new(), |s| soft_name(s).to_owned()),
            o.shadow_maps.map_or(String::new(), |m| maps_name(m).to_owned()),
            ism(c.near_field),
            c.glossy_interpolation.map_or(String::new(), |g| glossy_interpolation_name(g).to_owned()),
            c.adaptive_percent.map_or(String::new(), |a| (f64::from(a) / 100.0).to_string()),
            c.kernel.map_or(String::new(), |k| kernel_name(k).to_owned()),
            c.bound.map_or(String::new(), |b| bound_name(b).to_owned()),
            ism(c.subdivision),
        ]);
        row.extend(stages.iter().map(|s| opt(r.stages_ms.iter().find(|(n, _)| n == s).map(|(_, ms)| *ms))));
        out += &(row.join(",") + "\n");
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(a: &[&str]) -> Vec<String> {
        a.iter().map(|s| s.to_string()).collect()
    }

    const BASE: Config = Config {
        sparse_points_per_mesh: None,
        neighbours: None,
        near_field: None,
        glossy_interpolation: None,
        adaptive_percent: None,
        kernel: None,
        bound: None,
        subdivision: None,
        rsm_resolution: 64,
        occlusion: Occlusion::Off,
        glossy: true,
        width: 100,
        height: 50,
        ism_count: None,
        ism_resolution: None,
        ism_points: None,
        ism_pull_push_levels: None,
        clusters: ClusterOverrides::NONE,
    };

    #[test]
    fn sweep_parses_every_axis() {
        let s = Sweep::parse(&args(&[
            "sparse_points=256,1024",
            "rsm_resolution=32",
            "occlusion=off,disks",
            "glossy=on,off",
            "resolution=64,320x240",
        ]))
        .unwrap();
        assert_eq!(s.sparse_points, Some(vec![256, 1024]));
        assert_eq!(s.rsm_resolution, Some(vec![32]));
        assert_eq!(s.occlusion, Some(vec![Occlusion::Off, Occlusion::Disks]));
        assert_eq!(s.glossy, Some(vec![true, false]));
        assert_eq!(s.resolution, Some(vec![(64, 64), (320, 240)]));
    }

    #[test]
    fn sweep_errors_name_the_axis_and_value() {
        for (arg, wanted) in [
            ("sparse_points=0", "--sweep sparse_points: `0`: must be in 1..=65536"),
            ("sparse_points=12k", "--sweep sparse_points: `12k`: not a whole number"),
            ("rsm_resolution=4", "--sweep rsm_resolution: `4`: must be in 8..=2048"),
            ("occlusion=on", "--sweep occlusion: `on`: expected `off`, `disks`, `clusters` or `ism`"),
            ("glossy=maybe", "--sweep glossy: `maybe`"),
            ("resolution=0x10", "--sweep resolution: `0x10`: must be in 1..=8192"),
            ("resolution=64,", "--sweep resolution: empty value"),
            ("speed=1", "--sweep speed: unknown axis"),
            ("neighbours=4,17", "--sweep neighbours: `17`: must be in 1..=16"),
            ("near_field=0,9", "--sweep near_field: `9`: must be in 0..=8"),
            ("sparse_points", "--sweep: expected AXIS=V1,V2"),
            ("ism_resolution=48", "--sweep ism_resolution: `48`: must be a power of two in 16..=512"),
            ("ism_count=0", "--sweep ism_count: `0`: must be in 1..=4096"),
            ("ism_points=8", "--sweep ism_points: `8`: must be in 16..=65536"),
            ("ism_pull_push_levels=5", "--sweep ism_pull_push_levels: `5`: must be in 0..=4"),
            ("cluster_count=257", "--sweep cluster_count: `257`: must be in 1..=256"),
            ("cluster_resolution=8", "--sweep cluster_resolution: `8`: must be in 16..=1024"),
            ("cluster_soft=soft", "--sweep cluster_soft: `soft`: expected `pcss`, `pcf` or `hard`"),
            ("cluster_maps=voxels", "--sweep cluster_maps: `voxels`: expected `raster` or `ism`"),
        ] {
            let e = Sweep::parse(&args(&[arg])).unwrap_err().to_string();
            assert!(e.starts_with(wanted), "{arg}: {e}");
        }
        let e = Sweep::parse(&args(&["glossy=on", "glossy=off"])).unwrap_err().to_string();
        assert_eq!(e, "--sweep glossy: given more than once");
    }

    #[test]
    fn one_axis_at_a_time_varies_each_axis_around_the_base() {
        let s = Sweep::parse(&args(&["sparse_points=16,32", "occlusion=off,disks"])).unwrap();
        let c = s.configs(&BASE, false);
        assert_eq!(c.len(), 4, "base, two sparse counts, disks (off is the base): {c:?}");
        assert_eq!(c[0], BASE);
        assert_eq!(c[1].sparse_points_per_mesh, Some(16));
        assert_eq!(c[3], Config { occlusion: Occlusion::Disks, ..BASE });
        let s = Sweep::parse(&args(&["neighbours=4,8,16"])).unwrap();
        let c = s.configs(&BASE, false);
        let k: Vec<Option<u32>> = c.iter().map(|c| c.neighbours).collect();
        assert_eq!(k, [None, Some(4), Some(8), Some(16)]);
        assert_eq!(s.configs(&BASE, true).len(), 3, "the grid replaces the base's count");
    }

    /// The near-field axis: one configuration per radius, and in the grid one per radius for
    /// every other combination.
    #[test]
    fn glossy_interpolation_axis_measures_each_form() {
        let s = Sweep::parse(&args(&["glossy_interpolation=lights,radiance"])).unwrap();
        let g: Vec<Option<GlossyInterpolation>> =
            s.configs(&BASE, false).iter().map(|c| c.glossy_interpolation).collect();
        assert_eq!(g, [None, Some(GlossyInterpolation::Lights), Some(GlossyInterpolation::Radiance)]);
        let s = Sweep::parse(&args(&["glossy_interpolation=radiance", "near_field=0,4"])).unwrap();
        let grid = s.configs(&BASE, true);
        assert_eq!(grid.len(), 2);
        assert!(grid.iter().all(|c| c.glossy_interpolation == Some(GlossyInterpolation::Radiance)));
        let e = Sweep::parse(&args(&["glossy_interpolation=pixel"])).unwrap_err().to_string();
        assert!(e.contains("glossy_interpolation") && e.contains("`lights` or `radiance`"), "{e}");
    }

    /// The adaptive axis: fractions in hundredths, one configuration each, and in the grid one
    /// per sparse point count and fraction; out of range or finer than 0.01 is refused.
    #[test]
    fn adaptive_axis_measures_each_budget() {
        let s = Sweep::parse(&args(&["adaptive=0,0.25,1"])).unwrap();
        let a: Vec<Option<u32>> = s.configs(&BASE, false).iter().map(|c| c.adaptive_percent).collect();
        assert_eq!(a, [None, Some(0), Some(25), Some(100)]);
        let s = Sweep::parse(&args(&["adaptive=0,0.5", "sparse_points=64,128"])).unwrap();
        let grid = s.configs(&BASE, true);
        assert_eq!(grid.len(), 4);
        for e in ["adaptive=1.5", "adaptive=0.125", "adaptive=x"] {
            let e = Sweep::parse(&args(&[e])).unwrap_err().to_string();
            assert!(e.contains("adaptive"), "{e}");
        }
    }

    /// The interpolation's axes: `kernel` and `bound` by name, `subdivision` in whole spacings
    /// within its range; in the grid one configuration per combination.
    #[test]
    fn kernel_bound_and_subdivision_axes_measure_each_value() {
        let s = Sweep::parse(&args(&["kernel=paper,smooth", "bound=off,gathered", "subdivision=1,2"])).unwrap();
        let one = s.configs(&BASE, false);
        assert_eq!(one.len(), 7);
        assert_eq!(one[1].kernel, Some(InterpolationKernel::Paper));
        assert_eq!(one[4].bound, Some(LightBound::Gathered));
        assert_eq!(one[6].subdivision, Some(2));
        assert_eq!(s.configs(&BASE, true).len(), 8);
        for (flag, wanted) in
            [("kernel=linear", "`paper` or `smooth`"), ("bound=on", "`off` or `gathered`"), ("subdivision=0", "1..=16")]
        {
            let e = Sweep::parse(&args(&[flag])).unwrap_err().to_string();
            assert!(e.contains(flag.split('=').next().unwrap()) && e.contains(wanted), "{e}");
        }
    }

    #[test]
    fn near_field_axis_measures_each_radius() {
        let s = Sweep::parse(&args(&["near_field=0,4"])).unwrap();
        let n: Vec<Option<u32>> = s.configs(&BASE, false).iter().map(|c| c.near_field).collect();
        assert_eq!(n, [None, Some(0), Some(4)]);
        let s = Sweep::parse(&args(&["near_field=0,4", "neighbours=4,8"])).unwrap();
        let grid = s.configs(&BASE, true);
        assert_eq!(grid.len(), 4);
        assert!(grid.iter().any(|c| c.near_field == Some(4) && c.neighbours == Some(8)));
    }

    /// An ISM axis measures the `ism` mode at each value; in the grid, ISM values apply only to
    /// the `ism` configurations (the others would repeat themselves).
    #[test]
    fn ism_axes_measure_the_ism_mode() {
        let s = Sweep::parse(&args(&["ism_resolution=32,64", "ism_pull_push_levels=0"])).unwrap();
        let c = s.configs(&BASE, false);
        assert_eq!(c.len(), 4, "{c:?}");
        assert!(c[1..].iter().all(|c| c.occlusion == Occlusion::Ism));
        assert_eq!((c[1].ism_resolution, c[3].ism_pull_push_levels), (Some(32), Some(0)));
        let ism = c[1].ism_settings(&crate::scene::IsmSettings::default());
        assert_eq!((ism.resolution, ism.count), (32, crate::scene::IsmSettings::default().count));
        assert!(
            describe(&c[1]).ends_with("ism scene maps of 32, scene points, scene pull-push levels"),
            "{}",
            describe(&c[1])
        );
        let s = Sweep::parse(&args(&["occlusion=off,ism", "ism_resolution=32,64"])).unwrap();
        let c = s.configs(&BASE, true);
        assert_eq!(c.len(), 3, "off once, ism at two resolutions: {c:?}");
    }

    #[test]
    fn cluster_axes_measure_the_clusters_mode() {
        let s = Sweep::parse(&args(&["cluster_count=8,256", "cluster_soft=hard", "cluster_maps=ism"])).unwrap();
        let c = s.configs(&BASE, false);
        assert_eq!(c.len(), 5, "the base and one per value: {c:?}");
        assert!(c[1..].iter().all(|c| c.occlusion == Occlusion::Clusters));
        let scene = ClusterSettings::default();
        let eight = c[1].clusters.apply(&scene);
        assert_eq!(
            (eight.count, eight.shadow_map_resolution, eight.soft),
            (8, scene.shadow_map_resolution, scene.soft)
        );
        assert_eq!(c[2].clusters.apply(&scene).count, 256);
        assert_eq!(c[3].clusters.apply(&scene).soft, SoftShadows::Hard);
        assert_eq!(c[4].clusters.apply(&scene).shadow_maps, ShadowMapSource::Ism);
        assert!(
            describe(&c[3]).ends_with("clusters scene maps of scene, soft hard, scene maps"),
            "{}",
            describe(&c[3])
        );
        let s = Sweep::parse(&args(&["occlusion=off,clusters", "cluster_resolution=64,512", "cluster_soft=pcss,pcf"]))
            .unwrap();
        let c = s.configs(&BASE, true);
        assert_eq!(c.len(), 5, "off once, clusters at two resolutions and two filters: {c:?}");
        assert!(c.iter().filter(|c| c.occlusion == Occlusion::Off).all(|c| c.clusters.is_none()));
    }

    #[test]
    fn grid_takes_every_combination() {
        let s = Sweep::parse(&args(&["sparse_points=16,32", "rsm_resolution=8,16,32", "glossy=on,off"])).unwrap();
        let c = s.configs(&BASE, true);
        assert_eq!(c.len(), 12);
        assert!(c.iter().all(|c| c.width == 100 && c.occlusion == Occlusion::Off));
    }
}

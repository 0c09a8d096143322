//! The sweep: the values given for each axis (`--sweep`), parsed, and the configurations they
//! make, one axis at a time around the base or (`grid`) every combination.

use super::{BenchError, flag_error};
use crate::scene::{
    GlossyInterpolation, InterpolationKernel, LightBound, MAX_CLUSTERS, MAX_SPARSE_POINTS, Occlusion,
    RSM_RESOLUTION_RANGE, ShadowMapSource, SoftShadows,
};

use super::config::{
    ClusterOverrides, Config, bound_name, glossy_interpolation_name, kernel_name, maps_name, soft_name,
};

/// Most pixels on one side of a bench image (as `render`'s `--width`).
const MAX_SIDE: u32 = 8192;

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
    /// Shadow rays per (sparse point, cluster): measured with `cluster_maps` `rays`.
    pub cluster_rays: Option<Vec<u32>>,
}

/// The axes `--sweep` accepts that override one of the level's research knobs (`tuning`); the
/// bench's CSV has a column of each, named as the axis, in this order.
pub const TUNING_AXES: [&str; 15] = [
    "ism_count",
    "ism_resolution",
    "ism_points",
    "ism_pull_push_levels",
    "cluster_count",
    "cluster_resolution",
    "cluster_soft",
    "cluster_maps",
    "cluster_rays",
    "near_field",
    "glossy_interpolation",
    "adaptive",
    "kernel",
    "bound",
    "subdivision",
];

/// The other axes `--sweep` accepts: the scene's sparse points, the RSM, visibility, glossy and
/// image size.
pub const SCENE_AXES: [&str; 6] =
    ["sparse_points", "neighbours", "rsm_resolution", "occlusion", "glossy", "resolution"];

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
            match axis {
                "sparse_points" => {
                    set_axis(&mut sweep.sparse_points, &flag, &values, |v| int_in(v, 1, MAX_SPARSE_POINTS))?
                }
                "rsm_resolution" => {
                    let (lo, hi) = RSM_RESOLUTION_RANGE;
                    set_axis(&mut sweep.rsm_resolution, &flag, &values, |v| int_in(v, lo, hi))?;
                }
                "occlusion" => {
                    set_axis(&mut sweep.occlusion, &flag, &values, |v| {
                        Occlusion::from_name(v).ok_or_else(|| {
                            let names: Vec<String> = Occlusion::ALL.iter().map(|m| format!("`{}`", m.name())).collect();
                            let (last, rest) = names.split_last().expect("the off mode at least");
                            format!("expected {} or {last}", rest.join(", "))
                        })
                    })?;
                }
                "glossy" => {
                    set_axis(&mut sweep.glossy, &flag, &values, |v| match v {
                        "on" | "true" => Ok(true),
                        "off" | "false" => Ok(false),
                        _ => Err("expected `on` or `off`".to_owned()),
                    })?;
                }
                "resolution" => set_axis(&mut sweep.resolution, &flag, &values, parse_resolution)?,
                "ism_count" => {
                    set_axis(&mut sweep.ism_count, &flag, &values, |v| int_in(v, 1, crate::scene::MAX_ISMS))?
                }
                "ism_resolution" => {
                    set_axis(&mut sweep.ism_resolution, &flag, &values, |v| {
                        let n = int_in(v, 16, 512)?;
                        if n.is_power_of_two() { Ok(n) } else { Err("must be a power of two in 16..=512".to_owned()) }
                    })?;
                }
                "ism_points" => {
                    let max = crate::scene::MAX_ISM_POINTS;
                    set_axis(&mut sweep.ism_points, &flag, &values, |v| int_in(v, 16, max))?;
                }
                "ism_pull_push_levels" => {
                    set_axis(&mut sweep.ism_pull_push_levels, &flag, &values, |v| int_in(v, 0, 4))?
                }
                "near_field" => {
                    let max = crate::scene::NEAR_FIELD_RANGE.1 as u32;
                    set_axis(&mut sweep.near_field, &flag, &values, |v| int_in(v, 0, max))?;
                }
                "adaptive" => set_axis(&mut sweep.adaptive, &flag, &values, hundredths)?,
                "kernel" => {
                    let all = [InterpolationKernel::Paper, InterpolationKernel::Smooth];
                    set_axis(&mut sweep.kernel, &flag, &values, |v| named(v, &all, kernel_name))?;
                }
                "bound" => {
                    let all = [LightBound::Off, LightBound::Gathered];
                    set_axis(&mut sweep.bound, &flag, &values, |v| named(v, &all, bound_name))?;
                }
                "subdivision" => {
                    let (lo, hi) = crate::scene::SUBDIVISION_RANGE;
                    set_axis(&mut sweep.subdivision, &flag, &values, |v| int_in(v, lo as u32, hi as u32))?;
                }
                "glossy_interpolation" => {
                    let all = [GlossyInterpolation::Lights, GlossyInterpolation::Radiance];
                    set_axis(&mut sweep.glossy_interpolation, &flag, &values, |v| {
                        named(v, &all, glossy_interpolation_name)
                    })?;
                }
                "cluster_count" => set_axis(&mut sweep.cluster_count, &flag, &values, |v| int_in(v, 1, MAX_CLUSTERS))?,
                "cluster_resolution" => {
                    set_axis(&mut sweep.cluster_resolution, &flag, &values, |v| int_in(v, 16, 1024))?
                }
                "cluster_soft" => {
                    let all = [SoftShadows::Pcss, SoftShadows::Pcf, SoftShadows::Hard];
                    set_axis(&mut sweep.cluster_soft, &flag, &values, |v| named(v, &all, soft_name))?;
                }
                "cluster_maps" => {
                    let all = [ShadowMapSource::Raster, ShadowMapSource::Ism, ShadowMapSource::Rays];
                    set_axis(&mut sweep.cluster_maps, &flag, &values, |v| named(v, &all, maps_name))?;
                }
                "cluster_rays" => {
                    let max = crate::scene::MAX_CLUSTER_RAYS;
                    set_axis(&mut sweep.cluster_rays, &flag, &values, |v| int_in(v, 1, max))?
                }
                "neighbours" | "neighbors" => {
                    let max = crate::scene::MAX_NEIGHBOURS;
                    set_axis(&mut sweep.neighbours, &flag, &values, |v| int_in(v, 1, max))?;
                }
                _ => {
                    return Err(flag_error(
                        &flag,
                        format!(
                            "unknown axis; the axes are {}",
                            [&SCENE_AXES[..], &TUNING_AXES[..]].concat().join(", ")
                        ),
                    ));
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
        let ism = Config { occlusion: Occlusion::Ism, ..*base };
        let clusters = Config { occlusion: Occlusion::Clusters, ..*base };
        let with = |o: ClusterOverrides| Config { clusters: o, ..clusters };
        // Each axis alone around `base`.
        let alone = [
            each(&self.sparse_points, |v| Config { sparse_points_per_mesh: Some(v), ..*base }),
            each(&self.neighbours, |v| Config { neighbours: Some(v), ..*base }),
            each(&self.near_field, |v| Config { near_field: Some(v), ..*base }),
            each(&self.glossy_interpolation, |v| Config { glossy_interpolation: Some(v), ..*base }),
            each(&self.adaptive, |v| Config { adaptive_percent: Some(v), ..*base }),
            each(&self.kernel, |v| Config { kernel: Some(v), ..*base }),
            each(&self.bound, |v| Config { bound: Some(v), ..*base }),
            each(&self.subdivision, |v| Config { subdivision: Some(v), ..*base }),
            each(&self.rsm_resolution, |v| Config { rsm_resolution: v, ..*base }),
            each(&self.occlusion, |v| Config { occlusion: v, ..*base }),
            each(&self.glossy, |v| Config { glossy: v, ..*base }),
            each(&self.resolution, |(width, height)| Config { width, height, ..*base }),
            each(&self.ism_count, |v| Config { ism_count: Some(v), ..ism }),
            each(&self.ism_resolution, |v| Config { ism_resolution: Some(v), ..ism }),
            each(&self.ism_points, |v| Config { ism_points: Some(v), ..ism }),
            each(&self.ism_pull_push_levels, |v| Config { ism_pull_push_levels: Some(v), ..ism }),
            each(&self.cluster_count, |v| with(ClusterOverrides { count: Some(v), ..base.clusters })),
            each(&self.cluster_resolution, |v| {
                with(ClusterOverrides { shadow_map_resolution: Some(v), ..base.clusters })
            }),
            each(&self.cluster_soft, |v| with(ClusterOverrides { soft: Some(v), ..base.clusters })),
            each(&self.cluster_maps, |v| with(ClusterOverrides { shadow_maps: Some(v), ..base.clusters })),
            each(&self.cluster_rays, |v| {
                with(ClusterOverrides { shadow_maps: Some(ShadowMapSource::Rays), rays: Some(v), ..base.clusters })
            }),
        ];
        alone.into_iter().flatten().for_each(push);
        out
    }

    /// Every combination of the ISM and cluster axes' values as overrides on `base` (the grid).
    fn mode_variants(&self, base: &Config) -> Vec<Config> {
        let mut out = vec![*base];
        vary(&mut out, self.ism_count.as_deref(), |c, v| c.ism_count = Some(v));
        vary(&mut out, self.ism_resolution.as_deref(), |c, v| c.ism_resolution = Some(v));
        vary(&mut out, self.ism_points.as_deref(), |c, v| c.ism_points = Some(v));
        vary(&mut out, self.ism_pull_push_levels.as_deref(), |c, v| c.ism_pull_push_levels = Some(v));
        vary(&mut out, self.cluster_count.as_deref(), |c, v| c.clusters.count = Some(v));
        vary(&mut out, self.cluster_resolution.as_deref(), |c, v| c.clusters.shadow_map_resolution = Some(v));
        vary(&mut out, self.cluster_soft.as_deref(), |c, v| c.clusters.soft = Some(v));
        vary(&mut out, self.cluster_maps.as_deref(), |c, v| c.clusters.shadow_maps = Some(v));
        vary(&mut out, self.cluster_rays.as_deref(), |c, v| c.clusters.rays = Some(v));
        out
    }
}

/// Each of `configs` once per value of a swept axis, set by `set` (the axis varying inside the
/// earlier ones); unchanged when the axis is not swept.
fn vary<T: Copy>(configs: &mut Vec<Config>, values: Option<&[T]>, set: impl Fn(&mut Config, T)) {
    let Some(values) = values else { return };
    let set = &set;
    *configs = configs
        .iter()
        .flat_map(|&c| {
            values.iter().map(move |&v| {
                let mut c = c;
                set(&mut c, v);
                c
            })
        })
        .collect();
}

/// The values of an override axis as overrides, or the base override alone when it is not swept.
fn opts<T: Copy>(values: &Option<Vec<T>>, base: Option<T>) -> Vec<Option<T>> {
    values.as_ref().map_or(vec![base], |v| v.iter().copied().map(Some).collect())
}

/// `config(v)` for each value of an axis (none when it is not swept).
fn each<T: Copy>(values: &Option<Vec<T>>, config: impl Fn(T) -> Config) -> Vec<Config> {
    values.iter().flatten().map(|&v| config(v)).collect()
}

/// The values of an axis, or the base value alone when it is not swept.
fn one<T: Clone>(values: &Option<Vec<T>>, base: T) -> Vec<T> {
    values.clone().unwrap_or_else(|| vec![base])
}

/// `axis` set to `values` parsed by `f`, unless it was given before.
fn set_axis<T>(
    axis: &mut Option<Vec<T>>,
    flag: &str,
    values: &[&str],
    f: impl Fn(&str) -> Result<T, String>,
) -> Result<(), BenchError> {
    if axis.is_some() {
        return Err(flag_error(flag, "given more than once"));
    }
    let parsed = values.iter().map(|v| f(v).map_err(|m| flag_error(flag, format!("`{v}`: {m}"))));
    *axis = Some(parsed.collect::<Result<_, _>>()?);
    Ok(())
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

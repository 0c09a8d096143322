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
mod config;
pub mod equal_error;
pub mod fma;
pub mod levels;
pub mod plot;
mod results;
mod run;
mod sweep;
pub mod table1;
pub mod temporal;

pub use config::{ClusterOverrides, Config, describe};
pub use results::{
    BenchResults, BruteForceIsmResult, ConfigResult, GPU_MEMORY_NOTE, brute_force_ism_csv, csv, write_results,
};
pub use run::{BenchOptions, Job, run};
pub use sweep::{SCENE_AXES, Sweep, TUNING_AXES};

use crate::gpu::GpuError;
use crate::scene::SceneError;
use std::path::PathBuf;

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

pub(crate) fn flag_error(flag: &str, message: impl Into<String>) -> BenchError {
    BenchError::Flag { flag: flag.to_owned(), message: message.into() }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{
        ClusterSettings, GlossyInterpolation, InterpolationKernel, LightBound, Occlusion, ShadowMapSource, SoftShadows,
    };

    fn args(a: &[&str]) -> Vec<String> {
        a.iter().map(|s| s.to_string()).collect()
    }

    const BASE: Config = Config::new(64, Occlusion::Off, true, 100, 50);

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
            ("cluster_maps=voxels", "--sweep cluster_maps: `voxels`: expected `raster`, `ism` or `rays`"),
            ("cluster_rays=0", "--sweep cluster_rays: `0`: must be in 1..=64"),
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
    fn grid_varies_the_later_mode_axes_inside_the_earlier() {
        let s = Sweep::parse(&args(&["occlusion=clusters", "cluster_count=8,256", "cluster_soft=pcss,pcf"])).unwrap();
        let c = s.configs(&BASE, true);
        let axes: Vec<_> = c.iter().map(|c| (c.clusters.count, c.clusters.soft)).collect();
        let (pcss, pcf) = (Some(SoftShadows::Pcss), Some(SoftShadows::Pcf));
        assert_eq!(axes, [(Some(8), pcss), (Some(8), pcf), (Some(256), pcss), (Some(256), pcf)]);
    }

    #[test]
    fn grid_takes_every_combination() {
        let s = Sweep::parse(&args(&["sparse_points=16,32", "rsm_resolution=8,16,32", "glossy=on,off"])).unwrap();
        let c = s.configs(&BASE, true);
        assert_eq!(c.len(), 12);
        assert!(c.iter().all(|c| c.width == 100 && c.occlusion == Occlusion::Off));
    }
}

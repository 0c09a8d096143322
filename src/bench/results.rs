//! What the bench measured, per configuration, and its output files (`results.json`,
//! `results.csv`, `brute_force_ism.csv`).

use super::compare::{self, IndirectError};
use super::{BenchError, equal_error, fma, temporal};
use crate::gpu::MemoryInUse;
use crate::gpu::timing::TimingSource;
use crate::scene::IsmSettings;
use std::path::Path;

use super::config::{Config, bound_name, glossy_interpolation_name, kernel_name, maps_name, soft_name};

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

pub(super) fn write_file(path: &Path, bytes: &[u8]) -> Result<(), BenchError> {
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

/// The CSV's values of the research knobs `c` overrides, in [`super::TUNING_AXES`]' order (empty
/// where it keeps the level's value).
fn tuning_values(c: &Config) -> [String; 15] {
    let n = |o: Option<u32>| o.map_or(String::new(), |n| n.to_string());
    let o = &c.clusters;
    [
        n(c.ism_count),
        n(c.ism_resolution),
        n(c.ism_points),
        n(c.ism_pull_push_levels),
        n(o.count),
        n(o.shadow_map_resolution),
        o.soft.map_or(String::new(), |s| soft_name(s).to_owned()),
        o.shadow_maps.map_or(String::new(), |m| maps_name(m).to_owned()),
        n(o.rays),
        n(c.near_field),
        c.glossy_interpolation.map_or(String::new(), |g| glossy_interpolation_name(g).to_owned()),
        c.adaptive_percent.map_or(String::new(), |a| (f64::from(a) / 100.0).to_string()),
        c.kernel.map_or(String::new(), |k| kernel_name(k).to_owned()),
        c.bound.map_or(String::new(), |b| bound_name(b).to_owned()),
        n(c.subdivision),
    ]
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
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    header.extend(super::TUNING_AXES.map(str::to_owned));
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
        row.extend(tuning_values(c));
        row.extend(stages.iter().map(|s| opt(r.stages_ms.iter().find(|(n, _)| n == s).map(|(_, ms)| *ms))));
        out += &(row.join(",") + "\n");
    }
    out
}

//! `relume bench --levels`: every quality level of one scene, rendered and measured in one run,
//! so that the trade the levels offer is a generated table, not a typed one.
//!
//! One exact reference serves every level: the scene loaded at `reference` (its VALs are the
//! finest any level uses), rendered by the exact reference as `--reference-*` says (every VAL by
//! default; an importance-sampled estimate states its noise, which is taken out of the errors).
//! Each of `fast`, `balanced` and `accurate` is then loaded at its level and rendered four times
//! (the first frame builds and warms its passes); of the other three, the frame of median
//! indirect time is compared with the reference: the relative RMSE (noise-corrected), the same without the worst 1 % of pixels,
//! its indirect time and stages, the frame's own error estimate ([`crate::renderer::estimate`])
//! and, with `--equal-error`, the time the importance-sampled estimator needs to reach the
//! same error ([`super::equal_error`]). The `reference` row is the reference itself.
//!
//! With `--candidates` it also measures the configurations one parameter away from a level,
//! each parameter taking a value another level takes on this scene ([`Knobs`]: visibility,
//! the spot light's RSM, the fraction of sparse points, the near field; a parameter the scene
//! file sets in its `tuning` is left as set), and says of each level which measured
//! configuration **dominates** it: more accurate and at least [`DOMINANCE_SPEEDUP`] times
//! faster. A level so dominated is a wrong choice for this scene. Beside them it measures the
//! brute force through the clusters' maps (`brute_force_clusters`, the technique a measured
//! level may name) with `balanced`'s and `accurate`'s VALs and clusters, at the level's
//! subdivision and at the coarsest (its maps draw fewer triangles; docs/measurements/
//! clustered-visibility.md).

use super::BenchError;
use super::compare::{ExactOptions, ExactReference, ReferenceDevice, exact_reference, rel_rmse_without_worst};
use super::equal_error::{self, AtEqualError, EqualErrorCurve};
use crate::gpu::Gpu;
use crate::renderer::Rendered;
use crate::renderer::estimate::{ErrorEstimate, EstimateOptions, Estimator};
use crate::renderer::{Method as RenderMethod, Renderer};
use crate::scene::settings::SUBDIVISION_RANGE;
use crate::scene::{Occlusion, Quality, ResolvedConfig, Scene};
use std::path::Path;

mod suggest;
pub use suggest::suggest_levels;

/// One level's row of the table.
#[derive(Clone, Debug, serde::Serialize)]
pub struct LevelRow {
    pub level: Quality,
    /// Relative RMSE of the indirect light against the exact reference, corrected for the
    /// reference's noise where it has an estimate of it (0 for `reference` itself).
    pub rel_rmse_vs_exact: f64,
    pub rel_rmse_without_worst_1pct: f64,
    /// The frame's own estimate of `rel_rmse_vs_exact` (`None` for `reference`).
    pub error_estimate: Option<ErrorEstimate>,
    /// `error_estimate.rel_rmse / rel_rmse_vs_exact`.
    pub estimate_ratio: Option<f64>,
    /// The indirect light's stages, ms (the frame of median time of three after the first; the
    /// reference's own time for `reference`).
    pub ms: f64,
    pub stages_ms: Vec<(String, f64)>,
    /// The importance-sampled estimator's time to the same error, ms (with `--equal-error`).
    pub estimator_ms_at_equal_error: Option<f64>,
    pub at_equal_error: Option<AtEqualError>,
    /// What the level resolved to on this scene, with the reasons.
    pub resolved: ResolvedConfig,
    /// The level's parameters that `--candidates` varies.
    pub knobs: Knobs,
    /// With `--candidates`: the measured configurations (other levels and candidates) that
    /// dominate this level, by name; empty when none does.
    pub dominated_by: Vec<String>,
}

/// A configuration is dominated by one both more accurate and at least this many times faster.
pub const DOMINANCE_SPEEDUP: f64 = 1.2;

/// The parameters a level sets that `--candidates` varies (and the subdivision, which it
/// keeps: it is the base level's).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Knobs {
    pub visibility: Occlusion,
    pub rsm_resolution: u32,
    /// `sparse.points`: the fraction of each mesh's sparse points placed.
    pub points: f32,
    /// `sparse.near_field`, in sparse point spacings (0: off).
    pub near_field: f32,
    /// `sparse.near_field_interleave`: the block side the near field is interleaved over (1:
    /// not interleaved).
    pub near_field_interleave: u32,
    pub subdivision: f32,
}

/// The interleaving block `--candidates` tries wherever a level's near field is on or turned
/// on: 4 x 4, which kept most of the near field's gain at a fraction of its cost on Sponza
/// (docs/measurements/sparse-real-scenes.md, the near field interleaved).
pub const CANDIDATE_INTERLEAVE: u32 = 4;

impl Knobs {
    fn of(scene: &Scene) -> Knobs {
        let s = &scene.settings;
        Knobs {
            visibility: s.visibility.mode,
            rsm_resolution: s.rsm_resolution,
            points: s.sparse.points,
            near_field: s.sparse.near_field,
            near_field_interleave: s.sparse.near_field_interleave,
            subdivision: s.sparse.subdivision,
        }
    }

    /// The scene file's `settings.tuning` with these knobs set in it.
    fn tuning(&self, mut tuning: serde_json::Value) -> serde_json::Value {
        if !tuning.is_object() {
            tuning = serde_json::json!({});
        }
        tuning["visibility"] = self.visibility.name().into();
        tuning["rsm_resolution"] = self.rsm_resolution.into();
        if !tuning["sparse"].is_object() {
            tuning["sparse"] = serde_json::json!({});
        }
        tuning["sparse"]["points"] = self.points.into();
        tuning["sparse"]["near_field"] = self.near_field.into();
        tuning["sparse"]["near_field_interleave"] = self.near_field_interleave.into();
        tuning
    }
}

/// One configuration `--candidates` measured: a level with one parameter changed.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CandidateRow {
    /// The level it starts from, and the change, as `level + parameter=value`.
    pub name: String,
    /// The parameters (the reference's, for the GPU estimator, which ignores them).
    pub knobs: Knobs,
    /// How the indirect light was computed: the sparse method, the GPU estimator of the exact
    /// reference (`--gpu-estimator`), or the brute force through the clusters' maps.
    pub method: crate::renderer::Method,
    /// The GPU estimator's draws per pixel (`None` for the sparse method).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub draws: Option<u32>,
    pub rel_rmse_vs_exact: f64,
    pub rel_rmse_without_worst_1pct: f64,
    /// Indirect ms, the median of three frames after a warm-up one (as the levels').
    pub ms: f64,
    pub stages_ms: Vec<(String, f64)>,
}

impl CandidateRow {
    /// The row of configuration `name`, `scene` as measured in `m` by `method`, the figures also
    /// printed as it goes.
    fn of(name: String, scene: &Scene, method: Method, m: &Measured) -> CandidateRow {
        eprintln!("{name}: rel RMSE {:.4}, {:.1} ms", m.error, m.ms);
        let draws = method.draws();
        CandidateRow {
            name,
            knobs: Knobs::of(scene),
            method: method.render_method(),
            draws,
            rel_rmse_vs_exact: m.error,
            rel_rmse_without_worst_1pct: m.without_worst,
            ms: m.ms,
            stages_ms: m.frame.timings.stages.clone(),
        }
    }
}

/// `levels.json`: the rows and what they were measured against.
#[derive(Clone, Debug, serde::Serialize)]
pub struct LevelsReport {
    pub scene: String,
    pub adapter: String,
    pub width: u32,
    pub height: u32,
    /// "all", "stride" or "importance".
    pub reference_estimator: &'static str,
    /// The reference's own relative noise (`None` for a stride, whose noise is not estimated).
    pub reference_rel_stderr: Option<f64>,
    pub reference_ms: f64,
    pub levels: Vec<LevelRow>,
    pub equal_error_curve: Option<EqualErrorCurve>,
    /// With `--candidates`: the configurations one parameter away from a level.
    pub candidates: Vec<CandidateRow>,
    /// With `--candidates`: what to write as the scene file's `settings.levels`
    /// ([`suggest_levels`]); an empty object when no level is dominated.
    pub suggested_levels: serde_json::Value,
}

/// What `relume bench --levels` measures besides the levels.
#[derive(Clone, Copy, Debug, Default)]
pub struct LevelsOptions<'a> {
    /// The converging CPU estimator's draws per pixel (`--equal-error`), if measured.
    pub equal_error: Option<&'a [u32]>,
    /// The configurations one parameter away from a level (`--candidates`).
    pub candidates: bool,
    /// The estimator over the reference's VALs at each of these draws per pixel
    /// (`--gpu-estimator`; with `candidates` and none given, [`ESTIMATOR_CANDIDATE_DRAWS`]).
    pub gpu_estimator: &'a [u32],
}

/// Measure every level of the scene at `path`, `width` x `height` (`None`: the camera's).
pub fn levels(
    gpu: &Gpu,
    path: &Path,
    size: Option<(u32, u32)>,
    exact: &ExactOptions,
    options: &LevelsOptions<'_>,
) -> Result<LevelsReport, BenchError> {
    let (equal_error_samples, candidates) = (options.equal_error, options.candidates);
    let load = |quality| {
        Scene::load_at(path, Some(quality)).map_err(|source| BenchError::Scene { path: path.to_owned(), source })
    };
    let finest = load(Quality::Reference)?;
    let (w, h) = size.unwrap_or((finest.camera.width, finest.camera.height));
    let mut renderer = Renderer::new(gpu, &finest)?;
    let reference = exact_reference(gpu, &mut renderer, w, h, exact)?;
    let curve = match equal_error_samples {
        Some(samples) => Some(equal_error::measure("levels".into(), gpu, &mut renderer, w, h, &reference, samples)?),
        None => None,
    };
    let mut rows = Vec::new();
    for level in [Quality::Fast, Quality::Balanced, Quality::Accurate] {
        let scene = load(level)?;
        rows.push(level_row(gpu, &scene, level, (w, h), &reference, curve.as_ref())?);
    }
    rows.push(LevelRow {
        level: Quality::Reference,
        rel_rmse_vs_exact: 0.0,
        rel_rmse_without_worst_1pct: 0.0,
        error_estimate: None,
        estimate_ratio: None,
        ms: reference.ms(),
        stages_ms: reference.frame.timings.stages.clone(),
        estimator_ms_at_equal_error: None,
        at_equal_error: None,
        resolved: finest.resolved.clone(),
        knobs: Knobs::of(&finest),
        dominated_by: Vec::new(),
    });
    let (measured, existing) = match candidates {
        true => {
            let file = read_json(path)?;
            let measured = measure_candidates(gpu, path, &file, &finest, &rows[..3], (w, h), &reference)?;
            (measured, file["settings"]["levels"].clone())
        }
        false => (Vec::new(), serde_json::Value::Null),
    };
    let mut measured = measured;
    // The estimator over the reference's VALs, as `accurate`: its draws' noise falls as 1/sqrt
    // of their count, where every other technique's error has a floor (its VALs', its
    // visibility's), and on the CPU its cost is mostly the unoccluded sum over every VAL that
    // its draws are proportional to, so more draws cost little more.
    let draws = match options.gpu_estimator {
        [] if candidates => &ESTIMATOR_CANDIDATE_DRAWS[..],
        given => given,
    };
    for &draws in draws {
        let m = measure(gpu, &finest, (w, h), &reference, Method::Estimator(draws))?;
        let name = format!("accurate + technique=estimator + draws={draws}");
        measured.push(CandidateRow::of(name, &finest, Method::Estimator(draws), &m));
    }
    mark_dominated(&mut rows[..3], &measured);
    let at = format!("{w}x{h} on {}", gpu.adapter_name());
    let suggested_levels = suggest_levels(&rows[..3], &measured, &existing, finest.resolved.analysis.spot_light, &at);
    Ok(LevelsReport {
        scene: finest.meshes.iter().map(|m| m.name.as_str()).collect::<Vec<_>>().join("+"),
        adapter: gpu.adapter_name(),
        width: w,
        height: h,
        reference_estimator: exact.estimator(),
        reference_rel_stderr: reference.rel_stderr(),
        reference_ms: reference.ms(),
        levels: rows,
        equal_error_curve: curve,
        candidates: measured,
        suggested_levels,
    })
}

/// The scene file at `path`, as JSON.
fn read_json(path: &Path) -> Result<serde_json::Value, BenchError> {
    let text = std::fs::read_to_string(path).map_err(|source| BenchError::Read { path: path.to_owned(), source })?;
    serde_json::from_str(&text).map_err(|e| super::flag_error("--candidates", e.to_string()))
}

/// The levels' plot of a `levels.json` (as [`levels`] writes it): its levels (but
/// `reference`) and candidates, and the estimator's curve. From the JSON, so that a report
/// already written can be drawn again (`relume bench --levels --replot`).
pub fn plot_points(report: &serde_json::Value) -> (String, Vec<super::plot::LevelPoint>, Vec<(f64, f64)>) {
    let point = |name: &serde_json::Value, row: &serde_json::Value, level: bool| {
        Some(super::plot::LevelPoint {
            name: name.as_str()?.to_owned(),
            rel_rmse: row["rel_rmse_vs_exact"].as_f64()?,
            ms: row["ms"].as_f64()?,
            level,
        })
    };
    let empty = Vec::new();
    let levels = report["levels"].as_array().unwrap_or(&empty);
    let candidates = report["candidates"].as_array().unwrap_or(&empty);
    let points = levels
        .iter()
        .filter(|l| l["level"] != "reference")
        .filter_map(|l| point(&l["level"], l, true))
        .chain(candidates.iter().filter_map(|c| point(&c["name"], c, false)))
        .collect();
    let curve = report["equal_error_curve"]["points"]
        .as_array()
        .unwrap_or(&empty)
        .iter()
        .filter_map(|p| Some((p["ms"].as_f64()?, p["rel_rmse"].as_f64()?)))
        .collect();
    let title = format!(
        "{} at {}x{}: levels against exact ({})",
        report["scene"].as_str().unwrap_or_default(),
        report["width"],
        report["height"],
        report["adapter"].as_str().unwrap_or_default()
    );
    (title, points, curve)
}

/// The configurations [`candidate_knobs`] makes around `levels` (the rows of fast, balanced and
/// accurate), each the scene file at `path` with its knobs set in its `tuning`, loaded at its
/// base level and measured as the levels are.
fn measure_candidates(
    gpu: &Gpu,
    path: &Path,
    file: &serde_json::Value,
    finest: &Scene,
    levels: &[LevelRow],
    size: (u32, u32),
    reference: &ExactReference,
) -> Result<Vec<CandidateRow>, BenchError> {
    let base_dir = path.parent().unwrap_or_else(|| Path::new("."));
    let knobs: Vec<(Quality, Knobs)> = levels.iter().map(|r| (r.level, r.knobs)).collect();
    let mut measured = Vec::new();
    let spot_light = finest.resolved.analysis.spot_light;
    let reference_rsm = Knobs::of(finest).rsm_resolution;
    for (base, name, knobs) in candidate_knobs(&knobs, &file["settings"]["tuning"], spot_light, reference_rsm) {
        let mut file = file.clone();
        file["settings"]["tuning"] = knobs.tuning(file["settings"]["tuning"].take());
        let scene = Scene::from_json_str_at(&file.to_string(), base_dir, Some(base))
            .map_err(|source| BenchError::Scene { path: path.to_owned(), source })?;
        let m = measure(gpu, &scene, size, reference, Method::Sparse)?;
        measured.push(CandidateRow::of(name, &scene, Method::Sparse, &m));
    }
    // The brute force through the clusters' maps with balanced's and accurate's VALs and
    // clusters (the level's technique where it dominates), at the level's subdivision and at
    // the coarsest (unless the scene file's `tuning` sets it): the brute force shades pixels,
    // so the subdivision only splits the triangles its maps draw, which costs time everywhere
    // and buys accuracy where the maps' paraboloid projection needs small triangles. Not at the
    // level's own subdivision where the level already is that brute force: its row is that
    // measurement, and a second one differing by the timing's noise could dominate it. Also
    // with the reference's VALs (on a scene with a spot light whose file does not set the RSM),
    // at the coarsest subdivision the file allows.
    let tuned = file["settings"]["tuning"]["sparse"].get("subdivision").is_some();
    let rsm_tuned = file["settings"]["tuning"].get("rsm_resolution").is_some();
    for row in levels.iter().filter(|r| matches!(r.level, Quality::Balanced | Quality::Accurate)) {
        let (level, knobs) = (&row.level, &row.knobs);
        let coarsest = SUBDIVISION_RANGE.1;
        let coarse = (!tuned && knobs.subdivision != coarsest).then_some(coarsest);
        let own = (row.resolved.method != crate::scene::Technique::BruteForceClusters).then_some(None);
        let variants = own.into_iter().map(|s| (s, None)).chain(coarse.map(|s| (Some(s), None)));
        let finer_vals = (spot_light && !rsm_tuned && knobs.rsm_resolution != reference_rsm)
            .then_some((if tuned { None } else { Some(coarsest) }, Some(reference_rsm)));
        for (subdivision, rsm) in variants.chain(finer_vals) {
            let mut file = file.clone();
            let mut name = format!("{} + technique=brute_force_clusters", level.name());
            if let Some(r) = rsm {
                file["settings"]["tuning"]["rsm_resolution"] = r.into();
                name += &format!(" + rsm_resolution={r}");
            }
            if let Some(s) = subdivision {
                file["settings"]["tuning"]["sparse"]["subdivision"] = s.into();
                name += &format!(" + sparse.subdivision={s}");
            }
            let scene = Scene::from_json_str_at(&file.to_string(), base_dir, Some(*level))
                .map_err(|source| BenchError::Scene { path: path.to_owned(), source })?;
            let m = measure(gpu, &scene, size, reference, Method::BruteForceClusters)?;
            measured.push(CandidateRow::of(name, &scene, Method::BruteForceClusters, &m));
        }
    }
    // The exact reference itself over coarser VALs, as `accurate` (on a scene with a spot light
    // whose file does not set the RSM; one bounce: the GPU's exact reference has no second):
    // a shadow ray per pixel and VAL costs the reference's time over the VALs' ratio, and where
    // the maps cannot see what blocks the light next to the receivers it can be the most
    // accurate configuration short of the reference. Not for a scene lit by its `lights`:
    // fewer of their VALs lose light (`sponza_lights` at a quarter of `direct.val_budget`: 0.139
    // in 32.5 s against 0.121 in 6.7 s for the maps' brute force, docs/measurements/
    // clustered-visibility.md).
    if spot_light && !rsm_tuned && finest.settings.bounces == 1 {
        for r in exact_candidate_rsm(reference_rsm) {
            let mut file = file.clone();
            file["settings"]["tuning"]["rsm_resolution"] = r.into();
            let scene = Scene::from_json_str_at(&file.to_string(), base_dir, Some(Quality::Accurate))
                .map_err(|source| BenchError::Scene { path: path.to_owned(), source })?;
            let m = measure(gpu, &scene, size, reference, Method::Exact)?;
            let name = format!("accurate + technique=exact + rsm_resolution={r}");
            measured.push(CandidateRow::of(name, &scene, Method::Exact, &m));
        }
    }
    Ok(measured)
}

/// The estimator's draws per pixel measured as candidates unless `--gpu-estimator` gives them:
/// on the Sponza scenes the converging estimator's curve crosses balanced's target 0.10 near 16
/// draws, its 0.07 without the worst 1 % of pixels between 16 and 32, and accurate's 0.05 near
/// 64 (docs/measurements/levels.md).
pub const ESTIMATOR_CANDIDATE_DRAWS: [u32; 4] = [16, 32, 64, 256];

/// The RSM sides the exact reference is measured at as a candidate: an eighth, a quarter and
/// half the reference's side (1/64, 1/16 and 1/4 of its VALs and time), within the RSM's range.
pub fn exact_candidate_rsm(reference_rsm: u32) -> Vec<u32> {
    let (lo, _) = crate::scene::RSM_RESOLUTION_RANGE;
    [8, 4, 2].iter().map(|d| reference_rsm / d).filter(|&r| r >= lo).collect()
}

/// Each level's `dominated_by`: the other levels and the candidates that dominate it (none
/// without candidates).
fn mark_dominated(levels: &mut [LevelRow], candidates: &[CandidateRow]) {
    if candidates.is_empty() {
        return;
    }
    let all: Vec<(String, f64, f64)> = levels
        .iter()
        .map(|r| (r.level.name().to_owned(), r.rel_rmse_vs_exact, r.ms))
        .chain(candidates.iter().map(|c| (c.name.clone(), c.rel_rmse_vs_exact, c.ms)))
        .collect();
    for row in levels {
        row.dominated_by = all
            .iter()
            .filter(|(_, error, ms)| dominates((*error, *ms), (row.rel_rmse_vs_exact, row.ms)))
            .map(|(name, _, _)| name.clone())
            .collect();
    }
}

/// Whether a configuration at `(error, ms)` dominates one at `(by_error, by_ms)`: more
/// accurate and at least [`DOMINANCE_SPEEDUP`] times faster.
pub fn dominates((error, ms): (f64, f64), (other_error, other_ms): (f64, f64)) -> bool {
    error < other_error && ms * DOMINANCE_SPEEDUP <= other_ms
}

/// The configurations one parameter away from each of `levels` (fast, balanced, accurate with
/// their knobs), each parameter taking the values the levels take (and visibility `off`), in
/// the order of the levels, without repeats and without the levels' own. The RSM also takes
/// `reference_rsm`, the reference's: the VALs every error is measured against, which on a scene
/// lit next to its blockers are worth more than any level's parameter. A parameter set in the
/// scene file's `tuning` is not varied; nor is the RSM without a spot light.
pub fn candidate_knobs(
    levels: &[(Quality, Knobs)],
    tuning: &serde_json::Value,
    spot_light: bool,
    reference_rsm: u32,
) -> Vec<(Quality, String, Knobs)> {
    let set = |key: &str| tuning.get(key).is_some();
    let set_sparse = |key: &str| tuning.get("sparse").and_then(|s| s.get(key)).is_some();
    let values = |f: fn(&Knobs) -> f64| {
        let mut v: Vec<f64> = levels.iter().map(|(_, k)| f(k)).collect();
        v.sort_by(f64::total_cmp);
        v.dedup();
        v
    };
    let points = if set_sparse("points") { Vec::new() } else { values(|k| f64::from(k.points)) };
    let near_field = if set_sparse("near_field") { Vec::new() } else { values(|k| f64::from(k.near_field)) };
    // The near field interleaved counts as one choice with the near field: a level without it
    // tries it on and interleaved, one with it tries it interleaved.
    let interleave = !(set_sparse("near_field") || set_sparse("near_field_interleave"));
    let rsm = if set("rsm_resolution") || !spot_light {
        Vec::new()
    } else {
        let mut v = values(|k| f64::from(k.rsm_resolution));
        if !v.contains(&f64::from(reference_rsm)) {
            v.push(f64::from(reference_rsm));
            v.sort_by(f64::total_cmp);
        }
        v
    };
    let mut visibility: Vec<Occlusion> = Vec::new();
    if !(set("visibility") || set("occlusion")) {
        for v in std::iter::once(Occlusion::Off).chain(levels.iter().map(|(_, k)| k.visibility)) {
            if !visibility.contains(&v) {
                visibility.push(v);
            }
        }
    }
    let mut out: Vec<(Quality, String, Knobs)> = Vec::new();
    for &(level, knobs) in levels {
        let mut changes: Vec<(String, Knobs)> = Vec::new();
        for &v in &visibility {
            changes.push((format!("visibility={}", v.name()), Knobs { visibility: v, ..knobs }));
        }
        for &r in &rsm {
            changes.push((format!("rsm_resolution={r}"), Knobs { rsm_resolution: r as u32, ..knobs }));
        }
        for &p in &points {
            changes.push((format!("sparse.points={p}"), Knobs { points: p as f32, ..knobs }));
        }
        for &n in &near_field {
            changes.push((format!("sparse.near_field={n}"), Knobs { near_field: n as f32, ..knobs }));
            let side = CANDIDATE_INTERLEAVE;
            if interleave && n > 0.0 && knobs.near_field_interleave != side {
                let change = match knobs.near_field == n as f32 {
                    true => format!("sparse.near_field_interleave={side}"),
                    false => format!("sparse.near_field={n} + sparse.near_field_interleave={side}"),
                };
                changes.push((change, Knobs { near_field: n as f32, near_field_interleave: side, ..knobs }));
            }
        }
        for (change, k) in changes {
            let known = levels.iter().any(|(_, l)| *l == k) || out.iter().any(|(_, _, o)| *o == k);
            if !known {
                out.push((level, format!("{} + {change}", level.name()), k));
            }
        }
    }
    out
}

/// Frames timed per level after the warm-up frame: the row is the one of median indirect time
/// (on a shared machine a single frame's time is at the mercy of whatever else runs).
const TIMED_FRAMES: usize = 3;

/// One configuration's frame against the reference.
struct Measured {
    frame: Rendered,
    error: f64,
    without_worst: f64,
    ms: f64,
    renderer: Renderer,
}

/// How a measured configuration computes its indirect light.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Method {
    Sparse,
    /// The GPU estimator with this many draws per pixel.
    Estimator(u32),
    /// The brute force through the clusters' maps.
    BruteForceClusters,
    /// The exact reference (a shadow ray per pixel and VAL) over the configuration's VALs.
    Exact,
}

impl Method {
    /// What a level resolved to on a scene is measured as: the estimator where the scene's
    /// measured level names it with its draws, the brute force through the clusters' maps
    /// where it names that, else the sparse method.
    fn of(resolved: &ResolvedConfig) -> Method {
        match (resolved.method, resolved.estimator_draws) {
            (crate::scene::Technique::Estimator, Some(draws)) => Method::Estimator(draws),
            (crate::scene::Technique::BruteForceClusters, _) => Method::BruteForceClusters,
            (crate::scene::Technique::Exact, _) => Method::Exact,
            _ => Method::Sparse,
        }
    }

    /// The estimator's draws per pixel (none for the other methods).
    fn draws(self) -> Option<u32> {
        match self {
            Method::Estimator(draws) => Some(draws),
            Method::Sparse | Method::BruteForceClusters | Method::Exact => None,
        }
    }

    fn render_method(self) -> RenderMethod {
        match self {
            Method::Sparse => RenderMethod::Sparse,
            Method::Estimator(_) => RenderMethod::Estimator,
            Method::BruteForceClusters => RenderMethod::BruteForceClusters,
            Method::Exact => RenderMethod::Exact,
        }
    }
}

/// Render `scene` once to warm up, then [`TIMED_FRAMES`] times; the frame of median indirect
/// time against `reference`.
fn measure(
    gpu: &Gpu,
    scene: &Scene,
    (w, h): (u32, u32),
    reference: &ExactReference,
    method: Method,
) -> Result<Measured, BenchError> {
    let mut renderer = Renderer::new(gpu, scene)?;
    if let Method::Estimator(draws) = method {
        renderer.set_estimator(draws, scene.settings.seed as u32);
    }
    let traced = match method {
        Method::Exact => Some(ExactOptions::every_val(ReferenceDevice::Auto)),
        Method::Estimator(_) if gpu.is_cpu() => Some(ExactOptions::estimator_on(ReferenceDevice::Auto)),
        _ => None,
    };
    let frame = if let Some(options) = traced {
        // As `relume render` runs them: on the device `auto` picks (the CPU on lavapipe, where
        // the GPU's exact reference takes about 15x as long), once (its figures do not vary and
        // its time hardly does; after the direct light's frame, which warms the renderer up).
        exact_reference(gpu, &mut renderer, w, h, &options)?.frame
    } else {
        let method = method.render_method();
        renderer.render(gpu, method, w, h)?;
        let mut frames =
            (0..TIMED_FRAMES).map(|_| renderer.render(gpu, method, w, h)).collect::<Result<Vec<_>, _>>()?;
        frames.sort_by(|a, b| a.indirect_ms().total_cmp(&b.indirect_ms()));
        frames.swap_remove(TIMED_FRAMES / 2)
    };
    let error = reference
        .corrected_rel_rmse(&frame.indirect)
        .unwrap_or_else(|| crate::image::relative_rmse(&frame.indirect, reference.indirect()));
    let without_worst = rel_rmse_without_worst(&frame.indirect, reference.indirect(), 0.01);
    Ok(Measured { ms: frame.indirect_ms(), frame, error, without_worst, renderer })
}

fn level_row(
    gpu: &Gpu,
    scene: &Scene,
    level: Quality,
    size: (u32, u32),
    reference: &ExactReference,
    curve: Option<&EqualErrorCurve>,
) -> Result<LevelRow, BenchError> {
    let method = Method::of(&scene.resolved);
    let Measured { frame, error, without_worst, ms, renderer } = measure(gpu, scene, size, reference, method)?;
    let estimate = Estimator::new().estimate(gpu, &renderer, &frame, &EstimateOptions::default())?;
    let at_equal_error = curve.and_then(|c| equal_error::at_error(&c.points, error, ms));
    Ok(LevelRow {
        level,
        rel_rmse_vs_exact: error,
        rel_rmse_without_worst_1pct: without_worst,
        estimate_ratio: estimate.map(|e| e.rel_rmse / error),
        error_estimate: estimate,
        ms,
        stages_ms: frame.timings.stages.clone(),
        estimator_ms_at_equal_error: at_equal_error.map(|a| a.estimator_ms),
        at_equal_error,
        resolved: scene.resolved.clone(),
        knobs: Knobs::of(scene),
        dominated_by: Vec::new(),
    })
}

/// The report as a Markdown table (what `docs/measurements/levels.md` is generated from).
pub fn markdown(report: &LevelsReport) -> String {
    let mut out = format!(
        "### {} at {}x{} ({})\n\nReference: exact, {} VALs estimator{}, {:.0} ms.\n\n\
         | level | technique | rel RMSE vs exact | without worst 1 % | estimate (spread) | estimate / measured | indirect ms | estimator ms at equal error |\n\
         |---|---|---|---|---|---|---|---|\n",
        report.scene,
        report.width,
        report.height,
        report.adapter,
        report.reference_estimator,
        report.reference_rel_stderr.map_or(String::new(), |s| format!(", noise {s:.4}")),
        report.reference_ms,
    );
    for r in &report.levels {
        let estimate = r.error_estimate.map_or("–".to_owned(), |e| format!("{:.4} (±{:.4})", e.rel_rmse, e.spread));
        let ratio = r.estimate_ratio.map_or("–".to_owned(), |x| format!("{x:.2}"));
        let estimator = r.estimator_ms_at_equal_error.map_or("–".to_owned(), |x| format!("{x:.1}"));
        let technique = serde_json::to_string(&r.resolved.method).unwrap_or_default();
        out.push_str(&format!(
            "| {} | {} | {:.4} | {:.4} | {estimate} | {ratio} | {:.1} | {estimator} |\n",
            r.level.name(),
            technique.trim_matches('"'),
            r.rel_rmse_vs_exact,
            r.rel_rmse_without_worst_1pct,
            r.ms,
        ));
    }
    if !report.candidates.is_empty() {
        out.push_str(&candidates_markdown(report));
    }
    if report.suggested_levels.as_object().is_some_and(|o| !o.is_empty()) {
        let json = serde_json::to_string_pretty(&report.suggested_levels).unwrap_or_default();
        out.push_str(&format!(
            "\nThe scene file's `settings.levels` this run suggests (each level that misses its target error as \
             the fastest configuration that meets it, `accurate` with none meeting it as the most accurate \
             measured, each other dominated level as its most accurate dominating configuration):\n\n```json\n\
             {json}\n```\n"
        ));
    }
    out
}

/// The candidates' table and, per level, what dominates it.
fn candidates_markdown(report: &LevelsReport) -> String {
    let mut out = format!(
        "\nOne parameter away from a level (`--candidates`), against the same reference; **bold**: a \
         configuration that dominates a level (more accurate and at least {DOMINANCE_SPEEDUP}x faster):\n\n\
         | configuration | visibility | RSM | points | near field | subdivision | rel RMSE vs exact | without worst 1 % | indirect ms |\n\
         |---|---|---|---|---|---|---|---|---|\n",
    );
    let knobs = |k: &Knobs| {
        let near_field = match k.near_field_interleave {
            side if side > 1 && k.near_field > 0.0 => format!("{} ({side}x{side})", k.near_field),
            _ => k.near_field.to_string(),
        };
        format!("{} | {} | {} | {near_field} | {}", k.visibility.name(), k.rsm_resolution, k.points, k.subdivision)
    };
    let rows = report.levels[..3.min(report.levels.len())]
        .iter()
        .map(|r| (r.level.name().to_owned(), knobs(&r.knobs), r.rel_rmse_vs_exact, r.rel_rmse_without_worst_1pct, r.ms))
        .chain(report.candidates.iter().map(|c| {
            // The estimator and the exact reference have none of the sparse method's
            // parameters; the estimator's VALs are the reference's.
            let k = match c.method {
                RenderMethod::Sparse => knobs(&c.knobs),
                RenderMethod::BruteForceClusters => {
                    format!("clusters per pixel | {} | – | – | –", c.knobs.rsm_resolution)
                }
                RenderMethod::Estimator => format!("estimator | {} | – | – | –", c.knobs.rsm_resolution),
                _ => format!("exact | {} | – | – | –", c.knobs.rsm_resolution),
            };
            (c.name.clone(), k, c.rel_rmse_vs_exact, c.rel_rmse_without_worst_1pct, c.ms)
        }));
    for (label, k, error, without, ms) in rows {
        let dominant = report.levels.iter().any(|l| l.dominated_by.contains(&label));
        let label = if dominant { format!("**{label}**") } else { label };
        out.push_str(&format!("| {label} | {k} | {error:.4} | {without:.4} | {ms:.1} |\n"));
    }
    out.push('\n');
    for l in report.levels.iter().filter(|l| l.level != Quality::Reference) {
        let targets = suggest::targets_text(l.level);
        let target = match l.level.meets_targets(l.rel_rmse_vs_exact, l.rel_rmse_without_worst_1pct) {
            _ if targets.is_empty() => String::new(),
            false => format!("; **misses** its target {targets}"),
            true => format!("; meets its target {targets}"),
        };
        match l.dominated_by.as_slice() {
            [] => out.push_str(&format!("- `{}`: not dominated{target}.\n", l.level.name())),
            by => out.push_str(&format!(
                "- `{}`: **dominated** by {}{target}.\n",
                l.level.name(),
                by.iter().map(|b| format!("`{b}`")).collect::<Vec<_>>().join(", ")
            )),
        }
    }
    out
}

#[cfg(test)]
mod tests;

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

use super::BenchError;
use super::compare::{ExactOptions, ExactReference, exact_reference, rel_rmse_without_worst};
use super::equal_error::{self, AtEqualError, EqualErrorCurve};
use crate::gpu::Gpu;
use crate::renderer::estimate::{ErrorEstimate, EstimateOptions, Estimator};
use crate::renderer::{Method, Renderer};
use crate::scene::{Quality, ResolvedConfig, Scene};
use std::path::Path;

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
}

/// Measure every level of the scene at `path`, `width` x `height` (`None`: the camera's).
pub fn levels(
    gpu: &Gpu,
    path: &Path,
    size: Option<(u32, u32)>,
    exact: &ExactOptions,
    equal_error_samples: Option<&[u32]>,
) -> Result<LevelsReport, BenchError> {
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
    });
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
    })
}

/// Frames timed per level after the warm-up frame: the row is the one of median indirect time
/// (on a shared machine a single frame's time is at the mercy of whatever else runs).
const TIMED_FRAMES: usize = 3;

fn level_row(
    gpu: &Gpu,
    scene: &Scene,
    level: Quality,
    (w, h): (u32, u32),
    reference: &ExactReference,
    curve: Option<&EqualErrorCurve>,
) -> Result<LevelRow, BenchError> {
    let mut renderer = Renderer::new(gpu, scene)?;
    renderer.render(gpu, Method::Sparse, w, h)?;
    let mut frames =
        (0..TIMED_FRAMES).map(|_| renderer.render(gpu, Method::Sparse, w, h)).collect::<Result<Vec<_>, _>>()?;
    frames.sort_by(|a, b| a.indirect_ms().total_cmp(&b.indirect_ms()));
    let frame = frames.swap_remove(TIMED_FRAMES / 2);
    let error = reference
        .corrected_rel_rmse(&frame.indirect)
        .unwrap_or_else(|| crate::image::relative_rmse(&frame.indirect, reference.indirect()));
    let estimate = Estimator::new().estimate(gpu, &renderer, &frame, &EstimateOptions::default())?;
    let ms = frame.indirect_ms();
    let at_equal_error = curve.and_then(|c| equal_error::at_error(&c.points, error, ms));
    Ok(LevelRow {
        level,
        rel_rmse_vs_exact: error,
        rel_rmse_without_worst_1pct: rel_rmse_without_worst(&frame.indirect, reference.indirect(), 0.01),
        estimate_ratio: estimate.map(|e| e.rel_rmse / error),
        error_estimate: estimate,
        ms,
        stages_ms: frame.timings.stages.clone(),
        estimator_ms_at_equal_error: at_equal_error.map(|a| a.estimator_ms),
        at_equal_error,
        resolved: scene.resolved.clone(),
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
    out
}

//! What a levels run suggests for the scene file's `settings.levels`: for each level, the
//! measured configuration it should become, written as what differs from it.

use super::{CandidateRow, Knobs, LevelRow, Method, RenderMethod};
use crate::scene::Quality;

/// The scene file's `settings.levels` the measurement suggests: for each level that misses its
/// target error ([`Quality::meets_targets`]: the rel RMSE, and for balanced also without the
/// worst 1 % of pixels), the fastest measured configuration (another
/// level or a candidate) that meets it within the level's time bound
/// ([`Quality::time_share_of_accurate`] of accurate's time as suggested); `accurate`, which has
/// no time bound, where nothing meets its target, the most accurate measured configuration
/// more accurate than its own; for each other level that a measured configuration dominates,
/// the most accurate of those configurations. Each
/// is written as the parameters where it differs from the level as measured (over that
/// level's entry in `existing`, the scene file's `settings.levels`, whose other parameters it
/// keeps; the RSM only on a scene with a spot light), with what was measured (`at`: the size
/// and adapter). A level that meets its target undominated, or that misses it with nothing
/// measured meeting it nor dominating it, keeps its entry in `existing`.
pub fn suggest_levels(
    levels: &[LevelRow],
    candidates: &[CandidateRow],
    existing: &serde_json::Value,
    spot_light: bool,
    at: &str,
) -> serde_json::Value {
    // The GPU estimator's rows carry their draws (the level becomes the estimator), the brute
    // force's its method (the level becomes it, with the row's VALs).
    type Technique = (RenderMethod, Option<u32>);
    let technique = |r: &LevelRow| {
        let method = Method::of(&r.resolved);
        (method.render_method(), method.draws())
    };
    struct Row<'a> {
        name: &'a str,
        knobs: Knobs,
        technique: Technique,
        error: f64,
        without_worst: f64,
        ms: f64,
    }
    let measured: Vec<Row> = levels
        .iter()
        .map(|r| Row {
            name: r.level.name(),
            knobs: r.knobs,
            technique: technique(r),
            error: r.rel_rmse_vs_exact,
            without_worst: r.rel_rmse_without_worst_1pct,
            ms: r.ms,
        })
        .chain(candidates.iter().map(|c| Row {
            name: c.name.as_str(),
            knobs: c.knobs,
            technique: (c.method, c.draws),
            error: c.rel_rmse_vs_exact,
            without_worst: c.rel_rmse_without_worst_1pct,
            ms: c.ms,
        }))
        .collect();
    // What each level becomes: the fastest meeting its target within its time bound; else,
    // for `accurate`, which has no bound, the most accurate measured configuration where it is
    // more accurate than the level's own; else the most accurate dominating one.
    let choose = |row: &LevelRow, max_ms: f64| {
        let level = row.level;
        let misses = !level.meets_targets(row.rel_rmse_vs_exact, row.rel_rmse_without_worst_1pct);
        let meeting = misses
            .then(|| {
                measured
                    .iter()
                    .filter(|m| {
                        m.name != level.name() && level.meets_targets(m.error, m.without_worst) && m.ms <= max_ms
                    })
                    .min_by(|a, b| a.ms.total_cmp(&b.ms))
            })
            .flatten();
        let closer = (misses && level == Quality::Accurate)
            .then(|| {
                measured
                    .iter()
                    .filter(|m| m.name != level.name() && m.error < row.rel_rmse_vs_exact)
                    .min_by(|a, b| a.error.total_cmp(&b.error))
            })
            .flatten();
        let best = meeting.or(closer).or_else(|| {
            measured
                .iter()
                .filter(|m| row.dominated_by.iter().any(|d| d == m.name))
                .min_by(|a, b| a.error.total_cmp(&b.error))
        });
        (misses, meeting, best)
    };
    // The other levels' time bounds are shares of accurate's time as it will run.
    let accurate_ms =
        levels.iter().find(|r| r.level == Quality::Accurate).map(|r| choose(r, f64::INFINITY).2.map_or(r.ms, |m| m.ms));
    let mut out = existing.as_object().cloned().unwrap_or_default();
    for row in levels {
        let max_ms = match (row.level.time_share_of_accurate(), accurate_ms) {
            (Some(share), Some(ms)) => share * ms,
            _ => f64::INFINITY,
        };
        let (misses, meeting, best) = choose(row, max_ms);
        let Some(&Row { name, knobs, technique: draws, error, ms, .. }) = best else { continue };
        let mut entry = out.get(row.level.name()).filter(|e| e.is_object()).cloned().unwrap_or(serde_json::json!({}));
        match draws {
            // The estimator takes none of the sparse method's parameters, but its draws and the
            // row's VALs (the reference's RSM).
            (_, Some(draws)) => {
                entry = serde_json::json!({"technique": "estimator", "draws": draws});
                if spot_light {
                    entry["rsm_resolution"] = knobs.rsm_resolution.into();
                }
            }
            // The exact reference takes the row's VALs (its RSM) and nothing else.
            (RenderMethod::Exact, None) => {
                entry = serde_json::json!({"technique": "exact"});
                if spot_light {
                    entry["rsm_resolution"] = knobs.rsm_resolution.into();
                }
            }
            // The brute force takes the row's VALs (its RSM), clusters and subdivision: each
            // where the candidate changed it, else as the level's entry already set it (the
            // row ran with it), and none of the other sparse parameters.
            (RenderMethod::BruteForceClusters, None) => {
                let before = std::mem::replace(&mut entry, serde_json::json!({"technique": "brute_force_clusters"}));
                if spot_light && knobs.rsm_resolution != row.knobs.rsm_resolution {
                    entry["rsm_resolution"] = knobs.rsm_resolution.into();
                } else if let Some(r) = before.get("rsm_resolution") {
                    entry["rsm_resolution"] = r.clone();
                }
                if knobs.subdivision != row.knobs.subdivision {
                    entry["sparse"] = serde_json::json!({"subdivision": knobs.subdivision});
                } else if let Some(s) = before.get("sparse").and_then(|s| s.get("subdivision")) {
                    entry["sparse"] = serde_json::json!({"subdivision": s});
                }
            }
            _ => {
                if let Some(e) = entry.as_object_mut() {
                    e.remove("technique");
                    e.remove("draws");
                }
                set_changed_knobs(&mut entry, knobs, row.knobs, spot_light);
            }
        }
        let targets = targets_text(row.level);
        let why = match (meeting, misses) {
            (Some(_), true) => {
                format!("; the fastest measured within the level's target {targets}, which its own misses")
            }
            (None, true) if !row.dominated_by.iter().any(|d| d == name) => {
                format!("; the most accurate measured, none within the level's target {targets}")
            }
            _ => String::new(),
        };
        entry["measured"] = format!(
            "`{name}`: rel RMSE {error:.4} at {ms:.0} ms, the level's own {:.4} at {:.0} ms, at {at} (relume \
             bench --levels --candidates){why}",
            row.rel_rmse_vs_exact, row.ms
        )
        .into();
        out.insert(row.level.name().to_owned(), entry);
    }
    serde_json::Value::Object(out)
}

/// The level's targets in words: `0.10 (0.07 without its worst 1 %)`.
pub fn targets_text(level: Quality) -> String {
    let whole = level.target_rel_rmse().map_or(String::new(), |t| format!("{t:.2}"));
    match level.target_without_worst_1pct() {
        Some(t) => format!("{whole} ({t:.2} without its worst 1 %)"),
        None => whole,
    }
}

/// Into a `settings.levels` entry, each of `knobs` that differs from the level's `was` (the RSM
/// only on a scene with a spot light).
fn set_changed_knobs(entry: &mut serde_json::Value, knobs: Knobs, was: Knobs, spot_light: bool) {
    if knobs.visibility != was.visibility {
        entry["visibility"] = knobs.visibility.name().into();
    }
    if spot_light && knobs.rsm_resolution != was.rsm_resolution {
        entry["rsm_resolution"] = knobs.rsm_resolution.into();
    }
    let sparse: [(&str, bool, serde_json::Value); 4] = [
        ("points", knobs.points != was.points, knobs.points.into()),
        ("near_field", knobs.near_field != was.near_field, knobs.near_field.into()),
        ("subdivision", knobs.subdivision != was.subdivision, knobs.subdivision.into()),
        (
            "near_field_interleave",
            knobs.near_field_interleave != was.near_field_interleave,
            knobs.near_field_interleave.into(),
        ),
    ];
    for (key, changed, value) in sparse {
        if changed {
            if !entry["sparse"].is_object() {
                entry["sparse"] = serde_json::json!({});
            }
            entry["sparse"][key] = value;
        }
    }
}

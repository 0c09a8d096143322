//! The levels bench's pure parts: the candidates around the levels, dominance, the
//! suggested `settings.levels`, the plot's points.

use super::*;

fn knobs(visibility: Occlusion, rsm_resolution: u32, points: f32, near_field: f32, subdivision: f32) -> Knobs {
    Knobs { visibility, rsm_resolution, points, near_field, near_field_interleave: 1, subdivision }
}

fn levels() -> Vec<(Quality, Knobs)> {
    vec![
        (Quality::Fast, knobs(Occlusion::Disks, 64, 0.5, 0.0, 4.0)),
        (Quality::Balanced, knobs(Occlusion::Disks, 128, 1.0, 0.0, 2.0)),
        (Quality::Accurate, knobs(Occlusion::Clusters, 128, 1.0, 4.0, 2.0)),
    ]
}

/// Each level's one-parameter neighbours over the values the levels take, without the
/// levels themselves and without repeats: accurate's disks are balanced with the near field,
/// its near field off is balanced with clusters, both already listed from balanced.
#[test]
fn candidates_are_one_parameter_from_a_level_and_never_repeat() {
    let c = candidate_knobs(&levels(), &serde_json::json!({}), true, 128);
    let names: Vec<&str> = c.iter().map(|(_, n, _)| n.as_str()).collect();
    assert_eq!(
        names,
        [
            "fast + visibility=off",
            "fast + visibility=clusters",
            "fast + rsm_resolution=128",
            "fast + sparse.points=1",
            "fast + sparse.near_field=4",
            "fast + sparse.near_field=4 + sparse.near_field_interleave=4",
            "balanced + visibility=off",
            "balanced + visibility=clusters",
            "balanced + rsm_resolution=64",
            "balanced + sparse.points=0.5",
            "balanced + sparse.near_field=4",
            "balanced + sparse.near_field=4 + sparse.near_field_interleave=4",
            "accurate + visibility=off",
            "accurate + rsm_resolution=64",
            "accurate + sparse.points=0.5",
            "accurate + sparse.near_field_interleave=4",
        ]
    );
    for (base, _, k) in &c {
        let (_, from) = levels().into_iter().find(|(l, _)| l == base).unwrap();
        let differ = [
            k.visibility != from.visibility,
            k.rsm_resolution != from.rsm_resolution,
            k.points != from.points,
            // The near field and its interleaving: one choice.
            k.near_field != from.near_field || k.near_field_interleave != from.near_field_interleave,
            k.subdivision != from.subdivision,
        ];
        assert_eq!(differ.iter().filter(|d| **d).count(), 1, "{k:?} from {from:?}");
    }
}

/// The reference's RSM is a candidate where no level takes it: the finer VALs every error is
/// measured against.
#[test]
fn candidates_try_the_references_vals() {
    let coarse: Vec<(Quality, Knobs)> =
        levels().into_iter().map(|(q, k)| (q, Knobs { rsm_resolution: 64, ..k })).collect();
    let c = candidate_knobs(&coarse, &serde_json::json!({}), true, 128);
    let rsm: Vec<&str> = c.iter().map(|(_, n, _)| n.as_str()).filter(|n| n.contains("rsm")).collect();
    assert_eq!(rsm, ["fast + rsm_resolution=128", "balanced + rsm_resolution=128", "accurate + rsm_resolution=128"]);
    assert!(c.iter().filter(|(_, n, _)| n.contains("rsm")).all(|(_, _, k)| k.rsm_resolution == 128));
    // Not where the file sets the RSM, nor without a spot light.
    let tuned = candidate_knobs(&coarse, &serde_json::json!({"rsm_resolution": 64}), true, 128);
    assert!(!tuned.iter().any(|(_, n, _)| n.contains("rsm")), "{tuned:?}");
    assert!(!candidate_knobs(&coarse, &serde_json::json!({}), false, 128).iter().any(|(_, n, _)| n.contains("rsm")));
}

/// A parameter the scene file's tuning sets, or the RSM of a scene without a spot light,
/// is not varied.
#[test]
fn candidates_leave_what_the_scene_file_sets() {
    let tuning = serde_json::json!({"rsm_resolution": 32, "visibility": "off", "sparse": {"near_field": 2}});
    let c = candidate_knobs(&levels(), &tuning, true, 128);
    assert!(c.iter().all(|(_, n, _)| n.contains("sparse.points")), "{c:?}");
    let c = candidate_knobs(&levels(), &serde_json::json!({}), false, 128);
    assert!(!c.iter().any(|(_, n, _)| n.contains("rsm_resolution")), "{c:?}");
}

/// The plot takes the levels but `reference`, every candidate, and the estimator's curve,
/// from the JSON the bench wrote.
#[test]
fn the_plot_takes_levels_candidates_and_the_curve_from_the_json() {
    let report = serde_json::json!({
        "scene": "room", "width": 64, "height": 48, "adapter": "cpu",
        "levels": [
            {"level": "fast", "rel_rmse_vs_exact": 0.2, "ms": 10.0},
            {"level": "balanced", "rel_rmse_vs_exact": 0.1, "ms": 20.0},
            {"level": "reference", "rel_rmse_vs_exact": 0.0, "ms": 900.0},
        ],
        "candidates": [{"name": "fast + sparse.points=1", "rel_rmse_vs_exact": 0.15, "ms": 15.0}],
        "equal_error_curve": {"points": [{"ms": 100.0, "rel_rmse": 0.3}, {"ms": 200.0, "rel_rmse": 0.2}]},
    });
    let (title, points, curve) = plot_points(&report);
    assert!(title.starts_with("room at 64x48"), "{title}");
    let names: Vec<(&str, bool)> = points.iter().map(|p| (p.name.as_str(), p.level)).collect();
    assert_eq!(names, [("fast", true), ("balanced", true), ("fast + sparse.points=1", false)]);
    assert_eq!((points[2].rel_rmse, points[2].ms), (0.15, 15.0));
    assert_eq!(curve, [(100.0, 0.3), (200.0, 0.2)]);
    let (_, points, curve) = plot_points(&serde_json::json!({}));
    assert!(points.is_empty() && curve.is_empty());
}

fn row(level: Quality, knobs: Knobs, error: f64, ms: f64, dominated_by: &[&str]) -> LevelRow {
    LevelRow {
        level,
        rel_rmse_vs_exact: error,
        // Most of the error in a few pixels, as on the fixtures.
        rel_rmse_without_worst_1pct: 0.6 * error,
        error_estimate: None,
        estimate_ratio: None,
        ms,
        stages_ms: Vec::new(),
        estimator_ms_at_equal_error: None,
        at_equal_error: None,
        resolved: ResolvedConfig::default(),
        knobs,
        dominated_by: dominated_by.iter().map(|d| (*d).to_owned()).collect(),
    }
}

fn candidate(name: &str, knobs: Knobs, error: f64, ms: f64) -> CandidateRow {
    CandidateRow {
        name: name.to_owned(),
        knobs,
        method: RenderMethod::Sparse,
        draws: None,
        rel_rmse_vs_exact: error,
        // Most of the error in a few pixels, as on the fixtures.
        rel_rmse_without_worst_1pct: 0.6 * error,
        ms,
        stages_ms: Vec::new(),
    }
}

/// A dominated level is suggested as its most accurate dominating configuration, written as
/// what differs from the level (over the scene file's entry, whose other fields stay);
/// a level not dominated keeps its entry; a scene loaded with the suggestion is that
/// configuration at that level, and passes validation.
#[test]
fn a_dominated_level_is_suggested_as_its_most_accurate_dominating_configuration() {
    let l = levels();
    let rows = [
        row(Quality::Fast, l[0].1, 0.20, 100.0, &[]),
        row(Quality::Balanced, l[1].1, 0.10, 500.0, &["fast + visibility=clusters", "balanced + rsm_resolution=64"]),
        row(Quality::Accurate, l[2].1, 0.05, 2000.0, &[]),
    ];
    let candidates = [
        candidate("fast + visibility=clusters", knobs(Occlusion::Clusters, 64, 0.5, 0.0, 4.0), 0.08, 400.0),
        candidate("balanced + rsm_resolution=64", knobs(Occlusion::Disks, 64, 1.0, 0.0, 2.0), 0.099, 300.0),
        candidate("balanced + sparse.points=0.5", knobs(Occlusion::Disks, 128, 0.5, 0.0, 2.0), 0.07, 450.0),
    ];
    let existing = serde_json::json!({"balanced": {"measured": "before", "sparse": {"kernel": "paper"}},
        "accurate": {"measured": "kept", "rsm_resolution": 64}});
    let s = suggest_levels(&rows, &candidates, &existing, true, "64x64 on cpu");
    let balanced = &s["balanced"];
    assert_eq!(balanced["visibility"], "clusters");
    assert_eq!(balanced["rsm_resolution"], 64);
    assert_eq!(balanced["sparse"], serde_json::json!({"kernel": "paper", "points": 0.5, "subdivision": 4.0}));
    let text = balanced["measured"].as_str().unwrap();
    assert!(text.starts_with("`fast + visibility=clusters`: rel RMSE 0.0800 at 400 ms, the level's own 0.1000 at 500"));
    assert!(text.contains("64x64 on cpu"), "{text}");
    assert_eq!(s["accurate"], existing["accurate"]);
    assert!(s.get("fast").is_none());
    // Without a spot light the RSM is left out.
    let s = suggest_levels(&rows, &candidates, &serde_json::Value::Null, false, "here");
    assert!(s["balanced"].get("rsm_resolution").is_none(), "{s}");
    // Nothing dominated: nothing suggested.
    let free = [row(Quality::Fast, l[0].1, 0.2, 100.0, &[])];
    assert_eq!(suggest_levels(&free, &candidates, &serde_json::Value::Null, true, "here"), serde_json::json!({}));

    let suggested = suggest_levels(&rows, &candidates, &existing, true, "64x64 on cpu");
    let settings: crate::scene::SettingsDescription =
        serde_json::from_value(serde_json::json!({"levels": suggested})).expect("the suggestion parses");
    settings.validate("settings").expect("and is valid");
    let (resolved, _) = crate::scene::settings::resolve(Quality::Balanced, &Default::default(), &settings);
    assert_eq!((resolved.rsm_resolution, resolved.sparse.points, resolved.sparse.subdivision), (64, 0.5, 4.0));
    assert_eq!(resolved.visibility.mode, Occlusion::Clusters);
}

/// A level that misses its target error is suggested as the fastest measured configuration
/// that meets it within the level's time bound, dominating or not (the most accurate
/// dominating one may be slower, or miss the target too); another level's row may be that
/// configuration, with its technique. With nothing meeting the target the dominance rule
/// applies; a level at its target is not moved.
#[test]
fn a_level_missing_its_target_takes_the_fastest_configuration_meeting_it() {
    let l = levels();
    let mut accurate = row(Quality::Accurate, l[2].1, 0.02, 1200.0, &[]);
    accurate.resolved.method = crate::scene::Technique::BruteForceClusters;
    let rows =
        [row(Quality::Fast, l[0].1, 0.19, 80.0, &[]), row(Quality::Balanced, l[1].1, 0.118, 60.0, &[]), accurate];
    let near = "balanced + sparse.near_field=4";
    let candidates = [
        // More accurate and as fast: not dominating, and still over 0.10.
        candidate("balanced + visibility=clusters", knobs(Occlusion::Clusters, 128, 1.0, 0.0, 2.0), 0.105, 58.0),
        candidate(near, knobs(Occlusion::Disks, 128, 1.0, 4.0, 2.0), 0.090, 460.0),
    ];
    let existing = serde_json::json!({"accurate": {"measured": "kept", "technique": "brute_force_clusters"}});
    let s = suggest_levels(&rows, &candidates, &existing, true, "here");
    assert_eq!(s["balanced"]["sparse"], serde_json::json!({"near_field": 4.0}), "{s}");
    // The near field interleaved, faster at the target: both parameters in the entry.
    let interleaved = "balanced + sparse.near_field=4 + sparse.near_field_interleave=4";
    let knobs_4x4 = Knobs { near_field_interleave: 4, ..knobs(Occlusion::Disks, 128, 1.0, 4.0, 2.0) };
    let with_4x4 = [candidates[0].clone(), candidates[1].clone(), candidate(interleaved, knobs_4x4, 0.095, 150.0)];
    let s4 = suggest_levels(&rows, &with_4x4, &existing, true, "here");
    assert_eq!(s4["balanced"]["sparse"], serde_json::json!({"near_field": 4.0, "near_field_interleave": 4}), "{s4}");
    let text = s["balanced"]["measured"].as_str().unwrap();
    assert!(text.starts_with(&format!("`{near}`: rel RMSE 0.0900 at 460 ms")), "{text}");
    assert!(text.contains("within the level's target 0.10"), "{text}");
    assert!(s.get("fast").is_none() && s["accurate"] == existing["accurate"], "{s}");

    // Without the near field's row, accurate's (the brute force) is the fastest under 0.10.
    let s = suggest_levels(&rows, &candidates[..1], &existing, true, "here");
    assert_eq!(s["balanced"]["technique"], "brute_force_clusters", "{s}");
    let settings: crate::scene::SettingsDescription =
        serde_json::from_value(serde_json::json!({"levels": s})).expect("the suggestion parses");
    settings.validate("settings").expect("and is valid");
    let technique = crate::scene::settings::technique(Quality::Balanced, &settings);
    assert_eq!(technique, (crate::scene::Technique::BruteForceClusters, None));

    // Nothing under 0.10 but a dominating configuration: the dominance rule.
    let rows = [row(Quality::Balanced, l[1].1, 0.118, 600.0, &["balanced + visibility=clusters"])];
    let s = suggest_levels(&rows, &candidates[..1], &serde_json::json!({}), true, "here");
    assert_eq!(s["balanced"]["visibility"], "clusters", "{s}");
    assert!(!s["balanced"]["measured"].as_str().unwrap().contains("target"), "{s}");

    // Only within the level's time bound: fast at most a quarter of accurate's time (Sponza's
    // fast at 0.28, its accurate brute force at 0.12 but 7 s: fast stays); a candidate under
    // the bound that meets 0.20 is taken.
    let mut accurate = row(Quality::Accurate, l[2].1, 0.12, 7000.0, &[]);
    accurate.resolved.method = crate::scene::Technique::BruteForceClusters;
    let rows = [row(Quality::Fast, l[0].1, 0.28, 137.0, &[]), accurate];
    let s = suggest_levels(&rows, &[], &serde_json::json!({}), true, "here");
    assert!(s.get("fast").is_none(), "{s}");
    let near = candidate("fast + sparse.near_field=4", knobs(Occlusion::Disks, 64, 0.5, 4.0, 4.0), 0.19, 1700.0);
    let s = suggest_levels(&rows, &[near], &serde_json::json!({}), true, "here");
    assert_eq!(s["fast"]["sparse"], serde_json::json!({"near_field": 4.0}), "{s}");
}

/// `accurate` missing its target with nothing measured meeting it becomes the most accurate
/// measured configuration, slower or not (it has no time bound), and the other levels' bounds
/// follow its time as suggested: balanced may then take a configuration slower than
/// accurate's own row that meets 0.10. With nothing more accurate than its own, it stays.
#[test]
fn accurate_missing_its_target_takes_the_most_accurate_measured() {
    let l = levels();
    let mut accurate = row(Quality::Accurate, l[2].1, 0.118, 7500.0, &[]);
    accurate.resolved.method = crate::scene::Technique::BruteForceClusters;
    let rows = [row(Quality::Balanced, l[1].1, 0.31, 1700.0, &[]), accurate];
    let mut finer = candidate("accurate + technique=brute_force_clusters + rsm_resolution=128", l[2].1, 0.092, 9000.0);
    finer.method = RenderMethod::BruteForceClusters;
    finer.knobs.rsm_resolution = 256;
    let mut coarse = finer.clone();
    (coarse.name, coarse.rel_rmse_vs_exact, coarse.ms) =
        ("balanced + technique=brute_force_clusters".into(), 0.099, 8000.0);
    let candidates = [finer, coarse];
    let s = suggest_levels(&rows, &candidates, &serde_json::json!({}), true, "here");
    assert_eq!(s["accurate"]["rsm_resolution"], 256, "{s}");
    let text = s["accurate"]["measured"].as_str().unwrap();
    assert!(text.contains("the most accurate measured, none within the level's target 0.05"), "{text}");
    // Balanced's bound is accurate's suggested 9000 ms: the fastest under 0.10 within it.
    assert!(
        s["balanced"]["measured"].as_str().unwrap().starts_with("`balanced + technique=brute_force_clusters`"),
        "{s}"
    );
    // Without the finer one, the other: the most accurate of what was measured.
    let s = suggest_levels(&rows, &candidates[1..], &serde_json::json!({}), true, "here");
    assert!(s["accurate"]["measured"].as_str().unwrap().starts_with("`balanced + technique"), "{s}");
    let slower = [row(Quality::Balanced, l[1].1, 0.31, 1700.0, &[]), row(Quality::Accurate, l[2].1, 0.06, 7500.0, &[])];
    let s = suggest_levels(&slower, &candidates, &serde_json::json!({}), true, "here");
    assert!(s.get("accurate").is_none(), "{s}");
}

/// The exact reference over coarser VALs is tried at an eighth, a quarter and half the
/// reference's RSM side, never under the RSM's range; chosen, it is the level's technique with
/// its RSM and nothing else, and a scene loads with it.
#[test]
fn the_exact_reference_over_coarser_vals_can_become_accurate() {
    assert_eq!(exact_candidate_rsm(128), [16, 32, 64]);
    assert_eq!(exact_candidate_rsm(32), [8, 16]);
    let l = levels();
    let rows = [row(Quality::Accurate, l[2].1, 0.085, 1100.0, &[])];
    let mut exact = candidate("accurate + technique=exact + rsm_resolution=16", l[2].1, 0.044, 4700.0);
    (exact.method, exact.knobs.rsm_resolution) = (RenderMethod::Exact, 16);
    let existing = serde_json::json!({"accurate": {"measured": "before", "sparse": {"near_field": 0.0}}});
    let s = suggest_levels(&rows, &[exact], &existing, true, "here");
    assert_eq!(s["accurate"]["technique"], "exact", "{s}");
    assert_eq!(s["accurate"]["rsm_resolution"], 16, "{s}");
    assert!(s["accurate"].get("sparse").is_none(), "{s}");
    let settings: crate::scene::SettingsDescription =
        serde_json::from_value(serde_json::json!({"levels": s})).expect("the suggestion parses");
    settings.validate("settings").expect("and is valid");
    assert_eq!(crate::scene::settings::technique(Quality::Accurate, &settings), (crate::scene::Technique::Exact, None));
}

/// The estimator dominating a level makes it that level's technique, with its draws and its
/// row's VALs (the reference's RSM, where the level's entry had its own) and none of the
/// sparse parameters; a sparse configuration suggested later takes it back.
#[test]
fn a_dominating_estimator_becomes_the_levels_technique() {
    let l = levels();
    let rows = [row(Quality::Accurate, l[2].1, 0.29, 12000.0, &["accurate + technique=estimator + draws=8"])];
    let mut estimator = candidate("accurate + technique=estimator + draws=8", l[2].1, 0.10, 9000.0);
    estimator.method = RenderMethod::Estimator;
    estimator.draws = Some(8);
    let existing = serde_json::json!({"accurate": {"measured": "before", "rsm_resolution": 64}});
    let s = suggest_levels(&rows, &[estimator], &existing, true, "here");
    let accurate = &s["accurate"];
    assert_eq!((&accurate["technique"], &accurate["draws"]), (&serde_json::json!("estimator"), &serde_json::json!(8)));
    assert_eq!(accurate["rsm_resolution"], l[2].1.rsm_resolution, "{accurate}");
    assert_ne!(l[2].1.rsm_resolution, 64, "the entry's own RSM replaced");
    let settings: crate::scene::SettingsDescription =
        serde_json::from_value(serde_json::json!({"levels": s})).expect("the suggestion parses");
    settings.validate("settings").expect("and is valid");
    let technique = crate::scene::settings::technique(Quality::Accurate, &settings);
    assert_eq!(technique, (crate::scene::Technique::Estimator, Some(8)));
    // A sparse configuration dominating it later: the technique goes.
    let rows = [row(Quality::Accurate, l[2].1, 0.10, 9000.0, &["accurate + sparse.points=0.5"])];
    let sparse =
        candidate("accurate + sparse.points=0.5", knobs(Occlusion::Clusters, 128, 0.5, 4.0, 2.0), 0.09, 5000.0);
    let s = suggest_levels(&rows, &[sparse], &s, true, "here");
    assert!(s["accurate"].get("technique").is_none() && s["accurate"].get("draws").is_none(), "{s}");
    assert_eq!(s["accurate"]["sparse"]["points"], 0.5);
}

/// Balanced, the default level, has a second target: 0.07 without the frame's worst 1 % of
/// pixels. A balanced level within 0.10 but over 0.07 without its worst pixels misses, and is
/// suggested as the fastest configuration meeting both (here the estimator at twice the draws,
/// as on the many lights' Sponza); one within 0.10 only does not qualify, however fast. The
/// other levels have no second target.
#[test]
fn balanced_is_held_to_its_error_without_the_worst_pixels_too() {
    assert!(Quality::Balanced.meets_targets(0.10, 0.07) && !Quality::Balanced.meets_targets(0.084, 0.078));
    assert!(!Quality::Balanced.meets_targets(0.11, 0.05));
    assert!(Quality::Fast.meets_targets(0.2, 0.2) && Quality::Accurate.meets_targets(0.05, 0.05));
    assert!(Quality::Reference.meets_targets(1.0, 1.0));
    let l = levels();
    let mut balanced = row(Quality::Balanced, l[1].1, 0.084, 9000.0, &[]);
    balanced.rel_rmse_without_worst_1pct = 0.078;
    let rows = [balanced, row(Quality::Accurate, l[2].1, 0.04, 11000.0, &[])];
    let estimator = |draws: u32, error: f64, without: f64, ms: f64| {
        let mut c = candidate(&format!("accurate + technique=estimator + draws={draws}"), l[2].1, error, ms);
        (c.method, c.draws, c.rel_rmse_without_worst_1pct) = (RenderMethod::Estimator, Some(draws), without);
        c
    };
    let mut faster =
        candidate("balanced + visibility=clusters", knobs(Occlusion::Clusters, 128, 1.0, 0.0, 2.0), 0.08, 500.0);
    faster.rel_rmse_without_worst_1pct = 0.072;
    let candidates = [faster, estimator(32, 0.059, 0.055, 9500.0), estimator(64, 0.04, 0.037, 11000.0)];
    let s = suggest_levels(&rows, &candidates, &serde_json::json!({}), true, "here");
    assert_eq!((&s["balanced"]["technique"], &s["balanced"]["draws"]), (&"estimator".into(), &32.into()), "{s}");
    let text = s["balanced"]["measured"].as_str().unwrap();
    assert!(text.contains("within the level's target 0.10 (0.07 without its worst 1 %)"), "{text}");
    assert!(s.get("accurate").is_none(), "{s}");
    // Within 0.07 without its worst pixels, balanced stays.
    let mut rows = rows;
    rows[0].rel_rmse_without_worst_1pct = 0.069;
    assert!(suggest_levels(&rows, &candidates, &serde_json::json!({}), true, "here").get("balanced").is_none());
}

/// The brute force through the clusters' maps dominating a level makes it that level's
/// technique, with the candidate's RSM where it differs and none of the sparse parameters.
#[test]
fn a_dominating_brute_force_through_the_clusters_becomes_the_levels_technique() {
    let l = levels();
    let name = "balanced + technique=brute_force_clusters";
    let rows = [row(Quality::Accurate, l[2].1, 0.24, 8000.0, &[name])];
    let mut brute = candidate(name, knobs(Occlusion::Disks, 64, 1.0, 0.0, 2.0), 0.10, 6000.0);
    brute.method = RenderMethod::BruteForceClusters;
    let existing = serde_json::json!({"accurate": {"measured": "before", "sparse": {"points": 0.5}}});
    let s = suggest_levels(&rows, &[brute], &existing, true, "here");
    let accurate = &s["accurate"];
    assert_eq!(accurate["technique"], "brute_force_clusters");
    assert_eq!(accurate["rsm_resolution"], 64, "{accurate}");
    assert!(accurate.get("sparse").is_none() && accurate.get("draws").is_none(), "{accurate}");
    let settings: crate::scene::SettingsDescription =
        serde_json::from_value(serde_json::json!({"levels": s})).expect("the suggestion parses");
    settings.validate("settings").expect("and is valid");
    let technique = crate::scene::settings::technique(Quality::Accurate, &settings);
    assert_eq!(technique, (crate::scene::Technique::BruteForceClusters, None));
}

/// The brute force at the coarsest subdivision dominating a level takes that subdivision into
/// the entry (its maps draw fewer triangles), and the entry is a valid level.
#[test]
fn a_dominating_brute_force_at_the_coarsest_subdivision_keeps_it() {
    let l = levels();
    let name = "accurate + technique=brute_force_clusters + sparse.subdivision=16";
    let rows = [row(Quality::Accurate, l[2].1, 0.24, 8000.0, &[name])];
    let mut brute = candidate(name, Knobs { subdivision: 16.0, ..l[2].1 }, 0.23, 3000.0);
    brute.method = RenderMethod::BruteForceClusters;
    let s = suggest_levels(&rows, std::slice::from_ref(&brute), &serde_json::json!({}), true, "here");
    let accurate = &s["accurate"];
    assert_eq!(accurate["technique"], "brute_force_clusters");
    assert_eq!(accurate["sparse"], serde_json::json!({"subdivision": 16.0}), "{accurate}");
    assert!(accurate.get("rsm_resolution").is_none(), "the level's own RSM: {accurate}");
    // The level ran with its entry's RSM (and the candidate with it): the new entry keeps it,
    // and drops the sparse parameters the brute force does not take.
    let existing = serde_json::json!({"accurate": {"measured": "before", "technique": "brute_force_clusters",
        "rsm_resolution": 64, "sparse": {"points": 0.5}}});
    let s = suggest_levels(&rows, &[brute], &existing, true, "here");
    assert_eq!(s["accurate"]["rsm_resolution"], 64, "{s}");
    assert_eq!(s["accurate"]["sparse"], serde_json::json!({"subdivision": 16.0}), "{s}");
    let settings: crate::scene::SettingsDescription =
        serde_json::from_value(serde_json::json!({"levels": s})).expect("the suggestion parses");
    settings.validate("settings").expect("and is valid");
}

#[test]
fn dominance_needs_both_lower_error_and_the_speedup() {
    assert!(dominates((0.10, 100.0), (0.11, 120.0)));
    assert!(!dominates((0.10, 100.0), (0.11, 119.0)), "not 1.2x faster");
    assert!(!dominates((0.11, 10.0), (0.11, 120.0)), "not more accurate");
    assert!(!dominates((0.10, 100.0), (0.10, 100.0)), "itself");
}

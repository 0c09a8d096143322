//! `relume bench --quick`: the smoke test CI runs. Checks the outputs' shape and that every
//! figure is finite; the numbers themselves are not asserted.

use super::{fixture, scratch};
use std::process::{Command, Output};

fn relume(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_relume")).args(args).output().expect("running relume")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The `results.json` a bench run wrote into `dir`.
fn results(dir: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("results.json")).unwrap()).unwrap()
}

fn finite_non_negative(v: &serde_json::Value, key: &str) -> f64 {
    let x = v[key].as_f64().unwrap_or_else(|| panic!("{key} missing or not a number: {v}"));
    assert!(x.is_finite() && x >= 0.0, "{key} = {x}");
    x
}

#[test]
fn quick_bench_writes_a_finite_table_and_plots() {
    let dir = scratch("bench_quick");
    let scene = fixture("scenes/cornell_bunny_small.json");
    let o = relume(&["bench", scene.to_str().unwrap(), "--quick", "--out", dir.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));

    let json = results(&dir);
    assert!(json["timing"].as_str().is_some_and(|t| t == "gpu_timestamps" || t == "wall_clock"), "{json}");
    assert!(json["adapter"].as_str().is_some_and(|a| !a.is_empty()));
    let configs = json["configs"].as_array().expect("configs");
    // Base, 128 sparse points per mesh, R = 16, disks.
    assert_eq!(configs.len(), 4, "{json}");
    for c in configs {
        for key in ["sparse_indirect_ms", "frame_ms", "brute_force_ms", "speedup", "gather_interactions_per_s"] {
            finite_non_negative(c, key);
        }
        for key in ["rel_rmse", "flip_mean"] {
            finite_non_negative(&c["vs_brute_force"], key);
        }
        assert!(c["gpu_memory_bytes"].as_u64().is_some_and(|b| b > 0), "{c}");
        assert!(c["vals"].as_u64().is_some_and(|n| n > 0), "{c}");
        assert_eq!(c["pixels"].as_u64(), Some(32 * 32));
        let stages = c["stages_ms"].as_array().expect("stages");
        for name in ["rsm_raster", "rsm_vals", "visibility", "gather", "renormalise", "interpolate", "shade", "direct"]
        {
            let stage = stages.iter().find(|s| s[0] == name).unwrap_or_else(|| panic!("stage {name}: {c}"));
            assert!(stage[1].as_f64().is_some_and(|ms| ms.is_finite() && ms >= 0.0), "{stage}");
        }
        assert!(c["vs_exact"].is_null());
    }
    assert!(configs.iter().any(|c| c["occlusion"] == "disks"));

    let fma = &json["fma"];
    for key in ["fma_per_s", "fma_ms"] {
        assert!(finite_non_negative(fma, key) > 0.0, "{key}: {fma}");
    }
    let variants = fma["gather_variants"].as_array().expect("gather variants");
    assert!(!variants.is_empty());
    for v in variants {
        for key in ["gather_ms", "interactions_per_s", "ratio_to_fma"] {
            finite_non_negative(v, key);
        }
    }
    let motions = json["temporal"]["motions"].as_array().expect("temporal motions");
    let names: Vec<&str> = motions.iter().map(|m| m["motion"].as_str().unwrap()).collect();
    assert_eq!(names, ["camera_orbit", "moving_light", "moving_model"]);
    for m in motions {
        for key in
            ["sparse_image_change", "brute_force_image_change", "error_image_change", "sparse_point_irradiance_change"]
        {
            finite_non_negative(m, key);
        }
    }

    let csv = std::fs::read_to_string(dir.join("results.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 1 + configs.len());
    let header: Vec<&str> = lines[0].split(',').collect();
    for row in &lines[1..] {
        let cells: Vec<&str> = row.split(',').collect();
        assert_eq!(cells.len(), header.len(), "{row}");
        for (name, cell) in header.iter().zip(&cells) {
            let numeric = name.ends_with("_ms") || name.starts_with("rel_rmse") || name.starts_with("flip_mean");
            if numeric && !cell.is_empty() {
                let x: f64 = cell.parse().unwrap_or_else(|_| panic!("{name} = {cell}"));
                assert!(x.is_finite(), "{name} = {cell}");
            }
        }
    }
    for name in relume::bench::plot::PLOTS {
        let png = image::open(dir.join(format!("{name}.png"))).unwrap_or_else(|e| panic!("{name}.png: {e}"));
        assert!(png.width() > 100 && png.height() > 100, "{name}.png");
        let svg = std::fs::read_to_string(dir.join(format!("{name}.svg"))).unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("</svg>"), "{name}.svg");
    }
}

#[test]
fn bench_flags_are_checked_and_named() {
    let dir = scratch("bench_errors");
    let scene = fixture("scenes/cornell_bunny_small.json");
    let scene = scene.to_str().unwrap();
    let out = dir.to_str().unwrap();
    for (args, wanted) in [
        (vec!["--sweep", "sparse_points=0"], "--sweep sparse_points"),
        (vec!["--sweep", "neighbours=0"], "--sweep neighbours"),
        (vec!["--sweep", "fps=60"], "unknown axis"),
        (vec!["--val-stride", "4"], "--val-stride"),
        (vec!["--reference", "exact", "--val-stride", "0"], "--val-stride"),
        (vec!["--equal-error"], "--reference"),
        (vec!["--reference", "exact", "--equal-error", "1,8"], "--equal-error"),
        (vec!["--reference", "exact", "--equal-error", "8,x"], "--equal-error"),
    ] {
        let mut all = vec!["bench", scene, "--quick", "--out", out];
        all.extend(&args);
        let o = relume(&all);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(stderr(&o).contains(wanted), "{args:?}: {}", stderr(&o));
        assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
    }
}

#[test]
fn table1_preset_builds_its_scenes_and_runs_quick() {
    let dir = scratch("bench_table1");
    let scene = fixture("scenes/cornell_bunny_small.json");
    let args = ["bench", scene.to_str().unwrap(), "--table1", "--quick", "--no-fma", "--no-temporal"];
    let o = relume(&[&args[..], &["--no-plots", "--out", dir.to_str().unwrap()]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let json = results(&dir);
    let configs = json["configs"].as_array().expect("configs");
    assert_eq!(configs.len(), 3, "diffuse, + glossy, + occlusion");
    for c in configs {
        assert_eq!(c["variant"], "table1_200k");
        assert!(c["triangles"].as_u64().is_some_and(|t| t > 200_000), "three bunnies and the room: {c}");
        assert!(c["brute_force_ms"].is_null() && c["vs_brute_force"].is_null(), "no references: {c}");
        finite_non_negative(c, "frame_ms");
    }
    assert_eq!(configs[1]["glossy_active"], true);
    let built = relume::scene::Scene::load(&dir.join("table1_200k.json")).expect("the built scene loads");
    assert_eq!(built.meshes.len(), 4, "the room and three bunnies");
}

/// `--equal-error`: the converging estimator's curve and each configuration's speed at equal
/// error. The figures are timings, not asserted; what is asserted is what cannot depend on the
/// machine: the estimator converges (16x the samples, about a quarter of the error: below half
/// of it here, leaving room for one image's noise), casts rays in proportion to its samples, and
/// every configuration gets a finite time and speed-up.
#[test]
fn equal_error_measures_the_converging_estimator() {
    let dir = scratch("bench_equal_error");
    let scene = fixture("scenes/cornell_bunny_small.json");
    let args = [
        "bench",
        scene.to_str().unwrap(),
        "--quick",
        "--sweep",
        "occlusion=off,disks",
        "--no-fma",
        "--no-temporal",
        "--reference",
        "exact",
        "--equal-error",
        "2,32",
        "--out",
        dir.to_str().unwrap(),
    ];
    let o = relume(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("at equal error"), "{}", stderr(&o));
    let json = results(&dir);
    let curves = json["equal_error_curves"].as_array().expect("curves");
    assert_eq!(curves.len(), 1, "one renderer, one size: {json}");
    let points = curves[0]["points"].as_array().unwrap();
    let samples: Vec<u64> = points.iter().map(|p| p["samples"].as_u64().unwrap()).collect();
    assert_eq!(samples, [2, 32]);
    let error: Vec<f64> = points.iter().map(|p| finite_non_negative(p, "rel_rmse")).collect();
    assert!(error[1] < 0.5 * error[0] && error[1] > 0.0, "{error:?}");
    let rays: Vec<f64> = points.iter().map(|p| finite_non_negative(p, "shadow_rays")).collect();
    assert!(rays[1] > 8.0 * rays[0], "{rays:?}");
    let configs = json["configs"].as_array().unwrap();
    assert_eq!(configs.len(), 2, "{json}");
    for c in configs {
        let at = &c["at_equal_error"];
        assert!(finite_non_negative(at, "estimator_ms") > 0.0, "{c}");
        assert!(finite_non_negative(at, "speedup") > 0.0, "{c}");
        assert!(at["extrapolated"].is_boolean(), "{c}");
    }
    let csv = std::fs::read_to_string(dir.join("results.csv")).unwrap();
    assert!(csv.lines().next().unwrap().contains("speedup_at_equal_error"));
}

/// With `ism` configurations and the references, the bench renders `brute_force_ism` (the ISM
/// lookup per pixel) once per size and `ism` settings the configurations used, beside them:
/// its error against the brute force and exact, its stages, `brute_force_ism.csv` and the
/// plots. Timings are not asserted; what is: one entry per distinct settings (two counts, the
/// plain base adds none), each with its own settings, its ISM stages in its frame, and an
/// image that differs from the brute force's (the maps occlude: a per-pixel ISM that saw
/// nothing would be 0 from it).
#[test]
fn bench_measures_brute_force_ism_beside_the_ism_configurations() {
    let dir = scratch("bench_brute_force_ism");
    let scene = fixture("scenes/cornell_bunny_small.json");
    let args = [
        "bench",
        scene.to_str().unwrap(),
        "--quick",
        "--sweep",
        "ism_count=8,16",
        "--no-fma",
        "--no-temporal",
        "--reference",
        "exact",
        "--out",
        dir.to_str().unwrap(),
    ];
    let o = relume(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("brute_force_ism (8 maps"), "{}", stderr(&o));
    let json = results(&dir);
    let configs = json["configs"].as_array().expect("configs");
    assert_eq!(configs.len(), 3, "the base and two ISM counts: {json}");
    let per_pixel = json["brute_force_ism"].as_array().expect("brute_force_ism");
    let counts: Vec<u64> = per_pixel.iter().map(|r| r["ism"]["count"].as_u64().unwrap()).collect();
    assert_eq!(counts, [8, 16], "{json}");
    for r in per_pixel {
        assert_eq!(r["config"]["occlusion"], "ism");
        assert!(finite_non_negative(r, "indirect_ms") > 0.0, "{r}");
        assert!(finite_non_negative(r, "ism_ms") > 0.0, "{r}");
        let stages: Vec<&str> = r["stages_ms"].as_array().unwrap().iter().map(|s| s[0].as_str().unwrap()).collect();
        for name in ["brute_force_ism_sampling", "brute_force_ism_splat", "brute_force_ism_visibility", "brute_force"] {
            assert!(stages.contains(&name), "{name}: {stages:?}");
        }
        assert!(finite_non_negative(&r["vs_brute_force"], "rel_rmse") > 0.0, "the maps occlude: {r}");
        finite_non_negative(&r["vs_exact"], "rel_rmse");
    }
    let csv = std::fs::read_to_string(dir.join("brute_force_ism.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 3, "{csv}");
    let columns = lines[0].split(',').count();
    assert!(lines[1..].iter().all(|l| l.split(',').count() == columns), "{csv}");
    assert!(dir.join("error_vs_time_exact.png").exists());
}

/// `relume bench --levels`: every level against one exact reference, and the frame's error
/// estimate within a factor 1.5 of the error measured against that reference, on three
/// fixtures at 64² (more pixels than the estimate looks at, so it does sample).
#[test]
fn levels_are_measured_and_the_estimate_is_within_1_5x_of_the_error() {
    for name in ["cornell_bunny_small", "cornell_gltf_small", "cornell_bunny_two_bounces"] {
        let dir = scratch(&format!("bench_levels_{name}"));
        let scene = fixture(&format!("scenes/{name}.json"));
        let (w, h) = if name == "cornell_bunny_two_bounces" { ("48", "48") } else { ("64", "64") };
        let mut args = vec!["bench", "--levels", scene.to_str().unwrap(), "--width", w, "--height", h];
        args.extend(["--out", dir.to_str().unwrap()]);
        // The small room pins its RSM: the candidates vary the visibility, the points and the
        // near field, a few frames at 64x64.
        let candidates = name == "cornell_bunny_small";
        if candidates {
            args.push("--candidates");
        }
        let o = relume(&args);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        let report: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("levels.json")).unwrap()).unwrap();
        let levels = report["levels"].as_array().unwrap();
        let names: Vec<&str> = levels.iter().map(|l| l["level"].as_str().unwrap()).collect();
        assert_eq!(names, ["fast", "balanced", "accurate", "reference"], "{name}");
        for l in &levels[..3] {
            let measured = finite_non_negative(l, "rel_rmse_vs_exact");
            let estimate = &l["error_estimate"];
            let estimated = estimate["rel_rmse"].as_f64().unwrap();
            assert!(estimate["pixels"].as_u64().unwrap() == 1024, "{name}: the estimate samples: {estimate}");
            let ratio = estimated / measured;
            assert!((1.0 / 1.5..=1.5).contains(&ratio), "{name} {}: estimate {estimated} vs {measured}", l["level"]);
            assert!(l["resolved"]["choices"].as_array().is_some_and(|c| !c.is_empty()), "{name}: {l}");
        }
        assert_eq!(levels[3]["resolved"]["method"].as_str(), Some("exact"));
        let table = std::fs::read_to_string(dir.join("levels.md")).unwrap();
        assert!(table.contains("| balanced | sparse |"));
        if candidates {
            let file: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&scene).unwrap()).unwrap();
            assert_candidates(&report, &table, &file["settings"]["levels"]);
            // The plot, and drawn again from levels.json alone (`--replot` renders nothing).
            let svg = dir.join("levels.svg");
            assert!(std::fs::metadata(&svg).is_ok_and(|m| m.len() > 1000), "no levels.svg");
            assert!(std::fs::metadata(dir.join("levels.png")).is_ok_and(|m| m.len() > 1000), "no levels.png");
            std::fs::remove_file(&svg).unwrap();
            let o = relume(&["bench", "--levels", scene.to_str().unwrap(), "--replot", "--out", dir.to_str().unwrap()]);
            assert!(o.status.success(), "{name} --replot: {}", stderr(&o));
            let drawn = std::fs::read_to_string(&svg).unwrap();
            for l in ["fast", "balanced", "accurate"] {
                assert!(drawn.contains(l), "{l} not labelled in the plot");
            }
        }
    }
}

/// `--candidates` on the small room: each candidate is a level with its visibility, points or
/// near field changed (the scene file pins the RSM), or the brute force through the clusters'
/// maps with a level's VALs, measured against the same reference; a level's `dominated_by`
/// names exactly the measured configurations more accurate and 1.2x faster; a level over its
/// target error is suggested as the fastest configuration under it in the level's time, else
/// `accurate` as the most accurate measured that beats it, else a dominated one as the most
/// accurate of what dominates it, and a level neither keeps the
/// scene file's entry (`existing`) in the suggestion.
fn assert_candidates(report: &serde_json::Value, table: &str, existing: &serde_json::Value) {
    let levels = &report["levels"].as_array().unwrap()[..3];
    let candidates = report["candidates"].as_array().unwrap();
    assert!(candidates.len() >= 3, "{candidates:?}");
    let estimators: Vec<u64> = candidates.iter().filter_map(|c| c["draws"].as_u64()).collect();
    assert_eq!(estimators, relume::bench::levels::ESTIMATOR_CANDIDATE_DRAWS.map(u64::from), "{candidates:?}");
    // (name, rel RMSE, without the worst 1 %, ms)
    let mut all: Vec<(String, f64, f64, f64)> = Vec::new();
    for l in levels {
        all.push((
            l["level"].as_str().unwrap().to_owned(),
            finite_non_negative(l, "rel_rmse_vs_exact"),
            finite_non_negative(l, "rel_rmse_without_worst_1pct"),
            l["ms"].as_f64().unwrap(),
        ));
    }
    for c in candidates {
        let name = c["name"].as_str().unwrap();
        let (base, change) = name.split_once(" + ").unwrap_or_else(|| panic!("{name}"));
        let base = levels.iter().find(|l| l["level"] == base).unwrap_or_else(|| panic!("{name}"));
        assert_eq!(c["knobs"]["rsm_resolution"], base["knobs"]["rsm_resolution"], "{name}: the file pins the RSM");
        if change == "technique=brute_force_clusters" {
            // The brute force through the clusters' maps with the level's VALs.
            assert_eq!(c["method"], "brute-force-clusters", "{name}");
            assert_eq!(c["knobs"], base["knobs"], "{name}");
        } else if let Some(draws) = change.strip_prefix("technique=estimator + draws=") {
            // The estimator over the reference's VALs, as accurate, at each default count.
            assert_eq!(base["level"], "accurate", "{name}");
            assert_eq!((c["method"].as_str(), c["draws"].as_u64()), (Some("estimator"), draws.parse().ok()), "{name}");
        } else if let Some(s) = change.strip_prefix("technique=brute_force_clusters + sparse.subdivision=") {
            // And at the coarsest subdivision: only that knob differs.
            assert_eq!((c["method"].as_str(), s), (Some("brute-force-clusters"), "16"), "{name}");
            let mut knobs = c["knobs"].clone();
            assert_eq!(knobs["subdivision"], 16.0, "{name}");
            knobs["subdivision"] = base["knobs"]["subdivision"].clone();
            assert_eq!(knobs, base["knobs"], "{name}");
        } else {
            let knob = ["visibility=", "sparse.points=", "sparse.near_field=", "sparse.near_field_interleave="]
                .iter()
                .any(|k| change.starts_with(k));
            assert!(knob, "{name}");
            assert_eq!(c["method"], "sparse", "{name}");
            assert_ne!(c["knobs"], base["knobs"], "{name}");
        }
        // Bold where it dominates a level.
        let row = [format!("| {name} |"), format!("| **{name}** |")];
        assert!(row.iter().any(|r| table.contains(r.as_str())), "{name} missing from the table");
        all.push((
            name.to_owned(),
            finite_non_negative(c, "rel_rmse_vs_exact"),
            finite_non_negative(c, "rel_rmse_without_worst_1pct"),
            c["ms"].as_f64().unwrap(),
        ));
    }
    // A level over its target (balanced's two: 0.10, and 0.07 without the worst 1 % of
    // pixels) with a configuration within it in the level's time (fast a quarter of
    // accurate's, balanced accurate's, accurate's being what it is suggested as) gets the
    // fastest of those as its suggested `settings.levels` entry; else `accurate` the most
    // accurate configuration measured, where one beats its own; else a dominated level, and
    // only one, the most accurate of what dominates it.
    let choose = |l: &serde_json::Value, accurate_ms: f64| {
        let (error, ms) = (l["rel_rmse_vs_exact"].as_f64().unwrap(), l["ms"].as_f64().unwrap());
        let without = l["rel_rmse_without_worst_1pct"].as_f64().unwrap();
        let level = l["level"].as_str().unwrap();
        let by: Vec<&str> =
            all.iter().filter(|(_, e, _, m)| *e < error && m * 1.2 <= ms).map(|(n, ..)| n.as_str()).collect();
        let (target, target_without, max_ms) = match level {
            "fast" => (0.20, f64::INFINITY, 0.25 * accurate_ms),
            "balanced" => (0.10, 0.07, accurate_ms),
            _ => (0.05, f64::INFINITY, f64::INFINITY),
        };
        let misses = error > target || without > target_without;
        let meeting = all
            .iter()
            .filter(|(n, e, w, m)| misses && n != level && *e <= target && *w <= target_without && *m <= max_ms)
            .min_by(|a, b| a.3.total_cmp(&b.3));
        let closer = all
            .iter()
            .filter(|(n, e, ..)| level == "accurate" && misses && n != level && *e < error)
            .min_by(|a, b| a.1.total_cmp(&b.1));
        let dominating = all.iter().filter(|(n, ..)| by.contains(&n.as_str())).min_by(|a, b| a.1.total_cmp(&b.1));
        (by, meeting.or(closer).or(dominating).cloned())
    };
    let accurate_ms = choose(&levels[2], f64::INFINITY).1.map_or(levels[2]["ms"].as_f64().unwrap(), |b| b.3);
    for l in levels {
        let (expected, best) = choose(l, accurate_ms);
        let by: Vec<&str> = l["dominated_by"].as_array().unwrap().iter().map(|n| n.as_str().unwrap()).collect();
        assert_eq!(by, expected, "{}", l["level"]);
        let level = l["level"].as_str().unwrap();
        let suggested = &report["suggested_levels"][level];
        match best {
            Some((name, ..)) => {
                let measured = suggested["measured"].as_str().unwrap_or_else(|| panic!("{suggested}"));
                assert!(measured.starts_with(&format!("`{name}`: rel RMSE")), "{measured}");
                assert!(table.contains("settings.levels"), "the table shows the suggestion");
            }
            // Not dominated: the scene file's own entry stays (none, or the one it has).
            None => assert_eq!(suggested, &existing[l["level"].as_str().unwrap()], "{suggested}"),
        }
    }
}

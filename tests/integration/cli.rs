//! The `relume` binary: outputs on success, and clear errors naming the offending field or flag.

use super::{fixture, fixture_scene_json, scratch};
use std::process::{Command, Output};

fn relume(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_relume")).args(args).output().expect("running relume")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn render_writes_png_and_exr_of_the_requested_size() {
    let dir = scratch("cli_render");
    let (png, exr) = (dir.join("x.png"), dir.join("x.exr"));
    let scene = fixture("scenes/cornell_bunny_small.json");
    let o = relume(&[
        "render",
        scene.to_str().unwrap(),
        "--out",
        png.to_str().unwrap(),
        "--hdr",
        exr.to_str().unwrap(),
        "--component",
        "indirect",
        "--width",
        "40",
        "--height",
        "30",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (40, 30));
    let hdr = image::open(&exr).unwrap().into_rgba32f();
    assert_eq!((hdr.width(), hdr.height()), (40, 30));
    assert!(hdr.pixels().all(|p| p.0.iter().all(|c| c.is_finite() && *c >= 0.0)));
    assert!(hdr.pixels().any(|p| p.0[0] > 0.0), "indirect light reaches the image");
}

#[test]
fn compare_prints_the_documented_fields() {
    let scene = fixture("scenes/cornell_bunny_small.json");
    let o = relume(&["compare", scene.to_str().unwrap(), "--width", "32", "--height", "32"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    for key in ["sparse_ms", "brute_force_ms", "indirect_rel_rmse", "indirect_flip_mean"] {
        let x = v[key].as_f64().unwrap_or_else(|| panic!("{key} missing: {v}"));
        assert!(x.is_finite() && x >= 0.0, "{key} = {x}");
    }
    assert!(v["timing"].as_str().is_some_and(|t| t == "gpu_timestamps" || t == "wall_clock"));
    assert!(v["vals"].as_u64().unwrap() > 0);
    assert_eq!(v["pixels"].as_u64(), Some(1024));
    assert_eq!(v["sparse_points"].as_u64(), Some(768));
    assert!(v["adapter"].as_str().is_some_and(|a| !a.is_empty()));
}

/// `render` and `compare` print the resolved configuration to stderr; `--quality` replaces the
/// scene's level, and a scene at `reference` renders with the exact method unless `--method`
/// says otherwise.
#[test]
fn render_prints_the_resolved_configuration_and_takes_a_quality() {
    let dir = scratch("cli_quality");
    let scene = fixture("scenes/cornell_bunny_small.json");
    let png = dir.join("q.png");
    let args = |extra: &[&str]| {
        let mut args = vec!["render", scene.to_str().unwrap(), "--out", png.to_str().unwrap()];
        args.extend(["--component", "indirect", "--width", "8", "--height", "8"]);
        args.extend(extra);
        relume(&args)
    };
    let o = args(&[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stderr(&o);
    assert!(text.contains("quality balanced: technique sparse"), "{text}");
    assert!(text.contains("tuning.rsm_resolution = 32: set in the scene file"), "{text}");
    assert!(text.contains("sparse.subdivision = 2.0: "), "{text}");
    // Every frame carries its error estimate: printed, and in the JSON on standard output.
    assert!(text.contains("error estimate: indirect rel RMSE "), "{text}");
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    assert_eq!(v["quality"], "balanced");
    let e = &v["error_estimate"];
    assert!(e["rel_rmse"].as_f64().is_some_and(|r| r.is_finite() && r >= 0.0), "{v}");
    assert!(e["pixels"].as_u64().is_some_and(|p| p > 0), "{v}");
    assert!(v["timings_ms"]["error_estimate"].as_f64().is_some(), "{v}");
    let o = args(&["--quality", "fast"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("sparse.subdivision = 4.0: "), "{}", stderr(&o));
    // At `reference` the exact method renders; a direct-only image would skip it, so ask for
    // the indirect light with every 64th VAL to stay quick.
    let o = args(&["--quality", "reference", "--val-stride", "64", "--reference-device", "cpu"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("technique exact"), "{}", stderr(&o));
    let o = args(&["--quality", "reference", "--method", "sparse", "--reference-device", "cpu"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--reference-device: only with --method exact"), "{}", stderr(&o));
    let o = args(&["--quality", "best"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--quality"), "{}", stderr(&o));
}

#[test]
fn bad_inputs_fail_with_a_message_naming_the_field() {
    let dir = scratch("cli_errors");
    let scene = fixture("scenes/cornell_bunny_small.json");
    let o = relume(&["render", scene.to_str().unwrap(), "--width", "0"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--width"), "{}", stderr(&o));

    let text = std::fs::read_to_string(&scene).unwrap().replace("\"rsm_resolution\"", "\"rsm_resolutoin\"");
    let bad = dir.join("bad.json");
    std::fs::write(&bad, text).unwrap();
    let o = relume(&["render", bad.to_str().unwrap(), "--out", dir.join("x.png").to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("rsm_resolutoin"), "{}", stderr(&o));

    let o = relume(&["render", dir.join("missing.json").to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("missing.json"), "{}", stderr(&o));
    assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
}

/// `compare --reference exact` on the CPU with sampled VALs and jittered pixels reports its
/// estimator, its noise and a noise-corrected error (never above the raw one) beside each raw
/// error.
#[test]
fn compare_reports_the_cpu_reference_and_its_noise() {
    let scene = fixture("scenes/cornell_bunny_small.json");
    let o = relume(&[
        "compare",
        scene.to_str().unwrap(),
        "--width",
        "12",
        "--height",
        "10",
        "--reference",
        "exact",
        "--reference-device",
        "cpu",
        "--reference-samples",
        "8",
        "--spp",
        "2",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    assert_eq!((v["exact_device"].as_str(), v["exact_estimator"].as_str()), (Some("cpu"), Some("importance")));
    assert_eq!((v["exact_samples"].as_u64(), v["exact_spp"].as_u64()), (Some(8), Some(2)));
    let stderr_rel = v["exact_rel_stderr"].as_f64().unwrap();
    assert!(stderr_rel > 0.0 && stderr_rel.is_finite(), "a sampled reference has noise: {stderr_rel}");
    assert!(v["exact_shadow_rays"].as_u64().unwrap() > 0 && v["exact_rays_per_s"].as_f64().unwrap() > 0.0);
    let modes = v["modes_vs_exact"].as_array().expect("every mode against exact");
    let keys: Vec<&str> = modes.iter().map(|m| m["mode"].as_str().unwrap()).collect();
    assert_eq!(keys, ["off", "sum", "product", "clusters", "ism"]);
    for m in modes {
        let (key, raw, corrected) =
            (&m["mode"], m["rel_rmse"].as_f64().unwrap(), m["rel_rmse_corrected"].as_f64().unwrap());
        assert!(corrected >= 0.0 && corrected <= raw, "{key}: corrected {corrected} vs raw {raw}");
        let visibility_ms = m["visibility_ms"].as_f64().unwrap();
        assert_eq!(visibility_ms == 0.0, key == "off", "{key}: its own stages took {visibility_ms} ms");
    }
    let brute = &v["brute_force_vs_exact"];
    assert_eq!(brute["mode"].as_str(), Some("brute_force"));
    let (raw, corrected) = (brute["rel_rmse"].as_f64().unwrap(), brute["rel_rmse_corrected"].as_f64().unwrap());
    assert!(raw.is_finite() && corrected >= 0.0 && corrected <= raw, "brute force: {corrected} vs {raw}");
    for key in ["brute_force_ism", "brute_force_clusters"] {
        let grouped = &v[format!("{key}_vs_exact")];
        assert_eq!(grouped["mode"].as_str(), Some(key));
        let (rel_rmse, visibility_ms) = (grouped["rel_rmse"].as_f64().unwrap(), grouped["visibility_ms"].as_f64());
        assert!(rel_rmse.is_finite() && visibility_ms.unwrap() > 0.0, "{grouped}");
        assert!(v[format!("{key}_skipped")].is_null(), "a small image's table fits");
    }
    // The scene's own configuration against exact, with the frame's estimate of that error.
    let default = &v["default_vs_exact"];
    let measured = default["rel_rmse_corrected"].as_f64().unwrap();
    let estimate = &default["error_estimate"];
    let (estimated, spread) = (estimate["rel_rmse"].as_f64().unwrap(), estimate["spread"].as_f64().unwrap());
    assert!(measured.is_finite() && estimated.is_finite() && spread >= 0.0, "{default}");
    assert!(estimate["pixels"].as_u64().unwrap() >= 4 && estimate["samples"].as_u64() == Some(128), "{estimate}");
    let ratio = default["estimate_ratio"].as_f64().unwrap();
    assert!((ratio - estimated / measured).abs() < 1e-9, "{ratio}");
    let without_worst = default["rel_rmse_without_worst_1pct"].as_f64().unwrap();
    assert!(without_worst <= default["rel_rmse"].as_f64().unwrap(), "{default}");
    assert_eq!((v["bounces"].as_u64(), v["second_bounce_ms"].as_f64()), (Some(1), Some(0.0)));
}

/// `compare`'s exact reference is the scene at its own level, so the estimate beside it sums
/// over the same VALs, not the `reference` level's: cornell_bunny's balanced level draws a 64²
/// RSM (at most 4,096 VALs), its reference a 128² one, which the per-frame estimate would trace.
#[test]
fn compares_estimate_sums_over_the_scenes_own_vals() {
    let scene = fixture("scenes/cornell_bunny.json");
    let args = ["--width", "8", "--height", "8", "--reference", "exact", "--reference-device", "cpu"];
    let o = relume(&[&["compare", scene.to_str().unwrap()][..], &args].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    let e = &v["default_vs_exact"]["error_estimate"];
    assert!(e["reference_rsm_resolution"].is_null(), "{e}");
    assert!((1..=64 * 64).contains(&e["reference_vals"].as_u64().unwrap()), "{e}");
}

/// With `"bounces": 2` the second bounce runs in every method `compare` renders (the CPU exact
/// reference making its own through shadow rays) and its cost is reported; the GPU exact
/// reference refuses it, naming the setting.
#[test]
fn two_bounces_are_compared_and_the_gpu_reference_refuses_them() {
    let dir = scratch("cli_two_bounces");
    let mut json: serde_json::Value = serde_json::from_str(&super::test_room_text()).unwrap();
    json["settings"]["tuning"]["second_bounce"] = serde_json::json!({"points": 256, "vals": 32});
    json["settings"]["bounces"] = 2.into();
    // In the scratch directory, its meshes named by absolute path.
    let meshes = fixture("meshes");
    let text = json.to_string().replace("../meshes/", &format!("{}/", meshes.to_str().unwrap()));
    let scene = dir.join("two_bounces.json");
    std::fs::write(&scene, &text).unwrap();
    let scene_arg = scene.to_str().unwrap();
    let size = ["--width", "8", "--height", "8"];
    let o =
        relume(&[&["compare", scene_arg][..], &size, &["--reference", "exact", "--reference-device", "cpu"]].concat());
    let gpu = relume(
        &[
            &["render", scene_arg, "--method", "exact", "--reference-device", "gpu"][..],
            &size,
            &["--out", dir.join("x.png").to_str().unwrap()],
        ]
        .concat(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    assert_eq!(v["bounces"].as_u64(), Some(2));
    assert!(v["second_bounce_ms"].as_f64().unwrap() > 0.0);
    let stages: Vec<&str> =
        v["brute_force_stages_ms"].as_array().unwrap().iter().map(|s| s[0].as_str().unwrap()).collect();
    assert!(stages.contains(&"bounce2_points") && stages.contains(&"bounce2_vals"), "{stages:?}");
    assert!(v["brute_force_vs_exact"]["rel_rmse"].as_f64().unwrap().is_finite());
    assert!(!gpu.status.success());
    assert!(stderr(&gpu).contains("settings.bounces"), "{}", stderr(&gpu));
}

/// The exact reference's options: bad values and combinations are named, not panics.
#[test]
fn exact_reference_flags_are_checked() {
    let scene = fixture("scenes/cornell_bunny_small.json");
    let scene = scene.to_str().unwrap();
    for (args, flag) in [
        (&["--reference", "exact", "--reference-samples", "1"][..], "--reference-samples"),
        (&["--reference", "exact", "--spp", "0"][..], "--spp"),
        (&["--reference", "exact", "--spp", "100000"][..], "--spp"),
        (&["--reference", "exact", "--reference-device", "gpu", "--spp", "4"][..], "--reference-device"),
        (&["--reference", "exact", "--reference-samples", "8", "--val-stride", "4"][..], "--reference-samples"),
        (&["--reference-samples", "8"][..], "--reference"),
    ] {
        let o = relume(&[&["compare", scene, "--width", "8", "--height", "8"][..], args].concat());
        assert!(!o.status.success(), "{args:?} must fail");
        assert!(stderr(&o).contains(flag) && !stderr(&o).contains("panicked"), "{args:?}: {}", stderr(&o));
    }
    // The GPU estimator's draws, on `render` and on `bench --levels`.
    let out = super::scratch("cli-estimator-flags");
    let out = out.to_str().unwrap();
    for (command, args, flag) in [
        ("render", &["--method", "estimator", "--draws", "0"][..], "--draws"),
        ("render", &["--method", "estimator", "--draws", "257"][..], "--draws"),
        ("render", &["--draws", "8"][..], "--draws"),
        ("bench", &["--levels", "--gpu-estimator", "0,8"][..], "--gpu-estimator"),
        ("bench", &["--levels", "--gpu-estimator", "8,x"][..], "--gpu-estimator"),
    ] {
        let o = relume(&[&[command, scene, "--width", "8", "--height", "8", "--out", out][..], args].concat());
        assert!(!o.status.success(), "{command} {args:?} must fail");
        assert!(stderr(&o).contains(flag) && !stderr(&o).contains("panicked"), "{args:?}: {}", stderr(&o));
    }
}

/// `record-synthetic`: every out-of-range flag and a scene without a spot light are named, not
/// panics; a good call writes a recording that `Recording::open` reads, one frame per pose.
#[test]
fn record_synthetic_checks_its_flags_and_writes_a_readable_recording() {
    let scene = fixture("scenes/cornell_bunny_small.json");
    let scene = scene.to_str().unwrap();
    let out = super::scratch("cli-record-synthetic");
    let out = out.to_str().unwrap();
    for (args, flag) in [
        (&["--frames", "0"][..], "--frames"),
        (&["--frames", "1001"][..], "--frames"),
        (&["--arc-deg", "301"][..], "--arc-deg"),
        (&["--turn-deg", "-181"][..], "--turn-deg"),
        (&["--turn-deg", "nan"][..], "--turn-deg"),
        (&["--radiance-scale=0"][..], "--radiance-scale"),
        (&["--width", "0"][..], "width"),
    ] {
        let o = relume(&[&["record-synthetic", scene, "--out", out][..], args].concat());
        assert!(!o.status.success(), "{args:?} must fail");
        assert!(stderr(&o).contains(flag) && !stderr(&o).contains("panicked"), "{args:?}: {}", stderr(&o));
    }
    let unlit = fixture("scenes/mr_bunny.json");
    let o = relume(&["record-synthetic", unlit.to_str().unwrap(), "--out", out]);
    assert!(!o.status.success() && !stderr(&o).contains("panicked"), "{}", stderr(&o));
    assert!(stderr(&o).contains("light"), "names the missing spot light: {}", stderr(&o));

    let o = relume(&[
        "record-synthetic",
        scene,
        "--out",
        out,
        "--frames",
        "3",
        "--turn-deg",
        "-20",
        "--width",
        "24",
        "--height",
        "16",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let options = relume::rgbd::recording::RecordingOptions::default();
    let recording = relume::rgbd::recording::Recording::open(std::path::Path::new(out), &options).expect("reads back");
    assert_eq!(recording.len(), 3);
    assert_eq!((recording.intrinsics().width, recording.intrinsics().height), (24, 16));
}

/// `replay --server` and `load`: bad flags and an unreachable server are named, not panics.
#[test]
fn client_commands_name_bad_flags_and_unreachable_servers() {
    let recording = fixture("recordings/tum_fr1_xyz");
    let scene = fixture("scenes/mr_bunny.json");
    let (recording, scene) = (recording.to_str().unwrap(), scene.to_str().unwrap());
    let out = scratch("cli_client");
    let out = out.to_str().unwrap();
    let cases: [(&[&str], &str); 5] = [
        (&["replay", recording, "--scene", scene, "--out", out, "--server", "https://x:1"], "--server: scheme `https`"),
        (
            &["replay", recording, "--scene", scene, "--out", out, "--server", "http://x:1", "--accumulate"],
            "--accumulate",
        ),
        // Port 1 on loopback: nothing listens there.
        (
            &["replay", recording, "--scene", scene, "--out", out, "--server", "http://127.0.0.1:1"],
            "cannot reach the server",
        ),
        (&["load", "--seconds", "0"], "--seconds"),
        (&["load", "--streams", "0", "--http", "0", "--server", "http://127.0.0.1:1"], "at least one client"),
    ];
    for (args, needle) in cases {
        let o = relume(args);
        assert!(!o.status.success(), "{args:?}");
        assert!(stderr(&o).contains(needle) && !stderr(&o).contains("panicked"), "{args:?}: {}", stderr(&o));
    }
}

/// A scene lit by `lights` alone renders its direct light, and `compare` takes it (its lights'
/// RSMs make VALs); a scene with neither is refused, naming `light`.
#[test]
fn render_takes_a_scene_lit_by_lights_alone() {
    let dir = scratch("cli_render_lights");
    let mut scene = fixture_scene_json("cornell_bunny_small");
    scene.as_object_mut().unwrap().remove("light");
    let neither = dir.join("neither.json");
    std::fs::write(&neither, scene.to_string()).unwrap();
    scene["lights"] = serde_json::json!([{"type": "point", "position": [0, 1.8, 0], "intensity": [2, 2, 2]}]);
    let lit = dir.join("lights.json");
    std::fs::write(&lit, scene.to_string()).unwrap();
    let exr = dir.join("direct.exr");
    let png = dir.join("direct.png");
    let args = ["--component", "direct", "--width", "24", "--height", "24", "--hdr", exr.to_str().unwrap()];
    let o = relume(&[&["render", lit.to_str().unwrap(), "--out", png.to_str().unwrap()], &args[..]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("lights_direct"), "{}", stderr(&o));
    let hdr = image::open(&exr).unwrap().into_rgba32f();
    assert!(hdr.pixels().any(|p| p.0[0] > 0.0), "the point light reaches the image");
    let o = relume(&["compare", lit.to_str().unwrap(), "--width", "24", "--height", "24"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(report["vals"].as_u64().unwrap() > 0, "the point light's RSM makes VALs: {report}");
    let o = relume(&[&["render", neither.to_str().unwrap(), "--out", png.to_str().unwrap()], &args[..]].concat());
    assert!(!o.status.success());
    assert!(stderr(&o).contains("light: required by this command unless the scene has `lights`"), "{}", stderr(&o));
}

/// With GPU timestamps (what real GPUs use; lavapipe only when `RELUME_TIMING=gpu` asks), every
/// technique's passes record valid timestamp writes: a stage made of several passes writes its
/// beginning in the first and its end in the last, none in between (wgpu refuses writes with
/// neither). `compare --reference exact` runs the exact reference in rounds and every visibility
/// mode; `bench --levels` every level, the near field and the clusters among them.
#[test]
fn every_technique_records_valid_gpu_timestamps() {
    let scene = fixture("scenes/cornell_bunny_small.json");
    let dir = scratch("cli_gpu_timestamps");
    let run = |args: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_relume")).env("RELUME_TIMING", "gpu").args(args).output().unwrap();
        assert!(o.status.success(), "relume {args:?}: {}", stderr(&o));
        o
    };
    let o = run(&["compare", scene.to_str().unwrap(), "--width", "16", "--height", "12", "--reference", "exact"]);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    assert_eq!(v["timing"].as_str(), Some("gpu_timestamps"), "the adapter must offer timestamps for this test: {v}");
    run(&[
        "bench",
        scene.to_str().unwrap(),
        "--levels",
        "--width",
        "16",
        "--height",
        "12",
        "--out",
        dir.to_str().unwrap(),
    ]);
    let levels: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("levels.json")).unwrap()).unwrap();
    assert_eq!(levels["levels"].as_array().map(Vec::len), Some(4), "{levels}");
}

/// A scene whose measured `accurate` level names the estimator renders with it at that level
/// (the summary's method and stages: the GPU pass, or on a CPU adapter its CPU twin), and with
/// the sparse method at `balanced`.
#[test]
fn a_measured_level_naming_the_estimator_renders_with_it() {
    let mut scene = fixture_scene_json("cornell_bunny_small");
    scene["settings"]["levels"] =
        serde_json::json!({"accurate": {"measured": "a test", "technique": "estimator", "draws": 4}});
    let out = scratch("cli-estimator-level");
    let path = out.join("scene.json");
    std::fs::write(&path, scene.to_string()).unwrap();
    let (estimator, twin) = ("estimator", relume::twin::exact_cpu::STAGE);
    for (quality, method, stages) in
        [("accurate", "estimator", [estimator, twin]), ("balanced", "sparse", ["gather"; 2])]
    {
        let png = out.join(format!("{quality}.png"));
        let o = relume(&[
            "render",
            path.to_str().unwrap(),
            "--quality",
            quality,
            "--width",
            "12",
            "--height",
            "10",
            "--out",
            png.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(summary["method"], method, "{quality}");
        assert!(stages.iter().any(|s| summary["timings_ms"].get(s).is_some()), "{quality}: {summary}");
        assert_eq!(summary["timings_ms"].get("gather").is_some(), method == "sparse", "{quality}: {summary}");
    }
}

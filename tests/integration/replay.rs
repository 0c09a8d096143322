//! Mixed-reality replay of the fixture recording (issue: RGB-D frames as light sources): the
//! virtual bunny receives the room's light, takes on its colour, and the composite is the
//! camera image wherever the bunny is not drawn.

use super::{fixture, fixture_scene_json, gpu, load_scene, scratch};
use relume::mr::{MrOptions, MrRenderer};
use relume::rgbd::RgbdFrame;
use relume::rgbd::recording::{Recording, RecordingOptions};
use relume::scene::Scene;

/// Small and coarse so the test stays fast on lavapipe: 160x120 output, one VAL per 16x16
/// depth pixels (about 1,200 VALs). Without differential rendering: these tests check the
/// real-to-virtual light and the compositing, which leaves the camera image untouched around
/// the bunny; `mr_differential_*` below checks what the bunny does to the desk.
fn small_scene() -> Scene {
    let mut scene = load_scene("mr_bunny");
    scene.settings.rgbd.grid_step = 16;
    scene.settings.mr.differential = false;
    scene
}

fn options() -> MrOptions {
    MrOptions { width: 160, height: 120, exposure: 1.0, accumulate: None }
}

fn recording() -> Recording {
    Recording::open(&fixture("recordings/tum_fr1_xyz"), &RecordingOptions::default()).unwrap()
}

/// `r / (r + g + b)` of a summed colour.
fn red_share(c: glam::Vec3) -> f32 {
    c.x / c.element_sum()
}

#[test]
fn bunny_is_lit_by_the_room_and_composited_over_the_camera_image() {
    let gpu = gpu();
    let scene = small_scene();
    let frame = recording().frame(0).unwrap();
    let mut mr = MrRenderer::new(&gpu, &scene, options()).unwrap();
    let out = mr.render_frame(&gpu, &frame).unwrap();
    assert!(out.val_count > 500, "the room gives VALs: {}", out.val_count);
    let covered: Vec<usize> = (0..out.indirect.pixels.len()).filter(|&i| out.indirect.covered(i)).collect();
    assert!(covered.len() > 100, "the bunny is in view: {} pixels", covered.len());
    let lit = covered.iter().filter(|&&i| out.indirect.rgb(i).max_element() > 0.0).count();
    assert!(lit * 2 > covered.len(), "most of the bunny receives indirect light: {lit} of {}", covered.len());
    assert!(out.sparse_irradiance.iter().any(|e| e.max_element() > 0.0));

    // Where the bunny is not drawn, the composite is the camera image (nearest pixel of the
    // 640x480 frame for each 160x120 output pixel), exactly.
    let (w, fw) = (160usize, 640usize);
    let mut differing_outside = 0;
    let mut drawn = 0;
    for i in 0..w * 120 {
        let (x, y) = (i % w, i / w);
        let camera = frame.color[(y * 4) * fw + x * 4];
        if out.composited[i] != camera {
            if out.indirect.covered(i) {
                drawn += 1;
            } else {
                differing_outside += 1;
            }
        }
    }
    assert_eq!(differing_outside, 0, "pixels changed where the bunny is absent");
    assert!(drawn > 50, "the bunny is drawn over the camera image: {drawn} pixels");
}

/// The render over the pixels the bunny's box projects to (the default) is the render over
/// the whole image: every pixel the full render covers is covered, with the same light (each
/// crop pixel sees the full image's ray through it), and the composites agree; the differential
/// pass runs in both, so this holds for the relit desk too.
#[test]
fn the_render_over_the_contents_pixels_is_the_whole_images() {
    let gpu = gpu();
    let mut scene = load_scene("mr_bunny_differential");
    scene.settings.rgbd.grid_step = 16;
    let frame = recording().frame(0).unwrap();
    let mut frames = [true, false].map(|crop| {
        let mut mr = MrRenderer::new(&gpu, &scene, MrOptions { width: 320, height: 240, ..options() }).unwrap();
        mr.set_crop_to_content(crop);
        mr.render_frame(&gpu, &frame).unwrap()
    });
    let [cropped, full] = &mut frames;
    assert_eq!((cropped.indirect.width, cropped.indirect.height), (320, 240));
    let covered = |f: &relume::mr::MrFrame| (0..320 * 240).filter(|&i| f.indirect.covered(i)).collect::<Vec<_>>();
    let pixels = covered(full);
    assert!(pixels.len() > 500, "the bunny is in view: {} pixels", pixels.len());
    assert_eq!(covered(cropped), pixels, "the same pixels covered");
    let peak = pixels.iter().map(|&i| full.indirect.rgb(i).max_element()).fold(0.0f32, f32::max);
    let off = pixels
        .iter()
        .filter(|&&i| (cropped.indirect.rgb(i) - full.indirect.rgb(i)).abs().max_element() > 1e-4 * peak)
        .count();
    assert!(off * 1000 <= pixels.len(), "{off} of {} pixels' light differs", pixels.len());
    let apart = cropped.composited.iter().zip(&full.composited).filter(|(a, b)| a != b).count();
    assert!(apart * 1000 <= cropped.composited.len(), "{apart} composite pixels differ");
}

/// Tinting the room red tints the bunny's indirect light red: with the green and blue of the
/// camera image scaled by 0.3 the bunny's red share must rise from near neutral to near the
/// VALs' own red share (within 0.05: the white bunny reflects the mix of VALs it sees, which
/// is not the mix of all VALs).
#[test]
fn bunny_takes_on_the_rooms_colour() {
    let gpu = gpu();
    let scene = small_scene();
    let frame = recording().frame(0).unwrap();
    let tinted = RgbdFrame {
        color: frame.color.iter().map(|c| [c[0], (c[1] as f32 * 0.3) as u8, (c[2] as f32 * 0.3) as u8]).collect(),
        ..frame.clone()
    };
    let mut shares = Vec::new();
    for f in [&frame, &tinted] {
        let mut mr = MrRenderer::new(&gpu, &scene, options()).unwrap();
        let out = mr.render_frame(&gpu, f).unwrap();
        let bunny: glam::Vec3 = (0..out.indirect.pixels.len()).map(|i| out.indirect.rgb(i)).sum();
        let vals: glam::Vec3 = relume::twin::rgbd::rgbd_vals(f, &scene.settings.rgbd).iter().map(|v| v.flux).sum();
        shares.push((red_share(bunny), red_share(vals)));
    }
    let (neutral, red) = (shares[0], shares[1]);
    eprintln!("red share (bunny, VALs): original {neutral:?}, tinted {red:?}");
    assert!((neutral.0 - neutral.1).abs() < 0.05, "untinted: {neutral:?}");
    assert!((red.0 - red.1).abs() < 0.05, "tinted: {red:?}");
    assert!(red.0 > neutral.0 + 0.2, "the tint shows on the bunny: {neutral:?} -> {red:?}");
}

/// A frame without valid depth gives no VALs and no indirect light, and no error.
#[test]
fn frame_without_depth_gives_no_light() {
    let gpu = gpu();
    let scene = small_scene();
    let frame = recording().frame(0).unwrap();
    let empty = RgbdFrame { depth: vec![0.0; frame.depth.len()], ..frame };
    let mut mr = MrRenderer::new(&gpu, &scene, options()).unwrap();
    let out = mr.render_frame(&gpu, &empty).unwrap();
    assert_eq!(out.val_count, 0);
    assert!(out.indirect.pixels.iter().all(|p| p[0] == 0.0 && p[1] == 0.0 && p[2] == 0.0));
}

/// Accumulating keeps VALs from earlier frames: the set grows as frames see more of the room.
/// (Its count is not comparable with one frame's: a frame's VALs that share a 5 cm cell are
/// merged, 905 into 677 on frame 0, and a surface seen again replaces its older VALs.)
#[test]
fn accumulation_keeps_earlier_vals() {
    let gpu = gpu();
    let scene = small_scene();
    let rec = recording();
    let frames: Vec<RgbdFrame> = [0, 12, 24].iter().map(|&i| rec.frame(i).unwrap()).collect();
    let acc = relume::mr::AccumulateOptions::default();
    let mut plain = MrRenderer::new(&gpu, &scene, options()).unwrap();
    let mut accumulating = MrRenderer::new(&gpu, &scene, MrOptions { accumulate: Some(acc), ..options() }).unwrap();
    let mut counts = Vec::new();
    for f in &frames {
        let a = plain.render_frame(&gpu, f).unwrap();
        let b = accumulating.render_frame(&gpu, f).unwrap();
        counts.push((a.val_count, b.val_count));
    }
    eprintln!("VALs (plain, accumulated): {counts:?}");
    assert!(counts.windows(2).all(|w| w[1].1 >= w[0].1), "the accumulated set grows: {counts:?}");
    assert!(counts[2].1 > counts[0].1, "frames 12 and 24 add what frame 0 did not see: {counts:?}");
}

/// `relume replay` writes one composited and one indirect PNG per frame and a summary.
#[test]
fn replay_command_writes_frames_and_summary() {
    let out = scratch("replay_cli");
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_relume"))
        .args(["replay", fixture("recordings/tum_fr1_xyz").to_str().unwrap(), "--scene"])
        .arg(fixture("scenes/mr_bunny.json"))
        .args(["--frames", "2", "--width", "80", "--height", "60", "--out"])
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success());
    for dir in ["composited", "indirect"] {
        for name in ["0000.png", "0001.png"] {
            let image = image::open(out.join(dir).join(name)).unwrap();
            assert_eq!((image.width(), image.height()), (80, 60));
        }
    }
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["frames"], 2);
    assert_eq!(summary["vals_per_frame"].as_array().unwrap().len(), 2);
    assert_eq!(summary["irradiance_change"].as_array().unwrap().len(), 1);
    assert!(summary["stage_ms"]["rgbd_vals"].as_array().unwrap().iter().all(|v| v.as_f64().unwrap() >= 0.0));
    // The composite (CPU) is a stage of its own, as on streams, so that the stages account
    // for the frame.
    let composite = summary["stage_ms"]["composite"].as_array().expect("a composite stage");
    assert_eq!(composite.len(), 2);
    assert!(composite.iter().all(|v| v.as_f64().unwrap() > 0.0));
}

/// `relume replay --budget-ms` with a budget no frame can meet falls, frame by frame, to the
/// cheapest rung of its ladder and reports what each frame ran at (the level, its parameters),
/// each frame's error estimate and the composite's frame-to-frame change; the composites stay
/// at the output size while the render size drops (dynamic resolution).
#[test]
fn replay_with_a_budget_reports_the_levels_it_ran_at() {
    let out = scratch("replay_budget");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_relume"))
        .args(["replay", fixture("recordings/tum_fr1_xyz").to_str().unwrap(), "--scene"])
        .arg(fixture("scenes/mr_bunny.json"))
        .args(["--frames", "5", "--width", "80", "--height", "60", "--budget-ms", "0.5", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(stderr.contains("budget 0.5 ms: p90 frame after the first 5"), "{stderr}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["budget_ms"], 0.5);
    let parameters = summary["parameters"].as_array().unwrap();
    assert_eq!(parameters.len(), 5);
    assert_eq!(parameters[0]["level"], "balanced", "the scene's level first");
    let last = &parameters[4];
    assert_eq!((last["level"].as_str(), last["occlusion"].as_str()), (Some("fast"), Some("off")), "{last}");
    assert_eq!((last["vals_step"].as_u64(), last["resolution_scale"].as_f64()), (Some(3), Some(0.5)), "{last}");
    assert_eq!(last["receivers_step"].as_u64(), Some(1), "no differential pass, no receivers to thin: {last}");
    assert!(summary["level_frames"]["fast"].as_u64().unwrap() >= 2, "{summary}");
    let estimates = summary["error_estimate"].as_array().unwrap();
    assert!(estimates.iter().all(|e| e.as_f64().is_some_and(|e| e.is_finite() && e >= 0.0)), "{estimates:?}");
    assert_eq!(summary["composite_change"].as_array().unwrap().len(), 4);
    let image = image::open(out.join("composited").join("0004.png")).unwrap();
    assert_eq!((image.width(), image.height()), (80, 60));
}

/// With the differential pass, the budget's rungs below `fast` thin its receivers: the frames
/// the controller moved there report `receivers_step` 2 (4 at half size, where a budget no
/// frame meets ends) and compute about a quarter (a sixteenth) of the receivers the first frame
/// (the scene's level) did; a scene without the pass (the test above) keeps them. Receivers
/// every 16 pixels, so that the pass stays cheap here.
#[test]
fn a_budget_thins_the_differential_receivers() {
    let out = scratch("replay_budget_receivers");
    let mut scene = fixture_scene_json("mr_bunny_differential");
    scene["settings"]["mr"] = serde_json::json!({ "receiver_step": 16 });
    let path = out.join("scene.json");
    std::fs::write(&path, scene.to_string()).unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_relume"))
        .args(["replay", fixture("recordings/tum_fr1_xyz").to_str().unwrap(), "--scene"])
        .arg(&path)
        .args(["--frames", "5", "--width", "80", "--height", "60", "--budget-ms", "0.5", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let parameters = summary["parameters"].as_array().unwrap();
    let steps: Vec<u64> = parameters.iter().map(|p| p["receivers_step"].as_u64().unwrap()).collect();
    assert_eq!(steps[0], 1, "the scene's level first: {steps:?}");
    assert!(steps[1..].iter().all(|s| [2, 4].contains(s)), "then the thinned rungs: {steps:?}");
    assert_eq!(steps[4], 4, "the half-size rungs by the last frame: {steps:?}");
    let receivers: Vec<f64> =
        summary["receivers_per_frame"].as_array().unwrap().iter().map(|r| r.as_f64().unwrap()).collect();
    assert!(receivers[0] > 100.0, "receivers per frame {receivers:?}");
    for (i, &step) in steps.iter().enumerate().skip(1) {
        let expected = 1.0 / (step * step) as f64;
        let ratio = receivers[i] / receivers[0];
        assert!((0.4 * expected..1.6 * expected).contains(&ratio), "frame {i}: receivers per frame {receivers:?}");
    }
}

/// A scene with its own spot light gets the spot's VALs on top of the frame's: both sources
/// append to one VAL buffer sized for both.
#[test]
fn spot_light_and_frame_light_together() {
    let gpu = gpu();
    let dir = fixture("scenes");
    let json = std::fs::read_to_string(dir.join("mr_bunny.json")).unwrap().replacen(
        "\"camera\"",
        r#""light": { "position": [0.84, 0.70, 1.6], "direction": [0, 0, -1], "inner_angle_deg": 10,
                     "outer_angle_deg": 20, "intensity": [1, 1, 1] },
        "camera""#,
        1,
    );
    let mut scene = Scene::from_json_str(&json, &dir).unwrap();
    scene.settings.rgbd.grid_step = 16;
    scene.settings.rsm_resolution = 16;
    let frame = recording().frame(0).unwrap();
    let room_only = MrRenderer::new(&gpu, &small_scene(), options()).unwrap().render_frame(&gpu, &frame).unwrap();
    let mut mr = MrRenderer::new(&gpu, &scene, options()).unwrap();
    let both = mr.render_frame(&gpu, &frame).unwrap();
    assert!(both.timings.stages.iter().any(|(n, _)| n == "rsm_vals"));
    assert!(both.val_count > room_only.val_count, "{} vs {}", both.val_count, room_only.val_count);
    assert!(both.val_count <= room_only.val_count + 16 * 16);
}

/// Differential rendering in the replay: the desk around the bunny changes, mostly darker (the
/// bunny's shadow: it blocks the light the desk receives from above, here the `auto`
/// environment), and the camera image is untouched beyond the receiver margin.
#[test]
fn mr_differential_replay_shades_the_desk() {
    use relume::mr::environment::{DirectionGrid, Environment};
    let gpu = gpu();
    let mut scene = small_scene();
    scene.settings.mr.differential = true;
    let frame = recording().frame(0).unwrap();
    let mut plain = MrRenderer::new(&gpu, &small_scene(), options()).unwrap();
    plain.set_environment(Environment::Auto {
        grid: DirectionGrid::new(8, glam::Vec3::Z),
        distribution: Default::default(),
        albedo: None,
    });
    let before = plain.render_frame(&gpu, &frame).unwrap();
    let mut mr = MrRenderer::new(&gpu, &scene, options()).unwrap();
    mr.set_environment(Environment::Auto {
        grid: DirectionGrid::new(8, glam::Vec3::Z),
        distribution: Default::default(),
        albedo: None,
    });
    let after = mr.render_frame(&gpu, &frame).unwrap();
    assert!(after.timings.stages.iter().any(|(n, _)| n == relume::mr::DIFFERENTIAL_STAGE));
    let luma = |c: [u8; 3]| u32::from(c[0]) + u32::from(c[1]) + u32::from(c[2]);
    let (mut darker, mut brighter) = (0, 0);
    for (i, (b, a)) in before.composited.iter().zip(&after.composited).enumerate() {
        if after.indirect.covered(i) || a == b {
            continue;
        }
        if luma(*a) < luma(*b) { darker += 1 } else { brighter += 1 }
    }
    eprintln!("around the bunny: {darker} pixels darker, {brighter} brighter");
    assert!(darker > 50, "the bunny shades the desk: {darker} darker pixels");
    assert!(darker > brighter, "{darker} darker vs {brighter} brighter");
    // Far from the bunny (the top rows of the image, beyond the margin) nothing changes.
    assert_eq!(before.composited[..160 * 10], after.composited[..160 * 10]);
}

/// The differential pass follows the frame's level: a replay at `reference` renders the
/// virtual content with the exact reference and relights the room with the exact differential
/// pass; at the default level, the sparse method and the fast pass.
#[test]
fn replay_at_reference_runs_the_exact_differential_pass() {
    use relume::scene::settings::DifferentialMethod;
    let gpu = gpu();
    let frame = recording().frame(0).unwrap();
    let path = fixture("scenes/mr_bunny.json");
    let mut json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let settings = &mut json["settings"];
    settings["rgbd"]["grid_step"] = 32.into();
    settings["mr"] = serde_json::json!({ "differential": true, "receiver_step": 16 });
    let mut ran = Vec::new();
    for quality in ["balanced", "reference"] {
        json["settings"]["quality"] = quality.into();
        let scene = Scene::from_json_str(&json.to_string(), path.parent().unwrap()).unwrap();
        let options = MrOptions { width: 32, height: 24, ..options() };
        let out = MrRenderer::new(&gpu, &scene, options).unwrap().render_frame(&gpu, &frame).unwrap();
        let d = out.differential.expect("the differential pass ran");
        assert!(d.light.len() >= 10, "{quality}: receivers near the bunny ({})", d.light.len());
        assert!(
            out.timings.stages.iter().any(|(s, _)| s == relume::renderer::stage::EXACT) == (quality == "reference")
        );
        ran.push(d.method);
    }
    assert_eq!(ran, [DifferentialMethod::Fast, DifferentialMethod::Exact]);
}

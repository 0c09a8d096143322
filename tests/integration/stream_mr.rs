//! Mixed reality on the service: a stream frame goes through the mixed-reality pipeline of `relume
//! replay` (`mr::MrPipeline`): the `auto` environment (its level raised by the differential
//! receivers), the differential relighting of the real surfaces, the composite. Frames of
//! `fixtures/recordings/tum_fr1_xyz` at a quarter of their size (160x120), the bunny with 256
//! sparse points, one VAL and one receiver per 4x4 pixels, the differential pass on the CPU twin
//! (`settings.mr.device` `auto` on lavapipe): the three tests take about 3 s together on
//! lavapipe (dev profile).

use relume::mr::environment::Environment;
use relume::mr::{MrFrame, MrOptions, MrRenderer};
use relume::rgbd::RgbdFrame;
use relume::rgbd::recording::{Recording, RecordingOptions};
use relume::scene::{Scene, SceneDescription};
use relume::service::config::Limits;
use relume::service::wire::{self, ClientMessage, proto, proto::envelope::Body};
use serde_json::{Value, json};

use super::fixture;
use super::service::{TestServer, envelope, fixture_scene, streamed_png};

/// The recording's frames are divided by this on each side.
const DOWNSCALE: u32 = 4;

/// `mr_bunny.json` made cheap (256 sparse points, `grid_step` and `receiver_step` 4 on the
/// 160x120 frames), with the differential pass on or off and the `auto` environment, and the
/// bunny 0.16 m further along the desk than in the fixture so that its contact with the desk
/// is in view (the README's "The shadow is still faint" placement).
pub(super) fn mr_scene(differential: bool) -> Value {
    let mut scene = fixture_scene("mr_bunny", 64);
    scene["meshes"][0]["sparse_points"] = 256.into();
    scene["anchor"]["translation"] = json!([0.68, 0.66, 0.70]);
    scene["settings"]["rgbd"]["grid_step"] = 4.into();
    scene["settings"]["mr"] = json!({ "differential": differential, "receiver_step": 4 });
    scene["settings"]["environment"] = json!({ "source": "auto" });
    scene
}

/// Frames `indices` of the fixture recording at 1/[`DOWNSCALE`] of their size: the stream
/// message (as a Rust client encodes it) and the frame the server decodes from it.
pub(super) fn frames(indices: &[usize]) -> Vec<(Vec<u8>, RgbdFrame)> {
    let recording = Recording::open(&fixture("recordings/tum_fr1_xyz"), &RecordingOptions::default()).expect("rec");
    indices
        .iter()
        .map(|&i| {
            let frame = recording.frame(i).expect("frame").downsampled(DOWNSCALE);
            let bytes = wire::encode_rgbd_frame(i as u64, &frame);
            let Ok(ClientMessage::Frame(decoded)) = wire::decode(&bytes, &Limits::default()) else {
                panic!("frame {i} decodes");
            };
            (bytes, decoded.frame)
        })
        .collect()
}

/// `relume replay`'s renderer on `scene` (paths relative to `fixtures/`, its
/// `settings.environment` read as the replay reads it), relighting `frames` in order.
pub(super) fn offline(scene: &Value, frames: &[&RgbdFrame]) -> Vec<MrFrame> {
    let gpu = super::gpu();
    let text = scene.to_string();
    let loaded = Scene::from_json_str(&text, &fixture("")).expect("scene");
    let environment = SceneDescription::from_json_str(&text).expect("description").settings.environment;
    let k = frames[0].intrinsics;
    let options = MrOptions { width: k.width, height: k.height, exposure: 1.0, accumulate: None };
    let mut mr = MrRenderer::new(&gpu, &loaded, options).expect("renderer");
    mr.set_environment(Environment::from_settings(&environment, &fixture("")).expect("environment"));
    frames.iter().map(|f| mr.render_frame(&gpu, f).expect("render")).collect()
}

/// The largest difference in any channel, and how many pixels differ by more than one level.
pub(super) fn difference(a: &image::RgbImage, b: &[[u8; 3]]) -> (u8, usize) {
    let per_pixel: Vec<u8> =
        a.pixels().zip(b).map(|(p, q)| (0..3).map(|c| p.0[c].abs_diff(q[c])).max().unwrap_or(0)).collect();
    (per_pixel.iter().copied().max().unwrap_or(0), per_pixel.iter().filter(|&&d| d > 1).count())
}

/// A stream of a scene with `mr.differential` and the `auto` environment gives the offline
/// replay's composites; its timings name the environment and differential stages; and a model
/// transform that moves the bunny moves its shadow too (the differential pass's BVH, re-emitters
/// and bounds are rebuilt for the new placement, not kept from the first frames).
///
/// Tolerance: frames 0 and 1 identical (both paths run `MrPipeline::render_frame`, and the
/// RGB-D VALs come in their cells' order, so every float sum over them is the same); the moved
/// frame within one 8-bit level, the composite's rounding: offline the bunny is placed by the
/// scene file, on the stream by a control message, two paths to the same f32 transform. A
/// difference of whole levels would be a different pipeline. (Measured: frames 0 and 1 0 levels,
/// the moved frame 1; with the first placement's differential pass kept after the move, the moved
/// frame is 75 levels off.)
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stream_frame_is_relit_as_the_offline_replay_relights_it() {
    let scene = mr_scene(true);
    let frames = frames(&[0, 1, 2]);
    let server = TestServer::start(|_| {}).await;
    let id = server.create(&scene).await;
    let mut ws = server.stream(&id).await;
    let mut streamed = Vec::new();
    for (i, (bytes, _)) in frames.iter().enumerate().take(2) {
        let (rendered, image) = streamed_png(ws.exchange(bytes.clone()).await, i as u64);
        let stages: Vec<&str> = rendered.timings.iter().map(|t| t.stage.as_str()).collect();
        for stage in ["rgbd_vals", "environment", "gather", "differential", "composite"] {
            assert!(stages.contains(&stage), "frame {i}: {stage} missing from {stages:?}");
        }
        streamed.push(image);
    }
    // The bunny moved 8 cm along the desk (its own transform but the translation).
    let moved = json!({ "translation": [0.08, 0.0, 0.0], "rotation_deg": [90, 0, 0], "scale": 1.3 });
    let control = proto::Control {
        request_id: 1,
        model_transforms: vec![proto::ModelTransform {
            mesh_index: 0,
            translation: Some(proto::Vec3 { x: 0.08, y: 0.0, z: 0.0 }),
            rotation_deg: Some(proto::Vec3 { x: 90.0, y: 0.0, z: 0.0 }),
            scale: Some(proto::Vec3 { x: 1.3, y: 1.3, z: 1.3 }),
        }],
        ..Default::default()
    };
    assert!(matches!(ws.exchange(envelope(Body::Control(control))).await, Body::SettingsAck(_)));
    let (_, moved_image) = streamed_png(ws.exchange(frames[2].0.clone()).await, 2);
    drop(ws);
    server.stop().await;

    let mut moved_scene = scene.clone();
    moved_scene["meshes"][0]["transform"] = moved;
    let (expected, expected_moved) = tokio::task::spawn_blocking(move || {
        let all: Vec<&RgbdFrame> = frames.iter().map(|(_, f)| f).collect();
        (offline(&scene, &all), offline(&moved_scene, &all[2..]))
    })
    .await
    .expect("the offline replay");
    for (i, (wire, offline)) in streamed.iter().zip(&expected).enumerate() {
        let (worst, over) = difference(wire, &offline.composited);
        eprintln!("frame {i}: streamed vs offline composite: worst {worst} levels, {over} pixels over 1");
        assert_eq!(worst, 0, "frame {i}: the streamed composite differs from the offline one by {worst} levels");
    }
    let (worst, over) = difference(&moved_image, &expected_moved[0].composited);
    let (unmoved, unmoved_over) = difference(&moved_image, &expected[2].composited);
    eprintln!(
        "moved frame: vs the offline moved scene worst {worst} ({over} pixels over 1); vs the unmoved scene \
         worst {unmoved} ({unmoved_over} pixels over 1)"
    );
    assert!(unmoved_over > 50, "the move changes the composite ({unmoved_over} pixels over 1 level)");
    assert!(worst <= 1, "the moved frame differs from the offline replay of the moved scene by {worst} levels");
}

/// With `mr.differential` on, a streamed frame's real surfaces around the bunny change (its
/// shadow and reflected light); off, every pixel the bunny does not cover is the camera's.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_differential_stream_frame_relights_the_real_surfaces_near_the_object() {
    let frames = frames(&[0]);
    let (bytes, frame) = &frames[0];
    let server = TestServer::start(|_| {}).await;
    let mut images = Vec::new();
    for differential in [false, true] {
        let id = server.create(&mr_scene(differential)).await;
        let mut ws = server.stream(&id).await;
        let (rendered, image) = streamed_png(ws.exchange(bytes.clone()).await, 0);
        let stages: Vec<&str> = rendered.timings.iter().map(|t| t.stage.as_str()).collect();
        assert_eq!(stages.contains(&"differential"), differential, "{stages:?}");
        images.push(image);
    }
    server.stop().await;
    let (off, on) = (&images[0], &images[1]);
    let width = frame.intrinsics.width as usize;
    // The bunny: where the composite without the differential pass is not the camera's image.
    let bunny: Vec<usize> =
        (0..frame.color.len()).filter(|&i| off.as_raw()[3 * i..3 * i + 3] != frame.color[i]).collect();
    assert!(bunny.len() > 100, "the bunny is drawn ({} pixels)", bunny.len());
    let changed: Vec<usize> = (0..frame.color.len())
        .filter(|&i| !bunny.contains(&i) && on.as_raw()[3 * i..3 * i + 3] != frame.color[i])
        .collect();
    let distance_squared = |i: usize| {
        let (x, y) = ((i % width) as i64, (i / width) as i64);
        bunny.iter().map(|&b| ((b % width) as i64 - x).pow(2) + ((b / width) as i64 - y).pow(2)).min().unwrap_or(0)
    };
    // Near the object: the receivers are the real surfaces within `receiver_margin` (0.3 m) of
    // the bunny's bounding box, which at the desk's 0.7 to 1.5 m (fx 131 px at this size) is
    // 26 to 56 pixels beyond the box; 64 pixels from the silhouette bound them all here.
    const NEAR: i64 = 64;
    let far = (0..frame.color.len()).filter(|&i| distance_squared(i) > NEAR * NEAR).count();
    let far_changed: Vec<usize> = changed.iter().copied().filter(|&i| distance_squared(i) > NEAR * NEAR).collect();
    eprintln!(
        "differential: {} real pixels changed, {} of them far from the bunny (of {far})",
        changed.len(),
        far_changed.len()
    );
    let dir = super::scratch("stream_mr_differential");
    for (name, image) in [("off", off), ("on", on)] {
        image.save(dir.join(format!("{name}.png"))).expect("written");
    }
    assert!(changed.len() > 50, "the differential pass changes the real surfaces ({} pixels)", changed.len());
    assert!(far > 1000, "the frame has real surfaces far from the bunny ({far} pixels)");
    assert!(far_changed.is_empty(), "the pass changed {} pixels far from the bunny", far_changed.len());
}

/// `settings.environment.map` on the service: a path confined to the asset directory, a file of
/// at most `max_mesh_bytes` and a map of at most `max_pixels` pixels, each refused with a 400
/// (413 for bytes) naming the field; a good map lights a stream's frames (its `environment`
/// stage runs).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_environment_map_on_the_service_is_confined_and_bounded() {
    use relume::service::scenes;
    let assets = std::fs::canonicalize(super::scratch("stream_mr_maps")).expect("scratch");
    let sky = image::Rgb32FImage::from_pixel(8, 4, image::Rgb([2.0, 1.5, 1.0]));
    sky.save(assets.join("sky.hdr")).expect("an 8x4 map");
    let wide = image::Rgb32FImage::from_pixel(64, 32, image::Rgb([1.0, 1.0, 1.0]));
    wide.save(assets.join("wide.hdr")).expect("a 64x32 map");
    std::fs::write(assets.join("notes.hdr"), "not a map").expect("written");
    let scene = |map: &str| {
        let mut scene = super::service::inline_scene();
        scene["settings"]["environment"] = json!({ "source": "map", "map": map, "rows": 4 });
        scene.to_string()
    };
    // 1,024 pixels: the 8x4 map and the 16x16 camera fit, the 64x32 map does not.
    let limits = Limits { max_pixels: 1024, ..Limits::default() };
    let refused = |map: &str, limits: &Limits| match scenes::load(&scene(map), &assets, limits) {
        Ok(_) => panic!("{map}: admitted"),
        Err(error) => {
            assert_eq!(error.field.as_deref(), Some("settings.environment.map"), "{map}: {error:?}");
            assert!(!error.message.contains(assets.to_str().expect("UTF-8")), "{map}: {}", error.message);
            error
        }
    };
    for outside in ["../stream_mr_differential/on.png", "/etc/passwd", "../../../../Cargo.toml"] {
        assert_eq!(refused(outside, &limits).code, relume::service::error::Code::PathOutsideAssets, "{outside}");
    }
    for unreadable in ["missing.hdr", "notes.hdr"] {
        assert_eq!(refused(unreadable, &limits).code, relume::service::error::Code::InvalidScene, "{unreadable}");
    }
    assert_eq!(refused("wide.hdr", &limits).limit, Some("max_pixels"));
    let bytes = std::fs::metadata(assets.join("sky.hdr")).expect("sky").len() as usize;
    assert_eq!(refused("sky.hdr", &Limits { max_mesh_bytes: bytes - 1, ..limits }).limit, Some("max_mesh_bytes"));
    let (_, _, environment) = scenes::load(&scene("sky.hdr"), &assets, &limits).expect("the map is admitted");
    assert!(matches!(environment, Environment::Map { .. }), "{environment:?}");

    // Through the server: refused with a JSON 400 naming the field, and a good map lights frames.
    let dir = assets.clone();
    let server = TestServer::start(move |config| config.assets = dir).await;
    let error = server.post("/v1/scenes", &serde_json::from_str(&scene("../x.hdr")).expect("JSON")).await;
    assert_eq!(error.error(400, "path_outside_assets")["field"], "settings.environment.map");
    let id = server.create(&serde_json::from_str(&scene("sky.hdr")).expect("JSON")).await;
    let mut ws = server.stream(&id).await;
    let (bytes, _) = &frames(&[0])[0];
    let (rendered, _) = streamed_png(ws.exchange(bytes.clone()).await, 0);
    assert!(rendered.timings.iter().any(|t| t.stage == "environment"), "{:?}", rendered.timings);
    drop(ws);
    server.stop().await;
}

/// A stream of a scene with the differential pass under a budget no frame can meet falls to
/// the rungs that thin the pass's receivers (`receivers_step` 2, then 4 at the cheapest), which
/// its frames report; its first frame, at the scene's level, computes every receiver.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_budgeted_differential_stream_thins_its_receivers() {
    let frames = frames(&[0, 1, 2, 3]);
    let server = TestServer::start(|_| {}).await;
    let id = server.create(&mr_scene(true)).await;
    let mut ws = server.stream(&id).await;
    let (first, _) = streamed_png(ws.exchange(frames[0].0.clone()).await, 0);
    assert_eq!(parameter(&first, "receivers_step"), "1");
    assert!(first.timings.iter().any(|t| t.stage == "differential"), "{:?}", first.timings);
    let render = proto::RenderSettings { budget_ms: Some(0.5), ..Default::default() };
    let control = proto::Control { request_id: 1, render: Some(render), ..Default::default() };
    assert!(matches!(ws.exchange(envelope(Body::Control(control))).await, Body::SettingsAck(_)));
    let mut last = None;
    for (i, (bytes, _)) in frames.iter().enumerate().skip(1) {
        last = Some(streamed_png(ws.exchange(bytes.clone()).await, i as u64).0);
    }
    let last = last.expect("frames");
    assert_eq!(last.quality(), proto::QualityLevel::Fast, "{:?}", last.parameters);
    assert_eq!(parameter(&last, "receivers_step"), "4", "{:?}", last.parameters);
    drop(ws);
    server.stop().await;
}

/// The parameters a streamed frame reports it ran at, by name.
fn parameter(frame: &proto::RenderedFrame, name: &str) -> String {
    let found = frame.parameters.iter().find(|p| p.name == name);
    found.unwrap_or_else(|| panic!("no parameter {name} in {:?}", frame.parameters)).value.clone()
}

/// A stream's quality level, chosen at the start (`?quality=`) and changed mid-stream by a
/// control message, changes what its frames run at (the level's visibility mode and near
/// field, resolved for the scene); every frame carries its error estimate; and a budget far
/// under the frame's time makes the controller fall, frame by frame, to the cheapest rung
/// (visibility off, a third of the VAL grid, the camera drawing the simplified meshes), which
/// the frames report.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stream_changes_its_level_mid_stream_and_falls_under_a_budget() {
    let scene = mr_scene(false);
    let frames = frames(&[0, 1, 2, 3, 4, 5]);
    let server = TestServer::start(|_| {}).await;
    let id = server.create(&scene).await;
    let refused = server.get(&format!("/v1/scenes/{id}/stream?quality=best")).await;
    assert_eq!(refused.status, 400, "{}", refused.json());
    assert_eq!(refused.json()["error"]["field"], "quality", "{}", refused.json());
    let url = format!("ws://{}/v1/scenes/{id}/stream?quality=fast", server.addr);
    let (ws, _) = tokio_tungstenite::connect_async(url).await.expect("the stream opens");
    let mut ws = super::service::Ws(ws);
    let (first, _) = streamed_png(ws.exchange(frames[0].0.clone()).await, 0);
    assert_eq!(first.quality(), proto::QualityLevel::Fast);
    assert_eq!(parameter(&first, "visibility"), "disks", "the bunny can occlude itself");
    assert_eq!(parameter(&first, "near_field"), "0");
    assert_eq!(parameter(&first, "method"), "sparse");
    let estimate = first.error_estimate.expect("every frame carries its error estimate");
    assert!(estimate.rel_rmse.is_finite() && estimate.rel_rmse >= 0.0 && estimate.pixels > 0, "{estimate:?}");
    assert!(first.timings.iter().any(|t| t.stage == "error_estimate"), "{:?}", first.timings);

    let level = |quality: Option<i32>, budget_ms: Option<f32>, request_id| {
        let render = proto::RenderSettings { quality, budget_ms, ..Default::default() };
        envelope(Body::Control(proto::Control { request_id, render: Some(render), ..Default::default() }))
    };
    let accurate = Some(proto::QualityLevel::Accurate as i32);
    assert!(matches!(ws.exchange(level(accurate, None, 1)).await, Body::SettingsAck(_)));
    let (second, _) = streamed_png(ws.exchange(frames[1].0.clone()).await, 1);
    assert_eq!(second.quality(), proto::QualityLevel::Accurate);
    // Lit by RGB-D frames only: accurate takes imperfect shadow maps and adds the near field.
    assert_eq!(parameter(&second, "visibility"), "ism");
    assert_eq!(parameter(&second, "near_field"), "4");
    assert!(second.error_estimate.is_some());

    // A budget no frame can meet: down two rungs per frame (over 1.5x the budget).
    assert!(matches!(ws.exchange(level(None, Some(0.5), 2)).await, Body::SettingsAck(_)));
    let mut last = None;
    for (i, (bytes, _)) in frames.iter().enumerate().skip(2) {
        let (frame, _) = streamed_png(ws.exchange(bytes.clone()).await, i as u64);
        assert_eq!(frame.budget_ms, 0.5);
        last = Some(frame);
    }
    let last = last.expect("frames");
    assert_eq!(last.quality(), proto::QualityLevel::Fast, "{:?}", last.parameters);
    assert_eq!(parameter(&last, "visibility"), "off");
    assert_eq!(parameter(&last, "vals_step"), "3");
    assert_eq!(parameter(&last, "camera_detail"), "0.25");
    assert_eq!(parameter(&last, "receivers_step"), "1", "no differential pass, no receivers to thin");
    let bad = ws.exchange(level(None, Some(-3.0), 3)).await;
    let Body::Error(e) = bad else { panic!("a budget out of range is an error, got {bad:?}") };
    assert_eq!(e.field, "control.render.budget_ms");
    drop(ws);
    let metrics = String::from_utf8(server.get("/metrics").await.body.to_vec()).expect("text");
    assert!(metrics.contains("relume_frame_error_estimate_count 6"), "{metrics}");
    assert!(metrics.contains("relume_frames_by_level_total{level=\"accurate\"} 2"), "{metrics}");
    server.stop().await;
}

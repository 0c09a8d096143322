//! Every visibility mode on a mixed-reality stream: a stream switches the indirect light's
//! visibility (protobuf `Occlusion`: off, discs, clusters, imperfect shadow maps) between frames,
//! and each frame is relit as the offline replay relights it with the scene file's
//! `settings.tuning.visibility` set to that mode, to the level, and two offline runs of the mode
//! are identical (checked: the RGB-D VALs come in their cells' order, so every sum over them,
//! the clusters' k-means seeds and the flux draw are the same from run to run; with an atomic
//! append the clusters mode's runs were 14-39 levels apart). The scene and frames are those of
//! `stream_mr.rs` (a 160x120 TUM frame, the bunny with 256 sparse points, the differential pass
//! on).
//!
//! The exact reference (the frame's own VALs through shadow rays at the sparse points) darkens
//! the bunny from 4.116 to 3.656 W/m²; the discs give 3.626. The group modes are printed against
//! it but not held to it yet: clusters darken by 0.38 of the exact darkening, and ISM by almost
//! nothing, because its flux draw spends its groups on the `auto` environment's VALs (1000 m
//! away, large flux) and leaves the room's VALs in a handful of groups.

use relume::mr::environment::Environment;
use relume::mr::{FrameInput, FrameSettings, MrPipeline};
use relume::renderer::{Method, Renderer};
use relume::rgbd::RgbdFrame;
use relume::scene::{Scene, SceneDescription};
use relume::service::wire::{self, proto, proto::envelope::Body};
use serde_json::{Value, json};

use super::clusters::exact_sparse_irradiance;
use super::fixture;
use super::service::{TestServer, envelope, streamed_png};
use super::stream_mr::{difference, frames, mr_scene, offline};

/// Each mode with its JSON name and the stage only it runs (`None` for off).
const MODES: [(proto::Occlusion, &str, Option<&str>); 4] = [
    (proto::Occlusion::Clusters, "clusters", Some("cluster_visibility")),
    (proto::Occlusion::Ism, "ism", Some("ism_visibility")),
    (proto::Occlusion::Off, "off", None),
    (proto::Occlusion::Disks, "disks", Some("occlusion")),
];

/// Mean of the luminance (Rec. 709 weights) of the sparse points' diffuse irradiance (W/m²).
fn mean_irradiance(irradiance: &[glam::Vec3]) -> f64 {
    let sum: f64 = irradiance.iter().map(|e| f64::from(e.dot(glam::Vec3::new(0.2126, 0.7152, 0.0722)))).sum();
    sum / irradiance.len().max(1) as f64
}

/// The bunny's mean irradiance (luminance, W/m², as [`mean_irradiance`]) in `frame` without
/// and with exact visibility: the VALs that lit the frame (the room's and the environment's, read
/// back from the renderer after the MR pipeline set them) summed at every sparse point on the
/// CPU, each through a shadow ray against the bunny (the exact reference's offsets).
fn exact_reference(scene: &Value, frame: &RgbdFrame) -> (f64, f64) {
    let gpu = super::gpu();
    let text = scene.to_string();
    let loaded = Scene::from_json_str(&text, &fixture("")).expect("scene");
    let environment = SceneDescription::from_json_str(&text).expect("description").settings.environment;
    let mut renderer = Renderer::new(&gpu, &loaded).expect("renderer");
    let mut mr = MrPipeline::new(loaded.settings.mr, Environment::None);
    mr.set_environment(Environment::from_settings(&environment, &fixture("")).expect("environment"));
    let placement = renderer.placement().to_vec();
    mr.place(&gpu, &mut renderer, &loaded, &placement).expect("placed");
    let k = frame.intrinsics;
    let settings = FrameSettings {
        width: k.width,
        height: k.height,
        exposure: 1.0,
        rgbd: loaded.settings.rgbd,
        receivers_step: 1,
        method: Method::Sparse,
    };
    mr.render_frame(&gpu, &mut renderer, FrameInput { frame, settings: &settings, accumulate: None }).expect("render");
    let vals = renderer.read_vals(&gpu).expect("the frame's VALs");
    exact_sparse_irradiance(&renderer.scene.flat, &vals)
}

/// A stream renders frame 0 in every mode, chosen by a control message: the mode's own stage
/// runs (and no other mode's), the composite is the offline replay's with that mode exactly,
/// and the light is sane: the bunny's irradiance is finite and positive in
/// every mode, and a mode that blocks light never gives more than no visibility.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stream_renders_every_visibility_mode_as_the_offline_replay() {
    let scene = mr_scene(true);
    let frames = frames(&[0]);
    let frame = frames[0].1.clone();
    // Four frames with the differential pass on the CPU twin take longer than the server's 15 s
    // between keep-alive pings, which the client's `answer` steps over.
    let server = TestServer::start(|_| {}).await;
    let id = server.create(&scene).await;
    let mut ws = server.stream(&id).await;
    let mut streamed = Vec::new();
    for (i, (mode, name, _)) in MODES.iter().enumerate() {
        let control = proto::Control {
            request_id: i as u64 + 1,
            render: Some(proto::RenderSettings { occlusion: Some(*mode as i32), ..Default::default() }),
            ..Default::default()
        };
        let ack = ws.exchange(envelope(Body::Control(control))).await;
        assert!(matches!(ack, Body::SettingsAck(_)), "{name}: {ack:?}");
        let (rendered, image) = streamed_png(ws.exchange(wire::encode_rgbd_frame(i as u64, &frame)).await, i as u64);
        let stages: Vec<String> = rendered.timings.iter().map(|t| t.stage.clone()).collect();
        streamed.push((image, stages));
    }
    drop(ws);
    server.stop().await;

    let (expected, (unoccluded, exact)) = tokio::task::spawn_blocking(move || {
        // Each mode replayed twice: two offline runs of one mode are identical.
        let replays = MODES
            .iter()
            .map(|(_, name, _)| {
                let mut scene = scene.clone();
                scene["settings"]["tuning"] = json!({ "visibility": name });
                (offline(&scene, &[&frame]).remove(0), offline(&scene, &[&frame]).remove(0))
            })
            .collect::<Vec<_>>();
        (replays, exact_reference(&scene, &frame))
    })
    .await
    .expect("the offline replays");

    let irradiance: Vec<f64> = expected.iter().map(|(e, _)| mean_irradiance(&e.sparse_irradiance)).collect();
    for (((_, name, stage), (image, stages)), ((offline, again), e)) in
        MODES.iter().zip(&streamed).zip(expected.iter().zip(&irradiance))
    {
        for (_, other, other_stage) in &MODES {
            if let Some(s) = other_stage {
                let runs = stages.iter().any(|t| t == s);
                assert_eq!(runs, stage == other_stage, "{name}: stage {s} of {other} in {stages:?}");
            }
        }
        let (worst, over) = difference(image, &offline.composited);
        let again = image::RgbImage::from_raw(image.width(), image.height(), again.composited.concat())
            .expect("a composite of the frame's size");
        let (spread, spread_over) = difference(&again, &offline.composited);
        eprintln!(
            "{name}: streamed vs offline composite worst {worst} levels ({over} pixels over 1); two offline runs \
             {spread} levels apart ({spread_over} pixels over 1); bunny irradiance {e:.7} W/m²"
        );
        assert_eq!(spread, 0, "{name}: two offline runs differ by {spread} levels");
        assert_eq!(worst, 0, "{name}: the streamed composite differs from the offline one by {worst} levels");
        assert!(e.is_finite() && *e > 0.0, "{name}: bunny irradiance {e}");
    }
    let off = irradiance[2];
    for ((_, name, _), e) in MODES.iter().zip(&irradiance) {
        assert!(*e <= off * 1.001, "{name}: {e} W/m², more than without visibility ({off})");
    }
    eprintln!("exact reference: {unoccluded:.7} W/m² without visibility, {exact:.7} W/m² with it");
    // The CPU sum without visibility is the GPU's off (the gather sums every VAL; 1e-3 relative
    // as the twins, `twins.rs`): the reference is lit by the frame's own VALs.
    assert!((unoccluded - off).abs() <= 1e-3 * off, "CPU sum {unoccluded} W/m², GPU off {off}");
    assert!(exact < off * 0.95, "the bunny shadows itself: exact {exact} W/m², off {off}");
    // The group modes against it: printed, not yet held to a tolerance (see the module's note).
    for (i, name) in [(0, "clusters"), (1, "ism")] {
        let (darkening, want) = (off - irradiance[i], off - exact);
        eprintln!("{name}: darkens the bunny by {darkening:.7} W/m², exact {want:.7} (ratio {:.3})", darkening / want);
    }
}

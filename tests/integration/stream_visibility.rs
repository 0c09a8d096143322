//! Every visibility mode on a mixed-reality stream: a stream switches the indirect light's
//! visibility (protobuf `Occlusion`: off, discs, clusters, imperfect shadow maps) between frames,
//! and each frame is relit as the offline replay relights it with the scene file's
//! `settings.tuning.visibility` set to that mode. The scene and frames are those of
//! `stream_mr.rs` (a 160x120 TUM frame, the bunny with 256 sparse points, the differential pass
//! on).

use relume::service::wire::{self, proto, proto::envelope::Body};
use serde_json::json;

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

/// A stream renders frame 0 in every mode, chosen by a control message: the mode's own stage
/// runs (and no other mode's), the composite is the offline replay's with that mode within one
/// 8-bit level (the tolerance `stream_mr.rs` explains: the VALs' order, and with it float sums,
/// varies between runs), and the light is sane: the bunny's irradiance is finite and positive in
/// every mode, and a mode that blocks light never gives more than no visibility.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stream_renders_every_visibility_mode_as_the_offline_replay() {
    let scene = mr_scene(true);
    let frames = frames(&[0]);
    let frame = frames[0].1.clone();
    // Four frames with the differential pass on the CPU twin take longer than the server's
    // 15 s between pings, which the test's client does not expect between its exchanges.
    let server = TestServer::start(|c| c.timeouts.stream_ping_seconds = 3600).await;
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

    let expected = tokio::task::spawn_blocking(move || {
        MODES
            .iter()
            .map(|(_, name, _)| {
                let mut scene = scene.clone();
                scene["settings"]["tuning"] = json!({ "visibility": name });
                offline(&scene, &[&frame]).remove(0)
            })
            .collect::<Vec<_>>()
    })
    .await
    .expect("the offline replays");

    let irradiance: Vec<f64> = expected.iter().map(|e| mean_irradiance(&e.sparse_irradiance)).collect();
    for (((_, name, stage), (image, stages)), (offline, e)) in
        MODES.iter().zip(&streamed).zip(expected.iter().zip(&irradiance))
    {
        for (_, other, other_stage) in &MODES {
            if let Some(s) = other_stage {
                let runs = stages.iter().any(|t| t == s);
                assert_eq!(runs, stage == other_stage, "{name}: stage {s} of {other} in {stages:?}");
            }
        }
        let (worst, over) = difference(image, &offline.composited);
        eprintln!(
            "{name}: streamed vs offline composite worst {worst} levels ({over} pixels over 1); bunny irradiance {e:.7} W/m²"
        );
        assert!(worst <= 1, "{name}: the streamed composite differs from the offline one by {worst} levels");
        assert!(e.is_finite() && *e > 0.0, "{name}: bunny irradiance {e}");
    }
    let off = irradiance[2];
    for ((_, name, _), e) in MODES.iter().zip(&irradiance) {
        assert!(*e <= off * 1.001, "{name}: {e} W/m², more than without visibility ({off})");
    }
}

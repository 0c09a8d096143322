//! `relume serve` end to end: a real server on 127.0.0.1 port 0, driven over HTTP and WebSocket,
//! good inputs and bad ones. Renders are tiny (32x32 of `cornell_bunny_small`, or a two-quad
//! scene given inline).
//!
//! `proto/openapi.json` is compared with the document the handlers generate; after a
//! deliberate API change, `BLESS=1 cargo test --test integration openapi` rewrites it.

use std::future::Future;
use std::net::SocketAddr;
use std::time::Duration;

use bytes::Bytes;
use futures_util::{SinkExt, StreamExt};
use http_body_util::{BodyExt, Full};
use hyper::{HeaderMap, Method, StatusCode};
use hyper_util::client::legacy::Client;
use hyper_util::client::legacy::connect::HttpConnector;
use prost::Message as _;
use relume::service::wire::proto::{self, envelope::Body};
use relume::service::wire::{ErrorCode, PROTOCOL_VERSION};
use relume::service::{Config, ServeError, Server};
use serde_json::{Value, json};
use tokio::sync::oneshot;
use tokio_tungstenite::tungstenite;

use super::fixture;

/// A server on a free loopback port, stopped by [`TestServer::stop`].
pub(super) struct TestServer {
    pub(super) addr: SocketAddr,
    stop: Option<oneshot::Sender<()>>,
    task: tokio::task::JoinHandle<Result<(), ServeError>>,
    client: Client<HttpConnector, Full<Bytes>>,
    pub(super) token: Option<String>,
    /// The server's state, for test hooks.
    pub(super) state: std::sync::Arc<relume::service::AppState>,
}

/// An HTTP answer, body read.
pub(super) struct Reply {
    pub(super) status: StatusCode,
    pub(super) headers: HeaderMap,
    pub(super) body: Bytes,
}

impl Reply {
    pub(super) fn json(&self) -> Value {
        serde_json::from_slice(&self.body)
            .unwrap_or_else(|e| panic!("{}: not JSON ({e}): {}", self.status, String::from_utf8_lossy(&self.body)))
    }

    pub(super) fn header(&self, name: &str) -> &str {
        self.headers.get(name).and_then(|v| v.to_str().ok()).unwrap_or_else(|| panic!("no header {name}"))
    }

    /// Asserts an error answer with this status and code; returns the `error` object.
    #[track_caller]
    pub(super) fn error(&self, status: u16, code: &str) -> Value {
        let body = self.json();
        assert_eq!(self.status.as_u16(), status, "{body}");
        assert_eq!(self.header("content-type"), "application/json");
        assert_eq!(body["error"]["code"], code, "{body}");
        assert!(body["error"]["message"].as_str().is_some_and(|m| !m.is_empty()), "{body}");
        body["error"].clone()
    }
}

impl TestServer {
    /// Serves `fixtures/` as the asset directory, with the defaults changed by `edit`.
    pub(super) async fn start(edit: impl FnOnce(&mut Config)) -> TestServer {
        TestServer::start_with(edit, |config| Box::pin(Server::bind(config))).await
    }

    /// [`TestServer::start`] with the server `bind` makes of the config.
    pub(super) async fn start_with(
        edit: impl FnOnce(&mut Config),
        bind: impl FnOnce(Config) -> std::pin::Pin<Box<dyn Future<Output = Result<Server, ServeError>> + Send>>,
    ) -> TestServer {
        let mut config = Config::new(SocketAddr::from(([127, 0, 0, 1], 0)), fixture(""));
        config.shutdown_grace_seconds = 20;
        edit(&mut config);
        let token = config.token.clone();
        let server = bind(config).await.expect("the server starts");
        let addr = server.local_addr();
        let state = server.state().clone();
        assert!(addr.ip().is_loopback());
        let (stop, stopped) = oneshot::channel::<()>();
        let task = tokio::spawn(server.run(async {
            let _ = stopped.await;
        }));
        let client = Client::builder(hyper_util::rt::TokioExecutor::new()).build_http();
        TestServer { addr, stop: Some(stop), task, client, token, state }
    }

    pub(super) async fn request(&self, method: Method, path: &str, body: impl Into<Bytes>) -> Reply {
        let mut request = hyper::Request::builder().method(method).uri(format!("http://{}{path}", self.addr));
        if let Some(token) = &self.token {
            request = request.header("authorization", format!("Bearer {token}"));
        }
        self.send(request.body(Full::new(body.into())).expect("request")).await
    }

    pub(super) async fn send(&self, request: hyper::Request<Full<Bytes>>) -> Reply {
        let response = self.client.request(request).await.expect("the server answers");
        let (parts, body) = response.into_parts();
        let body = body.collect().await.expect("body").to_bytes();
        Reply { status: parts.status, headers: parts.headers, body }
    }

    pub(super) async fn get(&self, path: &str) -> Reply {
        self.request(Method::GET, path, Bytes::new()).await
    }

    pub(super) async fn post(&self, path: &str, body: &Value) -> Reply {
        self.request(Method::POST, path, body.to_string()).await
    }

    /// Creates a scene; returns its id.
    pub(super) async fn create(&self, scene: &Value) -> String {
        let reply = self.post("/v1/scenes", scene).await;
        assert_eq!(reply.status, StatusCode::CREATED, "{}", reply.json());
        let id = reply.json()["id"].as_str().expect("id").to_owned();
        assert_eq!(reply.header("location"), format!("/v1/scenes/{id}"));
        id
    }

    pub(super) async fn stream(&self, id: &str) -> Ws {
        let url = format!("ws://{}/v1/scenes/{id}/stream", self.addr);
        let (ws, response) = tokio_tungstenite::connect_async(url).await.expect("the stream opens");
        assert_eq!(response.status(), StatusCode::SWITCHING_PROTOCOLS);
        Ws(ws)
    }

    /// Asks the server to stop and waits until it has.
    pub(super) async fn stop(mut self) {
        let _ = self.stop.take().expect("running").send(());
        let result = tokio::time::timeout(Duration::from_secs(60), self.task).await;
        result.expect("the server stops within a minute").expect("the server task").expect("a clean stop");
    }
}

pub(super) struct Ws(
    pub(super) tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>,
);

impl Ws {
    async fn send(&mut self, message: tungstenite::Message) {
        self.0.send(message).await.expect("sent");
    }

    async fn next(&mut self) -> tungstenite::Message {
        let message = tokio::time::timeout(Duration::from_secs(60), self.0.next()).await.expect("an answer in time");
        message.expect("the stream is open").expect("a message")
    }

    /// Sends one binary message and decodes the envelope that answers it.
    pub(super) async fn exchange(&mut self, bytes: Vec<u8>) -> Body {
        self.send(tungstenite::Message::Binary(bytes.into())).await;
        self.answer().await
    }

    /// The next envelope, past the server's keep-alive pings (every
    /// `timeouts.stream_ping_seconds`; tungstenite queues their pongs itself) and any pong.
    async fn answer(&mut self) -> Body {
        loop {
            match self.next().await {
                tungstenite::Message::Binary(bytes) => {
                    let envelope = proto::Envelope::decode(bytes.as_ref()).expect("an Envelope");
                    assert_eq!(envelope.version, PROTOCOL_VERSION);
                    return envelope.body.expect("a body");
                }
                tungstenite::Message::Ping(_) | tungstenite::Message::Pong(_) => continue,
                other => panic!("expected a binary message, got {other:?}"),
            }
        }
    }

    /// Sends `bytes` and asserts an `Error` with this code; returns it.
    async fn expect_error(&mut self, bytes: Vec<u8>, code: ErrorCode) -> proto::Error {
        match self.exchange(bytes).await {
            Body::Error(error) => {
                assert_eq!(error.code(), code, "{error:?}");
                assert!(!error.message.is_empty());
                error
            }
            other => panic!("expected an error {code:?}, got {other:?}"),
        }
    }
}

pub(super) fn envelope(body: Body) -> Vec<u8> {
    proto::Envelope { version: PROTOCOL_VERSION, body: Some(body) }.encode_to_vec()
}

/// `fixtures/scenes/<name>.json` with its mesh paths made relative to `fixtures/` (the
/// asset directory), at `size` x `size` pixels.
pub(super) fn fixture_scene(name: &str, size: u32) -> Value {
    let text = std::fs::read_to_string(fixture(&format!("scenes/{name}.json"))).expect("fixture");
    let mut scene: Value = serde_json::from_str(&text.replace("\"../meshes/", "\"meshes/")).expect("JSON");
    scene["camera"]["width"] = size.into();
    scene["camera"]["height"] = size.into();
    scene
}

/// A floor and a back wall given as OBJ text, lit from above: loads in milliseconds.
pub(super) fn inline_scene() -> Value {
    json!({
        "meshes": [{
            "obj": "room.obj",
            "obj_text": "v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nv -1 2 -1\nv 1 2 -1\nf 1 4 3 2\nf 1 2 6 5\n",
            "sparse_points": 64,
            "material": {"diffuse": [0.8, 0.3, 0.2]}
        }],
        "light": {"position": [0, 1.8, 0.5], "direction": [0, -1, -0.3], "inner_angle_deg": 30,
                  "outer_angle_deg": 45, "intensity": [5, 5, 5]},
        "camera": {"position": [0, 1, 3], "target": [0, 0.5, 0], "fov_y_deg": 50, "width": 16, "height": 16},
        "settings": {"tuning": {"rsm_resolution": 16}}
    })
}

/// A valid RGB-D frame envelope: `w` x `h`, raw RGB8, u16 depth (mm), identity pose.
pub(super) fn frame(frame_id: u64, w: u32, h: u32) -> proto::RgbdFrame {
    let pixels = (w * h) as usize;
    proto::RgbdFrame {
        frame_id,
        timestamp: 12.5,
        intrinsics: Some(proto::Intrinsics {
            width: w,
            height: h,
            fx: 50.0,
            fy: 50.0,
            cx: w as f32 / 2.0,
            cy: h as f32 / 2.0,
        }),
        color: Some(proto::Color { data: Some(proto::color::Data::Rgb8(vec![128; pixels * 3])) }),
        depth: Some(proto::Depth {
            data: Some(proto::depth::Data::U16(proto::DepthU16 {
                data: 1500u16.to_le_bytes().repeat(pixels),
                units_per_metre: 1000.0,
            })),
        }),
        camera_to_world: Some(pose(0.0, 0.0, 0.0, 1.0)),
    }
}

fn pose(x: f32, y: f32, z: f32, w: f32) -> proto::Pose {
    proto::Pose {
        transform: Some(proto::pose::Transform::TranslationRotation(proto::TranslationRotation {
            translation: Some(proto::Vec3 { x: 0.0, y: 1.0, z: 2.0 }),
            rotation: Some(proto::Quaternion { x, y, z, w }),
        })),
        translation_f64: None,
    }
}

fn v3(x: f32, y: f32, z: f32) -> Option<proto::Vec3> {
    Some(proto::Vec3 { x, y, z })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn scenes_are_created_rendered_and_deleted() {
    let server = TestServer::start(|_| {}).await;
    let health = server.get("/healthz").await;
    assert_eq!(health.status, StatusCode::OK);
    assert_eq!(health.json()["status"], "ok");
    assert!(health.json()["adapter"].as_str().is_some_and(|a| !a.is_empty()));

    let id = server.create(&fixture_scene("cornell_bunny_small", 32)).await;
    let info = server.get(&format!("/v1/scenes/{id}")).await;
    assert_eq!(info.status, StatusCode::OK);
    let info = info.json();
    assert_eq!(info["id"], id.as_str());
    assert_eq!(info["sparse_points"], 768);
    assert_eq!(info["max_vals"], 32 * 32);
    assert_eq!(info["meshes"].as_array().map(Vec::len), Some(2));

    // An empty body: the scene's camera (32x32), sparse, PNG.
    let render = server.request(Method::POST, &format!("/v1/scenes/{id}/render"), Bytes::new()).await;
    assert_eq!(render.status, StatusCode::OK, "{}", String::from_utf8_lossy(&render.body));
    assert_eq!(render.header("content-type"), "image/png");
    let png = image::load_from_memory(&render.body).expect("a PNG").into_rgb8();
    assert_eq!(png.dimensions(), (32, 32));
    assert!(png.pixels().any(|p| p.0 != [0, 0, 0]), "the image is lit");
    assert_eq!((render.header("x-relume-width"), render.header("x-relume-height")), ("32", "32"));
    assert!(render.header("x-relume-val-count").parse::<u32>().expect("a count") > 0);
    let timing = render.header("server-timing");
    for stage in ["queue;dur=", "rsm_raster;dur=", "gather;dur=", "shade;dur=", "gpu;dur=", "encode;dur=", "total;dur="]
    {
        assert!(timing.contains(stage), "{stage} missing from {timing}");
    }

    // Another camera, a light override, brute force, linear floats.
    let request = json!({
        "camera": {"position": [0, 1, 3.3], "target": [0, 0.9, 0], "fov_y_deg": 45, "width": 24, "height": 16},
        "light": {"intensity": [20, 20, 20], "outer_angle_deg": 30},
        "quality": {"method": "brute-force", "component": "indirect", "format": "f32"}
    });
    let render = server.post(&format!("/v1/scenes/{id}/render"), &request).await;
    assert_eq!(render.status, StatusCode::OK, "{}", String::from_utf8_lossy(&render.body));
    assert_eq!(render.header("content-type"), "application/octet-stream");
    assert!(render.header("server-timing").contains("brute_force;dur="));
    let floats: Vec<f32> =
        render.body.chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().expect("4 bytes"))).collect();
    assert_eq!(floats.len(), 24 * 16 * 4);
    assert!(floats.iter().all(|v| v.is_finite() && *v >= 0.0));
    assert!(floats.chunks_exact(4).any(|p| p[0] > 0.0 && p[3] == 1.0), "indirect light on covered pixels");

    // The light's frame: a zero `up` is refused, naming the field.
    let zero_up = json!({"light": {"up": [0, 0, 0]}});
    let reply = server.post(&format!("/v1/scenes/{id}/render"), &zero_up).await;
    assert_eq!(reply.error(400, "invalid_field")["field"], "light.up");

    let metrics = server.get("/metrics").await;
    assert_eq!(metrics.status, StatusCode::OK);
    assert!(metrics.header("content-type").starts_with("text/plain; version=0.0.4"));
    let text = String::from_utf8_lossy(&metrics.body);
    for needle in [
        "relume_http_requests_total{route=\"/v1/scenes/{id}/render\",method=\"POST\",status=\"200\"} 2",
        "relume_frame_duration_seconds_count 2",
        "relume_gpu_seconds_total{stage=\"gather\"}",
        "relume_render_queue_depth 0",
        "relume_scenes 1",
        "relume_dropped_frames_total 0",
    ] {
        assert!(text.contains(needle), "{needle} missing from\n{text}");
    }

    let deleted = server.request(Method::DELETE, &format!("/v1/scenes/{id}"), Bytes::new()).await;
    assert_eq!(deleted.status, StatusCode::NO_CONTENT);
    server.get(&format!("/v1/scenes/{id}")).await.error(404, "not_found");
    server.post(&format!("/v1/scenes/{id}/render"), &json!({})).await.error(404, "not_found");
    server.request(Method::DELETE, &format!("/v1/scenes/{id}"), Bytes::new()).await.error(404, "not_found");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_scenes_get_errors_naming_the_field() {
    let server = TestServer::start(|c| c.limits.max_mesh_bytes = 2 << 20).await;
    let create = |scene: Value| {
        let server = &server;
        async move { server.post("/v1/scenes", &scene).await }
    };

    let reply = server.request(Method::POST, "/v1/scenes", "{\"meshes\": [").await;
    assert_eq!(reply.error(400, "invalid_json")["field"], "meshes[0]");
    let reply = server.request(Method::POST, "/v1/scenes", vec![0xff, 0xfe]).await;
    reply.error(400, "invalid_json");
    let mut scene = inline_scene();
    scene["camera"]["colour"] = json!(1);
    let error = create(scene).await.error(400, "invalid_json");
    assert!(error["message"].as_str().unwrap().contains("colour"), "{error}");
    let mut scene = inline_scene();
    scene["camera"]["fov_y_deg"] = json!(0);
    assert_eq!(create(scene).await.error(400, "invalid_field")["field"], "camera.fov_y_deg");
    let mut scene = inline_scene();
    scene["meshes"][0]["sparse_points"] = json!(0);
    assert_eq!(create(scene).await.error(400, "invalid_field")["field"], "meshes[0].sparse_points");

    // Paths that leave the asset directory, whether or not the file exists.
    for path in ["../Cargo.toml", "/etc/passwd", "meshes/../../src/lib.rs", "../../../../nope.obj"] {
        let scene = json!({"meshes": [{"obj": path, "sparse_points": 8}],
                           "light": inline_scene()["light"], "camera": inline_scene()["camera"]});
        let error = create(scene).await.error(400, "path_outside_assets");
        assert_eq!(error["field"], "meshes[0].obj");
        assert!(!error["message"].as_str().unwrap().contains(&fixture("").display().to_string()), "{error}");
    }
    let mut scene = inline_scene();
    scene["meshes"][0]["material"]["diffuse_texture"] = json!("../../etc/hostname");
    assert_eq!(create(scene).await.error(400, "path_outside_assets")["field"], "meshes[0].material.diffuse_texture");
    let scene = json!({"meshes": [{"obj": "meshes/missing.obj", "sparse_points": 8}],
                       "light": inline_scene()["light"], "camera": inline_scene()["camera"]});
    assert_eq!(create(scene).await.error(400, "invalid_scene")["field"], "meshes[0].obj");

    // Invalid OBJ text: the line is named, the server's directory is not.
    let mut scene = inline_scene();
    scene["meshes"][0]["obj_text"] = json!("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n");
    let error = create(scene).await.error(400, "invalid_scene");
    let message = error["message"].as_str().unwrap();
    assert!(message.contains("room.obj:3"), "{message}");
    assert!(!message.contains(&fixture("").display().to_string()), "{message}");
    let mut scene = inline_scene();
    scene["meshes"][0]["obj_text"] = json!("mtllib ../scenes/x.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    assert_eq!(create(scene).await.error(400, "invalid_scene")["field"], "meshes[0].obj_text");
    let mut scene = inline_scene();
    scene["meshes"][0]["obj_text"] = json!("v 0 0 0\nf 1 2 3\n");
    create(scene).await.error(400, "invalid_scene");

    // Limits: mesh size (413), VALs and frame size (400).
    let scene = json!({"meshes": [{"obj": "meshes/stanford_bunny/stanford-bunny.obj", "sparse_points": 8}],
                       "light": inline_scene()["light"], "camera": inline_scene()["camera"]});
    let error = create(scene).await.error(413, "limit_exceeded");
    assert_eq!((error["limit"].as_str(), error["field"].as_str()), (Some("max_mesh_bytes"), Some("meshes[0].obj")));
    let mut scene = inline_scene();
    scene["settings"]["tuning"]["rsm_resolution"] = json!(512);
    assert_eq!(create(scene).await.error(400, "limit_exceeded")["limit"], "max_vals");
    let mut scene = inline_scene();
    scene["camera"]["width"] = json!(8000);
    assert_eq!(create(scene).await.error(400, "limit_exceeded")["limit"], "max_frame_side");

    // Nothing was kept, and the server still works.
    assert_eq!(server.get("/healthz").await.json()["scenes"], 0);
    server.create(&inline_scene()).await;
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_full_queue_answers_503_with_retry_after() {
    let server = TestServer::start(|c| {
        c.limits.max_queue = 1;
        c.limits.max_client_queue = 8;
    })
    .await;
    let id = server.create(&fixture_scene("cornell_bunny_small", 48)).await;
    let body = json!({"quality": {"method": "brute-force"}}).to_string();
    let path = format!("/v1/scenes/{id}/render");
    let replies =
        futures_util::future::join_all((0..6).map(|_| server.request(Method::POST, &path, body.clone()))).await;
    let mut refused = 0;
    for reply in &replies {
        match reply.status.as_u16() {
            200 => assert_eq!(reply.header("content-type"), "image/png"),
            503 => {
                assert_eq!(reply.error(503, "queue_full")["limit"], "max_queue");
                assert!(reply.header("retry-after").parse::<u32>().expect("seconds") >= 1);
                refused += 1;
            }
            other => panic!("unexpected status {other}"),
        }
    }
    // At most one render waits: the first is queued at once, so at least one succeeds, and
    // the six arrive well within one frame, so some are refused.
    assert!((1..=5).contains(&refused), "{refused} refused");
    let metrics = server.get("/metrics").await;
    let text = String::from_utf8_lossy(&metrics.body);
    assert!(text.contains(&format!("relume_renders_rejected_total {refused}")), "{text}");
    server.stop().await;
}

/// `brute-force-ism` renders through the scene's imperfect shadow maps, darker than the plain
/// brute force (the maps occlude, never add light), and a size whose pixels x groups table
/// cannot fit one storage binding is a 400 naming the table, before any GPU work; the scene
/// renders normally after it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn brute_force_ism_renders_and_is_refused_over_the_device_limit() {
    let server = TestServer::start(|_| {}).await;
    let mut scene = fixture_scene("cornell_bunny_small", 16);
    // Few small maps: the lookup at 256 pixels x 16 groups is fast on lavapipe.
    scene["settings"]["tuning"]["ism"] = json!({"count": 16, "resolution": 32, "points": 400});
    let id = server.create(&scene).await;
    let path = format!("/v1/scenes/{id}/render");
    let indirect = |method: &str| json!({"quality": {"method": method, "component": "indirect", "format": "f32"}});
    let floats = |reply: &Reply| -> Vec<f32> {
        assert_eq!(reply.status, StatusCode::OK, "{}", String::from_utf8_lossy(&reply.body));
        reply.body.chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().expect("4 bytes"))).collect()
    };
    let ism = server.post(&path, &indirect("brute-force-ism")).await;
    let timing = ism.header("server-timing").to_owned();
    for stage in ["brute_force_ism_sampling;", "brute_force_ism_splat;", "brute_force_ism_visibility;", "brute_force;"]
    {
        assert!(timing.contains(stage), "{stage} missing from {timing}");
    }
    let ism = floats(&ism);
    let plain = floats(&server.post(&path, &indirect("brute-force")).await);
    assert_eq!(ism.len(), 16 * 16 * 4);
    assert!(ism.iter().all(|v| v.is_finite() && *v >= 0.0));
    let sum = |f: &[f32]| f.chunks_exact(4).map(|p| f64::from(p[0] + p[1] + p[2])).sum::<f64>();
    // Visibility only removes light: the box and the bunny hide some VALs from some pixels.
    // 1e-4 relative: the two passes add the same VALs in the same order except for the weights.
    let (lit, unoccluded) = (sum(&ism), sum(&plain));
    assert!(lit > 0.0 && lit < unoccluded * (1.0 + 1e-4), "{lit} vs {unoccluded}");
    assert!(lit < unoccluded * 0.99, "the maps occlude nothing: {lit} vs {unoccluded}");

    // 2048x2048 pixels x 1,024 groups x 4 bytes = 16 GiB, over any device's storage binding.
    scene["settings"]["tuning"]["ism"] = json!({"count": 1024});
    let big = server.create(&scene).await;
    let request = json!({
        "camera": {"position": [0, 1, 3.3], "target": [0, 0.9, 0], "fov_y_deg": 45, "width": 2048, "height": 2048},
        "quality": {"method": "brute-force-ism", "component": "indirect"}
    });
    let reply = server.post(&format!("/v1/scenes/{big}/render"), &request).await;
    let error = reply.error(400, "limit_exceeded");
    let message = error["message"].as_str().expect("a message");
    assert!(message.contains("brute_force_ism") && message.contains("settings.ism.count 1024"), "{message}");
    let after = server.post(&format!("/v1/scenes/{big}/render"), &indirect("sparse")).await;
    assert_eq!(after.status, StatusCode::OK, "{}", String::from_utf8_lossy(&after.body));
    server.stop().await;
}

/// A level whose technique traces shadow rays renders it through the service as `relume render`
/// does: on a CPU adapter the CPU's (the exact reference, or the estimator's twin; stage
/// `exact_cpu`), elsewhere the GPU pass, with the error estimate every level's frame carries; at
/// `reference` the same exact sum over the scene's VALs (the level's are the scene's, fixed when
/// it loads) without an estimate, the frame being what the estimate compares with.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_level_naming_the_exact_reference_or_the_estimator_renders_it() {
    let server = TestServer::start(|_| {}).await;
    let mut scene = fixture_scene("cornell_bunny_small", 16);
    scene["settings"]["quality"] = "accurate".into();
    let measured = "a test: the exact reference over 16² VALs";
    scene["settings"]["levels"] = json!({
        "accurate": {"measured": measured, "technique": "exact", "rsm_resolution": 16},
        "balanced": {"measured": "a test", "technique": "estimator", "draws": 4},
        "fast": {"measured": "a test", "technique": "estimator", "draws": 64},
    });
    let id = server.create(&scene).await;
    let cpu = server.get("/healthz").await.json()["adapter"].as_str().is_some_and(|a| a.contains("llvmpipe"));
    let path = format!("/v1/scenes/{id}/render");
    let render = |level: &'static str, method: &'static str| {
        let request = json!({"quality": {"level": level, "component": "indirect", "format": "f32"}});
        let (server, path) = (&server, &path);
        let gpu_pass = if method == "exact" { relume::renderer::stage::EXACT } else { "estimator" };
        let stage = if cpu { relume::twin::exact_cpu::STAGE } else { gpu_pass };
        async move {
            let reply = server.post(path, &request).await;
            assert_eq!(reply.status, StatusCode::OK, "{}", String::from_utf8_lossy(&reply.body));
            let timing = reply.header("server-timing").to_owned();
            assert!(timing.contains(&format!("{stage};dur=")), "{stage} missing from {timing}");
            assert!(!timing.contains("gather;dur="), "the sparse method ran: {timing}");
            let gpu_pass = format!("{gpu_pass};dur=");
            assert!(!cpu || !timing.contains(&gpu_pass), "the GPU pass ran on a CPU adapter: {timing}");
            let parameters = reply.header("x-relume-parameters");
            assert!(parameters.starts_with(&format!("level={level}; method={method}; ")), "{parameters}");
            let estimate = reply.headers.get("x-relume-error-estimate").map(|v| v.to_str().expect("ASCII").to_owned());
            let floats: Vec<f32> =
                reply.body.chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().expect("4 bytes"))).collect();
            (floats, estimate)
        }
    };
    let (accurate, estimate) = render("accurate", "exact").await;
    let estimate: f64 = estimate.expect("an accurate frame carries its estimate").parse().expect("a number");
    assert!(estimate.is_finite() && estimate >= 0.0, "{estimate}");
    let (reference, none) = render("reference", "exact").await;
    assert_eq!(none, None, "the reference carries no estimate");
    assert_eq!(accurate.len(), 16 * 16 * 4);
    assert!(accurate.chunks_exact(4).any(|p| p[0] > 0.0 && p[3] == 1.0), "indirect light on covered pixels");
    assert_eq!(accurate, reference, "the same exact sum over the same VALs");
    // Four draws per pixel: an estimate of the same sum, with its noise; each level with its own
    // draws (the scene's level, `accurate`, has none), so 64 draws come closer.
    let (balanced, estimate) = render("balanced", "estimator").await;
    assert!(estimate.is_some(), "a balanced frame carries its estimate");
    let (fast, _) = render("fast", "estimator").await;
    let error = |f: &[f32]| {
        let image = |f: &[f32]| relume::image::LinearImage {
            width: 16,
            height: 16,
            pixels: f.chunks_exact(4).map(|p| [p[0], p[1], p[2], p[3]]).collect(),
        };
        relume::image::relative_rmse(&image(f), &image(&reference))
    };
    let (four, sixty_four) = (error(&balanced), error(&fast));
    assert!(four > 1e-3 && four < 1.0, "4 draws against the exact sum: {four}");
    assert!(sixty_four < 0.7 * four, "64 draws against the exact sum: {sixty_four}, 4 draws: {four}");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_stream_decoder_answers_every_bad_message_with_an_error() {
    let server = TestServer::start(|c| {
        c.limits.max_message_bytes = 512 << 10;
        c.limits.max_vals = 1000;
    })
    .await;
    let missing = tokio_tungstenite::connect_async(format!("ws://{}/v1/scenes/nope/stream", server.addr)).await;
    match missing {
        Err(tungstenite::Error::Http(response)) => assert_eq!(response.status(), StatusCode::NOT_FOUND),
        other => panic!("expected 404, got {other:?}"),
    }
    let id = server.create(&inline_scene()).await;
    let mut ws = server.stream(&id).await;

    ws.expect_error(vec![0xff, 0x01, 0x02], ErrorCode::Malformed).await;
    ws.send(tungstenite::Message::Text("{\"hello\": 1}".into())).await;
    match ws.answer().await {
        Body::Error(e) => assert_eq!(e.code(), ErrorCode::Malformed),
        other => panic!("{other:?}"),
    }
    let v2 = proto::Envelope { version: 2, body: Some(Body::RgbdFrame(frame(1, 8, 6))) }.encode_to_vec();
    ws.expect_error(v2, ErrorCode::UnsupportedVersion).await;
    let e = ws.expect_error(envelope(Body::SettingsAck(Default::default())), ErrorCode::UnexpectedMessage).await;
    assert_eq!(e.field, "body");

    // Wrong byte lengths, bad poses, bad intrinsics: the field and the frame are named.
    let mut short = frame(7, 8, 6);
    short.color = Some(proto::Color { data: Some(proto::color::Data::Rgb8(vec![0; 8 * 6 * 3 - 1])) });
    let e = ws.expect_error(envelope(Body::RgbdFrame(short)), ErrorCode::InvalidField).await;
    assert_eq!((e.field.as_str(), e.frame_id), ("rgbd_frame.color.rgb8", Some(7)));
    let mut short = frame(8, 8, 6);
    short.depth = Some(proto::Depth { data: Some(proto::depth::Data::F32Metres(vec![0; 8 * 6 * 2])) });
    let e = ws.expect_error(envelope(Body::RgbdFrame(short)), ErrorCode::InvalidField).await;
    assert_eq!(e.field, "rgbd_frame.depth.f32_metres");
    let rotation = "rgbd_frame.camera_to_world.translation_rotation.rotation";
    for bad in [pose(f32::NAN, 0.0, 0.0, 1.0), pose(0.0, 0.0, 0.0, 2.0)] {
        let mut f = frame(9, 8, 6);
        f.camera_to_world = Some(bad);
        assert_eq!(ws.expect_error(envelope(Body::RgbdFrame(f)), ErrorCode::InvalidField).await.field, rotation);
    }
    let mut f = frame(10, 8, 6);
    f.camera_to_world = Some(proto::Pose {
        transform: Some(proto::pose::Transform::Matrix(proto::Matrix4 {
            column_major: vec![2.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0],
        })),
        translation_f64: None,
    });
    let e = ws.expect_error(envelope(Body::RgbdFrame(f)), ErrorCode::InvalidField).await;
    assert_eq!(e.field, "rgbd_frame.camera_to_world.matrix.column_major");
    let mut f = frame(11, 8, 6);
    f.intrinsics.as_mut().expect("intrinsics").fx = f32::NAN;
    assert_eq!(
        ws.expect_error(envelope(Body::RgbdFrame(f)), ErrorCode::InvalidField).await.field,
        "rgbd_frame.intrinsics.fx"
    );

    // Limits: frame side, VALs per frame (320 x 240 at grid 8 is 1200 > 1000), message size.
    let mut f = frame(12, 8, 6);
    f.intrinsics.as_mut().expect("intrinsics").width = 5000;
    let e = ws.expect_error(envelope(Body::RgbdFrame(f)), ErrorCode::LimitExceeded).await;
    assert_eq!((e.limit.as_str(), e.field.as_str()), ("max_frame_side", "rgbd_frame.intrinsics.width"));
    let e = ws.expect_error(envelope(Body::RgbdFrame(frame(13, 320, 240))), ErrorCode::LimitExceeded).await;
    assert_eq!((e.limit.as_str(), e.frame_id), ("max_vals", Some(13)));
    let e = ws.expect_error(vec![0; 600 << 10], ErrorCode::LimitExceeded).await;
    assert_eq!(e.limit, "max_message_bytes");

    // Control messages: validated against the scene, acknowledged, all or nothing.
    let control = |edit: &dyn Fn(&mut proto::Control)| {
        let mut c = proto::Control { request_id: 21, ..Default::default() };
        edit(&mut c);
        envelope(Body::Control(c))
    };
    let e = ws
        .expect_error(
            control(&|c| c.light = Some(proto::LightOverride { inner_angle_deg: Some(60.0), ..Default::default() })),
            ErrorCode::InvalidField,
        )
        .await;
    assert_eq!((e.field.as_str(), e.request_id), ("control.light.inner_angle_deg", Some(21)));
    let e = ws
        .expect_error(
            control(&|c| c.light = Some(proto::LightOverride { up: v3(0.0, 0.0, 0.0), ..Default::default() })),
            ErrorCode::InvalidField,
        )
        .await;
    assert_eq!((e.field.as_str(), e.request_id), ("control.light.up", Some(21)));
    let e = ws
        .expect_error(
            control(&|c| {
                c.model_transforms = vec![proto::ModelTransform {
                    mesh_index: 3,
                    translation: v3(0.0, 0.0, 0.0),
                    rotation_deg: v3(0.0, 0.0, 0.0),
                    scale: None,
                }]
            }),
            ErrorCode::InvalidField,
        )
        .await;
    assert_eq!(e.field, "control.model_transforms[0].mesh_index");
    let ok = control(&|c| {
        c.camera = Some(proto::Camera {
            position: v3(0.0, 1.0, 3.0),
            target: v3(0.0, 0.5, 0.0),
            up: None,
            fov_y_deg: 40.0,
            width: 16,
            height: 16,
        });
        c.quality = Some(proto::Quality { format: proto::ImageFormat::Rgba8 as i32, ..Default::default() });
        c.rgbd = Some(proto::RgbdSettings { grid_step: Some(16), ..Default::default() });
    });
    match ws.exchange(ok).await {
        Body::SettingsAck(ack) => {
            assert_eq!(ack.request_id, 21);
            assert_eq!(ack.applied, ["camera", "quality", "rgbd"]);
        }
        other => panic!("{other:?}"),
    }
    // With grid_step 16 the 320 x 240 frame is within max_vals; it is rendered from the virtual
    // camera just set (16 x 16), as raw RGBA8.
    match ws.exchange(envelope(Body::RgbdFrame(frame(14, 320, 240)))).await {
        Body::RenderedFrame(f) => {
            assert_eq!((f.frame_id, f.width, f.height), (14, 16, 16));
            assert!(matches!(&f.image, Some(proto::rendered_frame::Image::Rgba8(b)) if b.len() == 16 * 16 * 4));
        }
        other => panic!("{other:?}"),
    }

    // Beyond twice the limit the transport itself closes the connection (1009).
    // (The server may close before the client has finished sending.)
    let _ = ws.0.send(tungstenite::Message::Binary(vec![0u8; 2 << 20].into())).await;
    loop {
        match tokio::time::timeout(Duration::from_secs(30), ws.0.next()).await.expect("closed in time") {
            Some(Ok(tungstenite::Message::Close(frame))) => {
                assert_eq!(frame.map(|f| u16::from(f.code)), Some(1009));
                break;
            }
            Some(Ok(_)) => continue,
            None | Some(Err(_)) => break,
        }
    }

    let metrics = String::from_utf8_lossy(&server.get("/metrics").await.body).into_owned();
    assert!(metrics.contains("relume_stream_errors_total{code=\"ERROR_CODE_INVALID_FIELD\"}"), "{metrics}");
    assert!(metrics.contains("relume_stream_messages_total{kind=\"control\"} 4"), "{metrics}");
    // Other clients were not affected.
    assert_eq!(server.get(&format!("/v1/scenes/{id}")).await.status, StatusCode::OK);
    server.stop().await;
}

/// A frame of `frame(..)`'s grey room seen from (0, 1, 2) looking down -Z (a 180 degree turn
/// about X: the RGB-D camera looks along its +Z with +Y down), the real wall 5 m away, behind
/// `inline_scene`'s floor and back wall.
fn frame_behind_the_scene(frame_id: u64) -> proto::RgbdFrame {
    let mut f = frame(frame_id, 64, 48);
    f.camera_to_world = Some(pose(1.0, 0.0, 0.0, 0.0));
    f.depth = Some(proto::Depth {
        data: Some(proto::depth::Data::U16(proto::DepthU16 {
            data: 5000u16.to_le_bytes().repeat(64 * 48),
            units_per_metre: 1000.0,
        })),
    });
    f
}

/// Decodes a streamed frame's PNG.
pub(super) fn streamed_png(answer: Body, frame_id: u64) -> (proto::RenderedFrame, image::RgbImage) {
    let Body::RenderedFrame(f) = answer else { panic!("expected a RenderedFrame, got {answer:?}") };
    assert_eq!(f.frame_id, frame_id);
    let Some(proto::rendered_frame::Image::Png(png)) = &f.image else { panic!("expected a PNG") };
    let png = image::load_from_memory(png).expect("a PNG").into_rgb8();
    assert_eq!(png.dimensions(), (f.width, f.height));
    (f, png)
}

/// The stream relights: each frame's pixels light the scene, which is seen from the frame's
/// camera and composited over its colour; a model transform moves the content; a light
/// override changes it; and none of it leaks into the scene's HTTP renders.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stream_relights_frames_and_follows_its_controls() {
    let server = TestServer::start(|_| {}).await;
    let id = server.create(&inline_scene()).await;
    let http_render = || async {
        let request = json!({"quality": {"component": "indirect", "format": "f32"}});
        let reply = server.post(&format!("/v1/scenes/{id}/render"), &request).await;
        assert_eq!(reply.status, StatusCode::OK, "{}", String::from_utf8_lossy(&reply.body));
        reply.body
    };
    let before = http_render().await;

    let mut ws = server.stream(&id).await;
    let (first, image) = streamed_png(ws.exchange(envelope(Body::RgbdFrame(frame_behind_the_scene(1)))).await, 1);
    assert_eq!((first.width, first.height), (64, 48), "the frame's own size");
    assert!(first.val_count > 0);
    let stages: Vec<&str> = first.timings.iter().map(|t| t.stage.as_str()).collect();
    for stage in ["decode", "queue", "rgbd_vals", "gather", "shade", "composite", "encode"] {
        assert!(stages.contains(&stage), "{stage} missing from {stages:?}");
    }
    assert!(first.timings.iter().all(|t| t.ms.is_finite() && t.ms >= 0.0));
    // The real wall (the frame's grey, 128) shows where there is no virtual content: the top
    // corners; the lit virtual floor and wall cover the middle of the image.
    assert_eq!(image.get_pixel(0, 0).0, [128, 128, 128]);
    let virtual_pixels = image.pixels().filter(|p| p.0 != [128, 128, 128]).count();
    assert!(virtual_pixels > 64 * 48 / 10, "the scene is composited in: {virtual_pixels} pixels");

    // Move the mesh 0.5 m to the right: the composite changes.
    let control = proto::Control {
        request_id: 3,
        model_transforms: vec![proto::ModelTransform {
            mesh_index: 0,
            translation: v3(0.5, 0.0, 0.0),
            rotation_deg: v3(0.0, 0.0, 0.0),
            scale: None,
        }],
        ..Default::default()
    };
    assert!(matches!(ws.exchange(envelope(Body::Control(control))).await, Body::SettingsAck(_)));
    let (_, moved) = streamed_png(ws.exchange(envelope(Body::RgbdFrame(frame_behind_the_scene(2)))).await, 2);
    assert_ne!(moved, image, "the model transform moves the content");
    let control = proto::Control {
        request_id: 4,
        light: Some(proto::LightOverride { intensity: v3(0.0, 0.0, 0.0), ..Default::default() }),
        quality: Some(proto::Quality { component: proto::Component::Direct as i32, ..Default::default() }),
        ..Default::default()
    };
    assert!(matches!(ws.exchange(envelope(Body::Control(control))).await, Body::SettingsAck(_)));
    let (dark, direct) = streamed_png(ws.exchange(envelope(Body::RgbdFrame(frame_behind_the_scene(3)))).await, 3);
    assert!(!dark.timings.iter().any(|t| t.stage == "composite"), "a component alone is not composited");
    assert!(direct.pixels().all(|p| p.0 == [0, 0, 0]), "the spot light is off: no direct light");

    // Occlusion is a stream setting: on, the frame runs the occlusion stage; off, it does not.
    for (request_id, occlusion, expected) in [(5, proto::Occlusion::Disks, true), (6, proto::Occlusion::Off, false)] {
        let control = proto::Control {
            request_id,
            render: Some(proto::RenderSettings {
                occlusion: Some(occlusion as i32),
                glossy: Some(false),
                ..Default::default()
            }),
            ..Default::default()
        };
        match ws.exchange(envelope(Body::Control(control))).await {
            Body::SettingsAck(ack) => {
                assert_eq!((ack.request_id, ack.applied), (request_id, vec!["render".to_owned()]))
            }
            other => panic!("expected an ack, got {other:?}"),
        }
        let (f, _) =
            streamed_png(ws.exchange(envelope(Body::RgbdFrame(frame_behind_the_scene(request_id)))).await, request_id);
        let stages: Vec<&str> = f.timings.iter().map(|t| t.stage.as_str()).collect();
        assert_eq!(stages.contains(&"occlusion"), expected, "{occlusion:?}: {stages:?}");
    }

    // The scene's own renders: same light, same placement, no RGB-D VALs, as before.
    // Not bit for bit: the RSM appends VALs with an atomic counter, so their order (and the
    // gather's float summation order) depends on thread scheduling; under load two renders of
    // one scene differ in the last bits. A leak (the stream's dark light, moved mesh or VALs)
    // changes pixels by their whole value, so 1e-4 of the brightest pixel separates the two.
    let floats = |b: &Bytes| -> Vec<f32> {
        b.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes"))).collect()
    };
    let (before, after) = (floats(&before), floats(&http_render().await));
    assert_eq!(before.len(), after.len());
    let peak = before.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let worst = before.iter().zip(&after).fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
    assert!(peak > 0.0 && worst <= 1e-4 * peak, "the stream's state leaked into an HTTP render: {worst} of {peak}");
    drop(ws);
    server.stop().await;
}

/// A stream may ask for `brute-force-ism`: its frames run the ISM stages per pixel; a view
/// whose pixels x `settings.ism.count` table passes the device's storage binding is answered
/// with an `Error` of code LIMIT_EXCEEDED naming the table, and the stream goes on.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stream_renders_brute_force_ism_and_refuses_it_over_the_device_limit() {
    let server = TestServer::start(|_| {}).await;
    let mut scene = inline_scene();
    scene["settings"]["tuning"]["ism"] = json!({"count": 16, "resolution": 32, "points": 400});
    let id = server.create(&scene).await;
    let mut ws = server.stream(&id).await;
    let quality = |request_id| proto::Control {
        request_id,
        quality: Some(proto::Quality {
            method: proto::Method::BruteForceIsm as i32,
            component: proto::Component::Indirect as i32,
            ..Default::default()
        }),
        ..Default::default()
    };
    assert!(matches!(ws.exchange(envelope(Body::Control(quality(1)))).await, Body::SettingsAck(_)));
    let (f, _) = streamed_png(ws.exchange(envelope(Body::RgbdFrame(frame_behind_the_scene(1)))).await, 1);
    let stages: Vec<&str> = f.timings.iter().map(|t| t.stage.as_str()).collect();
    for stage in ["brute_force_ism_splat", "brute_force_ism_visibility", "brute_force"] {
        assert!(stages.contains(&stage), "{stage} missing from {stages:?}");
    }

    // A 2048x2048 virtual view with 1,024 maps: 16 GiB of table.
    let mut scene = inline_scene();
    scene["settings"]["tuning"]["ism"] = json!({"count": 1024});
    let big = server.create(&scene).await;
    let mut ws = server.stream(&big).await;
    let camera = proto::Camera {
        position: v3(0.0, 1.0, 3.0),
        target: v3(0.0, 0.5, 0.0),
        up: None,
        fov_y_deg: 50.0,
        width: 2048,
        height: 2048,
    };
    let control = proto::Control { camera: Some(camera), ..quality(2) };
    assert!(matches!(ws.exchange(envelope(Body::Control(control))).await, Body::SettingsAck(_)));
    match ws.exchange(envelope(Body::RgbdFrame(frame_behind_the_scene(2)))).await {
        Body::Error(e) => {
            assert_eq!(e.code(), ErrorCode::LimitExceeded, "{e:?}");
            assert!(e.message.contains("brute_force_ism") && e.message.contains("1024"), "{e:?}");
            assert_eq!(e.frame_id, Some(2), "{e:?}");
        }
        other => panic!("expected an Error, got {other:?}"),
    }
    // The stream goes on: the same view at 32x32 fits (4 MiB of table) and renders.
    let control = proto::Control { camera: Some(proto::Camera { width: 32, height: 32, ..camera }), ..quality(3) };
    assert!(matches!(ws.exchange(envelope(Body::Control(control))).await, Body::SettingsAck(_)));
    let (f, _) = streamed_png(ws.exchange(envelope(Body::RgbdFrame(frame_behind_the_scene(3)))).await, 3);
    assert_eq!((f.width, f.height), (32, 32));
    drop(ws);
    server.stop().await;
}

/// The viewer's files, and the recordings it plays: the fixture recording listed, a frame
/// answered as the stream message that a stream then renders unchanged, and JSON errors for
/// bad names, indices and queries.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_viewer_and_the_recordings_are_served() {
    let server = TestServer::start(|_| {}).await;
    for (path, content_type) in [
        ("/", "text/html; charset=utf-8"),
        ("/viewer.js", "text/javascript; charset=utf-8"),
        ("/proto.js", "text/javascript; charset=utf-8"),
        ("/relume.proto.json", "application/json"),
        ("/vendor/protobufjs/protobuf.min.js", "text/javascript; charset=utf-8"),
        ("/vendor/protobufjs/LICENSE", "text/plain; charset=utf-8"),
        ("/viewer.css", "text/css; charset=utf-8"),
        ("/default-scene.json", "application/json"),
    ] {
        let reply = server.get(path).await;
        assert_eq!(reply.status, StatusCode::OK, "{path}");
        assert_eq!(reply.header("content-type"), content_type, "{path}");
    }
    let mut scene = server.get("/default-scene.json").await.json();
    scene["meshes"][0]["sparse_points"] = 64.into();
    let id = server.create(&scene).await;

    let list = server.get("/v1/recordings").await.json();
    let recording = &list["recordings"][0];
    assert_eq!(recording["name"], "tum_fr1_xyz", "{list}");
    assert_eq!((recording["width"].as_u64(), recording["height"].as_u64()), (Some(640), Some(480)));
    let frames = recording["frames"].as_u64().expect("a frame count");
    assert!(frames > 10 && recording["duration_s"].as_f64().is_some_and(|d| d > 0.0), "{list}");

    let path = "/v1/recordings/tum_fr1_xyz/frames";
    let reply = server.get(&format!("{path}/3?downscale=8")).await;
    assert_eq!(reply.status, StatusCode::OK, "{}", String::from_utf8_lossy(&reply.body));
    assert_eq!(reply.header("content-type"), "application/x-protobuf");
    assert_eq!(reply.header("x-relume-frame-count"), frames.to_string());
    assert_eq!((reply.header("x-relume-width"), reply.header("x-relume-height")), ("80", "60"));
    let envelope = proto::Envelope::decode(reply.body.as_ref()).expect("an Envelope");
    assert_eq!(envelope.version, PROTOCOL_VERSION);
    let Some(Body::RgbdFrame(frame)) = &envelope.body else { panic!("an RgbdFrame, got {:?}", envelope.body) };
    assert_eq!(frame.frame_id, 3);
    let k = frame.intrinsics.expect("intrinsics");
    assert_eq!((k.width, k.height, k.fx), (80, 60, 525.0 / 8.0));
    let mut ws = server.stream(&id).await;
    let (rendered, _) = streamed_png(ws.exchange(reply.body.to_vec()).await, 3);
    assert_eq!((rendered.width, rendered.height), (80, 60));
    assert!(rendered.val_count > 0);
    drop(ws);

    let last = server.get(&format!("{path}/{}", frames - 1)).await;
    assert_eq!((last.status, last.header("x-relume-width")), (StatusCode::OK, "640"));
    server.get(&format!("{path}/{frames}")).await.error(404, "not_found");
    server.get("/v1/recordings/no_such_recording/frames/0").await.error(404, "not_found");
    for escape in ["..%2Fscenes", ".hidden", "a%5Cb", "%2E%2E"] {
        let error = server.get(&format!("/v1/recordings/{escape}/frames/0")).await.error(400, "invalid_field");
        assert_eq!(error["field"], "name", "{escape}");
    }
    for (query, field) in [("x/frames/-1", "index"), ("x/frames/one", "index")] {
        let error = server.get(&format!("/v1/recordings/{query}")).await.error(400, "invalid_field");
        assert_eq!(error["field"], field, "{query}");
    }
    for (query, field) in [("?downscale=0", "downscale"), ("?downscale=17", "downscale"), ("?size=2", "size")] {
        let error = server.get(&format!("{path}/0{query}")).await.error(400, "invalid_field");
        assert_eq!(error["field"], field, "{query}");
    }
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn shutdown_finishes_in_flight_renders_and_closes_streams() {
    let server = TestServer::start(|_| {}).await;
    let id = server.create(&fixture_scene("cornell_bunny_small", 32)).await;
    let mut ws = server.stream(&id).await;
    let path = format!("/v1/scenes/{id}/render");
    let body = json!({"quality": {"method": "brute-force"}, "camera": {
        "position": [0, 1, 3.3], "target": [0, 0.9, 0], "fov_y_deg": 38, "width": 64, "height": 64}})
    .to_string();
    let in_flight = {
        let request = hyper::Request::post(format!("http://{}{path}", server.addr))
            .body(Full::new(Bytes::from(body)))
            .expect("request");
        let client = server.client.clone();
        tokio::spawn(async move { client.request(request).await })
    };
    // Let the render reach the GPU thread.
    tokio::time::sleep(Duration::from_millis(100)).await;
    let addr = server.addr;
    let stop = tokio::spawn(server.stop());

    match ws.answer().await {
        Body::Error(e) => assert_eq!(e.code(), ErrorCode::ShuttingDown),
        other => panic!("{other:?}"),
    }
    match ws.next().await {
        tungstenite::Message::Close(Some(frame)) => assert_eq!(u16::from(frame.code), 1001),
        other => panic!("expected a close frame, got {other:?}"),
    }
    let response = in_flight.await.expect("task").expect("the in-flight render is answered");
    assert_eq!(response.status(), StatusCode::OK);
    let png = response.into_body().collect().await.expect("body").to_bytes();
    assert_eq!(image::load_from_memory(&png).expect("a PNG").width(), 64);
    stop.await.expect("stopped cleanly");
    assert!(tokio::net::TcpStream::connect(addr).await.is_err(), "no longer listening");
}

#[test]
fn openapi_document_is_in_sync() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("proto/openapi.json");
    let generated = relume::service::openapi_json();
    if std::env::var_os("BLESS").is_some() {
        std::fs::write(&path, &generated).expect("writing proto/openapi.json");
        return;
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == generated,
        "proto/openapi.json differs from the document the handlers generate; if the API change is \
         deliberate, run `BLESS=1 cargo test --test integration openapi` (or `relume openapi > \
         proto/openapi.json`) and commit the result"
    );
}

/// The binary: flags and environment variables, a request, and a clean exit on SIGTERM.
#[cfg(unix)]
#[test]
fn the_binary_serves_until_sigterm() {
    use std::io::{BufRead, BufReader, Read, Write};
    use std::process::{Command, Stdio};

    let bad = Command::new(env!("CARGO_BIN_EXE_relume"))
        .args(["serve", "--addr", "127.0.0.1:0"])
        .env("RELUME_ASSETS", fixture("no-such-dir"))
        .output()
        .expect("runs");
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("no-such-dir"), "{}", String::from_utf8_lossy(&bad.stderr));

    let serve = |extra: &[&str]| {
        let mut child = Command::new(env!("CARGO_BIN_EXE_relume"))
            .args(["serve", "--addr", "127.0.0.1:0"])
            .args(extra)
            .env("RELUME_ASSETS", fixture(""))
            .env("NO_COLOR", "1")
            .env_remove("RUST_LOG")
            .stderr(Stdio::piped())
            .spawn()
            .expect("starts");
        let stderr = BufReader::new(child.stderr.take().expect("stderr"));
        (child, stderr, String::new())
    };
    let (mut child, mut stderr, mut log) = serve(&["--max-queue", "3"]);
    let port = loop {
        let mut line = String::new();
        assert!(stderr.read_line(&mut line).expect("reads") > 0, "exited early:\n{log}");
        log.push_str(&line);
        if line.contains("serving") {
            let after = &line[line.find("127.0.0.1:").expect("the address is logged") + "127.0.0.1:".len()..];
            break after.chars().take_while(char::is_ascii_digit).collect::<String>();
        }
    };
    let mut stream = std::net::TcpStream::connect(format!("127.0.0.1:{port}")).expect("connects");
    stream.write_all(b"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n").expect("writes");
    let mut answer = String::new();
    stream.read_to_string(&mut answer).expect("reads");
    assert!(answer.starts_with("HTTP/1.1 200"), "{answer}");
    assert!(answer.contains("\"max_queue\":3"), "{answer}");

    let killed = Command::new("kill").args(["-TERM", &child.id().to_string()]).status().expect("kill runs");
    assert!(killed.success());
    let status = child.wait().expect("exits");
    stderr.read_to_string(&mut log).expect("reads the rest");
    assert!(status.success(), "{status}\n{log}");
    assert!(log.contains("SIGTERM received") && log.contains("stopped"), "{log}");

    // SIGTERM the moment "serving" is logged, with no request between: the handlers must
    // already listen then (a signal before them kills the process, as CI once saw).
    let (mut child, mut stderr, mut log) = serve(&[]);
    while !log.contains("serving") {
        let mut line = String::new();
        assert!(stderr.read_line(&mut line).expect("reads") > 0, "exited early:\n{log}");
        log.push_str(&line);
    }
    let killed = Command::new("kill").args(["-TERM", &child.id().to_string()]).status().expect("kill runs");
    assert!(killed.success());
    let status = child.wait().expect("exits");
    stderr.read_to_string(&mut log).expect("reads the rest");
    assert!(status.success(), "SIGTERM right after \"serving\": {status}\n{log}");
}

/// `relume replay --server`: the fixture recording through the service gives the same
/// composites as the offline replay. Two frames at the recording's 640x480, one VAL per 16x16
/// depth pixels to stay fast.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_recording_replays_through_the_server_as_offline() {
    use relume::mr::{MrOptions, MrRenderer};
    use relume::rgbd::recording::{Recording, RecordingOptions};
    use relume::service::client::{RemoteReplayOptions, replay_remote};

    let dir = super::scratch("wire_replay");
    let mut scene: Value =
        serde_json::from_str(&std::fs::read_to_string(fixture("scenes/mr_bunny.json")).expect("fixture"))
            .expect("JSON");
    scene["meshes"][0]["obj"] =
        fixture("meshes/stanford_bunny/stanford-bunny.obj").to_string_lossy().into_owned().into();
    scene["settings"]["rgbd"]["grid_step"] = 16.into();
    // The stream runs the replay's pipeline, environment (`auto` here) and differential pass
    // included (`stream_mr.rs` compares those at a small size); off at 640x480, where it costs
    // seconds a frame on lavapipe.
    scene["settings"]["mr"] = serde_json::json!({ "differential": false });
    let scene_path = dir.join("mr_bunny_coarse.json");
    std::fs::write(&scene_path, scene.to_string()).expect("scene written");

    let server = TestServer::start(|_| {}).await;
    let options = RemoteReplayOptions {
        server: format!("http://{}", server.addr),
        token: None,
        recording: fixture("recordings/tum_fr1_xyz"),
        recording_options: RecordingOptions::default(),
        scene: scene_path.clone(),
        out: dir.join("out"),
        frames: Some(2),
        exposure: None,
        progress: false,
        reconnect: Duration::ZERO,
    };
    let summary = replay_remote(&options).await.expect("the replay runs");
    assert_eq!((summary.frames, summary.width, summary.height, summary.dropped_frames), (2, 640, 480, 0));
    assert!(summary.stage_ms.contains_key("composite") && summary.round_trip_ms.len() == 2);
    let summary_json: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/summary.json")).expect("summary")).expect("JSON");
    assert_eq!(summary_json["vals_per_frame"].as_array().map(Vec::len), Some(2));
    // The replay's scene was deleted again.
    let health = server.get("/healthz").await.json();
    assert_eq!(health["scenes"], 0, "{health}");
    server.stop().await;

    let (offline, recording) = tokio::task::spawn_blocking(move || {
        let gpu = super::gpu();
        let scene = relume::scene::Scene::load(&scene_path).expect("scene");
        let recording = Recording::open(&fixture("recordings/tum_fr1_xyz"), &RecordingOptions::default()).expect("rec");
        let options = MrOptions { width: 640, height: 480, exposure: 1.0, accumulate: None };
        let mut mr = MrRenderer::new(&gpu, &scene, options).expect("renderer");
        let text = std::fs::read_to_string(&scene_path).expect("scene");
        let environment = relume::scene::SceneDescription::from_json_str(&text).expect("JSON").settings.environment;
        let environment = relume::mr::environment::Environment::from_settings(
            &environment,
            scene_path.parent().expect("a directory"),
        )
        .expect("auto");
        assert_ne!(environment, relume::mr::environment::Environment::None, "mr_bunny.json's `auto`");
        mr.set_environment(environment);
        let frames: Vec<_> = (0..2)
            .map(|i| mr.render_frame(&gpu, &recording.frame(i).expect("frame")).expect("render").composited)
            .collect();
        (frames, recording)
    })
    .await
    .expect("the offline replay");
    for (i, offline) in offline.iter().enumerate() {
        let wire = image::open(dir.join(format!("out/composited/{i:04}.png"))).expect("a PNG").into_rgb8();
        assert_eq!(wire.dimensions(), (640, 480));
        // Same scene, frame, adapter and shaders on both paths: the 8-bit composites must agree
        // exactly but for rounding, so at most 1 level in any channel.
        let worst =
            wire.pixels().zip(offline).map(|(w, o)| (0..3).map(|c| w.0[c].abs_diff(o[c])).max().unwrap_or(0)).max();
        assert!(worst <= Some(1), "frame {i}: the wire composite differs from the offline one by {worst:?}");
        let camera = recording.frame(i).expect("frame").color;
        let virtual_pixels = offline.iter().zip(&camera).filter(|(o, c)| o != c).count();
        assert!(virtual_pixels > 1000, "frame {i}: the bunny is drawn ({virtual_pixels} pixels)");
    }
}

/// A whole scene from one glTF file (its meshes, spot light and camera, with relume's
/// settings beside it), sent as `fixtures/scenes/cornell_gltf_small.json` reads it, renders
/// through the service as the renderer renders that file in this process.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_whole_gltf_scene_renders_through_the_service_as_from_its_file() {
    const SIDE: u32 = 32;
    let text = std::fs::read_to_string(fixture("scenes/cornell_gltf_small.json")).expect("fixture");
    let mut scene: Value = serde_json::from_str(&text).expect("JSON");
    (scene["width"], scene["height"]) = (SIDE.into(), SIDE.into());
    let local = relume::scene::Scene::from_json_str(&scene.to_string(), &fixture("scenes")).expect("loads");
    // The same file, named relative to the server's asset directory (`fixtures/`).
    let mut served = scene.clone();
    served["gltf"] = json!("meshes/cornell_box_gltf/CornellBox-Original.glb");

    let server = TestServer::start(|_| {}).await;
    let id = server.create(&served).await;
    let info = server.get(&format!("/v1/scenes/{id}")).await.json();
    assert_eq!(info["sparse_points"], 512);
    assert_eq!(info["triangles"], local.triangle_count());
    assert_eq!((info["camera"]["width"].as_u64(), info["camera"]["height"].as_u64()), (Some(32), Some(32)));
    assert!(info["light"]["intensity"].is_array(), "the glTF's spot light: {info}");

    let request = json!({"quality": {"method": "sparse", "component": "indirect", "format": "f32"}});
    let render = server.post(&format!("/v1/scenes/{id}/render"), &request).await;
    assert_eq!(render.status, StatusCode::OK, "{}", String::from_utf8_lossy(&render.body));
    let served: Vec<[f32; 4]> = render
        .body
        .chunks_exact(16)
        .map(|p| std::array::from_fn(|c| f32::from_le_bytes(p[4 * c..4 * c + 4].try_into().expect("4 bytes"))))
        .collect();
    server.stop().await;

    let gpu = super::gpu();
    let mut renderer = relume::renderer::Renderer::new(&gpu, &local).expect("renderer");
    let frame = renderer.render(&gpu, relume::renderer::Method::Sparse, SIDE, SIDE).expect("renders");
    let served = relume::image::LinearImage { width: SIDE, height: SIDE, pixels: served };
    assert!(frame.indirect.coverage() > (SIDE * SIDE / 2) as usize, "the box fills the view");
    assert_eq!(served.coverage(), frame.indirect.coverage());
    // Same device, same scene, same settings: only the order in which the RSM appends VALs
    // (atomicAdd) and so the order of the gather's float sums may differ, a few ulps.
    let error = relume::image::relative_rmse(&served, &frame.indirect);
    assert!(error < 1e-4, "served vs in-process indirect: rel RMSE {error}");
}

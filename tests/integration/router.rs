//! The router's limits, token and 4xx paths, driven as a tower service
//! (`tower::ServiceExt::oneshot`, as axum's `examples/testing` does) on the fake GPU thread:
//! no adapter, no socket. What needs a real connection (timeouts, upgrades, the connection cap,
//! WebSocket frames) is tested over loopback in `service.rs` and `hardening.rs`.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::body::Body;
use axum::extract::ConnectInfo;
use bytes::Bytes;
use http_body_util::BodyExt;
use hyper::{Method, StatusCode};
use relume::service::{AppState, Config, GpuWorker, router};
use serde_json::{Value, json};
use tower::ServiceExt;

use super::fake_backend::FakeBackend;
use super::fixture;
use super::service::{Reply, inline_scene};

/// The router on a fake GPU thread (renders take no time), `fixtures/` as the asset
/// directory, the defaults changed by `edit`.
struct App {
    router: Router,
    state: Arc<AppState>,
    token: Option<String>,
}

impl App {
    async fn start(edit: impl FnOnce(&mut Config)) -> App {
        let mut config = Config::new(SocketAddr::from(([127, 0, 0, 1], 0)), fixture(""));
        edit(&mut config);
        let token = config.token.clone();
        let limits = config.limits;
        let state = AppState::start(config, move |metrics| {
            GpuWorker::start_with(|| Ok(FakeBackend::new(Duration::ZERO)), &limits, metrics)
        })
        .await
        .expect("the state starts");
        App { router: router(state.clone()), state, token }
    }

    /// One request through the router, as the connection loop hands it over: with the peer's
    /// address (the fair queue's client) in its extensions.
    async fn send(&self, request: hyper::Request<Body>) -> Reply {
        let mut request = request;
        request.extensions_mut().insert(ConnectInfo(SocketAddr::from(([127, 0, 0, 1], 40000))));
        let response = self.router.clone().oneshot(request).await.expect("the router is infallible");
        let (parts, body) = response.into_parts();
        let body = body.collect().await.expect("body").to_bytes();
        Reply { status: parts.status, headers: parts.headers, body }
    }

    async fn request(&self, method: Method, path: &str, body: impl Into<Bytes>) -> Reply {
        let mut request = hyper::Request::builder().method(method).uri(path);
        if let Some(token) = &self.token {
            request = request.header("authorization", format!("Bearer {token}"));
        }
        self.send(request.body(Body::from(body.into())).expect("request")).await
    }

    async fn get(&self, path: &str) -> Reply {
        self.request(Method::GET, path, Bytes::new()).await
    }

    async fn post(&self, path: &str, body: &Value) -> Reply {
        self.request(Method::POST, path, body.to_string()).await
    }

    async fn create(&self, scene: &Value) -> String {
        let reply = self.post("/v1/scenes", scene).await;
        assert_eq!(reply.status, StatusCode::CREATED, "{}", reply.json());
        reply.json()["id"].as_str().expect("id").to_owned()
    }

    async fn stop(self) {
        self.state.workers.stop().await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn limits_and_routes_answer_with_json_errors() {
    let app = App::start(|c| {
        c.limits.max_body_bytes = 4096;
        c.limits.max_scenes = 1;
    })
    .await;
    let mut big = inline_scene();
    big["meshes"][0]["obj_text"] = json!(format!("# {}\n", "x".repeat(5000)));
    let error = app.post("/v1/scenes", &big).await.error(413, "limit_exceeded");
    assert_eq!(error["limit"], "max_body_bytes");

    let id = app.create(&inline_scene()).await;
    assert_eq!(app.post("/v1/scenes", &inline_scene()).await.error(400, "limit_exceeded")["limit"], "max_scenes");

    let render = |body: Value| {
        let path = format!("/v1/scenes/{id}/render");
        let app = &app;
        async move { app.post(&path, &body).await }
    };
    let camera = |edit: &dyn Fn(&mut Value)| {
        let mut c = json!({"position": [0, 1, 3], "target": [0, 0.5, 0], "fov_y_deg": 50, "width": 8, "height": 8});
        edit(&mut c);
        json!({ "camera": c })
    };
    let e = render(camera(&|c| c["target"] = json!([0, 1, 3]))).await.error(400, "invalid_field");
    assert_eq!(e["field"], "camera.target");
    let e = render(camera(&|c| c["width"] = json!(5000))).await.error(400, "limit_exceeded");
    assert_eq!((e["limit"].as_str(), e["field"].as_str()), (Some("max_frame_side"), Some("camera.width")));
    let e = render(camera(&|c| c["width"] = json!(-1))).await.error(400, "invalid_json");
    assert_eq!(e["field"], "camera.width");
    let e = render(json!({"light": {"inner_angle_deg": 50}})).await.error(400, "invalid_field");
    assert_eq!(e["field"], "light.inner_angle_deg");
    let e = render(json!({"light": {"direction": [0, 0, 0]}})).await.error(400, "invalid_field");
    assert_eq!(e["field"], "light.direction");
    let e = render(json!({"quality": {"method": "exact"}})).await.error(400, "invalid_json");
    assert_eq!(e["field"], "quality.method");
    let e = render(json!({"quality": {"exposure": -1}})).await.error(400, "invalid_field");
    assert_eq!(e["field"], "quality.exposure");
    render(json!({"quality": {"typo": 1}})).await.error(400, "invalid_json");

    app.get("/v1/scenes/nope").await.error(404, "not_found");
    app.get("/v1/nothing").await.error(404, "not_found");
    app.request(Method::PUT, "/v1/scenes", Bytes::new()).await.error(405, "method_not_allowed");
    // A plain GET of the stream route is not an upgrade.
    app.get(&format!("/v1/scenes/{id}/stream")).await.error(400, "upgrade_required");

    let reply = render(json!({"quality": {"exposure": 2, "component": "direct"}})).await;
    assert_eq!(reply.status, StatusCode::OK);
    assert_eq!(reply.header("x-relume-exposure"), "2");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_token_guards_the_v1_routes() {
    let mut app = App::start(|c| c.token = Some("s3cret".to_owned())).await;
    app.token = None;
    app.post("/v1/scenes", &inline_scene()).await.error(401, "unauthorized");
    app.get("/v1/scenes/x").await.error(401, "unauthorized");
    app.token = Some("wrong".to_owned());
    let reply = app.get("/v1/scenes/x").await;
    reply.error(401, "unauthorized");
    assert_eq!(reply.header("www-authenticate"), "Bearer");
    assert_eq!(app.get("/healthz").await.status, StatusCode::OK);
    assert_eq!(app.get("/metrics").await.status, StatusCode::OK);
    app.token = Some("s3cret".to_owned());
    let id = app.create(&inline_scene()).await;
    assert_eq!(app.get(&format!("/v1/scenes/{id}")).await.status, StatusCode::OK);
    // The scheme is case-insensitive (RFC 7235, section 2.1); the token is not.
    for (value, status) in [
        ("bearer s3cret", StatusCode::OK),
        ("BEARER s3cret", StatusCode::OK),
        ("bearer  s3cret", StatusCode::OK),
        ("bearer S3CRET", StatusCode::UNAUTHORIZED),
        ("Basic s3cret", StatusCode::UNAUTHORIZED),
    ] {
        let request = hyper::Request::get(format!("/v1/scenes/{id}"))
            .header("authorization", value)
            .body(Body::empty())
            .expect("request");
        assert_eq!(app.send(request).await.status, status, "Authorization: {value}");
    }
    // A WebSocket handshake without the token is refused before the upgrade.
    app.token = None;
    let handshake = hyper::Request::get(format!("/v1/scenes/{id}/stream"))
        .header("upgrade", "websocket")
        .header("connection", "Upgrade")
        .header("sec-websocket-key", "dGhlIHNhbXBsZSBub25jZQ==")
        .header("sec-websocket-version", "13")
        .body(Body::empty())
        .expect("request");
    app.send(handshake).await.error(401, "unauthorized");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn metrics_labels_stay_a_closed_set() {
    let app = App::start(|_| {}).await;
    for i in 0..20 {
        let method = Method::from_bytes(format!("INVENTED{i}").as_bytes()).expect("a method token");
        app.request(method, &format!("/no/such/route/{i}"), Bytes::new()).await;
    }
    let metrics = String::from_utf8(app.get("/metrics").await.body.to_vec()).expect("text");
    assert!(!metrics.contains("INVENTED"), "an invented method became a label");
    assert!(!metrics.contains("/no/such/route"), "an unmatched path became a label");
    assert!(metrics.contains("method=\"other\""), "invented methods are counted as other:\n{metrics}");
    app.stop().await;
}

/// A WebSocket handshake of the scene's stream, with `query` (e.g. `?ticket=...`) and the
/// token `app` holds. It carries a (never completed) upgrade, so that a handshake the router
/// lets through is answered 101.
async fn handshake(app: &App, id: &str, query: &str) -> Reply {
    handshake_offering(app, id, query, &[]).await
}

/// [`handshake`] with these `Sec-WebSocket-Protocol` headers.
async fn handshake_offering(app: &App, id: &str, query: &str, protocols: &[&str]) -> Reply {
    let mut request = hyper::Request::get(format!("/v1/scenes/{id}/stream{query}"))
        .header("upgrade", "websocket")
        .header("connection", "Upgrade")
        .header("sec-websocket-key", "dGhlIHNhbXBsZSBub25jZQ==")
        .header("sec-websocket-version", "13");
    if let Some(token) = &app.token {
        request = request.header("authorization", format!("Bearer {token}"));
    }
    for protocol in protocols {
        request = request.header("sec-websocket-protocol", *protocol);
    }
    let mut request = request.body(Body::empty()).expect("request");
    let upgrade = hyper::upgrade::on(&mut request);
    request.extensions_mut().insert(upgrade);
    app.send(request).await
}

/// `POST /v1/tickets` with the token `app` holds: the ticket.
async fn ticket(app: &App) -> String {
    let reply = app.request(Method::POST, "/v1/tickets", Bytes::new()).await;
    assert_eq!(reply.status, StatusCode::OK, "{}", reply.json());
    assert_eq!(reply.header("cache-control"), "no-store");
    reply.json()["ticket"].as_str().expect("a ticket").to_owned()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_ticket_opens_one_stream_in_place_of_the_token() {
    let mut app = App::start(|c| c.token = Some("s3cret".to_owned())).await;
    let id = app.create(&inline_scene()).await;
    // Tickets are issued with the token only.
    app.token = None;
    app.request(Method::POST, "/v1/tickets", Bytes::new()).await.error(401, "unauthorized");
    app.token = Some("wrong".to_owned());
    app.request(Method::POST, "/v1/tickets", Bytes::new()).await.error(401, "unauthorized");
    app.token = Some("s3cret".to_owned());
    let reply = app.request(Method::POST, "/v1/tickets", Bytes::new()).await;
    assert_eq!(reply.status, StatusCode::OK);
    assert_eq!(reply.json()["expires_in_seconds"], 30);
    let first = reply.json()["ticket"].as_str().expect("a ticket").to_owned();
    assert_eq!(app.state.tickets.outstanding(), 1);

    // Without the token, the ticket opens the stream once; the same ticket again, an unknown
    // one, and none at all are refused before the upgrade with the JSON error.
    app.token = None;
    assert_eq!(handshake(&app, &id, &format!("?ticket={first}")).await.status, StatusCode::SWITCHING_PROTOCOLS);
    let reused = handshake(&app, &id, &format!("?ticket={first}")).await;
    let error = reused.error(401, "unauthorized");
    assert!(error["message"].as_str().is_some_and(|m| m.contains("ticket")), "{error}");
    assert_eq!(reused.header("www-authenticate"), "Bearer");
    handshake(&app, &id, "?ticket=not-a-ticket").await.error(401, "unauthorized");
    handshake(&app, &id, "?ticket=").await.error(401, "unauthorized");
    handshake(&app, &id, "").await.error(401, "unauthorized");
    assert_eq!(app.state.tickets.outstanding(), 0);

    // A ticket given is the credential: a wrong one is refused even beside the right token.
    app.token = Some("s3cret".to_owned());
    handshake(&app, &id, "?ticket=not-a-ticket").await.error(401, "unauthorized");
    assert_eq!(handshake(&app, &id, "").await.status, StatusCode::SWITCHING_PROTOCOLS);
    let twice = handshake(&app, &id, "?ticket=a&ticket=b").await.error(400, "invalid_field");
    assert_eq!(twice["field"], "ticket");

    // Tickets open streams only: another route wants the token and leaves the ticket unspent.
    let second = ticket(&app).await;
    app.token = None;
    app.get(&format!("/v1/scenes/{id}?ticket={second}")).await.error(401, "unauthorized");
    app.request(Method::POST, &format!("/v1/tickets?ticket={second}"), Bytes::new()).await.error(401, "unauthorized");
    assert_eq!(handshake(&app, &id, &format!("?ticket={second}")).await.status, StatusCode::SWITCHING_PROTOCOLS);
    // A ticket spent on a handshake refused after the check (no such scene) is spent all the same.
    app.token = Some("s3cret".to_owned());
    let third = ticket(&app).await;
    app.token = None;
    handshake(&app, "nope", &format!("?ticket={third}")).await.error(404, "not_found");
    handshake(&app, &id, &format!("?ticket={third}")).await.error(401, "unauthorized");
    app.stop().await;
}

/// The ticket as a subprotocol (`relume.ticket.<ticket>` beside `relume.v1`), out of the URL:
/// the same single use, `relume.v1` selected, and clear 400s for a ticket offered twice or
/// without `relume.v1` (a browser would fail a handshake that selects none of its offers).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_ticket_can_ride_in_the_websocket_subprotocol() {
    let mut app = App::start(|c| c.token = Some("s3cret".to_owned())).await;
    let id = app.create(&inline_scene()).await;
    let first = ticket(&app).await;
    let (second, third) = (ticket(&app).await, ticket(&app).await);
    app.token = None;
    let offer = |ticket: &str| format!("relume.v1, relume.ticket.{ticket}");
    let opened = handshake_offering(&app, &id, "", &[&offer(&first)]).await;
    assert_eq!(opened.status, StatusCode::SWITCHING_PROTOCOLS);
    assert_eq!(opened.header("sec-websocket-protocol"), "relume.v1");
    handshake_offering(&app, &id, "", &[&offer(&first)]).await.error(401, "unauthorized");
    // In two header lines, in either order.
    let split = [format!("relume.ticket.{second}"), "relume.v1".to_owned()];
    let opened = handshake_offering(&app, &id, "", &[&split[0], &split[1]]).await;
    assert_eq!(opened.status, StatusCode::SWITCHING_PROTOCOLS);

    let error = handshake_offering(&app, &id, "", &[&format!("relume.ticket.{third}")]).await;
    let error = error.error(400, "invalid_field");
    assert_eq!(error["field"], "Sec-WebSocket-Protocol");
    assert!(error["message"].as_str().unwrap().contains("relume.v1"), "{error}");
    let error = handshake_offering(&app, &id, &format!("?ticket={third}"), &[&offer(&third)]).await;
    assert_eq!(error.error(400, "invalid_field")["field"], "ticket");
    let twice = format!("relume.v1, relume.ticket.{third}, relume.ticket.x");
    assert_eq!(handshake_offering(&app, &id, "", &[&twice]).await.error(400, "invalid_field")["field"], "ticket");
    // None of those spent it: it was never checked.
    assert_eq!(handshake_offering(&app, &id, "", &[&offer(&third)]).await.status, StatusCode::SWITCHING_PROTOCOLS);
    handshake_offering(&app, &id, "", &["relume.v1, relume.ticket.nope"]).await.error(401, "unauthorized");
    // `relume.v1` alone carries no credential, and is still selected for the token holder.
    handshake_offering(&app, &id, "", &["relume.v1"]).await.error(401, "unauthorized");
    app.token = Some("s3cret".to_owned());
    let opened = handshake_offering(&app, &id, "", &["relume.v1"]).await;
    assert_eq!(opened.header("sec-websocket-protocol"), "relume.v1");
    assert_eq!(app.state.tickets.outstanding(), 0);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_expired_ticket_is_refused() {
    let mut app = App::start(|c| {
        c.token = Some("s3cret".to_owned());
        c.ticket_seconds = 1;
    })
    .await;
    let id = app.create(&inline_scene()).await;
    let reply = app.request(Method::POST, "/v1/tickets", Bytes::new()).await;
    assert_eq!(reply.json()["expires_in_seconds"], 1);
    let expired = reply.json()["ticket"].as_str().expect("a ticket").to_owned();
    tokio::time::sleep(Duration::from_millis(1100)).await;
    app.token = None;
    handshake(&app, &id, &format!("?ticket={expired}")).await.error(401, "unauthorized");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_outstanding_tickets_are_bounded() {
    let mut app = App::start(|c| {
        c.token = Some("s3cret".to_owned());
        c.limits.max_tickets = 2;
    })
    .await;
    let id = app.create(&inline_scene()).await;
    let first = ticket(&app).await;
    ticket(&app).await;
    let refused = app.request(Method::POST, "/v1/tickets", Bytes::new()).await;
    assert_eq!(refused.error(503, "limit_exceeded")["limit"], "max_tickets");
    let retry: u32 = refused.header("retry-after").parse().expect("Retry-After in seconds");
    assert!((1..=30).contains(&retry), "Retry-After {retry}");
    assert_eq!(app.state.tickets.outstanding(), 2);
    // A used ticket frees its place.
    app.token = None;
    assert_eq!(handshake(&app, &id, &format!("?ticket={first}")).await.status, StatusCode::SWITCHING_PROTOCOLS);
    app.token = Some("s3cret".to_owned());
    ticket(&app).await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn without_a_token_tickets_are_issued_and_checked_when_given() {
    let app = App::start(|_| {}).await;
    let id = app.create(&inline_scene()).await;
    let ticket = ticket(&app).await;
    assert_eq!(handshake(&app, &id, "").await.status, StatusCode::SWITCHING_PROTOCOLS);
    assert_eq!(handshake(&app, &id, &format!("?ticket={ticket}")).await.status, StatusCode::SWITCHING_PROTOCOLS);
    handshake(&app, &id, &format!("?ticket={ticket}")).await.error(401, "unauthorized");
    app.stop().await;
}

/// A whole glTF scene (a top-level `gltf` field) is admitted like a mesh file: its
/// path confined to the asset directory, its size under `max_mesh_bytes`, its fields and the
/// file's own errors answered with 400 JSON naming the field.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_whole_gltf_scene_is_admitted_like_a_mesh_file() {
    let app = App::start(|c| c.limits.max_mesh_bytes = 4096).await;
    let scene = |gltf: &str| {
        json!({"gltf": gltf, "sparse_points": 64, "width": 16, "height": 16,
                                     "skip_groups": ["light"], "settings": {"tuning": {"rsm_resolution": 16}}})
    };
    for path in ["../Cargo.toml", "/etc/passwd", "meshes/../../src/lib.rs"] {
        let error = app.post("/v1/scenes", &scene(path)).await.error(400, "path_outside_assets");
        assert_eq!(error["field"], "gltf");
        assert!(!error["message"].as_str().unwrap().contains(&fixture("").display().to_string()), "{error}");
    }
    let error = app.post("/v1/scenes", &scene("meshes/missing.glb")).await.error(400, "invalid_scene");
    assert_eq!(error["field"], "gltf");
    // The .glb is 7,684 bytes, over this server's 4,096.
    let error = app.post("/v1/scenes", &scene("meshes/cornell_box_gltf/CornellBox-Original.glb")).await;
    let error = error.error(413, "limit_exceeded");
    assert_eq!((error["limit"].as_str(), error["field"].as_str()), (Some("max_mesh_bytes"), Some("gltf")));

    // The .gltf (its JSON 8,631 bytes) is over it too; with room for it, a typo and a bad value
    // are named, and the scene loads.
    let app = App::start(|_| {}).await;
    let gltf = "meshes/cornell_box_gltf/CornellBox-Original.glb";
    let mut typo = scene(gltf);
    typo["sparse_point"] = json!(8);
    let error = app.post("/v1/scenes", &typo).await.error(400, "invalid_json");
    assert!(error["message"].as_str().unwrap().contains("sparse_point"), "{error}");
    let mut unknown = scene(gltf);
    unknown["skip_groups"] = json!(["lamp"]);
    let error = app.post("/v1/scenes", &unknown).await.error(400, "invalid_scene");
    assert_eq!(error["field"], "skip_groups[0]", "the field as sent, not the mesh it stands for");
    assert!(error["message"].as_str().unwrap().starts_with("skip_groups[0]: "), "{error}");
    assert!(error["message"].as_str().unwrap().contains("lamp"), "{error}");
    let mut zero = scene(gltf);
    zero["sparse_points"] = json!(0);
    assert_eq!(app.post("/v1/scenes", &zero).await.error(400, "invalid_field")["field"], "sparse_points");
    let mut wide = scene(gltf);
    wide["height"] = json!(9000);
    assert_eq!(app.post("/v1/scenes", &wide).await.error(400, "invalid_field")["field"], "height");
    wide["height"] = json!(5000);
    wide["width"] = json!(5000);
    let error = app.post("/v1/scenes", &wide).await.error(400, "limit_exceeded");
    assert_eq!((error["limit"].as_str(), error["field"].as_str()), (Some("max_frame_side"), Some("width")));
    let id = app.create(&scene(gltf)).await;
    let info = app.get(&format!("/v1/scenes/{id}")).await.json();
    assert_eq!(info["sparse_points"], 64);
    assert_eq!(info["camera"]["width"], 16);
    app.stop().await;
}

/// `GET /v1/scenes/{id}` returns the resolved configuration (level, technique, analysis, and a
/// reason per parameter); a research knob in its old place is a 400 naming the key and where it
/// moved.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn scenes_report_their_resolved_configuration() {
    let app = App::start(|_| {}).await;
    let mut scene = inline_scene();
    scene["settings"] = json!({"quality": "fast", "budget_ms": 50, "tuning": {"interpolation_neighbours": 6}});
    let id = app.create(&scene).await;
    let info = app.get(&format!("/v1/scenes/{id}")).await.json();
    let resolved = &info["resolved"];
    assert_eq!((resolved["quality"].as_str(), resolved["method"].as_str()), (Some("fast"), Some("sparse")));
    assert_eq!(resolved["budget_ms"].as_f64(), Some(50.0));
    assert_eq!(resolved["analysis"]["meshes"].as_u64(), Some(1));
    let choices = resolved["choices"].as_array().expect("choices");
    let of = |parameter: &str| choices.iter().find(|c| c["parameter"] == parameter).cloned();
    assert_eq!(of("rsm_resolution").expect("the level's")["value"], "64");
    let tuned = of("tuning.interpolation_neighbours").expect("the file's");
    assert_eq!(tuned["value"], "6");
    assert!(tuned["reason"].as_str().unwrap().starts_with("set in the scene file"), "{tuned}");
    assert!(choices.iter().all(|c| !c["reason"].as_str().unwrap_or_default().is_empty()), "{resolved}");

    let mut old = inline_scene();
    old["settings"] = json!({"rsm_resolution": 64});
    let error = app.post("/v1/scenes", &old).await.error(400, "invalid_json");
    assert_eq!(error["field"], "settings.rsm_resolution");
    let message = error["message"].as_str().unwrap();
    assert!(message.contains("moved to settings.tuning.rsm_resolution"), "{message}");
    app.stop().await;
}

//! Scaling out: several GPU workers in one process (`--adapters 2`: two lavapipe devices on its
//! one adapter), the scene store shared by backends (`--scene-store`), stream tickets good on
//! every backend sharing the store and the ticket key (`--ticket-key-file`), and `/readyz` with
//! the drain.

use std::time::Duration;

use hyper::StatusCode;
use relume::service::client::Connection;
use relume::service::config::AdapterSelection;
use relume::service::tickets::TicketKey;
use relume::service::wire::proto::envelope::Body;
use relume::service::{Config, GpuWorker, Server, WorkerError, Workers};
use serde_json::{Value, json};

use super::fake_backend::FakeBackend;
use super::service::{TestServer, envelope, frame, inline_scene};

/// A series of `/metrics` with this name and `worker` label.
fn worker_value(text: &str, name: &str, worker: usize) -> f64 {
    let prefix = format!("{name}{{worker=\"{worker}\"}} ");
    let line = text.lines().find_map(|l| l.strip_prefix(&prefix)).unwrap_or_else(|| panic!("{prefix} in\n{text}"));
    line.parse().expect("a number")
}

async fn metrics(server: &TestServer) -> String {
    String::from_utf8(server.get("/metrics").await.body.to_vec()).expect("UTF-8")
}

/// Frames each of the two workers has rendered.
async fn frames(server: &TestServer) -> [f64; 2] {
    let text = metrics(server).await;
    [0, 1].map(|w| worker_value(&text, "relume_worker_frames_total", w))
}

/// The inline scene in another colour (a different scene, so it may land on another worker).
fn other_scene() -> Value {
    let mut scene = inline_scene();
    scene["meshes"][0]["material"]["diffuse"] = json!([0.2, 0.4, 0.8]);
    scene
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_devices_share_the_renders_pin_streams_and_take_over_a_lost_device() {
    let server = TestServer::start(|config| config.adapters = AdapterSelection::Count(2)).await;
    assert_eq!(server.state.workers.len(), 2);
    let ready = server.get("/readyz").await;
    assert_eq!(ready.status, StatusCode::OK);
    assert_eq!((ready.json()["status"].as_str(), ready.json()["workers_up"].as_u64()), (Some("ready"), Some(2)));

    // Two scenes go to the two workers (the idle one with fewer scenes), and each one's
    // renders to the worker holding it: renders land on both.
    let a = server.create(&inline_scene()).await;
    let b = server.create(&other_scene()).await;
    let holder = |id: &str| (0..2).find(|&w| server.state.workers.get(w).expect("worker").holds(id));
    let (wa, wb) = (holder(&a).expect("a held"), holder(&b).expect("b held"));
    assert_ne!(wa, wb, "the second scene goes to the other worker");
    let render = |id: &str| {
        let path = format!("/v1/scenes/{id}/render");
        let server = &server;
        async move { server.request(hyper::Method::POST, &path, "{}").await }
    };
    let image_a = render(&a).await;
    assert_eq!(image_a.status, StatusCode::OK);
    assert_eq!(render(&b).await.status, StatusCode::OK);
    let after_renders = frames(&server).await;
    assert_eq!((after_renders[wa], after_renders[wb]), (1.0, 1.0), "one render on each worker");

    // A stream of `a` is pinned to `a`'s worker: its frames all render there. The session
    // (and its pin) starts on the server after the handshake's answer has reached the client,
    // so the gauge is read until it shows the pin (a busy machine once read it before).
    let mut ws = server.stream(&a).await;
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
    while worker_value(&metrics(&server).await, "relume_worker_streams", wa) == 0.0
        && std::time::Instant::now() < deadline
    {
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
    assert_eq!(worker_value(&metrics(&server).await, "relume_worker_streams", wa), 1.0);
    for id in 1..=3 {
        let answer = ws.exchange(envelope(Body::RgbdFrame(frame(id, 8, 8)))).await;
        assert!(matches!(answer, Body::RenderedFrame(_)), "{answer:?}");
    }
    let after_stream = frames(&server).await;
    assert_eq!((after_stream[wa], after_stream[wb]), (after_renders[wa] + 3.0, after_renders[wb]));

    // `a`'s worker loses its device under the next render: the render is run again on the
    // other worker, which uploads the scene and answers the same image.
    server.state.workers.get(wa).expect("worker").lose_device().expect("the hook is queued");
    let moved = render(&a).await;
    assert_eq!(moved.status, StatusCode::OK, "{}", String::from_utf8_lossy(&moved.body));
    assert_eq!(moved.body, image_a.body, "the same image from the other device");
    let text = metrics(&server).await;
    assert_eq!(worker_value(&text, "relume_worker_up", wa), 0.0);
    assert_eq!(worker_value(&text, "relume_worker_device_losses_total", wa), 1.0);
    assert_eq!(worker_value(&text, "relume_worker_scenes", wb), 2.0, "a uploaded to the other worker");
    assert_eq!(server.get("/readyz").await.json()["workers_up"], 1);

    // New work goes to the worker that is up: renders of `a`, and the stream, which moves.
    let before = frames(&server).await;
    assert_eq!(render(&a).await.status, StatusCode::OK);
    let answer = ws.exchange(envelope(Body::RgbdFrame(frame(4, 8, 8)))).await;
    assert!(matches!(answer, Body::RenderedFrame(_)), "{answer:?}");
    let after = frames(&server).await;
    assert_eq!((after[wa], after[wb]), (before[wa], before[wb] + 2.0), "both on the worker that is up");
    let text = metrics(&server).await;
    assert_eq!(worker_value(&text, "relume_worker_streams", wb), 1.0, "the stream moved");
    assert_eq!(worker_value(&text, "relume_worker_streams", wa), 0.0);

    // Deleting a scene removes it from every worker.
    assert_eq!(
        server.request(hyper::Method::DELETE, &format!("/v1/scenes/{a}"), "").await.status,
        StatusCode::NO_CONTENT
    );
    assert!((0..2).all(|w| !server.state.workers.get(w).expect("worker").holds(&a)));
    drop(ws);
    server.stop().await;
}

/// `workers` fake GPU workers (no GPU), each render taking `render_time`.
fn fake_workers(
    config: &Config,
    workers: usize,
    render_time: Duration,
) -> impl FnOnce(std::sync::Arc<relume::service::Metrics>) -> Result<Workers, WorkerError> + Send + 'static {
    let limits = config.limits;
    let quarantine = Duration::from_secs(config.worker_quarantine_seconds);
    move |metrics| {
        let workers = (0..workers)
            .map(|i| GpuWorker::start_numbered(i, move || Ok(FakeBackend::new(render_time)), &limits, metrics.clone()))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Workers::new(workers, quarantine))
    }
}

/// A server on `workers` fake workers, with `edit` applied.
async fn fake_server(workers: usize, render_time: Duration, edit: impl FnOnce(&mut Config)) -> TestServer {
    TestServer::start_with(edit, move |config| {
        let start = fake_workers(&config, workers, render_time);
        Box::pin(Server::bind_workers(config, start))
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_scene_outlives_its_backend_through_the_shared_store() {
    let store = super::scratch("workers-scene-store");
    let _ = std::fs::remove_dir_all(&store);
    let with_store = |config: &mut Config| config.scene_store = Some(store.clone());
    let first = fake_server(1, Duration::ZERO, with_store).await;
    let second = fake_server(1, Duration::ZERO, with_store).await;
    let id = first.create(&inline_scene()).await;
    assert!(store.join(format!("{id}.json")).is_file());
    // The second backend never saw the scene: it loads it from the store under the same id.
    let info = second.get(&format!("/v1/scenes/{id}")).await;
    assert_eq!(info.status, StatusCode::OK);
    assert_eq!(info.json()["id"], id.as_str());
    first.stop().await;
    let rendered = second.post(&format!("/v1/scenes/{id}/render"), &json!({})).await;
    assert_eq!(rendered.status, StatusCode::OK, "renderable after the first backend stopped");
    // A third backend started later takes a stream of it.
    let third = fake_server(1, Duration::ZERO, with_store).await;
    let mut ws = third.stream(&id).await;
    assert!(matches!(ws.exchange(envelope(Body::RgbdFrame(frame(1, 8, 8)))).await, Body::RenderedFrame(_)));
    drop(ws);
    // Deleted through one backend, it is gone from the others too.
    assert_eq!(
        third.request(hyper::Method::DELETE, &format!("/v1/scenes/{id}"), "").await.status,
        StatusCode::NO_CONTENT
    );
    second.get(&format!("/v1/scenes/{id}")).await.error(404, "not_found");
    second.post(&format!("/v1/scenes/{id}/render"), &json!({})).await.error(404, "not_found");
    // Ids not of a scene's form never reach the file system.
    second.get("/v1/scenes/..%2F..%2Fetc%2Fpasswd").await.error(404, "not_found");
    second.stop().await;
    third.stop().await;
}

/// The status of a browser-style stream handshake (no `Authorization`) with `?ticket=`: 101
/// when it opened (the stream is then dropped), else the refusal's.
async fn open_with_ticket(server: &TestServer, id: &str, ticket: &str) -> StatusCode {
    let url = format!("ws://{}/v1/scenes/{id}/stream?ticket={ticket}", server.addr);
    match tokio_tungstenite::connect_async(&url).await {
        Ok((_, response)) => response.status(),
        Err(tokio_tungstenite::tungstenite::Error::Http(response)) => response.status(),
        Err(other) => panic!("the handshake failed: {other}"),
    }
}

/// A ticket from `POST /v1/tickets` on `server`.
async fn issue(server: &TestServer) -> String {
    let reply = server.request(hyper::Method::POST, "/v1/tickets", "").await;
    assert_eq!(reply.status, StatusCode::OK, "{}", reply.json());
    reply.json()["ticket"].as_str().expect("a ticket").to_owned()
}

/// Behind a balancer a ticket's request and its stream may land on different backends: with
/// the ticket key (`--ticket-key-file`) and the scene store shared, a ticket issued by one
/// opens a stream on the other, and only once, whichever backend sees it again. A backend with
/// another key file (the same token) or without the store refuses it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_ticket_from_one_backend_opens_one_stream_on_another_sharing_key_and_store() {
    let scratch = super::scratch("workers-tickets");
    let store = scratch.join("store");
    let key_file = |name: &str, secret: &str| {
        let path = scratch.join(name);
        std::fs::write(&path, format!("{secret}\n")).expect("key file written");
        TicketKey::from_file(&path).expect("a key")
    };
    let key = key_file("key", "the secret every backend of this deployment shares");
    let other_key = key_file("other-key", "a secret of another deployment, as long as that");
    let backend = |key: &TicketKey, store: Option<&std::path::PathBuf>| {
        let (key, store) = (key.clone(), store.cloned());
        move |config: &mut Config| {
            config.token = Some("s3cret".to_owned());
            config.ticket_key = Some(key);
            config.scene_store = store;
        }
    };
    let first = fake_server(1, Duration::ZERO, backend(&key, Some(&store))).await;
    let second = fake_server(1, Duration::ZERO, backend(&key, Some(&store))).await;
    let stranger = fake_server(1, Duration::ZERO, backend(&other_key, Some(&store))).await;
    let storeless = fake_server(1, Duration::ZERO, backend(&key, None)).await;
    let id = first.create(&inline_scene()).await;
    // Issued by the first, used on the second (which loads the scene from the store), then
    // refused on both, and on the others.
    let ticket = issue(&first).await;
    assert_eq!(open_with_ticket(&second, &id, &ticket).await, StatusCode::SWITCHING_PROTOCOLS);
    for server in [&second, &first, &stranger] {
        assert_eq!(open_with_ticket(server, &id, &ticket).await, StatusCode::UNAUTHORIZED);
    }
    // The other way round, and on its own issuer.
    let ticket = issue(&second).await;
    assert_eq!(open_with_ticket(&first, &id, &ticket).await, StatusCode::SWITCHING_PROTOCOLS);
    assert_eq!(open_with_ticket(&second, &id, &ticket).await, StatusCode::UNAUTHORIZED);
    let ticket = issue(&first).await;
    assert_eq!(open_with_ticket(&first, &id, &ticket).await, StatusCode::SWITCHING_PROTOCOLS);
    assert_eq!(open_with_ticket(&second, &id, &ticket).await, StatusCode::UNAUTHORIZED);
    // Another key refuses it (and spends nothing); so does a backend without the store, which
    // takes only its own tickets; the second still opens it.
    let ticket = issue(&first).await;
    assert_eq!(open_with_ticket(&stranger, &id, &ticket).await, StatusCode::UNAUTHORIZED);
    let stranger_ticket = issue(&stranger).await;
    assert_eq!(open_with_ticket(&first, &id, &stranger_ticket).await, StatusCode::UNAUTHORIZED);
    let storeless_id = storeless.create(&inline_scene()).await;
    assert_eq!(open_with_ticket(&storeless, &storeless_id, &ticket).await, StatusCode::UNAUTHORIZED);
    assert_eq!(open_with_ticket(&second, &id, &ticket).await, StatusCode::SWITCHING_PROTOCOLS);
    assert_eq!(std::fs::read_dir(store.join("tickets")).expect("the marks").count(), 4, "one per use");
    for server in [first, second, stranger, storeless] {
        server.stop().await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn readyz_says_saturated_while_every_queue_is_full() {
    let server = fake_server(2, Duration::from_millis(1000), |config| {
        config.limits.max_queue = 1;
        config.limits.max_client_queue = 1;
    })
    .await;
    let id = server.create(&inline_scene()).await;
    // Four renders 100 ms apart: the first runs on the scene's worker, the second waits there,
    // the third spills to the idle worker and the fourth waits there. Both queues are then
    // full, and no render was refused.
    let path = format!("/v1/scenes/{id}/render");
    let renders = futures_util::future::join_all((0..4).map(|i| {
        let (server, path) = (&server, &path);
        async move {
            tokio::time::sleep(Duration::from_millis(100 * i)).await;
            server.request(hyper::Method::POST, path, "{}").await
        }
    }));
    let saturated = async {
        loop {
            let ready = server.get("/readyz").await;
            if ready.status == StatusCode::SERVICE_UNAVAILABLE {
                return ready.json();
            }
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    };
    let (answers, body) = tokio::join!(renders, tokio::time::timeout(Duration::from_secs(10), saturated));
    let body = body.expect("saturated within 10 s");
    assert_eq!(body["status"], "saturated", "{body}");
    assert!(answers.iter().all(|a| a.status == StatusCode::OK), "every render answered 200");
    let text = metrics(&server).await;
    assert_eq!([0, 1].map(|w| worker_value(&text, "relume_worker_frames_total", w)), [2.0, 2.0]);
    assert_eq!(server.get("/readyz").await.json()["status"], "ready", "ready again once the queues emptied");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn after_a_signal_readyz_says_draining_while_the_server_still_serves_then_it_stops() {
    let mut config = Config::new(std::net::SocketAddr::from(([127, 0, 0, 1], 0)), super::fixture(""));
    config.drain_delay_seconds = 2;
    let start = fake_workers(&config, 1, Duration::ZERO);
    let server = Server::bind_workers(config, start).await.expect("the server starts");
    let connection = Connection::new(&format!("http://{}", server.local_addr()), None).expect("client");
    let (signal, signalled) = tokio::sync::oneshot::channel::<()>();
    let running = tokio::spawn(server.run(async {
        let _ = signalled.await;
    }));
    let get = |path: &'static str| connection.request(hyper::Method::GET, path, bytes::Bytes::new());
    assert_eq!(get("/readyz").await.expect("answer").0, StatusCode::OK);
    let id = connection.create_scene(&inline_scene()).await.expect("created");
    let signalled_at = std::time::Instant::now();
    signal.send(()).expect("running");
    tokio::time::sleep(Duration::from_millis(100)).await;
    let (status, body) = get("/readyz").await.expect("answer while draining");
    assert_eq!(status, StatusCode::SERVICE_UNAVAILABLE);
    assert_eq!(serde_json::from_slice::<Value>(&body).expect("JSON")["status"], "draining");
    assert_eq!(get("/healthz").await.expect("answer").0, StatusCode::OK, "alive while draining");
    let path = format!("/v1/scenes/{id}/render");
    let (status, _) = connection.request(hyper::Method::POST, &path, bytes::Bytes::new()).await.expect("answer");
    assert_eq!(status, StatusCode::OK, "still serving during the drain delay");
    tokio::time::timeout(Duration::from_secs(30), running).await.expect("stops").expect("task").expect("clean");
    assert!(signalled_at.elapsed() >= Duration::from_secs(2), "not before the drain delay");
}

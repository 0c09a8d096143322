//! What one client can make `relume serve` hold or do, bounded: each test
//! drives a real server on a loopback port, as a hostile or careless client would, and fails
//! without the bound it checks. The GPU thread runs a fake backend (it sleeps a fixed time per
//! render and answers grey images), so scheduling and limits are tested without a GPU and
//! with known render times; scenes are still parsed and loaded for real.

use std::net::{IpAddr, SocketAddr};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use bytes::Bytes;
use futures_util::{SinkExt, StreamExt};
use http_body_util::{BodyExt, Full};
use hyper::{Method, StatusCode};
use hyper_util::client::legacy::Client;
use hyper_util::client::legacy::connect::HttpConnector;
use relume::service::{Config, GpuWorker, Server};
use serde_json::{Value, json};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite;

use super::fake_backend::FakeBackend;
use super::service::{Reply, TestServer, inline_scene};

/// A server on the fake backend, renders taking `render_ms`.
pub(super) async fn fake_server(render_ms: u64, edit: impl FnOnce(&mut Config)) -> TestServer {
    TestServer::start_with(edit, move |config| {
        Box::pin(async move {
            let limits = config.limits;
            let render_time = Duration::from_millis(render_ms);
            Server::bind_with(config, move |metrics| {
                GpuWorker::start_with(move || Ok(FakeBackend::new(render_time)), &limits, metrics)
            })
            .await
        })
    })
    .await
}

/// An HTTP client whose connections come from `source` (another loopback address is another
/// client to the server's fair queue).
fn client_from(source: IpAddr) -> Client<HttpConnector, Full<Bytes>> {
    let mut connector = HttpConnector::new();
    connector.set_local_address(Some(source));
    Client::builder(hyper_util::rt::TokioExecutor::new()).build(connector)
}

async fn post_from(client: &Client<HttpConnector, Full<Bytes>>, addr: SocketAddr, path: &str, body: &Value) -> Reply {
    let request = hyper::Request::post(format!("http://{addr}{path}"))
        .body(Full::new(Bytes::from(body.to_string())))
        .expect("request");
    let response = client.request(request).await.expect("the server answers");
    let (parts, body) = response.into_parts();
    Reply { status: parts.status, headers: parts.headers, body: body.collect().await.expect("body").to_bytes() }
}

/// The `queue` entry of a `Server-Timing` header, s.
fn queue_seconds(reply: &Reply) -> f64 {
    let timing = reply.header("server-timing");
    let queue = timing.split(", ").find_map(|t| t.strip_prefix("queue;dur=")).expect("a queue time");
    queue.parse::<f64>().expect("ms") / 1e3
}

/// Opens `path` as a WebSocket by hand (so that frames can be written raw); the 101 is read.
async fn raw_websocket(addr: SocketAddr, path: &str) -> TcpStream {
    let mut stream = TcpStream::connect(addr).await.expect("connects");
    let request = format!(
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
    );
    stream.write_all(request.as_bytes()).await.expect("sent");
    let mut head = Vec::new();
    while !head.ends_with(b"\r\n\r\n") {
        let mut byte = [0u8];
        stream.read_exact(&mut byte).await.expect("the handshake answer");
        head.push(byte[0]);
    }
    let head = String::from_utf8_lossy(&head);
    assert!(head.starts_with("HTTP/1.1 101"), "{head}");
    stream
}

/// Reads server frames (unmasked) until a Close, within `within`: its code, or `None` when
/// the connection ends without one. Pings are counted into `pings`.
async fn close_code(stream: &mut TcpStream, within: Duration, pings: &mut usize) -> Option<u16> {
    let read = async {
        loop {
            let mut header = [0u8; 2];
            stream.read_exact(&mut header).await.ok()?;
            let length = match header[1] & 0x7f {
                126 => stream.read_u16().await.ok()? as u64,
                127 => stream.read_u64().await.ok()?,
                n => n as u64,
            };
            let mut payload = vec![0u8; length as usize];
            stream.read_exact(&mut payload).await.ok()?;
            match header[0] & 0x0f {
                0x8 => return Some(u16::from_be_bytes([payload[0], payload[1]])),
                0x9 => *pings += 1,
                _ => {}
            }
        }
    };
    tokio::time::timeout(within, read).await.expect("the server ends the stream in time")
}

/// Whether the server closes `stream` (end of file or reset) within `within`; what it sent
/// before is returned.
async fn closed_within(stream: &mut TcpStream, within: Duration) -> Option<Vec<u8>> {
    let mut received = Vec::new();
    let read = async {
        let mut buffer = [0u8; 4096];
        loop {
            match stream.read(&mut buffer).await {
                Ok(0) | Err(_) => return,
                Ok(n) => received.extend_from_slice(&buffer[..n]),
            }
        }
    };
    tokio::time::timeout(within, read).await.ok().map(|()| received)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn invented_methods_do_not_grow_the_metrics() {
    let mut server = fake_server(0, |c| c.token = Some("s3cret".to_owned())).await;
    server.token = None;
    let before = server.get("/metrics").await.body.len();
    for i in 0..300 {
        let method = Method::from_bytes(format!("X{i:03}{}", "M".repeat(2000)).as_bytes()).expect("a method");
        server.request(method, "/healthz", Bytes::new()).await.error(405, "method_not_allowed");
    }
    let text = String::from_utf8(server.get("/metrics").await.body.to_vec()).expect("UTF-8");
    let other: u64 = text
        .lines()
        .filter(|l| l.starts_with("relume_http_requests_total{") && l.contains("method=\"other\""))
        .map(|l| l.rsplit(' ').next().and_then(|n| n.parse::<u64>().ok()).expect("a count"))
        .sum();
    assert_eq!(other, 300, "{text}");
    assert!(!text.contains("MMMM"));
    // The 300 requests add one series per histogram and counter, not one per method.
    assert!(text.len() < before + 4096, "/metrics grew from {before} to {} bytes", text.len());
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stream_message_over_the_transport_limit_is_closed_with_1009() {
    let server = fake_server(0, |c| c.limits.max_message_bytes = 64 << 10).await;
    let id = server.create(&inline_scene()).await;
    let mut stream = raw_websocket(server.addr, &format!("/v1/scenes/{id}/stream")).await;
    // A binary frame announcing 100 MB (masked, as clients must), then the first 1 KiB of it.
    let mut frame = vec![0x82, 0xff];
    frame.extend_from_slice(&100_000_000u64.to_be_bytes());
    frame.extend_from_slice(&[1, 2, 3, 4]);
    frame.extend_from_slice(&[0u8; 1024]);
    stream.write_all(&frame).await.expect("sent");
    let mut pings = 0;
    assert_eq!(close_code(&mut stream, Duration::from_secs(10), &mut pings).await, Some(1009));
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn open_streams_are_capped_before_the_upgrade() {
    let server = fake_server(0, |c| c.limits.max_streams = 2).await;
    let id = server.create(&inline_scene()).await;
    let url = format!("ws://{}/v1/scenes/{id}/stream", server.addr);
    let (first, _) = tokio_tungstenite::connect_async(&url).await.expect("the first stream opens");
    let (_second, _) = tokio_tungstenite::connect_async(&url).await.expect("the second stream opens");
    match tokio_tungstenite::connect_async(&url).await {
        Err(tungstenite::Error::Http(response)) => {
            assert_eq!(response.status(), StatusCode::SERVICE_UNAVAILABLE);
            let body: Value = serde_json::from_slice(response.body().as_deref().expect("a body")).expect("JSON");
            assert_eq!(
                (body["error"]["code"].as_str(), body["error"]["limit"].as_str()),
                (Some("limit_exceeded"), Some("max_streams"))
            );
        }
        other => panic!("expected 503, got {other:?}"),
    }
    drop(first);
    // The closed stream's slot comes back once the server has seen it go.
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        match tokio_tungstenite::connect_async(&url).await {
            Ok(_) => break,
            Err(error) => assert!(Instant::now() < deadline, "no slot freed: {error}"),
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_ticket_opens_one_real_stream_on_a_server_with_a_token() {
    let server = fake_server(0, |c| c.token = Some("s3cret".to_owned())).await;
    let id = server.create(&inline_scene()).await;
    let reply = server.request(Method::POST, "/v1/tickets", Bytes::new()).await;
    assert_eq!(reply.status, StatusCode::OK, "{}", reply.json());
    let ticket = reply.json()["ticket"].as_str().expect("a ticket").to_owned();
    let refused = |result: Result<_, tungstenite::Error>| match result {
        Err(tungstenite::Error::Http(response)) => {
            assert_eq!(response.status(), StatusCode::UNAUTHORIZED);
            let body: Value = serde_json::from_slice(response.body().as_deref().expect("a body")).expect("JSON");
            assert_eq!(body["error"]["code"], "unauthorized", "{body}");
        }
        Err(other) => panic!("expected 401, got {other}"),
        Ok(_) => panic!("expected 401, the stream opened"),
    };
    // A browser's handshake: no Authorization header.
    let url = format!("ws://{}/v1/scenes/{id}/stream", server.addr);
    refused(tokio_tungstenite::connect_async(&url).await);
    let with_ticket = format!("{url}?ticket={ticket}");
    let (mut stream, response) = tokio_tungstenite::connect_async(&with_ticket).await.expect("the ticket opens it");
    assert_eq!(response.status(), StatusCode::SWITCHING_PROTOCOLS);
    // The stream is live: a message that is not an Envelope gets an answer, not a close.
    stream.send(tungstenite::Message::binary(vec![0xff, 0xff, 0xff])).await.expect("sent");
    let answer = tokio::time::timeout(Duration::from_secs(10), stream.next()).await.expect("an answer in time");
    assert!(matches!(answer, Some(Ok(tungstenite::Message::Binary(_)))), "{answer:?}");
    refused(tokio_tungstenite::connect_async(&with_ticket).await);
    drop(stream);

    // The ticket as a subprotocol, out of the URL, as the viewer sends it; the client (which
    // checks that the selected protocol is one it offered) gets `relume.v1`.
    let reply = server.request(Method::POST, "/v1/tickets", Bytes::new()).await;
    let ticket = reply.json()["ticket"].as_str().expect("a ticket").to_owned();
    let offering = || {
        use tungstenite::client::IntoClientRequest as _;
        let mut request = url.as_str().into_client_request().expect("a request");
        let offer = format!("relume.v1, relume.ticket.{ticket}").parse().expect("a header value");
        request.headers_mut().insert("sec-websocket-protocol", offer);
        request
    };
    let (mut stream, response) = tokio_tungstenite::connect_async(offering()).await.expect("the ticket opens it");
    assert_eq!(response.headers()["sec-websocket-protocol"], "relume.v1");
    stream.send(tungstenite::Message::binary(vec![0xff, 0xff, 0xff])).await.expect("sent");
    let answer = tokio::time::timeout(Duration::from_secs(10), stream.next()).await.expect("an answer in time");
    assert!(matches!(answer, Some(Ok(tungstenite::Message::Binary(_)))), "{answer:?}");
    refused(tokio_tungstenite::connect_async(offering()).await);
    drop(stream);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn slow_silent_and_idle_connections_are_closed() {
    let server = fake_server(0, |c| {
        c.timeouts.header_timeout_seconds = 1;
        c.timeouts.body_timeout_seconds = 1;
        c.timeouts.stream_idle_seconds = 2;
        c.timeouts.stream_ping_seconds = 1;
        c.limits.max_connections = 6;
    })
    .await;
    let id = server.create(&inline_scene()).await;
    let addr = server.addr;
    // Each closed within the 1 s timeout plus scheduling slack (they stayed open for minutes).
    let within = Duration::from_secs(5);
    let half_headers = async {
        let mut s = TcpStream::connect(addr).await.expect("connects");
        s.write_all(b"GET /healthz HTTP/1.1\r\nHost: x\r\n").await.expect("sent");
        assert!(closed_within(&mut s, within).await.is_some(), "half-sent headers");
    };
    let silent = async {
        let mut s = TcpStream::connect(addr).await.expect("connects");
        assert!(closed_within(&mut s, within).await.is_some(), "a silent socket");
    };
    let keep_alive = async {
        let mut s = TcpStream::connect(addr).await.expect("connects");
        s.write_all(b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n").await.expect("sent");
        let received = closed_within(&mut s, within).await.expect("an idle keep-alive connection");
        assert!(received.starts_with(b"HTTP/1.1 200"), "{}", String::from_utf8_lossy(&received));
    };
    let slow_body = async {
        let mut s = TcpStream::connect(addr).await.expect("connects");
        s.write_all(b"POST /v1/scenes HTTP/1.1\r\nHost: x\r\nContent-Length: 100\r\n\r\n{\"mesh").await.expect("sent");
        let received = closed_within(&mut s, within).await.expect("a body that never ends");
        let text = String::from_utf8_lossy(&received);
        assert!(text.starts_with("HTTP/1.1 408") && text.contains("request_timeout"), "{text}");
    };
    tokio::join!(half_headers, silent, keep_alive, slow_body);

    // Six silent sockets hold every slot (with the test client's pooled connection, if the
    // server has not closed it yet, one of them is refused already): the next connection is
    // answered 503 at once...
    let mut held = Vec::new();
    for _ in 0..6 {
        held.push(TcpStream::connect(addr).await.expect("connects"));
    }
    tokio::time::sleep(Duration::from_millis(200)).await;
    let mut over = TcpStream::connect(addr).await.expect("connects");
    let refused = closed_within(&mut over, Duration::from_millis(500)).await.expect("refused at once");
    let text = String::from_utf8_lossy(&refused);
    assert!(text.starts_with("HTTP/1.1 503") && text.contains("max_connections"), "{text}");
    // ...and once the header timeout has closed them, /healthz answers again.
    tokio::time::sleep(Duration::from_millis(2500)).await;
    assert_eq!(server.get("/healthz").await.status, StatusCode::OK);

    // A stream whose client never answers the pings is closed (1001) after the idle timeout.
    let mut stream = raw_websocket(addr, &format!("/v1/scenes/{id}/stream")).await;
    let mut pings = 0;
    assert_eq!(close_code(&mut stream, within, &mut pings).await, Some(1001));
    // A client that reads answers the pings (tungstenite does) and stays connected.
    let url = format!("ws://{addr}/v1/scenes/{id}/stream");
    let (mut alive, _) = tokio_tungstenite::connect_async(&url).await.expect("opens");
    let until = tokio::time::Instant::now() + Duration::from_millis(3500);
    let mut seen_pings = 0;
    while let Ok(message) = tokio::time::timeout_at(until, alive.next()).await {
        match message.expect("still open").expect("a message") {
            tungstenite::Message::Ping(_) => seen_pings += 1,
            other => panic!("unexpected {other:?}"),
        }
    }
    assert!(seen_pings >= 2, "{seen_pings} pings in 3.5 s");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn one_triangle_repeated_loads_in_linear_time() {
    let server = fake_server(0, |_| {}).await;
    let mut scene = inline_scene();
    // 40k copies of one triangle: every edge is shared by 40k faces. Pairwise comparison of
    // the faces around an edge took 34 s in a release build; sorted by angle, well under one.
    scene["meshes"][0]["obj_text"] = json!(format!("v 0 0 0\nv 1 0 0\nv 0 1 0\n{}", "f 1 2 3\n".repeat(40_000)));
    let started = Instant::now();
    let reply = tokio::time::timeout(Duration::from_secs(30), server.post("/v1/scenes", &scene))
        .await
        .unwrap_or_else(|_| panic!("no answer after {:?}", started.elapsed()));
    assert_eq!(reply.status, StatusCode::CREATED, "{}", reply.json());
    assert_eq!(reply.json()["meshes"][0]["vertices"], 3, "one smooth sheet");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn work_per_scene_and_render_is_bounded_before_it_starts() {
    let server = fake_server(0, |c| c.limits.max_triangles = 1000).await;
    // 8 meshes x 65,536 sparse points: refused at once (it took 31 s and 500 MB to load).
    let mut big = inline_scene();
    let mut mesh = big["meshes"][0].clone();
    mesh["sparse_points"] = json!(65_536);
    big["meshes"] = Value::Array(vec![mesh; 8]);
    let started = Instant::now();
    let e = server.post("/v1/scenes", &big).await.error(400, "limit_exceeded");
    assert_eq!((e["limit"].as_str(), e["field"].as_str()), (Some("max_sparse_points"), Some("meshes")));
    assert!(started.elapsed() < Duration::from_secs(5), "checked before loading");
    // Adaptive candidates are points the scene holds: 25,000 points with `adaptive` 0.5 hold
    // 50,000 candidates more, over the 65,536 points of the limit.
    let mut adaptive = inline_scene();
    adaptive["meshes"][0]["sparse_points"] = json!(25_000);
    adaptive["settings"]["tuning"]["sparse"] = json!({"adaptive": 0.5});
    let e = server.post("/v1/scenes", &adaptive).await.error(400, "limit_exceeded");
    assert_eq!((e["limit"].as_str(), e["field"].as_str()), (Some("max_sparse_points"), Some("meshes")));
    let message = e["message"].as_str().unwrap();
    assert!(message.contains("75000 sparse points") && message.contains("50000 adaptive candidates"), "{message}");

    // Subdividing the room for 4096 sparse points would pass 1000 triangles.
    let mut dense = inline_scene();
    dense["meshes"][0]["sparse_points"] = json!(4096);
    let e = server.post("/v1/scenes", &dense).await.error(400, "limit_exceeded");
    assert_eq!((e["limit"].as_str(), e["field"].as_str()), (Some("max_triangles"), Some("meshes[0].sparse_points")));
    // An OBJ that has more triangles than the limit to begin with.
    let mut many = inline_scene();
    many["meshes"][0]["obj_text"] =
        json!(format!("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n{}", "f 1 2 3\nf 2 4 3\n".repeat(501)));
    let e = server.post("/v1/scenes", &many).await.error(400, "limit_exceeded");
    assert_eq!((e["limit"].as_str(), e["field"].as_str()), (Some("max_triangles"), Some("meshes[0].obj")));

    // Pixels: each side within max_frame_side (4096), the image over max_pixels (4 Mi).
    let id = server.create(&inline_scene()).await;
    let camera = json!({"position": [0, 1, 3], "target": [0, 0.5, 0], "fov_y_deg": 50, "width": 4096, "height": 2048});
    let e =
        server.post(&format!("/v1/scenes/{id}/render"), &json!({"camera": camera})).await.error(400, "limit_exceeded");
    assert_eq!((e["limit"].as_str(), e["field"].as_str()), (Some("max_pixels"), Some("camera")));
    let mut wide = inline_scene();
    wide["camera"] = camera;
    let e = server.post("/v1/scenes", &wide).await.error(400, "limit_exceeded");
    assert_eq!(e["limit"], "max_pixels");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_flood_from_one_client_does_not_starve_another() {
    const RENDER_MS: u64 = 500;
    let server = fake_server(RENDER_MS, |c| {
        c.limits.max_queue = 16;
        c.limits.max_client_queue = 2;
    })
    .await;
    let id = server.create(&inline_scene()).await;
    let (addr, path) = (server.addr, format!("/v1/scenes/{id}/render"));
    let normal = client_from("127.0.0.1".parse().expect("IP"));
    let timed_render = |client: &Client<HttpConnector, Full<Bytes>>| {
        let (client, path) = (client.clone(), path.clone());
        async move {
            let started = Instant::now();
            let reply = post_from(&client, addr, &path, &json!({})).await;
            (reply, started.elapsed().as_secs_f64())
        }
    };
    let mut solo = Vec::new();
    for _ in 0..3 {
        let (reply, seconds) = timed_render(&normal).await;
        assert_eq!(reply.status, StatusCode::OK);
        solo.push(seconds);
    }
    let solo_max = solo.iter().copied().fold(0.0, f64::max);

    // Twelve connections from another address render back to back, retrying at once on 503.
    let flooding = Arc::new(AtomicBool::new(true));
    let flooder = client_from("127.0.0.2".parse().expect("IP"));
    let floods: Vec<_> = (0..12)
        .map(|_| {
            let (flooding, flooder, path) = (flooding.clone(), flooder.clone(), path.clone());
            tokio::spawn(async move {
                let (mut waits, mut retry_afters) = (Vec::new(), Vec::new());
                while flooding.load(Ordering::SeqCst) {
                    let reply = post_from(&flooder, addr, &path, &json!({})).await;
                    match reply.status {
                        StatusCode::OK => waits.push(queue_seconds(&reply)),
                        StatusCode::SERVICE_UNAVAILABLE => {
                            assert_eq!(reply.error(503, "queue_full")["limit"], "max_client_queue");
                            retry_afters.push(reply.header("retry-after").parse::<f64>().expect("seconds"));
                            tokio::time::sleep(Duration::from_millis(20)).await;
                        }
                        other => panic!("flooder got {other}"),
                    }
                }
                (waits, retry_afters)
            })
        })
        .collect();
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let mut mixed = Vec::new();
    for _ in 0..6 {
        let (reply, seconds) = timed_render(&normal).await;
        assert_eq!(reply.status, StatusCode::OK, "the normal client was refused: {}", reply.json());
        mixed.push(seconds);
    }
    flooding.store(false, Ordering::SeqCst);
    let (mut waits, mut retry_afters) = (Vec::new(), Vec::new());
    for flood in floods {
        let (w, r) = flood.await.expect("a flooder");
        waits.extend(w);
        retry_afters.extend(r);
    }
    // Fair queueing: the normal client's render waits for at most the flooder's render already
    // on the GPU, so it takes at most about twice its solo time; 3x leaves room for scheduling.
    let mixed_max = mixed.iter().copied().fold(0.0, f64::max);
    assert!(mixed_max <= 3.0 * solo_max, "solo max {solo_max:.2} s, under the flood max {mixed_max:.2} s");
    // Retry-After is the flooder's measured queue wait (rounded up), not a constant.
    waits.sort_by(f64::total_cmp);
    let median_wait = waits[waits.len() / 2];
    assert!(!retry_afters.is_empty());
    let last_retry_after = *retry_afters.last().expect("a refusal");
    assert!(
        last_retry_after >= median_wait.floor().max(1.0) && last_retry_after <= median_wait.ceil() + 2.0,
        "Retry-After {last_retry_after} s, median queue wait {median_wait:.2} s"
    );
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_lost_device_is_recreated_and_its_scenes_re_uploaded() {
    // The real GPU backend (lavapipe in CI).
    let server = TestServer::start_with(|_| {}, |config| Box::pin(Server::bind(config))).await;
    let id = server.create(&inline_scene()).await;
    let path = format!("/v1/scenes/{id}/render");
    let before = server.post(&path, &json!({})).await;
    assert_eq!(before.status, StatusCode::OK);
    // The device is destroyed under the next render: that render is answered 503...
    server.state.workers.lose_device().expect("the hook is queued");
    let lost = server.post(&path, &json!({})).await;
    lost.error(503, "device_lost");
    assert_eq!(lost.header("retry-after"), "1");
    // ...and the next one renders the scene, re-uploaded to a new device, as before.
    let after = server.post(&path, &json!({})).await;
    assert_eq!(after.status, StatusCode::OK, "{}", String::from_utf8_lossy(&after.body));
    assert_eq!(after.body, before.body, "the same image from the new device");
    server.stop().await;
}

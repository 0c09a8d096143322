//! What `relume serve` gives back and how it answers clients that misbehave at the HTTP
//! level: memory of deleted scenes, renders whose clients have gone, the HTTP layer's own
//! refusals (as JSON, like every other error), bodies refused from their `Content-Length`,
//! and empty stream messages. Each test drives a real server on a loopback port and fails
//! without the fix it guards.

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use bytes::Bytes;
use futures_util::SinkExt;
use hyper::{Method, StatusCode};
use relume::service::wire::ErrorCode;
use relume::service::wire::proto::envelope::Body;
use serde_json::{Value, json};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite;

use super::hardening::fake_server;
use super::service::{TestServer, envelope, fixture_scene, frame, inline_scene};

/// An answer read off a raw socket.
struct RawAnswer {
    status: u16,
    /// The head, lower-cased.
    head: String,
    body: Vec<u8>,
    /// From the end of the request to the end of the answer.
    took: Duration,
}

impl RawAnswer {
    /// Asserts a JSON error of this status, code and (when given) limit.
    #[track_caller]
    fn error(&self, status: u16, code: &str, limit: Option<&str>) {
        let text = String::from_utf8_lossy(&self.body);
        assert_eq!(self.status, status, "{}{text}", self.head);
        assert!(self.head.contains("content-type: application/json\r\n"), "{}", self.head);
        let body: Value = serde_json::from_slice(&self.body).unwrap_or_else(|e| panic!("not JSON ({e}): {text}"));
        assert_eq!(body["error"]["code"], code, "{body}");
        assert!(body["error"]["message"].as_str().is_some_and(|m| !m.is_empty()), "{body}");
        assert_eq!(body["error"]["limit"].as_str(), limit, "{body}");
    }
}

/// Sends `request` on a new connection (writing on while reading, ignoring a write the server
/// cuts short) and reads one answer: its head, then `content-length` bytes of body.
async fn exchange(addr: SocketAddr, request: Vec<u8>) -> RawAnswer {
    let stream = TcpStream::connect(addr).await.expect("connects");
    let (mut reader, mut writer) = stream.into_split();
    let sent = Instant::now();
    let writing = tokio::spawn(async move {
        let _ = writer.write_all(&request).await;
        writer
    });
    let read = async {
        let mut received = Vec::new();
        let mut buffer = [0u8; 4096];
        loop {
            if let Some(end) = received.windows(4).position(|w| w == b"\r\n\r\n") {
                let head = String::from_utf8_lossy(&received[..end + 4]).to_ascii_lowercase();
                let length = head
                    .lines()
                    .find_map(|l| l.strip_prefix("content-length: "))
                    .and_then(|n| n.trim().parse::<usize>().ok())
                    .unwrap_or(0);
                if received.len() >= end + 4 + length {
                    return (head, received[end + 4..end + 4 + length].to_vec());
                }
            }
            match reader.read(&mut buffer).await {
                Ok(0) | Err(_) => {
                    panic!("the connection ended before a whole answer: {}", String::from_utf8_lossy(&received))
                }
                Ok(n) => received.extend_from_slice(&buffer[..n]),
            }
        }
    };
    let (head, body) = tokio::time::timeout(Duration::from_secs(40), read).await.expect("an answer within 40 s");
    let took = sent.elapsed();
    writing.abort();
    let status = head.split(' ').nth(1).and_then(|s| s.parse().ok()).expect("a status line");
    RawAnswer { status, head, body, took }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_http_layers_own_refusals_are_json() {
    let server = fake_server(0, |c| c.limits.max_body_bytes = 1 << 20).await;
    let addr = server.addr;
    // A 100 kB scene id, and a 100 kB ticket: the request line alone is over max_header_bytes.
    let long_id = format!("GET /v1/scenes/{} HTTP/1.1\r\nHost: x\r\n\r\n", "a".repeat(100_000));
    exchange(addr, long_id.into_bytes()).await.error(431, "limit_exceeded", Some("max_header_bytes"));
    let long_ticket = format!("GET /v1/scenes/s/stream?ticket={} HTTP/1.1\r\nHost: x\r\n\r\n", "t".repeat(100_000));
    exchange(addr, long_ticket.into_bytes()).await.error(431, "limit_exceeded", Some("max_header_bytes"));
    // 500 short headers: within the bytes, over the count.
    let headers: String = (0..500).map(|i| format!("x-h{i}: v\r\n")).collect();
    let many = format!("GET /healthz HTTP/1.1\r\nHost: x\r\n{headers}\r\n");
    exchange(addr, many.into_bytes()).await.error(431, "limit_exceeded", Some("max_headers"));
    // A 1 MB Authorization header.
    let big = format!("GET /v1/scenes/x HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {}\r\n\r\n", "k".repeat(1 << 20));
    exchange(addr, big.into_bytes()).await.error(431, "limit_exceeded", Some("max_header_bytes"));
    // A negative Content-Length, and a TLS ClientHello where a request line belongs.
    let negative = b"POST /v1/scenes HTTP/1.1\r\nHost: x\r\nContent-Length: -5\r\n\r\n".to_vec();
    exchange(addr, negative).await.error(400, "bad_request", None);
    let client_hello = vec![0x16, 0x03, 0x01, 0x02, 0x00, 0x01, 0x00, 0x01, 0xfc, 0x03, 0x03, 0x5a, 0x5a, 0x5a, 0x5a];
    exchange(addr, client_hello).await.error(400, "bad_request", None);
    // Well-formed requests on the same server are answered as before.
    let healthz = exchange(addr, b"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n".to_vec()).await;
    assert_eq!(healthz.status, 200, "{}", healthz.head);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_body_over_the_limit_is_refused_from_its_content_length_at_once() {
    let server = fake_server(0, |c| c.limits.max_body_bytes = 1 << 20).await;
    let id = server.create(&inline_scene()).await;
    let addr = server.addr;
    for path in ["/v1/scenes".to_owned(), format!("/v1/scenes/{id}/render"), "/v1/tickets".to_owned()] {
        for expect in ["Expect: 100-continue\r\n", ""] {
            let request =
                format!("POST {path} HTTP/1.1\r\nHost: x\r\n{expect}Content-Length: 10000000000\r\n\r\n").into_bytes();
            let answer = exchange(addr, request).await;
            answer.error(413, "limit_exceeded", Some("max_body_bytes"));
            // It waited for neither the body nor the body timeout (30 s), and did not ask for
            // the body it refuses.
            assert!(answer.took < Duration::from_secs(1), "{path} {expect:?}: {:?}", answer.took);
            assert!(!answer.head.contains("100 continue"), "{}", answer.head);
        }
    }
    // Within the limit, the body is still read (and checked while read).
    let reply = server.post("/v1/scenes", &inline_scene()).await;
    assert_eq!(reply.status, StatusCode::CREATED);
    server.stop().await;
}

/// The count of frames the GPU thread has rendered, from `/metrics`.
async fn frames_rendered(server: &TestServer) -> u64 {
    let text = String::from_utf8(server.get("/metrics").await.body.to_vec()).expect("UTF-8");
    let line = text.lines().find_map(|l| l.strip_prefix("relume_frame_duration_seconds_count ")).expect("a count");
    line.parse().expect("a number")
}

/// Waits (up to `within`) until the render queue holds `depth` renders; whether it did.
async fn queue_reaches(server: &TestServer, depth: usize, within: Duration) -> bool {
    let deadline = Instant::now() + within;
    while server.state.workers.queue_depth() != depth {
        if Instant::now() > deadline {
            return false;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    true
}

/// Waits up to `within` for the (one) worker to run a render.
async fn gpu_runs(server: &TestServer, within: Duration) -> bool {
    let worker = server.state.workers.get(0).expect("a worker");
    let deadline = Instant::now() + within;
    // Its load counts the renders waiting and running and the streams pinned (none here).
    while worker.load().saturating_sub(worker.queue_depth()) != 1 {
        if Instant::now() > deadline {
            return false;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    true
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn renders_whose_clients_have_gone_leave_the_queue() {
    const RENDER_MS: u64 = 3000;
    let server = fake_server(RENDER_MS, |c| {
        c.limits.max_client_queue = 2;
        c.limits.max_queue = 16;
    })
    .await;
    let id = server.create(&inline_scene()).await;
    let path = format!("/v1/scenes/{id}/render");
    let send = || async {
        let mut socket = TcpStream::connect(server.addr).await.expect("connects");
        let request = format!("POST {path} HTTP/1.1\r\nHost: x\r\nContent-Length: 2\r\n\r\n{{}}");
        socket.write_all(request.as_bytes()).await.expect("sent");
        socket
    };
    // Three renders from this client: one goes to the GPU, then two wait (its max_client_queue;
    // sent once the first runs, so that none is refused however late the GPU thread takes the
    // first on a loaded machine); then the client goes away.
    let mut gone = vec![send().await];
    assert!(gpu_runs(&server, Duration::from_secs(5)).await, "the first render runs");
    for _ in 0..2 {
        gone.push(send().await);
    }
    assert!(queue_reaches(&server, 2, Duration::from_secs(5)).await, "two renders wait");
    drop(gone);
    // Their places are given back as soon as the server sees the connections close, long
    // before the render on the GPU ends (the GPU thread used to skip them only then).
    let emptied = queue_reaches(&server, 0, Duration::from_millis(500)).await;
    // The same client's next render is taken and served after at most the one on the GPU.
    let started = Instant::now();
    let reply = server.post(&path, &json!({})).await;
    assert_eq!(reply.status, StatusCode::OK, "{}", String::from_utf8_lossy(&reply.body));
    let took = started.elapsed();
    assert!(emptied, "the abandoned renders still count in the queue");
    assert!(took < Duration::from_millis(2 * RENDER_MS + 1000), "served after {took:?}");
    // The two abandoned renders that waited did not run: only this one, and the render that
    // was on the GPU when its client left, if the GPU thread had started it by then (on a
    // loaded machine it can still be waiting, and is then dropped too).
    let rendered = frames_rendered(&server).await;
    assert!((1..=2).contains(&rendered), "{rendered} renders ran");

    // A stream frame whose stream closes while it waits behind a render leaves the queue
    // too (at once, not when the GPU thread comes to it).
    let holding = tokio::spawn(raw_render(server.addr, path.clone()));
    tokio::time::sleep(Duration::from_millis(300)).await;
    let url = format!("ws://{}/v1/scenes/{id}/stream", server.addr);
    let (mut stream, _) = tokio_tungstenite::connect_async(&url).await.expect("the stream opens");
    let message = envelope(Body::RgbdFrame(frame(1, 8, 6)));
    stream.send(tungstenite::Message::Binary(message.into())).await.expect("sent");
    assert!(queue_reaches(&server, 1, Duration::from_secs(5)).await, "the frame waits behind the render");
    drop(stream);
    assert!(queue_reaches(&server, 0, Duration::from_millis(500)).await, "the closed stream's frame still waits");
    assert_eq!(holding.await.expect("the render task"), StatusCode::OK);
    // The holding render ran; the closed stream's frame did not.
    assert_eq!(frames_rendered(&server).await, rendered + 1, "the frame of the closed stream was rendered");
    server.stop().await;
}

/// A render of `path` (`{}`) on its own connection; its status.
async fn raw_render(addr: SocketAddr, path: String) -> StatusCode {
    let request = format!("POST {path} HTTP/1.1\r\nHost: x\r\nContent-Length: 2\r\nConnection: close\r\n\r\n{{}}");
    StatusCode::from_u16(exchange(addr, request.into_bytes()).await.status).expect("a status")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_empty_stream_message_is_malformed() {
    let server = fake_server(0, |_| {}).await;
    let id = server.create(&inline_scene()).await;
    let mut ws = server.stream(&id).await;
    match ws.exchange(Vec::new()).await {
        Body::Error(error) => {
            assert_eq!(error.code(), ErrorCode::Malformed, "{error:?}");
            assert!(!error.message.is_empty());
        }
        other => panic!("expected an error, got {other:?}"),
    }
    // The stream stays open: a real frame is still answered.
    assert!(matches!(ws.exchange(envelope(Body::RgbdFrame(frame(2, 8, 6)))).await, Body::RenderedFrame(_)));
    server.stop().await;
}

/// The process's resident memory, bytes (`VmRSS` of `/proc/self/status`).
fn resident_bytes() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").expect("/proc/self/status");
    let kib = status.lines().find_map(|l| l.strip_prefix("VmRSS:")).expect("VmRSS");
    kib.trim().trim_end_matches("kB").trim().parse::<u64>().expect("kB") * 1024
}

/// `relume_gpu_buffer_bytes + relume_gpu_texture_bytes` from `/metrics`.
async fn gpu_bytes(server: &TestServer) -> u64 {
    let text = String::from_utf8(server.get("/metrics").await.body.to_vec()).expect("UTF-8");
    ["relume_gpu_buffer_bytes ", "relume_gpu_texture_bytes "]
        .iter()
        .map(|name| {
            let value = text.lines().find_map(|l| l.strip_prefix(name)).unwrap_or_else(|| panic!("{name}in\n{text}"));
            value.parse::<u64>().expect("bytes")
        })
        .sum()
}

/// One cycle: create the scene, optionally render it and run a stream (opened with a ticket)
/// on it, delete it.
async fn cycle(server: &TestServer, scene: &Value, render: bool) {
    let id = server.create(scene).await;
    if render {
        let reply = server.post(&format!("/v1/scenes/{id}/render"), &json!({})).await;
        assert_eq!(reply.status, StatusCode::OK, "{}", String::from_utf8_lossy(&reply.body));
        let ticket = server.request(Method::POST, "/v1/tickets", Bytes::new()).await.json()["ticket"]
            .as_str()
            .expect("a ticket")
            .to_owned();
        let url = format!("ws://{}/v1/scenes/{id}/stream?ticket={ticket}", server.addr);
        let (stream, _) = tokio_tungstenite::connect_async(&url).await.expect("the ticket opens a stream");
        drop(stream);
    }
    let deleted = server.request(Method::DELETE, &format!("/v1/scenes/{id}"), Bytes::new()).await;
    assert_eq!(deleted.status, StatusCode::NO_CONTENT);
}

/// A soak on the real GPU backend (lavapipe in CI): scenes created and deleted a hundred
/// times after a warm-up, some rendered and streamed in between, give their memory back. Each deleted
/// `cornell_bunny_small` held about 5.5 MiB until the next render submitted and polled.
///
/// Resident memory is the process's, and the other tests of this binary run beside each other
/// in one process: the soak runs in a process of its own, this binary started again with only
/// [`soak_in_a_process_of_its_own`].
#[test]
fn deleted_scenes_give_their_memory_back() {
    let exe = std::env::current_exe().expect("the test binary");
    let out = std::process::Command::new(exe)
        .args(["reliability::soak_in_a_process_of_its_own", "--exact", "--ignored", "--nocapture"])
        .output()
        .expect("running the soak");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    println!("{text}");
    assert!(out.status.success(), "the soak failed:\n{text}");
    assert!(text.contains("1 passed"), "the soak did not run:\n{text}");
}

/// The soak itself (see [`deleted_scenes_give_their_memory_back`], which runs it alone in a
/// process).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "run in a process of its own by deleted_scenes_give_their_memory_back"]
async fn soak_in_a_process_of_its_own() {
    const CYCLES: usize = 100;
    const RENDERED_EVERY: usize = 25;
    /// Resident growth allowed after the warm-up: allocator noise (2.7 MiB measured over 300
    /// cycles). The leak held 5.5 MiB per cycle since the last render, 130 MiB at the end
    /// here.
    const BOUND: u64 = 32 << 20;
    /// GPU memory allowed above the warm-up's: less than one deleted scene's.
    const GPU_BOUND: u64 = 4 << 20;
    let server = TestServer::start(|_| {}).await;
    let scene = fixture_scene("cornell_bunny_small", 16);
    let start = resident_bytes();
    for i in 0..10 {
        cycle(&server, &scene, i % 5 == 0).await;
    }
    let warm = resident_bytes();
    let warm_gpu = gpu_bytes(&server).await;
    let started = Instant::now();
    for i in 0..CYCLES {
        cycle(&server, &scene, i % RENDERED_EVERY == 0).await;
    }
    let end = resident_bytes();
    let end_gpu = gpu_bytes(&server).await;
    let mib = |b: u64| b as f64 / (1 << 20) as f64;
    println!(
        "resident memory: start {:.1} MiB, after warm-up {:.1} MiB, after {CYCLES} cycles {:.1} MiB ({:.1} s); \
         GPU memory held: {:.1} MiB after warm-up, {:.1} MiB at the end",
        mib(start),
        mib(warm),
        mib(end),
        started.elapsed().as_secs_f64(),
        mib(warm_gpu),
        mib(end_gpu)
    );
    assert!(
        end_gpu <= warm_gpu + GPU_BOUND,
        "GPU memory of deleted scenes is still held: {:.1} MiB after the warm-up, {:.1} MiB at the end",
        mib(warm_gpu),
        mib(end_gpu)
    );
    assert!(
        end.saturating_sub(warm) < BOUND,
        "resident memory grew {:.1} MiB over {CYCLES} cycles (bound {:.0} MiB)",
        mib(end.saturating_sub(warm)),
        mib(BOUND)
    );
    server.stop().await;
}

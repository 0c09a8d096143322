//! The soak's hostile mix: render floods, slow and idle sockets, oversized and truncated
//! stream messages, disconnects mid-frame and scene churn, each a loop until the phase ends,
//! from [`HOSTILE`].

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use hyper::{Method, StatusCode};
use serde_json::json;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

use super::soak::{FLOODERS, HOSTILE, HostileTally, IDLE_SOCKETS, OVERSIZED_BYTES, SLOW_SOCKETS};
use crate::service::client::Connection;
use crate::service::wire::proto;
use crate::service::wire::proto::envelope::Body;

/// The hostile mix's counters.
#[derive(Default)]
pub(super) struct Hostile {
    flood_ok: AtomicU64,
    flood_refused: AtomicU64,
    sockets_closed: AtomicU64,
    oversized_1009: AtomicU64,
    oversized_other: AtomicU64,
    truncated_answered: AtomicU64,
    disconnects: AtomicU64,
    churned: AtomicU64,
    refused: AtomicU64,
}

impl Hostile {
    pub(super) fn tally(&self) -> HostileTally {
        let get = |c: &AtomicU64| c.load(Ordering::SeqCst);
        HostileTally {
            flood_renders_ok: get(&self.flood_ok),
            flood_renders_refused: get(&self.flood_refused),
            sockets_closed: get(&self.sockets_closed),
            oversized_closed_1009: get(&self.oversized_1009),
            oversized_other: get(&self.oversized_other),
            truncated_answered: get(&self.truncated_answered),
            disconnects_mid_frame: get(&self.disconnects),
            scenes_created_and_deleted: get(&self.churned),
            refused: get(&self.refused),
        }
    }

    /// Starts every hostile loop; each ends at `deadline`.
    pub(super) fn start(
        self: &Arc<Self>,
        connection: Connection,
        addr: SocketAddr,
        scene: &str,
        deadline: tokio::time::Instant,
    ) -> Vec<tokio::task::JoinHandle<()>> {
        let mut tasks = Vec::new();
        let mut spawn = |task: std::pin::Pin<Box<dyn std::future::Future<Output = ()> + Send>>| {
            tasks.push(tokio::spawn(task));
        };
        let render_path = format!("/v1/scenes/{scene}/render");
        let stream_path = format!("/v1/scenes/{scene}/stream");
        for _ in 0..FLOODERS {
            let (me, connection, path) = (self.clone(), connection.clone(), render_path.clone());
            spawn(Box::pin(async move { me.flood(&connection, &path, deadline).await }));
        }
        for i in 0..SLOW_SOCKETS + IDLE_SOCKETS {
            let me = self.clone();
            spawn(Box::pin(async move { me.hold_socket(addr, i < SLOW_SOCKETS, deadline).await }));
        }
        let me = self.clone();
        let path = stream_path.clone();
        spawn(Box::pin(async move { me.stream_abuse(addr, &path, deadline).await }));
        let me = self.clone();
        spawn(Box::pin(async move { me.churn_scenes(&connection, deadline).await }));
        tasks
    }

    /// Renders the scene by brute force back to back, retrying refusals after 20 ms.
    async fn flood(&self, connection: &Connection, path: &str, deadline: tokio::time::Instant) {
        let body = json!({"quality": {"method": "brute-force"}}).to_string();
        while tokio::time::Instant::now() < deadline {
            match connection.request(Method::POST, path, body.clone().into()).await {
                Ok((StatusCode::OK, _)) => self.flood_ok.fetch_add(1, Ordering::SeqCst),
                _ => {
                    tokio::time::sleep(Duration::from_millis(20)).await;
                    self.flood_refused.fetch_add(1, Ordering::SeqCst)
                }
            };
        }
    }

    /// Holds a connection open, silent or sending a request's headers a byte every 500 ms,
    /// and opens another when the server closes it.
    async fn hold_socket(&self, addr: SocketAddr, slow: bool, deadline: tokio::time::Instant) {
        let headers = b"GET /healthz HTTP/1.1\r\nHost: relume\r\nX-Slow: 1\r\n";
        while tokio::time::Instant::now() < deadline {
            let Ok(mut socket) = hostile_socket(addr).await else {
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            };
            let mut sent = 0;
            let mut buffer = [0u8; 1024];
            loop {
                let tick = tokio::time::sleep(Duration::from_millis(500));
                tokio::select! {
                    read = socket.read(&mut buffer) => if matches!(read, Ok(0) | Err(_)) {
                        self.sockets_closed.fetch_add(1, Ordering::SeqCst);
                        break;
                    },
                    () = tick => {
                        if tokio::time::Instant::now() >= deadline {
                            return;
                        }
                        if slow && socket.write_all(&headers[sent % headers.len()..][..1]).await.is_err() {
                            break;
                        }
                        sent += 1;
                    }
                }
            }
        }
    }

    /// Stream messages a careless or hostile client sends, in turn: a frame announcing
    /// [`OVERSIZED_BYTES`], an envelope cut in half, and half a frame then a disconnect.
    async fn stream_abuse(&self, addr: SocketAddr, path: &str, deadline: tokio::time::Instant) {
        let envelope = proto::Envelope {
            version: crate::service::wire::PROTOCOL_VERSION,
            body: Some(Body::Control(proto::Control { request_id: 1, ..Default::default() })),
        };
        let whole = prost::Message::encode_to_vec(&envelope);
        let mut round = 0u64;
        while tokio::time::Instant::now() < deadline {
            round += 1;
            let Ok(mut socket) = hostile_websocket(addr, path).await else {
                self.refused.fetch_add(1, Ordering::SeqCst);
                tokio::time::sleep(Duration::from_millis(200)).await;
                continue;
            };
            match round % 3 {
                0 => {
                    let mut frame = masked_frame_header(OVERSIZED_BYTES);
                    frame.extend_from_slice(&[0u8; 1024]);
                    let closed =
                        socket.write_all(&frame).await.is_ok() && read_close_code(&mut socket).await == Some(1009);
                    let counter = if closed { &self.oversized_1009 } else { &self.oversized_other };
                    counter.fetch_add(1, Ordering::SeqCst);
                }
                1 => {
                    let half = &whole[..whole.len() / 2];
                    let mut frame = masked_frame_header(half.len() as u64);
                    frame.extend_from_slice(half);
                    if socket.write_all(&frame).await.is_ok() && read_binary(&mut socket).await {
                        self.truncated_answered.fetch_add(1, Ordering::SeqCst);
                    }
                }
                _ => {
                    let mut frame = masked_frame_header(64 << 10);
                    frame.extend_from_slice(&[0u8; 32 << 10]);
                    let _ = socket.write_all(&frame).await;
                    self.disconnects.fetch_add(1, Ordering::SeqCst);
                }
            }
        }
    }

    /// Creates a small scene and deletes it, over and over.
    async fn churn_scenes(&self, connection: &Connection, deadline: tokio::time::Instant) {
        let scene = json!({
            "meshes": [{"obj": "quad.obj", "obj_text": "v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nf 1 4 3 2\n",
                        "sparse_points": 16, "material": {"diffuse": [0.5, 0.5, 0.5]}}],
            "light": {"position": [0, 1, 0], "direction": [0, -1, 0], "inner_angle_deg": 30,
                      "outer_angle_deg": 45, "intensity": [1, 1, 1]},
            "camera": {"position": [0, 1, 2], "target": [0, 0, 0], "fov_y_deg": 50, "width": 8, "height": 8},
            "settings": {"tuning": {"rsm_resolution": 8}}
        });
        while tokio::time::Instant::now() < deadline {
            match connection.create_scene(&scene).await {
                Ok(id) => {
                    if connection.delete_scene(&id).await.is_ok() {
                        self.churned.fetch_add(1, Ordering::SeqCst);
                    }
                }
                Err(_) => {
                    self.refused.fetch_add(1, Ordering::SeqCst);
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
            }
        }
    }
}

/// A TCP connection to `addr` from [`HOSTILE`].
async fn hostile_socket(addr: SocketAddr) -> std::io::Result<tokio::net::TcpStream> {
    let socket = tokio::net::TcpSocket::new_v4()?;
    socket.bind(SocketAddr::new(HOSTILE, 0))?;
    tokio::time::timeout(Duration::from_secs(5), socket.connect(addr)).await?
}

/// A WebSocket opened by hand on `path` (the 101 read), for raw frames.
async fn hostile_websocket(addr: SocketAddr, path: &str) -> anyhow::Result<tokio::net::TcpStream> {
    let mut socket = hostile_socket(addr).await?;
    let request = format!(
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
    );
    socket.write_all(request.as_bytes()).await?;
    let mut head = Vec::new();
    while !head.ends_with(b"\r\n\r\n") && head.len() < 16 << 10 {
        head.push(tokio::time::timeout(Duration::from_secs(5), socket.read_u8()).await??);
    }
    anyhow::ensure!(head.starts_with(b"HTTP/1.1 101"), "{}", String::from_utf8_lossy(&head));
    Ok(socket)
}

/// The header of a masked binary frame of `length` bytes, with mask key 0 (the payload goes
/// as is).
fn masked_frame_header(length: u64) -> Vec<u8> {
    let mut header = vec![0x82, 0x80 | 127];
    header.extend_from_slice(&length.to_be_bytes());
    header.extend_from_slice(&[0; 4]);
    header
}

/// Reads server frames (within 10 s) until a Close; its code.
async fn read_close_code(socket: &mut tokio::net::TcpStream) -> Option<u16> {
    loop {
        let (opcode, payload) = read_server_frame(socket).await?;
        if opcode == 0x8 {
            return payload.get(..2).map(|code| u16::from_be_bytes([code[0], code[1]]));
        }
    }
}

/// Whether a binary message arrives (within 10 s).
async fn read_binary(socket: &mut tokio::net::TcpStream) -> bool {
    while let Some((opcode, _)) = read_server_frame(socket).await {
        if opcode == 0x2 {
            return true;
        }
    }
    false
}

/// One unmasked server frame (within 10 s): opcode and payload.
async fn read_server_frame(socket: &mut tokio::net::TcpStream) -> Option<(u8, Vec<u8>)> {
    let read = async {
        let mut header = [0u8; 2];
        socket.read_exact(&mut header).await.ok()?;
        let length = match header[1] & 0x7f {
            126 => socket.read_u16().await.ok()? as u64,
            127 => socket.read_u64().await.ok()?,
            n => n as u64,
        };
        let mut payload = vec![0u8; usize::try_from(length).ok().filter(|&n| n <= 64 << 20)?];
        socket.read_exact(&mut payload).await.ok()?;
        Some((header[0] & 0x0f, payload))
    };
    tokio::time::timeout(Duration::from_secs(10), read).await.ok().flatten()
}

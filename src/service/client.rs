//! A client of `relume serve`: uploads a scene, streams RGB-D frames over the WebSocket
//! protocol (`proto/relume.proto`) and collects the relit frames. `relume replay --server`
//! ([`replay_remote`]) and `relume load` (`crate::service::load`) are built on it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use bytes::Bytes;
use futures_util::{SinkExt, StreamExt};
use http_body_util::{BodyExt, Full};
use hyper::{Method, StatusCode, Uri};
use hyper_util::client::legacy::Client;
use hyper_util::client::legacy::connect::HttpConnector;
use prost::Message as _;
use serde::Serialize;
use serde_json::Value;
use tokio_tungstenite::tungstenite;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;

use crate::rgbd::RgbdFrame;
use crate::rgbd::recording::{Recording, RecordingOptions};
use crate::service::wire::proto::{self, envelope::Body};
use crate::service::wire::{PROTOCOL_VERSION, encode_rgbd_frame};

/// How long any one answer from the server may take before the client gives up.
pub const ANSWER_TIMEOUT: Duration = Duration::from_secs(120);

/// The first wait before a client opens a stream again after it ended (doubled each try, up
/// to [`MAX_RETRY_DELAY`]).
pub const FIRST_RETRY_DELAY: Duration = Duration::from_millis(100);

/// The longest wait between two tries.
pub const MAX_RETRY_DELAY: Duration = Duration::from_secs(2);

/// The default of `--reconnect-seconds`: how long a client tries to get a stream back.
pub const DEFAULT_RECONNECT_SECONDS: u64 = 60;

/// The server does not know the scene (404): the backend that held it is gone and no scene
/// store shares it.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct SceneUnknown(String);

/// Waits of a retry loop: [`FIRST_RETRY_DELAY`], doubled up to [`MAX_RETRY_DELAY`], until
/// `give_up` has passed since the first.
pub struct Backoff {
    delay: Duration,
    deadline: Instant,
}

impl Backoff {
    pub fn new(give_up: Duration) -> Backoff {
        Backoff { delay: FIRST_RETRY_DELAY, deadline: Instant::now() + give_up }
    }

    /// Sleeps the next wait; false (at once) once `give_up` has passed.
    pub async fn wait(&mut self) -> bool {
        if Instant::now() + self.delay > self.deadline {
            return false;
        }
        tokio::time::sleep(self.delay).await;
        self.delay = (self.delay * 2).min(MAX_RETRY_DELAY);
        true
    }
}

/// A relume server: its address and the bearer token, if it wants one.
#[derive(Clone)]
pub struct Connection {
    /// `host:port`.
    authority: String,
    token: Option<String>,
    http: Client<HttpConnector, Full<Bytes>>,
}

impl Connection {
    /// `server` is `http://host:port` (a trailing `/` is fine); `ws://` is accepted too.
    pub fn new(server: &str, token: Option<String>) -> anyhow::Result<Connection> {
        let uri: Uri = server.parse().map_err(|e| anyhow::anyhow!("--server: `{server}` is not a URL: {e}"))?;
        match uri.scheme_str() {
            Some("http" | "ws") => {}
            Some(other) => bail!("--server: scheme `{other}` is not supported (use http://host:port; no TLS)"),
            None => bail!("--server: `{server}` has no scheme (use http://host:port)"),
        }
        let authority = uri.authority().map(|a| a.to_string()).context("--server: no host:port")?;
        if !matches!(uri.path(), "" | "/") {
            bail!("--server: give the server's root (http://host:port), not a path ({})", uri.path());
        }
        let http = Client::builder(hyper_util::rt::TokioExecutor::new()).build_http();
        Ok(Connection { authority, token, http })
    }

    /// The same server, with HTTP connections made from `source` (another loopback address is
    /// another client to the server's fair queue).
    pub fn from_source(&self, source: std::net::IpAddr) -> Connection {
        let mut connector = HttpConnector::new();
        connector.set_local_address(Some(source));
        let http = Client::builder(hyper_util::rt::TokioExecutor::new()).build(connector);
        Connection { authority: self.authority.clone(), token: self.token.clone(), http }
    }

    /// `host:port` of the server.
    pub fn authority(&self) -> &str {
        &self.authority
    }

    /// One HTTP request; the answer's status and body.
    pub async fn request(&self, method: Method, path: &str, body: Bytes) -> anyhow::Result<(StatusCode, Bytes)> {
        let mut request = hyper::Request::builder()
            .method(method)
            .uri(format!("http://{}{path}", self.authority))
            .header("content-type", "application/json");
        if let Some(token) = &self.token {
            request = request.header("authorization", format!("Bearer {token}"));
        }
        let request = request.body(Full::new(body)).context("building the request")?;
        let response = tokio::time::timeout(ANSWER_TIMEOUT, self.http.request(request))
            .await
            .with_context(|| format!("no answer from {} within {ANSWER_TIMEOUT:?}", self.authority))?
            .with_context(|| format!("cannot reach the server at {}", self.authority))?;
        let status = response.status();
        let body = response.into_body().collect().await.context("reading the answer")?.to_bytes();
        Ok((status, body))
    }

    /// Creates a scene from a description (see [`upload_description`]); returns its id.
    pub async fn create_scene(&self, description: &Value) -> anyhow::Result<String> {
        let (status, body) = self.request(Method::POST, "/v1/scenes", description.to_string().into()).await?;
        if status != StatusCode::CREATED {
            bail!("creating the scene: {}", server_error(status, &body));
        }
        let info: Value = serde_json::from_slice(&body).context("the scene summary is not JSON")?;
        info["id"].as_str().map(str::to_owned).context("the scene summary has no id")
    }

    pub async fn delete_scene(&self, id: &str) -> anyhow::Result<()> {
        let (status, body) = self.request(Method::DELETE, &format!("/v1/scenes/{id}"), Bytes::new()).await?;
        if status != StatusCode::NO_CONTENT {
            bail!("deleting scene {id}: {}", server_error(status, &body));
        }
        Ok(())
    }

    /// Opens the scene's stream.
    pub async fn open_stream(&self, id: &str) -> anyhow::Result<Stream> {
        let mut request = format!("ws://{}/v1/scenes/{id}/stream", self.authority)
            .into_client_request()
            .context("building the stream request")?;
        if let Some(token) = &self.token {
            let value = format!("Bearer {token}").parse().context("--token: not a valid header value")?;
            request.headers_mut().insert("authorization", value);
        }
        let (ws, _) = match tokio_tungstenite::connect_async(request).await {
            Ok(ok) => ok,
            Err(tungstenite::Error::Http(response)) => {
                let body = response.body().clone().unwrap_or_default();
                let error = format!("opening the stream: {}", server_error(response.status(), &body));
                if response.status() == StatusCode::NOT_FOUND {
                    return Err(SceneUnknown(error).into());
                }
                bail!(error);
            }
            Err(e) => return Err(e).context("opening the stream"),
        };
        Ok(Stream { ws })
    }

    /// Opens scene `id`'s stream again after the last one ended (its backend stopped or died;
    /// through a load balancer the new stream may land on another backend): tries at once,
    /// then with [`Backoff`] until `give_up`. A scene the server no longer knows is created
    /// again from `description` and `id` changes to the new one's; the answer says whether.
    pub async fn reopen_stream(
        &self,
        id: &mut String,
        description: &Value,
        give_up: Duration,
    ) -> anyhow::Result<(Stream, bool)> {
        let mut backoff = Backoff::new(give_up);
        let mut recreated = false;
        loop {
            let error = match self.open_stream(id).await {
                Ok(stream) => return Ok((stream, recreated)),
                Err(error) if error.downcast_ref::<SceneUnknown>().is_some() => {
                    match self.create_scene(description).await {
                        Ok(new_id) => {
                            tracing::warn!(old = %id, new = %new_id, "the server no longer knows the scene: created it again");
                            *id = new_id;
                            recreated = true;
                            continue;
                        }
                        Err(error) => error,
                    }
                }
                Err(error) => error,
            };
            tracing::warn!("the stream is gone, reconnecting: {error:#}");
            if !backoff.wait().await {
                return Err(error.context(format!("no stream back within {give_up:?}")));
            }
        }
    }
}

/// `status: code: message (field ...)` from a JSON error body, or the body as text.
fn server_error(status: StatusCode, body: &[u8]) -> String {
    let parsed: Option<Value> = serde_json::from_slice(body).ok();
    match parsed.as_ref().map(|v| &v["error"]) {
        Some(Value::Object(e)) => {
            let field = e.get("field").and_then(Value::as_str).filter(|f| !f.is_empty());
            let code = e.get("code").and_then(Value::as_str).unwrap_or("?");
            let message = e.get("message").and_then(Value::as_str).unwrap_or("");
            match field {
                Some(field) => format!("{status}: {code}: {message} (field `{field}`)"),
                None => format!("{status}: {code}: {message}"),
            }
        }
        _ => format!("{status}: {}", String::from_utf8_lossy(body)),
    }
}

/// One open stream.
pub struct Stream {
    ws: tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>,
}

impl Stream {
    pub async fn send_frame(&mut self, frame_id: u64, frame: &RgbdFrame) -> anyhow::Result<()> {
        self.send(encode_rgbd_frame(frame_id, frame)).await
    }

    pub async fn send_control(&mut self, control: proto::Control) -> anyhow::Result<()> {
        let envelope = proto::Envelope { version: PROTOCOL_VERSION, body: Some(Body::Control(control)) };
        self.send(envelope.encode_to_vec()).await
    }

    async fn send(&mut self, bytes: Vec<u8>) -> anyhow::Result<()> {
        self.ws.send(tungstenite::Message::Binary(bytes.into())).await.context("sending on the stream")
    }

    /// The next message from the server; `None` once the server has closed the stream.
    pub async fn next(&mut self) -> anyhow::Result<Option<Body>> {
        loop {
            let message = tokio::time::timeout(ANSWER_TIMEOUT, self.ws.next())
                .await
                .with_context(|| format!("the server sent nothing for {ANSWER_TIMEOUT:?}"))?;
            match message {
                None | Some(Ok(tungstenite::Message::Close(_))) => return Ok(None),
                Some(Err(e)) => return Err(e).context("reading the stream"),
                Some(Ok(tungstenite::Message::Binary(bytes))) => {
                    let envelope = proto::Envelope::decode(bytes.as_ref()).context("the server sent a bad envelope")?;
                    if envelope.version != PROTOCOL_VERSION {
                        bail!(
                            "the server speaks protocol version {}, this client {PROTOCOL_VERSION}",
                            envelope.version
                        );
                    }
                    return envelope.body.map(Some).context("the server sent an empty envelope");
                }
                Some(Ok(_)) => continue,
            }
        }
    }

    /// Closes the stream politely.
    pub async fn close(mut self) {
        let _ = self.ws.close(None).await;
    }
}

/// `error` as one line: code, message, field, limit.
pub fn describe_error(error: &proto::Error) -> String {
    let mut text = format!("{}: {}", error.code().as_str_name(), error.message);
    if !error.field.is_empty() {
        text.push_str(&format!(" (field `{}`)", error.field));
    }
    if !error.limit.is_empty() {
        text.push_str(&format!(" (limit `{}`)", error.limit));
    }
    text
}

/// The scene file at `path` as JSON, with `edit(scene file's directory, index, mesh)` applied
/// to each of its meshes.
fn edit_meshes(
    path: &Path,
    mut edit: impl FnMut(&Path, usize, &mut Value) -> anyhow::Result<()>,
) -> anyhow::Result<Value> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading scene {}", path.display()))?;
    let mut description: Value =
        serde_json::from_str(&text).with_context(|| format!("{}: not a JSON scene", path.display()))?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let meshes =
        description["meshes"].as_array_mut().with_context(|| format!("{}: meshes: required", path.display()))?;
    for (i, mesh) in meshes.iter_mut().enumerate() {
        edit(dir, i, mesh)?;
    }
    Ok(description)
}

/// The scene file at `path` as a `POST /v1/scenes` body: every mesh's OBJ is read here and sent
/// inline (`obj_text`), so the server needs none of the client's files. Textures and MTL files
/// cannot travel this way; a scene that needs them must live in the server's asset directory.
pub fn upload_description(path: &Path) -> anyhow::Result<Value> {
    edit_meshes(path, |dir, i, mesh| {
        if mesh.get("obj_text").is_some() {
            return Ok(());
        }
        let obj = mesh["obj"].as_str().with_context(|| format!("{}: meshes[{i}].obj: required", path.display()))?;
        let obj_path = dir.join(obj);
        let obj_text = std::fs::read_to_string(&obj_path)
            .with_context(|| format!("meshes[{i}].obj: reading {}", obj_path.display()))?;
        let name = obj_path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        mesh["obj"] = name.into();
        mesh["obj_text"] = obj_text.into();
        Ok(())
    })
}

/// The scene file at `path` as a `POST /v1/scenes` body for a server whose asset directory is
/// `assets` (as this process sees it): mesh and texture paths, relative to the scene file's
/// directory, are made relative to `assets`. For scenes whose meshes need MTL files or
/// textures, which [`upload_description`] cannot send.
pub fn asset_description(path: &Path, assets: &Path) -> anyhow::Result<Value> {
    let assets = assets.canonicalize().with_context(|| format!("asset directory {}", assets.display()))?;
    edit_meshes(path, |dir, i, mesh| {
        let relative = |field: &str, file: &str| -> anyhow::Result<Value> {
            let full = dir.join(file).canonicalize().with_context(|| format!("{field}: {file}"))?;
            let inside = full.strip_prefix(&assets).with_context(|| {
                format!("{field}: {} is outside the server's asset directory {}", full.display(), assets.display())
            })?;
            Ok(inside.to_string_lossy().into_owned().into())
        };
        if let Some(obj) = mesh["obj"].as_str().filter(|_| mesh.get("obj_text").is_none()) {
            mesh["obj"] = relative(&format!("meshes[{i}].obj"), obj)?;
        }
        if let Some(texture) = mesh["material"]["diffuse_texture"].as_str() {
            mesh["material"]["diffuse_texture"] = relative(&format!("meshes[{i}].material.diffuse_texture"), texture)?;
        }
        Ok(())
    })
}

/// What to replay against which server.
#[derive(Clone, Debug)]
pub struct RemoteReplayOptions {
    /// `http://host:port`.
    pub server: String,
    pub token: Option<String>,
    pub recording: PathBuf,
    pub recording_options: RecordingOptions,
    /// The scene file, uploaded with its meshes inline.
    pub scene: PathBuf,
    /// Output directory: `composited/NNNN.png`, `summary.json`.
    pub out: PathBuf,
    pub frames: Option<usize>,
    /// Exposure of the virtual content in the composite (the stream's default is 1).
    pub exposure: Option<f32>,
    pub progress: bool,
    /// How long to try to get a stream back after one ended (0: give up at once).
    pub reconnect: Duration,
}

/// Figures of one replay over the wire, written as `summary.json`.
#[derive(Clone, Debug, Serialize)]
pub struct RemoteReplaySummary {
    pub server: String,
    pub scene_id: String,
    pub frames: usize,
    pub width: u32,
    pub height: u32,
    pub vals_per_frame: Vec<u32>,
    /// Milliseconds per stage as the server reported them (decode, queue, GPU stages,
    /// composite, encode), one entry per frame.
    pub stage_ms: BTreeMap<String, Vec<f64>>,
    /// From sending a frame to receiving its relit image, ms.
    pub round_trip_ms: Vec<f64>,
    /// Frames the server dropped (none are expected: the replay waits for each answer).
    pub dropped_frames: u64,
    /// Frames sent whose answer never came because the stream ended (the frames in flight
    /// when a backend stopped or died), and their indices.
    pub frames_lost: u64,
    pub lost_frames: Vec<usize>,
    /// Streams opened again after one ended, and scenes created again on the way.
    pub reconnects: u32,
    pub scenes_recreated: u32,
}

/// Streams `options.recording` through a relume server one frame at a time (each frame is sent
/// when the previous one has come back, as the offline replay renders them) and writes every
/// relit frame. The scene is created for the replay and deleted after it.
pub async fn replay_remote(options: &RemoteReplayOptions) -> anyhow::Result<RemoteReplaySummary> {
    let recording = Recording::open(&options.recording, &options.recording_options)?;
    let frames = options.frames.unwrap_or(usize::MAX).min(recording.len());
    let description = upload_description(&options.scene)?;
    let connection = Connection::new(&options.server, options.token.clone())?;
    let composited_dir = options.out.join("composited");
    std::fs::create_dir_all(&composited_dir).with_context(|| format!("creating {}", composited_dir.display()))?;
    let mut scene_id = connection.create_scene(&description).await?;
    let result =
        stream_recording(&connection, &mut scene_id, &description, &recording, frames, options, &composited_dir).await;
    let deleted = connection.delete_scene(&scene_id).await;
    let summary = result?;
    deleted?;
    let json = serde_json::to_string_pretty(&summary)?;
    let path = options.out.join("summary.json");
    std::fs::write(&path, json).with_context(|| format!("writing {}", path.display()))?;
    Ok(summary)
}

/// Sets the stream's exposure, when the options give one.
async fn configure(stream: &mut Stream, options: &RemoteReplayOptions) -> anyhow::Result<()> {
    if let Some(exposure) = options.exposure {
        let quality = proto::Quality { exposure: Some(exposure), ..Default::default() };
        stream.send_control(proto::Control { request_id: 1, quality: Some(quality), ..Default::default() }).await?;
        match stream.next().await? {
            Some(Body::SettingsAck(_)) => {}
            Some(Body::Error(e)) => bail!("the server refused the settings: {}", describe_error(&e)),
            other => bail!("expected a SettingsAck, got {other:?}"),
        }
    }
    Ok(())
}

/// Sends frame `i` and waits for its answer: `None` when the stream ended first (closed,
/// broken, or a `SHUTTING_DOWN` error for the frame).
async fn exchange(stream: &mut Stream, i: usize, frame: &RgbdFrame) -> anyhow::Result<Option<proto::RenderedFrame>> {
    if let Err(error) = stream.send_frame(i as u64, frame).await {
        tracing::warn!("frame {i}: {error:#}");
        return Ok(None);
    }
    match stream.next().await {
        Ok(Some(Body::RenderedFrame(f))) if f.frame_id == i as u64 => Ok(Some(f)),
        Ok(Some(Body::Error(e))) if e.code() == proto::ErrorCode::ShuttingDown => Ok(None),
        Ok(Some(Body::Error(e))) => bail!("frame {i}: {}", describe_error(&e)),
        Ok(Some(other)) => bail!("frame {i}: expected a RenderedFrame, got {other:?}"),
        Ok(None) => Ok(None),
        Err(error) => {
            tracing::warn!("frame {i}: {error:#}");
            Ok(None)
        }
    }
}

async fn stream_recording(
    connection: &Connection,
    scene_id: &mut String,
    description: &Value,
    recording: &Recording,
    frames: usize,
    options: &RemoteReplayOptions,
    composited_dir: &Path,
) -> anyhow::Result<RemoteReplaySummary> {
    let mut stream = connection.open_stream(scene_id).await?;
    configure(&mut stream, options).await?;
    let mut summary = RemoteReplaySummary {
        server: options.server.clone(),
        scene_id: scene_id.clone(),
        frames,
        width: 0,
        height: 0,
        vals_per_frame: Vec::new(),
        stage_ms: BTreeMap::new(),
        round_trip_ms: Vec::new(),
        dropped_frames: 0,
        frames_lost: 0,
        lost_frames: Vec::new(),
        reconnects: 0,
        scenes_recreated: 0,
    };
    let bar = crate::mr::replay::progress_bar(options.progress, frames as u64);
    for i in 0..frames {
        let frame = recording.frame(i)?;
        let sent = Instant::now();
        let Some(rendered) = exchange(&mut stream, i, &frame).await? else {
            // The stream ended with this frame in flight: it is lost; the next goes on a new one.
            summary.frames_lost += 1;
            summary.lost_frames.push(i);
            if options.reconnect.is_zero() {
                bail!("frame {i}: the stream ended (no reconnecting with --reconnect-seconds 0)");
            }
            let (reopened, recreated) = connection.reopen_stream(scene_id, description, options.reconnect).await?;
            stream = reopened;
            configure(&mut stream, options).await?;
            summary.reconnects += 1;
            summary.scenes_recreated += u32::from(recreated);
            summary.scene_id = scene_id.clone();
            bar.inc(1);
            continue;
        };
        summary.round_trip_ms.push(sent.elapsed().as_secs_f64() * 1e3);
        (summary.width, summary.height) = (rendered.width, rendered.height);
        summary.vals_per_frame.push(rendered.val_count);
        summary.dropped_frames = rendered.dropped_frames;
        for t in &rendered.timings {
            summary.stage_ms.entry(t.stage.clone()).or_default().push(t.ms);
        }
        let Some(proto::rendered_frame::Image::Png(png)) = rendered.image else {
            bail!("frame {i}: expected a PNG image");
        };
        let path = composited_dir.join(format!("{i:04}.png"));
        std::fs::write(&path, png).with_context(|| format!("writing {}", path.display()))?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    stream.close().await;
    Ok(summary)
}

/// The `q`-quantile (0..=1) of `values` by the nearest-rank method; 0 when empty.
pub fn quantile(values: &[f64], q: f64) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let rank = (q * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn server_urls_are_checked() {
        assert!(Connection::new("http://127.0.0.1:8080", None).is_ok());
        assert!(Connection::new("http://127.0.0.1:8080/", None).is_ok());
        let error = |s: &str| Connection::new(s, None).err().expect("an error").to_string();
        assert!(error("https://example.com").contains("no TLS"));
        assert!(error("127.0.0.1:8080").contains("no scheme"));
        assert!(error("http://127.0.0.1:8080/v1").contains("root"));
        assert!(error("http://[::1").starts_with("--server"));
    }

    #[test]
    fn quantiles_use_the_nearest_rank() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(quantile(&v, 0.5), 50.0);
        assert_eq!(quantile(&v, 0.99), 99.0);
        assert_eq!(quantile(&v, 1.0), 100.0);
        assert_eq!(quantile(&[3.0], 0.99), 3.0);
        assert_eq!(quantile(&[], 0.5), 0.0);
    }

    #[test]
    fn server_errors_name_code_and_field() {
        let body = br#"{"error": {"code": "invalid_field", "message": "must be > 0", "field": "camera.width"}}"#;
        assert_eq!(
            server_error(StatusCode::BAD_REQUEST, body),
            "400 Bad Request: invalid_field: must be > 0 (field `camera.width`)"
        );
        assert_eq!(server_error(StatusCode::BAD_GATEWAY, b"oops"), "502 Bad Gateway: oops");
    }

    #[test]
    fn uploads_inline_the_meshes() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let description = upload_description(&root.join("fixtures/scenes/mr_bunny.json")).expect("uploads");
        let mesh = &description["meshes"][0];
        assert_eq!(mesh["obj"], "stanford-bunny.obj");
        assert!(mesh["obj_text"].as_str().is_some_and(|t| t.contains("\nf ")));
        let missing = upload_description(&root.join("fixtures/scenes/no-such.json")).expect_err("missing");
        assert!(missing.to_string().contains("no-such.json"));
    }

    #[test]
    fn asset_paths_are_made_relative_to_the_asset_directory() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let scene = root.join("fixtures/scenes/cornell_bunny_small.json");
        let description = asset_description(&scene, root).expect("inside");
        assert_eq!(description["meshes"][0]["obj"], "fixtures/meshes/cornell_box/CornellBox-Original.obj");
        let description = asset_description(&scene, &root.join("fixtures")).expect("inside");
        assert_eq!(description["meshes"][0]["obj"], "meshes/cornell_box/CornellBox-Original.obj");
        let outside = asset_description(&scene, &root.join("src")).expect_err("outside");
        assert!(outside.to_string().contains("outside the server's asset directory"), "{outside}");
    }
}

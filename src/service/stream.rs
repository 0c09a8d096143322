//! `GET /v1/scenes/{id}/stream`: the WebSocket stream of one scene.
//!
//! Frames are decoded and validated off the runtime, then rendered on the GPU thread
//! ([`super::gpu_worker`]) through the mixed-reality pipeline of `relume replay`
//! ([`crate::mr::MrPipeline`]): the frame's pixels become VALs, the scene's environment and
//! differential pass (`settings.environment`, `settings.mr`) apply, the virtual content is seen
//! from the frame's camera and composited over its colour, relit (or seen from a virtual camera
//! the client set), and the answer is a `RenderedFrame` ([`rendered_frame`]) whose timings
//! include the `environment` and `differential` stages when they ran. Control messages are
//! validated, applied to the stream's settings and acknowledged; every malformed or invalid
//! message gets an `Error` naming the field or limit and leaves the connection open. At most
//! one frame per stream is on the GPU, and a newer frame replaces one still waiting (latest
//! frame wins; the replaced one counts as dropped).

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::extract::ws::{CloseFrame, Message, WebSocket, WebSocketUpgrade, close_code};
use axum::extract::{Path, State};
use axum::response::Response;
use tokio::sync::oneshot;
use tokio_tungstenite::tungstenite;

use crate::gpu::GpuError;
use crate::renderer::Method;
use crate::renderer::budget::{self, BudgetController, FrameParameters};
use crate::rgbd::RgbdSettings;
use crate::scene::settings::{SceneAnalysis, SettingsDescription};
use crate::scene::{CameraDescription, LightDescription, Occlusion, Quality, TransformDescription};

use super::AppState;
use super::error::ApiError;
use super::gpu_worker::{RenderOutput, StreamFrameJob, WorkerError};
use super::scenes::SceneEntry;
use super::schedule::ClientId;
use super::wire::{
    self, ClientMessage, ControlMessage, ErrorCode, FrameImage, FrameMessage, RenderedFrame, ServerMessage,
    SettingsAck, StreamImageFormat, StreamQuality, WireError,
};

/// Opens the WebSocket stream of a scene.
///
/// 404 before the upgrade when there is no such scene. With `--token`, the handshake carries
/// the bearer token or, from a browser (which cannot set a WebSocket's headers), a ticket from
/// `POST /v1/tickets` as `?ticket=` or as the subprotocol `relume.ticket.<ticket>` offered
/// beside `relume.v1` (`Sec-WebSocket-Protocol: relume.v1, relume.ticket.<ticket>`), spent by
/// this handshake whatever its answer. A handshake that offers `relume.v1` gets it selected.
#[utoipa::path(
    get,
    path = "/v1/scenes/{id}/stream",
    tag = "scenes",
    params(
        ("id" = String, Path, description = "The scene's id"),
        ("ticket" = Option<String>, Query, description = "A single-use ticket from `POST /v1/tickets`, in place \
            of the bearer token; checked (and spent) whenever it is given"),
        ("quality" = Option<Quality>, Query, description = "The stream's quality level from its first frame \
            (default: the scene's `settings.quality`); a control message's `render.quality` changes it"),
        ("budget_ms" = Option<f32>, Query, description = "The stream's frame-time budget, ms, in [0.1, 600000] \
            (default: the scene's `settings.budget_ms`): frames move between the level's parameters and cheaper \
            or richer ones to hold it; a control message's `render.budget_ms` changes it"),
        ("Sec-WebSocket-Protocol" = Option<String>, Header, description = "`relume.v1` (selected when \
            offered), and optionally `relume.ticket.<ticket>`: a ticket in place of `?ticket=`, out of the URL"),
    ),
    responses(
        (status = 101, description = "WebSocket stream: one `relume.v1.Envelope` (proto/relume.proto) per \
            binary message. Each RGB-D frame is answered with the relit frame (`RenderedFrame`) or an \
            `Error`; each control message with a `SettingsAck` or an `Error`."),
        (status = 400, description = "Not a WebSocket upgrade request, a ticket given more than once, a \
            ticket subprotocol without `relume.v1` beside it, or an invalid `quality` or `budget_ms` (`field` \
            names it)",
            body = super::error::ErrorBody),
        (status = 401, description = "Missing or wrong bearer token, or an unknown, used or expired ticket",
            body = super::error::ErrorBody),
        super::error::UnknownScene,
        (status = 503, description = "Shutting down, or max_streams streams are open (`limit` names it)",
            body = super::error::ErrorBody),
    ),
    security((), ("bearer" = []), ("ticket" = []))
)]
pub async fn open_stream(
    State(state): State<Arc<AppState>>,
    client: ClientId,
    Path(id): Path<String>,
    uri: axum::http::Uri,
    upgrade: Result<WebSocketUpgrade, axum::extract::ws::rejection::WebSocketUpgradeRejection>,
) -> Result<Response, ApiError> {
    if state.shutting_down() {
        return Err(ApiError::shutting_down());
    }
    let scene = super::store::scene(&state, &id)
        .await?
        .ok_or_else(|| ApiError::not_found(format!("no scene with id `{id}`")))?;
    let start = stream_start(&uri).map_err(|e| ApiError::scene(&e, &state.assets))?;
    let upgrade = upgrade.map_err(|rejection| {
        ApiError::new(rejection.status(), super::error::Code::UpgradeRequired, rejection.body_text())
    })?;
    // Held from here, so that an upgrade that never completes frees its slot too.
    let open = state.open_stream()?;
    // Messages up to twice the limit reach the decoder, which answers with an error naming
    // `max_message_bytes`; larger ones close the connection (1009, message too big). This is
    // also the most a stream buffers of an incoming message.
    let transport_limit = transport_limit(&state.config.limits);
    let upgrade = upgrade.protocols([super::tickets::STREAM_PROTOCOL]);
    Ok(upgrade.max_message_size(transport_limit).max_frame_size(transport_limit).on_upgrade(move |socket| async move {
        let _open = open;
        Session::new(state.clone(), client, id, &scene, start).run(socket).await;
    }))
}

/// The level and budget a stream starts with (`?quality=`, `?budget_ms=`; `None`: the
/// scene's).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StreamStart {
    pub quality: Option<Quality>,
    pub budget_ms: Option<f32>,
}

/// The `quality` and `budget_ms` query parameters of a stream handshake, validated as a scene
/// file's `settings.quality` and `settings.budget_ms` are; other parameters are left alone.
pub fn stream_start(uri: &axum::http::Uri) -> Result<StreamStart, crate::scene::SceneError> {
    use crate::scene::SceneError;
    let mut start = StreamStart::default();
    for pair in uri.query().unwrap_or("").split('&') {
        let (key, value) = pair.split_once('=').unwrap_or((pair, ""));
        let value = percent_encoding::percent_decode_str(value).decode_utf8_lossy();
        match key {
            "quality" => {
                let level = Quality::ALL.into_iter().find(|q| q.name() == value).ok_or_else(|| {
                    let names: Vec<&str> = Quality::ALL.iter().map(|q| q.name()).collect();
                    SceneError::field("quality", format!("must be one of {}, got `{value}`", names.join(", ")))
                })?;
                start.quality = Some(level);
            }
            "budget_ms" => {
                let ms: f32 = value
                    .parse()
                    .map_err(|_| SceneError::field("budget_ms", format!("must be a number of ms, got `{value}`")))?;
                crate::scene::settings::validate_budget_ms(ms, "budget_ms")?;
                start.budget_ms = Some(ms);
            }
            _ => {}
        }
    }
    Ok(start)
}

/// The most bytes of one incoming message a stream buffers: `2 * max_message_bytes` (at least
/// 64 KiB).
pub fn transport_limit(limits: &super::Limits) -> usize {
    limits.max_message_bytes.saturating_mul(2).max(64 << 10)
}

/// A stream's settings, changed by control messages.
#[derive(Clone, Debug)]
struct Settings {
    /// A virtual camera to render from; `None` (the default): each frame's own camera.
    camera: Option<CameraDescription>,
    light: Option<LightDescription>,
    model_transforms: BTreeMap<u32, TransformDescription>,
    quality: StreamQuality,
    rgbd: RgbdSettings,
    /// The visibility mode the client set, over the level's.
    occlusion: Option<Occlusion>,
    glossy: bool,
    /// The quality level and the frame-time budget.
    level: Quality,
    budget_ms: Option<f32>,
}

/// A frame on the GPU thread.
struct InFlight {
    frame_id: u64,
    timestamp: f64,
    decode_ms: f64,
    quality: StreamQuality,
    /// What the frame runs at, and the stream's budget then.
    parameters: FrameParameters,
    /// The frame's indirect technique.
    method: Method,
    budget_ms: Option<f32>,
    answer: oneshot::Receiver<Result<RenderOutput, WorkerError>>,
}

struct Session {
    state: Arc<AppState>,
    /// Whose queue the stream's frames wait in.
    client: ClientId,
    /// The GPU worker the stream's frames go to.
    pin: super::workers::StreamPin,
    scene_id: String,
    mesh_count: usize,
    /// The scene's floating origin: the stream's cameras and lights are made relative to it.
    origin: glam::DVec3,
    /// The scene's level, what `QUALITY_LEVEL_UNSPECIFIED` goes back to; its analysis and
    /// file's settings, which a level is resolved from.
    scene_level: Quality,
    analysis: SceneAnalysis,
    described: SettingsDescription,
    settings: Settings,
    /// With a budget: what moves the frames between parameter sets.
    controller: Option<BudgetController>,
    in_flight: Option<InFlight>,
    /// The newest frame not yet submitted (and how long it took to decode, ms).
    waiting: Option<(FrameMessage, f64)>,
    dropped_frames: u64,
}

impl Session {
    fn new(
        state: Arc<AppState>,
        client: ClientId,
        scene_id: String,
        scene: &SceneEntry,
        start: StreamStart,
    ) -> Session {
        let resolved = &scene.info.resolved;
        let mut session = Session {
            pin: state.workers.pin(&scene_id),
            state,
            client,
            scene_id,
            mesh_count: scene.mesh_count,
            origin: scene.origin,
            settings: Settings {
                camera: None,
                light: scene.light.clone(),
                model_transforms: BTreeMap::new(),
                quality: StreamQuality { exposure: scene.exposure, ..StreamQuality::default() },
                rgbd: scene.settings.rgbd,
                occlusion: None,
                glossy: scene.settings.glossy,
                level: start.quality.unwrap_or(resolved.quality),
                budget_ms: start.budget_ms.or(resolved.budget_ms),
            },
            scene_level: resolved.quality,
            analysis: resolved.analysis.clone(),
            described: scene.described.clone(),
            controller: None,
            in_flight: None,
            waiting: None,
            dropped_frames: 0,
        };
        session.restart_controller();
        session
    }

    /// A new controller for the stream's level and budget (none without a budget).
    fn restart_controller(&mut self) {
        let s = &self.settings;
        self.controller = s.budget_ms.map(|ms| {
            let ladder = budget::ladder(&self.analysis, &self.described, false);
            BudgetController::at_level(ms, ladder, s.level)
        });
    }

    /// What the next frame runs at: the controller's parameters, else the level's.
    fn parameters(&self) -> FrameParameters {
        match &self.controller {
            Some(c) => c.parameters(),
            None => budget::level_parameters(self.settings.level, &self.analysis, &self.described),
        }
    }

    async fn run(mut self, mut socket: WebSocket) {
        tracing::info!(scene = %self.scene_id, "stream opened");
        let mut shutdown = self.state.shutdown_receiver();
        let timeouts = self.state.config.timeouts;
        let idle = Duration::from_secs(timeouts.stream_idle_seconds);
        let ping_every = Duration::from_secs(timeouts.stream_ping_seconds.max(1));
        let mut ping = tokio::time::interval_at(tokio::time::Instant::now() + ping_every, ping_every);
        let mut heard = tokio::time::Instant::now();
        loop {
            let answer = async {
                match self.in_flight.as_mut() {
                    Some(in_flight) => (&mut in_flight.answer).await,
                    None => std::future::pending().await,
                }
            };
            let replies = tokio::select! {
                message = socket.recv() => match message {
                    Some(Ok(message)) => {
                        heard = tokio::time::Instant::now();
                        match self.on_message(message).await {
                            Some(replies) => replies,
                            None => break,
                        }
                    }
                    Some(Err(error)) => {
                        tracing::debug!(scene = %self.scene_id, "stream transport error: {error}");
                        if too_big(error) {
                            self.state.metrics.record_stream_message("too_big");
                            let reason = format!(
                                "message over {} bytes (twice max_message_bytes)",
                                transport_limit(&self.state.config.limits)
                            );
                            close(&mut socket, close_code::SIZE, reason, idle).await;
                        }
                        break;
                    }
                    None => break,
                },
                result = answer => {
                    let in_flight = self.in_flight.take().expect("an answer comes only from a frame in flight");
                    let mut replies = vec![self.on_rendered(in_flight, result).await];
                    replies.extend(self.submit_waiting());
                    replies
                }
                _ = ping.tick() => {
                    match tokio::time::timeout(idle, socket.send(Message::Ping(Default::default()))).await {
                        Ok(Ok(())) => continue,
                        _ => break,
                    }
                }
                () = tokio::time::sleep_until(heard + idle) => {
                    tracing::info!(scene = %self.scene_id, "stream idle: closing it");
                    let reason = format!("no message for {} s (stream_idle_seconds)", idle.as_secs());
                    close(&mut socket, close_code::AWAY, reason, idle).await;
                    break;
                }
                () = async { let _ = shutdown.wait_for(|&stopping| stopping).await; } => {
                    let error = WireError::new(ErrorCode::ShuttingDown, None, "the server is shutting down");
                    let _ = tokio::time::timeout(idle, self.send(&mut socket, ServerMessage::Error(error))).await;
                    close(&mut socket, close_code::AWAY, "server shutting down".to_owned(), idle).await;
                    break;
                }
            };
            for reply in replies {
                // A client that does not read cannot hold the stream (and its buffers) forever.
                if !matches!(tokio::time::timeout(idle, self.send(&mut socket, reply)).await, Ok(Ok(()))) {
                    return;
                }
            }
        }
        tracing::info!(scene = %self.scene_id, dropped_frames = self.dropped_frames, "stream closed");
    }

    async fn send(&self, socket: &mut WebSocket, message: ServerMessage) -> Result<(), axum::Error> {
        if let ServerMessage::Error(error) = &message {
            self.state.metrics.record_stream_error(error.code_name());
        }
        socket.send(Message::Binary(wire::encode(message).into())).await
    }

    /// The replies to one client message; `None` to end the session.
    async fn on_message(&mut self, message: Message) -> Option<Vec<ServerMessage>> {
        let bytes = match message {
            Message::Binary(bytes) => bytes,
            Message::Text(_) => {
                self.state.metrics.record_stream_message("invalid");
                let message = "text messages are not part of the protocol: send one binary protobuf Envelope";
                return Some(vec![ServerMessage::Error(WireError::new(ErrorCode::Malformed, None, message))]);
            }
            Message::Close(_) => return None,
            Message::Ping(_) | Message::Pong(_) => return Some(Vec::new()),
        };
        let limits = self.state.config.limits;
        let started = Instant::now();
        // Decoding copies and converts whole images (and may inflate a PNG): off the runtime.
        let decoded = tokio::task::spawn_blocking(move || wire::decode(&bytes, &limits)).await;
        let decode_ms = started.elapsed().as_secs_f64() * 1e3;
        let decoded = match decoded {
            Ok(decoded) => decoded,
            Err(panic) => {
                tracing::error!("the stream decoder panicked: {panic}");
                Err(WireError::new(ErrorCode::Internal, None, "internal error (logged on the server)"))
            }
        };
        let replies = match decoded {
            Ok(ClientMessage::Frame(frame)) => {
                self.state.metrics.record_stream_message("rgbd_frame");
                self.on_frame(frame, decode_ms)
            }
            Ok(ClientMessage::Control(control)) => {
                self.state.metrics.record_stream_message("control");
                vec![self.on_control(control)]
            }
            Err(error) => {
                self.state.metrics.record_stream_message("invalid");
                vec![ServerMessage::Error(error)]
            }
        };
        Some(replies)
    }

    fn on_frame(&mut self, frame: FrameMessage, decode_ms: f64) -> Vec<ServerMessage> {
        let limits = self.state.config.limits;
        if let Err(error) = wire::check_frame_vals(&frame.frame.intrinsics, &self.settings.rgbd, &limits) {
            return vec![ServerMessage::Error(error.with_frame(frame.frame_id))];
        }
        if let Some((replaced, _)) = self.waiting.replace((frame, decode_ms)) {
            tracing::debug!(frame_id = replaced.frame_id, "frame replaced by a newer one before rendering");
            self.dropped_frames += 1;
            self.state.metrics.record_dropped_frame();
        }
        if self.in_flight.is_none() { self.submit_waiting().into_iter().collect() } else { Vec::new() }
    }

    /// Sends the waiting frame to the GPU thread; an error reply when it cannot be queued.
    fn submit_waiting(&mut self) -> Option<ServerMessage> {
        let (message, decode_ms) = self.waiting.take()?;
        let mut parameters = self.parameters();
        let s = &self.settings;
        parameters.occlusion = s.occlusion.unwrap_or(parameters.occlusion);
        // `reference` asks for the exact reference, unless the client chose another method.
        let method = match (s.level, s.quality.method) {
            (Quality::Reference, Method::Sparse) => Method::Exact,
            (_, method) => method,
        };
        let rgbd = RgbdSettings { grid_step: (s.rgbd.grid_step * parameters.vals_step).min(64), ..s.rgbd };
        let job = StreamFrameJob {
            frame_id: message.frame_id,
            frame: message.frame,
            camera: s.camera.as_ref().map(|c| c.to_camera(self.origin)),
            light: s.light.as_ref().map(|l| l.to_spot_light(self.origin)),
            model_transforms: s.model_transforms.iter().map(|(&mesh, t)| (mesh, t.to_matrix())).collect(),
            method,
            component: s.quality.component,
            exposure: s.quality.exposure,
            format: s.quality.format,
            rgbd,
            occlusion: parameters.occlusion,
            near_field: parameters.near_field,
            camera_lod: parameters.camera_lod(),
            receivers_step: parameters.receivers_step,
            glossy: s.glossy,
        };
        let (frame_id, timestamp) = (job.frame_id, job.frame.timestamp);
        match self.state.workers.try_render_stream_frame(&mut self.pin, self.client, &self.scene_id, job) {
            Ok(answer) => {
                let budget_ms = s.budget_ms;
                self.in_flight = Some(InFlight {
                    frame_id,
                    timestamp,
                    decode_ms,
                    quality: s.quality,
                    parameters,
                    method,
                    budget_ms,
                    answer,
                });
                None
            }
            Err(error) => {
                self.dropped_frames += 1;
                self.state.metrics.record_dropped_frame();
                Some(ServerMessage::Error(WireError::from(error).with_frame(frame_id)))
            }
        }
    }

    async fn on_rendered(
        &mut self,
        in_flight: InFlight,
        result: Result<Result<RenderOutput, WorkerError>, oneshot::error::RecvError>,
    ) -> ServerMessage {
        let frame_id = in_flight.frame_id;
        let output = match result {
            Ok(Ok(output)) => output,
            Ok(Err(error)) => return ServerMessage::Error(WireError::from(error).with_frame(frame_id)),
            Err(_) => return ServerMessage::Error(WireError::from(WorkerError::Stopped).with_frame(frame_id)),
        };
        // The controller learns the frame's time where the frame ran at its current rung (not
        // one left behind by a control message while the frame was in flight).
        let ran_at =
            |c: &BudgetController| FrameParameters { occlusion: c.parameters().occlusion, ..in_flight.parameters };
        if let Some(c) = self.controller.as_mut()
            && c.parameters() == ran_at(c)
        {
            c.observe(output.gpu_ms);
        }
        self.state.metrics.record_frame_quality(
            output.frame.error_estimate.map(|e| e.rel_rmse),
            &in_flight.parameters,
            in_flight.budget_ms.map(|b| output.gpu_ms > f64::from(b)),
        );
        let dropped_frames = self.dropped_frames;
        let encoded = tokio::task::spawn_blocking(move || rendered_frame(&in_flight, output, dropped_frames)).await;
        match encoded {
            Ok(Ok(frame)) => ServerMessage::Frame(frame),
            Ok(Err(error)) => ServerMessage::Error(error.with_frame(frame_id)),
            Err(panic) => {
                tracing::error!("encoding a stream frame panicked: {panic}");
                ServerMessage::Error(WireError::new(ErrorCode::Internal, None, "internal error").with_frame(frame_id))
            }
        }
    }

    /// Validates the whole control message against the scene, then applies all of it.
    fn on_control(&mut self, control: ControlMessage) -> ServerMessage {
        let request_id = control.request_id;
        match self.apply(control) {
            Ok(applied) => ServerMessage::Ack(SettingsAck { request_id, applied }),
            Err(error) => ServerMessage::Error(error.with_request(request_id)),
        }
    }

    fn apply(&mut self, control: ControlMessage) -> Result<Vec<String>, WireError> {
        let mut next = self.settings.clone();
        let mut applied = Vec::new();
        if let Some(camera) = control.camera {
            next.camera = Some(camera);
            applied.push("camera");
        }
        if let Some(light) = control.light {
            next.light = Some(light.apply(self.settings.light.as_ref(), "control.light").map_err(|e| {
                WireError::new(ErrorCode::InvalidField, e.field_path().map(str::to_owned), e.to_string())
            })?);
            applied.push("light");
        }
        if !control.model_transforms.is_empty() {
            for (i, (mesh, transform)) in control.model_transforms.into_iter().enumerate() {
                if mesh as usize >= self.mesh_count {
                    return Err(WireError::invalid(
                        format!("control.model_transforms[{i}].mesh_index"),
                        format!("the scene has {} meshes, got index {mesh}", self.mesh_count),
                    ));
                }
                next.model_transforms.insert(mesh, transform);
            }
            applied.push("model_transforms");
        }
        if let Some(quality) = control.quality {
            next.quality = quality;
            applied.push("quality");
        }
        if let Some(rgbd) = control.rgbd {
            next.rgbd = rgbd.apply(&self.settings.rgbd, "control.rgbd")?;
            applied.push("rgbd");
        }
        let mut restart = false;
        if let Some(render) = control.render {
            if let Some(occlusion) = render.occlusion {
                next.occlusion = occlusion;
            }
            if let Some(glossy) = render.glossy {
                next.glossy = glossy;
            }
            if let Some(level) = render.quality {
                next.level = level.unwrap_or(self.scene_level);
                restart |= next.level != self.settings.level;
            }
            if let Some(budget_ms) = render.budget_ms {
                next.budget_ms = budget_ms;
                restart |= budget_ms.is_some() != self.settings.budget_ms.is_some();
            }
            applied.push("render");
        }
        let budget_changed = next.budget_ms != self.settings.budget_ms;
        self.settings = next;
        if restart {
            self.restart_controller();
        } else if let (true, Some(c), Some(ms)) = (budget_changed, self.controller.as_mut(), self.settings.budget_ms) {
            c.set_budget_ms(ms);
        }
        Ok(applied.into_iter().map(str::to_owned).collect())
    }
}

/// The `RenderedFrame` of a finished frame: the composite, or the quality's component tone
/// mapped, encoded, with the decode, queue, GPU stage, composite and encode times.
fn rendered_frame(in_flight: &InFlight, output: RenderOutput, dropped_frames: u64) -> Result<RenderedFrame, WireError> {
    let started = Instant::now();
    let (width, height) = (output.frame.indirect.width, output.frame.indirect.height);
    let internal = |e: &dyn std::fmt::Display| WireError::new(ErrorCode::Internal, None, e.to_string());
    let encoded = match (&output.composited, in_flight.quality.format) {
        (Some((rgb, _)), StreamImageFormat::Png) => {
            FrameImage::Png(crate::image::encode_rgb8_png(width, height, rgb).map_err(|e| internal(&e))?)
        }
        (Some((rgb, _)), StreamImageFormat::Rgba8) => {
            FrameImage::Rgba8(rgb.iter().flat_map(|&[r, g, b]| [r, g, b, 255]).collect())
        }
        (None, format) => {
            let image = in_flight.quality.component.of(&output.frame);
            let exposure = in_flight.quality.exposure.unwrap_or_else(|| image.auto_exposure());
            match format {
                StreamImageFormat::Png => FrameImage::Png(image.encode_png(exposure).map_err(|e| internal(&e))?),
                StreamImageFormat::Rgba8 => FrameImage::Rgba8(image.tone_map_rgba8(exposure)),
            }
        }
    };
    let mut timings = vec![("decode".to_owned(), in_flight.decode_ms), ("queue".to_owned(), output.queue_ms)];
    timings.extend(output.frame.timings.stages.iter().cloned());
    if let Some((_, composite_ms)) = output.composited {
        timings.push((crate::mr::COMPOSITE_STAGE.to_owned(), composite_ms));
    }
    timings.push(("encode".to_owned(), started.elapsed().as_secs_f64() * 1e3));
    Ok(RenderedFrame {
        frame_id: in_flight.frame_id,
        timestamp: in_flight.timestamp,
        width,
        height,
        image: encoded,
        timings,
        val_count: output.frame.val_count,
        dropped_frames,
        error_estimate: output.frame.error_estimate,
        quality: in_flight.parameters.level,
        parameters: in_flight.parameters.pairs_with_method(in_flight.method),
        budget_ms: in_flight.budget_ms,
    })
}

/// Sends a Close frame (within `timeout`); the connection is dropped after it.
async fn close(socket: &mut WebSocket, code: u16, reason: String, timeout: Duration) {
    let close = CloseFrame { code, reason: reason.into() };
    let _ = tokio::time::timeout(timeout, socket.send(Message::Close(Some(close)))).await;
}

/// Whether a transport error is a message or frame over the transport limit.
fn too_big(error: axum::Error) -> bool {
    error
        .into_inner()
        .downcast_ref::<tungstenite::Error>()
        .is_some_and(|e| matches!(e, tungstenite::Error::Capacity(_)))
}

impl From<WorkerError> for WireError {
    /// The stream error for a failed GPU job.
    fn from(error: WorkerError) -> WireError {
        match error {
            WorkerError::QueueFull { waiting, limit, .. } => WireError::limit(
                limit,
                None,
                format!("frame dropped: the GPU queue is full ({waiting} renders waiting)"),
            ),
            WorkerError::SceneNotFound(id) => {
                WireError::new(ErrorCode::SceneNotFound, None, format!("the scene `{id}` has been deleted"))
            }
            WorkerError::Stopped => WireError::new(ErrorCode::ShuttingDown, None, "the GPU thread has stopped"),
            error @ WorkerError::DeviceLost => {
                WireError::new(ErrorCode::Internal, None, format!("frame dropped: {error}; send the next"))
            }
            // A frame over the device's buffer limits (`brute-force-ism`'s table, named in
            // `what`): the client can ask for less, as the HTTP route's 400 says.
            WorkerError::Gpu(GpuError::TooLarge { what, needed, limit }) => WireError::new(
                ErrorCode::LimitExceeded,
                None,
                format!("{what} needs {needed} bytes of GPU memory, over the device's limit of {limit}"),
            ),
            error @ (WorkerError::Gpu(_) | WorkerError::Panicked(_)) => {
                tracing::error!("stream frame failed: {error}");
                WireError::new(ErrorCode::Internal, None, "internal error (logged on the server)")
            }
        }
    }
}

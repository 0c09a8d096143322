//! The HTTP API: routes, handlers and the OpenAPI document generated from them (committed as
//! `proto/openapi.json`; `tests/integration/service.rs` keeps the two equal).
//!
//! Every error answer is JSON `{"error": {"code", "message", "field"?, "limit"?}}`
//! ([`ApiError`]), including unknown routes, wrong methods and bodies over `max_body_bytes`.

use std::sync::Arc;
use std::time::Instant;

use axum::body::Body;
use axum::extract::rejection::PathRejection;
use axum::extract::{MatchedPath, Path, Request, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::{Json, Router};
use http_body_util::BodyExt;
use utoipa::OpenApi;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use crate::gpu::timing::TimingSource;
use crate::scene::parse_json;

use super::AppState;
use super::api::{Health, ImageFormat, RenderRequest, SceneInfo, SceneRequest};
use super::config::limit;
use super::error::{ApiError, Code, ErrorBody, Unauthorized, UnknownScene};
use super::gpu_worker::{RenderJob, RenderOutput, WorkerError};
use super::schedule::ClientId;
use super::{ready, recordings, store, stream, tickets, viewer};

#[derive(OpenApi)]
#[openapi(
    info(
        title = "relume",
        description = "One-bounce indirect light from thousands of virtual area lights, rendered on \
            the GPU. Scenes are created from a scene description (the scene file format of \
            docs/scene-format.md, mesh paths relative to the server's asset directory, or OBJ text inline), \
            then rendered with a camera, light overrides and quality settings. Errors are JSON \
            `{\"error\": {\"code\", \"message\", \"field\", \"limit\"}}`.",
        license(name = "MIT OR Apache-2.0")
    ),
    modifiers(&BearerAuth),
    tags(
        (name = "scenes", description = "Scenes and their renders"),
        (name = "recordings", description = "RGB-D recordings held by the server, frame by frame as stream messages"),
        (name = "tickets", description = "Single-use tickets that open a stream without the bearer token, for \
            browsers (which cannot set a WebSocket's headers)"),
        (name = "service", description = "Health and metrics")
    )
)]
struct ApiDoc;

/// Declares the optional bearer token, and the ticket a stream may present instead.
struct BearerAuth;

impl utoipa::Modify for BearerAuth {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        use utoipa::openapi::security::{ApiKey, ApiKeyValue, HttpAuthScheme, HttpBuilder, SecurityScheme};
        let components = openapi.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            "bearer",
            SecurityScheme::Http(
                HttpBuilder::new()
                    .scheme(HttpAuthScheme::Bearer)
                    .description(Some("Required on /v1 routes when the server runs with --token / RELUME_TOKEN."))
                    .build(),
            ),
        );
        components.add_security_scheme(
            "ticket",
            SecurityScheme::ApiKey(ApiKey::Query(ApiKeyValue::with_description(
                tickets::TICKET_PARAMETER,
                "A single-use ticket from POST /v1/tickets, in place of the bearer token on a stream's \
                 WebSocket handshake (browsers cannot set its headers).",
            ))),
        );
    }
}

/// The routes, documented; `/v1` ones behind the token check, streams also open to a ticket.
fn routes(state: Option<Arc<AppState>>) -> OpenApiRouter<Arc<AppState>> {
    let mut v1 = OpenApiRouter::new()
        .routes(routes!(create_scene))
        .routes(routes!(get_scene, delete_scene))
        .routes(routes!(render_scene))
        .routes(routes!(tickets::issue_ticket))
        .routes(routes!(recordings::list_recordings))
        .routes(routes!(recordings::recording_frame));
    let mut streams = OpenApiRouter::new().routes(routes!(stream::open_stream));
    if let Some(state) = state {
        v1 = v1.route_layer(middleware::from_fn_with_state(state.clone(), require_token));
        streams = streams.route_layer(middleware::from_fn_with_state(state, require_token_or_ticket));
    }
    OpenApiRouter::with_openapi(ApiDoc::openapi())
        .routes(routes!(healthz))
        .routes(routes!(metrics))
        .merge(v1)
        .merge(streams)
}

/// The OpenAPI 3.1 document of the API.
pub fn openapi() -> utoipa::openapi::OpenApi {
    routes(None).into_openapi()
}

/// [`openapi`] as pretty JSON with a final newline: the contents of `proto/openapi.json`.
pub fn openapi_json() -> String {
    let mut json = openapi().to_pretty_json().expect("the OpenAPI document serializes");
    json.push('\n');
    json
}

/// The service's router.
pub fn router(state: Arc<AppState>) -> Router {
    let (router, api) = routes(Some(state.clone())).split_for_parts();
    let api = Arc::new(api);
    router
        .merge(viewer::routes())
        .route("/readyz", axum::routing::get(ready::readyz))
        .route(
            "/openapi.json",
            axum::routing::get(move || {
                let api = api.clone();
                async move { Json(api.as_ref().clone()) }
            }),
        )
        .fallback(|| async { ApiError::not_found("no such route") })
        .method_not_allowed_fallback(|| async {
            ApiError::new(StatusCode::METHOD_NOT_ALLOWED, Code::MethodNotAllowed, "method not allowed on this route")
        })
        .layer(middleware::from_fn_with_state(state.clone(), refuse_large_bodies))
        .layer(middleware::from_fn_with_state(state.clone(), observe))
        .with_state(state)
}

/// Refuses at once, from its `Content-Length`, a request whose body is over `max_body_bytes`
/// (413 `limit_exceeded`), on any route: nothing of the body is read, and a client that sent
/// `Expect: 100-continue` is not told to go on. Bodies without a length are checked while
/// they are read ([`read_body`]).
async fn refuse_large_bodies(State(state): State<Arc<AppState>>, request: Request, next: Next) -> Response {
    match too_large(&state, request.body()) {
        Some(error) => error.into_response(),
        None => next.run(request).await,
    }
}

/// The 413 for a body whose announced length is over `max_body_bytes`.
fn too_large(state: &AppState, body: &Body) -> Option<ApiError> {
    use axum::body::HttpBody as _;
    let max = state.config.limits.max_body_bytes;
    let announced = body.size_hint().lower();
    (announced > max as u64).then(|| {
        ApiError::limit(
            limit::MAX_BODY_BYTES,
            None,
            format!("the request body is {announced} bytes (Content-Length), over the limit of {max} bytes"),
        )
    })
}

/// Logs every request and records its latency by matched route.
async fn observe(State(state): State<Arc<AppState>>, request: Request, next: Next) -> Response {
    let started = Instant::now();
    let method = method_label(request.method());
    let route = request.extensions().get::<MatchedPath>().map_or("unmatched", |m| m.as_str()).to_owned();
    let response = next.run(request).await;
    let seconds = started.elapsed().as_secs_f64();
    let status = response.status().as_u16();
    state.metrics.record_request(&route, method, status, seconds);
    if route == "/metrics" || route == "/healthz" {
        tracing::debug!(%method, route, status, ms = seconds * 1e3, "request");
    } else {
        tracing::info!(%method, route, status, ms = seconds * 1e3, "request");
    }
    response
}

/// The request's method as a metrics label and in the log: one of the standard methods, or
/// `other`, so that invented methods cannot grow `/metrics`. Routes are labelled by their
/// pattern (`MatchedPath`) or `unmatched`, a closed set too.
fn method_label(method: &axum::http::Method) -> &'static str {
    match method.as_str() {
        "GET" => "GET",
        "HEAD" => "HEAD",
        "POST" => "POST",
        "PUT" => "PUT",
        "DELETE" => "DELETE",
        "OPTIONS" => "OPTIONS",
        "PATCH" => "PATCH",
        "CONNECT" => "CONNECT",
        "TRACE" => "TRACE",
        _ => "other",
    }
}

/// Refuses `/v1` requests without the configured bearer token.
async fn require_token(State(state): State<Arc<AppState>>, request: Request, next: Next) -> Response {
    match authorize(&state, &request, false) {
        Ok(()) => next.run(request).await,
        Err(error) => error.into_response(),
    }
}

/// Refuses stream handshakes with neither the configured bearer token nor a valid ticket.
async fn require_token_or_ticket(State(state): State<Arc<AppState>>, request: Request, next: Next) -> Response {
    match authorize(&state, &request, true) {
        Ok(()) => next.run(request).await,
        Err(error) => error.into_response(),
    }
}

/// The one check of who may use a `/v1` route: where `tickets` are accepted (stream
/// handshakes) and the handshake presents a ticket (`?ticket=` or a `relume.ticket.`
/// subprotocol), that ticket, spent here, valid or not, and `Authorization` is not looked at; otherwise `Authorization: Bearer <token>` when the server has a
/// token. 401 `unauthorized` when neither holds.
fn authorize(state: &AppState, request: &Request, tickets: bool) -> Result<(), ApiError> {
    let unauthorized = |message: &str| ApiError::new(StatusCode::UNAUTHORIZED, Code::Unauthorized, message);
    if tickets && let Some(ticket) = tickets::presented(request.uri(), request.headers())? {
        if state.tickets.redeem(&ticket) {
            return Ok(());
        }
        return Err(unauthorized(
            "unknown, used or expired ticket (POST /v1/tickets issues one; each opens one stream)",
        ));
    }
    let Some(token) = &state.config.token else {
        return Ok(());
    };
    let given = request.headers().get(header::AUTHORIZATION).and_then(|v| v.to_str().ok()).and_then(bearer_token);
    if given.is_some_and(|given| constant_time_eq(given.as_bytes(), token.as_bytes())) {
        Ok(())
    } else if tickets {
        Err(unauthorized(
            "missing or wrong bearer token (Authorization: Bearer <token>, or a ticket from POST /v1/tickets as \
             ?ticket= or Sec-WebSocket-Protocol: relume.v1, relume.ticket.<ticket>)",
        ))
    } else {
        Err(unauthorized("missing or wrong bearer token (Authorization: Bearer <token>)"))
    }
}

/// The token of an `Authorization: Bearer <token>` value. The scheme is case-insensitive
/// (RFC 7235, section 2.1: `bearer`, `BEARER`) and separated from the token by one or more
/// spaces.
fn bearer_token(value: &str) -> Option<&str> {
    let (scheme, token) = value.split_once(' ')?;
    scheme.eq_ignore_ascii_case("bearer").then(|| token.trim_start_matches(' '))
}

/// Equality whose time does not depend on where the inputs differ.
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// The body, refused with 413 past `max_body_bytes` (checked while reading, not trusted from
/// `Content-Length`) and with 408 when it takes longer than `body_timeout_seconds`.
async fn read_body(state: &AppState, body: Body) -> Result<bytes::Bytes, ApiError> {
    if let Some(error) = too_large(state, &body) {
        return Err(error);
    }
    let max = state.config.limits.max_body_bytes;
    let too_large =
        || ApiError::limit(limit::MAX_BODY_BYTES, None, format!("the request body is over the limit of {max} bytes"));
    let seconds = state.config.timeouts.body_timeout_seconds;
    let collected = tokio::time::timeout(
        std::time::Duration::from_secs(seconds),
        http_body_util::Limited::new(body, max).collect(),
    )
    .await
    .map_err(|_| {
        ApiError::new(
            StatusCode::REQUEST_TIMEOUT,
            Code::RequestTimeout,
            format!("the request body did not arrive within {seconds} s (body_timeout_seconds)"),
        )
    })?;
    match collected {
        Ok(collected) => Ok(collected.to_bytes()),
        Err(error) if error.downcast_ref::<http_body_util::LengthLimitError>().is_some() => Err(too_large()),
        Err(error) => {
            Err(ApiError::new(StatusCode::BAD_REQUEST, Code::InvalidJson, format!("cannot read the body: {error}")))
        }
    }
}

fn utf8(bytes: &[u8]) -> Result<&str, ApiError> {
    std::str::from_utf8(bytes)
        .map_err(|e| ApiError::new(StatusCode::BAD_REQUEST, Code::InvalidJson, format!("the body is not UTF-8: {e}")))
}

fn scene_id(path: Result<Path<String>, PathRejection>) -> Result<String, ApiError> {
    path.map(|Path(id)| id).map_err(|_| ApiError::not_found("no scene with that id"))
}

fn unknown_scene(id: &str) -> ApiError {
    ApiError::not_found(format!("no scene with id `{id}`"))
}

/// Health of the service.
///
/// 503 while shutting down.
#[utoipa::path(
    get,
    path = "/healthz",
    tag = "service",
    responses(
        (status = 200, description = "Serving", body = Health),
        (status = 503, description = "Shutting down", body = Health),
    )
)]
async fn healthz(State(state): State<Arc<AppState>>) -> (StatusCode, Json<Health>) {
    let stopping = state.shutting_down();
    let health = Health {
        status: if stopping { "shutting_down" } else { "ok" }.to_owned(),
        adapter: state.workers.adapter(),
        scenes: state.scenes.len(),
        queue_depth: state.workers.queue_depth(),
        limits: state.config.limits,
    };
    (if stopping { StatusCode::SERVICE_UNAVAILABLE } else { StatusCode::OK }, Json(health))
}

/// Prometheus metrics.
///
/// Request and frame latency histograms, queue depth, rejected renders, dropped frames, GPU
/// time per stage.
#[utoipa::path(
    get,
    path = "/metrics",
    tag = "service",
    responses((status = 200, description = "Prometheus text format 0.0.4", body = String,
        content_type = "text/plain; version=0.0.4"))
)]
async fn metrics(State(state): State<Arc<AppState>>) -> impl IntoResponse {
    let text = state.metrics_text();
    ([(header::CONTENT_TYPE, "text/plain; version=0.0.4; charset=utf-8")], text)
}

/// Creates a scene from a scene description.
///
/// Mesh (`obj`, `gltf`) and texture paths are relative to the server's asset directory and may not leave it; a mesh may instead carry its OBJ text
/// in `obj_text` (no `mtllib`; materials via `material`). The body may also be a whole scene
/// from one glTF file in the asset directory (a top-level `gltf` field: its meshes, spot light
/// and camera, with relume's settings). Loading (sparse point placement) happens before the
/// answer.
#[utoipa::path(
    post,
    path = "/v1/scenes",
    tag = "scenes",
    request_body(content = SceneRequest, description = "A scene description, or a whole glTF scene (docs/scene-format.md)"),
    responses(
        (status = 201, description = "Created", body = SceneInfo,
            headers(("Location" = String, description = "/v1/scenes/{id}"))),
        (status = 400, description = "Invalid JSON, field, mesh or path (`field` names it), or over \
            max_vals, max_frame_side, max_pixels, max_sparse_points, max_triangles or max_scenes \
            (`limit` names it)", body = ErrorBody),
        Unauthorized,
        (status = 413, description = "Over max_body_bytes or max_mesh_bytes", body = ErrorBody),
        (status = 503, description = "Shutting down", body = ErrorBody),
    ),
    security((), ("bearer" = []))
)]
async fn create_scene(State(state): State<Arc<AppState>>, body: Body) -> Result<Response, ApiError> {
    if state.shutting_down() {
        return Err(ApiError::shutting_down());
    }
    let bytes = read_body(&state, body).await?;
    let reservation = state.scenes.reserve()?;
    let id = reservation.id.clone();
    let info = store::load_scene(&state, reservation, bytes, true).await?.info.clone();
    let location = HeaderValue::from_str(&format!("/v1/scenes/{id}")).map_err(ApiError::internal)?;
    Ok((StatusCode::CREATED, [(header::LOCATION, location)], Json(info)).into_response())
}

/// The scene's summary.
#[utoipa::path(
    get,
    path = "/v1/scenes/{id}",
    tag = "scenes",
    params(("id" = String, Path, description = "The scene's id")),
    responses(
        (status = 200, description = "The scene", body = SceneInfo),
        Unauthorized,
        UnknownScene,
    ),
    security((), ("bearer" = []))
)]
async fn get_scene(
    State(state): State<Arc<AppState>>,
    id: Result<Path<String>, PathRejection>,
) -> Result<Json<SceneInfo>, ApiError> {
    let id = scene_id(id)?;
    let entry = store::scene(&state, &id).await?.ok_or_else(|| unknown_scene(&id))?;
    Ok(Json(entry.info.clone()))
}

/// Deletes the scene and frees its GPU memory.
///
/// Renders of it still queued fail with 404; its streams get `ERROR_CODE_SCENE_NOT_FOUND`.
#[utoipa::path(
    delete,
    path = "/v1/scenes/{id}",
    tag = "scenes",
    params(("id" = String, Path, description = "The scene's id")),
    responses(
        (status = 204, description = "Deleted"),
        Unauthorized,
        UnknownScene,
    ),
    security((), ("bearer" = []))
)]
async fn delete_scene(
    State(state): State<Arc<AppState>>,
    id: Result<Path<String>, PathRejection>,
) -> Result<StatusCode, ApiError> {
    let id = scene_id(id)?;
    let stored = state.store.as_ref().map(|store| store.remove(&id)).transpose().map_err(ApiError::internal)?;
    if state.scenes.remove(&id).is_none() && stored != Some(true) {
        return Err(unknown_scene(&id));
    }
    state.workers.remove_scene(&id).await?;
    tracing::info!(scene = %id, "scene deleted");
    Ok(StatusCode::NO_CONTENT)
}

/// Renders the scene.
///
/// The body is optional (absent or `{}`: the scene's camera and light, sparse, PNG). The answer
/// is the image; its size, VAL count and per-stage times are in headers
/// (`Server-Timing`: `queue`, each GPU stage, `gpu` (the whole frame on the GPU thread),
/// `encode`, `total`, in ms).
#[utoipa::path(
    post,
    path = "/v1/scenes/{id}/render",
    tag = "scenes",
    params(("id" = String, Path, description = "The scene's id")),
    request_body(content = Option<RenderRequest>, description = "Camera, light overrides and quality; all optional"),
    responses(
        (status = 200, description = "The image: `image/png` (format `png`: 8-bit sRGB after exposure) or \
            `application/octet-stream` (format `f32`: linear radiance, W/(m² sr), RGBA f32 little-endian, \
            rows from the top, alpha = coverage)",
            content(("image/png"), ("application/octet-stream")),
            headers(
                ("Server-Timing" = String, description = "Per-stage times, e.g. `queue;dur=0.1, gather;dur=5.2, total;dur=9.8`"),
                ("X-Relume-Width" = u32, description = "Image width, pixels"),
                ("X-Relume-Height" = u32, description = "Image height, pixels"),
                ("X-Relume-Val-Count" = u32, description = "VALs with non-zero flux in this frame"),
                ("X-Relume-Exposure" = f32, description = "The exposure of a PNG"),
                ("X-Relume-Timing-Source" = String, description = "`gpu_timestamps` or `wall_clock`"),
                ("X-Relume-Quality" = String, description = "The level the render ran at"),
                ("X-Relume-Parameters" = String, description = "What it ran at, `name=value` pairs separated \
                    by `; `: `level`, `method` (the indirect technique), `visibility`, `near_field`, `vals_step`, `resolution_scale`, `camera_detail`, `receivers_step`"),
                ("X-Relume-Error-Estimate" = f64, description = "Estimated relative RMSE of the indirect light \
                    against the exact reference (src/renderer/estimate.rs); absent when the render has none"),
                ("X-Relume-Error-Estimate-Spread" = f64, description = "The estimate's standard error"),
                ("X-Relume-Budget-Ms" = f32, description = "The frame-time budget, when one was given"),
                ("X-Relume-Budget-Met" = bool, description = "Whether the frame's time on the GPU thread was \
                    within the budget"),
            )),
        (status = 400, description = "Invalid JSON or field (`field` names it), or over max_frame_side or \
            max_pixels", body = ErrorBody),
        Unauthorized,
        UnknownScene,
        (status = 413, description = "Over max_body_bytes", body = ErrorBody),
        (status = 408, description = "The body did not arrive within body_timeout_seconds", body = ErrorBody),
        (status = 503, description = "The client's queue (max_client_queue) or the whole render queue \
            (max_queue) is full, or the server is shutting down",
            body = ErrorBody, headers(("Retry-After" = u32,
                description = "Seconds, when the queue is full: the measured queue wait"))),
    ),
    security((), ("bearer" = []))
)]
async fn render_scene(
    State(state): State<Arc<AppState>>,
    client: ClientId,
    id: Result<Path<String>, PathRejection>,
    body: Body,
) -> Result<Response, ApiError> {
    let started = Instant::now();
    let id = scene_id(id)?;
    if state.shutting_down() {
        return Err(ApiError::shutting_down());
    }
    let entry = store::scene(&state, &id).await?.ok_or_else(|| unknown_scene(&id))?;
    let bytes = read_body(&state, body).await?;
    let text = utf8(&bytes)?;
    let request: RenderRequest = if text.trim().is_empty() {
        RenderRequest::default()
    } else {
        parse_json(text).map_err(|e| ApiError::scene(&e, &state.assets))?
    };
    let camera = request.camera.as_ref().unwrap_or(&entry.camera);
    if request.camera.is_some() {
        camera.validate("camera").map_err(|e| ApiError::scene(&e, &state.assets))?;
    }
    state.config.limits.check_image(camera.width, camera.height, "camera")?;
    let light = match &request.light {
        Some(light) => {
            Some(light.apply(entry.light.as_ref(), "light").map_err(|e| ApiError::scene(&e, &state.assets))?)
        }
        None => entry.light.clone(),
    };
    let quality = request.quality;
    quality.validate("quality").map_err(|e| ApiError::scene(&e, &state.assets))?;
    let resolved = &entry.info.resolved;
    let level = quality.level.unwrap_or(resolved.quality);
    let parameters = crate::renderer::budget::level_parameters(level, &resolved.analysis, &entry.described);
    let budget_ms = quality.budget_ms.or(resolved.budget_ms);
    // The level's technique: the exact reference at `reference`, the GPU estimator where the
    // scene's measured level names it, else the sparse method.
    let (technique, draws) = crate::scene::settings::technique(level, &entry.described);
    let method = quality.method.map_or(technique.into(), Into::into);
    let job = RenderJob {
        camera: camera.to_camera(entry.origin),
        light: light.map(|l| l.to_spot_light(entry.origin)),
        method,
        level,
        draws,
        width: camera.width,
        height: camera.height,
        occlusion: parameters.occlusion,
        near_field: parameters.near_field,
        camera_lod: parameters.camera_lod(),
    };
    let output = state.workers.render(client, &id, job).await.inspect_err(|error| {
        if matches!(error, WorkerError::QueueFull { .. }) {
            state.metrics.record_rejected_render();
        }
    })?;
    let met = budget_ms.map(|ms| output.gpu_ms <= f64::from(ms));
    let estimate = output.frame.error_estimate;
    state.metrics.record_frame_quality(estimate.map(|e| e.rel_rmse), &parameters, met.map(|m| !m));
    let exposure = quality.exposure.or(entry.exposure);
    let format = quality.format;
    let component = quality.component;
    let encoded = tokio::task::spawn_blocking(move || encode(&output, component, format, exposure))
        .await
        .map_err(ApiError::internal)??;
    let mut response = encoded.into_response(started);
    let headers = response.headers_mut();
    let mut put = |name: &'static str, value: String| {
        if let Ok(value) = HeaderValue::from_str(&value) {
            headers.insert(name, value);
        }
    };
    put("x-relume-quality", level.name().to_owned());
    let pairs: Vec<String> = parameters.pairs_with_method(method).iter().map(|(k, v)| format!("{k}={v}")).collect();
    put("x-relume-parameters", pairs.join("; "));
    if let Some(e) = estimate {
        put("x-relume-error-estimate", format!("{:.6}", e.rel_rmse));
        put("x-relume-error-estimate-spread", format!("{:.6}", e.spread));
    }
    if let (Some(ms), Some(met)) = (budget_ms, met) {
        put("x-relume-budget-ms", ms.to_string());
        put("x-relume-budget-met", met.to_string());
    }
    Ok(response)
}

/// A rendered image, encoded, with what its headers say.
struct Encoded {
    body: Vec<u8>,
    content_type: &'static str,
    width: u32,
    height: u32,
    val_count: u32,
    exposure: Option<f32>,
    source: TimingSource,
    /// (stage, ms) for `Server-Timing`, `total` excluded.
    timings: Vec<(String, f64)>,
}

fn encode(
    output: &RenderOutput,
    component: super::api::Component,
    format: ImageFormat,
    exposure: Option<f32>,
) -> Result<Encoded, ApiError> {
    let started = Instant::now();
    let image = component.of(&output.frame);
    let (body, content_type, exposure) = match format {
        ImageFormat::Png => {
            let exposure = exposure.unwrap_or_else(|| image.auto_exposure());
            (image.encode_png(exposure).map_err(ApiError::internal)?, "image/png", Some(exposure))
        }
        ImageFormat::F32 => {
            (bytemuck::cast_slice::<[f32; 4], u8>(&image.pixels).to_vec(), "application/octet-stream", None)
        }
    };
    let mut timings = vec![("queue".to_owned(), output.queue_ms)];
    timings.extend(output.frame.timings.stages.iter().cloned());
    timings.push(("gpu".to_owned(), output.gpu_ms));
    timings.push(("encode".to_owned(), started.elapsed().as_secs_f64() * 1e3));
    Ok(Encoded {
        body,
        content_type,
        width: image.width,
        height: image.height,
        val_count: output.frame.val_count,
        exposure,
        source: output.frame.timings.source,
        timings,
    })
}

impl Encoded {
    fn into_response(self, started: Instant) -> Response {
        let mut server_timing: Vec<String> =
            self.timings.iter().map(|(stage, ms)| format!("{stage};dur={ms:.3}")).collect();
        server_timing.push(format!("total;dur={:.3}", started.elapsed().as_secs_f64() * 1e3));
        let mut headers = HeaderMap::new();
        let mut put = |name: &'static str, value: String| {
            if let Ok(value) = HeaderValue::from_str(&value) {
                headers.insert(name, value);
            }
        };
        put("server-timing", server_timing.join(", "));
        put("x-relume-width", self.width.to_string());
        put("x-relume-height", self.height.to_string());
        put("x-relume-val-count", self.val_count.to_string());
        if let Some(exposure) = self.exposure {
            put("x-relume-exposure", exposure.to_string());
        }
        let source = match self.source {
            TimingSource::GpuTimestamps => "gpu_timestamps",
            TimingSource::WallClock => "wall_clock",
        };
        put("x-relume-timing-source", source.to_owned());
        headers.insert(header::CONTENT_TYPE, HeaderValue::from_static(self.content_type));
        (StatusCode::OK, headers, self.body).into_response()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bearer_scheme_is_case_insensitive() {
        for value in ["Bearer s3cret", "bearer s3cret", "BEARER s3cret", "bEaReR  s3cret"] {
            assert_eq!(bearer_token(value), Some("s3cret"), "{value}");
        }
        for value in ["Basic s3cret", "Bearers3cret", "Bearer", "s3cret", "Token s3cret"] {
            assert_ne!(bearer_token(value), Some("s3cret"), "{value}");
        }
    }

    #[test]
    fn tokens_compare_whole() {
        assert!(constant_time_eq(b"secret", b"secret"));
        assert!(!constant_time_eq(b"secret", b"secreT"));
        assert!(!constant_time_eq(b"secret", b"secret2"));
        assert!(!constant_time_eq(b"", b"x"));
    }

    #[test]
    fn the_document_is_openapi_3_1_with_every_route() {
        let doc: serde_json::Value = serde_json::from_str(&openapi_json()).expect("JSON");
        assert_eq!(doc["openapi"], "3.1.0");
        for route in [
            "/healthz",
            "/metrics",
            "/v1/scenes",
            "/v1/scenes/{id}",
            "/v1/scenes/{id}/render",
            "/v1/scenes/{id}/stream",
            "/v1/recordings",
            "/v1/recordings/{name}/frames/{index}",
            "/v1/tickets",
        ] {
            assert!(doc["paths"][route].is_object(), "{route} missing");
        }
        assert!(doc["components"]["schemas"]["SceneDescription"].is_object());
        assert!(doc["components"]["securitySchemes"]["bearer"].is_object());
        assert_eq!(doc["components"]["securitySchemes"]["ticket"]["in"], "query");
    }
}

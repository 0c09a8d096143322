//! `relume load`: a bounded load benchmark of the service (not a test). N streams replay a
//! recording at a fixed frame rate (each on its own scene, as separate clients would) while M
//! HTTP clients render another scene back to back, all for a fixed time against one server
//! (started in this process on a loopback port unless one is given). It reports throughput,
//! per-frame latency percentiles, dropped frames, refused renders and the process's peak
//! memory.
//!
//! `relume load --chaos` ([`soak`]) is the soak test of the service's bounds: a normal stream
//! and a normal HTTP client run alone, then again beside a hostile mix (render floods, slow and
//! idle sockets, oversized and truncated stream messages, clients that disconnect mid-frame,
//! a scene created and deleted in a loop), all on loopback against a server in this process,
//! for a fixed time with a fixed number of hostile tasks.

use std::collections::HashMap;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;
use hyper::{Method, StatusCode};
use serde::Serialize;
use serde_json::json;

use crate::rgbd::RgbdFrame;
use crate::rgbd::recording::{Recording, RecordingOptions};
use crate::service::client::{Backoff, Connection, asset_description, describe_error, quantile, upload_description};
use crate::service::wire::proto;
use crate::service::wire::proto::envelope::Body;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// What to run.
#[derive(Clone, Debug)]
pub struct LoadOptions {
    /// `http://host:port`; `None`: start a server in this process.
    pub server: Option<String>,
    pub token: Option<String>,
    pub streams: usize,
    pub http_clients: usize,
    pub duration: Duration,
    /// Frames per second each stream sends (faster than the server renders: frames are dropped).
    pub fps: f64,
    pub recording: PathBuf,
    /// The scene each stream relights (uploaded once per stream).
    pub stream_scene: PathBuf,
    /// The scene the HTTP clients render (created once), at its own camera. Its meshes are
    /// named by path inside the server's asset directory (they may need MTL files).
    pub http_scene: PathBuf,
    /// The server's asset directory as this process sees it; the server started here serves it.
    pub assets: PathBuf,
    /// Frames of the recording cycled through (kept in memory).
    pub frames: usize,
    /// Run [`soak`] instead: one normal stream and HTTP client, alone then beside the hostile
    /// mix, each phase `duration` long (`streams` and `http_clients` are not used).
    pub chaos: bool,
    /// How long a client tries to get its stream back, or its renders answered, after the
    /// server went away (through a load balancer: after a backend stopped or died); zero: a
    /// stream that ends or a render that fails ends the run. The soak does not reconnect.
    pub reconnect: Duration,
}

/// The figures of one run.
#[derive(Clone, Debug, Default, Serialize)]
pub struct LoadReport {
    pub streams: usize,
    pub http_clients: usize,
    pub seconds: f64,
    pub fps_per_stream: f64,
    pub frames_sent: u64,
    pub frames_rendered: u64,
    /// Dropped by the server (a newer frame replaced them), as its `dropped_frames` counts.
    pub frames_dropped: u64,
    /// Answered with an error.
    pub frame_errors: u64,
    /// Sent but never answered because their stream ended (in flight when a backend went
    /// away), and the streams opened again.
    pub frames_lost: u64,
    pub stream_reconnects: u64,
    pub frames_per_second: f64,
    /// From sending a frame to receiving its relit image, ms.
    pub frame_latency_p50_ms: f64,
    pub frame_latency_p99_ms: f64,
    pub renders_ok: u64,
    /// Answered 503 (queue full); the client waits for `Retry-After` before its next request.
    pub renders_refused: u64,
    /// Failed otherwise: no answer (connection refused or reset) or a 502/504 from a load
    /// balancer; the client waits and tries again while `reconnect` allows.
    pub renders_failed: u64,
    pub renders_per_second: f64,
    pub render_latency_p50_ms: f64,
    pub render_latency_p99_ms: f64,
    /// Peak resident memory of this process (`VmHWM`), MiB: server and clients together when
    /// the server runs in this process; `None` where /proc is not available.
    pub peak_rss_mib: Option<f64>,
    pub server: String,
}

#[derive(Default)]
struct StreamTally {
    sent: u64,
    rendered: u64,
    dropped: u64,
    errors: u64,
    lost: u64,
    reconnects: u64,
    latency_ms: Vec<f64>,
}

#[derive(Default)]
struct HttpTally {
    ok: u64,
    refused: u64,
    failed: u64,
    latency_ms: Vec<f64>,
}

/// How a client gets going again after the server went away: for `give_up` (zero: never),
/// creating its scene again from `description` when the server no longer knows it.
#[derive(Clone)]
struct Recover {
    give_up: Duration,
    description: serde_json::Value,
}

/// Runs the benchmark; the server it starts (if any) is stopped before this returns.
pub async fn run(options: &LoadOptions) -> anyhow::Result<LoadReport> {
    anyhow::ensure!(options.streams + options.http_clients > 0, "--streams and --http: at least one client");
    anyhow::ensure!(options.fps.is_finite() && options.fps > 0.0, "--fps: must be a positive number");
    anyhow::ensure!(options.frames > 0, "--frames: must be at least 1");
    let recording = Recording::open(&options.recording, &RecordingOptions::default())?;
    let frames: Vec<RgbdFrame> =
        (0..options.frames.min(recording.len())).map(|i| recording.frame(i)).collect::<Result<_, _>>()?;
    let frames = Arc::new(frames);
    let (server_url, local) = match &options.server {
        Some(url) => (url.clone(), None),
        None => {
            let mut config = crate::service::Config::new(([127, 0, 0, 1], 0).into(), &options.assets);
            config.shutdown_grace_seconds = 10;
            // Every client here comes from 127.0.0.1, which the fair queue sees as one client.
            config.limits.max_client_queue = config.limits.max_queue;
            let server = crate::service::Server::bind(config).await.context("starting the server")?;
            let url = format!("http://{}", server.local_addr());
            let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
            let task = tokio::spawn(server.run(async {
                let _ = stopped.await;
            }));
            (url, Some((stop, task)))
        }
    };
    let connection = Connection::new(&server_url, options.token.clone())?;
    let stream_scene = upload_description(&options.stream_scene)?;
    let mut stream_ids = Vec::new();
    for _ in 0..options.streams {
        stream_ids.push(connection.create_scene(&stream_scene).await?);
    }
    let http_scene = match options.http_clients {
        0 => serde_json::Value::Null,
        _ => asset_description(&options.http_scene, &options.assets)?,
    };
    let http_id = match options.http_clients {
        0 => None,
        _ => Some(connection.create_scene(&http_scene).await?),
    };
    let stream_recover = Recover { give_up: options.reconnect, description: stream_scene };
    let http_recover = Recover { give_up: options.reconnect, description: http_scene };

    let started = Instant::now();
    let deadline = tokio::time::Instant::now() + options.duration;
    let mut streams = Vec::new();
    for id in &stream_ids {
        let (connection, id, frames, fps) = (connection.clone(), id.clone(), frames.clone(), options.fps);
        let recover = stream_recover.clone();
        streams
            .push(tokio::spawn(async move { drive_stream(&connection, id, &frames, fps, deadline, &recover).await }));
    }
    let mut renders = Vec::new();
    for _ in 0..options.http_clients {
        let (connection, id) = (connection.clone(), http_id.clone().expect("a scene"));
        let recover = http_recover.clone();
        renders.push(tokio::spawn(async move { drive_renders(&connection, id, deadline, &recover).await }));
    }
    let mut report = LoadReport {
        streams: options.streams,
        http_clients: options.http_clients,
        fps_per_stream: options.fps,
        server: server_url,
        ..LoadReport::default()
    };
    let mut frame_latency = Vec::new();
    let mut final_ids = Vec::new();
    for task in streams {
        let (tally, id) = task.await.context("a stream client panicked")??;
        final_ids.push(id);
        report.frames_lost += tally.lost;
        report.stream_reconnects += tally.reconnects;
        report.frames_sent += tally.sent;
        report.frames_rendered += tally.rendered;
        report.frames_dropped += tally.dropped;
        report.frame_errors += tally.errors;
        frame_latency.extend(tally.latency_ms);
    }
    let mut render_latency = Vec::new();
    for task in renders {
        let (tally, id) = task.await.context("an HTTP client panicked")??;
        if !final_ids.contains(&id) {
            final_ids.push(id);
        }
        report.renders_failed += tally.failed;
        report.renders_ok += tally.ok;
        report.renders_refused += tally.refused;
        render_latency.extend(tally.latency_ms);
    }
    report.seconds = started.elapsed().as_secs_f64();
    report.frames_per_second = report.frames_rendered as f64 / report.seconds;
    report.renders_per_second = report.renders_ok as f64 / report.seconds;
    report.frame_latency_p50_ms = quantile(&frame_latency, 0.5);
    report.frame_latency_p99_ms = quantile(&frame_latency, 0.99);
    report.render_latency_p50_ms = quantile(&render_latency, 0.5);
    report.render_latency_p99_ms = quantile(&render_latency, 0.99);
    for id in &final_ids {
        connection.delete_scene(id).await?;
    }
    report.peak_rss_mib = peak_rss_mib();
    if let Some((stop, task)) = local {
        let _ = stop.send(());
        task.await.context("the server task")?.context("stopping the server")?;
    }
    Ok(report)
}

/// Sends a frame every `1 / fps` s until `deadline`, then waits (at most 60 s) for the answers
/// still owed. The server renders one frame per stream at a time and drops the older of two
/// waiting ones, so latency is measured per answered frame. When the stream ends (its backend
/// went away), the frames owed are lost and the stream is opened again ([`Recover`]); the
/// answer is the tally and the scene's id at the end (new if it was created again).
async fn drive_stream(
    connection: &Connection,
    mut id: String,
    frames: &[RgbdFrame],
    fps: f64,
    deadline: tokio::time::Instant,
    recover: &Recover,
) -> anyhow::Result<(StreamTally, String)> {
    let mut stream = connection.open_stream(&id).await?;
    let mut tally = StreamTally::default();
    let mut sent_at: HashMap<u64, Instant> = HashMap::new();
    let mut ticker = tokio::time::interval(Duration::from_secs_f64(1.0 / fps));
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut sending = true;
    let mut drain_until = None;
    // Dropped frames counted by the streams closed before this one.
    let mut dropped_before = 0;
    loop {
        if sending && tokio::time::Instant::now() >= deadline {
            sending = false;
            drain_until = Some(tokio::time::Instant::now() + Duration::from_secs(60));
        }
        let owed = tally.sent.saturating_sub(tally.rendered + tally.errors + tally.dropped + tally.lost);
        if !sending && owed == 0 {
            break;
        }
        let ended = tokio::select! {
            _ = ticker.tick(), if sending => {
                let frame_id = tally.sent;
                let sent = stream.send_frame(frame_id, &frames[frame_id as usize % frames.len()]).await;
                sent_at.insert(frame_id, Instant::now());
                tally.sent += 1;
                sent.err()
            }
            _ = tokio::time::sleep_until(drain_until.unwrap_or(deadline)), if !sending => {
                tracing::warn!(stream = %id, owed, "answers still owed after 60 s");
                break;
            }
            message = stream.next() => match message {
                Ok(Some(Body::RenderedFrame(f))) => {
                    if let Some(sent) = sent_at.remove(&f.frame_id) {
                        tally.latency_ms.push(sent.elapsed().as_secs_f64() * 1e3);
                    }
                    tally.rendered += 1;
                    tally.dropped = dropped_before + f.dropped_frames;
                    None
                }
                Ok(Some(Body::Error(e))) if e.code() == proto::ErrorCode::ShuttingDown => {
                    Some(anyhow::anyhow!("{}", describe_error(&e)))
                }
                Ok(Some(Body::Error(e))) => {
                    tracing::warn!(stream = %id, "{}", describe_error(&e));
                    tally.errors += 1;
                    None
                }
                Ok(Some(_)) => None,
                Ok(None) => Some(anyhow::anyhow!("stream {id}: the server closed the stream")),
                Err(error) => Some(error),
            },
        };
        let Some(error) = ended else { continue };
        if recover.give_up.is_zero() {
            return Err(error);
        }
        // Every frame sent and not answered was in flight on the stream that ended.
        let owed = tally.sent.saturating_sub(tally.rendered + tally.errors + tally.dropped + tally.lost);
        tracing::warn!(stream = %id, lost = owed, "the stream ended ({error:#}); reconnecting");
        tally.lost += owed;
        sent_at.clear();
        dropped_before = tally.dropped;
        (stream, _) = connection.reopen_stream(&mut id, &recover.description, recover.give_up).await?;
        tally.reconnects += 1;
    }
    stream.close().await;
    Ok((tally, id))
}

/// Renders the scene back to back until `deadline`; a 503 waits its `Retry-After` (capped at
/// 1 s) before the next request. With [`Recover`], a render without an answer or answered
/// 502/504 (a load balancer without a backend) counts as failed and is tried again after a
/// [`Backoff`] wait, and a 404 (a backend that does not know the scene) creates it again; the
/// answer is the tally and the scene's id at the end.
async fn drive_renders(
    connection: &Connection,
    mut id: String,
    deadline: tokio::time::Instant,
    recover: &Recover,
) -> anyhow::Result<(HttpTally, String)> {
    let mut tally = HttpTally::default();
    let body = json!({}).to_string();
    let mut backoff = Backoff::new(recover.give_up);
    while tokio::time::Instant::now() < deadline {
        let sent = Instant::now();
        let path = format!("/v1/scenes/{id}/render");
        let answer = connection.request(Method::POST, &path, body.clone().into()).await;
        let failure = match answer {
            Ok((StatusCode::OK, _)) => {
                tally.ok += 1;
                tally.latency_ms.push(sent.elapsed().as_secs_f64() * 1e3);
                backoff = Backoff::new(recover.give_up);
                continue;
            }
            Ok((StatusCode::SERVICE_UNAVAILABLE, _)) => {
                tally.refused += 1;
                tokio::time::sleep(Duration::from_millis(1000)).await;
                continue;
            }
            Ok((StatusCode::NOT_FOUND, answer)) if !recover.give_up.is_zero() => {
                tracing::warn!(scene = %id, "render: 404 ({}); creating the scene again", String::from_utf8_lossy(&answer));
                id = connection.create_scene(&recover.description).await?;
                continue;
            }
            Ok((status @ (StatusCode::BAD_GATEWAY | StatusCode::GATEWAY_TIMEOUT), answer)) => {
                anyhow::anyhow!("{status}: {}", String::from_utf8_lossy(&answer))
            }
            Ok((other, answer)) => {
                anyhow::bail!("render of scene {id}: {other}: {}", String::from_utf8_lossy(&answer))
            }
            Err(error) => error,
        };
        tally.failed += 1;
        tracing::warn!(scene = %id, "render failed: {failure:#}");
        if recover.give_up.is_zero() {
            return Err(failure.context(format!("render of scene {id}")));
        }
        if !backoff.wait().await {
            return Err(failure.context(format!("render of scene {id}: no answer within {:?}", recover.give_up)));
        }
    }
    Ok((tally, id))
}

/// `VmHWM` (peak resident memory) of /proc/self/status in MiB.
fn peak_rss_mib() -> Option<f64> {
    proc_status_mib("VmHWM:")
}

/// A memory line of /proc/self/status (`VmHWM:`, `VmRSS:`) in MiB.
fn proc_status_mib(key: &str) -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with(key))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

/// The report as printed by `relume load`.
pub fn table(r: &LoadReport) -> String {
    let mib = r.peak_rss_mib.map_or("n/a".to_owned(), |m| format!("{m:.0} MiB"));
    [
        format!(
            "server {} for {:.1} s: {} streams at {} fps, {} HTTP clients",
            r.server, r.seconds, r.streams, r.fps_per_stream, r.http_clients
        ),
        format!(
            "stream frames: {} sent, {} rendered ({:.2}/s), {} dropped, {} errors, {} lost in flight ({} reconnects); \
             latency p50 {:.0} ms, p99 {:.0} ms",
            r.frames_sent,
            r.frames_rendered,
            r.frames_per_second,
            r.frames_dropped,
            r.frame_errors,
            r.frames_lost,
            r.stream_reconnects,
            r.frame_latency_p50_ms,
            r.frame_latency_p99_ms
        ),
        format!(
            "HTTP renders: {} ok ({:.2}/s), {} refused (503), {} failed; latency p50 {:.0} ms, p99 {:.0} ms",
            r.renders_ok,
            r.renders_per_second,
            r.renders_refused,
            r.renders_failed,
            r.render_latency_p50_ms,
            r.render_latency_p99_ms
        ),
        format!("peak memory (this process): {mib}"),
    ]
    .join("\n")
}

/// The address the hostile clients of [`soak`] connect from: another host to the server.
const HOSTILE: IpAddr = IpAddr::V4(Ipv4Addr::new(127, 0, 0, 2));
/// Hostile tasks of the mix, each a loop until the phase ends.
const FLOODERS: usize = 20;
const SLOW_SOCKETS: usize = 8;
const IDLE_SOCKETS: usize = 32;
/// A hostile stream message announces this many bytes (100 MB).
const OVERSIZED_BYTES: u64 = 100_000_000;

/// What the normal clients saw in one phase.
#[derive(Clone, Debug, Default, Serialize)]
pub struct NormalFigures {
    pub renders_ok: u64,
    /// Refused (503) renders.
    pub renders_refused: u64,
    pub render_p50_ms: f64,
    pub render_p99_ms: f64,
    pub frames_rendered: u64,
    pub frame_errors: u64,
    pub frame_p50_ms: f64,
    pub frame_p99_ms: f64,
    /// Renders and frames answered with an image, of those answered (frames the server
    /// replaced by newer ones, by design, are not counted).
    pub success_rate: f64,
    /// Most descriptors this process had open during the phase.
    pub max_open_descriptors: usize,
    /// Most resident memory during the phase (sampled every 100 ms), MiB.
    pub max_rss_mib: Option<f64>,
}

/// What the hostile mix did.
#[derive(Clone, Debug, Default, Serialize)]
pub struct HostileTally {
    pub flood_renders_ok: u64,
    pub flood_renders_refused: u64,
    /// Slow and idle sockets the server closed (header timeout) or refused (max_connections).
    pub sockets_closed: u64,
    /// Oversized messages answered with Close 1009.
    pub oversized_closed_1009: u64,
    pub oversized_other: u64,
    /// Truncated envelopes answered with an `Error`.
    pub truncated_answered: u64,
    pub disconnects_mid_frame: u64,
    pub scenes_created_and_deleted: u64,
    /// Hostile requests refused for a limit (e.g. max_streams, max_scenes) rather than served.
    pub refused: u64,
}

/// The soak's figures.
#[derive(Clone, Debug, Default, Serialize)]
pub struct SoakReport {
    pub seconds_per_phase: f64,
    pub solo: NormalFigures,
    pub mixed: NormalFigures,
    pub hostile: HostileTally,
    /// `VmHWM` of this process (server and clients), MiB.
    pub peak_rss_mib: Option<f64>,
    /// Panics anywhere in the process during the soak.
    pub panics: u64,
    /// The targets: normal success rate >= 95 % and p99 <= 3x solo under the mix.
    pub targets_met: bool,
}

/// The soak: see the module docs. Loopback only: the server runs in this process.
pub async fn soak(options: &LoadOptions) -> anyhow::Result<SoakReport> {
    anyhow::ensure!(options.server.is_none(), "--chaos: runs its own server on loopback; drop --server");
    anyhow::ensure!(options.fps.is_finite() && options.fps > 0.0, "--fps: must be a positive number");
    anyhow::ensure!(options.frames > 0, "--frames: must be at least 1");
    let panics = Arc::new(AtomicU64::new(0));
    let previous_hook = Arc::new(std::panic::take_hook());
    {
        let (panics, previous_hook) = (panics.clone(), previous_hook.clone());
        std::panic::set_hook(Box::new(move |info| {
            panics.fetch_add(1, Ordering::SeqCst);
            previous_hook(info);
        }));
    }
    let recording = Recording::open(&options.recording, &RecordingOptions::default())?;
    let frames: Vec<RgbdFrame> =
        (0..options.frames.min(recording.len())).map(|i| recording.frame(i)).collect::<Result<_, _>>()?;
    let frames = Arc::new(frames);
    let mut config = crate::service::Config::new(([127, 0, 0, 1], 0).into(), &options.assets);
    config.shutdown_grace_seconds = 10;
    config.token.clone_from(&options.token);
    let server = crate::service::Server::bind(config).await.context("starting the server")?;
    let addr = server.local_addr();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let task = tokio::spawn(server.run(async {
        let _ = stopped.await;
    }));
    let connection = Connection::new(&format!("http://{addr}"), options.token.clone())?;
    let stream_id = connection.create_scene(&upload_description(&options.stream_scene)?).await?;
    let http_id = connection.create_scene(&asset_description(&options.http_scene, &options.assets)?).await?;

    let solo = normal_phase(&connection, &stream_id, &http_id, &frames, options, None).await?;
    let hostile = Arc::new(Hostile::default());
    let mixed = normal_phase(&connection, &stream_id, &http_id, &frames, options, Some(hostile.clone())).await?;
    connection.delete_scene(&stream_id).await?;
    connection.delete_scene(&http_id).await?;
    let _ = stop.send(());
    task.await.context("the server task")?.context("stopping the server")?;
    let panics = panics.load(Ordering::SeqCst);
    let _ = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| previous_hook(info)));
    let targets_met = panics == 0
        && mixed.success_rate >= 0.95
        && mixed.render_p99_ms <= 3.0 * solo.render_p99_ms
        && mixed.frame_p99_ms <= 3.0 * solo.frame_p99_ms;
    Ok(SoakReport {
        seconds_per_phase: options.duration.as_secs_f64(),
        solo,
        mixed,
        hostile: hostile.tally(),
        peak_rss_mib: peak_rss_mib(),
        panics,
        targets_met,
    })
}

/// One phase: the normal stream and HTTP client for `options.duration`, beside the hostile
/// mix when `hostile` is given.
async fn normal_phase(
    connection: &Connection,
    stream_id: &str,
    http_id: &str,
    frames: &Arc<Vec<RgbdFrame>>,
    options: &LoadOptions,
    hostile: Option<Arc<Hostile>>,
) -> anyhow::Result<NormalFigures> {
    let deadline = tokio::time::Instant::now() + options.duration;
    let sampler = tokio::spawn(sample_process(deadline));
    let mut hostile_tasks = Vec::new();
    if let Some(hostile) = &hostile {
        let addr: SocketAddr = connection.authority().parse().context("the server's address")?;
        hostile_tasks = hostile.start(connection.from_source(HOSTILE), addr, http_id, deadline);
    }
    // The soak's clients do not reconnect: a stream that ends or a render that fails is a
    // finding.
    let no_recover = Recover { give_up: Duration::ZERO, description: serde_json::Value::Null };
    let stream = {
        let (connection, id, frames, fps) = (connection.clone(), stream_id.to_owned(), frames.clone(), options.fps);
        let recover = no_recover.clone();
        tokio::spawn(async move { drive_stream(&connection, id, &frames, fps, deadline, &recover).await })
    };
    let (renders, _) = drive_renders(connection, http_id.to_owned(), deadline, &no_recover).await?;
    let (stream, _) = stream.await.context("the stream client panicked")??;
    for task in hostile_tasks {
        // Every hostile loop ends at the deadline; a stuck one is a finding, not a hang.
        match tokio::time::timeout(Duration::from_secs(30), task).await {
            Ok(joined) => joined.context("a hostile client panicked")?,
            Err(_) => tracing::warn!("a hostile client did not finish 30 s after the phase"),
        }
    }
    let (max_open_descriptors, max_rss_mib) = sampler.await.context("the sampler")?;
    let answered = (renders.ok + renders.refused + stream.rendered + stream.errors).max(1);
    Ok(NormalFigures {
        renders_ok: renders.ok,
        renders_refused: renders.refused,
        render_p50_ms: quantile(&renders.latency_ms, 0.5),
        render_p99_ms: quantile(&renders.latency_ms, 0.99),
        frames_rendered: stream.rendered,
        frame_errors: stream.errors,
        frame_p50_ms: quantile(&stream.latency_ms, 0.5),
        frame_p99_ms: quantile(&stream.latency_ms, 0.99),
        success_rate: (renders.ok + stream.rendered) as f64 / answered as f64,
        max_open_descriptors,
        max_rss_mib,
    })
}

/// Most open descriptors and resident memory of this process until `deadline`, every 100 ms.
async fn sample_process(deadline: tokio::time::Instant) -> (usize, Option<f64>) {
    let (mut descriptors, mut rss) = (0usize, None::<f64>);
    while tokio::time::Instant::now() < deadline {
        if let Ok(entries) = std::fs::read_dir("/proc/self/fd") {
            descriptors = descriptors.max(entries.count());
        }
        if let Some(now) = proc_status_mib("VmRSS:") {
            rss = Some(rss.map_or(now, |r| r.max(now)));
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    (descriptors, rss)
}

/// The hostile mix's counters.
#[derive(Default)]
struct Hostile {
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
    fn tally(&self) -> HostileTally {
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
    fn start(
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

/// The soak's report as printed by `relume load --chaos`.
pub fn soak_table(r: &SoakReport) -> String {
    let mib = |m: Option<f64>| m.map_or("n/a".to_owned(), |m| format!("{m:.0} MiB"));
    let phase = |name: &str, f: &NormalFigures| {
        format!(
            "{name}: renders {} ok / {} refused, p50 {:.0} ms, p99 {:.0} ms; stream frames {} rendered / {} errors, \
             p50 {:.0} ms, p99 {:.0} ms; success {:.1} %; max {} descriptors, max RSS {}",
            f.renders_ok,
            f.renders_refused,
            f.render_p50_ms,
            f.render_p99_ms,
            f.frames_rendered,
            f.frame_errors,
            f.frame_p50_ms,
            f.frame_p99_ms,
            f.success_rate * 100.0,
            f.max_open_descriptors,
            mib(f.max_rss_mib),
        )
    };
    let h = &r.hostile;
    [
        format!("soak: {:.0} s alone, then {:.0} s beside the hostile mix (loopback)", r.seconds_per_phase, r.seconds_per_phase),
        phase("alone", &r.solo),
        phase("mixed", &r.mixed),
        format!(
            "hostile: {FLOODERS} flooders {} ok / {} refused; {SLOW_SOCKETS} slow + {IDLE_SOCKETS} idle sockets closed {} times; \
             oversized {} closed 1009 / {} otherwise; truncated {} answered; {} disconnects mid-frame; \
             {} scenes created and deleted; {} refused for a limit",
            h.flood_renders_ok,
            h.flood_renders_refused,
            h.sockets_closed,
            h.oversized_closed_1009,
            h.oversized_other,
            h.truncated_answered,
            h.disconnects_mid_frame,
            h.scenes_created_and_deleted,
            h.refused
        ),
        format!("peak memory (this process): {}; panics: {}", mib(r.peak_rss_mib), r.panics),
        format!(
            "targets (success >= 95 %, p99 <= 3x alone, no panic): {}",
            if r.targets_met { "met" } else { "NOT met" }
        ),
    ]
    .join("\n")
}

//! `relume load`: a bounded load benchmark of the service (not a test). N streams replay a
//! recording at a fixed frame rate (each on its own scene, as separate clients would) while M
//! HTTP clients render another scene back to back, all for a fixed time against one server
//! (started in this process on a loopback port unless one is given). It reports throughput,
//! per-frame latency percentiles, dropped frames, refused renders and the process's peak
//! memory.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use hyper::{Method, StatusCode};
use serde::Serialize;
use serde_json::json;

use crate::service::client::{Connection, asset_description, describe_error, quantile, upload_description};
use crate::rgbd::RgbdFrame;
use crate::rgbd::recording::{Recording, RecordingOptions};
use crate::service::wire::proto::envelope::Body;

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
    pub frames_per_second: f64,
    /// From sending a frame to receiving its relit image, ms.
    pub frame_latency_p50_ms: f64,
    pub frame_latency_p99_ms: f64,
    pub renders_ok: u64,
    /// Answered 503 (queue full); the client waits for `Retry-After` before its next request.
    pub renders_refused: u64,
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
    latency_ms: Vec<f64>,
}

#[derive(Default)]
struct HttpTally {
    ok: u64,
    refused: u64,
    latency_ms: Vec<f64>,
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
    let http_id = match options.http_clients {
        0 => None,
        _ => Some(connection.create_scene(&asset_description(&options.http_scene, &options.assets)?).await?),
    };

    let started = Instant::now();
    let deadline = tokio::time::Instant::now() + options.duration;
    let mut streams = Vec::new();
    for id in &stream_ids {
        let (connection, id, frames, fps) = (connection.clone(), id.clone(), frames.clone(), options.fps);
        streams.push(tokio::spawn(async move { drive_stream(&connection, &id, &frames, fps, deadline).await }));
    }
    let mut renders = Vec::new();
    for _ in 0..options.http_clients {
        let (connection, id) = (connection.clone(), http_id.clone().expect("a scene"));
        renders.push(tokio::spawn(async move { drive_renders(&connection, &id, deadline).await }));
    }
    let mut report = LoadReport {
        streams: options.streams,
        http_clients: options.http_clients,
        fps_per_stream: options.fps,
        server: server_url,
        ..LoadReport::default()
    };
    let mut frame_latency = Vec::new();
    for task in streams {
        let tally = task.await.context("a stream client panicked")??;
        report.frames_sent += tally.sent;
        report.frames_rendered += tally.rendered;
        report.frames_dropped += tally.dropped;
        report.frame_errors += tally.errors;
        frame_latency.extend(tally.latency_ms);
    }
    let mut render_latency = Vec::new();
    for task in renders {
        let tally = task.await.context("an HTTP client panicked")??;
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
    for id in stream_ids.iter().chain(&http_id) {
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
/// waiting ones, so latency is measured per answered frame.
async fn drive_stream(
    connection: &Connection,
    id: &str,
    frames: &[RgbdFrame],
    fps: f64,
    deadline: tokio::time::Instant,
) -> anyhow::Result<StreamTally> {
    let mut stream = connection.open_stream(id).await?;
    let mut tally = StreamTally::default();
    let mut sent_at: HashMap<u64, Instant> = HashMap::new();
    let mut ticker = tokio::time::interval(Duration::from_secs_f64(1.0 / fps));
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut sending = true;
    let mut drain_until = None;
    loop {
        if sending && tokio::time::Instant::now() >= deadline {
            sending = false;
            drain_until = Some(tokio::time::Instant::now() + Duration::from_secs(60));
        }
        let owed = tally.sent.saturating_sub(tally.rendered + tally.errors + tally.dropped);
        if !sending && owed == 0 {
            break;
        }
        tokio::select! {
            _ = ticker.tick(), if sending => {
                let frame_id = tally.sent;
                stream.send_frame(frame_id, &frames[frame_id as usize % frames.len()]).await?;
                sent_at.insert(frame_id, Instant::now());
                tally.sent += 1;
            }
            _ = tokio::time::sleep_until(drain_until.unwrap_or(deadline)), if !sending => {
                tracing::warn!(stream = id, owed, "answers still owed after 60 s");
                break;
            }
            message = stream.next() => match message? {
                Some(Body::RenderedFrame(f)) => {
                    if let Some(sent) = sent_at.remove(&f.frame_id) {
                        tally.latency_ms.push(sent.elapsed().as_secs_f64() * 1e3);
                    }
                    tally.rendered += 1;
                    tally.dropped = f.dropped_frames;
                }
                Some(Body::Error(e)) => {
                    tracing::warn!(stream = id, "{}", describe_error(&e));
                    tally.errors += 1;
                }
                Some(_) => {}
                None => anyhow::bail!("stream {id}: the server closed the stream"),
            },
        }
    }
    stream.close().await;
    Ok(tally)
}

/// Renders the scene back to back until `deadline`; a 503 waits its `Retry-After` (capped at
/// 1 s) before the next request.
async fn drive_renders(connection: &Connection, id: &str, deadline: tokio::time::Instant) -> anyhow::Result<HttpTally> {
    let mut tally = HttpTally::default();
    let path = format!("/v1/scenes/{id}/render");
    let body = json!({}).to_string();
    while tokio::time::Instant::now() < deadline {
        let sent = Instant::now();
        let (status, answer) = connection.request(Method::POST, &path, body.clone().into()).await?;
        match status {
            StatusCode::OK => {
                tally.ok += 1;
                tally.latency_ms.push(sent.elapsed().as_secs_f64() * 1e3);
            }
            StatusCode::SERVICE_UNAVAILABLE => {
                tally.refused += 1;
                tokio::time::sleep(Duration::from_millis(1000)).await;
            }
            other => anyhow::bail!("render of scene {id}: {other}: {}", String::from_utf8_lossy(&answer)),
        }
    }
    Ok(tally)
}

/// `VmHWM` of /proc/self/status in MiB.
fn peak_rss_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
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
            "stream frames: {} sent, {} rendered ({:.2}/s), {} dropped, {} errors; latency p50 {:.0} ms, p99 {:.0} ms",
            r.frames_sent,
            r.frames_rendered,
            r.frames_per_second,
            r.frames_dropped,
            r.frame_errors,
            r.frame_latency_p50_ms,
            r.frame_latency_p99_ms
        ),
        format!(
            "HTTP renders: {} ok ({:.2}/s), {} refused (503); latency p50 {:.0} ms, p99 {:.0} ms",
            r.renders_ok, r.renders_per_second, r.renders_refused, r.render_latency_p50_ms, r.render_latency_p99_ms
        ),
        format!("peak memory (this process): {mib}"),
    ]
    .join("\n")
}

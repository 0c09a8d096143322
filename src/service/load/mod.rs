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

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use serde::Serialize;

use crate::rgbd::RgbdFrame;
use crate::rgbd::recording::{Recording, RecordingOptions};
use crate::service::client::{Connection, asset_description, quantile, upload_description};
use clients::{drive_renders, drive_stream};

mod clients;
mod hostile;
mod soak;

pub use soak::{HostileTally, NormalFigures, SoakReport, soak, soak_table};

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

/// What a stream client saw ([`drive_stream`]).
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

/// What an HTTP client saw ([`drive_renders`]).
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
    let frames = load_frames(options)?;
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

/// The recording's first `options.frames` frames (all of a shorter one), kept in memory.
fn load_frames(options: &LoadOptions) -> anyhow::Result<Arc<Vec<RgbdFrame>>> {
    let recording = Recording::open(&options.recording, &RecordingOptions::default())?;
    let frames: Vec<RgbdFrame> =
        (0..options.frames.min(recording.len())).map(|i| recording.frame(i)).collect::<Result<_, _>>()?;
    Ok(Arc::new(frames))
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

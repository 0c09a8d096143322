//! `relume load --chaos`: the soak test of the service's bounds (see `super`'s docs): the
//! normal clients alone, then beside the hostile mix ([`Hostile`]).

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use anyhow::Context;
use serde::Serialize;

use super::clients::{drive_renders, drive_stream};
use super::hostile::Hostile;
use super::{LoadOptions, Recover, load_frames, peak_rss_mib, proc_status_mib};
use crate::rgbd::RgbdFrame;
use crate::service::client::{Connection, asset_description, quantile, upload_description};

/// The address the hostile clients of [`soak`] connect from: another host to the server.
pub(super) const HOSTILE: IpAddr = IpAddr::V4(Ipv4Addr::new(127, 0, 0, 2));
/// Hostile tasks of the mix, each a loop until the phase ends.
pub(super) const FLOODERS: usize = 20;
pub(super) const SLOW_SOCKETS: usize = 8;
pub(super) const IDLE_SOCKETS: usize = 32;
/// A hostile stream message announces this many bytes (100 MB).
pub(super) const OVERSIZED_BYTES: u64 = 100_000_000;

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
    let frames = load_frames(options)?;
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

//! `relume replay`: relight an RGB-D recording, here or through a running server.

use super::Size;
use anyhow::Context;
use relume::gpu::Gpu;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Recording: a TUM folder (rgb.txt, depth.txt, optional groundtruth.txt and
    /// intrinsics.json), an Open3D/Redwood folder (color/, depth/, optional trajectory.log and
    /// camera JSON) or a ROS 2 MCAP file (.mcap).
    recording: PathBuf,
    #[command(flatten)]
    mcap: relume::rgbd::rosbag::McapTopics,
    /// Scene with the virtual content and its anchor in the recording's world frame.
    #[arg(long)]
    scene: PathBuf,
    /// Output directory.
    #[arg(long, default_value = "out/replay")]
    out: PathBuf,
    #[command(flatten)]
    size: Size,
    /// Replay only the first N frames.
    #[arg(long)]
    frames: Option<usize>,
    /// Accumulate VALs across frames into a world-space set (steadier light).
    #[arg(long)]
    accumulate: bool,
    /// With --accumulate: grid cell of the set (m).
    #[arg(long, default_value_t = 0.05)]
    cell_size: f32,
    /// With --accumulate: VALs kept at most (memory bound; the oldest go first).
    #[arg(long, default_value_t = 65_536)]
    max_vals: usize,
    /// With --accumulate: VALs older than this many frames are dropped.
    #[arg(long, default_value_t = 300)]
    max_age: u32,
    /// Exposure of the virtual object in the composite (1: on the camera's scale, its radiance
    /// divided by radiance_scale as the room's was multiplied).
    #[arg(long, default_value_t = 1.0)]
    exposure: f32,
    /// Intrinsics fx,fy,cx,cy for a recording without its own: a directory without intrinsics.json
    /// (default: TUM's), an .mcap without camera info (no default: required there).
    #[arg(long, value_delimiter = ',', num_args = 4)]
    intrinsics: Option<Vec<f32>>,
    /// Depth units per metre for a recording without intrinsics.json (default 5000, TUM's).
    #[arg(long)]
    depth_scale: Option<f32>,
    /// Replay through a running `relume serve` (http://host:port) over its WebSocket stream
    /// instead of rendering here: the scene is uploaded with its meshes inline, every frame is
    /// sent and its composite written to `composited/`.
    #[arg(long)]
    server: Option<String>,
    #[command(flatten)]
    client: super::ServerClient,
    /// Hold each frame's time under this many milliseconds: the replay moves frame by frame
    /// between the scene's level and cheaper or richer parameters (VAL grid, render size,
    /// visibility, near field), and reports what each frame ran at (default: the scene's
    /// `settings.budget_ms`, else none).
    #[arg(long)]
    budget_ms: Option<f32>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let exposure = args.exposure;
    anyhow::ensure!(exposure.is_finite() && exposure > 0.0, "--exposure: must be a positive number, got {exposure}");
    anyhow::ensure!(args.frames != Some(0), "--frames: must be at least 1");
    if let Some(ms) = args.budget_ms {
        relume::scene::settings::validate_budget_ms(ms, "--budget-ms").map_err(|e| anyhow::anyhow!("{e}"))?;
    }
    let recording_options = relume::rgbd::recording::RecordingOptions {
        mcap: args.mcap,
        ..recording_options(args.intrinsics, args.depth_scale)?
    };
    if let Some(server) = args.server {
        anyhow::ensure!(
            !args.accumulate && args.size.width.is_none() && args.size.height.is_none() && args.budget_ms.is_none(),
            "--accumulate, --width, --height and --budget-ms: not available with --server (the stream renders each frame at its own size, without accumulation, at the scene's budget)"
        );
        let options = relume::service::client::RemoteReplayOptions {
            server,
            token: args.client.token.clone(),
            recording: args.recording,
            recording_options,
            scene: args.scene,
            out: args.out,
            frames: args.frames,
            exposure: Some(exposure),
            progress: true,
            reconnect: args.client.reconnect(),
        };
        return remote_replay_command(&options);
    }
    let accumulate = args.accumulate.then_some(relume::mr::AccumulateOptions {
        cell_size: args.cell_size,
        max_vals: args.max_vals,
        max_age_frames: args.max_age,
    });
    let options = relume::mr::replay::ReplayOptions {
        recording: args.recording,
        recording_options,
        scene: args.scene,
        out: args.out,
        size: args.size.resolve_optional()?,
        frames: args.frames,
        accumulate,
        exposure,
        progress: true,
        budget_ms: args.budget_ms,
    };
    replay_command(&options)
}

/// `replay --server`: the replay through a running server, and its summary.
fn remote_replay_command(options: &relume::service::client::RemoteReplayOptions) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let summary = runtime.block_on(relume::service::client::replay_remote(options))?;
    let vals = &summary.vals_per_frame;
    eprintln!(
        "replayed {} frames at {}x{} through {}: {} to {} VALs per frame, round trip p50 {:.0} ms, p99 {:.0} ms, {} dropped",
        summary.frames,
        summary.width,
        summary.height,
        summary.server,
        vals.iter().min().unwrap_or(&0),
        vals.iter().max().unwrap_or(&0),
        relume::service::client::quantile(&summary.round_trip_ms, 0.5),
        relume::service::client::quantile(&summary.round_trip_ms, 0.99),
        summary.dropped_frames,
    );
    if summary.reconnects > 0 {
        eprintln!(
            "the stream ended {} times: {} frames lost in flight ({:?}), {} scenes created again",
            summary.reconnects, summary.frames_lost, summary.lost_frames, summary.scenes_recreated
        );
    }
    eprintln!("{}", relume::mr::replay::stage_table(&summary.stage_ms, ("round trip", &summary.round_trip_ms)));
    eprintln!("wrote {}", options.out.display());
    Ok(())
}

/// The replay here, and its summary.
fn replay_command(options: &relume::mr::replay::ReplayOptions) -> anyhow::Result<()> {
    let gpu = Gpu::new()?;
    let summary = relume::mr::replay::replay(&gpu, options)?;
    let vals = &summary.vals_per_frame;
    eprintln!(
        "replayed {} frames at {}x{} on {} ({}): {} to {} VALs per frame, mean relative change of the object's irradiance {:.4}{}",
        summary.frames,
        summary.width,
        summary.height,
        summary.adapter,
        summary.timing,
        vals.iter().min().unwrap_or(&0),
        vals.iter().max().unwrap_or(&0),
        summary.mean_irradiance_change,
        if summary.accumulate { " (accumulating)" } else { "" },
    );
    eprintln!("{}", relume::mr::replay::stage_table(&summary.stage_ms, ("frame (wall)", &summary.frame_ms)));
    let estimates: Vec<f64> = summary.error_estimate.iter().flatten().copied().collect();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    eprintln!(
        "error estimate per frame: mean rel RMSE {:.4} over {} frames, {:.2} ms mean ({:.1} % of the mean frame)",
        mean(&estimates),
        estimates.len(),
        mean(&summary.error_estimate_ms),
        100.0 * mean(&summary.error_estimate_ms) / mean(&summary.frame_ms).max(1e-9),
    );
    let levels: Vec<String> = summary.level_frames.iter().map(|(l, n)| format!("{l} {n}")).collect();
    let last = summary
        .parameters
        .last()
        .map(|p| p.pairs().iter().map(|(k, v)| format!("{k}={v}")).collect::<Vec<_>>().join(" "));
    eprintln!(
        "budget {}: p90 frame after the first 5 {:.1} ms; frames per level: {}; last frame ran at {}; mean composite change {:.3} levels",
        summary.budget_ms.map_or("none".to_owned(), |ms| format!("{ms} ms")),
        summary.p90_frame_ms_after_5,
        levels.join(", "),
        last.unwrap_or_default(),
        mean(&summary.composite_change),
    );
    eprintln!("wrote {}", options.out.display());
    Ok(())
}

/// The recording options of `--intrinsics` and `--depth-scale`, checked.
fn recording_options(
    intrinsics: Option<Vec<f32>>,
    depth_scale: Option<f32>,
) -> anyhow::Result<relume::rgbd::recording::RecordingOptions> {
    if let Some(s) = depth_scale {
        anyhow::ensure!(s.is_finite() && s > 0.0, "--depth-scale: must be a positive number, got {s}");
    }
    let mut options = relume::rgbd::recording::RecordingOptions { depth_scale, ..Default::default() };
    if let Some(k) = intrinsics {
        let tum = relume::rgbd::Intrinsics::TUM;
        let k = relume::rgbd::Intrinsics { fx: k[0], fy: k[1], cx: k[2], cy: k[3], ..tum };
        relume::rgbd::recording::check_intrinsics(&k)
            .map_err(|(field, m)| anyhow::anyhow!("--intrinsics: {field}: {m}"))?;
        options.intrinsics = Some(k);
    }
    Ok(options)
}

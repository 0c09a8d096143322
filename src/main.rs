//! The `relume` command line.

use anyhow::Context;
use clap::{Parser, Subcommand, ValueEnum};
use relume::compare;
use relume::gpu::Gpu;
use relume::image::LinearImage;
use relume::renderer::{Method, Renderer, stage};
use relume::scene::Scene;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

#[derive(Parser)]
#[command(name = "relume", version, about = "One-bounce global illumination from thousands of virtual area lights")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene file to a tone-mapped PNG (and optionally linear EXR).
    Render {
        /// Scene description (JSON).
        scene: PathBuf,
        /// Output PNG (8-bit sRGB after exposure and clipping).
        #[arg(long, default_value = "out.png")]
        out: PathBuf,
        /// Also write linear float radiance (OpenEXR, RGBA f32, alpha = coverage).
        #[arg(long)]
        hdr: Option<PathBuf>,
        /// Which light to write.
        #[arg(long, value_enum, default_value_t = Component::Full)]
        component: Component,
        /// How the indirect light is computed.
        #[arg(long, value_enum, default_value_t = Method::Sparse)]
        method: Method,
        #[command(flatten)]
        size: Size,
        /// Exposure multiplier before tone mapping (default: the scene's, else automatic).
        #[arg(long)]
        exposure: Option<f32>,
        /// With --method exact: use every N-th VAL (flux x N), for large scenes.
        #[arg(long, default_value_t = 1)]
        val_stride: u32,
    },
    /// Render with the sparse method and the brute-force reference and print the error and cost.
    Compare {
        scene: PathBuf,
        /// Print one JSON object (the only output format for now; kept for scripts).
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        size: Size,
        /// Write sparse.png, brute_force.png and difference images of the indirect light here.
        #[arg(long)]
        images: Option<PathBuf>,
        /// Also compare against exact visibility: sparse with occlusion off, "sum" and
        /// "product" against the ray-traced reference.
        #[arg(long, value_enum)]
        reference: Option<Reference>,
        /// Exact reference: use every N-th VAL (flux x N); reported in the output.
        #[arg(long, default_value_t = 1)]
        val_stride: u32,
    },
    /// Sweep quality settings: per configuration the time of every stage, the device memory
    /// held and the indirect error against brute force (and exact); writes results.json,
    /// results.csv and plots into --out (see README, "Benchmark").
    Bench {
        scene: PathBuf,
        /// An axis and its values, AXIS=V1,V2,...; axes: sparse_points (per mesh),
        /// rsm_resolution (VALs <= R²), occlusion (off,disks), glossy (on,off), resolution
        /// (WxH or N). Repeat for more axes.
        #[arg(long = "sweep", value_name = "AXIS=V1,V2,...")]
        sweep: Vec<String>,
        /// Every combination of the swept values instead of one axis at a time around the
        /// scene's settings.
        #[arg(long)]
        grid: bool,
        /// A tiny sweep at 32x32 that runs in seconds (the CI smoke test).
        #[arg(long)]
        quick: bool,
        /// Also compare every configuration against exact visibility.
        #[arg(long, value_enum)]
        reference: Option<Reference>,
        /// With --reference exact: use every N-th VAL (flux x N).
        #[arg(long)]
        val_stride: Option<u32>,
        /// Skip the plots (results.json and results.csv only).
        #[arg(long)]
        no_plots: bool,
        /// The paper's Table 1 configurations (200k/730k triangles, 4k/16k sparse points,
        /// 16k/64k/512k VALs, diffuse/+glossy/+occlusion, 1920x1080) on scenes built from this
        /// one (its other meshes replicated in the room); no references. Hours on lavapipe.
        #[arg(long, conflicts_with_all = ["sweep", "grid", "reference"])]
        table1: bool,
        /// Skip the brute-force reference (and the error against it): for configurations too
        /// large to brute-force.
        #[arg(long, conflicts_with = "reference")]
        no_references: bool,
        /// Skip the FMA-bound kernel and the gather variants.
        #[arg(long)]
        no_fma: bool,
        /// Skip the temporal-stability frames.
        #[arg(long)]
        no_temporal: bool,
        /// Output directory (created).
        #[arg(long)]
        out: PathBuf,
    },
    /// Relight every frame of an RGB-D recording (a TUM or Open3D/Redwood folder, or an MCAP
    /// file) with a scene's virtual content: writes composited and indirect-only frames and a
    /// timing and stability summary.
    Replay {
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
        /// Exposure of the virtual object in the composite (1 keeps the radiance_scale calibration).
        #[arg(long, default_value_t = 1.0)]
        exposure: f32,
        /// Intrinsics for a recording without intrinsics.json: fx,fy,cx,cy (default: TUM's).
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
        /// With --server: the server's bearer token.
        #[arg(long, env = "RELUME_TOKEN", hide_env_values = true)]
        token: Option<String>,
    },
    /// Load benchmark of the service: streams replaying a recording plus HTTP render clients,
    /// for a fixed time; prints throughput, latency percentiles, dropped frames, peak memory.
    Load {
        /// A running server (http://host:port); default: one started in this process.
        #[arg(long)]
        server: Option<String>,
        #[arg(long, env = "RELUME_TOKEN", hide_env_values = true)]
        token: Option<String>,
        /// Concurrent streams (each on its own copy of --scene).
        #[arg(long, default_value_t = 2)]
        streams: usize,
        /// Concurrent HTTP render clients (on one copy of --http-scene).
        #[arg(long = "http", default_value_t = 2)]
        http_clients: usize,
        /// How long the clients send, s.
        #[arg(long, default_value_t = 30.0)]
        seconds: f64,
        /// Frames per second each stream sends.
        #[arg(long, default_value_t = 10.0)]
        fps: f64,
        #[arg(long, default_value = "fixtures/recordings/tum_fr1_xyz")]
        recording: PathBuf,
        /// The scene the streams relight.
        #[arg(long, default_value = "fixtures/scenes/mr_bunny.json")]
        scene: PathBuf,
        /// The scene the HTTP clients render (at its camera); its meshes are named by path
        /// inside the server's asset directory.
        #[arg(long, default_value = "fixtures/scenes/cornell_bunny_small.json")]
        http_scene: PathBuf,
        /// The server's asset directory as seen from here (the server started here serves it).
        #[arg(long, default_value = ".")]
        assets: PathBuf,
        /// Frames of the recording loaded and cycled through.
        #[arg(long, default_value_t = 8)]
        frames: usize,
        /// Print the report as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Serve the HTTP + WebSocket API (see README, "Service"). Every flag also reads the
    /// environment variable shown; SIGINT/SIGTERM shut down gracefully.
    Serve(relume::service::Config),
    /// Print the service's OpenAPI 3.1 document (the contents of proto/openapi.json).
    Openapi,
}

#[derive(Clone, Copy, ValueEnum)]
enum Reference {
    Exact,
}

#[derive(clap::Args)]
struct Size {
    /// Override the camera's width in pixels (1..=8192).
    #[arg(long)]
    width: Option<u32>,
    /// Override the camera's height in pixels (1..=8192).
    #[arg(long)]
    height: Option<u32>,
}

#[derive(Clone, Copy, ValueEnum)]
enum Component {
    Direct,
    Indirect,
    Full,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // The service logs its requests by default; the batch commands only warnings.
    let default_filter = if matches!(cli.command, Command::Serve(_)) { "warn,relume=info" } else { "warn" };
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| default_filter.into()),
        )
        .with_writer(std::io::stderr)
        .init();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Render { scene, out, hdr, component, method, size, exposure, val_stride } => {
            anyhow::ensure!(val_stride >= 1, "--val-stride: must be at least 1, got {val_stride}");
            let scene = load_lit(&scene)?;
            let (w, h) = size.resolve(&scene)?;
            let gpu = Gpu::new()?;
            let mut renderer = Renderer::new(&gpu, &scene)?;
            renderer.set_exact_val_stride(val_stride);
            let frame = renderer.render(&gpu, method, w, h)?;
            let image = match component {
                Component::Direct => frame.direct,
                Component::Indirect => frame.indirect,
                Component::Full => frame.direct.add(&frame.indirect),
            };
            if let Some(e) = exposure {
                anyhow::ensure!(e.is_finite() && e > 0.0, "--exposure: must be a positive number, got {e}");
            }
            let exposure = exposure.or(scene.settings.exposure).unwrap_or_else(|| image.auto_exposure());
            image.write_png(&out, exposure)?;
            if let Some(hdr) = hdr {
                image.write_exr(&hdr)?;
            }
            let stages: Vec<String> = frame.timings.stages.iter().map(|(n, ms)| format!("{n} {ms:.2}")).collect();
            eprintln!(
                "wrote {} ({w}x{h}, {} VALs, {} sparse points, exposure {exposure:.4}); {:?} ms: {}",
                out.display(),
                frame.val_count,
                scene.sparse_point_count(),
                frame.timings.source,
                stages.join(", ")
            );
            Ok(())
        }
        Command::Replay {
            recording,
            scene,
            out,
            size,
            frames,
            accumulate,
            cell_size,
            max_vals,
            max_age,
            exposure,
            intrinsics,
            depth_scale,
            server,
            token,
            mcap,
        } => {
            anyhow::ensure!(
                exposure.is_finite() && exposure > 0.0,
                "--exposure: must be a positive number, got {exposure}"
            );
            anyhow::ensure!(frames != Some(0), "--frames: must be at least 1");
            let recording_options =
                relume::rgbd::recording::RecordingOptions { mcap, ..recording_options(intrinsics, depth_scale)? };
            if let Some(server) = server {
                anyhow::ensure!(
                    !accumulate && size.width.is_none() && size.height.is_none(),
                    "--accumulate, --width and --height: not available with --server (the stream renders each frame at its own size, without accumulation)"
                );
                let options = relume::client::RemoteReplayOptions {
                    server,
                    token,
                    recording,
                    recording_options,
                    scene,
                    out,
                    frames,
                    exposure: Some(exposure),
                    progress: true,
                };
                return remote_replay_command(&options);
            }
            let accumulate =
                accumulate.then_some(relume::mr::AccumulateOptions { cell_size, max_vals, max_age_frames: max_age });
            replay_command(recording, scene, out, size, frames, accumulate, exposure, recording_options)
        }
        Command::Load {
            server,
            token,
            streams,
            http_clients,
            seconds,
            fps,
            recording,
            scene,
            http_scene,
            assets,
            frames,
            json,
        } => {
            anyhow::ensure!(
                seconds.is_finite() && seconds > 0.0,
                "--seconds: must be a positive number, got {seconds}"
            );
            let options = relume::load::LoadOptions {
                server,
                token,
                streams,
                http_clients,
                duration: std::time::Duration::from_secs_f64(seconds),
                fps,
                recording,
                stream_scene: scene,
                http_scene,
                assets,
                frames,
            };
            let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
            let report = runtime.block_on(relume::load::run(&options))?;
            if json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else {
                println!("{}", relume::load::table(&report));
            }
            Ok(())
        }
        Command::Bench {
            scene,
            sweep,
            grid,
            quick,
            reference,
            val_stride,
            table1,
            no_references,
            no_plots,
            no_fma,
            no_temporal,
            out,
        } => {
            anyhow::ensure!(val_stride.is_none() || reference.is_some(), "--val-stride: only with --reference exact");
            let options = relume::bench::BenchOptions {
                scene,
                sweep: relume::bench::Sweep::parse(&sweep)?,
                grid,
                quick,
                exact_val_stride: reference.map(|_| val_stride.unwrap_or(1)),
                references: !table1 && !no_references,
                table1,
                out,
                fma: !no_fma,
                temporal: !no_temporal,
                plots: !no_plots,
            };
            let gpu = Gpu::new()?;
            let start = Instant::now();
            let results = relume::bench::run(&gpu, &options, &mut |what| {
                eprintln!("[{:7.1} s] {what}", start.elapsed().as_secs_f64());
            })?;
            eprintln!(
                "{} configurations on {} ({} timing); wrote {}",
                results.configs.len(),
                results.adapter,
                results.timing.as_str(),
                options.out.join("results.json").display()
            );
            Ok(())
        }
        Command::Serve(config) => {
            let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
            runtime.block_on(relume::service::serve(config))?;
            Ok(())
        }
        Command::Openapi => {
            print!("{}", relume::service::openapi_json());
            Ok(())
        }
        Command::Compare { scene, json: _, size, images, reference, val_stride } => {
            anyhow::ensure!(val_stride >= 1, "--val-stride: must be at least 1, got {val_stride}");
            let scene = load_lit(&scene)?;
            let (w, h) = size.resolve(&scene)?;
            let gpu = Gpu::new()?;
            let start = Instant::now();
            let mut renderer = Renderer::new(&gpu, &scene)?;
            let setup_ms = start.elapsed().as_secs_f64() * 1e3;
            // The brute force has no visibility, so it is compared with sparse without occlusion;
            // `--reference exact` measures occlusion.
            renderer.set_occlusion(relume::scene::Occlusion::Off, scene.settings.occlusion_rule);
            let sparse = compare::sparse_frame(&gpu, &mut renderer, w, h)?;
            let brute = compare::brute_force_frame(&gpu, &mut renderer, w, h)?;
            let error = compare::indirect_error(&sparse.indirect, &brute.indirect);
            let exposure = error.exposure;
            let sparse_ms = sparse.timings.total_of(stage::SPARSE_INDIRECT);
            let brute_force_ms = brute.timings.total_of(stage::BRUTE_FORCE_INDIRECT);
            if let Some(dir) = &images {
                write_comparison(dir, &sparse.indirect, &brute.indirect, exposure)?;
            }
            let mut report = serde_json::json!({
                "scene": scene_name(&scene),
                "adapter": gpu.adapter_name(),
                "timing": sparse.timings.source,
                "width": w,
                "height": h,
                "pixels": w as u64 * h as u64,
                "covered_pixels": brute.indirect.coverage(),
                "vals": sparse.val_count,
                "rsm_resolution": scene.settings.rsm_resolution,
                "sparse_points": scene.sparse_point_count(),
                "triangles": scene.triangle_count(),
                "vertices": scene.vertex_count(),
                "glossy": renderer.glossy(),
                "occlusion_setting": scene.settings.occlusion,
                "occlusion_rule_setting": scene.settings.occlusion_rule,
                "sparse_ms": sparse_ms,
                "brute_force_ms": brute_force_ms,
                "speedup": brute_force_ms / sparse_ms,
                "indirect_rel_rmse": error.rel_rmse,
                "indirect_flip_mean": error.flip_mean,
                "exposure": exposure,
                "setup_ms": setup_ms,
                "sparse_stages_ms": sparse.timings.stages,
                "brute_force_stages_ms": brute.timings.stages,
            });
            if reference.is_some() {
                add_exact_comparison(&mut report, &gpu, &mut renderer, &scene, (w, h), val_stride, images.as_deref())?;
            }
            println!("{}", serde_json::to_string_pretty(&report)?);
            Ok(())
        }
    }
}

impl Size {
    /// The flags' size, else the scene camera's.
    fn resolve(&self, scene: &Scene) -> anyhow::Result<(u32, u32)> {
        Ok((
            checked_side("width", self.width.unwrap_or(scene.camera.width))?,
            checked_side("height", self.height.unwrap_or(scene.camera.height))?,
        ))
    }

    /// The flags' size, both or neither.
    fn resolve_optional(&self) -> anyhow::Result<Option<(u32, u32)>> {
        match (self.width, self.height) {
            (None, None) => Ok(None),
            (Some(w), Some(h)) => Ok(Some((checked_side("width", w)?, checked_side("height", h)?))),
            _ => anyhow::bail!("--width and --height: give both or neither"),
        }
    }
}

fn checked_side(name: &str, v: u32) -> anyhow::Result<u32> {
    anyhow::ensure!((1..=8192).contains(&v), "--{name}: must be in 1..=8192, got {v}");
    Ok(v)
}

/// `replay --server`: the replay through a running server, and its summary.
fn remote_replay_command(options: &relume::client::RemoteReplayOptions) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let summary = runtime.block_on(relume::client::replay_remote(options))?;
    let vals = &summary.vals_per_frame;
    eprintln!(
        "replayed {} frames at {}x{} through {}: {} to {} VALs per frame, round trip p50 {:.0} ms, p99 {:.0} ms, {} dropped",
        summary.frames,
        summary.width,
        summary.height,
        summary.server,
        vals.iter().min().unwrap_or(&0),
        vals.iter().max().unwrap_or(&0),
        relume::client::quantile(&summary.round_trip_ms, 0.5),
        relume::client::quantile(&summary.round_trip_ms, 0.99),
        summary.dropped_frames,
    );
    eprintln!("{}", relume::replay::stage_table(&summary.stage_ms, ("round trip", &summary.round_trip_ms)));
    eprintln!("wrote {}", options.out.display());
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn replay_command(
    recording: PathBuf,
    scene: PathBuf,
    out: PathBuf,
    size: Size,
    frames: Option<usize>,
    accumulate: Option<relume::mr::AccumulateOptions>,
    exposure: f32,
    recording_options: relume::rgbd::recording::RecordingOptions,
) -> anyhow::Result<()> {
    let size = size.resolve_optional()?;
    let options = relume::replay::ReplayOptions {
        recording,
        recording_options,
        scene,
        out,
        size,
        frames,
        accumulate,
        exposure,
        progress: true,
    };
    let gpu = Gpu::new()?;
    let summary = relume::replay::replay(&gpu, &options)?;
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
    eprintln!("{}", relume::replay::stage_table(&summary.stage_ms, ("frame (wall)", &summary.frame_ms)));
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

fn load(path: &Path) -> anyhow::Result<Scene> {
    Scene::load(path).with_context(|| format!("loading scene {}", path.display()))
}

/// A scene for `render` and `compare`, which are lit by the scene's own spot light.
fn load_lit(path: &Path) -> anyhow::Result<Scene> {
    let scene = load(path)?;
    anyhow::ensure!(
        scene.light.is_some(),
        "{}: light: required by this command (a scene without one is lit by RGB-D frames: use `replay`)",
        path.display()
    );
    Ok(scene)
}

/// Sparse with occlusion off, "sum" and "product" against the exact-visibility reference.
fn add_exact_comparison(
    report: &mut serde_json::Value,
    gpu: &Gpu,
    renderer: &mut Renderer,
    scene: &Scene,
    (w, h): (u32, u32),
    val_stride: u32,
    images: Option<&Path>,
) -> anyhow::Result<()> {
    use relume::scene::{Occlusion, OcclusionRule};
    let exact = compare::exact_frame(gpu, renderer, w, h, val_stride)?;
    let exposure = exact.indirect.auto_exposure();
    report["exact_ms"] = exact.timings.total_of(&[stage::EXACT]).into();
    report["exact_val_stride"] = val_stride.into();
    report["exact_vals_used"] = (exact.val_count / val_stride).into();
    report["exact_rounds"] = exact.exact_rounds.into();
    if let Some(dir) = images {
        exact.indirect.write_png(&dir.join("indirect_exact.png"), exposure)?;
    }
    for (key, occlusion, rule) in [
        ("off", Occlusion::Off, OcclusionRule::Sum),
        ("sum", Occlusion::Disks, OcclusionRule::Sum),
        ("product", Occlusion::Disks, OcclusionRule::Product),
    ] {
        renderer.set_occlusion(occlusion, rule);
        let sparse = renderer.render(gpu, Method::Sparse, w, h)?;
        if let Some(dir) = images {
            sparse.indirect.write_png(&dir.join(format!("indirect_sparse_occlusion_{key}.png")), exposure)?;
        }
        let error = compare::indirect_error(&sparse.indirect, &exact.indirect);
        report[format!("indirect_rel_rmse_vs_exact_{key}")] = error.rel_rmse.into();
        report[format!("indirect_flip_mean_vs_exact_{key}")] = error.flip_mean.into();
        if key == "sum" {
            report["occlusion_ms"] = sparse.timings.total_of(&[stage::OCCLUSION]).into();
            report["gather_ms"] = sparse.timings.total_of(&[stage::GATHER]).into();
        }
    }
    renderer.set_occlusion(scene.settings.occlusion, scene.settings.occlusion_rule);
    Ok(())
}

fn scene_name(scene: &Scene) -> String {
    scene.meshes.iter().map(|m| m.name.as_str()).collect::<Vec<_>>().join("+")
}

fn write_comparison(dir: &Path, sparse: &LinearImage, brute: &LinearImage, exposure: f32) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    sparse.write_png(&dir.join("indirect_sparse.png"), exposure)?;
    brute.write_png(&dir.join("indirect_brute_force.png"), exposure)?;
    let diff = LinearImage {
        width: sparse.width,
        height: sparse.height,
        pixels: sparse
            .pixels
            .iter()
            .zip(&brute.pixels)
            .map(|(s, b)| [(s[0] - b[0]).abs(), (s[1] - b[1]).abs(), (s[2] - b[2]).abs(), b[3]])
            .collect(),
    };
    diff.write_png(&dir.join("indirect_difference.png"), exposure * 4.0)?;
    Ok(())
}

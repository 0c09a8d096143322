//! The `relume` command line: one module per command, each an `Args` struct and a `run`.

pub mod bench;
pub mod compare;
pub mod load;
pub mod record_synthetic;
pub mod render;
pub mod replay;
pub mod serve;

use anyhow::Context;
use clap::{Parser, Subcommand, ValueEnum};
use relume::bench::compare::{ExactOptions, ReferenceDevice};
use relume::scene::{Quality, Scene};
use std::path::Path;

/// How a client of a running server (`relume replay --server`, `relume load --server`) talks to
/// it: the bearer token, and how long it tries to get its stream back.
#[derive(clap::Args)]
pub struct ServerClient {
    /// The server's bearer token.
    #[arg(long, env = "RELUME_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// Seconds to try to get a stream back, or renders answered, after the server went away (a
    /// backend behind a load balancer stopped or died; the new one may be another backend),
    /// waiting 0.1 s doubling to 2 s between tries; the frames in flight are lost and counted.
    /// 0: the run fails instead.
    #[arg(long, default_value_t = relume::service::client::DEFAULT_RECONNECT_SECONDS,
        value_parser = clap::value_parser!(u64).range(0..=3600))]
    pub reconnect_seconds: u64,
}

impl ServerClient {
    /// `--reconnect-seconds` as a duration.
    pub fn reconnect(&self) -> std::time::Duration {
        std::time::Duration::from_secs(self.reconnect_seconds)
    }
}

#[derive(Parser)]
#[command(name = "relume", version, about = "One-bounce global illumination from thousands of virtual area lights")]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand)]
pub enum Command {
    /// Render a scene file to a tone-mapped PNG (and optionally linear EXR).
    Render(render::Args),
    /// Render with the sparse method and the brute-force reference and print the error and
    /// cost as one JSON object.
    Compare(compare::Args),
    /// Sweep quality settings: per configuration the time of every stage, the device memory
    /// held and the indirect error against brute force (and exact); writes results.json,
    /// results.csv and plots into --out (see docs/measurements/benchmark.md).
    Bench(bench::Args),
    /// Relight every frame of an RGB-D recording (a TUM or Open3D/Redwood folder, or an MCAP
    /// file) with a scene's virtual content: writes composited and indirect-only frames and a
    /// timing and stability summary.
    Replay(replay::Args),
    /// Render a synthetic TUM RGB-D recording of a scene's lit room (colour = direct radiance
    /// / radiance_scale, depth, ground-truth poses along an arc) for closed-loop tests of
    /// `replay` (see docs/measurements/closed-loop.md).
    RecordSynthetic(record_synthetic::Args),
    /// Load benchmark of the service: streams replaying a recording plus HTTP render clients,
    /// for a fixed time; prints throughput, latency percentiles, dropped frames, peak memory.
    Load(load::Args),
    /// Serve the HTTP + WebSocket API (see docs/service.md). Every flag also reads the
    /// environment variable shown; SIGINT/SIGTERM shut down gracefully.
    Serve(relume::service::Config),
    /// Print the service's OpenAPI 3.1 document (the contents of proto/openapi.json).
    Openapi,
}

impl Command {
    pub fn run(self) -> anyhow::Result<()> {
        match self {
            Command::Render(args) => render::run(args),
            Command::Compare(args) => compare::run(args),
            Command::Bench(args) => bench::run(args),
            Command::Replay(args) => replay::run(args),
            Command::RecordSynthetic(args) => record_synthetic::run(args),
            Command::Load(args) => load::run(args),
            Command::Serve(config) => serve::run(config),
            Command::Openapi => serve::openapi(),
        }
    }
}

/// A reference to measure against, beside the brute force.
#[derive(Clone, Copy, ValueEnum)]
pub enum Reference {
    Exact,
}

/// How `--reference exact` computes its reference (`compare`, `bench`): the options beyond
/// `--val-stride`, which each command states itself.
#[derive(clap::Args)]
pub struct ExactArgs {
    /// Exact reference: where it runs (auto: the CPU on CPU adapters or with
    /// --reference-samples / --spp > 1, the GPU otherwise).
    #[arg(long, value_enum, default_value_t = ReferenceDevice::Auto, requires = "reference")]
    pub reference_device: ReferenceDevice,
    /// Exact reference (CPU): N importance-sampled VALs per receiver instead of every VAL;
    /// reports the reference's noise and noise-corrected errors.
    #[arg(long, conflicts_with = "val_stride", requires = "reference")]
    pub reference_samples: Option<u32>,
    /// Exact reference (CPU): jittered samples per pixel (box filter); 1 = the pixel centre.
    #[arg(long, default_value_t = 1, requires = "reference")]
    pub spp: u32,
}

impl ExactArgs {
    /// The checked options with every `val_stride`-th VAL; `Err` names the flag.
    pub fn options(&self, val_stride: u32) -> anyhow::Result<ExactOptions> {
        let options = ExactOptions {
            device: self.reference_device,
            val_stride,
            samples: self.reference_samples,
            spp: self.spp,
            blockers_from: 0.0,
            estimator: false,
        };
        options.check().map_err(anyhow::Error::msg)?;
        Ok(options)
    }
}

#[derive(clap::Args)]
pub struct Size {
    /// Override the camera's width in pixels (1..=8192).
    #[arg(long)]
    pub width: Option<u32>,
    /// Override the camera's height in pixels (1..=8192).
    #[arg(long)]
    pub height: Option<u32>,
}

impl Size {
    /// The flags' size, else the scene camera's.
    pub fn resolve(&self, scene: &Scene) -> anyhow::Result<(u32, u32)> {
        Ok((
            checked_side("width", self.width.unwrap_or(scene.camera.width))?,
            checked_side("height", self.height.unwrap_or(scene.camera.height))?,
        ))
    }

    /// The flags' size, both or neither.
    pub fn resolve_optional(&self) -> anyhow::Result<Option<(u32, u32)>> {
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

/// `--val-stride`, checked.
pub fn checked_val_stride(val_stride: u32) -> anyhow::Result<u32> {
    anyhow::ensure!(val_stride >= 1, "--val-stride: must be at least 1, got {val_stride}");
    Ok(val_stride)
}

pub fn load(path: &Path) -> anyhow::Result<Scene> {
    load_at(path, None)
}

/// [`load`] at `quality` instead of the scene file's `settings.quality` (`None`: the file's).
pub fn load_at(path: &Path, quality: Option<Quality>) -> anyhow::Result<Scene> {
    Scene::load_at(path, quality).with_context(|| format!("loading scene {}", path.display()))
}

/// A scene for `record-synthetic`, which is lit by the scene's own spot light.
pub fn load_lit(path: &Path) -> anyhow::Result<Scene> {
    let scene = load(path)?;
    anyhow::ensure!(
        scene.light.is_some(),
        "{}: light: required by this command (a scene without one is lit by RGB-D frames: use `replay`)",
        path.display()
    );
    Ok(scene)
}

/// A scene for `render` and `compare`: lit by its spot `light` or by its `lights` (each makes
/// direct light and VALs from its RSM). Prints its resolved configuration (quality level,
/// technique, every parameter and the reason for it) to stderr.
pub fn load_renderable(path: &Path, quality: Option<Quality>) -> anyhow::Result<Scene> {
    let scene = load_at(path, quality)?;
    anyhow::ensure!(
        scene.light.is_some() || !scene.lights.is_empty(),
        "{}: light: required by this command unless the scene has `lights` (a scene with neither is lit by RGB-D frames: use `replay`)",
        path.display()
    );
    eprintln!("{}", scene.resolved.report());
    Ok(scene)
}

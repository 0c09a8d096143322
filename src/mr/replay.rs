//! `relume replay`: relight every frame of a recorded RGB-D sequence (docs/design.md §6) and write
//! the composited frames, the indirect-only images and a timing and stability summary.

use crate::gpu::timing::TimingSource;
use crate::gpu::{Gpu, GpuError};
use crate::image::LinearImage;
use crate::mr::environment::Environment;
use crate::mr::{AccumulateOptions, MrOptions, MrRenderer, relative_change};
use crate::renderer::budget::{self, BudgetController, FrameParameters};
use crate::renderer::estimate::PER_FRAME;
use crate::rgbd::recording::{Recording, RecordingOptions};
use crate::scene::Scene;
use anyhow::Context;
use glam::Vec3;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What to replay and how.
#[derive(Clone, Debug)]
pub struct ReplayOptions {
    pub recording: PathBuf,
    pub recording_options: RecordingOptions,
    pub scene: PathBuf,
    /// Output directory: `composited/NNNN.png`, `indirect/NNNN.png`, `summary.json`.
    pub out: PathBuf,
    /// Output size (default: the recording's).
    pub size: Option<(u32, u32)>,
    /// Replay the first N frames only.
    pub frames: Option<usize>,
    pub accumulate: Option<AccumulateOptions>,
    /// Exposure of the virtual object in the composite (see [`MrOptions::exposure`]).
    pub exposure: f32,
    /// Draw a progress bar on standard error.
    pub progress: bool,
    /// Hold the frame time under this many ms by moving between parameter sets frame by
    /// frame (`renderer::budget`); `None` (or the scene's `settings.budget_ms` when given):
    /// the scene's level throughout.
    pub budget_ms: Option<f32>,
}

/// Figures of one replay, written as `summary.json`.
#[derive(Clone, Debug, Serialize)]
pub struct ReplaySummary {
    pub adapter: String,
    pub timing: &'static str,
    pub frames: usize,
    pub width: u32,
    pub height: u32,
    pub accumulate: bool,
    /// VALs that lit each frame.
    pub vals_per_frame: Vec<u32>,
    /// The differential pass's receivers each frame (0 where it did not run).
    pub receivers_per_frame: Vec<u32>,
    /// Milliseconds per stage, one entry per frame.
    pub stage_ms: BTreeMap<String, Vec<f64>>,
    /// Wall time per frame, from frame loaded to images read back (ms).
    pub frame_ms: Vec<f64>,
    /// Relative change of the object's per-sparse-point diffuse irradiance from the previous
    /// frame ([`relative_change`]); one entry per frame after the first.
    pub irradiance_change: Vec<f64>,
    /// Mean of `irradiance_change`.
    pub mean_irradiance_change: f64,
    /// Exposure used for the indirect-only images (fixed from the first lit frame on).
    pub indirect_exposure: f32,
    /// The frame-time budget the replay held (`--budget-ms`, else the scene's `budget_ms`).
    pub budget_ms: Option<f32>,
    /// What each frame ran at: the level and the parameters (the scene's level throughout
    /// without a budget).
    pub parameters: Vec<FrameParameters>,
    /// Each frame's estimated relative RMSE of its indirect light against the exact reference
    /// (`renderer::estimate::PER_FRAME`; `null` where the frame had nothing to estimate).
    pub error_estimate: Vec<Option<f64>>,
    /// Each frame's time spent on that estimate (ms, part of `frame_ms`).
    pub error_estimate_ms: Vec<f64>,
    /// Mean absolute change of the composite from the previous frame, 8-bit levels per channel;
    /// one entry per frame after the first.
    pub composite_change: Vec<f64>,
    /// 90th percentile of `frame_ms` after the first 5 frames (all of them when fewer).
    pub p90_frame_ms_after_5: f64,
    /// Frames per level the frames ran at.
    pub level_frames: BTreeMap<String, usize>,
}

/// Replay `options.recording` on `gpu`, writing images as it goes.
pub fn replay(gpu: &Gpu, options: &ReplayOptions) -> anyhow::Result<ReplaySummary> {
    let recording = Recording::open(&options.recording, &options.recording_options)?;
    let scene = Scene::load(&options.scene).with_context(|| format!("loading scene {}", options.scene.display()))?;
    let intrinsics = recording.intrinsics();
    let (width, height) = options.size.unwrap_or((intrinsics.width, intrinsics.height));
    let frames = options.frames.unwrap_or(usize::MAX).min(recording.len());
    let mr_options = MrOptions { width, height, exposure: options.exposure, accumulate: options.accumulate };
    let mut mr = MrRenderer::new(gpu, &scene, mr_options)?;
    // `settings.environment` holds a path, so it is not among the scene's (plain-data) settings:
    // it is read from the description, its map relative to the scene file.
    let text =
        std::fs::read_to_string(&options.scene).with_context(|| format!("reading {}", options.scene.display()))?;
    let description = crate::scene::SceneDescription::from_json_str(&text)?;
    let base_dir = options.scene.parent().unwrap_or(Path::new("."));
    mr.set_environment(Environment::from_settings(&description.settings.environment, base_dir)?);
    mr.renderer_mut().set_error_estimate(Some(PER_FRAME));
    let level = scene.resolved.quality;
    let analysis = &scene.resolved.analysis;
    let budget_ms = options.budget_ms.or(description.settings.budget_ms);
    let mut controller = budget_ms
        .map(|ms| BudgetController::at_level(ms, budget::ladder(analysis, &description.settings, true), level));
    let level_parameters = budget::level_parameters(level, analysis, &description.settings);
    let base_rgbd = scene.settings.rgbd;
    let composited_dir = options.out.join("composited");
    let indirect_dir = options.out.join("indirect");
    for dir in [&composited_dir, &indirect_dir] {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let bar = progress_bar(options.progress, frames as u64);
    let mut summary = ReplaySummary {
        adapter: gpu.adapter_name(),
        timing: "",
        frames,
        width,
        height,
        accumulate: options.accumulate.is_some(),
        vals_per_frame: Vec::new(),
        receivers_per_frame: Vec::new(),
        stage_ms: BTreeMap::new(),
        frame_ms: Vec::new(),
        irradiance_change: Vec::new(),
        mean_irradiance_change: 0.0,
        indirect_exposure: 0.0,
        budget_ms,
        parameters: Vec::new(),
        error_estimate: Vec::new(),
        error_estimate_ms: Vec::new(),
        composite_change: Vec::new(),
        p90_frame_ms_after_5: 0.0,
        level_frames: BTreeMap::new(),
    };
    let mut previous_composite: Option<Vec<[u8; 3]>> = None;
    let mut previous: Option<Vec<Vec3>> = None;
    let mut indirect_exposure = None;
    for i in 0..frames {
        let frame = recording.frame(i)?;
        let parameters = controller.as_ref().map_or(level_parameters, BudgetController::parameters);
        apply(gpu, &mut mr, &parameters, &scene, base_rgbd, (width, height))?;
        let start = Instant::now();
        let mut out = mr.render_frame(gpu, &frame)?;
        let (w, h) = parameters.scaled(width, height);
        let upscale = Instant::now();
        out.composited = budget::upscale_rgb(&out.composited, w, h, width, height);
        if let Some((_, ms)) = out.timings.stages.iter_mut().find(|(s, _)| s == crate::mr::COMPOSITE_STAGE) {
            // The composite scaled back up to the output size (dynamic resolution) is part of it.
            *ms += upscale.elapsed().as_secs_f64() * 1e3;
        }
        let frame_ms = start.elapsed().as_secs_f64() * 1e3;
        summary.frame_ms.push(frame_ms);
        if let Some(c) = controller.as_mut() {
            c.observe(frame_ms);
        }
        *summary.level_frames.entry(parameters.level.name().to_owned()).or_default() += 1;
        summary.parameters.push(parameters);
        summary.error_estimate.push(out.error_estimate.map(|e| e.rel_rmse));
        summary.error_estimate_ms.push(out.error_estimate.map_or(0.0, |e| e.ms));
        if let Some(p) = &previous_composite {
            summary.composite_change.push(budget::mean_abs_change(p, &out.composited));
        }
        summary.timing = match out.timings.source {
            TimingSource::GpuTimestamps => "gpu_timestamps",
            TimingSource::WallClock => "wall_clock",
        };
        for (stage, ms) in &out.timings.stages {
            summary.stage_ms.entry(stage.clone()).or_default().push(*ms);
        }
        summary.vals_per_frame.push(out.val_count);
        summary.receivers_per_frame.push(out.differential.as_ref().map_or(0, |d| d.grid.receivers.len() as u32));
        if let Some(p) = &previous {
            summary.irradiance_change.push(relative_change(p, &out.sparse_irradiance));
        }
        previous = Some(out.sparse_irradiance);
        let exposure = *indirect_exposure.get_or_insert_with(|| out.indirect.auto_exposure());
        let name = format!("{i:04}.png");
        write_rgb(&composited_dir.join(&name), width, height, &out.composited)?;
        write_indirect(&indirect_dir.join(&name), &out.indirect, exposure)?;
        previous_composite = Some(out.composited);
        bar.inc(1);
    }
    summary.p90_frame_ms_after_5 =
        p90(summary.frame_ms.get(5..).filter(|v| !v.is_empty()).unwrap_or(&summary.frame_ms));
    bar.finish_and_clear();
    let n = summary.irradiance_change.len().max(1) as f64;
    summary.mean_irradiance_change = summary.irradiance_change.iter().fold(0.0, |a, b| a + b) / n;
    summary.indirect_exposure = indirect_exposure.unwrap_or(1.0);
    let json = serde_json::to_string_pretty(&summary)?;
    let path = options.out.join("summary.json");
    std::fs::write(&path, json).with_context(|| format!("writing {}", path.display()))?;
    Ok(summary)
}

/// Sets what the next frame of `mr` runs at: the visibility mode, the near field, the RGB-D
/// grid (the scene's `grid_step` times `vals_step`, at most 64), the differential pass's
/// receivers, the render size and the camera's triangles.
fn apply(
    gpu: &Gpu,
    mr: &mut MrRenderer,
    p: &FrameParameters,
    scene: &Scene,
    rgbd: crate::rgbd::RgbdSettings,
    size: (u32, u32),
) -> Result<(), GpuError> {
    let renderer = mr.renderer_mut();
    renderer.set_occlusion(p.occlusion, scene.settings.visibility.rule);
    renderer.set_near_field(p.near_field);
    renderer.set_camera_lod(gpu, p.camera_lod())?;
    let settings = mr.frame_settings_mut();
    settings.rgbd = crate::rgbd::RgbdSettings { grid_step: (rgbd.grid_step * p.vals_step).min(64), ..rgbd };
    settings.receivers_step = p.receivers_step;
    (settings.width, settings.height) = p.scaled(size.0, size.1);
    Ok(())
}

/// The 90th percentile (nearest rank) of `values`; 0 for none.
pub fn p90(values: &[f64]) -> f64 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    match sorted.len() {
        0 => 0.0,
        n => sorted[(n * 9).div_ceil(10) - 1],
    }
}

/// A progress bar over `frames` frames on standard error, or a hidden one.
pub fn progress_bar(visible: bool, frames: u64) -> indicatif::ProgressBar {
    if !visible {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(frames);
    let style = indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} frames, {elapsed} elapsed, eta {eta}")
        .expect("a valid template");
    bar.set_style(style);
    bar
}

fn write_rgb(path: &Path, width: u32, height: u32, pixels: &[[u8; 3]]) -> anyhow::Result<()> {
    let image = crate::image::rgb8_image(width, height, pixels).context("composited image")?;
    image.save(path).with_context(|| format!("writing {}", path.display()))
}

fn write_indirect(path: &Path, image: &LinearImage, exposure: f32) -> anyhow::Result<()> {
    image.write_png(path, exposure).with_context(|| format!("writing {}", path.display()))
}

/// Mean, median and maximum of each stage's per-frame times and of the whole frame's
/// (`total`: its label and per-frame times), as printed after a replay.
pub fn stage_table(stage_ms: &BTreeMap<String, Vec<f64>>, total: (&str, &[f64])) -> String {
    let mut lines = vec![format!("{:<14} {:>10} {:>10} {:>10}", "stage", "mean ms", "median ms", "max ms")];
    let mut row = |name: &str, v: &[f64]| {
        let mut sorted = v.to_vec();
        sorted.sort_by(f64::total_cmp);
        let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
        let median = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
        let max = sorted.last().copied().unwrap_or(0.0);
        lines.push(format!("{name:<14} {mean:>10.2} {median:>10.2} {max:>10.2}"));
    };
    for (stage, v) in stage_ms {
        row(stage, v);
    }
    row(total.0, total.1);
    lines.join("\n")
}

//! `relume render`: a scene to PNG (and EXR), one component or all three.

use super::{Size, checked_val_stride, load_renderable};
use relume::bench::compare::{ExactOptions, ReferenceDevice, traced_level_frame};
use relume::gpu::Gpu;
use relume::image::LinearImage;
use relume::renderer::{Component, Components, Method, Renderer};
use relume::scene::Quality;
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct Args {
    /// Scene description (JSON).
    scene: PathBuf,
    /// Output PNG (8-bit sRGB after exposure and clipping).
    #[arg(long, default_value = "out.png")]
    out: PathBuf,
    /// Also write linear float radiance (OpenEXR, RGBA f32, alpha = coverage).
    #[arg(long)]
    hdr: Option<PathBuf>,
    /// Which light to write. A component left out is not computed (`direct` runs no gather).
    #[arg(long, value_enum, default_value_t = Component::Full)]
    component: Component,
    /// Write every component from one frame into this directory instead: `direct`,
    /// `indirect` and `full`, each as `.png` and `.exr`, all at the full image's exposure.
    #[arg(long, conflicts_with_all = ["out", "hdr", "component"])]
    out_dir: Option<PathBuf>,
    /// How the indirect light is computed (default: the level's technique: sparse, or exact at
    /// quality `reference`, or what the scene's `settings.levels` names).
    #[arg(long, value_enum)]
    method: Option<Method>,
    /// The quality level, instead of the scene file's `settings.quality`.
    #[arg(long, value_enum)]
    quality: Option<Quality>,
    #[command(flatten)]
    size: Size,
    /// Exposure multiplier before tone mapping (default: the scene's, else automatic).
    #[arg(long)]
    exposure: Option<f32>,
    /// With --method exact: use every N-th VAL (flux x N), for large scenes.
    #[arg(long, default_value_t = 1)]
    val_stride: u32,
    /// With --method estimator: VALs drawn per pixel, each with a shadow ray (1..=256,
    /// default the level's `draws`, else 32).
    #[arg(long)]
    draws: Option<u32>,
    /// With --method exact or estimator: where it runs (auto: the CPU on CPU adapters, the
    /// estimator as its twin's systematic draws; the GPU otherwise; as `compare
    /// --reference-device`).
    #[arg(long, value_enum)]
    reference_device: Option<ReferenceDevice>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let val_stride = checked_val_stride(args.val_stride)?;
    anyhow::ensure!(
        args.reference_device.is_none() || args.method.is_none_or(|m| matches!(m, Method::Exact | Method::Estimator)),
        "--reference-device: only with --method exact or estimator"
    );
    if let Some(e) = args.exposure {
        anyhow::ensure!(e.is_finite() && e > 0.0, "--exposure: must be a positive number, got {e}");
    }
    use relume::gpu::references::estimator::{DEFAULT_SAMPLES, MAX_SAMPLES};
    let draws = args.draws;
    if let Some(draws) = draws {
        anyhow::ensure!(
            (1..=MAX_SAMPLES).contains(&draws),
            "--draws: must be a count of draws per pixel in 1..={MAX_SAMPLES}, got {draws}"
        );
    }
    anyhow::ensure!(
        args.draws.is_none() || args.method == Some(Method::Estimator),
        "--draws: only with --method estimator"
    );
    let scene = load_renderable(&args.scene, args.quality)?;
    // The scene's quality level asks for a technique; --method overrides it.
    let method = args.method.unwrap_or(scene.resolved.method.into());
    anyhow::ensure!(
        args.reference_device.is_none() || matches!(method, Method::Exact | Method::Estimator),
        "--reference-device: only with --method exact or estimator (or a level whose technique is one of them)"
    );
    let (w, h) = args.size.resolve(&scene)?;
    let gpu = Gpu::new()?;
    let mut renderer = Renderer::new(&gpu, &scene)?;
    renderer.set_exact_val_stride(val_stride);
    // The level's draws (`settings.levels`) unless --draws gives them.
    let draws = draws.or(scene.resolved.estimator_draws).unwrap_or(DEFAULT_SAMPLES);
    renderer.set_estimator(draws, scene.settings.seed as u32);
    renderer.set_error_estimate(Some(relume::renderer::estimate::PER_FRAME));
    let needs = if args.out_dir.is_some() { Components::ALL } else { args.component.needs() };
    let device = args.reference_device.unwrap_or(ReferenceDevice::Auto);
    let frame = match ExactOptions::traced(method, device) {
        // A direct-only image needs no reference. --val-stride thins the exact reference's VALs.
        Some(options) if needs.indirect => {
            let options = ExactOptions { val_stride: if options.estimator { 1 } else { val_stride }, ..options };
            traced_level_frame(&gpu, &mut renderer, w, h, &options, scene.resolved.quality)?
        }
        _ => renderer.render_components(&gpu, method, w, h, needs)?,
    };
    let exposure_of =
        |image: &LinearImage| args.exposure.or(scene.settings.exposure).unwrap_or_else(|| image.auto_exposure());
    let (written, exposure) = match &args.out_dir {
        Some(dir) => {
            std::fs::create_dir_all(dir).map_err(|e| anyhow::anyhow!("--out-dir: creating {}: {e}", dir.display()))?;
            let full = Component::Full.of(&frame);
            let exposure = exposure_of(&full);
            for (name, image) in
                [("direct", frame.direct.clone()), ("indirect", frame.indirect.clone()), ("full", full)]
            {
                write(&image, &dir.join(format!("{name}.png")), Some(&dir.join(format!("{name}.exr"))), exposure)?;
            }
            (dir.clone(), exposure)
        }
        None => {
            let image = args.component.of(&frame);
            let exposure = exposure_of(&image);
            write(&image, &args.out, args.hdr.as_deref(), exposure)?;
            (args.out.clone(), exposure)
        }
    };
    let stages: Vec<String> = frame.timings.stages.iter().map(|(n, ms)| format!("{n} {ms:.2}")).collect();
    eprintln!(
        "wrote {} ({w}x{h}, {} VALs, {} sparse points, exposure {exposure:.4}); {:?} ms: {}",
        written.display(),
        frame.val_count,
        scene.sparse_point_count(),
        frame.timings.source,
        stages.join(", ")
    );
    let estimate = frame.error_estimate;
    match estimate {
        Some(e) => eprintln!("error estimate: {}", e.summary()),
        None => eprintln!("error estimate: none (no indirect light computed, or the exact reference rendered it)"),
    }
    let summary = serde_json::json!({
        "written": written,
        "width": w,
        "height": h,
        "method": method,
        "quality": scene.resolved.quality,
        "val_count": frame.val_count,
        "exposure": exposure,
        "timings_ms": frame.timings.stages.iter().cloned().collect::<std::collections::BTreeMap<String, f64>>(),
        "error_estimate": estimate,
    });
    println!("{summary}");
    Ok(())
}

fn write(image: &LinearImage, png: &Path, exr: Option<&Path>, exposure: f32) -> anyhow::Result<()> {
    image.write_png(png, exposure)?;
    if let Some(exr) = exr {
        image.write_exr(exr)?;
    }
    Ok(())
}

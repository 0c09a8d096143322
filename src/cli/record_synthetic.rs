//! `relume record-synthetic`: a TUM RGB-D recording of a scene's lit room, rendered here.

use super::{Size, load_lit};
use relume::gpu::Gpu;
use relume::mr::synthetic::{DEFAULT_ARC_DEG, DEFAULT_FRAMES, SyntheticOptions, record};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Scene with the room and its spot light (the camera gives the arc's centre and target,
    /// the field of view and the default size).
    scene: PathBuf,
    /// Output directory (TUM layout: rgb.txt, depth.txt, groundtruth.txt, rgb/, depth/,
    /// intrinsics.json, and synthetic.json with the radiance scale).
    #[arg(long)]
    out: PathBuf,
    /// Frames along the arc (1..=1000).
    #[arg(long, default_value_t = DEFAULT_FRAMES)]
    frames: u32,
    /// Width of the camera's horizontal arc around its target, degrees (0..=300).
    #[arg(long, default_value_t = DEFAULT_ARC_DEG)]
    arc_deg: f64,
    /// Turn of the arc's centre from the scene camera about its up axis, degrees
    /// (-180..=180): an arc turned away from the lit surfaces records less of them.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    turn_deg: f64,
    #[command(flatten)]
    size: Size,
    /// Radiance (W/(m² sr)) written as colour 1 (default: the largest direct radiance over
    /// all frames, so nothing clips). Replay with settings.rgbd.radiance_scale set to it.
    #[arg(long)]
    radiance_scale: Option<f32>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let scene = load_lit(&args.scene)?;
    let (width, height) = args.size.resolve(&scene)?;
    let options = SyntheticOptions {
        out: args.out,
        frames: args.frames,
        width,
        height,
        arc_deg: args.arc_deg,
        turn_deg: args.turn_deg,
        radiance_scale: args.radiance_scale,
    };
    options.check().map_err(|(flag, message)| anyhow::anyhow!("--{flag}: {message}"))?;
    let gpu = Gpu::new()?;
    let metadata = record(&gpu, &scene, &options)?;
    eprintln!(
        "wrote {} ({} frames, {width}x{height}, {}° arc; radiance_scale {:.6}{}, {:.4} % of channels clipped, {:.2} % of pixels without depth)",
        options.out.display(),
        metadata.frames,
        metadata.arc_deg,
        metadata.radiance_scale,
        if metadata.radiance_scale_auto { " (auto)" } else { "" },
        100.0 * metadata.clipped_fraction,
        100.0 * metadata.depth_missing_fraction,
    );
    Ok(())
}

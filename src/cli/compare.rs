//! `relume compare`: the sparse method against the brute force (and exact visibility), as
//! one JSON object ([`relume::bench::compare::CompareReport`]).

use super::{ExactArgs, Reference, Size, load_renderable};
use relume::gpu::Gpu;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    scene: PathBuf,
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
    #[command(flatten)]
    exact: ExactArgs,
    /// The quality level, instead of the scene file's `settings.quality`.
    #[arg(long, value_enum)]
    quality: Option<relume::scene::Quality>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let options = args.exact.options(args.val_stride)?;
    let scene = load_renderable(&args.scene, args.quality)?;
    let size = args.size.resolve(&scene)?;
    let gpu = Gpu::new()?;
    let exact = args.reference.map(|Reference::Exact| &options);
    let report = relume::bench::compare::compare(&gpu, &scene, size, exact, args.images.as_deref())?;
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}

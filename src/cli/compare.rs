//! `relume compare`: the sparse method against the brute force (and exact visibility), as
//! one JSON object ([`relume::bench::compare::CompareReport`]).

use super::{Reference, Size, load_lit};
use relume::bench::compare::{ExactOptions, ReferenceDevice};
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
    /// Exact reference: where it runs (auto: the CPU on CPU adapters or with
    /// --reference-samples / --spp > 1, the GPU otherwise).
    #[arg(long, value_enum, default_value_t = ReferenceDevice::Auto, requires = "reference")]
    reference_device: ReferenceDevice,
    /// Exact reference (CPU): N importance-sampled VALs per receiver instead of every VAL;
    /// reports the reference's noise and noise-corrected errors.
    #[arg(long, conflicts_with = "val_stride", requires = "reference")]
    reference_samples: Option<u32>,
    /// Exact reference (CPU): jittered samples per pixel (box filter); 1 = the pixel centre.
    #[arg(long, default_value_t = 1, requires = "reference")]
    spp: u32,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let options = ExactOptions {
        device: args.reference_device,
        val_stride: args.val_stride,
        samples: args.reference_samples,
        spp: args.spp,
    };
    options.check().map_err(anyhow::Error::msg)?;
    let scene = load_lit(&args.scene)?;
    let size = args.size.resolve(&scene)?;
    let gpu = Gpu::new()?;
    let exact = args.reference.map(|Reference::Exact| &options);
    let report = relume::bench::compare::compare(&gpu, &scene, size, exact, args.images.as_deref())?;
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}

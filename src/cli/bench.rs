//! `relume bench`: the sweep of quality settings, the paper's Table 1, the FMA and temporal
//! measurements.

use super::{ExactArgs, Reference, Size};
use relume::gpu::Gpu;
use std::path::PathBuf;
use std::time::Instant;

#[derive(clap::Args)]
pub struct Args {
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
    #[command(flatten)]
    exact: ExactArgs,
    /// With --reference exact: also measure the speed at equal error, the time relume's own
    /// converging estimator (the CPU exact reference with N importance-sampled VALs per pixel)
    /// needs for each configuration's error; the N to measure (default 2,4,...,256).
    #[arg(long, value_name = "N1,N2,...", num_args = 0..=1, default_missing_value = "")]
    equal_error: Option<String>,
    /// Every quality level of the scene (fast, balanced, accurate, reference) against one exact
    /// reference: levels.json and levels.md in --out (with --equal-error, each level's
    /// estimator time at equal error).
    #[arg(long, conflicts_with_all = ["sweep", "grid", "quick", "table1", "reference"])]
    levels: bool,
    /// With --levels: also measure the configurations one parameter away from a level (each
    /// parameter at a value another level takes) and say which level any of them dominates
    /// (more accurate and at least 1.2x faster).
    #[arg(long, requires = "levels")]
    candidates: bool,
    /// With --levels: also measure the estimator of the exact reference over the reference's
    /// VALs (VALs drawn per pixel by their unoccluded light, a shadow ray each; the GPU pass, or
    /// on a CPU adapter its CPU twin, as `relume render` runs it) at each of these draws per
    /// pixel, as configurations beside the candidates (with --candidates: 16, 32, 64 and 256 unless
    /// given).
    #[arg(long, requires = "levels", value_name = "N1,N2,...")]
    gpu_estimator: Option<String>,
    /// With --levels: render nothing, draw the plot of the levels.json already in --out again.
    #[arg(long, requires = "levels", conflicts_with_all = ["candidates", "equal_error", "gpu_estimator"])]
    replot: bool,
    /// With --levels: the image size (default: the scene camera's).
    #[command(flatten)]
    size: Size,
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
}

pub fn run(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.val_stride.is_none() || args.reference.is_some() || args.levels,
        "--val-stride: only with --reference exact or --levels"
    );
    anyhow::ensure!(
        args.equal_error.is_none() || args.reference.is_some() || args.levels,
        "--equal-error: only with --reference exact or --levels"
    );
    anyhow::ensure!(args.levels || args.size.resolve_optional()?.is_none(), "--width/--height: only with --levels");
    let exact = match args.reference {
        Some(Reference::Exact) => Some(args.exact.options(args.val_stride.unwrap_or(1))?),
        None => None,
    };
    let equal_error = match args.equal_error.as_deref() {
        None => None,
        Some("") => Some(relume::bench::equal_error::DEFAULT_SAMPLES.to_vec()),
        Some(list) => Some(
            list.split(',')
                .map(|n| n.trim().parse::<u32>().map_err(|e| anyhow::anyhow!("--equal-error: {n:?}: {e}")))
                .collect::<anyhow::Result<Vec<u32>>>()?,
        ),
    };
    if args.levels {
        return levels(&args, equal_error.as_deref());
    }
    let options = relume::bench::BenchOptions {
        scene: args.scene,
        sweep: relume::bench::Sweep::parse(&args.sweep)?,
        grid: args.grid,
        quick: args.quick,
        exact,
        equal_error,
        references: !args.table1 && !args.no_references,
        table1: args.table1,
        out: args.out,
        fma: !args.no_fma,
        temporal: !args.no_temporal,
        plots: !args.no_plots,
    };
    let gpu = Gpu::new()?;
    let start = Instant::now();
    let results = relume::bench::run(&gpu, &options, &mut |what| {
        eprintln!("[{:7.1} s] {what}", start.elapsed().as_secs_f64());
    })?;
    for curve in &results.equal_error_curves {
        let points: Vec<String> =
            curve.points.iter().map(|p| format!("N {}: {:.0} ms, {:.4}", p.samples, p.ms, p.rel_rmse)).collect();
        eprintln!(
            "converging estimator ({}): {}; fitted {:.0} ms + {:.2} ms per sample",
            curve.label,
            points.join("; "),
            curve.fixed_ms,
            curve.per_sample_ms
        );
    }
    for r in results.configs.iter().filter(|r| r.at_equal_error.is_some()) {
        let (Some(at), Some(error)) = (r.at_equal_error, r.error_vs_exact()) else {
            continue;
        };
        eprintln!(
            "{}: error {error:.4} in {:.0} ms; the estimator needs {:.1} samples, {:.0} ms{}: {:.2}x at equal error",
            relume::bench::describe(&r.config),
            r.sparse_indirect_ms,
            at.samples,
            at.estimator_ms,
            if at.extrapolated { " (extrapolated)" } else { "" },
            at.speedup
        );
    }
    for r in &results.brute_force_ism {
        let error = |name: &str, e: Option<relume::bench::compare::IndirectError>| {
            e.map_or(String::new(), |e| format!(", {:.4} / FLIP {:.4} vs {name}", e.rel_rmse, e.flip_mean))
        };
        eprintln!(
            "brute_force_ism ({} maps of {}², pull-push {}, {}x{}): {:.0} ms (ISM stages {:.0}){}{}",
            r.ism.count,
            r.ism.resolution,
            r.ism.pull_push_levels,
            r.config.width,
            r.config.height,
            r.indirect_ms,
            r.ism_ms,
            error("brute force", r.vs_brute_force),
            error("exact", r.vs_exact)
        );
    }
    eprintln!(
        "{} configurations on {} ({} timing); wrote {}",
        results.configs.len(),
        results.adapter,
        results.timing.as_str(),
        options.out.join("results.json").display()
    );
    Ok(())
}

/// `relume bench --levels`: every quality level against one exact reference.
fn levels(args: &Args, equal_error: Option<&[u32]>) -> anyhow::Result<()> {
    let json = args.out.join("levels.json");
    let report: serde_json::Value = if args.replot {
        let text =
            std::fs::read_to_string(&json).map_err(|e| anyhow::anyhow!("--replot: reading {}: {e}", json.display()))?;
        serde_json::from_str(&text).map_err(|e| anyhow::anyhow!("--replot: {}: {e}", json.display()))?
    } else {
        let exact = args.exact.options(args.val_stride.unwrap_or(1))?;
        let size = args.size.resolve_optional()?;
        let gpu = Gpu::new()?;
        use relume::gpu::references::estimator::MAX_SAMPLES as MAX_DRAWS;
        let draws = match args.gpu_estimator.as_deref() {
            None => Vec::new(),
            Some(list) => list
                .split(',')
                .map(|n| match n.trim().parse::<u32>() {
                    Ok(n) if (1..=MAX_DRAWS).contains(&n) => Ok(n),
                    _ => Err(anyhow::anyhow!("--gpu-estimator: {n:?} is not a count of draws in 1..={MAX_DRAWS}")),
                })
                .collect::<anyhow::Result<Vec<u32>>>()?,
        };
        let options =
            relume::bench::levels::LevelsOptions { equal_error, candidates: args.candidates, gpu_estimator: &draws };
        let report = relume::bench::levels::levels(&gpu, &args.scene, size, &exact, &options)?;
        std::fs::create_dir_all(&args.out)?;
        std::fs::write(&json, serde_json::to_string_pretty(&report)?)?;
        let table = relume::bench::levels::markdown(&report);
        std::fs::write(args.out.join("levels.md"), &table)?;
        eprint!("{table}");
        eprintln!("wrote {}", json.display());
        serde_json::to_value(&report)?
    };
    let (title, points, curve) = relume::bench::levels::plot_points(&report);
    relume::bench::plot::write_levels(&args.out, &title, &points, &curve).map_err(anyhow::Error::msg)?;
    eprintln!("wrote {}", args.out.join("levels.svg").display());
    Ok(())
}

//! How close the gather runs to the adapter's arithmetic limit: an FMA-bound kernel
//! (`shaders/fma.wgsl`) and the gather, timed in the same run with the same timing source; the
//! gather at several tile (= workgroup) sizes.

use super::BenchError;
use crate::bench::compare;
use crate::gpu::pass::module_from_source;
use crate::gpu::raw::RawGathered;
use crate::gpu::shader::Wgsl;
use crate::gpu::sparse::gather::{Gather, GatherInput, GatherLobes};
use crate::gpu::timing::{Recorder, TimingSource};
use crate::gpu::{Gpu, GpuError, Lobes};
use crate::renderer::Renderer;
use crate::scene::Scene;

const WGSL: &str = include_str!("fma.wgsl");
/// Independent vec4 chains per invocation (unrolled in the shader).
const CHAINS: u64 = 8;
const WORKGROUP_SIZE: u32 = 64;

/// The FMA kernel's and the gather variants' throughput.
#[derive(Clone, Debug, serde::Serialize)]
pub struct FmaReport {
    pub timing: TimingSource,
    /// Scalar FMAs the kernel ran, and its best time of `repeats`.
    pub fma_count: u64,
    pub fma_ms: f64,
    pub fma_per_s: f64,
    pub vals: u32,
    pub sparse_points: usize,
    pub glossy: bool,
    pub gather_variants: Vec<GatherVariant>,
    pub note: &'static str,
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct GatherVariant {
    /// What it sums: `diffuse`, `glossy_lights` (the lobe and its mean position, the paper's
    /// glossy lights) or `glossy_radiance` (the lobe alone, the default interpolation).
    pub lobes: GatherLobes,
    /// VALs per workgroup-memory tile and threads per workgroup (relume's default is 64).
    pub tile_size: u32,
    /// Sparse points per invocation (relume's default: `gather::receivers_for` the adapter).
    pub receivers: u32,
    /// Invocations per sparse point (relume's default: `gather::lanes_for` the adapter).
    pub lanes: u32,
    /// Best of `repeats` timed dispatches.
    pub gather_ms: f64,
    /// VAL-receiver interactions per second: VALs x sparse points / time.
    pub interactions_per_s: f64,
    /// `interactions_per_s / fma_per_s`: interactions per FMA slot the adapter offers.
    pub ratio_to_fma: f64,
}

const NOTE: &str = "ratio_to_fma = gather VAL-receiver interactions/s / scalar FMA/s of an FMA-bound kernel, \
     both timed in this run: 1 / ratio_to_fma is how many FMA issue slots of the adapter one interaction takes. \
     An interaction (disc form factor, normalisations, a square root, divisions, the sums; the Phong lobe when \
     glossy) is a few tens of operations (not counted exactly), so 1 / ratio far above that means the gather \
     runs far from the arithmetic limit";

/// Measure the FMA kernel and the gather of `scene` (its own settings; `quick`: a smaller run).
pub fn measure(gpu: &Gpu, scene: &Scene, quick: bool) -> Result<FmaReport, BenchError> {
    let repeats = if quick { 1 } else { 3 };
    let (invocations, iterations) = if quick { (4096u32, 64u32) } else { (65_536, 1024) };
    let fma_ms = fma_kernel(gpu, invocations, iterations, repeats)?;
    let fma_count = invocations as u64 * iterations as u64 * CHAINS * 4;
    let fma_per_s = fma_count as f64 / (fma_ms * 1e-3);

    let mut renderer = Renderer::new(gpu, scene)?;
    let frame = compare::sparse_frame(gpu, &mut renderer, 16, 16)?;
    let glossy = renderer.glossy();
    let n = renderer.scene.flat.sparse_points.len();
    let max_size = gpu.device.limits().max_compute_invocations_per_workgroup;
    // (tile size, points per invocation, invocations per point): the tile sizes with one point
    // each, then the points per invocation at the default tile, then the invocations per point
    // (GPUs' default, `gather::GPU_LANES`, and around it); each for the diffuse and (when the
    // scene has glossy materials) the glossy gather, side by side in one run.
    let shapes: &[(u32, u32, u32)] = if quick {
        &[(64, 1, 1), (64, 4, 1), (64, 1, 8)]
    } else {
        &[
            (32, 1, 1),
            (64, 1, 1),
            (128, 1, 1),
            (256, 1, 1),
            (64, 2, 1),
            (64, 4, 1),
            (64, 8, 1),
            (32, 4, 1),
            (64, 1, 4),
            (64, 1, 8),
            (64, 1, 16),
            (128, 1, 32),
        ]
    };
    let mut gather_variants = Vec::new();
    let lobes: &[GatherLobes] = if glossy {
        &[GatherLobes::Diffuse, GatherLobes::GlossyLights, GatherLobes::GlossyRadiance]
    } else {
        &[GatherLobes::Diffuse]
    };
    for (&lobe, &(tile_size, receivers, lanes)) in lobes.iter().flat_map(|l| shapes.iter().map(move |s| (l, s))) {
        if tile_size > max_size {
            continue;
        }
        let gathered = Lobes::new::<RawGathered>(gpu, "bench.gathered", n, lobe.glossy())?;
        let mut pass = Gather::variant(gpu, &renderer.scene, lobe, tile_size, (receivers, lanes))?;
        pass.fit(gpu, &renderer.scene, renderer.val_capacity())?;
        let mut best = f64::INFINITY;
        // One warm-up dispatch, then the timed ones.
        for i in 0..=repeats {
            let mut rec = Recorder::new(gpu, "bench.gather", 1);
            rec.stage("gather", |e, s| {
                pass.record(
                    gpu,
                    e,
                    &GatherInput { scene: &renderer.scene, vals: &renderer.vals, gathered: &gathered, groups: None },
                    s,
                )
            })?;
            let ms = rec.finish()?.stages[0].1;
            if i > 0 {
                best = best.min(ms);
            }
        }
        let interactions_per_s = frame.val_count as f64 * n as f64 / (best * 1e-3);
        gather_variants.push(GatherVariant {
            lobes: lobe,
            tile_size,
            receivers,
            lanes,
            gather_ms: best,
            interactions_per_s,
            ratio_to_fma: interactions_per_s / fma_per_s,
        });
    }
    Ok(FmaReport {
        timing: frame.timings.source,
        fma_count,
        fma_ms,
        fma_per_s,
        vals: frame.val_count,
        sparse_points: n,
        glossy,
        gather_variants,
        note: NOTE,
    })
}

/// Best time (ms) of `repeats` dispatches of the FMA kernel, after a warm-up dispatch.
fn fma_kernel(gpu: &Gpu, invocations: u32, iterations: u32, repeats: u32) -> Result<f64, GpuError> {
    let source = Wgsl::new()
        .u32("FMA_WORKGROUP_SIZE", WORKGROUP_SIZE)
        .u32("FMA_CHAINS", CHAINS as u32)
        .u32("FMA_ITERATIONS", iterations)
        .include(WGSL)
        .finish();
    let module = module_from_source(gpu, "fma", source)?;
    let sink = gpu.storage_buffer_sized::<[f32; 4]>("fma.sink", invocations as usize)?;
    let (pipeline, group) = gpu.build_checked("fma", || {
        let pipeline = gpu.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("fma.pipeline"),
            layout: None,
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
        let group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("fma.bind_group"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: sink.as_entire_binding() }],
        });
        (pipeline, group)
    })?;
    let mut best = f64::INFINITY;
    for i in 0..=repeats {
        let mut rec = Recorder::new(gpu, "bench.fma", 1);
        rec.stage("fma", |e, span| {
            let mut pass = e.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("fma"),
                timestamp_writes: span.as_ref().map(|s| s.compute()),
            });
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups(invocations.div_ceil(WORKGROUP_SIZE), 1, 1);
        })?;
        let ms = rec.finish()?.stages[0].1;
        if i > 0 {
            best = best.min(ms);
        }
    }
    Ok(best)
}

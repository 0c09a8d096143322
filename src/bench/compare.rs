//! What `relume compare` and `relume bench` both measure: a timed sparse frame, the references,
//! and the indirect image's error against a reference. One code path, so the sweep's figures
//! are the figures `compare` prints; [`CompareReport`] is what `compare` prints.

use super::BenchError;
use crate::gpu::timing::TimingSource;
use crate::gpu::{Gpu, GpuError};
use crate::image::{LinearImage, flip_mean, relative_rmse};
use crate::renderer::{Method, Rendered, Renderer, stage};
use crate::scene::{Occlusion, OcclusionRule, Scene};
use std::path::Path;
use std::time::Instant;

/// Error of an indirect image against a reference image.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct IndirectError {
    /// `sqrt(sum |test - reference|² / sum |reference|²)` over RGB of covered pixels.
    pub rel_rmse: f64,
    /// Mean FLIP error of the tone-mapped images, both at `exposure`, over covered pixels.
    pub flip_mean: f64,
    /// The reference image's automatic exposure, at which both were tone-mapped for FLIP.
    pub exposure: f32,
}

/// Error of `test` against `reference` (both indirect light), tone-mapped for FLIP at the
/// reference's automatic exposure.
pub fn indirect_error(test: &LinearImage, reference: &LinearImage) -> IndirectError {
    let exposure = reference.auto_exposure();
    IndirectError {
        rel_rmse: relative_rmse(test, reference),
        flip_mean: flip_mean(test, reference, exposure),
        exposure,
    }
}

/// A sparse frame timed after a warm-up frame that settles first-use allocations and
/// pipeline creation.
pub fn sparse_frame(gpu: &Gpu, renderer: &mut Renderer, width: u32, height: u32) -> Result<Rendered, GpuError> {
    renderer.render(gpu, Method::Sparse, width, height)?;
    renderer.render(gpu, Method::Sparse, width, height)
}

/// The brute-force reference, one frame: it is too slow to repeat and its single frame is
/// dominated by its own arithmetic.
pub fn brute_force_frame(gpu: &Gpu, renderer: &mut Renderer, width: u32, height: u32) -> Result<Rendered, GpuError> {
    renderer.render(gpu, Method::BruteForce, width, height)
}

/// The exact-visibility reference over every `val_stride`-th VAL, one frame.
pub fn exact_frame(
    gpu: &Gpu,
    renderer: &mut Renderer,
    width: u32,
    height: u32,
    val_stride: u32,
) -> Result<Rendered, GpuError> {
    renderer.set_exact_val_stride(val_stride);
    renderer.render(gpu, Method::Exact, width, height)
}

/// `relume compare`'s report: sparse against the brute force (both without visibility), and
/// with `--reference exact` every occlusion mode against exact visibility.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CompareReport {
    /// The meshes' names, joined by `+`.
    pub scene: String,
    pub adapter: String,
    pub timing: TimingSource,
    pub width: u32,
    pub height: u32,
    pub pixels: u64,
    pub covered_pixels: usize,
    pub vals: u32,
    pub rsm_resolution: u32,
    pub sparse_points: usize,
    pub triangles: usize,
    pub vertices: usize,
    pub glossy: bool,
    pub occlusion_setting: Occlusion,
    pub occlusion_rule_setting: OcclusionRule,
    /// The sparse frame's indirect stages (ms).
    pub sparse_ms: f64,
    /// The brute force's indirect stage (ms).
    pub brute_force_ms: f64,
    pub speedup: f64,
    pub indirect_rel_rmse: f64,
    pub indirect_flip_mean: f64,
    /// The brute force's automatic exposure, at which FLIP tone-maps both.
    pub exposure: f32,
    /// Scene upload and pipeline creation (ms).
    pub setup_ms: f64,
    pub sparse_stages_ms: Vec<(String, f64)>,
    pub brute_force_stages_ms: Vec<(String, f64)>,
    #[serde(flatten)]
    pub exact: Option<ExactComparison>,
}

/// Sparse with occlusion off, "sum" and "product" against the exact-visibility reference.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ExactComparison {
    pub exact_ms: f64,
    pub exact_val_stride: u32,
    pub exact_vals_used: u32,
    pub exact_rounds: u32,
    pub indirect_rel_rmse_vs_exact_off: f64,
    pub indirect_flip_mean_vs_exact_off: f64,
    pub indirect_rel_rmse_vs_exact_sum: f64,
    pub indirect_flip_mean_vs_exact_sum: f64,
    pub indirect_rel_rmse_vs_exact_product: f64,
    pub indirect_flip_mean_vs_exact_product: f64,
    /// The disks' stage with the "sum" rule (ms).
    pub occlusion_ms: f64,
    /// The gather in the same frame (ms).
    pub gather_ms: f64,
}

/// Measure `scene` at `width` x `height` as `relume compare` does; with `exact_val_stride`,
/// also against exact visibility over every n-th VAL. `images`: a directory for the indirect
/// images and their difference.
pub fn compare(
    gpu: &Gpu,
    scene: &Scene,
    (w, h): (u32, u32),
    exact_val_stride: Option<u32>,
    images: Option<&Path>,
) -> Result<CompareReport, BenchError> {
    let start = Instant::now();
    let mut renderer = Renderer::new(gpu, scene)?;
    let setup_ms = start.elapsed().as_secs_f64() * 1e3;
    // The brute force has no visibility, so it is compared with sparse without occlusion;
    // `exact_val_stride` measures occlusion.
    renderer.set_occlusion(Occlusion::Off, scene.settings.occlusion_rule);
    let sparse = sparse_frame(gpu, &mut renderer, w, h)?;
    let brute = brute_force_frame(gpu, &mut renderer, w, h)?;
    let error = indirect_error(&sparse.indirect, &brute.indirect);
    if let Some(dir) = images {
        write_comparison(dir, &sparse.indirect, &brute.indirect, error.exposure)?;
    }
    let (sparse_ms, brute_force_ms) = (sparse.indirect_ms(), brute.indirect_ms());
    let exact = match exact_val_stride {
        Some(stride) => Some(exact_comparison(gpu, &mut renderer, (w, h), stride, images)?),
        None => None,
    };
    Ok(CompareReport {
        scene: scene.meshes.iter().map(|m| m.name.as_str()).collect::<Vec<_>>().join("+"),
        adapter: gpu.adapter_name(),
        timing: sparse.timings.source,
        width: w,
        height: h,
        pixels: w as u64 * h as u64,
        covered_pixels: brute.indirect.coverage(),
        vals: sparse.val_count,
        rsm_resolution: scene.settings.rsm_resolution,
        sparse_points: scene.sparse_point_count(),
        triangles: scene.triangle_count(),
        vertices: scene.vertex_count(),
        glossy: renderer.glossy(),
        occlusion_setting: scene.settings.occlusion,
        occlusion_rule_setting: scene.settings.occlusion_rule,
        sparse_ms,
        brute_force_ms,
        speedup: brute_force_ms / sparse_ms,
        indirect_rel_rmse: error.rel_rmse,
        indirect_flip_mean: error.flip_mean,
        exposure: error.exposure,
        setup_ms,
        sparse_stages_ms: sparse.timings.stages,
        brute_force_stages_ms: brute.timings.stages,
        exact,
    })
}

/// Sparse with occlusion off, "sum" and "product" against the exact-visibility reference.
fn exact_comparison(
    gpu: &Gpu,
    renderer: &mut Renderer,
    (w, h): (u32, u32),
    val_stride: u32,
    images: Option<&Path>,
) -> Result<ExactComparison, BenchError> {
    let exact = exact_frame(gpu, renderer, w, h, val_stride)?;
    let exposure = exact.indirect.auto_exposure();
    if let Some(dir) = images {
        write_png(&exact.indirect, &dir.join("indirect_exact.png"), exposure)?;
    }
    let mut errors = Vec::new();
    let (mut occlusion_ms, mut gather_ms) = (0.0, 0.0);
    for (key, occlusion, rule) in [
        ("off", Occlusion::Off, OcclusionRule::Sum),
        ("sum", Occlusion::Disks, OcclusionRule::Sum),
        ("product", Occlusion::Disks, OcclusionRule::Product),
    ] {
        renderer.set_occlusion(occlusion, rule);
        let sparse = renderer.render(gpu, Method::Sparse, w, h)?;
        if let Some(dir) = images {
            write_png(&sparse.indirect, &dir.join(format!("indirect_sparse_occlusion_{key}.png")), exposure)?;
        }
        errors.push(indirect_error(&sparse.indirect, &exact.indirect));
        if key == "sum" {
            occlusion_ms = sparse.timings.total_of(&[stage::OCCLUSION]);
            gather_ms = sparse.timings.total_of(&[stage::GATHER]);
        }
    }
    let [off, sum, product] = errors[..] else { unreachable!("three modes measured") };
    Ok(ExactComparison {
        exact_ms: exact.indirect_ms(),
        exact_val_stride: val_stride,
        exact_vals_used: exact.val_count / val_stride,
        exact_rounds: exact.exact_rounds,
        indirect_rel_rmse_vs_exact_off: off.rel_rmse,
        indirect_flip_mean_vs_exact_off: off.flip_mean,
        indirect_rel_rmse_vs_exact_sum: sum.rel_rmse,
        indirect_flip_mean_vs_exact_sum: sum.flip_mean,
        indirect_rel_rmse_vs_exact_product: product.rel_rmse,
        indirect_flip_mean_vs_exact_product: product.flip_mean,
        occlusion_ms,
        gather_ms,
    })
}

fn write_png(image: &LinearImage, path: &Path, exposure: f32) -> Result<(), BenchError> {
    image.write_png(path, exposure).map_err(|e| BenchError::Write { path: path.to_owned(), message: e.to_string() })
}

/// The sparse and brute-force indirect images and their difference (at 4x the exposure).
fn write_comparison(dir: &Path, sparse: &LinearImage, brute: &LinearImage, exposure: f32) -> Result<(), BenchError> {
    std::fs::create_dir_all(dir)
        .map_err(|e| BenchError::Write { path: dir.to_owned(), message: format!("creating the directory: {e}") })?;
    write_png(sparse, &dir.join("indirect_sparse.png"), exposure)?;
    write_png(brute, &dir.join("indirect_brute_force.png"), exposure)?;
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
    write_png(&diff, &dir.join("indirect_difference.png"), exposure * 4.0)
}

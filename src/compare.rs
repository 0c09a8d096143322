//! What `relume compare` and `relume bench` both measure: a timed sparse frame, the references,
//! and the indirect image's error against a reference. One code path, so the sweep's figures
//! are the figures `compare` prints.

use crate::gpu::{Gpu, GpuError};
use crate::image::{LinearImage, flip_mean, relative_rmse};
use crate::renderer::{Method, Rendered, Renderer};

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

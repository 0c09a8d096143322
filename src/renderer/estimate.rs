//! The error estimate reported with every frame: how far the frame's indirect light is from the
//! exact reference (every VAL, shadow rays through the scene's BVH), estimated at about a
//! thousand of its pixels instead of all of them. The VALs are the frame's own: with two
//! bounces, the second bounce's VALs as the frame drew them, so the estimate leaves out the
//! error of the second bounce's own points (the exact reference of `relume compare` lights
//! them through shadow rays).
//!
//! At `pixels` covered pixels chosen by stratified sampling over the frame's covered pixels
//! (one uniform pick in each of `pixels` equal runs of them, in row-major order), the CPU
//! reference (`twin::exact_cpu`) estimates the exact indirect radiance with `samples`
//! importance-sampled VALs per receiver, unbiased, with its own variance. The estimate is the
//! frame's relative RMSE at those pixels with the reference's noise taken out,
//! `sqrt(max(0, sum |t - r|² - sum s²) / sum |r|²)` (as `image::noise_corrected_relative_rmse`
//! computes it over a whole image): a ratio estimator of the whole image's relative RMSE against
//! the exact reference, whose error shrinks as 1/sqrt(pixels) where the frame's error is spread
//! evenly, and is larger where a few pixels hold most of it (a heavy tail that a sample of
//! pixels can miss). Its spread is reported too: the standard deviation of the estimates of
//! four interleaved quarters of the pixels, halved (the standard error of their mean).
//!
//! The cost is `pixels` x `samples` shadow rays plus, per receiver, one pass over the VALs to
//! build the sampling distribution, and reading the frame's visibility buffer and VALs back:
//! about 131k shadow rays at the defaults (1,024 pixels, 128 VALs each), against the tens of
//! millions of the exact reference at 256². The
//! scene's BVH is built once and kept while the meshes stay where they are.
//!
//! Every frame of `relume render`, `relume replay`, the service's renders and streams runs the
//! cheaper [`PER_FRAME`] variant (`Renderer::set_error_estimate`): 64 pixels x 32 VALs, 2,048
//! shadow rays, a sixteenth of the rays of the default. Its trade: its own sampling error,
//! which shrinks as 1/sqrt(pixels), is about four times the default's where the frame's error
//! is spread evenly; successive frames look at other pixels, so their estimates average out
//! over a stream (the spread each frame reports says how far one frame's is to be trusted);
//! `relume compare`
//! and `relume bench --levels` keep the default. Its cost beside the frame's is measured by
//! `relume replay` (`summary.json`: `error_estimate_ms` beside `frame_ms`;
//! docs/measurements/budget.md).

use crate::gpu::{Gpu, GpuError};
use crate::image::{LinearImage, noise_corrected_relative_rmse, relative_stderr};
use crate::renderer::{Rendered, Renderer};
use crate::twin::bvh::TraceBvh;
use crate::twin::exact_cpu::{self as cpu, Receiver, Receivers, ValSampling};
use glam::{Mat4, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use std::time::Instant;

/// Pixels the estimate looks at by default.
pub const DEFAULT_PIXELS: u32 = 1024;
/// VALs each of them draws by default.
pub const DEFAULT_SAMPLES: u32 = 128;
/// The per-frame estimate: few enough pixels and VALs to run after every frame.
pub const PER_FRAME: EstimateOptions = EstimateOptions { pixels: 64, samples: 32, seed: 1 };
/// The stage the per-frame estimate's time is reported as.
pub const STAGE: &str = "error_estimate";
/// Bounds of [`EstimateOptions::pixels`]: at least one per interleaved quarter, at most what a
/// frame's estimate should cost.
pub const PIXELS_RANGE: (u32, u32) = (4, 1 << 16);
/// Bounds of [`EstimateOptions::samples`] (the CPU reference draws at least 2 to have a variance).
pub const SAMPLES_RANGE: (u32, u32) = (2, 1 << 12);

/// How much work an estimate does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EstimateOptions {
    /// Covered pixels looked at, in [`PIXELS_RANGE`].
    pub pixels: u32,
    /// VALs drawn per pixel, in [`SAMPLES_RANGE`].
    pub samples: u32,
    /// Seed of the pixels' and the VALs' random choices; a stream passes its frame index so that
    /// successive frames look at different pixels.
    pub seed: u64,
}

impl Default for EstimateOptions {
    fn default() -> Self {
        EstimateOptions { pixels: DEFAULT_PIXELS, samples: DEFAULT_SAMPLES, seed: 1 }
    }
}

/// A frame's estimated error against the exact reference.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, utoipa::ToSchema)]
pub struct ErrorEstimate {
    /// Estimated relative RMSE of the frame's indirect light against the exact reference.
    pub rel_rmse: f64,
    /// Standard error of `rel_rmse` from the choice of pixels (four interleaved quarters).
    pub spread: f64,
    /// The sampled reference's own relative noise at those pixels (already taken out of
    /// `rel_rmse`).
    pub reference_noise: f64,
    /// Pixels looked at (fewer than asked when the frame covers fewer).
    pub pixels: u32,
    /// VALs drawn per pixel.
    pub samples: u32,
    /// Wall-clock time of the estimate, ms (readbacks, BVH when rebuilt, shadow rays).
    pub ms: f64,
}

impl ErrorEstimate {
    /// The estimate in words, as `render` prints it. A noise-corrected error of exactly 0 means
    /// the frame's difference from the sampled reference was within that reference's own
    /// noise: it is said so, not printed as an error of 0.
    pub fn summary(&self) -> String {
        let error = match self.rel_rmse == 0.0 && self.reference_noise > 0.0 {
            true => format!("below the estimate's own noise ({:.4})", self.reference_noise),
            false => format!("{:.4} +- {:.4}", self.rel_rmse, self.spread),
        };
        format!(
            "indirect rel RMSE {error} against the exact reference ({} pixels x {} VALs, {:.1} ms)",
            self.pixels, self.samples, self.ms
        )
    }
}

/// Keeps the scene's BVH between frames.
#[derive(Default)]
pub struct Estimator {
    bvh: Option<(Vec<Mat4>, TraceBvh)>,
}

impl Estimator {
    pub fn new() -> Self {
        Self::default()
    }

    /// The estimate for `frame`, the renderer's last frame (its indirect light, visibility
    /// buffer and VALs); `None` when the frame has no indirect light or covers no pixel.
    pub fn estimate(
        &mut self,
        gpu: &Gpu,
        renderer: &Renderer,
        frame: &Rendered,
        options: &EstimateOptions,
    ) -> Result<Option<ErrorEstimate>, GpuError> {
        let start = Instant::now();
        let Some(view) = renderer.camera_view() else { return Ok(None) };
        let image = &frame.indirect;
        let hits = view.read(gpu)?;
        if hits.len() != image.pixels.len() {
            return Ok(None);
        }
        let covered: Vec<usize> = (0..hits.len()).filter(|&i| hits[i].is_some() && image.covered(i)).collect();
        let picked = stratified(&covered, options.pixels as usize, options.seed);
        if picked.len() < 4 {
            return Ok(None);
        }
        // The frame's own VALs: with two bounces they include the second bounce's, drawn from
        // the bounce points the frame lit, so its estimate measures what the frame made of them.
        let vals = renderer.read_vals(gpu)?;
        let flat = &renderer.scene.flat;
        let placement = renderer.placement().to_vec();
        if self.bvh.as_ref().is_none_or(|(p, _)| *p != placement) {
            self.bvh = Some((placement, flat.trace_bvh()));
        }
        let bvh = &self.bvh.as_ref().expect("built above").1;
        let eye = renderer.view().eye();
        let receivers: Vec<Option<Receiver>> =
            picked.iter().map(|&i| hits[i].map(|h| flat.receiver_at(h.triangle, h.barycentrics, eye))).collect();
        let scene = cpu::ExactScene { bvh, vals: &vals, glossy: renderer.glossy() };
        let sampling = ValSampling::Importance { samples: options.samples, seed: options.seed };
        let n = picked.len() as u32;
        let reference = cpu::render(&scene, &Receivers::Hits(&receivers), n, 1, sampling);
        let variance = reference.variance.unwrap_or_else(|| vec![Vec3::ZERO; picked.len()]);
        let test = LinearImage { width: n, height: 1, pixels: picked.iter().map(|&i| image.pixels[i]).collect() };
        let rel_rmse = noise_corrected_relative_rmse(&test, &reference.image, &variance);
        let quarters: Vec<f64> = (0..4)
            .map(|q| {
                let keep: Vec<usize> = (q..picked.len()).step_by(4).collect();
                let part = |img: &LinearImage| LinearImage {
                    width: keep.len() as u32,
                    height: 1,
                    pixels: keep.iter().map(|&k| img.pixels[k]).collect(),
                };
                let v: Vec<Vec3> = keep.iter().map(|&k| variance[k]).collect();
                noise_corrected_relative_rmse(&part(&test), &part(&reference.image), &v)
            })
            .collect();
        let mean = quarters.iter().sum::<f64>() / 4.0;
        let spread = (quarters.iter().map(|q| (q - mean).powi(2)).sum::<f64>() / 3.0).sqrt() / 2.0;
        Ok(Some(ErrorEstimate {
            rel_rmse,
            spread,
            reference_noise: relative_stderr(&reference.image, &variance),
            pixels: n,
            samples: options.samples,
            ms: start.elapsed().as_secs_f64() * 1e3,
        }))
    }
}

/// One uniform pick in each of `count` equal runs of `items` (all of them when there are fewer).
fn stratified(items: &[usize], count: usize, seed: u64) -> Vec<usize> {
    if items.len() <= count {
        return items.to_vec();
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..count)
        .map(|k| {
            let lo = k * items.len() / count;
            let hi = ((k + 1) * items.len() / count).max(lo + 1);
            items[rng.random_range(lo..hi)]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An error the sampled reference's noise swallows reads as such, not as 0.
    #[test]
    fn an_error_within_the_reference_noise_is_not_printed_as_zero() {
        let e = ErrorEstimate {
            rel_rmse: 0.0,
            spread: 0.0346,
            reference_noise: 0.1408,
            pixels: 64,
            samples: 32,
            ms: 280.0,
        };
        let text = e.summary();
        assert!(text.starts_with("indirect rel RMSE below the estimate's own noise (0.1408)"), "{text}");
        let measured = ErrorEstimate { rel_rmse: 0.0512, ..e };
        assert!(measured.summary().starts_with("indirect rel RMSE 0.0512 +- 0.0346"), "{}", measured.summary());
    }

    #[test]
    fn stratified_picks_one_from_each_run_and_all_when_few() {
        let items: Vec<usize> = (100..200).collect();
        let picked = stratified(&items, 10, 3);
        assert_eq!(picked.len(), 10);
        for (k, p) in picked.iter().enumerate() {
            assert!((100 + 10 * k..100 + 10 * (k + 1)).contains(p), "pick {k} = {p}");
        }
        assert_ne!(stratified(&items, 10, 3), stratified(&items, 10, 4), "the seed moves the picks");
        assert_eq!(stratified(&items[..5], 10, 3), items[..5].to_vec());
    }
}

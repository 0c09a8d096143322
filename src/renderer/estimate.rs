//! The error estimate reported with every frame: how far the frame's indirect light is from the
//! exact reference (every VAL, shadow rays through the scene's BVH), estimated at about a
//! thousand of its pixels instead of all of them. The VALs are the frame's own: with two
//! bounces, the second bounce's VALs as the frame drew them, so the estimate leaves out the
//! error of the second bounce's own points (the exact reference of `relume compare` lights
//! them through shadow rays).
//!
//! At `pixels` of the frame's covered pixels, the CPU reference (`twin::exact_cpu`) estimates
//! the exact indirect radiance with `samples` importance-sampled VALs per receiver, unbiased,
//! with its own variance. The pixels are drawn with probability proportional to
//! `q = 1/2 + 1/2 L² / mean(L²)`, `L` the frame's own indirect luminance there: half the draws
//! uniform over the covered pixels, half by the square of the frame's brightness, systematically
//! (one independent pick in each of `pixels` equal runs of the running sum of `q`, in row-major
//! order). The estimate is the frame's relative RMSE at those pixels with the reference's noise
//! taken out, `sqrt(max(0, sum w |t - r|² - sum w s²) / sum w |r|²)` with `w = 1 / q` (as
//! `image::weighted_noise_corrected_relative_rmse` computes it): a ratio estimator of the whole
//! image's relative RMSE against the exact reference. An image's squared error and squared
//! radiance both sit mostly in its bright pixels, and where a few pixels hold most of the error
//! (a heavy tail, the highlights of a glossy object) uniform picks miss them and the estimate
//! comes out low; drawing by brightness finds them, and the uniform half keeps every pixel a
//! chance (light the frame lacks where it is dark). On the exact and sparse images of
//! `cornell_glossy_open` at 256x256 (balanced: 0.0739, 82 % of its squared error in 1 % of the
//! pixels), 300 draws of 1,024 pixels without the reference's noise put the estimate at
//! 0.65-1.23 of the error (10th to 90th percentile, median 0.84) uniformly and at 0.81-1.16
//! (median 0.98) by brightness; on `sponza_bunny` (near field 8, no visibility: 0.312) at
//! 0.79-1.23 and 0.96-1.05; with the per-frame 64 pixels the medians go from 0.60 to 0.75 and
//! from 0.74 to 0.98 (`tools/estimate_draws.py` on `relume compare --reference exact --images`).
//! Its spread is reported too: the standard deviation of the estimates of four interleaved
//! quarters of the pixels, halved (the standard error of their mean).
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
use crate::image::{LinearImage, luminance, weighted_noise_corrected_relative_rmse, weighted_relative_stderr};
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
        let brightness: Vec<f64> = covered.iter().map(|&i| f64::from(luminance(image.rgb(i))).powi(2)).collect();
        let (picked, weights) = by_brightness(&covered, &brightness, options.pixels as usize, options.seed);
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
        let rel_rmse = weighted_noise_corrected_relative_rmse(&test, &reference.image, &variance, |k| weights[k]);
        let quarters: Vec<f64> = (0..4)
            .map(|q| {
                let keep: Vec<usize> = (q..picked.len()).step_by(4).collect();
                let part = |img: &LinearImage| LinearImage {
                    width: keep.len() as u32,
                    height: 1,
                    pixels: keep.iter().map(|&k| img.pixels[k]).collect(),
                };
                let v: Vec<Vec3> = keep.iter().map(|&k| variance[k]).collect();
                weighted_noise_corrected_relative_rmse(&part(&test), &part(&reference.image), &v, |j| weights[keep[j]])
            })
            .collect();
        let mean = quarters.iter().sum::<f64>() / 4.0;
        let spread = (quarters.iter().map(|q| (q - mean).powi(2)).sum::<f64>() / 3.0).sqrt() / 2.0;
        Ok(Some(ErrorEstimate {
            rel_rmse,
            spread,
            reference_noise: weighted_relative_stderr(&reference.image, &variance, |k| weights[k]),
            pixels: n,
            samples: options.samples,
            ms: start.elapsed().as_secs_f64() * 1e3,
        }))
    }
}

/// `count` picks of `items` (all of them, each of weight 1, when there are fewer) with
/// probability proportional to `q = 1/2 + 1/2 brightness / mean(brightness)`: one independent
/// uniform pick in each of `count` equal runs of the running sum of `q`. Each pick's weight is
/// `1 / q` (an item may be picked more than once, each pick counting).
fn by_brightness(items: &[usize], brightness: &[f64], count: usize, seed: u64) -> (Vec<usize>, Vec<f64>) {
    if items.len() <= count {
        return (items.to_vec(), vec![1.0; items.len()]);
    }
    let mean = brightness.iter().sum::<f64>() / brightness.len() as f64;
    let q: Vec<f64> =
        brightness.iter().map(|b| if mean > 0.0 && b.is_finite() { 0.5 + 0.5 * b / mean } else { 1.0 }).collect();
    let mut running = Vec::with_capacity(q.len());
    let mut sum = 0.0;
    for x in &q {
        sum += x;
        running.push(sum);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..count)
        .map(|k| {
            let goal = (k as f64 + rng.random::<f64>()) / count as f64 * sum;
            let j = running.partition_point(|&c| c <= goal).min(items.len() - 1);
            (items[j], 1.0 / q[j])
        })
        .unzip()
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

    /// Equal brightness: one pick in each equal run of the items, weight 1; all of them when few.
    #[test]
    fn picks_are_stratified_and_all_when_few() {
        let items: Vec<usize> = (100..200).collect();
        let (picked, weights) = by_brightness(&items, &[1.0; 100], 10, 3);
        assert_eq!(picked.len(), 10);
        for (k, p) in picked.iter().enumerate() {
            assert!((100 + 10 * k..100 + 10 * (k + 1)).contains(p), "pick {k} = {p}");
        }
        assert!(weights.iter().all(|&w| w == 1.0), "{weights:?}");
        assert_ne!(by_brightness(&items, &[1.0; 100], 10, 4).0, picked, "the seed moves the picks");
        assert_eq!(by_brightness(&items[..5], &[0.0; 5], 10, 3), (items[..5].to_vec(), vec![1.0; 5]));
    }

    /// Bright items are drawn as often as `q` says and weigh `1 / q`: the weighted mean of any
    /// quantity over the picks estimates its plain mean over the items without bias, here to 1 %
    /// over 200 seeds, where most of the items' sum sits in one bright item in a hundred.
    #[test]
    fn picks_by_brightness_are_unbiased_and_find_bright_items() {
        let items: Vec<usize> = (0..1000).collect();
        let brightness: Vec<f64> = items.iter().map(|&i| if i % 100 == 7 { 400.0 } else { 1.0 }).collect();
        let value = |i: usize| brightness[i];
        let truth = items.iter().map(|&i| value(i)).sum::<f64>() / items.len() as f64;
        let (mut estimates, mut bright) = (Vec::new(), 0usize);
        for seed in 0..200 {
            let (picked, weights) = by_brightness(&items, &brightness, 50, seed);
            let total: f64 = weights.iter().sum();
            estimates.push(picked.iter().zip(&weights).map(|(&i, w)| w * value(i)).sum::<f64>() / total);
            bright += picked.iter().filter(|&&i| i % 100 == 7).count();
        }
        let mean = estimates.iter().sum::<f64>() / estimates.len() as f64;
        assert!((mean / truth - 1.0).abs() < 0.01, "mean estimate {mean} against {truth}");
        // q is 0.5 + 0.5 x 400 / 4.99 = 40.6 for a bright item, 0.6 for the rest: about 40 % of
        // the picks, where a uniform draw would make 1 %.
        let share = bright as f64 / (200.0 * 50.0);
        assert!(share > 0.3 && share < 0.5, "bright share of the picks {share}");
    }
}

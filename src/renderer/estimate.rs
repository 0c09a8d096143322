//! The error estimate reported with every frame: how far the frame's indirect light is from the
//! exact reference (every VAL, shadow rays through the scene's BVH), estimated at about a
//! thousand of its pixels instead of all of them.
//!
//! **The VALs.** The exact reference `relume bench --levels` measures every level against is
//! the scene at its `reference` level, whose spot light's RSM is often finer than a level's
//! (`fast`, or a measured level with a coarser RSM). Where the frame's VALs are the spot
//! light's alone, drawn at another RSM side, the estimate traces the spot light's VALs at the
//! reference's side through the BVH ([`crate::twin::rsm::traced_vals`], once per light and
//! placement) and sums over those: otherwise the VALs' coarseness, which on `cornell_bunny`
//! with a 64² RSM against the reference's 128² is most of the brute force through the clusters'
//! maps' error (0.0319, with the estimate over the frame's own VALs at 0.0180), would be
//! invisible to it. `relume compare`, whose exact reference is the scene at its own level,
//! asks for the frame's own VALs ([`EstimateOptions::own_vals`]). Elsewhere the VALs are the
//! frame's own: with uploaded, RGB-D or `lights`
//! VALs (which no level changes), and with two bounces, the second bounce's VALs as the frame
//! drew them, so the estimate leaves out the error of the second bounce's own points (the exact
//! reference of `relume compare` lights them through shadow rays).
//!
//! **The pixels.** At `pixels` of the frame's covered pixels, the CPU reference
//! (`twin::exact_cpu`) estimates the exact indirect radiance with `samples` importance-sampled
//! VALs per receiver, unbiased, with its own variance. The pixels are drawn with probability
//! proportional to `q = (1 + L² / mean(L²) + C / mean(C)) / 3`, `L` the frame's own indirect
//! luminance there and `C` its local contrast (the larger central difference of `L`): a third
//! of the draws uniform over the covered pixels, a third by the square of the frame's
//! brightness, a third by its contrast, systematically (one independent pick in each of
//! `pixels` equal runs of the running sum of `q`, in row-major order). The estimate is the
//! frame's relative RMSE at those pixels with the reference's noise taken out,
//! `sqrt(max(0, sum w |t - r|² - sum w s²) / sum w |r|²)` with `w = 1 / q` (as
//! `image::weighted_noise_corrected_relative_rmse` computes it): a ratio estimator of the whole
//! image's relative RMSE against the exact reference. An image's squared error and squared
//! radiance both sit mostly in its bright pixels, and where a few pixels hold most of the error
//! uniform picks miss them and the estimate comes out low; drawing by brightness finds the
//! highlights of a glossy object, drawing by contrast the corners and contact lines where VALs
//! lie close to the receivers (where a coarse RSM's VALs are most wrong), and the uniform third
//! keeps every pixel a chance (light the frame lacks where it is dark). Over 300 draws of 1,024
//! pixels without the reference's noise (`tools/estimate_draws.py` on `relume compare
//! --reference exact --images`, and on `relume render --hdr` of `cornell_bunny` at `accurate`
//! and at `reference`), the share of estimates outside 1.5x of the error, uniform / by
//! brightness / by brightness and contrast: `cornell_bunny`'s brute force through the clusters'
//! maps on a 64² RSM against the 128² reference (0.0318, 80 % of its squared error in 1 % of
//! the pixels) 40 / 39 / 6 %; `cornell_glossy_open`'s brute force through the clusters' maps
//! (0.0134) 10 / 14 / 2 %; its sparse frame (0.0897) 9 / 0 / 0 %; the ears' brute force through
//! the maps (0.0619) 3 / 0 / 1 %; `sponza_bunny` without visibility (0.382) 0 / 0 / 0 %. With
//! the per-frame 64 pixels: 83 / 81 / 62 %, 66 / 72 / 65 %, 53 / 46 / 21 %, 34 / 25 / 15 %,
//! 26 / 1 / 1 %.
//!
//! Its spread is reported too: the standard deviation of the estimates of four interleaved
//! quarters of the pixels, halved (the standard error of their mean).
//!
//! The cost is `pixels` x `samples` shadow rays plus, per receiver, one pass over the VALs to
//! build the sampling distribution, and reading the frame's visibility buffer and VALs back:
//! about 131k shadow rays at the defaults (1,024 pixels, 128 VALs each), against the tens of
//! millions of the exact reference at 256². The scene's BVH is built once and kept while the
//! meshes stay where they are; the traced VALs (a ray per texel of the reference's RSM, 16,384
//! at 128²) are kept while the light and the meshes do.
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
use crate::renderer::{Method, Rendered, Renderer};
use crate::scene::SpotLight;
use crate::twin::Val;
use crate::twin::bvh::TraceBvh;
use crate::twin::exact_cpu::{self as cpu, Receiver, Receivers, ValSampling};
use crate::twin::flat::Hit;
use crate::twin::rsm;
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
pub const PER_FRAME: EstimateOptions = EstimateOptions { pixels: 64, samples: 32, seed: 1, own_vals: false };
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
    /// Sum over the frame's own VALs even where the `reference` level's differ: what
    /// `relume compare`'s exact reference sums over (the scene at its own level), so that its
    /// estimate and its measured error are of the same thing.
    pub own_vals: bool,
}

impl Default for EstimateOptions {
    fn default() -> Self {
        EstimateOptions { pixels: DEFAULT_PIXELS, samples: DEFAULT_SAMPLES, seed: 1, own_vals: false }
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
    /// VALs the reference sums over.
    pub reference_vals: u32,
    /// The RSM side at which the reference traced the spot light's VALs when the frame drew
    /// them at another (a level coarser than `reference`); `None`: the frame's own VALs.
    pub reference_rsm_resolution: Option<u32>,
    /// Wall-clock time of the estimate, ms (readbacks, BVH and traced VALs when rebuilt, shadow
    /// rays).
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
        let vals = match self.reference_rsm_resolution {
            Some(r) => format!(" of the spot light's {} at the reference's {r}x{r} RSM", self.reference_vals),
            None => format!(" of the frame's {}", self.reference_vals),
        };
        format!(
            "indirect rel RMSE {error} against the exact reference ({} pixels x {} VALs{vals}, {:.1} ms)",
            self.pixels, self.samples, self.ms
        )
    }
}

/// Keeps the scene's BVH, and the spot light's VALs traced at the reference's RSM side,
/// between frames.
#[derive(Default)]
pub struct Estimator {
    bvh: Option<(Vec<Mat4>, TraceBvh)>,
    traced: Option<((SpotLight, u32), Vec<Val>)>,
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
        let lum: Vec<f32> = (0..image.pixels.len()).map(|i| luminance(image.rgb(i))).collect();
        let brightness: Vec<f64> = covered.iter().map(|&i| f64::from(lum[i]).powi(2)).collect();
        let contrast: Vec<f64> = covered.iter().map(|&i| contrast(&lum, image.width as usize, i)).collect();
        let terms: [&[f64]; 2] = [&brightness, &contrast];
        let (picked, weights) = by_importance(&covered, &terms, options.pixels as usize, options.seed);
        if picked.len() < 4 {
            return Ok(None);
        }
        let flat = &renderer.scene.flat;
        let placement = renderer.placement().to_vec();
        if self.bvh.as_ref().is_none_or(|(p, _)| *p != placement) {
            self.bvh = Some((placement, flat.trace_bvh()));
            self.traced = None;
        }
        let bvh = &self.bvh.as_ref().expect("built above").1;
        // The VALs the exact reference sums over: the spot light's at the `reference` level's
        // RSM side where the frame drew them coarser (or finer), traced once per light and
        // placement; else the frame's own (with two bounces they include the second bounce's,
        // drawn from the bounce points the frame lit, so its estimate measures what the frame
        // made of them).
        let own;
        let reference_spot = renderer.reference_spot().filter(|_| !options.own_vals);
        let (vals, reference_rsm_resolution): (&[Val], _) = match reference_spot {
            Some(key) => {
                if self.traced.as_ref().is_none_or(|(k, _)| *k != key) {
                    self.traced = Some((key, rsm::traced_vals(flat, bvh, &key.0, key.1)));
                }
                (&self.traced.as_ref().expect("traced above").1, Some(key.1))
            }
            None => {
                own = renderer.read_vals(gpu)?;
                (&own, None)
            }
        };
        let eye = renderer.view().eye();
        // A frame that drew the simplified triangles is compared with the exact light where
        // the full meshes are at its pixels: the surface the eye's ray through the simplified
        // copy's point meets first (none where the copy's silhouette overhangs the meshes').
        let lod = renderer.camera_lod_drawn();
        let receiver = |h: Hit| match lod {
            None => Some(flat.receiver_at(h.triangle, h.barycentrics, eye)),
            Some(t) => {
                let (p, _, _) = flat.surface_on(&t.indices, &t.materials, h.triangle, h.barycentrics);
                let full = bvh.closest_hit(eye, p - eye)?;
                Some(flat.receiver_at(full.triangle, full.barycentrics, eye))
            }
        };
        let receivers: Vec<Option<Receiver>> = picked.iter().map(|&i| hits[i].and_then(receiver)).collect();
        let scene = cpu::ExactScene { bvh, vals, glossy: renderer.glossy(), blockers_from: 0.0 };
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
            reference_vals: vals.len() as u32,
            reference_rsm_resolution,
            ms: start.elapsed().as_secs_f64() * 1e3,
        }))
    }
}

/// `count` picks of `items` (all of them, each of weight 1, when there are fewer) with
/// probability proportional to `q = (1 + sum_k t_k / mean(t_k)) / (K + 1)` over the `K`
/// importance `terms` (a term of mean 0 counts as 1: uniform): one independent uniform pick in
/// each of `count` equal runs of the running sum of `q`. Each pick's weight is `1 / q` (an item
/// may be picked more than once, each pick counting).
fn by_importance(items: &[usize], terms: &[&[f64]], count: usize, seed: u64) -> (Vec<usize>, Vec<f64>) {
    if items.len() <= count {
        return (items.to_vec(), vec![1.0; items.len()]);
    }
    let means: Vec<f64> = terms.iter().map(|t| t.iter().sum::<f64>() / t.len() as f64).collect();
    let q: Vec<f64> = (0..items.len())
        .map(|i| {
            let share = |(t, &m): (&&[f64], &f64)| if m > 0.0 && t[i].is_finite() { t[i] / m } else { 1.0 };
            (1.0 + terms.iter().zip(&means).map(share).sum::<f64>()) / (terms.len() + 1) as f64
        })
        .collect();
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

/// The local contrast of a `width`-wide image of luminances at pixel `i`: the larger of its
/// horizontal and vertical central differences, `max(|L(x+1) - L(x-1)|, |L(y+1) - L(y-1)|)`,
/// each 0 where its neighbours would fall outside the image.
fn contrast(lum: &[f32], width: usize, i: usize) -> f64 {
    let (x, y, height) = (i % width, i / width, lum.len() / width);
    let dx = if x > 0 && x + 1 < width { (lum[i + 1] - lum[i - 1]).abs() } else { 0.0 };
    let dy = if y > 0 && y + 1 < height { (lum[i + width] - lum[i - width]).abs() } else { 0.0 };
    f64::from(dx.max(dy))
}

/// The renderer's per-frame estimate: asked for, run after a frame, or held back for one.
impl Renderer {
    /// Run the error estimate ([`Estimator`]) after every frame that computes indirect
    /// light, with `options` (its seed is offset by the frame's index, so that successive
    /// frames look at other pixels); `None`: no estimate. Its time is the frame's
    /// `error_estimate` stage.
    pub fn set_error_estimate(&mut self, options: Option<EstimateOptions>) {
        match options {
            None => self.estimate = None,
            Some(options) => {
                let estimator = self.estimate.take().map_or_else(Estimator::new, |(e, _)| e);
                self.estimate = Some((estimator, options));
            }
        }
    }

    /// [`Renderer::render`] without the error estimate [`Renderer::set_error_estimate`] asks
    /// for: a frame that is itself what the estimate compares with (the exact reference), or
    /// one whose estimate is taken afterwards.
    pub fn render_unestimated(
        &mut self,
        gpu: &Gpu,
        method: Method,
        width: u32,
        height: u32,
    ) -> Result<Rendered, GpuError> {
        let estimate = self.estimate.take();
        let rendered = self.render(gpu, method, width, height);
        self.estimate = estimate;
        rendered
    }

    /// The frame's error estimate, where [`Renderer::set_error_estimate`] asked for one, into
    /// `rendered` (and its time as the estimate's stage): what every frame with indirect light
    /// gets, also for one this renderer's frame was made from elsewhere (the CPU exact reference
    /// over a level's coarser VALs, `bench::compare::exact_reference`).
    pub fn estimate_error(&mut self, gpu: &Gpu, rendered: &mut Rendered) -> Result<(), GpuError> {
        let Some((mut estimator, options)) = self.estimate.take() else { return Ok(()) };
        let seed = options.seed.wrapping_add(self.estimated_frames);
        self.estimated_frames += 1;
        let result = estimator.estimate(gpu, self, rendered, &EstimateOptions { seed, ..options });
        self.estimate = Some((estimator, options));
        rendered.error_estimate = result?;
        if let Some(e) = &rendered.error_estimate {
            rendered.timings.stages.push((STAGE.to_owned(), e.ms));
        }
        Ok(())
    }
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
            reference_vals: 16_384,
            reference_rsm_resolution: Some(128),
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
        let (picked, weights) = by_importance(&items, &[&[1.0; 100]], 10, 3);
        assert_eq!(picked.len(), 10);
        for (k, p) in picked.iter().enumerate() {
            assert!((100 + 10 * k..100 + 10 * (k + 1)).contains(p), "pick {k} = {p}");
        }
        assert!(weights.iter().all(|&w| w == 1.0), "{weights:?}");
        assert_ne!(by_importance(&items, &[&[1.0; 100]], 10, 4).0, picked, "the seed moves the picks");
        assert_eq!(by_importance(&items[..5], &[&[0.0; 5]], 10, 3), (items[..5].to_vec(), vec![1.0; 5]));
    }

    /// Two terms share the draws: `q = (1 + b / mean(b) + c / mean(c)) / 3`, so the item
    /// bright in one and the item of high contrast in the other both get a third of the draws
    /// each (q = 3 of a sum of 8), the rest 1/3 each; a term of mean 0 counts as uniform.
    #[test]
    fn terms_share_the_draws() {
        let items: Vec<usize> = (0..8).collect();
        let (b, c) = ([8.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 8.0]);
        for seed in 0..20 {
            let (picked, weights) = by_importance(&items, &[&b, &c], 4, seed);
            assert_eq!((picked[0], weights[0]), (0, 1.0 / 3.0), "seed {seed}: {picked:?}");
            assert_eq!((picked[3], weights[3]), (7, 1.0 / 3.0), "seed {seed}: {picked:?}");
            for (p, w) in picked.iter().zip(&weights) {
                assert_eq!(*w, if *p == 0 || *p == 7 { 1.0 / 3.0 } else { 3.0 }, "seed {seed}: {picked:?}");
            }
        }
        let (_, weights) = by_importance(&items, &[&b, &[0.0; 8]], 8 - 1, 1);
        let near = |w: f64, x: f64| (w - x).abs() < 1e-12;
        assert!(weights.iter().all(|&w| near(w, 0.3) || near(w, 1.5)), "{weights:?}");
    }

    /// The contrast is the larger central difference: a vertical step from 0 to 1 is 1 on both
    /// columns beside it and 0 elsewhere, on the top row as on the others.
    #[test]
    fn contrast_is_the_larger_central_difference() {
        let (w, h) = (6, 4);
        let lum: Vec<f32> = (0..w * h).map(|i| if i % w >= 3 { 1.0 } else { 0.0 }).collect();
        let row: Vec<f64> = (w..2 * w).map(|i| contrast(&lum, w, i)).collect();
        assert_eq!(row, [0.0, 0.0, 1.0, 1.0, 0.0, 0.0]);
        let top: Vec<f64> = (0..w).map(|i| contrast(&lum, w, i)).collect();
        assert_eq!(top, row, "on the top row only the vertical difference is left out");
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
            let (picked, weights) = by_importance(&items, &[&brightness], 50, seed);
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

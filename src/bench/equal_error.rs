//! Speed at equal error: how long a converging estimator of the same image needs to reach each
//! configuration's error. relume's real-time method trades accuracy for time; on
//! hardware where an unbiased estimator that simply runs longer reaches the same error sooner,
//! that trade has lost its point.
//!
//! The converging estimator is relume's own CPU exact reference with importance-sampled VALs
//! (`twin::exact_cpu`, `ValSampling::Importance`): per pixel, `N` VALs drawn with probability
//! proportional to their unoccluded contribution, one shadow ray each through obvhs's CWBVH, on
//! every core (rayon). It is a path tracer of exactly this one-bounce light transport (the
//! camera ray is the visibility buffer's, 1 sample per pixel), seeded apart from the bench's
//! reference so that the two estimates are independent. Its error against the bench's
//! reference is measured at each `N` of a doubling ladder, corrected for the reference's own
//! noise like the configurations' errors; each configuration's error gives the samples the
//! estimator needs ([`at_error`]) and its time there, a fixed cost plus a cost per sample fitted
//! to the measured wall times (BVH build and tracing, [`time_model`]).

use crate::bench::compare::{self, ExactOptions, ExactReference, ReferenceDevice};
use crate::gpu::{Gpu, GpuError};
use crate::renderer::Renderer;

/// The curve's seed: independent of [`compare::REFERENCE_SEED`], which the reference uses.
pub const CURVE_SEED: u64 = 0xe9a1_e770;

/// The sample counts measured when `--equal-error` gives none.
pub const DEFAULT_SAMPLES: [u32; 8] = [2, 4, 8, 16, 32, 64, 128, 256];

/// One estimate of the converging estimator.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct CurvePoint {
    /// VALs drawn per pixel.
    pub samples: u32,
    /// Wall time of the estimate (BVH build and tracing), ms.
    pub ms: f64,
    /// Relative RMSE against the bench's exact reference, corrected for the reference's noise
    /// when it has an estimate of it (as the configurations' `rel_rmse_vs_exact_corrected`).
    pub rel_rmse: f64,
    pub shadow_rays: u64,
}

/// The converging estimator's error against time at one image size.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct EqualErrorCurve {
    /// The configurations it serves: those sharing this reference (the VALs of one RSM
    /// resolution, glossy or not, one size).
    pub label: String,
    pub width: u32,
    pub height: u32,
    /// What the estimator is, in words.
    pub estimator: &'static str,
    pub points: Vec<CurvePoint>,
    /// [`time_model`]: the estimator's fixed cost (ms) and cost per sample (ms).
    pub fixed_ms: f64,
    pub per_sample_ms: f64,
}

pub const ESTIMATOR: &str = "CPU exact reference, importance-sampled VALs (N per pixel, one shadow ray each, \
     obvhs CWBVH, rayon), 1 sample per pixel at the visibility buffer's hits";

/// The converging estimator's time at one configuration's error.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct AtEqualError {
    /// Samples per pixel the estimator needs for the configuration's error (fractional: on the
    /// interpolated curve).
    pub samples: f64,
    /// Time the estimator needs for the configuration's error, ms.
    pub estimator_ms: f64,
    /// `estimator_ms / sparse_indirect_ms`: above 1, relume is faster at equal error.
    pub speedup: f64,
    /// The error lies outside the measured points: the samples follow the Monte Carlo rate
    /// (error ∝ N^-1/2) from the nearest measured point.
    pub extrapolated: bool,
}

/// Measure the curve: the estimator at each of `samples` (each in `2..=MAX_VAL_SAMPLES`),
/// against `reference`, at `width` x `height` of `renderer`'s current frame.
pub fn measure(
    label: String,
    gpu: &Gpu,
    renderer: &mut Renderer,
    width: u32,
    height: u32,
    reference: &ExactReference,
    samples: &[u32],
) -> Result<EqualErrorCurve, GpuError> {
    let mut points = Vec::with_capacity(samples.len());
    for &n in samples {
        let options = ExactOptions { samples: Some(n), ..ExactOptions::every_val(ReferenceDevice::Cpu) };
        let estimate = compare::exact_reference_seeded(gpu, renderer, width, height, &options, CURVE_SEED)?;
        let rel_rmse = error_against(reference, estimate.indirect());
        points.push(CurvePoint {
            samples: n,
            ms: estimate.ms(),
            rel_rmse,
            shadow_rays: estimate.shadow_rays.unwrap_or(0),
        });
    }
    let (fixed_ms, per_sample_ms) = time_model(&points).unwrap_or_default();
    Ok(EqualErrorCurve { label, width, height, estimator: ESTIMATOR, points, fixed_ms, per_sample_ms })
}

/// `test`'s relative RMSE against `reference`, corrected for its noise where it is known.
fn error_against(reference: &ExactReference, test: &crate::image::LinearImage) -> f64 {
    reference.corrected_rel_rmse(test).unwrap_or_else(|| compare::indirect_error(test, reference.indirect()).rel_rmse)
}

/// The estimator's time as a fixed cost (BVH build, each pixel's VAL distribution) plus a cost
/// per sample: `ms = fixed + per_sample N`, least squares over `points`, both terms at least 0.
/// Wall times at small `N` are mostly the fixed cost and scatter about it, so the times are
/// fitted rather than interpolated.
pub fn time_model(points: &[CurvePoint]) -> Option<(f64, f64)> {
    let n = points.len() as f64;
    if points.is_empty() {
        return None;
    }
    let (sx, sy) = points.iter().fold((0.0, 0.0), |(x, y), p| (x + p.samples as f64, y + p.ms));
    let (mx, my) = (sx / n, sy / n);
    let sxx: f64 = points.iter().map(|p| (p.samples as f64 - mx).powi(2)).sum();
    let sxy: f64 = points.iter().map(|p| (p.samples as f64 - mx) * (p.ms - my)).sum();
    let slope = if sxx > 0.0 { (sxy / sxx).max(0.0) } else { my / mx.max(1.0) };
    let fixed = (my - slope * mx).max(0.0);
    Some((fixed, slope))
}

/// The time at which the estimator of `points` reaches `error`, and the speed-up over
/// `method_ms`. The samples it needs: along increasing `N`, the lower envelope of the measured
/// errors (the least error reached by then), interpolated linearly in log `N` and log error;
/// outside the measured errors the Monte Carlo rate (error ∝ `N`^-1/2) extends it from the
/// nearest point. Its time: [`time_model`] at those samples. `None` without points or for an
/// error that is not positive and finite.
pub fn at_error(points: &[CurvePoint], error: f64, method_ms: f64) -> Option<AtEqualError> {
    if !(error.is_finite() && error > 0.0) || method_ms <= 0.0 {
        return None;
    }
    let mut sorted: Vec<&CurvePoint> = points.iter().filter(|p| p.samples > 0 && p.rel_rmse > 0.0).collect();
    sorted.sort_by_key(|p| p.samples);
    let (fixed, per_sample) = time_model(&sorted.iter().map(|p| **p).collect::<Vec<_>>())?;
    let mut envelope: Vec<(f64, f64)> = Vec::new();
    for p in sorted {
        if envelope.last().is_none_or(|last| p.rel_rmse < last.1) {
            envelope.push((p.samples as f64, p.rel_rmse));
        }
    }
    let (first, last) = (*envelope.first()?, *envelope.last()?);
    let monte_carlo = |(n, e): (f64, f64)| n * (e / error).powi(2);
    let (samples, extrapolated) = if error >= first.1 {
        (monte_carlo(first), error > first.1)
    } else if error <= last.1 {
        (monte_carlo(last), error < last.1)
    } else {
        let i = envelope.windows(2).position(|w| w[0].1 >= error && error >= w[1].1)?;
        let ((n0, e0), (n1, e1)) = (envelope[i], envelope[i + 1]);
        let f = (error.ln() - e0.ln()) / (e1.ln() - e0.ln());
        ((n0.ln() + f * (n1.ln() - n0.ln())).exp(), false)
    };
    let estimator_ms = fixed + per_sample * samples;
    Some(AtEqualError { samples, estimator_ms, speedup: estimator_ms / method_ms, extrapolated })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(samples: u32, ms: f64, rel_rmse: f64) -> CurvePoint {
        CurvePoint { samples, ms, rel_rmse, shadow_rays: 0 }
    }

    /// 100 ms fixed, 1 ms a sample, error 0.4 / sqrt(N / 4): an ideal estimator.
    fn ideal(samples: &[u32]) -> Vec<CurvePoint> {
        samples.iter().map(|&n| point(n, 100.0 + n as f64, 0.4 / (n as f64 / 4.0).sqrt())).collect()
    }

    #[test]
    fn the_time_model_recovers_fixed_and_per_sample_costs() {
        let (fixed, per_sample) = time_model(&ideal(&[4, 16, 64])).unwrap();
        assert!((fixed - 100.0).abs() < 1e-9 && (per_sample - 1.0).abs() < 1e-9, "{fixed} {per_sample}");
        // One point: all of it per sample.
        assert_eq!(time_model(&[point(4, 8.0, 0.1)]), Some((0.0, 2.0)));
    }

    #[test]
    fn inside_the_curve_samples_are_interpolated_in_log_log() {
        let points = ideal(&[4, 16, 64]);
        let at = at_error(&points, 0.2, 10.0).unwrap();
        assert!((at.samples - 16.0).abs() < 1e-9 && !at.extrapolated, "{at:?}");
        assert!((at.estimator_ms - 116.0).abs() < 1e-9 && (at.speedup - 11.6).abs() < 1e-9, "{at:?}");
        // Halfway in log error between 0.4 and 0.2 is halfway in log N: 8 samples.
        let at = at_error(&points, (0.4f64 * 0.2).sqrt(), 1.0).unwrap();
        assert!((at.samples - 8.0).abs() < 1e-9, "{at:?}");
    }

    #[test]
    fn outside_the_curve_the_monte_carlo_rate_extends_it() {
        let points = ideal(&[4, 16]);
        // Half the last error: four times its samples.
        let at = at_error(&points, 0.1, 1.0).unwrap();
        assert!((at.samples - 64.0).abs() < 1e-9 && at.extrapolated, "{at:?}");
        assert!((at.estimator_ms - 164.0).abs() < 1e-9, "{at:?}");
        // Twice the first error: a quarter of its samples, and still the fixed cost.
        let at = at_error(&points, 0.8, 1.0).unwrap();
        assert!((at.samples - 1.0).abs() < 1e-9 && at.extrapolated, "{at:?}");
        assert!((at.estimator_ms - 101.0).abs() < 1e-9, "{at:?}");
    }

    #[test]
    fn times_that_scatter_about_the_fixed_cost_do_not_reorder_the_curve() {
        // Measured on a loaded machine: N = 16 timed faster than N = 2. The samples still come
        // from the errors in order of N, so an error between those of N = 2 and 4 is inside.
        let points = [point(2, 750.0, 0.32), point(4, 761.0, 0.24), point(16, 644.0, 0.11), point(256, 2294.0, 0.028)];
        let at = at_error(&points, 0.28, 1.0).unwrap();
        assert!(!at.extrapolated && at.samples > 2.0 && at.samples < 4.0, "{at:?}");
    }

    #[test]
    fn a_noisy_error_is_taken_at_its_lower_envelope() {
        // N = 8 measured worse than N = 4 (noise): skipped, so 0.25 lies between 4 and 16.
        let points = [point(4, 1.0, 0.3), point(8, 2.0, 0.35), point(16, 4.0, 0.2)];
        let at = at_error(&points, 0.25, 1.0).unwrap();
        assert!(at.samples > 4.0 && at.samples < 16.0 && !at.extrapolated, "{at:?}");
    }

    #[test]
    fn no_points_or_no_error_gives_nothing() {
        assert_eq!(at_error(&[], 0.1, 1.0), None);
        assert_eq!(at_error(&[point(2, 1.0, 0.1)], 0.0, 1.0), None);
        assert_eq!(at_error(&[point(2, 1.0, 0.1)], f64::NAN, 1.0), None);
    }
}

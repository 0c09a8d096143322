//! Speed at equal error: how long a converging estimator of the same image needs to reach each
//! configuration's error (issue 18). relume's real-time method trades accuracy for time; on
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
//! noise like the configurations' errors, and its time (BVH build and tracing, wall clock) is
//! interpolated to each configuration's error.

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
}

pub const ESTIMATOR: &str = "CPU exact reference, importance-sampled VALs (N per pixel, one shadow ray each, \
     obvhs CWBVH, rayon), 1 sample per pixel at the visibility buffer's hits";

/// The converging estimator's time at one configuration's error.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct AtEqualError {
    /// Time the estimator needs for the configuration's error, ms.
    pub estimator_ms: f64,
    /// `estimator_ms / sparse_indirect_ms`: above 1, relume is faster at equal error.
    pub speedup: f64,
    /// The error lies outside the measured points: the time follows the Monte Carlo rate
    /// (error ∝ time^-1/2) from the nearest measured point.
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
        let options = ExactOptions { device: ReferenceDevice::Cpu, val_stride: 1, samples: Some(n), spp: 1 };
        let estimate = compare::exact_reference_seeded(gpu, renderer, width, height, &options, CURVE_SEED)?;
        let rel_rmse = error_against(reference, estimate.indirect());
        points.push(CurvePoint {
            samples: n,
            ms: estimate.ms(),
            rel_rmse,
            shadow_rays: estimate.shadow_rays.unwrap_or(0),
        });
    }
    Ok(EqualErrorCurve { label, width, height, estimator: ESTIMATOR, points })
}

/// `test`'s relative RMSE against `reference`, corrected for its noise where it is known.
pub fn error_against(reference: &ExactReference, test: &crate::image::LinearImage) -> f64 {
    reference.corrected_rel_rmse(test).unwrap_or_else(|| compare::indirect_error(test, reference.indirect()).rel_rmse)
}

/// The time at which the estimator of `points` reaches `error`, and the speed-up over
/// `method_ms`. The points are taken in order of time; the curve is their lower envelope (the
/// least error reached by then), interpolated linearly in log time and log error. Outside the
/// measured errors the Monte Carlo rate extends it. `None` without points or for an error that
/// is not positive and finite.
pub fn at_error(points: &[CurvePoint], error: f64, method_ms: f64) -> Option<AtEqualError> {
    if !(error.is_finite() && error > 0.0) || method_ms <= 0.0 {
        return None;
    }
    let mut sorted: Vec<(f64, f64)> =
        points.iter().filter(|p| p.ms > 0.0 && p.rel_rmse > 0.0).map(|p| (p.ms, p.rel_rmse)).collect();
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
    // Lower envelope: keep a point only where it improves on every earlier one.
    let mut envelope: Vec<(f64, f64)> = Vec::new();
    for p in sorted {
        if envelope.last().is_none_or(|last| p.1 < last.1) {
            envelope.push(p);
        }
    }
    let (first, last) = (*envelope.first()?, *envelope.last()?);
    // error ∝ time^-1/2, so time = t0 (e0 / e)².
    let monte_carlo = |(t, e): (f64, f64)| t * (e / error).powi(2);
    let estimator_ms = if error >= first.1 {
        (monte_carlo(first), error > first.1)
    } else if error <= last.1 {
        (monte_carlo(last), error < last.1)
    } else {
        let i = envelope.windows(2).position(|w| w[0].1 >= error && error >= w[1].1)?;
        let ((t0, e0), (t1, e1)) = (envelope[i], envelope[i + 1]);
        let f = (error.ln() - e0.ln()) / (e1.ln() - e0.ln());
        ((t0.ln() + f * (t1.ln() - t0.ln())).exp(), false)
    };
    let (estimator_ms, extrapolated) = estimator_ms;
    Some(AtEqualError { estimator_ms, speedup: estimator_ms / method_ms, extrapolated })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(ms: f64, rel_rmse: f64) -> CurvePoint {
        CurvePoint { samples: 0, ms, rel_rmse, shadow_rays: 0 }
    }

    #[test]
    fn inside_the_curve_time_is_interpolated_in_log_log() {
        let points = [point(10.0, 0.4), point(40.0, 0.2), point(160.0, 0.1)];
        let at = at_error(&points, 0.2, 4.0).unwrap();
        assert!((at.estimator_ms - 40.0).abs() < 1e-9 && !at.extrapolated);
        assert!((at.speedup - 10.0).abs() < 1e-9);
        // Halfway in log error between 0.4 and 0.2 is halfway in log time: 20 ms.
        let at = at_error(&points, (0.4f64 * 0.2).sqrt(), 1.0).unwrap();
        assert!((at.estimator_ms - 20.0).abs() < 1e-9, "{at:?}");
    }

    #[test]
    fn outside_the_curve_the_monte_carlo_rate_extends_it() {
        let points = [point(10.0, 0.4), point(40.0, 0.2)];
        // Half the last error: four times its time.
        let at = at_error(&points, 0.1, 1.0).unwrap();
        assert!((at.estimator_ms - 160.0).abs() < 1e-9 && at.extrapolated, "{at:?}");
        // Twice the first error: a quarter of its time.
        let at = at_error(&points, 0.8, 1.0).unwrap();
        assert!((at.estimator_ms - 2.5).abs() < 1e-9 && at.extrapolated, "{at:?}");
    }

    #[test]
    fn a_noisy_curve_is_taken_at_its_lower_envelope() {
        // The 30 ms point is worse than the 20 ms one (noise): it is skipped, so the error 0.25
        // is reached between 20 and 80 ms, not before 30.
        let points = [point(80.0, 0.2), point(20.0, 0.3), point(30.0, 0.35)];
        let at = at_error(&points, 0.25, 1.0).unwrap();
        assert!(at.estimator_ms > 20.0 && at.estimator_ms < 80.0 && !at.extrapolated, "{at:?}");
    }

    #[test]
    fn no_points_or_no_error_gives_nothing() {
        assert_eq!(at_error(&[], 0.1, 1.0), None);
        assert_eq!(at_error(&[point(1.0, 0.1)], 0.0, 1.0), None);
        assert_eq!(at_error(&[point(1.0, 0.1)], f64::NAN, 1.0), None);
    }
}

//! Adaptive sparse points (`settings.sparse.adaptive`, beyond the paper): CPU twins of
//! `gpu/sparse/adaptive.wgsl`.
//!
//! A mesh holds, besides the points gathered every frame, a pool of candidates between them
//! (the points its blue-noise placement removed last). Every frame each candidate gets a
//! *score*, the spread of the light its neighbouring gathered points received
//! ([`candidate_score`]: where the interpolation between them has the most to get wrong), and
//! the candidates with the highest scores, up to the frame's budget, are gathered too
//! ([`select`]). A vertex weighs the chosen ones among its nearest candidates beside its
//! nearest points ([`candidate_weights`]), with weights that fall to 0 where a candidate
//! enters its list, so the light stays continuous over the surface; with none chosen it is the
//! light without candidates. A candidate chosen the frame before scores [`HYSTERESIS`] times
//! higher, so the choice stays put while the light changes little.
//!
//! The budget is met by a histogram: scores fall into bins of 1/[`BINS_PER_OCTAVE`] octave, and
//! every candidate in the bins from the top down to the last bin that keeps the count within
//! the budget is chosen ([`threshold_bin`]). Ties within a bin are chosen or left together, so
//! the choice does not depend on the order the GPU visits them in; the budget may be
//! underspent by up to one bin's count.

use glam::Vec3;

use super::{Gathered, InterpolationKernel, luminance};

/// Bins of the score histogram.
pub const SCORE_BINS: u32 = 512;
/// Bins per factor of two in score.
pub const BINS_PER_OCTAVE: f32 = 8.0;
/// `log2` of the lowest bin's lower edge (W/m²); lower positive scores fall into bin 0.
pub const SCORE_LOG2_MIN: f32 = -32.0;
/// A candidate chosen the frame before scores this many times higher (frame-to-frame
/// coherence).
pub const HYSTERESIS: f32 = 1.5;

/// The histogram bin of `score`: `None` for scores that are not positive and finite (never
/// chosen).
pub fn score_bin(score: f32) -> Option<u32> {
    if !(score > 0.0 && score.is_finite()) {
        return None;
    }
    let bin = ((score.log2() - SCORE_LOG2_MIN) * BINS_PER_OCTAVE).floor();
    Some(bin.clamp(0.0, (SCORE_BINS - 1) as f32) as u32)
}

/// The score of a candidate whose gathered neighbours have interpolation `weights` (as
/// [`super::interpolation_weights`] gives them, not normalised) and gathered light
/// `luminances` (W/m²: the diffuse irradiance's luminance plus the glossy sum's): the weighted
/// mean absolute deviation from their weighted mean, times [`HYSTERESIS`] when `chosen_before`.
pub fn candidate_score(weights: &[f32], luminances: &[f32], chosen_before: bool) -> f32 {
    let total: f32 = weights.iter().sum();
    if total <= 0.0 {
        return 0.0;
    }
    let mean: f32 = weights.iter().zip(luminances).map(|(w, y)| w * y).sum::<f32>() / total;
    let spread = weights.iter().zip(luminances).map(|(w, y)| w * (y - mean).abs()).sum::<f32>() / total;
    if chosen_before { spread * HYSTERESIS } else { spread }
}

/// What a candidate's score reads of a gathered point: the luminance of its diffuse irradiance
/// plus, with a glossy lobe, of its glossy sum.
pub fn scored_light(g: &Gathered, glossy: bool) -> f32 {
    let glossy = if glossy { luminance(g.glossy_irradiance) } else { 0.0 };
    luminance(g.irradiance) + glossy
}

/// The lowest bin whose candidates are chosen, for `histogram` (counts per bin) and `budget`:
/// the lowest `b` with at most `budget` candidates in bins `b..`; [`SCORE_BINS`] when even the
/// top bin holds more (nothing is chosen).
pub fn threshold_bin(histogram: &[u32], budget: u32) -> u32 {
    let mut above = 0u32;
    for b in (0..histogram.len()).rev() {
        above += histogram[b];
        if above > budget {
            return b as u32 + 1;
        }
    }
    0
}

/// Which candidates a frame gathers, from their `scores` ([`candidate_score`]) and `budget`.
pub fn select(scores: &[f32], budget: u32) -> Vec<bool> {
    let mut histogram = vec![0u32; SCORE_BINS as usize];
    for bin in scores.iter().filter_map(|&s| score_bin(s)) {
        histogram[bin as usize] += 1;
    }
    let threshold = threshold_bin(&histogram, budget);
    scores.iter().map(|&s| score_bin(s).is_some_and(|b| b >= threshold)).collect()
}

/// The interpolation weights of a vertex's nearest candidates (`candidate_offsets` and
/// `candidate_normals`, nearest first) beside its nearest points at `point_offsets`, for the
/// `kernel`: 0 for a candidate not `chosen` this frame, else the kernel's weight over the
/// radius `min(d_max, e_max)` (the points' and the listed candidates' largest distances), so a
/// candidate entering either list does so at weight 0.
pub fn candidate_weights(
    kernel: InterpolationKernel,
    n_v: Vec3,
    point_offsets: &[Vec3],
    candidate_offsets: &[Vec3],
    candidate_normals: &[Vec3],
    chosen: &[bool],
) -> Vec<f32> {
    let d_max = point_offsets.iter().map(|o| o.length()).fold(0.0f32, f32::max);
    let e_max = candidate_offsets.iter().map(|o| o.length()).fold(0.0f32, f32::max);
    let radius = d_max.min(e_max);
    candidate_offsets
        .iter()
        .zip(candidate_normals)
        .zip(chosen)
        .map(|((&o, &n), &chosen)| {
            if !chosen || radius <= 0.0 {
                return 0.0;
            }
            let spatial = match kernel {
                InterpolationKernel::Paper => super::paper_weight(o.length(), radius),
                InterpolationKernel::Smooth => super::smooth_weight(n_v, n, o, radius),
            };
            spatial * super::facing(n_v, n)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bins_are_monotonic_and_reject_nothing() {
        assert_eq!(score_bin(0.0), None);
        assert_eq!(score_bin(-1.0), None);
        assert_eq!(score_bin(f32::NAN), None);
        assert_eq!(score_bin(f32::INFINITY), None);
        assert_eq!(score_bin(1e-30), Some(0));
        assert_eq!(score_bin(1e30), Some(SCORE_BINS - 1));
        let mut last = 0;
        for i in 0..200 {
            let bin = score_bin(1e-6 * 1.1f32.powi(i)).unwrap();
            assert!(bin >= last);
            last = bin;
        }
        // One octave is BINS_PER_OCTAVE bins.
        assert_eq!(score_bin(2.0).unwrap() - score_bin(1.0).unwrap(), BINS_PER_OCTAVE as u32);
    }

    #[test]
    fn selection_keeps_the_highest_scores_within_the_budget() {
        let scores: Vec<f32> = (0..100).map(|i| i as f32 * 0.37 + 0.01).collect();
        for budget in [0, 1, 10, 50, 99, 100, 200] {
            let chosen = select(&scores, budget);
            let n = chosen.iter().filter(|&&c| c).count() as u32;
            assert!(n <= budget, "budget {budget}: {n}");
            // Every chosen score is above every score left out.
            let lowest_chosen =
                scores.iter().zip(&chosen).filter(|(_, c)| **c).map(|(s, _)| *s).fold(f32::MAX, f32::min);
            let highest_left = scores.iter().zip(&chosen).filter(|(_, c)| !**c).map(|(s, _)| *s).fold(0.0, f32::max);
            assert!(n == 0 || lowest_chosen > highest_left, "budget {budget}");
            // Underspent by at most one bin's count: a 1/8-octave bin holds at most 8 of these.
            assert!(budget.min(100) - n <= 8, "budget {budget}: {n}");
        }
        // Zero scores are never chosen.
        assert_eq!(select(&[0.0, 0.0, 1.0], 3), vec![false, false, true]);
    }

    #[test]
    fn spread_is_zero_for_uniform_light_and_grows_with_contrast() {
        let w = [1.0, 0.5, 0.25];
        assert_eq!(candidate_score(&w, &[2.0, 2.0, 2.0], false), 0.0);
        let low = candidate_score(&w, &[1.0, 2.0, 3.0], false);
        let high = candidate_score(&w, &[1.0, 4.0, 9.0], false);
        assert!(0.0 < low && low < high);
        assert_eq!(candidate_score(&w, &[1.0, 2.0, 3.0], true), low * HYSTERESIS);
        assert_eq!(candidate_score(&[0.0, 0.0], &[1.0, 5.0], false), 0.0);
    }

    #[test]
    fn candidates_weigh_only_when_chosen_and_fall_to_zero_at_the_radius() {
        let points = [Vec3::new(0.3, 0.0, 0.0), Vec3::new(0.0, 0.5, 0.0)];
        let candidates = [Vec3::new(0.1, 0.0, 0.0), Vec3::new(0.0, -0.2, 0.0), Vec3::new(0.6, 0.0, 0.0)];
        let normals = [Vec3::Z; 3];
        for kernel in [InterpolationKernel::Paper, InterpolationKernel::Smooth] {
            let none = candidate_weights(kernel, Vec3::Z, &points, &candidates, &normals, &[false; 3]);
            assert_eq!(none, vec![0.0; 3]);
            let all = candidate_weights(kernel, Vec3::Z, &points, &candidates, &normals, &[true; 3]);
            // Radius min(0.5, 0.6) = 0.5: the nearest weighs most, the one beyond weighs nothing.
            assert!(all[0] > all[1] && all[1] > 0.0 && all[2] == 0.0, "{kernel:?}: {all:?}");
            let facing_away = candidate_weights(kernel, Vec3::Z, &points, &candidates, &[-Vec3::Z; 3], &[true; 3]);
            assert_eq!(facing_away, vec![0.0; 3]);
        }
    }
}

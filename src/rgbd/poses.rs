//! Camera poses of a recording: samples (a transform at a time, f64 as recorded) and the pose
//! at a frame's timestamp, interpolated between the two bracketing samples (translation lerp,
//! rotation slerp). Shared by the TUM layout (`groundtruth.txt`) and MCAP (pose messages).

use glam::{DAffine3, DQuat, DVec3};

/// Largest `|‖q‖ - 1|` accepted for a ground-truth quaternion (TUM writes 4 decimals).
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

/// One line of `groundtruth.txt` (or one transform of an MCAP file): camera-to-world at
/// `timestamp`, in f64 as recorded (f32 keeps 7.8 mm at 100 km from the origin).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct PoseSample {
    pub timestamp: f64,
    pub translation: DVec3,
    /// Unit.
    pub rotation: DQuat,
}

impl PoseSample {
    /// A sample from a translation and a quaternion `[x, y, z, w]` as recorded (f64), the
    /// quaternion normalised; an error when its norm is off 1 by more than
    /// [`QUATERNION_NORM_TOLERANCE`].
    pub fn new(timestamp: f64, translation: [f64; 3], quaternion: [f64; 4]) -> Result<PoseSample, String> {
        let norm = quaternion.iter().map(|c| c * c).sum::<f64>().sqrt();
        if norm.is_nan() || (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
            return Err(format!("quaternion (x y z w) has norm {norm}, not 1 (within {QUATERNION_NORM_TOLERANCE})"));
        }
        let q = quaternion.map(|c| c / norm);
        Ok(PoseSample {
            timestamp,
            translation: DVec3::from_array(translation),
            rotation: DQuat::from_array(q).normalize(),
        })
    }
}

/// Index of the value of increasing `sorted` nearest to `t` (the earlier one on a tie).
pub(super) fn nearest(sorted: &[f64], t: f64) -> Option<usize> {
    let after = sorted.partition_point(|&x| x < t);
    match (after.checked_sub(1), (after < sorted.len()).then_some(after)) {
        (Some(before), Some(after)) => Some(if t - sorted[before] <= sorted[after] - t { before } else { after }),
        (before, after) => before.or(after),
    }
}

/// Camera-to-world at `t` from increasing `samples`: interpolated between the bracketing pair,
/// the end sample just outside the trajectory; `None` when no sample lies within `tolerance`.
pub(super) fn interpolate_pose(samples: &[PoseSample], t: f64, tolerance: f64) -> Option<DAffine3> {
    let after = samples.partition_point(|s| s.timestamp <= t);
    let (a, b) = match (after.checked_sub(1).map(|i| samples[i]), samples.get(after)) {
        (Some(a), Some(b)) => (a, *b),
        (Some(end), None) | (None, Some(&end)) => (end, end),
        (None, None) => return None,
    };
    if (t - a.timestamp).abs().min((b.timestamp - t).abs()) > tolerance {
        return None;
    }
    let s = if b.timestamp > a.timestamp { (t - a.timestamp) / (b.timestamp - a.timestamp) } else { 0.0 };
    let rotation = a.rotation.slerp(b.rotation, s).normalize();
    Some(DAffine3::from_rotation_translation(rotation, a.translation.lerp(b.translation, s)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    fn sample(timestamp: f64, x: f64, angle: f64) -> PoseSample {
        PoseSample { timestamp, translation: DVec3::new(x, 0.0, 0.0), rotation: DQuat::from_rotation_z(angle) }
    }

    #[test]
    fn nearest_picks_the_closer_neighbour() {
        let times = [1.0, 2.0, 4.0];
        assert_eq!(nearest(&times, 0.0), Some(0));
        assert_eq!(nearest(&times, 1.4), Some(0));
        assert_eq!(nearest(&times, 1.5), Some(0));
        assert_eq!(nearest(&times, 1.6), Some(1));
        assert_eq!(nearest(&times, 3.5), Some(2));
        assert_eq!(nearest(&times, 9.0), Some(2));
        assert_eq!(nearest(&[], 1.0), None);
    }

    #[test]
    fn poses_interpolate_between_bracketing_samples() {
        let samples = [sample(0.0, 0.0, 0.0), sample(0.01, 1.0, FRAC_PI_2)];
        let pose = interpolate_pose(&samples, 0.0025, 0.02).unwrap();
        let (scale, rotation, translation) = pose.to_scale_rotation_translation();
        assert!(scale.abs_diff_eq(DVec3::ONE, 1e-12));
        assert!(translation.abs_diff_eq(DVec3::new(0.25, 0.0, 0.0), 1e-12), "{translation}");
        assert!(rotation.abs_diff_eq(DQuat::from_rotation_z(FRAC_PI_2 / 4.0), 1e-12), "{rotation}");
    }

    #[test]
    fn slerp_takes_the_short_way_across_a_sign_flip() {
        // The second sample is stored as -q: the same rotation, the opposite hemisphere.
        let mut b = sample(0.01, 0.0, 0.2);
        b.rotation = -b.rotation;
        let pose = interpolate_pose(&[sample(0.0, 0.0, 0.0), b], 0.005, 0.02).unwrap();
        let (_, rotation, _) = pose.to_scale_rotation_translation();
        assert!(rotation.abs_diff_eq(DQuat::from_rotation_z(0.1), 1e-12), "{rotation}");
    }

    #[test]
    fn poses_outside_the_trajectory_or_in_gaps_are_missing() {
        let samples = [sample(1.0, 0.0, 0.0), sample(1.01, 1.0, 0.0), sample(2.0, 2.0, 0.0)];
        // Just outside: the end sample.
        let before = interpolate_pose(&samples, 0.99, 0.02).unwrap();
        assert_eq!(before.translation, DVec3::ZERO);
        let after = interpolate_pose(&samples, 2.015, 0.02).unwrap();
        assert_eq!(after.translation, DVec3::new(2.0, 0.0, 0.0));
        // Further outside, or in the middle of a 1 s tracking gap.
        assert!(interpolate_pose(&samples, 0.97, 0.02).is_none());
        assert!(interpolate_pose(&samples, 2.03, 0.02).is_none());
        assert!(interpolate_pose(&samples, 1.5, 0.02).is_none());
        assert!(interpolate_pose(&samples, 1.025, 0.02).is_some());
        assert!(interpolate_pose(&[], 1.0, 0.02).is_none());
    }
}

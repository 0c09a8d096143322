//! The poses of an MCAP recording's frames: `PoseStamped` samples or the transform tree of
//! `/tf` and `/tf_static`.

use std::collections::HashMap;

use glam::DAffine3;

use super::msg;
use crate::rgbd::poses::{PoseSample, interpolate_pose};

/// The transforms of `/tf` and `/tf_static`: for each child frame, its parent and its samples
/// (parent-to-child placement, i.e. child-to-parent coordinates), or one static transform.
#[derive(Debug, Default)]
pub(super) struct Transforms {
    edges: HashMap<String, Edge>,
}

#[derive(Debug)]
struct Edge {
    parent: String,
    samples: Vec<PoseSample>,
    is_static: bool,
}

impl Transforms {
    pub(super) fn is_empty(&self) -> bool {
        self.edges.is_empty()
    }

    pub(super) fn add(&mut self, tf: &msg::TfMessage, is_static: bool) -> Result<(), String> {
        for (i, t) in tf.transforms.iter().enumerate() {
            let field = format!("transforms[{i}]");
            let (v, q) = (t.transform.translation, t.transform.rotation);
            let sample = PoseSample::new(t.header.stamp.seconds(), [v.x, v.y, v.z], [q.x, q.y, q.z, q.w])
                .map_err(|m| format!("field `{field}.transform.rotation`: {m}"))?;
            if !sample.translation.is_finite() {
                return Err(format!("field `{field}.transform.translation`: not finite"));
            }
            let edge = self.edges.entry(t.child_frame_id.clone()).or_insert_with(|| Edge {
                parent: t.header.frame_id.clone(),
                samples: Vec::new(),
                is_static,
            });
            if edge.parent != t.header.frame_id {
                return Err(format!(
                    "field `{field}.header.frame_id`: frame `{}` has parent `{}` here and `{}` before",
                    t.child_frame_id, t.header.frame_id, edge.parent
                ));
            }
            if is_static {
                edge.samples = vec![sample];
            } else if edge.samples.last().is_some_and(|last| last.timestamp >= sample.timestamp) {
                // Out of order or repeated: keep the samples sorted, later duplicates win.
                edge.samples.retain(|s| s.timestamp != sample.timestamp);
                let at = edge.samples.partition_point(|s| s.timestamp < sample.timestamp);
                edge.samples.insert(at, sample);
            } else {
                edge.samples.push(sample);
            }
        }
        Ok(())
    }

    /// The frames from `frame` up to the root of its tree (`frame` first), with whether a
    /// dynamic link lies on the way; `None` on a cycle.
    fn chain<'a>(&'a self, frame: &'a str) -> Option<(Vec<&'a str>, bool)> {
        let (mut chain, mut moves) = (vec![frame], false);
        for _ in 0..=self.edges.len() {
            let Some(edge) = self.edges.get(*chain.last()?) else { return Some((chain, moves)) };
            moves |= !edge.is_static;
            chain.push(&edge.parent);
        }
        None
    }

    /// Checks that `frame` is in the tree, that its chain to the root has no cycle, and, when
    /// `/tf` moves some frames, that the chain reaches one of them (a chain of static links
    /// that stops short of the moving ones means a link is missing from the recording).
    /// Returns whether a dynamic link lies on the chain.
    pub(super) fn check_frame(&self, frame: &str) -> Result<bool, String> {
        if !self.edges.contains_key(frame) {
            let mut frames: Vec<&str> = self.edges.keys().map(String::as_str).collect();
            frames.sort_unstable();
            let hint = if self.edges.values().any(|e| e.is_static) {
                ""
            } else {
                " (the file has no /tf_static, where the camera's optical frames usually are: record it too)"
            };
            return Err(format!(
                "no transform places the depth image's frame `{frame}` (its header.frame_id){hint}; the transforms place {frames:?}"
            ));
        }
        let (chain, moves) =
            self.chain(frame).ok_or_else(|| format!("the transforms above frame `{frame}` form a cycle"))?;
        if !moves && self.edges.values().any(|e| !e.is_static) {
            let top = chain.last().copied().unwrap_or(frame);
            let mut moving_roots: Vec<&str> = self
                .edges
                .iter()
                .filter(|(_, edge)| !edge.is_static)
                .filter_map(|(child, _)| self.chain(child).and_then(|(up, _)| up.last().copied()))
                .collect();
            moving_roots.sort_unstable();
            moving_roots.dedup();
            let path: Vec<&str> = chain.iter().rev().copied().collect();
            return Err(format!(
                "the depth image's frame `{frame}` hangs from `{top}` by static links only ({}), and no transform \
                 places `{top}` in the tree that /tf moves (rooted at {moving_roots:?}): a link above `{top}` is \
                 missing",
                path.join(" -> ")
            ));
        }
        Ok(moves)
    }

    /// Root-to-`frame` placement at `t`: the chain of parent transforms composed, static ones
    /// as they are, dynamic ones as tf2 looks them up: interpolated between the link's two
    /// samples around `t` however far apart (a localiser may publish `map -> odom` at 1 Hz),
    /// the end sample just outside them; `None` when `t` lies further than `tolerance` outside
    /// a link's samples.
    fn at(&self, frame: &str, t: f64, tolerance: f64) -> Option<DAffine3> {
        let mut pose = DAffine3::IDENTITY;
        let mut current = frame;
        for _ in 0..=self.edges.len() {
            let Some(edge) = self.edges.get(current) else { return Some(pose) };
            let local = if edge.is_static {
                let s = edge.samples.first()?;
                DAffine3::from_rotation_translation(s.rotation, s.translation)
            } else {
                let inside = edge.samples.first().is_some_and(|s| s.timestamp <= t)
                    && edge.samples.last().is_some_and(|s| t <= s.timestamp);
                interpolate_pose(&edge.samples, t, if inside { f64::INFINITY } else { tolerance })?
            };
            pose = local * pose;
            current = &edge.parent;
        }
        None
    }
}

/// Where poses come from.
pub(super) enum PoseSource {
    None,
    Samples(Vec<PoseSample>),
    Tf(Transforms),
}

impl PoseSource {
    pub(super) fn at(&self, camera_frame: &str, t: f64, tolerance: f64) -> Option<DAffine3> {
        match self {
            PoseSource::None => Some(DAffine3::IDENTITY),
            PoseSource::Samples(samples) => interpolate_pose(samples, t, tolerance),
            PoseSource::Tf(transforms) => transforms.at(camera_frame, t, tolerance),
        }
    }
}

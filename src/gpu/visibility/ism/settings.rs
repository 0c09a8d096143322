//! Settings of the `"ism"` visibility mode and their overrides in `settings.tuning.ism` (data:
//! the bottom layer, held by the scene description).

use serde::{Deserialize, Serialize};

use crate::gpu::visibility::settings::SoftShadows;
use crate::scene::SceneError;
use crate::scene::settings::overrides;
use crate::scene::validate::{in_closed, int_in};

/// Settings of the `"ism"` visibility mode (paper 004, imperfect shadow maps): every frame
/// `count` VALs are drawn by flux (the paper's importance-sampled VPLs), every VAL joins the
/// nearest drawn one, and each group gets a low-resolution paraboloid shadow map splatted from
/// its own random subset of points on the meshes, its holes filled by pull-push.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields, default)]
pub struct IsmSettings {
    /// Shadow maps (VALs drawn by flux) per frame, in 1..=[`MAX_ISMS`]; default 1024 (the
    /// paper's VPL count).
    pub count: u32,
    /// Side of each paraboloid map, texels: a power of two in 16..=512; default 128 (the
    /// paper's).
    pub resolution: u32,
    /// Points splatted into each map, in 16..=[`MAX_ISM_POINTS`]; default `null`: the paper's
    /// rule `P ≈ N_res · N_vpl / 4`, a quarter of a map's `π/4 · resolution²` texels per map.
    pub points: Option<u32>,
    /// Pull-push levels, in 0..=4 (0: no hole filling); default 2 (the paper's).
    pub pull_push_levels: u32,
    /// Depths differing by at most this fraction of the scene's bounding diagonal (times
    /// `2^level`) are averaged by the pull, in (0, 1]; default 0.05 (the paper's 5 %).
    pub pull_threshold: f32,
    /// A depth differing from the coarser level's by more than this fraction of the diagonal
    /// (times `2^level`) is replaced by the push, in (0, 1]; default 0.05.
    pub push_threshold: f32,
    /// Shadow filter: `"pcss"`, `"pcf"` (default) or `"hard"`.
    pub soft: SoftShadows,
    /// Slope-scaled depth bias of the lookup, texels, in [0, 16]: a splatted point lies
    /// anywhere in its texel, so a receiver's own surface seen at a grazing angle may lie
    /// nearer than its tangent plane along the texel's centre ray by this many texel angles
    /// times the tangent of the incidence; default 1.
    pub slope_bias: f32,
}

/// Most imperfect shadow maps per frame.
pub const MAX_ISMS: u32 = 4096;
/// Most points splatted into one imperfect shadow map.
pub const MAX_ISM_POINTS: u32 = 65536;
/// Most texels of all imperfect shadow maps together (the finest level, 128 MiB: wgpu's default
/// and lavapipe's largest storage buffer binding).
pub const MAX_ISM_TEXELS: u64 = 1 << 25;
/// Most points splatted per frame (all maps together).
pub const MAX_ISM_SPLATS: u64 = 1 << 27;

impl Default for IsmSettings {
    fn default() -> Self {
        Self {
            count: 1024,
            resolution: 128,
            points: None,
            pull_push_levels: 2,
            pull_threshold: 0.05,
            push_threshold: 0.05,
            soft: SoftShadows::Pcf,
            slope_bias: 1.0,
        }
    }
}

impl IsmSettings {
    /// Points splatted into each map: `points`, or the paper's rule.
    pub fn points_per_map(&self) -> u32 {
        self.points.unwrap_or_else(|| {
            let texels = std::f64::consts::FRAC_PI_4 * f64::from(self.resolution).powi(2);
            ((texels / 4.0).round() as u32).clamp(16, MAX_ISM_POINTS)
        })
    }

    /// Check every field and the bounds on memory and work, naming the first bad field under
    /// `field`.
    pub fn validate(&self, field: &str) -> Result<(), SceneError> {
        int_in(self.count, 1, MAX_ISMS, &format!("{field}.count"))?;
        let r = self.resolution;
        if !(16..=512).contains(&r) || !r.is_power_of_two() {
            return Err(SceneError::field(
                format!("{field}.resolution"),
                format!("must be a power of two in 16..=512, got {r}"),
            ));
        }
        if let Some(points) = self.points {
            int_in(points, 16, MAX_ISM_POINTS, &format!("{field}.points"))?;
        }
        int_in(self.pull_push_levels, 0, 4, &format!("{field}.pull_push_levels"))?;
        in_closed(self.slope_bias, 0.0, 16.0, &format!("{field}.slope_bias"))?;
        for (value, name) in [(self.pull_threshold, "pull_threshold"), (self.push_threshold, "push_threshold")] {
            if !(value > 0.0 && value <= 1.0) {
                return Err(SceneError::field(format!("{field}.{name}"), format!("must be in (0, 1], got {value}")));
            }
        }
        let texels = u64::from(self.count) * u64::from(r) * u64::from(r);
        if texels > MAX_ISM_TEXELS {
            return Err(SceneError::field(
                format!("{field}.resolution"),
                format!("{} maps of {r}x{r} texels are {texels} texels, over {MAX_ISM_TEXELS}", self.count),
            ));
        }
        let splats = u64::from(self.count) * u64::from(self.points_per_map());
        if splats > MAX_ISM_SPLATS {
            return Err(SceneError::field(
                format!("{field}.points"),
                format!(
                    "{} maps of {} points are {splats} points, over {MAX_ISM_SPLATS}",
                    self.count,
                    self.points_per_map()
                ),
            ));
        }
        Ok(())
    }
}

overrides! {
    /// Overrides of the `"ism"` visibility mode ([`IsmSettings`]).
    IsmTuning for IsmSettings {
        plain {
            /// Shadow maps per frame, in 1..=4096.
            count: u32,
            /// Side of each map, a power of two in 16..=512.
            resolution: u32,
            /// Pull-push levels, in 0..=4.
            pull_push_levels: u32,
            /// In (0, 1].
            pull_threshold: f32,
            /// In (0, 1].
            push_threshold: f32,
            soft: SoftShadows,
            /// Texels, in [0, 16].
            slope_bias: f32,
        }
        optional {
            /// Points splatted into each map, in 16..=65536; default the paper's rule.
            points: u32,
        }
    }
}

//! Indirect visibility: the modes (`settings.visibility`), the disc occluders' rule, and the
//! settings of the `"clusters"` and `"ism"` modes.

use serde::{Deserialize, Serialize};

use crate::scene::SceneError;
use crate::scene::validate::{in_closed, int_in};

/// Settings of the `"clusters"` visibility mode (papers 000 §4-5, 001): the frame's VALs
/// grouped by k-means, one paraboloid shadow map per cluster, soft shadows per sparse point and
/// cluster.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields, default)]
pub struct ClusterSettings {
    /// How VALs are grouped: `"kmeans"` (the only one so far).
    pub method: ClusterMethod,
    /// Clusters (shadow maps), in 1..=[`MAX_CLUSTERS`]; default 64.
    pub count: u32,
    /// Side of each cluster's shadow map, texels, in 16..=1024; default 128. All maps share
    /// one atlas of `ceil(sqrt(count))` maps per side, at most [`MAX_CLUSTER_ATLAS_SIDE`] texels.
    pub shadow_map_resolution: u32,
    /// Shadow filter: `"pcss"`, `"pcf"` or `"hard"` (default).
    pub soft: SoftShadows,
    /// Weight of the angle between normals (per radian) against the position distance in
    /// units of the scene's bounding diagonal, in [0, 100]; default 0.43 (paper 000's
    /// `w_a / w_x = 0.3 / 0.7`).
    pub normal_weight: f32,
    /// k-means iterations per frame, in 1..=[`MAX_KMEANS_ITERATIONS`], each started from the
    /// previous frame's centres; default 4.
    pub iterations: u32,
    /// Where the clusters' shadow maps come from: `"raster"` (default: every triangle
    /// rasterised into every map, exact depths) or `"ism"` (imperfect shadow maps splatted
    /// from points with pull-push, as `settings.ism` says for points, pull-push and bias;
    /// `shadow_map_resolution` must then be a power of two up to 512).
    pub shadow_maps: ShadowMapSource,
}

/// Where the `"clusters"` mode's shadow maps come from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum ShadowMapSource {
    /// Rasterised triangles: exact depth per texel.
    #[default]
    Raster,
    /// Imperfect shadow maps (paper 004).
    Ism,
}

/// Most clusters of the `"clusters"` visibility mode.
pub const MAX_CLUSTERS: u32 = 256;
/// Most k-means iterations per frame.
pub const MAX_KMEANS_ITERATIONS: u32 = 32;
/// Widest shadow-map atlas of the `"clusters"` mode (texels per side: 64 MiB of depth).
pub const MAX_CLUSTER_ATLAS_SIDE: u32 = 4096;

impl Default for ClusterSettings {
    fn default() -> Self {
        Self {
            method: ClusterMethod::Kmeans,
            count: 64,
            shadow_map_resolution: 128,
            // Measured closer to exact than PCSS on every fixture (docs/measurements/clustered-visibility.md).
            soft: SoftShadows::Hard,
            normal_weight: 0.43,
            iterations: 4,
            shadow_maps: ShadowMapSource::Raster,
        }
    }
}

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

impl ClusterSettings {
    /// Shadow maps per atlas side.
    pub fn atlas_columns(&self) -> u32 {
        (self.count as f64).sqrt().ceil() as u32
    }

    /// Check every field and the bounds on memory, naming the first bad field under `field`.
    pub fn validate(&self, field: &str) -> Result<(), SceneError> {
        int_in(self.count, 1, MAX_CLUSTERS, &format!("{field}.count"))?;
        int_in(self.shadow_map_resolution, 16, 1024, &format!("{field}.shadow_map_resolution"))?;
        in_closed(self.normal_weight, 0.0, 100.0, &format!("{field}.normal_weight"))?;
        int_in(self.iterations, 1, MAX_KMEANS_ITERATIONS, &format!("{field}.iterations"))?;
        if self.shadow_maps == ShadowMapSource::Ism {
            let r = self.shadow_map_resolution;
            let texels = u64::from(self.count) * u64::from(r) * u64::from(r);
            if !r.is_power_of_two() || r > 512 || texels > MAX_ISM_TEXELS {
                return Err(SceneError::field(
                    format!("{field}.shadow_map_resolution"),
                    format!(
                        "imperfect shadow maps need a power of two up to 512 and at most {MAX_ISM_TEXELS} texels in all, got {} maps of {r}",
                        self.count
                    ),
                ));
            }
        }
        let side = self.atlas_columns() * self.shadow_map_resolution;
        if side > MAX_CLUSTER_ATLAS_SIDE {
            return Err(SceneError::field(
                format!("{field}.shadow_map_resolution"),
                format!(
                    "{} maps of {} texels need an atlas of {side} texels per side, over {MAX_CLUSTER_ATLAS_SIDE}",
                    self.count, self.shadow_map_resolution
                ),
            ));
        }
        Ok(())
    }
}

/// How the `"clusters"` mode groups VALs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum ClusterMethod {
    /// k-means on position and normal angle (paper 000 §5.1).
    #[default]
    Kmeans,
}

/// How a cluster's shadow is filtered.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum SoftShadows {
    /// Percentage-closer soft shadows: blocker search, penumbra from the cluster's radius and
    /// the mean blocker distance, PCF of that width (paper 001).
    Pcss,
    /// PCF of a fixed width (1.5 texels).
    Pcf,
    /// One texel (the clusters' default).
    #[default]
    Hard,
}

/// Indirect occlusion mode.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum Occlusion {
    #[default]
    Off,
    Disks,
    /// Shadow maps of clusters of VALs ([`ClusterSettings`]).
    Clusters,
    /// Imperfect shadow maps of VALs drawn by flux ([`IsmSettings`]).
    Ism,
}

/// Indirect occlusion as a scene file asks for it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum OcclusionSetting {
    /// Disks when the scene can occlude itself, else off.
    #[default]
    Auto,
    Off,
    Disks,
    Clusters,
    Ism,
}

/// Combination rule of disc occluders.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum OcclusionRule {
    /// `clamp(sum o_i, 0, 1)`: the paper's; double-counts overlapping occluders.
    Sum,
    /// `1 - prod(1 - o_i)`: closer to exact visibility on both measured fixtures (docs/measurements/disc-occlusion.md).
    #[default]
    Product,
}

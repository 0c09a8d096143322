//! Settings of the `"clusters"` visibility mode and their overrides in `settings.tuning.clusters`
//! (data: the bottom layer, held by the scene description).

use serde::{Deserialize, Serialize};

use crate::gpu::visibility::ism::settings::MAX_ISM_TEXELS;
use crate::gpu::visibility::settings::SoftShadows;
use crate::scene::SceneError;
use crate::scene::settings::overrides;
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
    /// Unused with `shadow_maps: "rays"`.
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
    /// `shadow_map_resolution` must then be a power of two up to 512) or `"rays"` (no maps:
    /// shadow rays through the scene's BVH from each sparse point to `rays` of the cluster's
    /// VALs).
    pub shadow_maps: ShadowMapSource,
    /// With `shadow_maps: "rays"`: shadow rays per (sparse point, cluster), in
    /// 1..=[`MAX_CLUSTER_RAYS`]; default [`DEFAULT_CLUSTER_RAYS`].
    pub rays: u32,
    /// The rasterised maps draw the meshes simplified (meshoptimizer's edge collapses, borders
    /// kept) to a surface within this fraction of the scene's extent of the full one, in
    /// [0, [`MAX_PROXY_ERROR`]]; 0 draws every triangle. Default [`DEFAULT_PROXY_ERROR`].
    pub proxy_error: f32,
}

/// Default of [`ClusterSettings::proxy_error`].
pub const DEFAULT_PROXY_ERROR: f32 = 0.001;
/// Largest [`ClusterSettings::proxy_error`]: a twentieth of the scene.
pub const MAX_PROXY_ERROR: f32 = 0.05;

/// Where the `"clusters"` mode's shadow maps come from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum ShadowMapSource {
    /// Rasterised triangles: exact depth per texel.
    #[default]
    Raster,
    /// Imperfect shadow maps (paper 004).
    Ism,
    /// No maps: shadow rays through the scene's BVH to some of the cluster's VALs, their
    /// outcomes weighted by the VALs' unoccluded light (`rays.wgsl`).
    Rays,
}

/// Default of [`ClusterSettings::rays`].
pub const DEFAULT_CLUSTER_RAYS: u32 = 4;
/// Most shadow rays per (sparse point, cluster).
pub const MAX_CLUSTER_RAYS: u32 = 64;

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
            rays: DEFAULT_CLUSTER_RAYS,
            proxy_error: DEFAULT_PROXY_ERROR,
        }
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
        in_closed(self.proxy_error, 0.0, MAX_PROXY_ERROR, &format!("{field}.proxy_error"))?;
        int_in(self.rays, 1, MAX_CLUSTER_RAYS, &format!("{field}.rays"))?;
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

overrides! {
    /// Overrides of the `"clusters"` visibility mode ([`ClusterSettings`]).
    ClusterTuning for ClusterSettings {
        plain {
            method: ClusterMethod,
            /// Clusters (shadow maps), in 1..=256.
            count: u32,
            /// Side of each cluster's shadow map, texels, in 16..=1024.
            shadow_map_resolution: u32,
            soft: SoftShadows,
            /// In [0, 100].
            normal_weight: f32,
            /// k-means iterations per frame, in 1..=32.
            iterations: u32,
            shadow_maps: ShadowMapSource,
            /// Shadow rays per (sparse point, cluster) with `shadow_maps: "rays"`, in 1..=64.
            rays: u32,
            /// In [0, 0.05]; 0 draws every triangle.
            proxy_error: f32,
        }
        optional {}
    }
}

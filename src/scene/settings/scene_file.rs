//! The scene file's `settings` object.

use serde::{Deserialize, Serialize};

use super::{
    ClusterSettings, DEFAULT_BOUNCES, DirectSettings, EnvironmentSettings, IsmSettings, MrSettings, Occlusion,
    OcclusionRule, OcclusionSetting, RgbdSettings, SecondBounceSettings, SparseShading,
};
use crate::scene::description::RSM_RESOLUTION_RANGE;
use crate::scene::validate::{int_in, positive};
use crate::scene::{DEFAULT_NEIGHBOURS, MAX_NEIGHBOURS, SceneError, Settings};

/// Render settings; every field has a default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SettingsDescription {
    /// RSM side, texels, in 8..=2048; default 128.
    #[serde(default = "default_rsm_resolution")]
    pub rsm_resolution: u32,
    /// Allow the glossy gather; default true.
    #[serde(default = "default_glossy")]
    pub glossy: bool,
    /// Seed for sparse point placement; default 1.
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// Exposure multiplier (> 0) before tone mapping; default `null` (automatic).
    #[serde(default)]
    pub exposure: Option<f32>,
    /// Sparse points each vertex interpolates from (paper eqs. 12-13), 1..=16; default 8.
    #[serde(default = "default_neighbours")]
    pub interpolation_neighbours: u32,
    /// Indirect visibility: `"auto"` (default), `"off"`, `"disks"` (docs/design.md §4 step 3),
    /// `"clusters"` (shadow maps of k-means clusters of the VALs, `clusters` below) or `"ism"`
    /// (imperfect shadow maps of VALs drawn by flux, `ism` below). `"auto"`
    /// is `"disks"` when the scene can occlude itself: more than one mesh, or a mesh that is
    /// neither a convex object nor a convex room ([`crate::scene::Scene`]). The JSON key is
    /// `visibility`; `occlusion` is its deprecated alias (accepted, not both at once).
    #[serde(default, rename = "visibility", alias = "occlusion")]
    pub occlusion: OcclusionSetting,
    /// How disc occluders combine: `"product"` (default: measured closer to exact) or `"sum"`
    /// (the paper's).
    #[serde(default)]
    pub occlusion_rule: OcclusionRule,
    /// How RGB-D frames become VALs (replay and streams); every field has a default.
    #[serde(default)]
    pub rgbd: RgbdSettings,
    /// Mixed-reality compositing (replay and streams): differential rendering onto the real
    /// surfaces; every field has a default.
    #[serde(default)]
    pub mr: MrSettings,
    /// Light from the directions no VAL covers (replay and streams): `source` `"none"`
    /// (default), `"auto"` or `"map"`; `auto`'s `distribution` `"uniform"` or `"overcast"`
    /// (`mr::environment`).
    #[serde(default)]
    pub environment: EnvironmentSettings,
    /// The sparse method's interpolation, light bound and subdivision; every field has a
    /// default.
    #[serde(default)]
    pub sparse: SparseShading,
    /// The `"clusters"` visibility mode; every field has a default.
    #[serde(default)]
    pub clusters: ClusterSettings,
    /// The `"ism"` visibility mode (imperfect shadow maps); every field has a default.
    #[serde(default)]
    pub ism: IsmSettings,
    /// Direct light from the scene's `lights`: how their shadows are computed and the limit
    /// on their count; every field has a default.
    #[serde(default)]
    pub direct: DirectSettings,
    /// Bounces of indirect light, 1 or 2; default 1. With 2, points on the meshes lit by the
    /// first bounce's VALs become second-bounce VALs (paper 004 §4.1, `second_bounce`).
    #[serde(default = "default_bounces")]
    pub bounces: u32,
    /// The second bounce's points and VAL budget (used when `bounces` is 2); every field has a
    /// default.
    #[serde(default)]
    pub second_bounce: SecondBounceSettings,
}

fn default_neighbours() -> u32 {
    DEFAULT_NEIGHBOURS
}

fn default_rsm_resolution() -> u32 {
    128
}

fn default_glossy() -> bool {
    true
}

fn default_bounces() -> u32 {
    DEFAULT_BOUNCES
}

fn default_seed() -> u64 {
    1
}

impl Default for SettingsDescription {
    fn default() -> Self {
        SettingsDescription {
            rsm_resolution: default_rsm_resolution(),
            glossy: default_glossy(),
            seed: default_seed(),
            exposure: None,
            interpolation_neighbours: default_neighbours(),
            occlusion: OcclusionSetting::Auto,
            occlusion_rule: OcclusionRule::Product,
            rgbd: RgbdSettings::default(),
            mr: MrSettings::default(),
            environment: EnvironmentSettings::default(),
            sparse: SparseShading::default(),
            clusters: ClusterSettings::default(),
            ism: IsmSettings::default(),
            direct: DirectSettings::default(),
            bounces: default_bounces(),
            second_bounce: SecondBounceSettings::default(),
        }
    }
}

impl SettingsDescription {
    /// The settings (assumes [`SceneDescription::validate`] passed); `self_occluding` resolves
    /// `"auto"` occlusion.
    pub fn to_settings(&self, self_occluding: bool) -> Settings {
        Settings {
            rsm_resolution: self.rsm_resolution,
            glossy: self.glossy,
            seed: self.seed,
            exposure: self.exposure,
            interpolation_neighbours: self.interpolation_neighbours,
            occlusion: match self.occlusion {
                OcclusionSetting::Off => Occlusion::Off,
                OcclusionSetting::Disks => Occlusion::Disks,
                OcclusionSetting::Clusters => Occlusion::Clusters,
                OcclusionSetting::Ism => Occlusion::Ism,
                OcclusionSetting::Auto if self_occluding => Occlusion::Disks,
                OcclusionSetting::Auto => Occlusion::Off,
            },
            occlusion_rule: self.occlusion_rule,
            rgbd: self.rgbd,
            mr: self.mr,
            sparse: self.sparse,
            clusters: self.clusters,
            ism: self.ism,
            direct: self.direct,
            bounces: self.bounces,
            second_bounce: self.second_bounce,
        }
    }

    pub(crate) fn validate(&self, field: &str) -> Result<(), SceneError> {
        let (lo, hi) = RSM_RESOLUTION_RANGE;
        int_in(self.rsm_resolution, lo, hi, &format!("{field}.rsm_resolution"))?;
        int_in(self.interpolation_neighbours, 1, MAX_NEIGHBOURS, &format!("{field}.interpolation_neighbours"))?;
        if let Some(exposure) = self.exposure {
            positive(exposure, &format!("{field}.exposure"))?;
        }
        self.sparse.validate(&format!("{field}.sparse"))?;
        self.rgbd.validate(&format!("{field}.rgbd"))?;
        self.mr.validate(&format!("{field}.mr"))?;
        self.environment.validate(&format!("{field}.environment"))?;
        self.clusters.validate(&format!("{field}.clusters"))?;
        self.ism.validate(&format!("{field}.ism"))?;
        self.direct.validate(&format!("{field}.direct"))?;
        int_in(self.bounces, 1, 2, &format!("{field}.bounces"))?;
        self.second_bounce.validate(&format!("{field}.second_bounce"))
    }
}

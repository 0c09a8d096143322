//! Every setting of a scene file's `settings`, with its default, its range and its one
//! validation. The structs live here, at the bottom of the crate, so the scene description can
//! hold them without reaching up into the modules that use them (`mr`, `rgbd`, `gpu`): those
//! import them from here.

mod bounce;
mod direct;
mod environment;
mod mr;
mod quality;
mod rgbd;
mod scene_file;
mod sparse;
#[cfg(test)]
mod tests;
mod tuning;

pub use bounce::{DEFAULT_BOUNCES, MAX_SECOND_BOUNCE_POINTS, MAX_SECOND_BOUNCE_VALS, SecondBounceSettings};
pub use direct::{DirectSettings, DirectShadows, MAX_DIRECT_LIGHTS, MAX_LIGHTS_VAL_BUDGET, POINT_VIEWS, SPOT_VIEWS};
pub use environment::{EnvironmentDistribution, EnvironmentSettings, EnvironmentSource, MAX_ENVIRONMENT_ROWS};
pub use mr::{DifferentialDevice, DifferentialMethod, MAX_RECEIVER_MARGIN, MrSettings};
pub use quality::{
    BUDGET_RANGE_MS, Choice, DEFAULT_ESTIMATOR_DRAWS, MAX_ESTIMATOR_DRAWS, MAX_MEASURED_CHARS, MeasuredLevel,
    MeasuredLevels, Quality, ResolvedConfig, SceneAnalysis, Technique, resolve, technique, validate_budget_ms,
};
pub use rgbd::RgbdSettings;
pub use scene_file::{SettingsDescription, validate_exposure};
pub use sparse::{
    ADAPTIVE_CANDIDATES, ADAPTIVE_RANGE, DEFAULT_ADAPTIVE, DEFAULT_NEAR_FIELD, DEFAULT_POINTS, DEFAULT_SUBDIVISION,
    GlossyInterpolation, InterpolationKernel, LightBound, NEAR_FIELD_INTERLEAVE_SIDES, NEAR_FIELD_RANGE, POINTS_RANGE,
    SUBDIVISION_RANGE, SparseShading,
};
pub use tuning::{DirectTuning, SecondBounceTuning, SparseTuning, Tuning};
pub(crate) use tuning::{SetField, json_value, overrides};

// The visibility modes' settings live in their folders under `gpu/visibility/` (data files
// there, with the registry of modes): re-exported here beside the others.
pub use crate::gpu::visibility::clusters::settings::{
    ClusterMethod, ClusterSettings, ClusterTuning, MAX_CLUSTER_ATLAS_SIDE, MAX_CLUSTER_RAYS, MAX_CLUSTERS,
    MAX_KMEANS_ITERATIONS, ShadowMapSource,
};
pub use crate::gpu::visibility::ism::settings::{
    IsmSettings, IsmTuning, MAX_ISM_POINTS, MAX_ISM_SPLATS, MAX_ISM_TEXELS, MAX_ISMS,
};
pub use crate::gpu::visibility::settings::{
    Occlusion, OcclusionRule, OcclusionSetting, SoftShadows, VisibilitySettings,
};

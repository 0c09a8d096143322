//! Stage names, as reported in timings: each is the name its technique records.

use crate::gpu::lights::{rgbd::RgbdVals, spot};
use crate::gpu::raster::CameraView;
use crate::gpu::{references, sparse, visibility};

pub const RSM_RASTER: &str = spot::RSM_RASTER;
pub const RSM_VALS: &str = spot::RSM_VALS;
/// The RSMs of the scene's `lights` (only with `lights`).
pub const LIGHTS_RSM_RASTER: &str = crate::gpu::lights::light_rsms::RASTER_STAGE;
pub const LIGHTS_RSM_VALS: &str = crate::gpu::lights::light_rsms::VALS_STAGE;
pub const RGBD_VALS: &str = RgbdVals::STAGE;
/// The second bounce's stages (`settings.bounces: 2`).
pub const BOUNCE2_POINTS: &str = crate::gpu::lights::bounce::POINTS_STAGE;
pub const BOUNCE2_VALS: &str = crate::gpu::lights::bounce::DRAW_STAGE;
/// The disks' occlusion of the bounce points (the sparse method with `disks` only).
pub const BOUNCE2_OCCLUSION: &str = crate::gpu::lights::bounce::OCCLUSION_STAGE;
/// The lookup of the first bounce's groups at the bounce points (`visibility` `clusters` or
/// `ism`, sparse method), after that instance's grouping and maps (`bounce::STAGES`).
pub const BOUNCE2_VISIBILITY: &str = crate::gpu::lights::bounce::VISIBILITY_STAGE;
pub const VISIBILITY: &str = CameraView::STAGE;
pub const GATHER: &str = sparse::gather::PASS.label;
pub const OCCLUSION: &str = visibility::disks::PASS.label;
/// The `Clusters` visibility mode's stages.
pub const CLUSTERING: &str = visibility::clusters::CLUSTERING_STAGE;
pub const CLUSTER_SHADOW_MAPS: &str = visibility::clusters::SHADOW_MAPS_STAGE;
pub const CLUSTER_VISIBILITY: &str = visibility::clusters::VISIBILITY.label;
/// The `Ism` visibility mode's stages.
pub const ISM_SAMPLING: &str = visibility::ism::SAMPLING_STAGE;
pub const ISM_SPLAT: &str = visibility::ism::SPLAT_STAGE;
pub const ISM_PULL_PUSH: &str = visibility::ism::PULL_PUSH_STAGE;
pub const ISM_VISIBILITY: &str = visibility::ism::VISIBILITY.label;
pub const RENORMALISE: &str = sparse::renormalise::PASS.label;
pub const INTERPOLATE: &str = sparse::interpolate::PASS.label;
pub const SHADE: &str = sparse::shade::PASS.label;
pub const BRUTE_FORCE: &str = references::brute_force::PASS.label;
/// `brute_force_ism`'s lookup at the pixels (after its groups and maps).
pub const BRUTE_FORCE_ISM_VISIBILITY: &str = references::brute_force::ISM_VISIBILITY_STAGE;
pub const EXACT: &str = references::exact::PASS.label;
pub const DIRECT: &str = spot::DIRECT;

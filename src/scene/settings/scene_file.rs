//! The scene file's `settings` object, in two layers: at the top what the user wants (a
//! `quality` level, a frame-time budget, bounces, glossy, exposure, seed, and the RGB-D, mixed
//! reality and environment inputs), and under `tuning` the research knobs that override what
//! the level chose.

use serde::{Deserialize, Deserializer, Serialize};

use super::quality::{MeasuredLevels, Quality, SceneAnalysis, resolve};
use super::tuning::Tuning;
use super::{DEFAULT_BOUNCES, EnvironmentSettings, MrSettings, RgbdSettings};
use crate::scene::description::RSM_RESOLUTION_RANGE;
use crate::scene::validate::{int_in, positive};
use crate::scene::{MAX_NEIGHBOURS, SceneError, Settings};

/// A key that moved from `settings` to `settings.tuning`: present in a scene file, it is an
/// error that says where it went. Never constructed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Moved {}

/// One function per moved key, for `deserialize_with`: the error's field path is the key's
/// (`settings.rsm_resolution`), its message where the key went.
macro_rules! moved_keys {
    ($($key:ident => $to:literal,)*) => {
        mod moved {
            use super::{Deserializer, Moved};
            $(pub(super) fn $key<'de, D: Deserializer<'de>>(_: D) -> Result<Option<Moved>, D::Error> {
                Err(serde::de::Error::custom(concat!("moved to settings.tuning.", $to)))
            })*
        }
    };
}

moved_keys! {
    rsm_resolution => "rsm_resolution",
    interpolation_neighbours => "interpolation_neighbours",
    visibility => "visibility",
    occlusion => "visibility",
    occlusion_rule => "occlusion_rule",
    sparse => "sparse",
    clusters => "clusters",
    ism => "ism",
    direct => "direct",
    second_bounce => "second_bounce",
}

/// Render settings; every field has a default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SettingsDescription {
    /// What the frames should favour: `"fast"`, `"balanced"` (default: the parameters every
    /// measured figure used), `"accurate"` or `"reference"` (accurate's parameters, rendered
    /// with the exact reference method where a command can). The level picks the sparse
    /// method's parameters for this scene (see the scene's resolved configuration for what and
    /// why); `tuning` overrides any of them.
    #[serde(default)]
    pub quality: Quality,
    /// Frame-time budget, ms, in [0.1, 600000]; default none. Streams and `relume replay`
    /// adapt their parameters frame by frame to hold it (`renderer::budget`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub budget_ms: Option<f32>,
    /// Bounces of indirect light, 1 or 2; default 1. With 2, points on the meshes lit by the
    /// first bounce's VALs become second-bounce VALs (paper 004 §4.1, `tuning.second_bounce`).
    #[serde(default = "default_bounces")]
    pub bounces: u32,
    /// Allow the glossy gather; default true.
    #[serde(default = "default_glossy")]
    pub glossy: bool,
    /// Exposure multiplier (> 0) before tone mapping; default `null` (automatic).
    #[serde(default)]
    pub exposure: Option<f32>,
    /// Seed for sparse point placement; default 1.
    #[serde(default = "default_seed")]
    pub seed: u64,
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
    /// Research knobs; each optional, each overriding the level's choice.
    #[serde(default, skip_serializing_if = "is_default")]
    pub tuning: Tuning,
    /// Per level (`fast`, `balanced`, `accurate`), parameters measured on this scene to beat
    /// the level's rule, each with what was measured (`relume bench --levels --candidates`
    /// suggests them); `tuning` still wins over them.
    #[serde(default, skip_serializing_if = "MeasuredLevels::is_empty")]
    pub levels: MeasuredLevels,
    #[serde(default, deserialize_with = "moved::rsm_resolution", skip_serializing)]
    #[schema(ignore)]
    rsm_resolution: Option<Moved>,
    #[serde(default, deserialize_with = "moved::interpolation_neighbours", skip_serializing)]
    #[schema(ignore)]
    interpolation_neighbours: Option<Moved>,
    #[serde(default, deserialize_with = "moved::visibility", skip_serializing)]
    #[schema(ignore)]
    visibility: Option<Moved>,
    #[serde(default, deserialize_with = "moved::occlusion", skip_serializing)]
    #[schema(ignore)]
    occlusion: Option<Moved>,
    #[serde(default, deserialize_with = "moved::occlusion_rule", skip_serializing)]
    #[schema(ignore)]
    occlusion_rule: Option<Moved>,
    #[serde(default, deserialize_with = "moved::sparse", skip_serializing)]
    #[schema(ignore)]
    sparse: Option<Moved>,
    #[serde(default, deserialize_with = "moved::clusters", skip_serializing)]
    #[schema(ignore)]
    clusters: Option<Moved>,
    #[serde(default, deserialize_with = "moved::ism", skip_serializing)]
    #[schema(ignore)]
    ism: Option<Moved>,
    #[serde(default, deserialize_with = "moved::direct", skip_serializing)]
    #[schema(ignore)]
    direct: Option<Moved>,
    #[serde(default, deserialize_with = "moved::second_bounce", skip_serializing)]
    #[schema(ignore)]
    second_bounce: Option<Moved>,
}

fn is_default(tuning: &Tuning) -> bool {
    *tuning == Tuning::default()
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
            quality: Quality::Balanced,
            budget_ms: None,
            bounces: default_bounces(),
            glossy: default_glossy(),
            exposure: None,
            seed: default_seed(),
            rgbd: RgbdSettings::default(),
            mr: MrSettings::default(),
            environment: EnvironmentSettings::default(),
            tuning: Tuning::default(),
            levels: MeasuredLevels::default(),
            rsm_resolution: None,
            interpolation_neighbours: None,
            visibility: None,
            occlusion: None,
            occlusion_rule: None,
            sparse: None,
            clusters: None,
            ism: None,
            direct: None,
            second_bounce: None,
        }
    }
}

/// Checks an exposure multiplier (> 0 and finite): the scene file's `settings.exposure` and a
/// render's or a stream's `quality.exposure` alike.
pub fn validate_exposure(exposure: f32, field: &str) -> Result<(), SceneError> {
    positive(exposure, field)
}

impl SettingsDescription {
    /// The settings before the scene is loaded: the level's and the tuning's parameters, with
    /// the choices that need the loaded scene (visibility) made as for a scene that cannot
    /// occlude itself. What the loader and the admission read (subdivision, neighbours,
    /// adaptive points, the VALs per frame) is final here: [`resolve`] decides it from the level
    /// and the tuning alone.
    pub fn before_load(&self) -> Settings {
        resolve(self.quality, &SceneAnalysis::default(), self).0
    }

    /// Checks every value's range, naming the field of the first problem; a tuning value is
    /// checked as resolved over the level, under `{field}.tuning`. Each settings struct's one
    /// validation does the checking.
    pub(crate) fn validate(&self, field: &str) -> Result<(), SceneError> {
        if let Some(ms) = self.budget_ms {
            super::quality::validate_budget_ms(ms, &format!("{field}.budget_ms"))?;
        }
        int_in(self.bounces, 1, 2, &format!("{field}.bounces"))?;
        if let Some(exposure) = self.exposure {
            validate_exposure(exposure, &format!("{field}.exposure"))?;
        }
        self.rgbd.validate(&format!("{field}.rgbd"))?;
        self.mr.validate(&format!("{field}.mr"))?;
        self.environment.validate(&format!("{field}.environment"))?;
        self.levels.validate(&format!("{field}.levels"))?;
        let tuning = format!("{field}.tuning");
        let s = self.before_load();
        let (lo, hi) = RSM_RESOLUTION_RANGE;
        int_in(s.rsm_resolution, lo, hi, &format!("{tuning}.rsm_resolution"))?;
        int_in(s.interpolation_neighbours, 1, MAX_NEIGHBOURS, &format!("{tuning}.interpolation_neighbours"))?;
        s.sparse.validate(&format!("{tuning}.sparse"))?;
        s.visibility.validate(&tuning)?;
        s.direct.validate(&format!("{tuning}.direct"))?;
        s.second_bounce.validate(&format!("{tuning}.second_bounce"))
    }
}

//! Quality levels: what the user asks for (`settings.quality`) turned into the parameters of the
//! sparse method for one scene, each with the reason it was chosen.
//!
//! [`resolve`] is a pure function of the level, the [`SceneAnalysis`] of the loaded scene and
//! the scene file's settings (their `tuning` overrides). The parameters the loader needs
//! (subdivision, interpolation neighbours, adaptive candidates, the sparse points placed) and those the service admits a
//! scene by (its VALs per frame) depend on the level and the tuning only, never on the
//! analysis, so they are known before the meshes are read.
//!
//! The levels, from the measurements (docs/measurements/):
//!
//! | parameter | fast | balanced | accurate, reference |
//! |---|---|---|---|
//! | `rsm_resolution` | 64 | 128 | 128 |
//! | `interpolation_neighbours` | 8 | 8 | 8 |
//! | visibility, scene that can occlude itself | disks | disks | clusters (ism when lit by RGB-D frames only) |
//! | visibility, scene that cannot | off | off | off |
//! | `sparse.subdivision` | 4 | 2 | 2 |
//! | `sparse.near_field` | 0 | 0 | 4 |
//! | `sparse.adaptive` | 0 | 0 | 0 |
//! | `sparse.points` (of each mesh's `sparse_points`) | 0.5 | 1 | 1 |
//!
//! `balanced` is the defaults every figure was measured with. `reference` takes accurate's
//! parameters and asks for the exact reference method ([`Technique::Exact`]).

use serde::{Deserialize, Serialize};

use super::tuning::{SetField, json_value};
use super::{
    DEFAULT_NEAR_FIELD, DEFAULT_SUBDIVISION, DifferentialMethod, Occlusion, OcclusionRule, OcclusionSetting,
    SettingsDescription, SparseShading, SparseTuning, Tuning,
};
use crate::scene::{DEFAULT_NEIGHBOURS, Settings};

/// What the user wants of a scene's frames (`settings.quality`).
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize, utoipa::ToSchema, clap::ValueEnum,
)]
#[serde(rename_all = "snake_case")]
#[schema(as = QualityLevel)]
pub enum Quality {
    /// Cheaper parameters: fewer VALs from the spot light, coarser subdivision.
    Fast,
    /// The defaults every measured figure used.
    #[default]
    Balanced,
    /// Parameters measured closer to the exact reference, at a higher cost: the near field, and
    /// clustered shadow maps on scenes that can occlude themselves (imperfect shadow maps on
    /// scenes lit by RGB-D frames only).
    Accurate,
    /// Accurate's parameters, rendered with the exact reference method (a shadow ray per pixel
    /// and VAL) where a command can.
    Reference,
}

/// Bounds of a frame-time budget (`budget_ms` of a scene file, a render request, a stream),
/// ms: from a tenth of a millisecond to ten minutes.
pub const BUDGET_RANGE_MS: (f32, f32) = (0.1, 600_000.0);

/// The one check of a frame-time budget wherever it is given; errors name `field`.
pub fn validate_budget_ms(ms: f32, field: &str) -> Result<(), crate::scene::SceneError> {
    crate::scene::validate::in_closed(ms, BUDGET_RANGE_MS.0, BUDGET_RANGE_MS.1, field)
}

impl Quality {
    /// Every level, cheapest first.
    pub const ALL: [Quality; 4] = [Quality::Fast, Quality::Balanced, Quality::Accurate, Quality::Reference];

    /// The level's name, as in a scene file.
    pub fn name(self) -> &'static str {
        match self {
            Quality::Fast => "fast",
            Quality::Balanced => "balanced",
            Quality::Accurate => "accurate",
            Quality::Reference => "reference",
        }
    }

    /// The indirect error the level aims at: rel RMSE against the converged exact reference,
    /// at 256 pixels wide (fast 0.20, balanced 0.10, accurate 0.05; none for the reference
    /// itself). `relume bench --levels --candidates` suggests, for a level that misses it on a
    /// scene, the fastest measured configuration that meets it within the level's
    /// [`Self::time_share_of_accurate`] (docs/measurements/levels.md).
    pub fn target_rel_rmse(self) -> Option<f64> {
        match self {
            Quality::Fast => Some(0.20),
            Quality::Balanced => Some(0.10),
            Quality::Accurate => Some(0.05),
            Quality::Reference => None,
        }
    }

    /// The level's second target, for `balanced` (the default, what a user gets without
    /// choosing): rel RMSE without the frame's worst 1 % of pixels at most 0.07, so that the
    /// level is close to the reference over most of the image, not only on the whole-image
    /// figure that a few bright pixels can dominate (none for the other levels). The levels
    /// bench holds a level and its suggestion to both ([`Self::meets_targets`]).
    pub fn target_without_worst_1pct(self) -> Option<f64> {
        match self {
            Quality::Balanced => Some(0.07),
            Quality::Fast | Quality::Accurate | Quality::Reference => None,
        }
    }

    /// Whether a frame `rel_rmse` from the exact reference, `without_worst_1pct` without its
    /// worst 1 % of pixels, meets both of the level's targets (true at `reference`).
    pub fn meets_targets(self, rel_rmse: f64, without_worst_1pct: f64) -> bool {
        self.target_rel_rmse().is_none_or(|t| rel_rmse <= t)
            && self.target_without_worst_1pct().is_none_or(|t| without_worst_1pct <= t)
    }

    /// The most of `accurate`'s frame time the level may take on a scene: fast a quarter,
    /// balanced no more than accurate (none for accurate and the reference). A configuration
    /// that meets the level's targets ([`Self::meets_targets`]) only slower than this is not the
    /// level.
    pub fn time_share_of_accurate(self) -> Option<f64> {
        match self {
            Quality::Fast => Some(0.25),
            Quality::Balanced => Some(1.0),
            Quality::Accurate | Quality::Reference => None,
        }
    }
}

/// How the indirect light of a resolved scene is asked to be computed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum Technique {
    /// The sparse model-space method (docs/design.md §4).
    #[default]
    Sparse,
    /// The exact reference: brute force with a shadow ray per pixel and VAL (docs/design.md §5).
    Exact,
    /// The exact reference estimated on the GPU: per pixel, `draws` VALs drawn by their
    /// unoccluded light, a shadow ray each (docs/design.md §5). Only where a scene's measured
    /// level names it (`settings.levels`).
    Estimator,
    /// Every VAL at every pixel, each weighted by its cluster's shadow-map lookup at the pixel
    /// (the clusters' visibility where the light lands, as the clustered-visibility paper
    /// shades; `gpu::references::brute_force`): the level's RSM and clusters settings, no
    /// sparse points. Only where a scene's measured level names it (`settings.levels`).
    BruteForceClusters,
}

/// Draws per pixel of [`Technique::Estimator`] at most, and unless a measured level says.
pub const MAX_ESTIMATOR_DRAWS: u32 = 256;
pub const DEFAULT_ESTIMATOR_DRAWS: u32 = 32;

/// The technique `quality` asks for on a scene with `settings`, and the estimator's draws
/// when it is the estimator: the exact reference at `reference`, else what the level's
/// measured parameters name, else the sparse method.
pub fn technique(quality: Quality, settings: &SettingsDescription) -> (Technique, Option<u32>) {
    if quality == Quality::Reference {
        return (Technique::Exact, None);
    }
    match settings.levels.get(quality) {
        Some(m) if m.technique == Some(Technique::Estimator) => {
            (Technique::Estimator, Some(m.draws.unwrap_or(DEFAULT_ESTIMATOR_DRAWS)))
        }
        Some(m) if m.technique == Some(Technique::BruteForceClusters) => (Technique::BruteForceClusters, None),
        Some(m) if m.technique == Some(Technique::Exact) => (Technique::Exact, None),
        _ => (Technique::Sparse, None),
    }
}

/// One parameter of the resolved configuration: its value and why it has it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Choice {
    /// The parameter, as a path under `settings` (`tuning.rsm_resolution` when the scene file
    /// set it), or a name (`method`, `glossy gather`).
    pub parameter: String,
    /// Its value, as JSON text.
    pub value: String,
    pub reason: String,
}

impl std::fmt::Display for Choice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} = {}: {}", self.parameter, self.value, self.reason)
    }
}

/// Characters at most in a measured level's `measured` text.
pub const MAX_MEASURED_CHARS: usize = 1000;

/// `settings.levels`: per level, parameters measured on this scene to beat what the level's
/// rule chooses (`relume bench --levels --candidates` writes them as `suggested_levels`, from
/// the configurations it measured both more accurate and faster). They apply to that level
/// only, below `tuning` (which still wins), and their reason in the resolved configuration is
/// the `measured` text. `reference` takes none: its VALs stay the finest.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct MeasuredLevels {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fast: Option<MeasuredLevel>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub balanced: Option<MeasuredLevel>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accurate: Option<MeasuredLevel>,
}

impl MeasuredLevels {
    /// The measured parameters of `quality` (none for `reference`).
    pub fn get(&self, quality: Quality) -> Option<&MeasuredLevel> {
        match quality {
            Quality::Fast => self.fast.as_ref(),
            Quality::Balanced => self.balanced.as_ref(),
            Quality::Accurate => self.accurate.as_ref(),
            Quality::Reference => None,
        }
    }

    pub fn is_empty(&self) -> bool {
        *self == Self::default()
    }

    /// Checks each level's values as `tuning` would (the same ranges) and its text, naming
    /// `{field}.{level}.{parameter}`.
    pub(crate) fn validate(&self, field: &str) -> Result<(), crate::scene::SceneError> {
        for quality in [Quality::Fast, Quality::Balanced, Quality::Accurate] {
            let Some(m) = self.get(quality) else { continue };
            let at = format!("{field}.{}", quality.name());
            let chars = m.measured.trim().chars().count();
            if chars == 0 || chars > MAX_MEASURED_CHARS {
                return Err(crate::scene::SceneError::field(
                    format!("{at}.measured"),
                    format!("must say what was measured, in 1 to {MAX_MEASURED_CHARS} characters, got {chars}"),
                ));
            }
            if let Some(r) = m.rsm_resolution {
                let (lo, hi) = crate::scene::description::RSM_RESOLUTION_RANGE;
                crate::scene::validate::int_in(r, lo, hi, &format!("{at}.rsm_resolution"))?;
            }
            if let Some(sparse) = m.sparse {
                sparse.apply(SparseShading::default()).validate(&format!("{at}.sparse"))?;
            }
            if let Some(draws) = m.draws {
                if m.technique != Some(Technique::Estimator) {
                    return Err(crate::scene::SceneError::field(
                        format!("{at}.draws"),
                        "only with technique \"estimator\"",
                    ));
                }
                crate::scene::validate::int_in(draws, 1, MAX_ESTIMATOR_DRAWS, &format!("{at}.draws"))?;
            }
        }
        Ok(())
    }
}

/// One level's measured parameters (`settings.levels.<level>`): each optional, each replacing
/// the level's rule on this scene.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct MeasuredLevel {
    /// What was measured that makes these parameters the better choice (the adapter, the size,
    /// the errors and times against the level's own), in 1 to 1000 characters: it becomes their
    /// reason in the resolved configuration.
    pub measured: String,
    /// RSM side, texels, in 8..=2048.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rsm_resolution: Option<u32>,
    /// Indirect visibility mode (not `"auto"`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub visibility: Option<Occlusion>,
    /// The sparse method's parameters, with `tuning.sparse`'s fields and ranges.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sparse: Option<SparseTuning>,
    /// `"sparse"`, `"estimator"` (the exact reference estimated on the GPU, `draws` VALs per
    /// pixel), `"brute_force_clusters"` (every VAL at every pixel through the clusters'
    /// shadow maps, the level's `visibility` then `"clusters"`) or `"exact"` (a shadow ray per
    /// pixel and VAL over the level's VALs, which a coarser `rsm_resolution` makes fewer than
    /// the `reference` level's). Renders, `compare`, replays and the levels bench follow it;
    /// streams run the sparse method at every level.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub technique: Option<Technique>,
    /// With `technique: "estimator"`: VALs drawn per pixel, in 1..=256 (default 32).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub draws: Option<u32>,
}

impl MeasuredLevel {
    /// The given fields, as `(parameter, value)` with the level's parameter names
    /// (`rsm_resolution`, `visibility`, `sparse.points`).
    fn set_fields(&self) -> Vec<SetField> {
        let mut set = Vec::new();
        if let Some(r) = self.rsm_resolution {
            set.push(("rsm_resolution".to_owned(), r.to_string()));
        }
        if let Some(v) = self.visibility {
            set.push(("visibility".to_owned(), json_value(&v)));
        }
        set.extend(self.sparse.map(|t| t.set_fields("sparse")).unwrap_or_default());
        set
    }

    /// `tuning` with each of these values it does not set.
    fn under(&self, mut tuning: Tuning) -> Tuning {
        tuning.rsm_resolution = tuning.rsm_resolution.or(self.rsm_resolution);
        if tuning.visibility.is_none_or(|v| v == OcclusionSetting::Auto) {
            tuning.visibility = self.visibility.map(OcclusionSetting::from).or(tuning.visibility);
        }
        tuning.sparse = match (tuning.sparse, self.sparse) {
            (Some(set), Some(measured)) => Some(set.or(measured)),
            (set, measured) => set.or(measured),
        };
        tuning
    }
}

/// What the quality levels look at in a loaded scene. The default is a scene not yet loaded:
/// nothing known, which decides nothing the loader needs.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct SceneAnalysis {
    /// Meshes in the scene.
    pub meshes: usize,
    /// Names of the meshes that may occlude themselves: neither a convex object nor a convex
    /// room (`Mesh::may_occlude_itself`).
    pub concave_meshes: Vec<String>,
    /// Materials in use with a glossy lobe (`rho_s > 0`).
    pub glossy_materials: usize,
    /// Whether the scene has a spot `light` (whose RSM makes `rsm_resolution²` VALs).
    pub spot_light: bool,
    /// Spot and point lights in `lights`.
    pub spot_lights: usize,
    pub point_lights: usize,
    /// Triangles (after subdivision) per sparse point, over all meshes.
    pub triangles_per_sparse_point: f32,
}

impl SceneAnalysis {
    /// Whether one part of the scene can hide another from a third: more than one mesh, or a
    /// mesh that is neither a convex object nor a convex room (the rule `"auto"` visibility has
    /// always used).
    pub fn self_occluding(&self) -> bool {
        self.meshes > 1 || !self.concave_meshes.is_empty()
    }

    /// Why [`Self::self_occluding`] says what it says, for the reasons.
    fn occlusion_reason(&self) -> String {
        match (self.meshes, self.concave_meshes.as_slice()) {
            (n, _) if n > 1 => format!("the scene can occlude itself ({n} meshes)"),
            (_, [mesh, ..]) => {
                format!("the scene can occlude itself (mesh `{mesh}` is neither a convex object nor a convex room)")
            }
            _ => "the scene cannot occlude itself (one mesh, a convex object or a convex room)".to_owned(),
        }
    }

    /// What lights the scene, in words.
    pub fn lit_by(&self) -> String {
        let mut parts = Vec::new();
        if self.spot_light {
            parts.push("a spot light".to_owned());
        }
        if self.spot_lights + self.point_lights > 0 {
            parts.push(format!("{} spot and {} point `lights`", self.spot_lights, self.point_lights));
        }
        if self.lit_by_rgbd_frames() { "RGB-D frames (no light of its own)".to_owned() } else { parts.join(" and ") }
    }

    /// Whether only RGB-D frames light the scene (no light of its own): a mixed-reality scene,
    /// whose VALs are the room's pixels and, with `settings.environment`, the environment's
    /// VALs far beyond the room.
    pub fn lit_by_rgbd_frames(&self) -> bool {
        !self.spot_light && self.spot_lights + self.point_lights == 0
    }
}

/// The resolved configuration of a scene: the level asked for, what it decided and why.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct ResolvedConfig {
    pub quality: Quality,
    /// The scene file's frame-time budget, ms: streams and `relume replay` hold their frame
    /// time under it (`renderer::budget`); a single render reports whether it met it.
    pub budget_ms: Option<f32>,
    /// The technique the level asks for: `exact` for `reference`, the level's measured
    /// technique where the scene file names one, else `sparse`.
    pub method: Technique,
    /// With the estimator: its draws per pixel.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimator_draws: Option<u32>,
    pub analysis: SceneAnalysis,
    /// Every parameter the level or the scene file decided, with its reason.
    pub choices: Vec<Choice>,
}

impl ResolvedConfig {
    /// The configuration as lines of text: the level, the scene's analysis, then one line per
    /// choice.
    pub fn report(&self) -> String {
        let a = &self.analysis;
        let budget = self.budget_ms.map_or(String::new(), |ms| format!(", budget {ms} ms"));
        let mut lines = vec![
            format!(
                "quality {}{budget}: technique {}",
                self.quality.name(),
                json_value(&self.method).trim_matches('"')
            ),
            format!(
                "scene: {} mesh(es), {}, {} glossy material(s), lit by {}, {:.1} triangles per sparse point",
                a.meshes,
                if a.self_occluding() { "can occlude itself" } else { "cannot occlude itself" },
                a.glossy_materials,
                a.lit_by(),
                a.triangles_per_sparse_point
            ),
        ];
        lines.extend(self.choices.iter().map(|c| format!("  {c}")));
        lines.join("\n")
    }
}

/// The parameters a level picks whatever the scene: what the loader and the admission need.
struct Level {
    rsm_resolution: (u32, &'static str),
    subdivision: (f32, &'static str),
    near_field: (f32, &'static str),
    adaptive: (f32, &'static str),
    points: (f32, &'static str),
}

const RSM_BALANCED: &str = "16,384 VALs; more did not lower the error against exact visibility in the benchmark \
     sweep (0.155-0.174 for 208 to 12,892 VALs on cornell_bunny_small, docs/measurements/ benchmark)";
const SUBDIVISION_BALANCED: &str = "edges over 2 sparse point spacings split: fewer triangles than the paper's 1 at \
     equal error (cornell_bunny 76,139 against 96,245 triangles, 0.0449 against 0.0447; docs/measurements/ \
     sparse method on real scenes)";
const NEAR_FIELD_OFF: &str = "off (the paper's): no grid pass per frame";
const ADAPTIVE_OFF: &str = "off (the paper's)";
const POINTS_ALL: &str = "every sparse point the meshes ask for";

fn level(quality: Quality) -> Level {
    match quality {
        Quality::Fast => Level {
            rsm_resolution: (
                64,
                "a quarter of balanced's VALs: the gather's time grows about linearly with the VALs while \
                 the error against brute force hardly depends on them (0.100-0.129 for 208 to 12,892 VALs on \
                 cornell_bunny_small, docs/measurements/ benchmark)",
            ),
            subdivision: (
                4.0,
                "edges over 4 sparse point spacings split: a quarter fewer triangles than at 2 for a small \
                 error increase (sponza_bunny 154,101 against 205,715 triangles, 0.387 against 0.373; \
                 docs/measurements/ sparse method on real scenes)",
            ),
            near_field: (DEFAULT_NEAR_FIELD, NEAR_FIELD_OFF),
            adaptive: (0.0, ADAPTIVE_OFF),
            points: (
                0.5,
                "half of each mesh's sparse points: the disc occluders cost up to the square of the points \
                 and the gather their number (cornell_bunny at 256x256: 262 against 688 ms, rel RMSE against \
                 exact 0.123 against 0.110; cornell_bunny_ears 259 against 824 ms, 0.168 against 0.156; \
                 docs/measurements/level-parameters.md)",
            ),
        },
        Quality::Balanced => Level {
            rsm_resolution: (128, RSM_BALANCED),
            subdivision: (DEFAULT_SUBDIVISION, SUBDIVISION_BALANCED),
            near_field: (DEFAULT_NEAR_FIELD, NEAR_FIELD_OFF),
            adaptive: (0.0, ADAPTIVE_OFF),
            points: (1.0, POINTS_ALL),
        },
        Quality::Accurate | Quality::Reference => Level {
            rsm_resolution: (128, RSM_BALANCED),
            subdivision: (DEFAULT_SUBDIVISION, SUBDIVISION_BALANCED),
            near_field: (
                4.0,
                "VALs within 4 sparse point spacings light pixels directly: lower error on every measured \
                 fixture (sponza_bunny 0.372 to 0.112, cornell_bunny 0.046 to 0.034, cornell_gltf_small 0.091 \
                 to 0.055) for a grid pass per frame (docs/measurements/ near field)",
            ),
            adaptive: (
                0.0,
                "off: its gain was mixed (cornell_gltf_small worse at 0.25 and 1) and it was not measured \
                 beside the near field (docs/measurements/ adaptive sparse points)",
            ),
            points: (1.0, POINTS_ALL),
        },
    }
}

/// The level's choices and the scene file's overrides, gathered in order.
struct Choices {
    tuned: Vec<SetField>,
    /// The level's measured parameters (`settings.levels`) not yet named, and what was measured.
    measured: Vec<SetField>,
    measured_text: String,
    choices: Vec<Choice>,
    level: &'static str,
}

impl Choices {
    /// `value` as the level chose it for `parameter`, unless the scene file's tuning sets it
    /// (the override's own choice then says what the level would have chosen).
    fn level<T: Serialize>(&mut self, parameter: &str, value: T, reason: impl Into<String>) {
        let value = json_value(&value);
        let tuned = format!("tuning.{parameter}");
        let measured = self.measured.iter().position(|(path, _)| path == parameter).map(|i| self.measured.remove(i));
        if let Some(i) = self.tuned.iter().position(|(path, _)| *path == tuned) {
            let (path, set) = self.tuned.remove(i);
            let value = measured.map_or(value, |(_, measured)| format!("{measured}, measured on this scene"));
            let reason = format!("set in the scene file ({} would choose {value})", self.level);
            self.choices.push(Choice { parameter: path, value: set, reason });
        } else if let Some((path, set)) = measured {
            let reason = format!("measured on this scene: {} (the rule would choose {value})", self.measured_text);
            self.choices.push(Choice { parameter: format!("levels.{}.{path}", self.level), value: set, reason });
        } else {
            self.choices.push(Choice { parameter: parameter.to_owned(), value, reason: reason.into() });
        }
    }

    fn note(&mut self, parameter: &str, value: &str, reason: impl Into<String>) {
        self.choices.push(Choice { parameter: parameter.to_owned(), value: value.to_owned(), reason: reason.into() });
    }

    /// The choices, with every override no level choice named after them.
    fn finish(mut self) -> Vec<Choice> {
        for (path, value) in std::mem::take(&mut self.measured) {
            let reason = format!("measured on this scene: {}", self.measured_text);
            self.choices.push(Choice { parameter: format!("levels.{}.{path}", self.level), value, reason });
        }
        for (parameter, value) in self.tuned {
            self.choices.push(Choice { parameter, value, reason: "set in the scene file".to_owned() });
        }
        self.choices
    }
}

/// The settings of a scene at `quality`, given what `analysis` found in it and the scene file's
/// `settings` (its user values, and its tuning, which wins over the level), with the reason for
/// every choice. Pure: the same inputs give the same result.
pub fn resolve(quality: Quality, analysis: &SceneAnalysis, settings: &SettingsDescription) -> (Settings, Vec<Choice>) {
    let measured = settings.levels.get(quality);
    let tuning = &measured.map_or(settings.tuning, |m| m.under(settings.tuning));
    let mut choices = Choices {
        tuned: settings.tuning.set_fields(),
        measured: measured.map(MeasuredLevel::set_fields).unwrap_or_default(),
        measured_text: measured.map(|m| m.measured.trim().to_owned()).unwrap_or_default(),
        choices: Vec::new(),
        level: quality.name(),
    };
    let Level { rsm_resolution, subdivision, near_field, adaptive, points } = level(quality);

    match quality {
        Quality::Reference => choices.note(
            "method",
            "\"exact\"",
            "quality \"reference\" asks for the exact reference method (a shadow ray per pixel and VAL); \
             its sparse parameters are accurate's",
        ),
        _ => match technique(quality, settings) {
            (Technique::Estimator, Some(draws)) => {
                let reason = format!(
                    "measured on this scene: {}; {draws} VALs drawn per pixel by their unoccluded light, a \
                     shadow ray each (the rule would choose \"sparse\")",
                    choices.measured_text
                );
                choices.note(&format!("levels.{}.technique", quality.name()), "\"estimator\"", reason);
            }
            (Technique::BruteForceClusters, _) => {
                let reason = format!(
                    "measured on this scene: {}; every VAL at every pixel, weighted by its cluster's shadow-map \
                     lookup there (the rule would choose \"sparse\")",
                    choices.measured_text
                );
                choices.note(&format!("levels.{}.technique", quality.name()), "\"brute_force_clusters\"", reason);
            }
            (Technique::Exact, _) => {
                let reason = format!(
                    "measured on this scene: {}; a shadow ray per pixel and VAL over the level's VALs (the rule \
                     would choose \"sparse\")",
                    choices.measured_text
                );
                choices.note(&format!("levels.{}.technique", quality.name()), "\"exact\"", reason);
            }
            _ => choices.note("method", "\"sparse\"", "the sparse model-space method"),
        },
    }

    let rsm_reason = if analysis.spot_light || analysis.meshes == 0 {
        rsm_resolution.1.to_owned()
    } else {
        "unused: the scene has no spot `light`".to_owned()
    };
    choices.level("rsm_resolution", rsm_resolution.0, rsm_reason);
    choices.level(
        "interpolation_neighbours",
        DEFAULT_NEIGHBOURS,
        "the paper's 8 (eqs. 12-13) at every level: no other count was measured against the error",
    );

    let occlusion_reason = analysis.occlusion_reason();
    let level_visibility = match (analysis.self_occluding(), quality) {
        (false, _) => (Occlusion::Off, occlusion_reason),
        (true, Quality::Fast | Quality::Balanced) => (
            Occlusion::Disks,
            format!("{occlusion_reason}; disc occluders were closer to exact than none on every measured fixture"),
        ),
        (true, Quality::Accurate | Quality::Reference) if analysis.lit_by_rgbd_frames() => (
            Occlusion::Ism,
            format!(
                "{occlusion_reason}; lit by RGB-D frames: imperfect shadow maps, focused on the virtual content \
                 from the VALs drawn by flux (the environment's far beyond the room among them), were the closest \
                 to exact on the bundled TUM replay: per-frame error estimate 0.074 against 0.107 with clusters \
                 of VALs (7x ism's frame time) and 0.131 with disc occluders (a fifth of ism's frame time; \
                 docs/measurements/mixed-reality.md)"
            ),
        ),
        (true, Quality::Accurate | Quality::Reference) => (
            Occlusion::Clusters,
            format!(
                "{occlusion_reason}; shadow maps of clusters of VALs were closer to exact than disks on every \
                 measured fixture but the glossy room (equal there), at 2.6-7x the disks' visibility cost \
                 (docs/measurements/ visibility against exact)"
            ),
        ),
    };
    let occlusion = tuning.visibility.unwrap_or(OcclusionSetting::Auto).or(level_visibility.0);
    choices.level("visibility", level_visibility.0, level_visibility.1);
    let occlusion_rule = tuning.occlusion_rule.unwrap_or(OcclusionRule::Product);
    if occlusion == Occlusion::Disks {
        choices.level(
            "occlusion_rule",
            OcclusionRule::Product,
            "product: closer to exact than the paper's sum on the ears close-up (0.154 against 0.263) and near \
             it elsewhere (docs/measurements/ visibility against exact)",
        );
    }

    let triangles = analysis.triangles_per_sparse_point;
    let subdivision_reason = match triangles > 0.0 {
        true => format!("{}; this scene: {triangles:.1} triangles per sparse point", subdivision.1),
        false => subdivision.1.to_owned(),
    };
    choices.level("sparse.subdivision", subdivision.0, subdivision_reason);
    choices.level("sparse.near_field", near_field.0, near_field.1);
    choices.level(
        "sparse.near_field_interleave",
        crate::scene::settings::sparse::DEFAULT_NEAR_FIELD_INTERLEAVE,
        "not interleaved: every pixel shades every near VAL (interleaving at 4x4 cuts the near field's \
         cost 1.8-3.3x where it is large and adds to it where it is small, at an accuracy that depends on \
         the scene: against the brute force sponza_bunny 0.111 to 0.125, cornell_bunny_small 0.069 to 0.089; docs/measurements/ the near field \
         interleaved)",
    );
    choices.level("sparse.adaptive", adaptive.0, adaptive.1);
    choices.level("sparse.points", points.0, points.1);
    let sparse = SparseShading {
        subdivision: subdivision.0,
        near_field: near_field.0,
        adaptive: adaptive.0,
        points: points.0,
        ..SparseShading::default()
    };
    let sparse = tuning.sparse.map_or(sparse, |t| t.apply(sparse));

    let glossy = match (settings.glossy, analysis.glossy_materials) {
        (false, _) => ("off", "settings.glossy is false".to_owned()),
        (true, 0) => ("off", "no glossy material".to_owned()),
        (true, n) => ("on", format!("{n} glossy material(s): their lobe is gathered in a second pass")),
    };
    if analysis.meshes > 0 {
        choices.note("glossy gather", glossy.0, glossy.1);
    }
    if analysis.lit_by_rgbd_frames() && settings.mr.differential {
        let exact = quality == Quality::Reference;
        // Resolved for the pass on the CPU; on the GPU the frames run the exact pass
        // (`DifferentialMethod::for_frames`), which the reason says.
        let method = DifferentialMethod::for_frames(None, exact, false);
        let value = json_value(&method);
        match settings.mr.differential_method {
            Some(set) => {
                let reason = format!("set in the scene file ({} would choose {value})", quality.name());
                choices.note("mr.differential_method", &json_value(&set), reason);
            }
            None if exact => choices.note(
                "mr.differential_method",
                &value,
                "beside the exact reference, the exact differential pass (every receiver sums every VAL with a shadow \
                 ray): the reference the fast pass is tested against",
            ),
            None => choices.note(
                "mr.differential_method",
                &value,
                "VALs in groups and receivers refined where the content's effect changes: about a third of the exact \
                 pass's time on the TUM replay, its change of irradiance within 4.5-8.5 % rel RMSE of the exact \
                 pass's and the contact shadow's darkest value within 1 % (docs/measurements/differential.md); where \
                 the pass runs on the GPU the frames take the exact pass, the faster there (an H200: 216 against 499 \
                 ms a frame, docs/measurements/gpu.md)",
            ),
        }
    }
    if let Some(ms) = settings.budget_ms {
        choices.note(
            "budget_ms",
            &json_value(&ms),
            "streams and replays move frame by frame between this level's parameters and cheaper or richer ones to \
             hold the frame time under it (renderer::budget); a single render reports whether it met it",
        );
    }

    let resolved = Settings {
        rsm_resolution: tuning.rsm_resolution.unwrap_or(rsm_resolution.0),
        reference_rsm_resolution: settings.tuning.rsm_resolution.unwrap_or(level(Quality::Reference).rsm_resolution.0),
        glossy: settings.glossy,
        seed: settings.seed,
        exposure: settings.exposure,
        interpolation_neighbours: tuning.interpolation_neighbours.unwrap_or(DEFAULT_NEIGHBOURS),
        visibility: tuning.visibility_settings(occlusion, occlusion_rule),
        rgbd: settings.rgbd,
        mr: settings.mr,
        sparse,
        direct: tuning.direct.map_or(Default::default(), |t| t.apply(Default::default())),
        bounces: settings.bounces,
        second_bounce: tuning.second_bounce.map_or(Default::default(), |t| t.apply(Default::default())),
    };
    (resolved, choices.finish())
}

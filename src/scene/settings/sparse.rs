//! `settings.sparse`: how the sparse method turns gathered light into pixels.

use serde::{Deserialize, Serialize};

use crate::scene::SceneError;

/// How the sparse method turns gathered light into pixels (docs/design.md §4 steps 0, 2, 4). The
/// paper's form is `{"kernel": "paper", "bound": "off", "subdivision": 1,
/// "glossy_interpolation": "lights"}`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SparseShading {
    /// Interpolation weights of a vertex's sparse neighbours; default `"smooth"`.
    #[serde(default)]
    pub kernel: InterpolationKernel,
    /// Upper bound on the irradiance an interpolated light may deliver; default `"gathered"`.
    #[serde(default)]
    pub bound: LightBound,
    /// Edges longer than this many sparse point spacings `sqrt(area / sparse_points)` are split
    /// at load, in [1, 16]; default [`DEFAULT_SUBDIVISION`]. 1 is the paper's.
    #[serde(default = "default_subdivision")]
    pub subdivision: f32,
    /// Radius, in sparse point spacings (the largest over the meshes, in world space), within
    /// which a VAL lights a receiver per pixel (the `near_field` stage) instead of through the
    /// sparse points, in [0, 8]; default [`DEFAULT_NEAR_FIELD`]. 0 is off (the paper's).
    #[serde(default = "default_near_field")]
    pub near_field: f32,
    /// The near field interleaved over blocks this many pixels wide: each pixel of a block
    /// shades one of `side²` subsets of the near VALs, and a filter over the block that keeps
    /// to the pixel's surface adds them up again (1/side² of the near field's cost); one of
    /// 1 (every pixel every near VAL), 2, 4, 8; default [`DEFAULT_NEAR_FIELD_INTERLEAVE`].
    #[serde(default = "default_near_field_interleave")]
    pub near_field_interleave: u32,
    /// How a pixel takes the glossy light of its sparse points; default `"radiance"`;
    /// `"lights"` is the paper's.
    #[serde(default)]
    pub glossy_interpolation: GlossyInterpolation,
    /// Adaptive sparse points (beyond the paper): every frame, up to this fraction of each
    /// mesh's sparse points more are gathered, at the candidates where the neighbouring points'
    /// gathered light differs most, in [0, 1]; default [`DEFAULT_ADAPTIVE`]. 0 is off (the
    /// paper's). Each mesh holds [`ADAPTIVE_CANDIDATES`] candidates per extra point.
    #[serde(default = "default_adaptive")]
    pub adaptive: f32,
    /// The fraction of each mesh's `sparse_points` placed at load, in [1/16, 1]; default
    /// [`DEFAULT_POINTS`] (every one). Fewer points make the gather and the disc occluders
    /// cheaper (the discs' cost grows with the square of the points) at a coarser interpolation.
    #[serde(default = "default_points")]
    pub points: f32,
}

/// Fraction of each mesh's sparse points placed unless a scene says otherwise: all.
pub const DEFAULT_POINTS: f32 = 1.0;

/// Range of [`SparseShading::points`].
pub const POINTS_RANGE: (f32, f32) = (0.0625, 1.0);

fn default_points() -> f32 {
    DEFAULT_POINTS
}

/// Adaptive sparse points unless a scene says otherwise: none.
pub const DEFAULT_ADAPTIVE: f32 = 0.0;

/// Range of [`SparseShading::adaptive`].
pub const ADAPTIVE_RANGE: (f32, f32) = (0.0, 1.0);

/// Candidates placed per adaptive point of the budget (`settings.sparse.adaptive`): the pool
/// a frame chooses its extra points from.
pub const ADAPTIVE_CANDIDATES: usize = 4;

fn default_adaptive() -> f32 {
    DEFAULT_ADAPTIVE
}

/// Near-field radius in sparse point spacings unless a scene says otherwise.
pub const DEFAULT_NEAR_FIELD: f32 = 0.0;

/// Range of [`SparseShading::near_field`].
pub const NEAR_FIELD_RANGE: (f32, f32) = (0.0, 8.0);

fn default_near_field() -> f32 {
    DEFAULT_NEAR_FIELD
}

/// Block sides the near field may be interleaved over (`near_field_interleave`): 1 (every pixel
/// sums every near VAL) to 8.
pub const NEAR_FIELD_INTERLEAVE_SIDES: [u32; 4] = [1, 2, 4, 8];

/// Near-field interleaving block side unless a scene says otherwise: none, every pixel shades
/// every near VAL (interleaving trades accuracy for speed, by how much depends on the scene:
/// docs/measurements/sparse-real-scenes.md, the near field interleaved).
pub const DEFAULT_NEAR_FIELD_INTERLEAVE: u32 = 1;

fn default_near_field_interleave() -> u32 {
    DEFAULT_NEAR_FIELD_INTERLEAVE
}

/// Subdivision edge length in sparse point spacings unless a scene says otherwise.
pub const DEFAULT_SUBDIVISION: f32 = 2.0;

/// Range of [`SparseShading::subdivision`].
pub const SUBDIVISION_RANGE: (f32, f32) = (1.0, 16.0);

fn default_subdivision() -> f32 {
    DEFAULT_SUBDIVISION
}

impl Default for SparseShading {
    fn default() -> Self {
        SparseShading {
            kernel: InterpolationKernel::default(),
            bound: LightBound::default(),
            subdivision: DEFAULT_SUBDIVISION,
            near_field: DEFAULT_NEAR_FIELD,
            near_field_interleave: DEFAULT_NEAR_FIELD_INTERLEAVE,
            glossy_interpolation: GlossyInterpolation::default(),
            adaptive: DEFAULT_ADAPTIVE,
            points: DEFAULT_POINTS,
        }
    }
}

impl SparseShading {
    /// Check every field's range, naming the first bad field under `field`.
    pub fn validate(&self, field: &str) -> Result<(), SceneError> {
        for (value, (lo, hi), name) in [
            (self.subdivision, SUBDIVISION_RANGE, "subdivision"),
            (self.near_field, NEAR_FIELD_RANGE, "near_field"),
            (self.adaptive, ADAPTIVE_RANGE, "adaptive"),
            (self.points, POINTS_RANGE, "points"),
        ] {
            if !(lo..=hi).contains(&value) {
                return Err(SceneError::field(
                    format!("{field}.{name}"),
                    format!("must be in [{lo}, {hi}], got {value}"),
                ));
            }
        }
        let sides = NEAR_FIELD_INTERLEAVE_SIDES;
        if !sides.contains(&self.near_field_interleave) {
            return Err(SceneError::field(
                format!("{field}.near_field_interleave"),
                format!("must be one of {sides:?}, got {}", self.near_field_interleave),
            ));
        }
        Ok(())
    }

    /// The sparse points a mesh whose description asks for `sparse_points` places: `points`
    /// of them, rounded, at least one.
    pub fn placed_points(&self, sparse_points: u32) -> usize {
        ((f64::from(sparse_points) * f64::from(self.points)).round() as usize).max(1)
    }
}

/// Interpolation weights of a vertex's sparse neighbours (`twin::interpolation_weights`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum InterpolationKernel {
    /// Paper eq. 12: `(1 - d / d_max) * clamp(n_v . n_j, 0, 1)`.
    Paper,
    /// `(1 - (d / d_max)^2)^2 * clamp(n_v . n_j, 0, 1)`, times a factor that falls to zero for
    /// points behind the vertex's tangent plane (the other side of thin geometry).
    #[default]
    Smooth,
}

/// Upper bound on the irradiance an interpolated point light may deliver at a pixel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum LightBound {
    /// None (the paper's).
    Off,
    /// The largest irradiance luminance that the sparse points it was interpolated from
    /// gathered.
    #[default]
    Gathered,
}

/// How the sparse method carries glossy light from the sparse points to a pixel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum GlossyInterpolation {
    /// The paper's (eqs. 11-13): each sparse point's gathered glossy light becomes a
    /// renormalised point light, each vertex averages its neighbours' lights (positions and
    /// intensities) into one, interpolated across the triangle and applied at the pixel through
    /// the pixel's own lobe.
    Lights,
    /// The glossy radiance each sparse point gathered toward the eye is interpolated with the
    /// same weights and times the pixel's specular albedo and lobe normalisation; no glossy
    /// point light. A sharp lobe evaluated for one merged light falls off within a few degrees
    /// of where the averaged position puts it; the radiance itself varies as smoothly as the
    /// reflected scene does. Closer to the brute force on every glossy fixture (docs/measurements/sparse-real-scenes.md).
    #[default]
    Radiance,
}

//! `settings.rgbd`: how an RGB-D frame becomes VALs (`rgbd`, `twin::rgbd`).

use serde::{Deserialize, Serialize};

use crate::scene::SceneError;
use crate::scene::validate::{at_least, in_closed, int_in, positive};

/// How a frame becomes VALs (docs/design.md §2 "RGB-D frames"). Every field is a documented scene /
/// stream setting with this default. Laid out as WGSL's `RgbdSettings`.
#[repr(C)]
#[derive(
    Clone, Copy, Debug, PartialEq, Serialize, Deserialize, bytemuck::Pod, bytemuck::Zeroable, utoipa::ToSchema,
)]
#[serde(default, deny_unknown_fields)]
pub struct RgbdSettings {
    /// Downsampling: one VAL per `grid_step x grid_step` block of depth pixels (640x480 at 8 gives
    /// an 80x60 grid, 4,800 VALs at most).
    pub grid_step: u32,
    /// Depth outside `[min_depth, max_depth]` (m) yields no VAL.
    pub min_depth: f32,
    pub max_depth: f32,
    /// Radiance (W/(m² sr)) of a linear colour of 1: `L = radiance_scale * srgb_to_linear(rgb)`.
    pub radiance_scale: f32,
    /// Bilateral depth filter: half-width in depth pixels (0 = off) and the depth difference (m)
    /// at which a neighbour's weight falls to 1/e (the spatial sigma is `radius / 2` pixels).
    pub bilateral_radius: u32,
    pub bilateral_depth_sigma: f32,
    /// `c_min` of the footprint area `(z/fx)(z/fy) step² / max(cos, c_min)`: bounds the area of
    /// surfaces seen at grazing angles.
    pub min_cosine: f32,
}

impl Default for RgbdSettings {
    fn default() -> Self {
        Self {
            grid_step: 8,
            min_depth: 0.1,
            max_depth: 10.0,
            radiance_scale: 1.0,
            bilateral_radius: 2,
            bilateral_depth_sigma: 0.05,
            min_cosine: 0.2,
        }
    }
}

impl RgbdSettings {
    /// Ranges of every field, naming the field of the first value out of range. The one check
    /// of these settings: a scene file's `settings.rgbd` and a stream's `control.rgbd` alike.
    pub fn validate(&self, field: &str) -> Result<(), SceneError> {
        let r = self;
        int_in(r.grid_step, 1, 64, &format!("{field}.grid_step"))?;
        positive(r.min_depth, &format!("{field}.min_depth"))?;
        positive(r.max_depth, &format!("{field}.max_depth"))?;
        if r.max_depth <= r.min_depth {
            return Err(SceneError::field(
                format!("{field}.max_depth"),
                format!("must be > min_depth ({}), got {}", r.min_depth, r.max_depth),
            ));
        }
        at_least(r.radiance_scale, 0.0, &format!("{field}.radiance_scale"))?;
        int_in(r.bilateral_radius, 0, 16, &format!("{field}.bilateral_radius"))?;
        positive(r.bilateral_depth_sigma, &format!("{field}.bilateral_depth_sigma"))?;
        in_closed(r.min_cosine, 1e-3, 1.0, &format!("{field}.min_cosine"))
    }
}

//! RGB-D frames as light sources (DESIGN.md §2 "RGB-D frames", §6): every valid depth pixel of
//! a real room's camera frame (after downsampling) becomes a VAL, so virtual content placed in
//! the room receives the room's colours as indirect light.
//!
//! - [`recording`]: TUM RGB-D recordings on disk (association, pose interpolation, intrinsics).
//! - [`accumulate`]: a persistent world-space VAL set across frames (paper §5, restriction 3).
//! - `reference::rgbd`: the CPU twin of the VAL generation; `gpu::rgbd`: the GPU pass.

use glam::Affine3A;
use serde::{Deserialize, Serialize};

pub mod accumulate;
pub mod recording;

/// Pinhole intrinsics of the depth image, registered to colour (pixels). Optical axes: x right,
/// y down, z forward; pixel centres at integer coordinates. Laid out as WGSL's `Intrinsics`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, bytemuck::Pod, bytemuck::Zeroable)]
#[serde(deny_unknown_fields)]
pub struct Intrinsics {
    pub width: u32,
    pub height: u32,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
}

impl Intrinsics {
    /// TUM RGB-D's registered depth (ECOSYSTEM.md): 640x480, fx = fy = 525, cx = 319.5, cy = 239.5.
    pub const TUM: Intrinsics = Intrinsics { width: 640, height: 480, fx: 525.0, fy: 525.0, cx: 319.5, cy: 239.5 };

    /// The same camera imaged at `width x height` (pixel centres stay at integer coordinates).
    pub fn scaled_to(&self, width: u32, height: u32) -> Intrinsics {
        let (sx, sy) = (width as f32 / self.width as f32, height as f32 / self.height as f32);
        Intrinsics {
            width,
            height,
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: (self.cx + 0.5) * sx - 0.5,
            cy: (self.cy + 0.5) * sy - 0.5,
        }
    }

    /// Pixel coordinates of an optical-frame point (x right, y down, z forward), z > 0.
    pub fn project(&self, p: glam::Vec3) -> glam::Vec2 {
        glam::Vec2::new(self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy)
    }
}

/// One RGB-D frame in memory, depth already converted to metres.
#[derive(Clone, Debug)]
pub struct RgbdFrame {
    /// Seconds (the recording's clock).
    pub timestamp: f64,
    pub intrinsics: Intrinsics,
    /// sRGB colour, row-major, `width * height` texels.
    pub color: Vec<[u8; 3]>,
    /// Depth along the optical axis (m), row-major, `width * height`; 0, negative or NaN = none.
    pub depth: Vec<f32>,
    /// Camera-to-world in optical axes (x right, y down, z forward).
    pub camera_to_world: Affine3A,
}

/// How a frame becomes VALs (DESIGN.md §2 "RGB-D frames"). Every field is a documented scene /
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

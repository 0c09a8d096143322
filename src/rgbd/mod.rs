//! RGB-D frames as light sources (docs/design.md §2 "RGB-D frames", §6): every valid depth pixel of
//! a real room's camera frame (after downsampling) becomes a VAL, so virtual content placed in
//! the room receives the room's colours as indirect light.
//!
//! - [`recording`]: RGB-D recordings on disk, in the TUM layout ([`tum`]), Open3D/Redwood's
//!   ([`redwood`]) or MCAP files ([`rosbag`]); what the layouts' readers share ([`reader`]:
//!   options, errors, checks) and the pose interpolation ([`poses`]).
//! - [`accumulate`]: a persistent world-space VAL set across frames (paper §5, restriction 3).
//! - `twin::rgbd`: the CPU twin of the VAL generation; `gpu::lights::rgbd`: the GPU pass.

use glam::DAffine3;
use serde::{Deserialize, Serialize};

pub mod accumulate;
mod images;
pub mod poses;
pub mod reader;
pub mod recording;
pub mod redwood;
pub mod rosbag;
pub mod tum;

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
    /// TUM RGB-D's registered depth (docs/rgbd.md): 640x480, fx = fy = 525, cx = 319.5, cy = 239.5.
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
    /// Camera-to-world in optical axes (x right, y down, z forward), in the user's world
    /// coordinates and f64 (as recorded or sent; f32 keeps 7.8 mm at 100 km from the origin):
    /// made relative to a scene's floating origin, then f32, by [`crate::scene::local_pose`].
    pub camera_to_world: DAffine3,
}

impl RgbdFrame {
    /// The frame at `1 / factor` of its size (each side rounded down, at least 1 pixel): colour
    /// averaged over each `factor x factor` block, depth the median of the block's valid
    /// measurements (no averaging across an edge between two surfaces), intrinsics
    /// [`Intrinsics::scaled_to`]. `factor` 0 or 1 keeps the frame.
    pub fn downsampled(&self, factor: u32) -> RgbdFrame {
        let k = self.intrinsics;
        if factor <= 1 {
            return self.clone();
        }
        let (width, height) = ((k.width / factor).max(1), (k.height / factor).max(1));
        let mut color = Vec::with_capacity((width * height) as usize);
        let mut depth = Vec::with_capacity((width * height) as usize);
        let mut valid = Vec::with_capacity((factor * factor) as usize);
        for y in 0..height {
            for x in 0..width {
                let mut sum = [0u32; 3];
                let mut texels = 0;
                valid.clear();
                for sy in y * factor..((y + 1) * factor).min(k.height) {
                    for sx in x * factor..((x + 1) * factor).min(k.width) {
                        let i = (sy * k.width + sx) as usize;
                        for (total, channel) in sum.iter_mut().zip(self.color[i]) {
                            *total += u32::from(channel);
                        }
                        texels += 1;
                        let d = self.depth[i];
                        if d.is_finite() && d > 0.0 {
                            valid.push(d);
                        }
                    }
                }
                color.push(sum.map(|total| ((total + texels / 2) / texels) as u8));
                valid.sort_by(f32::total_cmp);
                depth.push(valid.get(valid.len() / 2).copied().unwrap_or(0.0));
            }
        }
        RgbdFrame {
            timestamp: self.timestamp,
            intrinsics: k.scaled_to(width, height),
            color,
            depth,
            camera_to_world: self.camera_to_world,
        }
    }
}

/// How a frame becomes VALs: `settings.rgbd` of a scene file, `control.rgbd` of a stream.
pub use crate::scene::settings::RgbdSettings;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn downsampling_averages_colour_and_takes_the_median_valid_depth() {
        // 4x2: two 2x2 blocks. Left: colours 0, 10, 20, 30 and depths 1, 1, 5, missing;
        // right: all depth missing.
        let frame = RgbdFrame {
            timestamp: 2.5,
            intrinsics: Intrinsics { width: 4, height: 2, fx: 4.0, fy: 4.0, cx: 1.5, cy: 0.5 },
            color: [0u8, 10, 50, 50, 20, 30, 50, 50].iter().map(|&c| [c, c, 255]).collect(),
            depth: vec![1.0, 1.0, 0.0, f32::NAN, 5.0, -1.0, 0.0, 0.0],
            camera_to_world: DAffine3::from_translation(glam::DVec3::X),
        };
        let half = frame.downsampled(2);
        assert_eq!(half.intrinsics, Intrinsics { width: 2, height: 1, fx: 2.0, fy: 2.0, cx: 0.5, cy: 0.0 });
        assert_eq!(half.color, vec![[15, 15, 255], [50, 50, 255]]);
        assert_eq!(half.depth, vec![1.0, 0.0]);
        assert_eq!((half.timestamp, half.camera_to_world), (frame.timestamp, frame.camera_to_world));
        assert_eq!(frame.downsampled(1).depth.len(), 8);
    }
}

//! Where a frame's camera image is rendered from: the scene's camera or a pinhole (an RGB-D
//! frame's), and the pinhole's clip transform.

use crate::rgbd::Intrinsics;
use crate::scene::Camera;
use glam::{Affine3A, Mat4, Vec3, Vec4};

/// Where the camera image is rendered from.
#[derive(Clone, Copy, Debug)]
pub enum View {
    /// The scene file's perspective camera.
    Scene(Camera),
    /// A pinhole camera (an RGB-D frame's): intrinsics, scaled to the render size, and a
    /// camera-to-world pose in optical axes (x right, y down, z forward), relative to the
    /// scene's origin ([`super::Renderer::set_pinhole_view`] takes it in the user's world coordinates).
    Pinhole { intrinsics: Intrinsics, camera_to_world: Affine3A },
}

impl View {
    /// World-space position of the eye.
    pub fn eye(&self) -> Vec3 {
        match self {
            View::Scene(c) => c.position,
            View::Pinhole { camera_to_world, .. } => camera_to_world.translation.into(),
        }
    }
}

/// Optical camera coordinates (x right, y down, z forward) to wgpu clip space for a pinhole
/// camera whose pixel centres sit at integer coordinates: the image spans u in [-0.5, w - 0.5].
/// Depth maps `near..far` to `0..1` like `perspective` (DirectX convention).
pub fn pinhole_to_clip(k: &Intrinsics, near: f32, far: f32) -> Mat4 {
    let (w, h) = (k.width as f32, k.height as f32);
    let depth = far / (far - near);
    Mat4::from_cols(
        Vec4::new(2.0 * k.fx / w, 0.0, 0.0, 0.0),
        Vec4::new(0.0, -2.0 * k.fy / h, 0.0, 0.0),
        Vec4::new(2.0 * (k.cx + 0.5) / w - 1.0, 1.0 - 2.0 * (k.cy + 0.5) / h, depth, 1.0),
        Vec4::new(0.0, 0.0, -near * depth, 0.0),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The clip transform lands a point on the pixel the intrinsics project it to, and maps the
    /// near and far planes to depth 0 and 1.
    #[test]
    fn pinhole_to_clip_matches_intrinsics() {
        let k = Intrinsics { width: 64, height: 48, fx: 50.0, fy: 55.0, cx: 30.2, cy: 25.7 };
        let m = pinhole_to_clip(&k, 0.1, 10.0);
        for p in [Vec3::new(0.3, -0.2, 1.5), Vec3::new(-1.0, 0.7, 4.0), Vec3::new(0.0, 0.0, 0.1)] {
            let clip = m * p.extend(1.0);
            let ndc = clip.truncate() / clip.w;
            let pixel = glam::Vec2::new((ndc.x + 1.0) * 0.5 * 64.0 - 0.5, (1.0 - ndc.y) * 0.5 * 48.0 - 0.5);
            assert!((pixel - k.project(p)).abs().max_element() < 1e-4, "{p}: {pixel} vs {}", k.project(p));
        }
        let depth = |z: f32| {
            let c = m * Vec4::new(0.0, 0.0, z, 1.0);
            c.z / c.w
        };
        assert!(depth(0.1).abs() < 1e-6 && (depth(10.0) - 1.0).abs() < 1e-6);
    }

    /// Scaling the intrinsics keeps the image of a point at the same fraction of the image.
    #[test]
    fn scaled_intrinsics_keep_image_fractions() {
        let k = Intrinsics::TUM;
        let half = k.scaled_to(320, 240);
        let p = Vec3::new(0.4, -0.3, 2.0);
        let (a, b) = (k.project(p), half.project(p));
        assert!(((a.x + 0.5) / 640.0 - (b.x + 0.5) / 320.0).abs() < 1e-6);
        assert!(((a.y + 0.5) / 480.0 - (b.y + 0.5) / 240.0).abs() < 1e-6);
    }
}

//! The part of a mixed-reality frame the virtual content can cover: its box projected into the
//! camera, so that the render's per-pixel stages (the camera's visibility, shading, the error
//! estimate, the readbacks) run over those pixels only. On the default replay the bunny covers
//! a few percent of the 640x480 image. The crop is a pinhole of its own: the same focal lengths,
//! the principal point moved by the crop's corner, so each of its pixels sees exactly the ray
//! the full image's pixel does, and the render is pasted back at its place.

use crate::rgbd::Intrinsics;
use glam::{Affine3A, Vec3};

/// The crop's sides are rounded up to multiples of this many pixels (within the image), so that
/// the render target keeps its size while the content moves by a few pixels.
pub const GRANULE: u32 = 32;

/// Pixels added around the projected box on every side: the rasteriser's coverage of a pixel
/// the box's edge only touches.
pub const MARGIN: u32 = 2;

/// Camera-space depth (m) under which a corner of the box counts as behind the camera: the
/// content then may cover any pixel, and the crop is the whole image.
const NEAR: f32 = 1e-3;

/// A rectangle of pixels of a `width x height` image, `x..x + width` by `y..y + height`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Crop {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

impl Crop {
    /// The whole image.
    pub fn full(width: u32, height: u32) -> Crop {
        Crop { x: 0, y: 0, width, height }
    }

    /// The pixels of the image `k` describes (its size, the size rendered) that the box
    /// `bounds` (min, max corners) can cover, seen from `camera_to_world` (optical axes, in the
    /// box's coordinates): its corners projected, with [`MARGIN`], sides rounded up to
    /// [`GRANULE`]; the whole image where a corner is behind the camera, and a [`GRANULE`]
    /// square in the image's corner where the box is out of view (the frame still gathers its
    /// light, which the differential pass's re-emitters take).
    pub fn of_box(k: &Intrinsics, camera_to_world: &Affine3A, bounds: (Vec3, Vec3)) -> Crop {
        let (w, h) = (k.width, k.height);
        let world_to_camera = camera_to_world.inverse();
        let (mut lo, mut hi) = (glam::Vec2::splat(f32::INFINITY), glam::Vec2::splat(f32::NEG_INFINITY));
        for i in 0..8 {
            let corner = Vec3::select(glam::BVec3::new(i & 1 != 0, i & 2 != 0, i & 4 != 0), bounds.1, bounds.0);
            let p = world_to_camera.transform_point3(corner);
            // NaN (a degenerate pose) counts as behind.
            if p.z.is_nan() || p.z <= NEAR {
                return Crop::full(w, h);
            }
            let pixel = k.project(p);
            (lo, hi) = (lo.min(pixel), hi.max(pixel));
        }
        // Pixel centres are at integer coordinates: pixel u covers [u - 0.5, u + 0.5).
        let first = |v: f32| (v - 0.5).floor().max(-1e6) as i64 - i64::from(MARGIN);
        let last = |v: f32| (v + 0.5).ceil().min(1e6) as i64 + i64::from(MARGIN);
        let span = |lo: f32, hi: f32, size: u32| {
            let (a, b) = (first(lo).max(0), last(hi).min(i64::from(size)));
            (b > a).then_some((a as u32, (b - a) as u32))
        };
        let (Some((x, cw)), Some((y, ch))) = (span(lo.x, hi.x, w), span(lo.y, hi.y, h)) else {
            return Crop { x: 0, y: 0, width: GRANULE.min(w), height: GRANULE.min(h) };
        };
        // Round up, then move back where the rounding runs past the image's edge.
        let round = |start: u32, side: u32, size: u32| {
            let side = side.div_ceil(GRANULE).saturating_mul(GRANULE).min(size);
            (start.min(size - side), side)
        };
        let ((x, width), (y, height)) = (round(x, cw, w), round(y, ch, h));
        Crop { x, y, width, height }
    }

    /// Whether this is the whole `width x height` image.
    pub fn is_full(&self, width: u32, height: u32) -> bool {
        *self == Crop::full(width, height)
    }

    /// The pinhole of the crop's pixels: `k` (at the full image's size) with its principal point
    /// moved by the crop's corner, at the crop's size.
    pub fn intrinsics(&self, k: &Intrinsics) -> Intrinsics {
        Intrinsics { width: self.width, height: self.height, cx: k.cx - self.x as f32, cy: k.cy - self.y as f32, ..*k }
    }

    /// The crop's `pixels` (row-major, the crop's size) at their place in a `width x height`
    /// image of `fill`; `pixels` themselves where the crop is that whole image or they are
    /// none (an image the frame did not compute).
    pub fn paste<T: Copy>(&self, pixels: Vec<T>, width: u32, height: u32, fill: T) -> Vec<T> {
        if pixels.is_empty() || self.is_full(width, height) {
            return pixels;
        }
        let mut out = vec![fill; (width * height) as usize];
        for (row, src) in pixels.chunks_exact(self.width as usize).enumerate() {
            let start = ((self.y + row as u32) * width + self.x) as usize;
            out[start..start + src.len()].copy_from_slice(src);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn looking_down_z() -> Affine3A {
        Affine3A::IDENTITY
    }

    /// The crop holds every pixel a point of the box projects to, with the margin, its sides
    /// multiples of the granule, inside the image.
    #[test]
    fn the_crop_holds_the_boxs_projection() {
        let k = Intrinsics::TUM;
        let bounds = (Vec3::new(-0.1, 0.05, 1.0), Vec3::new(0.05, 0.2, 1.3));
        let c = Crop::of_box(&k, &looking_down_z(), bounds);
        assert!(c.width.is_multiple_of(GRANULE) && c.height.is_multiple_of(GRANULE), "{c:?}");
        assert!(c.x + c.width <= k.width && c.y + c.height <= k.height, "{c:?}");
        assert!(u64::from(c.width * c.height) * 4 < u64::from(k.width * k.height), "{c:?}");
        for i in 0..=10 {
            for j in 0..=10 {
                for l in 0..=10 {
                    let t = Vec3::new(i as f32, j as f32, l as f32) / 10.0;
                    let pixel = k.project(bounds.0 + (bounds.1 - bounds.0) * t).round();
                    let (u, v) = (pixel.x as u32, pixel.y as u32);
                    assert!((c.x + MARGIN..c.x + c.width - MARGIN).contains(&u), "{u} outside {c:?}");
                    assert!((c.y + MARGIN..c.y + c.height - MARGIN).contains(&v), "{v} outside {c:?}");
                }
            }
        }
    }

    /// A box reaching behind the camera may cover any pixel: the whole image. One out of view
    /// covers none: the smallest crop. One at the image's edge is clamped into it.
    #[test]
    fn behind_out_of_view_and_at_the_edge() {
        let k = Intrinsics::TUM;
        let behind = (Vec3::new(-0.1, -0.1, -0.5), Vec3::new(0.1, 0.1, 1.0));
        assert!(Crop::of_box(&k, &looking_down_z(), behind).is_full(640, 480));
        let beside = (Vec3::new(5.0, 0.0, 1.0), Vec3::new(5.2, 0.2, 1.2));
        assert_eq!(Crop::of_box(&k, &looking_down_z(), beside), Crop { x: 0, y: 0, width: GRANULE, height: GRANULE });
        let edge = (Vec3::new(0.55, 0.3, 1.0), Vec3::new(0.9, 0.4, 1.1));
        let c = Crop::of_box(&k, &looking_down_z(), edge);
        assert_eq!(c.x + c.width, 640, "{c:?}");
        assert!(c.y > 0 && c.y + c.height < 480, "{c:?}");
    }

    /// The crop's pinhole sends each of its pixels along the full image's ray through the same
    /// pixel; pasting puts each crop pixel back at its place.
    #[test]
    fn the_crops_pinhole_is_the_images_shifted() {
        let k = Intrinsics::TUM;
        let c = Crop { x: 96, y: 64, width: 128, height: 96 };
        let ck = c.intrinsics(&k);
        for p in [Vec3::new(0.0, 0.0, 1.0), Vec3::new(-0.2, -0.1, 1.4), Vec3::new(0.1, 0.05, 0.7)] {
            let (full, cropped) = (k.project(p), ck.project(p));
            assert!((full - cropped - glam::Vec2::new(96.0, 64.0)).abs().max_element() < 1e-4);
        }
        let pixels: Vec<u32> = (0..128 * 96).collect();
        let pasted = c.paste(pixels.clone(), 640, 480, u32::MAX);
        assert_eq!(pasted.iter().filter(|&&p| p != u32::MAX).count(), pixels.len());
        assert_eq!(pasted[(64 * 640 + 96) as usize], 0);
        assert_eq!(pasted[((64 + 95) * 640 + 96 + 127) as usize], 128 * 96 - 1);
        assert_eq!(pasted[(64 * 640 + 95) as usize], u32::MAX);
        // The whole image, or no pixels: as they are.
        assert_eq!(Crop::full(128, 96).paste(pixels.clone(), 128, 96, u32::MAX), pixels);
        assert!(c.paste(Vec::new(), 640, 480, u32::MAX).is_empty());
    }
}

//! Which triangles a raster view can draw (docs/measurements/many-lights.md "VALs from every light's RSM": culling), on the
//! CPU before the draws are recorded. The scene's triangles are taken in their own order in
//! chunks of [`CHUNK_TRIANGLES`], each with its world-space bounding box, and the chunks in
//! blocks of [`BLOCK_CHUNKS`] (one box each, for a coarse first test). A view draws the chunks
//! whose box may meet its clip volume (and, for a light with a `range`, lies partly within the
//! range), as few contiguous triangle ranges, in the scene's order: a triangle the cull drops
//! could not have made a fragment in the view (or, beyond the range, only fragments that make
//! no VAL), and the ones drawn keep their order, so ties of the depth test fall as before.

use crate::gpu::scene::FlatScene;
use glam::{DVec3, DVec4, Mat4, Vec3};
use std::ops::Range;

/// Triangles per chunk: the cull's finest unit. Small enough that a chunk's box stays near its
/// triangles in a mesh stored in modelling order, large enough that the draws stay few.
pub const CHUNK_TRIANGLES: u32 = 16;
/// Chunks per block, the coarse test's unit.
pub const BLOCK_CHUNKS: u32 = 32;

/// A test keeps whatever lies within this fraction of its terms' magnitude of a plane (or of the
/// range), so that f32 rounding on the GPU never draws what the cull dropped.
const MARGIN: f64 = 1e-5;

/// World-space boxes over the scene's triangles in their order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriangleChunks {
    /// Triangles in all.
    pub triangles: u32,
    /// Triangles per chunk.
    pub chunk: u32,
    /// Per chunk of `chunk` triangles (the last may be shorter): min and max corner (m).
    pub chunks: Vec<(Vec3, Vec3)>,
    /// Per block of [`BLOCK_CHUNKS`] chunks: the box around them.
    pub blocks: Vec<(Vec3, Vec3)>,
}

impl TriangleChunks {
    /// The boxes of `flat`'s triangles as placed now, in chunks of [`CHUNK_TRIANGLES`].
    pub fn new(flat: &FlatScene) -> Self {
        Self::with_chunk(flat, CHUNK_TRIANGLES)
    }

    /// The same in chunks of `chunk` triangles (at least 1; the benchmark compares sizes).
    pub fn with_chunk(flat: &FlatScene, chunk: u32) -> Self {
        let chunk = chunk.max(1);
        let triangles = flat.triangle_count();
        let chunks: Vec<(Vec3, Vec3)> = flat
            .indices
            .chunks(3 * chunk as usize)
            .map(|corners| {
                corners.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), &i| {
                    let p = Vec3::from(flat.vertices[i as usize].position);
                    (lo.min(p), hi.max(p))
                })
            })
            .collect();
        let blocks = chunks
            .chunks(BLOCK_CHUNKS as usize)
            .map(|c| {
                c.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), b| (lo.min(b.0), hi.max(b.1)))
            })
            .collect();
        Self { triangles, chunk, chunks, blocks }
    }

    /// The triangle ranges a view draws, in order and merged where they touch: the chunks whose
    /// box may meet the clip volume of `world_to_clip` (x and y in [-w, w], z in [0, w]) and,
    /// with `sphere` (a light's position and range), comes within it. Empty when nothing can.
    pub fn visible(&self, world_to_clip: Mat4, sphere: Option<(Vec3, f32)>) -> Vec<Range<u32>> {
        let planes = clip_planes(world_to_clip);
        self.kept(|(lo, hi)| {
            !planes.iter().any(|&p| box_outside_plane(p, lo, hi))
                && sphere.is_none_or(|(c, r)| box_meets_sphere(lo, hi, c, r))
        })
    }

    /// The triangle ranges of the chunks (in blocks first) that `keep` keeps, in order and
    /// merged where they touch.
    pub fn kept(&self, keep: impl Fn((Vec3, Vec3)) -> bool) -> Vec<Range<u32>> {
        let mut ranges: Vec<Range<u32>> = Vec::new();
        for (b, &block) in self.blocks.iter().enumerate() {
            if !keep(block) {
                continue;
            }
            let first = b * BLOCK_CHUNKS as usize;
            let last = (first + BLOCK_CHUNKS as usize).min(self.chunks.len());
            for c in first..last {
                if !keep(self.chunks[c]) {
                    continue;
                }
                let start = c as u32 * self.chunk;
                let end = (start + self.chunk).min(self.triangles);
                match ranges.last_mut() {
                    Some(r) if r.end == start => r.end = end,
                    _ => ranges.push(start..end),
                }
            }
        }
        ranges
    }
}

/// The six planes `(a, b, c, d)` of a clip volume with depth in [0, w] (wgpu's): a world point
/// `p` is inside where `a p.x + b p.y + c p.z + d >= 0` for all six.
pub fn clip_planes(world_to_clip: Mat4) -> [DVec4; 6] {
    let m = world_to_clip.as_dmat4();
    let row = |i: usize| DVec4::new(m.x_axis[i], m.y_axis[i], m.z_axis[i], m.w_axis[i]);
    let (x, y, z, w) = (row(0), row(1), row(2), row(3));
    [w + x, w - x, w + y, w - y, z, w - z]
}

/// Whether the box `[lo, hi]` lies wholly on the outer side of `plane` (by more than the
/// margin): its corner farthest along the plane's normal is outside.
pub fn box_outside_plane(plane: DVec4, lo: Vec3, hi: Vec3) -> bool {
    let (lo, hi) = (DVec3::from(lo), DVec3::from(hi));
    let n = plane.truncate();
    let far = DVec3::select(n.cmpge(DVec3::ZERO), hi, lo);
    let value = n.dot(far) + plane.w;
    let magnitude = n.abs().dot(far.abs()) + plane.w.abs();
    value < -MARGIN * magnitude
}

/// Whether some point of the box `[lo, hi]` lies in front of the plane through `point` with unit
/// normal `normal`, or behind it by at most `slack` times the box's diagonal (a raster that
/// accepts fragments a little outside a triangle, as the paraboloid maps' does, can reach that
/// far past it).
pub fn box_reaches_front(lo: Vec3, hi: Vec3, point: Vec3, normal: Vec3, slack: f32) -> bool {
    let (lo, hi, n, p) = (DVec3::from(lo), DVec3::from(hi), DVec3::from(normal), DVec3::from(point));
    let far = DVec3::select(n.cmpge(DVec3::ZERO), hi, lo);
    let reach = slack as f64 * (hi - lo).length();
    (far - p).dot(n) >= -reach - MARGIN * (far.abs() + p.abs()).dot(n.abs())
}

/// Whether some point of the box `[lo, hi]` lies within `radius` of `centre` (up to the margin).
pub fn box_meets_sphere(lo: Vec3, hi: Vec3, centre: Vec3, radius: f32) -> bool {
    let (lo, hi, c) = (DVec3::from(lo), DVec3::from(hi), DVec3::from(centre));
    let nearest = c.clamp(lo, hi);
    nearest.distance(c) <= radius as f64 * (1.0 + MARGIN)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::raw::RawVertex;

    /// A 90° view from the origin down -Z (near 0.1, far 10): what lies in front within the
    /// pyramid is kept, what lies behind, beside or past the far plane is not.
    #[test]
    fn boxes_against_a_frustum_known_answers() {
        let m = glam::camera::rh::proj::directx::perspective(std::f32::consts::FRAC_PI_2, 1.0, 0.1, 10.0);
        let planes = clip_planes(m);
        let outside = |lo: Vec3, hi: Vec3| planes.iter().any(|&p| box_outside_plane(p, lo, hi));
        let cube = |c: Vec3| (c - 0.1, c + 0.1);
        let (lo, hi) = cube(Vec3::new(0.0, 0.0, -5.0));
        assert!(!outside(lo, hi), "in front");
        let (lo, hi) = cube(Vec3::new(0.0, 0.0, 5.0));
        assert!(outside(lo, hi), "behind");
        let (lo, hi) = cube(Vec3::new(3.0, 0.0, -1.0));
        assert!(outside(lo, hi), "right of the 45° side plane");
        let (lo, hi) = cube(Vec3::new(0.0, -3.0, -1.0));
        assert!(outside(lo, hi), "below");
        let (lo, hi) = cube(Vec3::new(0.0, 0.0, -12.0));
        assert!(outside(lo, hi), "past the far plane");
        // Straddling the side plane x = -z: kept.
        let (lo, hi) = cube(Vec3::new(1.0, 0.0, -1.0));
        assert!(!outside(lo, hi), "on the side plane");
        // A box around the eye meets the volume.
        assert!(!outside(Vec3::splat(-1.0), Vec3::splat(1.0)));
    }

    #[test]
    fn boxes_against_a_sphere_known_answers() {
        let (lo, hi) = (Vec3::new(1.0, -1.0, -1.0), Vec3::new(2.0, 1.0, 1.0));
        assert!(box_meets_sphere(lo, hi, Vec3::ZERO, 1.0), "touches at x = 1");
        assert!(!box_meets_sphere(lo, hi, Vec3::ZERO, 0.99));
        assert!(box_meets_sphere(lo, hi, Vec3::new(1.5, 0.0, 0.0), 0.01), "centre inside");
        // Nearest point (2, 1, 1) from (3, 2, 2): sqrt(3) = 1.73205.
        assert!(box_meets_sphere(lo, hi, Vec3::new(3.0, 2.0, 2.0), 1.7321));
        assert!(!box_meets_sphere(lo, hi, Vec3::new(3.0, 2.0, 2.0), 1.73));
    }

    #[test]
    fn boxes_against_a_plane_known_answers() {
        let (lo, hi) = (Vec3::new(-1.0, -2.0, -1.0), Vec3::new(1.0, -1.0, 1.0));
        // Wholly below y = 0 by 1 m; the diagonal is sqrt(9) = 3 m.
        assert!(!box_reaches_front(lo, hi, Vec3::ZERO, Vec3::Y, 0.0));
        assert!(!box_reaches_front(lo, hi, Vec3::ZERO, Vec3::Y, 0.33), "0.99 m of slack");
        assert!(box_reaches_front(lo, hi, Vec3::ZERO, Vec3::Y, 0.34), "1.02 m of slack");
        assert!(box_reaches_front(lo, hi, Vec3::ZERO, -Vec3::Y, 0.0), "in front of the flipped plane");
        assert!(box_reaches_front(lo, hi, Vec3::new(0.0, -1.5, 0.0), Vec3::Y, 0.0), "straddling");
    }

    /// Thin triangles along the -Z axis, triangle t over z in [-(t + 1) s, -t s] (s = 5 m per
    /// chunk), so chunk c spans z in [-5 (c + 1), -5 c]: the far plane, the range and the view's
    /// direction select known chunks, returned as merged ranges in order.
    #[test]
    fn visible_ranges_follow_the_boxes_in_order() {
        let n = 3 * CHUNK_TRIANGLES * BLOCK_CHUNKS + 5;
        let mut flat = FlatScene::default();
        for t in 0..n {
            // Triangle t spans z in [-(t + 1) * s, -t * s] with s = 10 / (2 CHUNK_TRIANGLES).
            let s = 10.0 / (2 * CHUNK_TRIANGLES) as f32;
            let (z0, z1) = (-(t as f32) * s - 0.01, -(t as f32 + 1.0) * s);
            for p in [Vec3::new(-0.01, 0.0, z0), Vec3::new(0.01, 0.0, z0), Vec3::new(0.0, 0.01, z1)] {
                flat.indices.push(flat.vertices.len() as u32);
                flat.vertices.push(RawVertex { position: p.into(), ..Default::default() });
            }
            flat.triangle_materials.push(0);
        }
        let chunks = TriangleChunks::new(&flat);
        assert_eq!(chunks.chunks.len() as u32, n.div_ceil(CHUNK_TRIANGLES));
        assert_eq!(chunks.blocks.len(), 4);
        // Chunk c spans z down to -(c + 1) * 5 m: far 10 keeps chunks 0 and 1 only, in one range.
        let m = glam::camera::rh::proj::directx::perspective(std::f32::consts::FRAC_PI_2, 1.0, 0.001, 9.9);
        assert_eq!(chunks.visible(m, None), vec![0..2 * CHUNK_TRIANGLES]);
        // Looking up +Z instead (the view turned round): nothing.
        let back = m * Mat4::from_rotation_y(std::f32::consts::PI);
        assert_eq!(chunks.visible(back, None), vec![]);
        // A range of 4.9 m from the eye: chunk 0 alone.
        assert_eq!(chunks.visible(m, Some((Vec3::ZERO, 4.9))), vec![0..CHUNK_TRIANGLES]);
        // A sphere around the far end (z = -n s) but no far plane to speak of: the last chunk.
        let far = glam::camera::rh::proj::directx::perspective(std::f32::consts::FRAC_PI_2, 1.0, 0.001, 1e4);
        let end = -(n as f32) * 10.0 / (2 * CHUNK_TRIANGLES) as f32;
        let last = (n - 1) / CHUNK_TRIANGLES * CHUNK_TRIANGLES;
        assert_eq!(chunks.visible(far, Some((Vec3::new(0.0, 0.0, end), 0.05))), vec![last..n]);
        // Everything, as one range.
        assert_eq!(chunks.visible(far, None), vec![0..n]);
    }
}

//! A bounding volume hierarchy over the scene's triangles for exact visibility (DESIGN.md §5),
//! built here on the CPU and traversed on the GPU by `shaders/bvh.wgsl`; `occluded` below is
//! the traversal's twin, `ray_triangle` the intersection's.

use glam::Vec3;

/// Triangles per leaf at most.
pub const LEAF_SIZE: usize = 4;
/// `|det|` below this fraction of `|e1| |e2| |d|` (the sine of the angle between the ray and the
/// triangle's plane, times the sine of the triangle's smallest angle) counts as parallel.
pub const RAY_PARALLEL_EPSILON: f32 = 1e-5;
/// Depth of the tree at most (a bound on the build's recursion).
pub const MAX_DEPTH: usize = 32;

/// One node, as the GPU reads it (`BvhNode` in `shaders/bvh.wgsl`). Nodes are in depth-first
/// order, so an inner node's first child is `index + 1`. A leaf (`count > 0`) holds
/// `order[first .. first + count]` and is followed by `index + 1`; an inner node's `first` is
/// its miss link, the index just past its subtree. Traversal therefore needs no stack: on lavapipe
/// a dynamically indexed per-invocation stack lost hits under divergence.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct BvhNode {
    pub min: [f32; 3],
    pub first: u32,
    pub max: [f32; 3],
    pub count: u32,
}

/// The hierarchy: nodes in depth-first order and the triangle order its leaves index.
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    pub nodes: Vec<BvhNode>,
    /// Triangle indices (into the scene's triangle list) in leaf order.
    pub order: Vec<u32>,
}

impl Bvh {
    /// Median split on the longest axis of the centroids' bounds.
    pub fn build(positions: &[Vec3], triangles: &[[u32; 3]]) -> Self {
        let centroids: Vec<Vec3> =
            triangles.iter().map(|t| t.iter().map(|&i| positions[i as usize]).sum::<Vec3>() / 3.0).collect();
        let mut bvh = Bvh { nodes: Vec::new(), order: (0..triangles.len() as u32).collect() };
        if !triangles.is_empty() {
            bvh.split(positions, triangles, &centroids, 0, triangles.len(), 0);
        }
        bvh
    }

    fn split(&mut self, p: &[Vec3], tris: &[[u32; 3]], c: &[Vec3], lo: usize, hi: usize, depth: usize) {
        let (mut min, mut max) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
        let (mut cmin, mut cmax) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
        for &t in &self.order[lo..hi] {
            for &v in &tris[t as usize] {
                min = min.min(p[v as usize]);
                max = max.max(p[v as usize]);
            }
            cmin = cmin.min(c[t as usize]);
            cmax = cmax.max(c[t as usize]);
        }
        let index = self.nodes.len();
        self.nodes.push(BvhNode { min: min.into(), first: lo as u32, max: max.into(), count: (hi - lo) as u32 });
        let extent = cmax - cmin;
        if hi - lo <= LEAF_SIZE || depth + 1 >= MAX_DEPTH || extent.max_element() <= 0.0 {
            return;
        }
        let axis = if extent.x >= extent.y && extent.x >= extent.z {
            0
        } else if extent.y >= extent.z {
            1
        } else {
            2
        };
        let mid = (lo + hi) / 2;
        self.order[lo..hi]
            .select_nth_unstable_by(mid - lo, |a, b| c[*a as usize][axis].total_cmp(&c[*b as usize][axis]));
        self.split(p, tris, c, lo, mid, depth + 1);
        self.split(p, tris, c, mid, hi, depth + 1);
        self.nodes[index].first = self.nodes.len() as u32;
        self.nodes[index].count = 0;
    }

    /// Whether any triangle blocks the open segment from `origin` to `target` (twin of
    /// `occluded` in `shaders/bvh.wgsl`).
    pub fn occluded(&self, positions: &[Vec3], triangles: &[[u32; 3]], origin: Vec3, target: Vec3) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let d = target - origin;
        let inv = d.recip();
        let mut index = 0;
        while index < self.nodes.len() {
            let node = self.nodes[index];
            let enter = segment_hits_box(origin, inv, node.min.into(), node.max.into());
            if enter && node.count > 0 {
                for &t in &self.order[node.first as usize..(node.first + node.count) as usize] {
                    let [a, b, c] = triangles[t as usize].map(|i| positions[i as usize]);
                    if ray_triangle(origin, d, a, b, c).is_some_and(|t| t > 0.0 && t < 1.0) {
                        return true;
                    }
                }
            }
            index = if enter || node.count > 0 { index + 1 } else { (node.first as usize).max(index + 1) };
        }
        false
    }
}

/// Slab test of the segment `origin + s * d`, s in [0, 1] (`inv` = 1 / d), against a box.
pub fn segment_hits_box(origin: Vec3, inv: Vec3, min: Vec3, max: Vec3) -> bool {
    let t0 = (min - origin) * inv;
    let t1 = (max - origin) * inv;
    let near = t0.min(t1).max_element().max(0.0);
    let far = t0.max(t1).min_element().min(1.0);
    near <= far
}

/// Möller–Trumbore: parameter `t` along `d` where the ray `origin + t d` meets triangle
/// (`a`, `b`, `c`), two-sided; `None` when it misses or runs parallel.
pub fn ray_triangle(origin: Vec3, d: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Option<f32> {
    let e1 = b - a;
    let e2 = c - a;
    let p = d.cross(e2);
    let det = e1.dot(p);
    // Relative: a degenerate (collinear) triangle's det is rounding noise whose sign and size
    // depend on the float pipeline (FMA contraction made it a phantom hit on the GPU).
    if det.abs() <= RAY_PARALLEL_EPSILON * e1.length() * e2.length() * d.length() {
        return None;
    }
    let inv_det = 1.0 / det;
    let s = origin - a;
    let u = s.dot(p) * inv_det;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = d.dot(q) * inv_det;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    Some(e2.dot(q) * inv_det)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// The BVH traversal agrees with testing every triangle, on random segments through a soup
    /// of random triangles (exact agreement: both use the same intersection routine, so only a
    /// traversal bug can make them differ).
    #[test]
    fn traversal_agrees_with_brute_force_loop() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut r = |lo: f32, hi: f32| rng.random_range(lo..hi);
        let mut positions = Vec::new();
        let mut triangles = Vec::new();
        for i in 0..2000u32 {
            let c = Vec3::new(r(-5.0, 5.0), r(-5.0, 5.0), r(-5.0, 5.0));
            for _ in 0..3 {
                positions.push(c + Vec3::new(r(-0.3, 0.3), r(-0.3, 0.3), r(-0.3, 0.3)));
            }
            triangles.push([3 * i, 3 * i + 1, 3 * i + 2]);
        }
        let bvh = Bvh::build(&positions, &triangles);
        assert!(bvh.nodes.len() > 500);
        let (mut hits, mut misses) = (0, 0);
        for _ in 0..3000 {
            let o = Vec3::new(r(-6.0, 6.0), r(-6.0, 6.0), r(-6.0, 6.0));
            let t = Vec3::new(r(-6.0, 6.0), r(-6.0, 6.0), r(-6.0, 6.0));
            let brute = triangles.iter().any(|tri| {
                let [a, b, c] = tri.map(|i| positions[i as usize]);
                ray_triangle(o, t - o, a, b, c).is_some_and(|s| s > 0.0 && s < 1.0)
            });
            assert_eq!(bvh.occluded(&positions, &triangles, o, t), brute, "segment {o} -> {t}");
            if brute { hits += 1 } else { misses += 1 }
        }
        assert!(hits > 300 && misses > 300, "both outcomes exercised: {hits} hits, {misses} misses");
    }

    #[test]
    fn ray_triangle_hits_and_misses() {
        let (a, b, c) = (Vec3::ZERO, Vec3::X, Vec3::Y);
        let t = ray_triangle(Vec3::new(0.2, 0.2, 1.0), Vec3::new(0.0, 0.0, -2.0), a, b, c).unwrap();
        assert!((t - 0.5).abs() < 1e-6);
        assert!(ray_triangle(Vec3::new(0.8, 0.8, 1.0), Vec3::new(0.0, 0.0, -2.0), a, b, c).is_none());
        assert!(ray_triangle(Vec3::new(0.2, 0.2, 1.0), Vec3::X, a, b, c).is_none(), "parallel");
    }
}

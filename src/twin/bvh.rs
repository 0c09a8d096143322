//! The bounding volume hierarchies over the scene's triangles for exact visibility (DESIGN.md §5),
//! both built by the `obvhs` crate from the same PLOC build (its `medium_build` preset, no
//! spatial splits):
//!
//! - [`Bvh`], for the GPU pass: obvhs's binary tree (with SAH-driven leaf collapsing) flattened
//!   into the stackless depth-first layout that `shaders/bvh.wgsl` traverses. [`Bvh::occluded`]
//!   is that traversal's twin.
//! - [`TraceBvh`], for the CPU exact reference (`twin::exact_cpu`): obvhs's compressed 8-wide
//!   BVH (CWBVH), its fastest CPU traversal (SIMD node tests, ordered children), with an
//!   early exit at the first blocker for shadow rays ([`TraceBvh::segment_blocked`]) and a
//!   closest-hit query for primary rays ([`TraceBvh::closest_hit`]). Its triangles are stored in
//!   the tree's leaf order with their edges precomputed ([`EdgeTriangle`]).
//!
//! Every traversal decides a triangle with the same Möller–Trumbore arithmetic
//! ([`ray_triangle`], [`EdgeTriangle::hit`]), so CPU and GPU decide each shadow ray alike.

use glam::{Vec2, Vec3, Vec3A};
use obvhs::bvh2::Bvh2;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::Ray;

/// `|det|` below this fraction of `|e1| |e2| |d|` (the sine of the angle between the ray and the
/// triangle's plane, times the sine of the triangle's smallest angle) counts as parallel.
pub const RAY_PARALLEL_EPSILON: f32 = 1e-5;

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

/// The GPU pass's hierarchy: obvhs's binary tree, flattened.
#[derive(Clone, Default)]
pub struct Bvh {
    /// The GPU layout: nodes in depth-first order with miss links.
    pub nodes: Vec<BvhNode>,
    /// Triangle indices (into the scene's triangle list) in leaf order.
    pub order: Vec<u32>,
}

/// A triangle prepared for the CPU traversal: its first corner, its two edges and
/// `RAY_PARALLEL_EPSILON |e1| |e2|`, computed once with the same operations [`ray_triangle`]
/// performs per ray, so [`EdgeTriangle::hit`] returns bit for bit what [`ray_triangle_hit`] does.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EdgeTriangle {
    a: Vec3,
    e1: Vec3,
    e2: Vec3,
    /// `RAY_PARALLEL_EPSILON * |e1| * |e2|`.
    parallel: f32,
}

impl EdgeTriangle {
    pub fn new(a: Vec3, b: Vec3, c: Vec3) -> Self {
        let (e1, e2) = (b - a, c - a);
        Self { a, e1, e2, parallel: RAY_PARALLEL_EPSILON * e1.length() * e2.length() }
    }

    /// [`ray_triangle_hit`] with `d_length = |d|`.
    #[inline(always)]
    pub fn hit(&self, origin: Vec3, d: Vec3, d_length: f32) -> Option<(f32, Vec2)> {
        let p = d.cross(self.e2);
        let det = self.e1.dot(p);
        // Relative: a degenerate (collinear) triangle's det is rounding noise whose sign and size
        // depend on the float pipeline (FMA contraction made it a phantom hit on the GPU).
        if det.abs() <= self.parallel * d_length {
            return None;
        }
        let inv_det = 1.0 / det;
        let s = origin - self.a;
        let u = s.dot(p) * inv_det;
        if !(0.0..=1.0).contains(&u) {
            return None;
        }
        let q = s.cross(self.e1);
        let v = d.dot(q) * inv_det;
        if v < 0.0 || u + v > 1.0 {
            return None;
        }
        Some((self.e2.dot(q) * inv_det, Vec2::new(u, v)))
    }
}

/// The CPU reference's hierarchy: obvhs's CWBVH and its triangles in leaf order.
#[derive(Clone, Default)]
pub struct TraceBvh {
    tree: CwBvh,
    /// `triangles[k]` is the scene's triangle `tree.primitive_indices[k]`, so a leaf's triangles
    /// are contiguous in memory.
    triangles: Vec<EdgeTriangle>,
}

/// A ray's closest intersection: the scene's triangle, the distance along the ray's direction
/// and the barycentrics `(u, v)` of `FlatScene::surface_at` (weights of the second and third
/// corner).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriangleHit {
    pub triangle: u32,
    pub t: f32,
    pub barycentrics: Vec2,
}

/// The scene's triangles as obvhs's input.
fn obvhs_triangles(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<obvhs::triangle::Triangle> {
    triangles
        .iter()
        .map(|t| {
            let [v0, v1, v2] = t.map(|i| Vec3A::from(positions[i as usize]));
            obvhs::triangle::Triangle { v0, v1, v2 }
        })
        .collect()
}

impl Bvh {
    /// Build over `triangles` (corner indices into `positions`) with obvhs.
    pub fn build(positions: &[Vec3], triangles: &[[u32; 3]]) -> Self {
        if triangles.is_empty() {
            return Self::default();
        }
        let tris = obvhs_triangles(positions, triangles);
        let params = obvhs::BvhBuildParams::medium_build();
        let tree = obvhs::bvh2::builder::build_bvh2_from_tris(&tris, params, &mut Default::default());
        let (nodes, order) = flatten(&tree);
        Self { nodes, order }
    }

    /// Whether any triangle blocks the open segment from `origin` to `target`, through the
    /// flattened GPU layout (twin of `occluded` in `shaders/bvh.wgsl`).
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

impl TraceBvh {
    /// Build over `triangles` (corner indices into `positions`) with obvhs: PLOC, reinsertion,
    /// then the BVH2-to-CWBVH conversion with at most 3 triangles per leaf (its limit).
    pub fn build(positions: &[Vec3], triangles: &[[u32; 3]]) -> Self {
        if triangles.is_empty() {
            return Self::default();
        }
        let tris = obvhs_triangles(positions, triangles);
        let params = obvhs::BvhBuildParams::medium_build();
        let tree = obvhs::cwbvh::builder::build_cwbvh_from_tris(&tris, params, &mut Default::default());
        let triangles = tree
            .primitive_indices
            .iter()
            .map(|&i| {
                let [a, b, c] = triangles[i as usize].map(|v| positions[v as usize]);
                EdgeTriangle::new(a, b, c)
            })
            .collect();
        Self { tree, triangles }
    }

    /// Whether any triangle blocks the open segment from `origin` to `target` (the same
    /// question as [`Bvh::occluded`]): obvhs's CWBVH traversal, stopped at the first blocker.
    #[inline]
    pub fn segment_blocked(&self, origin: Vec3, target: Vec3) -> bool {
        if self.triangles.is_empty() {
            return false;
        }
        let d = target - origin;
        let d_length = d.length();
        let ray = Ray::new(origin.into(), d.into(), 0.0, 1.0);
        !self.tree.ray_traverse_miss(ray, |_, k| match self.triangles[k].hit(origin, d, d_length) {
            Some((t, _)) if t > 0.0 && t < 1.0 => t,
            _ => f32::INFINITY,
        })
    }

    /// The nearest triangle the ray `origin + t direction`, t > 0, meets (obvhs's closest-hit
    /// traversal).
    pub fn closest_hit(&self, origin: Vec3, direction: Vec3) -> Option<TriangleHit> {
        if self.triangles.is_empty() {
            return None;
        }
        let ray = Ray::new(origin.into(), direction.into(), 0.0, f32::INFINITY);
        let d_length = direction.length();
        let mut hit = obvhs::ray::RayHit::none();
        let mut best: Option<(f32, Vec2)> = None;
        self.tree.ray_traverse(ray, &mut hit, |_, k| match self.triangles[k].hit(origin, direction, d_length) {
            Some((t, uv)) if t > 0.0 && best.is_none_or(|(bt, _)| t < bt) => {
                best = Some((t, uv));
                t
            }
            _ => f32::INFINITY,
        });
        let (t, barycentrics) = best?;
        Some(TriangleHit { triangle: self.tree.primitive_indices[hit.primitive_id as usize], t, barycentrics })
    }
}

/// obvhs's tree in depth-first order with miss links ([`BvhNode`]), and the leaves' triangles.
fn flatten(tree: &Bvh2) -> (Vec<BvhNode>, Vec<u32>) {
    enum Step {
        Visit(usize),
        /// Set the miss link of the flattened node at this index: its subtree is done.
        Close(usize),
    }
    let mut nodes = Vec::with_capacity(tree.nodes.len());
    let mut order = Vec::with_capacity(tree.primitive_indices.len());
    let mut stack = vec![Step::Visit(0)];
    while let Some(step) = stack.pop() {
        match step {
            Step::Visit(i) => {
                let n = &tree.nodes[i];
                let at = nodes.len();
                nodes.push(BvhNode { min: n.aabb.min.into(), first: 0, max: n.aabb.max.into(), count: 0 });
                if n.is_leaf() {
                    let first = n.first_index as usize;
                    nodes[at].first = order.len() as u32;
                    nodes[at].count = n.prim_count;
                    order.extend_from_slice(&tree.primitive_indices[first..first + n.prim_count as usize]);
                } else {
                    let left = n.first_index as usize;
                    stack.extend([Step::Close(at), Step::Visit(left + 1), Step::Visit(left)]);
                }
            }
            Step::Close(at) => nodes[at].first = nodes.len() as u32,
        }
    }
    (nodes, order)
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
    ray_triangle_hit(origin, d, a, b, c).map(|(t, _)| t)
}

/// [`ray_triangle`] with the barycentrics `(u, v)` of the hit (weights of `b` and `c`).
pub fn ray_triangle_hit(origin: Vec3, d: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Option<(f32, Vec2)> {
    EdgeTriangle::new(a, b, c).hit(origin, d, d.length())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Both traversals (the GPU layout's twin and obvhs's CWBVH with early exit) agree with testing every
    /// triangle, on random segments through a soup of random triangles, and the closest hit with
    /// the nearest of all triangles (exact agreement: every path uses the same intersection
    /// routine, so only a traversal or flattening bug can make them differ).
    #[test]
    fn traversals_agree_with_brute_force_loop() {
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
        let wide = TraceBvh::build(&positions, &triangles);
        assert!(bvh.nodes.len() > 200, "a tree, not a list: {} nodes", bvh.nodes.len());
        let mut seen = bvh.order.clone();
        seen.sort_unstable();
        assert_eq!(seen, (0..2000).collect::<Vec<u32>>(), "every triangle in exactly one leaf");
        let (mut hits, mut misses) = (0, 0);
        for _ in 0..3000 {
            let o = Vec3::new(r(-6.0, 6.0), r(-6.0, 6.0), r(-6.0, 6.0));
            let t = Vec3::new(r(-6.0, 6.0), r(-6.0, 6.0), r(-6.0, 6.0));
            let corners = |tri: &[u32; 3]| tri.map(|i| positions[i as usize]);
            let brute = triangles.iter().any(|tri| {
                let [a, b, c] = corners(tri);
                ray_triangle(o, t - o, a, b, c).is_some_and(|s| s > 0.0 && s < 1.0)
            });
            assert_eq!(bvh.occluded(&positions, &triangles, o, t), brute, "GPU layout: segment {o} -> {t}");
            assert_eq!(wide.segment_blocked(o, t), brute, "obvhs CWBVH: segment {o} -> {t}");
            let nearest = triangles
                .iter()
                .enumerate()
                .filter_map(|(k, tri)| {
                    let [a, b, c] = corners(tri);
                    ray_triangle(o, t - o, a, b, c).filter(|s| *s > 0.0).map(|s| (k as u32, s))
                })
                .min_by(|x, y| x.1.total_cmp(&y.1));
            let closest = wide.closest_hit(o, t - o);
            assert_eq!(closest.map(|h| (h.triangle, h.t)), nearest, "closest hit along {o} -> {t}");
            if brute { hits += 1 } else { misses += 1 }
        }
        assert!(hits > 300 && misses > 300, "both outcomes exercised: {hits} hits, {misses} misses");
    }

    #[test]
    fn empty_and_single_triangle_scenes() {
        assert!(Bvh::build(&[], &[]).nodes.is_empty());
        let empty = TraceBvh::build(&[], &[]);
        assert!(!empty.segment_blocked(Vec3::ZERO, Vec3::ONE) && empty.closest_hit(Vec3::ZERO, Vec3::X).is_none());
        let (corners, tris) = ([Vec3::ZERO, Vec3::X, Vec3::Y], [[0, 1, 2]]);
        let one = Bvh::build(&corners, &tris);
        let wide = TraceBvh::build(&corners, &tris);
        assert_eq!(one.nodes.len(), 1);
        let (o, t) = (Vec3::new(0.2, 0.3, 1.0), Vec3::new(0.2, 0.3, -1.0));
        assert!(one.occluded(&corners, &tris, o, t) && wide.segment_blocked(o, t));
        let hit = wide.closest_hit(o, Vec3::NEG_Z).unwrap();
        assert!((hit.t - 1.0).abs() < 1e-6 && (hit.barycentrics - Vec2::new(0.2, 0.3)).length() < 1e-6, "{hit:?}");
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

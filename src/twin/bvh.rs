//! The bounding volume hierarchies over the scene's triangles for exact visibility (docs/design.md §5),
//! both built by the `obvhs` crate from the same PLOC build (its `medium_build` preset, no
//! spatial splits):
//!
//! - [`Bvh`], for the GPU pass: obvhs's binary tree (with SAH-driven leaf collapsing) flattened
//!   into the stackless depth-first layout that `shaders/bvh.wgsl` traverses. [`Bvh::occluded`]
//!   is that traversal's twin.
//! - [`TraceBvh`], for the CPU exact reference (`twin::exact_cpu`): obvhs's compressed 8-wide
//!   BVH (CWBVH, its `very_slow_build` preset: a reference builds it once per frame, and the
//!   better tree traces 1.2-1.7x faster on the fixtures, see `examples/exact_rays.rs`), its
//!   fastest CPU traversal (SIMD node tests, ordered children), with an early exit at the first
//!   blocker for shadow rays ([`TraceBvh::segment_blocked`]) and a closest-hit query for primary
//!   rays ([`TraceBvh::closest_hit`]). Its triangles are stored in the tree's leaf order with their
//!   edges precomputed ([`EdgeTriangle`]).
//!
//! A receiver's shadow rays all leave one point, toward VALs that lie close together when they
//! are taken in space-filling-curve order; [`TraceBvh::shadow_rays`] traces such bundles as
//! packets through obvhs's traversal macro (one interval-arithmetic test of the bundle's cone per
//! node instead of one test per ray, [`ShadowTraversal::Packets`]) and remembers the last blocker,
//! which the next ray tests first. Both only skip work: every ray is still decided by its own
//! triangle test.
//!
//! Every traversal decides a triangle with the same Möller–Trumbore arithmetic
//! ([`ray_triangle`], [`EdgeTriangle::hit`]), so CPU and GPU decide each shadow ray alike.

use glam::{UVec2, Vec2, Vec3, Vec3A};
use obvhs::bvh2::Bvh2;
use obvhs::cwbvh::CwBvh;
use obvhs::cwbvh::node::extract_byte64;
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

    /// Whether the triangle blocks the open segment `origin + t d`, t in (0, 1).
    #[inline(always)]
    fn blocks(&self, origin: Vec3, d: Vec3, d_length: f32) -> bool {
        matches!(self.hit(origin, d, d_length), Some((t, _)) if t > 0.0 && t < 1.0)
    }
}

/// How [`TraceBvh::shadow_rays`] walks the tree. Both decide every ray alike (each by its own
/// triangle tests); they differ only in cost, which depends on the scene: packets pay where a
/// receiver's rays to neighbouring VALs pass the same nodes (`cornell_bunny.json`: 2.4x the
/// single rays), single rays where the bundles' cones sweep much more geometry than their rays
/// do (`sponza_bunny.json`: packets 0.12x). `examples/exact_rays.rs` measures both.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ShadowTraversal {
    /// One ray at a time, obvhs's traversal.
    Single,
    /// Bundles of up to [`PACKET_RAYS`] consecutive targets whose directions from the origin lie
    /// within [`PACKET_SPREAD`] of each other (the diagonal of their unit directions' bounding
    /// box), traversed together when they number at least [`PACKET_MIN_RAYS`].
    Packets,
}

/// Rays per packet at most (the width of the active-ray mask).
pub const PACKET_RAYS: usize = 32;
/// The largest spread of unit directions in one packet: the diagonal of their bounding box
/// (0.1 is about 6°; 0.05 and 0.2 traced 5-10 % slower on `cornell_bunny.json`).
pub const PACKET_SPREAD: f32 = 0.1;
/// Fewer rays than this are traced one by one: the packet's node test costs more than a ray's.
pub const PACKET_MIN_RAYS: usize = 8;

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

/// Triangles with the GPU layout's tree over them: what the twins of the GPU passes trace their
/// shadow rays against.
#[derive(Clone, Default)]
pub struct Occluders {
    pub positions: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
    pub bvh: Bvh,
}

impl Occluders {
    /// The tree over `triangles` (corner indices into `positions`).
    pub fn new(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Self {
        let bvh = Bvh::build(&positions, &triangles);
        Self { positions, triangles, bvh }
    }

    /// [`Bvh::occluded`] from `origin` to each of at most [`PACKET_RAYS`] `targets`: bit `j` is
    /// set when the segment to `targets[j]` is blocked (the shape of [`TraceBvh::blocked_mask`]).
    pub fn blocked_mask(&self, origin: Vec3, targets: &[Vec3]) -> u32 {
        assert!(targets.len() <= PACKET_RAYS, "{} targets in one mask", targets.len());
        targets.iter().enumerate().fold(0, |mask, (j, &target)| {
            mask | u32::from(self.bvh.occluded(&self.positions, &self.triangles, origin, target)) << j
        })
    }
}

impl TraceBvh {
    /// Build over `triangles` (corner indices into `positions`) with obvhs: large triangles
    /// pre-split, PLOC, reinsertion, then the BVH2-to-CWBVH conversion with at most 3 triangles
    /// per leaf (its limit).
    pub fn build(positions: &[Vec3], triangles: &[[u32; 3]]) -> Self {
        Self::build_with(positions, triangles, obvhs::BvhBuildParams::very_slow_build())
    }

    /// [`TraceBvh::build`] with another of obvhs's build presets (`examples/exact_rays.rs`
    /// times the trees against each other).
    pub fn build_with(positions: &[Vec3], triangles: &[[u32; 3]], params: obvhs::BvhBuildParams) -> Self {
        if triangles.is_empty() {
            return Self::default();
        }
        let tris = obvhs_triangles(positions, triangles);
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
        !self.triangles.is_empty() && self.segment_blocker(origin, target, None).is_some()
    }

    /// The first blocker found on the open segment from `origin` to `target` (its leaf-order
    /// index), testing `cached` first: a receiver's consecutive rays are often blocked by the
    /// same triangle.
    #[inline]
    fn segment_blocker(&self, origin: Vec3, target: Vec3, cached: Option<usize>) -> Option<usize> {
        let d = target - origin;
        let d_length = d.length();
        if let Some(k) = cached.filter(|&k| self.triangles[k].blocks(origin, d, d_length)) {
            return Some(k);
        }
        if d_length == 0.0 {
            return None;
        }
        let ray = traversal_ray(origin, d / d_length, d_length);
        let mut found = None;
        let miss = self.tree.ray_traverse_miss(ray, |_, k| {
            if self.triangles[k].blocks(origin, d, d_length) {
                found = Some(k);
                0.0
            } else {
                f32::INFINITY
            }
        });
        if miss { None } else { found }
    }

    /// Which of the open segments from `origin` to each of `targets` a triangle blocks:
    /// `blocked[j]` for `targets[j]` (resized to match). Exactly [`TraceBvh::segment_blocked`]
    /// for each, but cheaper: the last blocker is tested first, and with
    /// [`ShadowTraversal::Packets`] runs of targets in similar directions are traced together, so
    /// `targets` should come in a spatially coherent order (the VALs sorted along a
    /// space-filling curve).
    pub fn shadow_rays(&self, origin: Vec3, targets: &[Vec3], traversal: ShadowTraversal, blocked: &mut Vec<bool>) {
        blocked.clear();
        blocked.resize(targets.len(), false);
        self.trace(origin, targets, traversal, |j| blocked[j] = true);
    }

    /// [`TraceBvh::shadow_rays`] for at most [`PACKET_RAYS`] targets, as a mask: bit `j` is set
    /// when the segment to `targets[j]` is blocked.
    pub fn blocked_mask(&self, origin: Vec3, targets: &[Vec3], traversal: ShadowTraversal) -> u32 {
        assert!(targets.len() <= PACKET_RAYS, "{} targets in one mask", targets.len());
        let mut mask = 0u32;
        self.trace(origin, targets, traversal, |j| mask |= 1 << j);
        mask
    }

    /// The shadow rays of [`TraceBvh::shadow_rays`]: `blocked(j)` for each blocked `targets[j]`.
    fn trace(&self, origin: Vec3, targets: &[Vec3], traversal: ShadowTraversal, mut blocked: impl FnMut(usize)) {
        if self.triangles.is_empty() {
            return;
        }
        let mut cached = None;
        let mut i = 0;
        while i < targets.len() {
            let end = match traversal {
                ShadowTraversal::Single => i + 1,
                ShadowTraversal::Packets => packet_end(origin, targets, i),
            };
            if end - i < PACKET_MIN_RAYS {
                for (j, &target) in targets.iter().enumerate().take(end).skip(i) {
                    let found = self.segment_blocker(origin, target, cached);
                    if found.is_some() {
                        blocked(j);
                    }
                    cached = found.or(cached);
                }
            } else {
                let mask = self.packet_blocked(origin, &targets[i..end], &mut cached);
                (0..end - i).filter(|j| mask >> j & 1 == 1).for_each(|j| blocked(i + j));
            }
            i = end;
        }
    }

    /// One packet (at most [`PACKET_RAYS`] targets): bit `j` of the result is set when the
    /// segment to `targets[j]` is blocked. The rays are `origin + s u_j`, s in [0, |d_j|], with
    /// unit directions `u_j`; a node's child is entered when the interval-arithmetic slab test
    /// of the whole bundle (per axis, the child's slab distances divided by the range of the
    /// `u_j` components; an axis whose components change sign bounds nothing, so the bundle's
    /// bounding box stands for it) leaves a non-empty range of s. That contains every ray that
    /// meets the child, so no blocker is skipped; each triangle then tests each ray still
    /// unblocked with [`EdgeTriangle::blocks`], as the single-ray traversal does.
    fn packet_blocked(&self, origin: Vec3, targets: &[Vec3], cached: &mut Option<usize>) -> u32 {
        let n = targets.len();
        debug_assert!((1..=PACKET_RAYS).contains(&n));
        let mut d = [Vec3::ZERO; PACKET_RAYS];
        let mut d_length = [0.0f32; PACKET_RAYS];
        let mut active: u32 = if n == PACKET_RAYS { u32::MAX } else { (1u32 << n) - 1 };
        let mut blocked = 0u32;
        let (mut box_min, mut box_max) = (origin, origin);
        let (mut u_min, mut u_max) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        let (mut reach, mut mean) = (0.0f32, Vec3::ZERO);
        for (j, &t) in targets.iter().enumerate() {
            d[j] = t - origin;
            d_length[j] = d[j].length();
            let u = d[j] / d_length[j];
            (u_min, u_max) = (u_min.min(u), u_max.max(u));
            (box_min, box_max) = (box_min.min(t), box_max.max(t));
            reach = reach.max(d_length[j]);
            mean += d[j];
        }
        if let Some(k) = *cached {
            let tri = &self.triangles[k];
            for j in 0..n {
                if tri.blocks(origin, d[j], d_length[j]) {
                    blocked |= 1 << j;
                }
            }
            active &= !blocked;
            if active == 0 {
                return blocked;
            }
        }
        // Per axis, the range of 1 / u (one sign), or unbounded where the sign changes.
        let (u_min, u_max) = (Vec3A::from(u_min), Vec3A::from(u_max));
        let unbounded = !(u_min.cmpgt(Vec3A::splat(1e-7)) | u_max.cmplt(Vec3A::splat(-1e-7)));
        let (a, b) = (u_min.recip(), u_max.recip());
        let inv_min = Vec3A::select(unbounded, Vec3A::ZERO, a.min(b));
        let inv_max = Vec3A::select(unbounded, Vec3A::ZERO, a.max(b));
        let o = Vec3A::from(origin);
        let (box_min, box_max) = (Vec3A::from(box_min), Vec3A::from(box_max));
        let mut state = self.tree.new_traversal(mean.into());
        let mut node;
        'traversal: {
            obvhs::traverse!(
                self.tree,
                node,
                state,
                {
                    let extent = node.compute_extent();
                    let p = Vec3A::from(node.p);
                    let (child_bits8, bit_index8) = node.get_child_and_index_bits(state.oct_inv4);
                    let mut hit_mask = 0u32;
                    for child in 0..8 {
                        let q_min = Vec3A::new(
                            node.child_min_x[child] as f32,
                            node.child_min_y[child] as f32,
                            node.child_min_z[child] as f32,
                        );
                        let q_max = Vec3A::new(
                            node.child_max_x[child] as f32,
                            node.child_max_y[child] as f32,
                            node.child_max_z[child] as f32,
                        );
                        let (lo, hi) = (p + q_min * extent, p + q_max * extent);
                        if !(lo.cmple(box_max) & hi.cmpge(box_min)).all() {
                            continue;
                        }
                        let (w_lo, w_hi) = (lo - o, hi - o);
                        let (s0, s1, s2, s3) = (w_lo * inv_min, w_lo * inv_max, w_hi * inv_min, w_hi * inv_max);
                        let enter = Vec3A::select(unbounded, Vec3A::NEG_INFINITY, s0.min(s1).min(s2).min(s3));
                        let exit = Vec3A::select(unbounded, Vec3A::INFINITY, s0.max(s1).max(s2).max(s3));
                        if enter.max_element().max(0.0) <= exit.min_element().min(reach) {
                            hit_mask |= extract_byte64(child_bits8, child) << extract_byte64(bit_index8, child);
                        }
                    }
                    hit_mask
                },
                {
                    let k = state.primitive_id as usize;
                    let tri = &self.triangles[k];
                    let mut rays = active;
                    while rays != 0 {
                        let j = rays.trailing_zeros() as usize;
                        rays &= rays - 1;
                        if tri.blocks(origin, d[j], d_length[j]) {
                            blocked |= 1 << j;
                            active &= !(1 << j);
                            *cached = Some(k);
                        }
                    }
                    if active == 0 {
                        break 'traversal;
                    }
                }
            );
        }
        blocked
    }

    /// The nearest triangle the ray `origin + t direction`, t > 0, meets (obvhs's closest-hit
    /// traversal).
    pub fn closest_hit(&self, origin: Vec3, direction: Vec3) -> Option<TriangleHit> {
        if self.triangles.is_empty() {
            return None;
        }
        let d_length = direction.length();
        if d_length == 0.0 {
            return None;
        }
        let ray = traversal_ray(origin, direction / d_length, f32::INFINITY);
        let mut hit = obvhs::ray::RayHit::none();
        let mut best: Option<(f32, Vec2)> = None;
        // The traversal prunes by distance along its own ray: `t d_length` past the origin,
        // `TRAVERSAL_LEAD` past its start.
        self.tree.ray_traverse(ray, &mut hit, |_, k| match self.triangles[k].hit(origin, direction, d_length) {
            Some((t, uv)) if t > 0.0 && best.is_none_or(|(bt, _)| t < bt) => {
                best = Some((t, uv));
                t * d_length + TRAVERSAL_LEAD
            }
            _ => f32::INFINITY,
        });
        let (t, barycentrics) = best?;
        Some(TriangleHit { triangle: self.tree.primitive_indices[hit.primitive_id as usize], t, barycentrics })
    }
}

/// How far behind the origin [`traversal_ray`] starts (m): twice obvhs's node-test floor.
const TRAVERSAL_LEAD: f32 = 2e-4;

/// The ray obvhs's CWBVH traversal walks for a segment or ray from `origin` along the unit
/// direction `u`, `reach` (m) long. obvhs's node test enters a child no nearer than t = 1e-4 (its
/// `cwbvh::node::EPSILON`, whatever the ray's `tmin`), in units of the ray's direction: on the
/// segment's own `d` it skipped the first 1e-4 |d| (10 cm of a shadow ray to an environment VAL
/// 1 km away, so blockers there were missed). With a unit direction started [`TRAVERSAL_LEAD`]
/// behind the origin, the part it skips lies behind the origin, and every node the segment meets
/// is entered. Only the nodes visited depend on this ray; each triangle is still tested on the
/// caller's own segment.
fn traversal_ray(origin: Vec3, u: Vec3, reach: f32) -> Ray {
    Ray::new((origin - u * TRAVERSAL_LEAD).into(), u.into(), 0.0, reach + TRAVERSAL_LEAD)
}

/// The end of the packet that starts at `targets[start]`: the following targets while their
/// unit directions from `origin` stay within [`PACKET_SPREAD`], [`PACKET_RAYS`] at most.
fn packet_end(origin: Vec3, targets: &[Vec3], start: usize) -> usize {
    let first = (targets[start] - origin).normalize_or_zero();
    let (mut lo, mut hi) = (first, first);
    let mut end = start + 1;
    // A target at the origin (no direction) is traced alone.
    while first != Vec3::ZERO && end < targets.len() && end - start < PACKET_RAYS {
        let u = (targets[end] - origin).normalize_or_zero();
        let (l, h) = (lo.min(u), hi.max(u));
        if u == Vec3::ZERO || (h - l).length() > PACKET_SPREAD {
            break;
        }
        (lo, hi) = (l, h);
        end += 1;
    }
    end
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

    /// `count` random triangles from the generator seeded with `seed`, each with its corners
    /// within `size` (per axis) of a centre in the cube `[-extent, extent]³`: the generator (for
    /// the test's other draws), the positions and the triangles.
    fn triangle_soup(
        seed: u64,
        count: u32,
        extent: f32,
        size: f32,
    ) -> (rand_chacha::ChaCha8Rng, Vec<Vec3>, Vec<[u32; 3]>) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut r = |lo: f32, hi: f32| rng.random_range(lo..hi);
        let (mut positions, mut triangles) = (Vec::new(), Vec::new());
        for i in 0..count {
            let c = Vec3::new(r(-extent, extent), r(-extent, extent), r(-extent, extent));
            for _ in 0..3 {
                positions.push(c + Vec3::new(r(-size, size), r(-size, size), r(-size, size)));
            }
            triangles.push([3 * i, 3 * i + 1, 3 * i + 2]);
        }
        (rng, positions, triangles)
    }

    /// Both traversals (the GPU layout's twin and obvhs's CWBVH with early exit) agree with testing every
    /// triangle, on random segments through a soup of random triangles, and the closest hit with
    /// the nearest of all triangles (exact agreement: every path uses the same intersection
    /// routine, so only a traversal or flattening bug can make them differ).
    #[test]
    fn traversals_agree_with_brute_force_loop() {
        let (mut rng, positions, triangles) = triangle_soup(5, 2000, 5.0, 0.3);
        let mut r = |lo: f32, hi: f32| rng.random_range(lo..hi);
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

    /// A blocker near the start of a long segment (a receiver next to the content, a VAL of
    /// the environment 1 km away): obvhs's node test skips the first 1e-4 of its ray's
    /// direction, so a traversal on the segment's own `d` missed it (`traversal_ray`).
    #[test]
    fn a_blocker_near_the_start_of_a_long_segment_is_found() {
        let (mut rng, mut positions, mut triangles) = triangle_soup(3, 500, 0.2, 0.02);
        // A small triangle 5 cm in front of the origin, across the +x axis.
        let n = positions.len() as u32;
        positions.extend([Vec3::new(0.05, -0.01, -0.01), Vec3::new(0.05, 0.02, -0.01), Vec3::new(0.05, -0.01, 0.02)]);
        triangles.push([n, n + 1, n + 2]);
        let bvh = Bvh::build(&positions, &triangles);
        let wide = TraceBvh::build(&positions, &triangles);
        let origin = Vec3::ZERO;
        for far in [1.0f32, 1e3, 1e5] {
            let target = Vec3::new(far, 0.0, 0.0);
            assert!(bvh.occluded(&positions, &triangles, origin, target), "GPU layout, {far} m");
            assert!(wide.segment_blocked(origin, target), "CWBVH, {far} m");
            let hit = wide.closest_hit(origin, target - origin).expect("a hit");
            assert!((hit.t * far - 0.05).abs() < 1e-5, "closest hit at {} m, {far} m", hit.t * far);
        }
        // Random long segments from points among the soup, against every triangle: one by one,
        // and as bundles of 32 close directions (packets and single rays with the last blocker).
        let mut r = |lo: f32, hi: f32| rng.random_range(lo..hi);
        let brute = |o: Vec3, t: Vec3| {
            triangles.iter().any(|tri| {
                let [a, b, c] = tri.map(|i| positions[i as usize]);
                ray_triangle(o, t - o, a, b, c).is_some_and(|s| s > 0.0 && s < 1.0)
            })
        };
        let mut blocked = 0;
        for _ in 0..100 {
            let o = Vec3::new(r(-0.2, 0.2), r(-0.2, 0.2), r(-0.2, 0.2));
            let axis = Vec3::new(r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0)).normalize();
            let targets: Vec<Vec3> =
                (0..32).map(|_| (axis + Vec3::new(r(-0.03, 0.03), r(-0.03, 0.03), r(-0.03, 0.03))) * 1e3).collect();
            let want: Vec<bool> = targets.iter().map(|&t| brute(o, t)).collect();
            for (t, w) in targets.iter().zip(&want) {
                assert_eq!(wide.segment_blocked(o, *t), *w, "segment {o} -> {t}");
            }
            for traversal in [ShadowTraversal::Single, ShadowTraversal::Packets] {
                let mut got = Vec::new();
                wide.shadow_rays(o, &targets, traversal, &mut got);
                assert_eq!(got, want, "{traversal:?} from {o}");
                let mask = wide.blocked_mask(o, &targets, traversal);
                assert!(
                    want.iter().enumerate().all(|(j, w)| (mask >> j & 1 == 1) == *w),
                    "{traversal:?} mask from {o}"
                );
            }
            blocked += want.iter().filter(|b| **b).count();
        }
        assert!((300..3000).contains(&blocked), "both outcomes: {blocked} of 3200 blocked");
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

    /// The packet and single-ray shadow traversals decide every segment as the brute-force loop
    /// over all triangles does, on a soup of small triangles seen from a few origins: targets in
    /// tight clusters (so that full packets form, and some clusters lie behind triangles, so
    /// that packets lose rays part-way), targets spread all round (packets of one), targets on
    /// the axes through the origin (direction components of both signs and exactly zero, where
    /// the interval test bounds nothing) and a target at the origin itself.
    #[test]
    fn shadow_ray_packets_agree_with_brute_force_loop() {
        let (mut rng, positions, triangles) = triangle_soup(9, 3000, 4.0, 0.15);
        let mut r = |lo: f32, hi: f32| rng.random_range(lo..hi);
        let wide = TraceBvh::build(&positions, &triangles);
        let brute = |o: Vec3, t: Vec3| {
            triangles.iter().any(|tri| {
                let [a, b, c] = tri.map(|i| positions[i as usize]);
                ray_triangle(o, t - o, a, b, c).is_some_and(|s| s > 0.0 && s < 1.0)
            })
        };
        let (mut packets_formed, mut blocked_total, mut clear_total) = (0, 0, 0);
        for _ in 0..6 {
            let o = Vec3::new(r(-3.0, 3.0), r(-3.0, 3.0), r(-3.0, 3.0));
            let mut targets = Vec::new();
            for _ in 0..24 {
                let c = Vec3::new(r(-5.0, 5.0), r(-5.0, 5.0), r(-5.0, 5.0));
                targets.extend((0..40).map(|_| c + Vec3::new(r(-0.05, 0.05), r(-0.05, 0.05), r(-0.05, 0.05))));
            }
            targets.extend((0..200).map(|_| Vec3::new(r(-5.0, 5.0), r(-5.0, 5.0), r(-5.0, 5.0))));
            for axis in [Vec3::X, Vec3::NEG_X, Vec3::Y, Vec3::NEG_Y, Vec3::Z, Vec3::NEG_Z] {
                targets.extend((1..=12).map(|k| o + axis * (0.4 * k as f32)));
            }
            targets.push(o);
            packets_formed += (0..targets.len()).filter(|&i| packet_end(o, &targets, i) - i >= PACKET_MIN_RAYS).count();
            let want: Vec<bool> = targets.iter().map(|&t| brute(o, t)).collect();
            for traversal in [ShadowTraversal::Single, ShadowTraversal::Packets] {
                let mut got = Vec::new();
                wide.shadow_rays(o, &targets, traversal, &mut got);
                for (j, (g, w)) in got.iter().zip(&want).enumerate() {
                    assert_eq!(g, w, "{traversal:?}: segment {o} -> {}", targets[j]);
                }
            }
            blocked_total += want.iter().filter(|b| **b).count();
            clear_total += want.iter().filter(|b| !**b).count();
        }
        assert!(packets_formed > 500, "the clusters must form packets: {packets_formed}");
        assert!(
            blocked_total > 500 && clear_total > 500,
            "both outcomes: {blocked_total} blocked, {clear_total} clear"
        );
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

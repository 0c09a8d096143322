//! Sparse shading points (docs/design.md §4 step 0): placement, vertex neighbours, occluder radii.
//!
//! Placement is blue noise by weighted sample elimination (Yuksel 2015, "Sample Elimination
//! for Generating Poisson Disk Sample Sets"): draw [`OVERSAMPLING`] times more candidates than
//! wanted, area-proportionally (stratified over the triangles' area CDF, uniform inside a
//! triangle by the square-root trick), then repeatedly remove the candidate with the most
//! crowded neighbourhood until the wanted number is left. Everything is deterministic for a
//! seed and stream (ChaCha8).

use std::num::NonZeroUsize;

use glam::{EulerRot, Quat, Vec2, Vec3};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{Geometry, SparsePoints};

/// Candidates drawn per sparse point kept (Yuksel suggests 5).
pub(crate) const OVERSAMPLING: usize = 5;

/// Exponent of the elimination weight `(1 - d / d_max)^ALPHA` (Yuksel: 8).
const ALPHA: i32 = 8;

/// Weight limiting (Yuksel §4.3): distances below `2 r_min`, with
/// `r_min = r_max (1 - (N / M)^GAMMA) BETA`, count as `2 r_min`.
const GAMMA: f64 = 1.5;
const BETA: f64 = 0.65;

/// Two candidates whose faces' normals have a cosine below this do not crowd each other: the
/// two sides of a thin wall keep their own points.
const MIN_NEIGHBOUR_COS: f32 = -0.5;

/// Coordinates for a k-d tree: `positions` in a fixed, generically rotated frame. k-d trees
/// split on coordinate axes, and walls aligned with them put thousands of points on one split
/// value, which degrades the tree badly; distances do not change under rotation.
fn tree_coordinates(positions: &[Vec3]) -> Vec<[f32; 3]> {
    let frame = tree_frame();
    positions.iter().map(|&p| (frame * p).to_array()).collect()
}

fn tree_frame() -> Quat {
    Quat::from_euler(EulerRot::XYZ, 0.31, 0.77, 1.13)
}

/// Places `count` sparse points on the surface, then `candidates` adaptive candidates after
/// them (`settings.sparse.adaptive`: the points the elimination removed last, so they fill the
/// gaps between the kept ones). Every vertex is linked to its `neighbours` nearest points of
/// the first kind and, with candidates, to its `neighbours` nearest candidates; every
/// candidate to its `neighbours` nearest points of the first kind. `seed` and `stream` (the
/// mesh index) make the placement reproducible; the first `count` points and the vertices'
/// links to them do not depend on `candidates`.
pub(crate) fn build(
    geometry: &Geometry,
    count: usize,
    candidates: usize,
    neighbours: usize,
    seed: u64,
    stream: u64,
) -> Result<SparsePoints, String> {
    let started = std::time::Instant::now();
    let samples = place(geometry, count, candidates, seed, stream)?;
    let placed_at = started.elapsed();
    let (positions, normals): (Vec<Vec3>, Vec<Vec3>) = samples.iter().map(|&(t, b)| evaluate(geometry, t, b)).unzip();
    // The placement keeps `count` points (all it drew when it drew fewer), then the candidates.
    let base = positions.len().min(count);
    let candidates = positions.len() - base;
    let (vertex_neighbours, mut occluder_radii) = link_vertices(&geometry.positions, &positions[..base], neighbours)?;
    // Candidates hide nothing: no vertex is theirs (disc radius 0).
    occluder_radii.resize(positions.len(), 0.0);
    let (vertex_candidates, candidate_neighbours) = if candidates > 0 {
        let local = link_vertices(&geometry.positions, &positions[base..], neighbours)?.0;
        let to_point = |i: u32| if i == u32::MAX { i } else { i + base as u32 };
        (
            local.into_iter().map(to_point).collect(),
            link_vertices(&positions[base..], &positions[..base], neighbours)?.0,
        )
    } else {
        (Vec::new(), Vec::new())
    };
    tracing::debug!(
        placement_ms = placed_at.as_secs_f64() * 1e3,
        neighbours_ms = (started.elapsed() - placed_at).as_secs_f64() * 1e3,
        "sparse points"
    );
    Ok(SparsePoints {
        triangles: samples.iter().map(|&(t, _)| t).collect(),
        barycentrics: samples.iter().map(|&(_, b)| b).collect(),
        positions,
        normals,
        occluder_radii,
        neighbours,
        vertex_neighbours,
        candidates,
        candidate_neighbours,
        vertex_candidates,
    })
}

/// Position and unit normal (interpolated vertex normals, renormalised; the face normal, then
/// +Y, where that vanishes) at barycentrics `b` of triangle `t`.
pub(crate) fn evaluate(geometry: &Geometry, t: u32, b: Vec2) -> (Vec3, Vec3) {
    let triangle = geometry.triangles[t as usize];
    let [p0, p1, p2] = triangle.map(|v| geometry.positions[v as usize]);
    let [n0, n1, n2] = triangle.map(|v| geometry.normals[v as usize]);
    let b0 = 1.0 - b.x - b.y;
    let position = b0 * p0 + b.x * p1 + b.y * p2;
    let normal = (b0 * n0 + b.x * n1 + b.y * n2)
        .try_normalize()
        .or_else(|| (p1 - p0).cross(p2 - p0).try_normalize())
        .unwrap_or(Vec3::Y);
    (position, normal)
}

/// Chooses `count` (triangle, barycentrics) samples: area-proportional candidates thinned to
/// blue noise; then up to `extra` more, the last ones the thinning removed (the most recently
/// removed first).
fn place(geometry: &Geometry, count: usize, extra: usize, seed: u64, stream: u64) -> Result<Vec<(u32, Vec2)>, String> {
    let areas: Vec<f64> = (0..geometry.triangles.len()).map(|t| geometry.triangle_area(t)).collect();
    let mut cdf = Vec::with_capacity(areas.len());
    let mut total = 0.0f64;
    for &area in &areas {
        total += area;
        cdf.push(total);
    }
    let Some(last_with_area) = areas.iter().rposition(|&a| a > 0.0) else {
        return Err("the mesh has no surface area to place sparse points on".to_owned());
    };
    if count == 0 {
        return Ok(Vec::new());
    }

    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    let candidate_count = count.saturating_mul(OVERSAMPLING);
    let mut candidates = Vec::with_capacity(candidate_count);
    for i in 0..candidate_count {
        // Stratified: one candidate per equal-area stratum of the CDF.
        let u = (i as f64 + rng.random::<f64>()) / candidate_count as f64 * total;
        let t = cdf.partition_point(|&c| c <= u).min(last_with_area);
        let (r1, r2): (f32, f32) = (rng.random(), rng.random());
        let s = r1.sqrt();
        candidates.push((t as u32, Vec2::new(s * (1.0 - r2), s * r2)));
    }
    let positions: Vec<Vec3> = candidates.iter().map(|&(t, b)| evaluate(geometry, t, b).0).collect();
    let face_normals: Vec<Vec3> = candidates
        .iter()
        .map(|&(t, _)| {
            let [a, b, c] = geometry.corners(t as usize);
            (b - a).cross(c - a).normalize_or_zero()
        })
        .collect();
    let (keep, last_removed) = eliminate(&positions, &face_normals, total, count)?;
    let extra = last_removed.iter().rev().take(extra);
    Ok(keep.into_iter().chain(extra.copied()).map(|i| candidates[i]).collect())
}

/// Weighted sample elimination: indices (ascending) of the `count` candidates kept, and the
/// removed ones in the order they were removed.
/// `area` is the surface area the candidates cover, square model units.
fn eliminate(
    positions: &[Vec3],
    normals: &[Vec3],
    area: f64,
    count: usize,
) -> Result<(Vec<usize>, Vec<usize>), String> {
    let m = positions.len();
    if m <= count {
        return Ok(((0..m).collect(), Vec::new()));
    }
    // Largest Poisson disk radius for `count` points on a 2D domain of this area.
    let r_max = (area / (2.0 * 3f64.sqrt() * count as f64)).sqrt();
    let d_max = 2.0 * r_max;
    let d_min = 2.0 * r_max * (1.0 - (count as f64 / m as f64).powf(GAMMA)) * BETA;
    let weight = |i: usize, j: usize| -> f64 {
        let d = f64::from(positions[i].distance(positions[j])).clamp(d_min, d_max);
        (1.0 - d / d_max).powi(ALPHA)
    };

    // Neighbour lists (compressed rows): candidates within d_max that face roughly the same way.
    let points = tree_coordinates(positions);
    let tree: ImmutableKdTree<f32, 3> =
        ImmutableKdTree::new_from_slice(&points).map_err(|e| format!("k-d tree: {e}"))?;
    let radius_squared = (d_max * d_max) as f32;
    let mut offsets = Vec::with_capacity(m + 1);
    let mut neighbours: Vec<u32> = Vec::with_capacity(m * 16);
    let mut weights = vec![0.0f64; m];
    offsets.push(0usize);
    for i in 0..m {
        let start = neighbours.len();
        tree.query(&points[i]).within::<SquaredEuclidean<f32>>(radius_squared).unsorted().visit(|found| {
            let j = found.item;
            if j as usize != i && normals[i].dot(normals[j as usize]) >= MIN_NEIGHBOUR_COS {
                neighbours.push(j);
            }
        });
        // Sort for a summation order independent of the tree's layout.
        neighbours[start..].sort_unstable();
        weights[i] = neighbours[start..].iter().map(|&j| weight(i, j as usize)).sum();
        offsets.push(neighbours.len());
    }

    // Remove the most crowded candidate until `count` are left.
    let mut heap = IndexedMaxHeap::new(weights);
    let mut removed = vec![false; m];
    let mut order = Vec::with_capacity(m - count);
    for _ in count..m {
        let Some(i) = heap.pop() else {
            break;
        };
        removed[i] = true;
        order.push(i);
        for &j in &neighbours[offsets[i]..offsets[i + 1]] {
            let j = j as usize;
            if !removed[j] {
                heap.decrease_by(j, weight(i, j));
            }
        }
    }
    Ok(((0..m).filter(|&i| !removed[i]).collect(), order))
}

/// A binary max-heap over the indices `0..n` ordered by a key per index (ties: larger index
/// first), with in-place key decrease: the elimination loop's priority queue.
struct IndexedMaxHeap {
    keys: Vec<f64>,
    /// Heap order: `heap[0]` is the index with the largest key.
    heap: Vec<u32>,
    /// Position of each index in `heap`; `u32::MAX` once popped.
    slot: Vec<u32>,
}

impl IndexedMaxHeap {
    fn new(keys: Vec<f64>) -> IndexedMaxHeap {
        let n = keys.len();
        let mut heap = IndexedMaxHeap { keys, heap: (0..n as u32).collect(), slot: (0..n as u32).collect() };
        for position in (0..n / 2).rev() {
            heap.sift_down(position);
        }
        heap
    }

    /// Whether the entry at heap position `a` belongs above the one at `b`.
    fn above(&self, a: usize, b: usize) -> bool {
        let (i, j) = (self.heap[a] as usize, self.heap[b] as usize);
        match self.keys[i].total_cmp(&self.keys[j]) {
            std::cmp::Ordering::Equal => i > j,
            order => order.is_gt(),
        }
    }

    fn swap(&mut self, a: usize, b: usize) {
        self.heap.swap(a, b);
        self.slot[self.heap[a] as usize] = a as u32;
        self.slot[self.heap[b] as usize] = b as u32;
    }

    fn sift_down(&mut self, mut position: usize) {
        loop {
            let (left, right) = (2 * position + 1, 2 * position + 2);
            let mut best = position;
            if left < self.heap.len() && self.above(left, best) {
                best = left;
            }
            if right < self.heap.len() && self.above(right, best) {
                best = right;
            }
            if best == position {
                return;
            }
            self.swap(position, best);
            position = best;
        }
    }

    /// Removes and returns the index with the largest key.
    fn pop(&mut self) -> Option<usize> {
        let top = *self.heap.first()? as usize;
        let last = self.heap.len() - 1;
        self.swap(0, last);
        self.heap.pop();
        self.slot[top] = u32::MAX;
        self.sift_down(0);
        Some(top)
    }

    /// Lowers the key of a not yet popped `index` by `amount >= 0`, not below zero.
    fn decrease_by(&mut self, index: usize, amount: f64) {
        let position = self.slot[index];
        if position == u32::MAX || amount.is_nan() || amount <= 0.0 {
            return;
        }
        self.keys[index] = (self.keys[index] - amount).max(0.0);
        self.sift_down(position as usize);
    }
}

/// For every vertex its `n` nearest sparse points (nearest first, `u32::MAX` padded; `n`
/// entries per vertex), and for every point the largest distance to a vertex whose nearest
/// point it is.
fn link_vertices(vertices: &[Vec3], points: &[Vec3], n: usize) -> Result<(Vec<u32>, Vec<f32>), String> {
    let mut radii = vec![0.0f32; points.len()];
    let Some(k) = NonZeroUsize::new(n.min(points.len())) else {
        return Ok((vec![u32::MAX; n * vertices.len()], radii));
    };
    let tree: ImmutableKdTree<f32, 3> =
        ImmutableKdTree::new_from_slice(&tree_coordinates(points)).map_err(|e| format!("k-d tree: {e}"))?;
    let frame = tree_frame();
    let mut neighbours = Vec::with_capacity(n * vertices.len());
    let mut nearest: Vec<(f32, u32)> = Vec::with_capacity(n);
    for vertex in vertices {
        let found = tree.query(&(frame * *vertex).to_array()).nearest_n::<SquaredEuclidean<f32>>(k).execute();
        // Re-rank by the distance in model space, which the radii and the shaders use.
        nearest.clear();
        nearest.extend(found.iter().map(|r| (vertex.distance(points[r.item as usize]), r.item)));
        nearest.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let mut row = vec![u32::MAX; n];
        for (slot, &(_, point)) in row.iter_mut().zip(&nearest) {
            *slot = point;
        }
        if let Some(&(distance, point)) = nearest.first() {
            radii[point as usize] = radii[point as usize].max(distance);
        }
        neighbours.extend(row);
    }
    Ok((neighbours, radii))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An axis-aligned quad in the plane z = 0 from `min` to `max`, two triangles.
    fn quad(geometry: &mut Geometry, min: Vec2, max: Vec2) {
        let base = geometry.positions.len() as u32;
        geometry.positions.extend([
            Vec3::new(min.x, min.y, 0.0),
            Vec3::new(max.x, min.y, 0.0),
            Vec3::new(max.x, max.y, 0.0),
            Vec3::new(min.x, max.y, 0.0),
        ]);
        geometry.normals.extend([Vec3::Z; 4]);
        geometry.texcoords.extend([Vec2::ZERO; 4]);
        geometry.triangles.extend([[base, base + 1, base + 2], [base, base + 2, base + 3]]);
        geometry.triangle_materials.extend([0, 0]);
    }

    fn square(side: f32) -> Geometry {
        let mut g = Geometry::default();
        quad(&mut g, Vec2::ZERO, Vec2::splat(side));
        g
    }

    #[test]
    fn placement_is_deterministic_per_seed_and_stream() {
        let g = square(1.0);
        let a = build(&g, 100, 0, 8, 7, 0).expect("builds");
        let b = build(&g, 100, 0, 8, 7, 0).expect("builds");
        assert_eq!(a.triangles, b.triangles);
        assert_eq!(a.barycentrics, b.barycentrics);
        assert_eq!(a.vertex_neighbours, b.vertex_neighbours);
        let other_seed = build(&g, 100, 0, 8, 8, 0).expect("builds");
        assert_ne!(a.barycentrics, other_seed.barycentrics);
        let other_stream = build(&g, 100, 0, 8, 7, 1).expect("builds");
        assert_ne!(a.barycentrics, other_stream.barycentrics);
    }

    #[test]
    fn points_lie_on_the_surface() {
        let mut g = square(2.0);
        g.positions[2].z = 1.0; // Bend one corner so the triangles differ.
        let sparse = build(&g, 300, 0, 8, 1, 0).expect("builds");
        assert_eq!(sparse.len(), 300);
        for i in 0..sparse.len() {
            let t = sparse.triangles[i];
            let b = sparse.barycentrics[i];
            assert!((t as usize) < g.triangles.len());
            assert!(b.x >= 0.0 && b.y >= 0.0 && b.x + b.y <= 1.0 + 1e-6, "{b}");
            let (p, n) = evaluate(&g, t, b);
            assert_eq!(sparse.positions[i], p);
            assert_eq!(sparse.normals[i], n);
            assert!((n.length() - 1.0).abs() < 1e-5);
        }
    }

    #[test]
    fn placement_is_area_proportional() {
        // A 1 m^2 and a 3 m^2 quad, 1 m apart: expect 1/4 of the points on the small one.
        let mut g = Geometry::default();
        quad(&mut g, Vec2::ZERO, Vec2::ONE);
        quad(&mut g, Vec2::new(2.0, 0.0), Vec2::new(5.0, 1.0));
        let count = 1024;
        for seed in 0..4 {
            let sparse = build(&g, count, 0, 8, seed, 0).expect("builds");
            let small = sparse.triangles.iter().filter(|&&t| t < 2).count();
            let fraction = small as f64 / count as f64;
            // Tolerance: 0.02 of all points (8 % of the small quad's 256). The small quad's
            // relatively longer boundary biases it up a little: 40 seeds gave 252..=268.
            assert!((fraction - 0.25).abs() < 0.02, "seed {seed}: {small} of {count}");
        }
    }

    #[test]
    fn placement_is_well_spread() {
        // Blue noise keeps points apart: the closest pair is far from the ~0 of white noise.
        let count = 400;
        let sparse = build(&square(1.0), count, 0, 8, 3, 0).expect("builds");
        let spacing = (1.0 / count as f32).sqrt();
        let mut closest = f32::INFINITY;
        for (i, p) in sparse.positions.iter().enumerate() {
            for q in &sparse.positions[i + 1..] {
                closest = closest.min(p.distance(*q));
            }
        }
        assert!(closest > 0.5 * spacing, "closest pair {closest}, spacing {spacing}");
    }

    #[test]
    fn thin_walls_keep_points_on_both_sides() {
        // Two coincident squares facing opposite ways.
        let mut g = square(1.0);
        quad(&mut g, Vec2::ZERO, Vec2::ONE);
        g.triangles[2].swap(1, 2);
        g.triangles[3].swap(1, 2);
        let sparse = build(&g, 200, 0, 8, 5, 0).expect("builds");
        let front = sparse.triangles.iter().filter(|&&t| t < 2).count();
        assert!((front as i32 - 100).abs() <= 10, "{front} of 200 on the front");
    }

    #[test]
    fn neighbours_are_sorted_and_padded() {
        let mut g = square(1.0);
        // Add interior vertices so there are more vertices than points.
        for i in 0..20 {
            g.positions.push(Vec3::new(0.05 * i as f32, 0.5, 0.0));
            g.normals.push(Vec3::Z);
        }
        let sparse = build(&g, 3, 0, 8, 2, 0).expect("builds");
        assert_eq!(sparse.vertex_neighbours.len(), 8 * g.positions.len());
        for (v, row) in sparse.vertex_neighbours.chunks_exact(8).enumerate() {
            assert!(row[..3].iter().all(|&i| i < 3), "{row:?}");
            assert!(row[3..].iter().all(|&i| i == u32::MAX), "{row:?}");
            let mut sorted = row[..3].to_vec();
            sorted.sort_unstable();
            sorted.dedup();
            assert_eq!(sorted.len(), 3, "distinct: {row:?}");
            let d: Vec<f32> = row[..3].iter().map(|&i| g.positions[v].distance(sparse.positions[i as usize])).collect();
            assert!(d.windows(2).all(|w| w[0] <= w[1]), "vertex {v}: {d:?}");
        }

        for k in [4, 8, 16] {
            let sparse = build(&g, 64, 0, k, 2, 0).expect("builds");
            assert_eq!(sparse.vertex_neighbours.len(), k * g.positions.len());
            check_nearest_first(&g, &sparse, k);
        }
    }

    /// Every vertex's `k` neighbours are points, by increasing distance, the nearest first.
    fn check_nearest_first(g: &Geometry, sparse: &SparsePoints, k: usize) {
        for (v, row) in sparse.vertex_neighbours.chunks_exact(k).enumerate() {
            assert!(row.iter().all(|&i| i < 64), "{row:?}");
            let d: Vec<f32> = row.iter().map(|&i| g.positions[v].distance(sparse.positions[i as usize])).collect();
            assert!(d.windows(2).all(|w| w[0] <= w[1]), "vertex {v}: {d:?}");
            // The first is the nearest of all points.
            let nearest = sparse.positions.iter().map(|p| g.positions[v].distance(*p)).fold(f32::INFINITY, f32::min);
            assert_eq!(d[0], nearest);
        }
    }

    #[test]
    fn occluder_radii_cover_their_vertices() {
        let mut g = square(1.0);
        super::super::subdivide::subdivide(&mut g, 0.1, 1 << 20).expect("within the cap");
        let sparse = build(&g, 50, 0, 8, 4, 0).expect("builds");
        let mut assigned = vec![0usize; sparse.len()];
        for (v, row) in sparse.vertex_neighbours.chunks_exact(8).enumerate() {
            let nearest = row[0] as usize;
            assigned[nearest] += 1;
            let d = g.positions[v].distance(sparse.positions[nearest]);
            assert!(sparse.occluder_radii[nearest] >= d);
        }
        for (radius, count) in sparse.occluder_radii.iter().zip(&assigned) {
            assert!(radius.is_finite() && *radius >= 0.0);
            if *count == 0 {
                assert_eq!(*radius, 0.0);
            }
        }
        // With ~120 vertices over 50 points, most points own a vertex.
        assert!(sparse.occluder_radii.iter().filter(|&&r| r > 0.0).count() > 25);
    }

    #[test]
    fn indexed_heap_pops_in_key_order() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let keys: Vec<f64> =
            (0..200).map(|i| f64::from(rng.random_range(0..50u32)) + if i % 7 == 0 { 0.0 } else { 0.5 }).collect();
        let mut reference = keys.clone();
        let mut alive = vec![true; keys.len()];
        let mut heap = IndexedMaxHeap::new(keys);
        for step in 0..200 {
            // Brute force: largest key, ties to the larger index.
            let expected = (0..reference.len())
                .filter(|&i| alive[i])
                .max_by(|&a, &b| reference[a].total_cmp(&reference[b]).then(a.cmp(&b)));
            assert_eq!(heap.pop(), expected, "step {step}");
            let Some(popped) = expected else { break };
            alive[popped] = false;
            for _ in 0..3 {
                let j = rng.random_range(0..reference.len());
                let amount = f64::from(rng.random_range(0..20u32)) * 0.25;
                heap.decrease_by(j, amount);
                if alive[j] && amount > 0.0 {
                    reference[j] = (reference[j] - amount).max(0.0);
                }
            }
        }
        assert_eq!(heap.pop(), None);
    }

    #[test]
    fn adaptive_candidates_fill_the_gaps_and_keep_the_points() {
        let g = square(1.0);
        let plain = build(&g, 100, 0, 8, 7, 0).expect("builds");
        let with = build(&g, 100, 40, 8, 7, 0).expect("builds");
        // The first points do not depend on the candidates.
        assert_eq!(with.candidates, 40);
        assert_eq!(with.len(), 140);
        assert_eq!(&with.positions[..100], &plain.positions[..]);
        assert!(plain.candidate_neighbours.is_empty() && plain.candidates == 0);
        // Every candidate is linked to its nearest points among the first 100, nearest first.
        assert_eq!(with.candidate_neighbours.len(), 40 * 8);
        for (c, row) in with.candidate_neighbours.chunks_exact(8).enumerate() {
            let p = with.positions[100 + c];
            assert!(row.iter().all(|&i| i < 100), "{row:?}");
            let nearest = plain.positions.iter().map(|q| p.distance(*q)).fold(f32::INFINITY, f32::min);
            assert_eq!(p.distance(with.positions[row[0] as usize]), nearest);
        }
        // Vertices keep their links to the first 100 and gain their nearest candidates.
        assert_eq!(with.vertex_neighbours, plain.vertex_neighbours);
        assert_eq!(with.vertex_candidates.len(), 8 * g.positions.len());
        assert!(with.vertex_candidates.iter().all(|&i| (100..140).contains(&i)));
        assert!(with.occluder_radii[100..].iter().all(|&r| r == 0.0));
        assert_eq!(with.occluder_radii[..100], plain.occluder_radii[..]);
        // The candidates were removed last, so they sit in the gaps: a candidate is farther
        // from its nearest point than white noise would be (a tenth of the spacing).
        let spacing = (1.0f32 / 100.0).sqrt();
        let gaps: f32 = (0..40)
            .map(|c| {
                let p = with.positions[100 + c];
                with.positions[..100].iter().map(|q| p.distance(*q)).fold(f32::INFINITY, f32::min)
            })
            .sum::<f32>()
            / 40.0;
        assert!(gaps > 0.3 * spacing, "mean gap {gaps}, spacing {spacing}");
    }

    #[test]
    fn zero_area_meshes_are_an_error() {
        let g = Geometry {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(2.0, 0.0, 0.0)],
            normals: vec![Vec3::Z; 3],
            texcoords: vec![Vec2::ZERO; 3],
            triangles: vec![[0, 1, 2]],
            triangle_materials: vec![0],
        };
        assert!(build(&g, 10, 0, 8, 1, 0).is_err());
    }
}

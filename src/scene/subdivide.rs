//! Subdivision of triangles larger than the sparse point spacing.
//!
//! The per-vertex interpolation of the pipeline (docs/design.md §4 step 4) only works when every
//! vertex has sparse points nearby, so a Cornell box wall made of two triangles must be refined.
//! Each round splits every edge longer than `max_edge` at its midpoint. Midpoints are shared
//! through an edge map, so both triangles of an edge split it at the same new vertex; a triangle
//! with 1, 2 or 3 split edges becomes 2, 3 or 4 triangles (red-green refinement, conforming: no
//! T-junctions). New edges are halves, medians shorter than `max_edge`, or the shorter
//! diagonal of a quad (at most 0.87 of the longest edge), so the rounds terminate.

use glam::Vec3;

use super::Geometry;
use super::hash::fast_hash_map;

/// More rounds than any float-representable mesh needs (each round shrinks long edges by at
/// least 0.87).
const MAX_ROUNDS: usize = 256;

/// Splits edges longer than `max_edge` (model units) until none is. Midpoint normals are the
/// renormalised mean of the edge's vertex normals, midpoint texture coordinates the mean of the
/// edge's; triangles keep their material and winding. A UV seam stays split: its two sides
/// are different edges (different vertices), each split at its own midpoint vertex.
/// Returns the number of rounds, or `Err(max_triangles)` when the result would exceed
/// `max_triangles`.
pub(crate) fn subdivide(geometry: &mut Geometry, max_edge: f32, max_triangles: usize) -> Result<usize, usize> {
    let max_edge_squared = max_edge * max_edge;
    let is_long = |positions: &[Vec3], (u, w): (u32, u32)| {
        positions[u as usize].distance_squared(positions[w as usize]) > max_edge_squared
    };
    for round in 0..MAX_ROUNDS {
        // Pass 1: which edges split, and their midpoint vertices.
        let mut masks = Vec::with_capacity(geometry.triangles.len());
        let mut midpoints = fast_hash_map::<(u32, u32), u32>(0);
        let mut new_triangle_count = 0usize;
        for triangle in &geometry.triangles {
            let mut mask = 0u8;
            for k in 0..3 {
                let key = edge_key(triangle[k], triangle[(k + 1) % 3]);
                if !is_long(&geometry.positions, key) {
                    continue;
                }
                mask |= 1 << k;
                midpoints.entry(key).or_insert_with(|| {
                    let (lo, hi) = (key.0 as usize, key.1 as usize);
                    let position = (geometry.positions[lo] + geometry.positions[hi]) * 0.5;
                    let (n_lo, n_hi) = (geometry.normals[lo], geometry.normals[hi]);
                    let normal = (n_lo + n_hi).try_normalize().unwrap_or(n_lo);
                    let texcoord = (geometry.texcoords[lo] + geometry.texcoords[hi]) * 0.5;
                    geometry.positions.push(position);
                    geometry.normals.push(normal);
                    geometry.texcoords.push(texcoord);
                    (geometry.positions.len() - 1) as u32
                });
            }
            new_triangle_count += 1 + mask.count_ones() as usize;
            masks.push(mask);
        }
        if midpoints.is_empty() {
            return Ok(round);
        }
        if new_triangle_count > max_triangles || geometry.positions.len() >= u32::MAX as usize {
            return Err(max_triangles);
        }

        // Pass 2: replace every split triangle by its children.
        let mut triangles = Vec::with_capacity(new_triangle_count);
        let mut materials = Vec::with_capacity(new_triangle_count);
        for ((triangle, &mask), &material) in geometry.triangles.iter().zip(&masks).zip(&geometry.triangle_materials) {
            let mid = |k: usize| midpoints[&edge_key(triangle[k], triangle[(k + 1) % 3])];
            let before = triangles.len();
            match mask.count_ones() {
                0 => triangles.push(*triangle),
                1 => {
                    // Rotate so the split edge is x-y.
                    let r = mask.trailing_zeros() as usize;
                    let [x, y, z] = rotate(*triangle, r);
                    let m = mid(r);
                    triangles.extend([[x, m, z], [m, y, z]]);
                }
                2 => {
                    // Rotate so the unsplit edge is z-x; x-y and y-z split at m0 and m1.
                    let unsplit = (!mask & 0b111).trailing_zeros() as usize;
                    let r = (unsplit + 1) % 3;
                    let [x, y, z] = rotate(*triangle, r);
                    let (m0, m1) = (mid(r), mid((r + 1) % 3));
                    triangles.push([m0, y, m1]);
                    // Split the remaining quad x-m0-m1-z along its shorter diagonal.
                    let p = |v: u32| geometry.positions[v as usize];
                    if p(x).distance_squared(p(m1)) <= p(m0).distance_squared(p(z)) {
                        triangles.extend([[x, m0, m1], [x, m1, z]]);
                    } else {
                        triangles.extend([[x, m0, z], [m0, m1, z]]);
                    }
                }
                _ => {
                    let [a, b, c] = *triangle;
                    let (m0, m1, m2) = (mid(0), mid(1), mid(2));
                    triangles.extend([[a, m0, m2], [m0, b, m1], [m2, m1, c], [m0, m1, m2]]);
                }
            }
            materials.resize(triangles.len(), material);
            debug_assert!(triangles.len() - before == 1 + mask.count_ones() as usize);
        }
        geometry.triangles = triangles;
        geometry.triangle_materials = materials;
    }
    Ok(MAX_ROUNDS)
}

/// Unordered edge key.
fn edge_key(u: u32, w: u32) -> (u32, u32) {
    if u < w { (u, w) } else { (w, u) }
}

/// `[t[r], t[r + 1], t[r + 2]]` (indices mod 3): same triangle, same winding.
fn rotate(t: [u32; 3], r: usize) -> [u32; 3] {
    [t[r % 3], t[(r + 1) % 3], t[(r + 2) % 3]]
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use proptest::prelude::*;

    use super::*;

    fn geometry(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Geometry {
        let normals = vec![Vec3::Z; positions.len()];
        let texcoords = vec![glam::Vec2::ZERO; positions.len()];
        let triangle_materials = (0..triangles.len() as u32).collect();
        Geometry { positions, normals, texcoords, triangles, triangle_materials }
    }

    /// Counts how many triangles use each undirected edge.
    fn edge_uses(geometry: &Geometry) -> HashMap<(u32, u32), usize> {
        let mut uses = HashMap::new();
        for t in &geometry.triangles {
            for k in 0..3 {
                *uses.entry(edge_key(t[k], t[(k + 1) % 3])).or_default() += 1;
            }
        }
        uses
    }

    fn longest_edge(geometry: &Geometry) -> f32 {
        geometry
            .triangles
            .iter()
            .flat_map(|t| {
                let [a, b, c] = t.map(|v| geometry.positions[v as usize]);
                [a.distance(b), b.distance(c), c.distance(a)]
            })
            .fold(0.0, f32::max)
    }

    #[test]
    fn two_triangle_quad_is_refined_conformingly() {
        // A 2 m x 2 m quad, as a Cornell box wall: two triangles.
        let positions = vec![
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ];
        let mut quad = geometry(positions, vec![[0, 1, 2], [0, 2, 3]]);
        let spacing = (quad.area() / 1024.0).sqrt() as f32;
        let rounds = subdivide(&mut quad, spacing, 1 << 22).expect("within the cap");
        assert!(rounds > 0);
        assert!(longest_edge(&quad) <= spacing, "{} > {spacing}", longest_edge(&quad));
        assert!((quad.area() - 4.0).abs() < 1e-9, "area {}", quad.area());
        assert_eq!(quad.triangle_materials.len(), quad.triangles.len());
        assert!(quad.triangle_materials.iter().all(|&m| m < 2));

        // Conforming: interior edges are shared by exactly two triangles, and an edge used
        // once lies on the quad's boundary.
        for ((u, w), count) in edge_uses(&quad) {
            let (p, q) = (quad.positions[u as usize], quad.positions[w as usize]);
            let boundary = (p.x == q.x && p.x.abs() == 1.0) || (p.y == q.y && p.y.abs() == 1.0);
            match count {
                1 => assert!(boundary, "open interior edge {p} - {q}"),
                2 => assert!(!boundary, "doubled boundary edge {p} - {q}"),
                _ => panic!("edge {p} - {q} used {count} times"),
            }
        }
        // Winding is kept: every normal still faces +Z.
        for t in &quad.triangles {
            let [a, b, c] = t.map(|v| quad.positions[v as usize]);
            assert!((b - a).cross(c - a).z > 0.0);
        }
    }

    #[test]
    fn small_triangles_are_untouched() {
        let mut small = geometry(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]);
        let before = small.clone();
        assert_eq!(subdivide(&mut small, 2.0, 100), Ok(0));
        assert_eq!(small.triangles, before.triangles);
        assert_eq!(small.positions, before.positions);
    }

    #[test]
    fn midpoint_normals_are_interpolated() {
        let mut g = geometry(vec![Vec3::ZERO, Vec3::new(2.0, 0.0, 0.0), Vec3::Y], vec![[0, 1, 2]]);
        g.normals = vec![Vec3::Z, Vec3::X, Vec3::Z];
        subdivide(&mut g, 1.5, 100).expect("within the cap");
        let m = g.positions.iter().position(|&p| p == Vec3::X).expect("midpoint of the long edge");
        assert!(g.normals[m].abs_diff_eq(Vec3::new(1.0, 0.0, 1.0).normalize(), 1e-6));
    }

    #[test]
    fn midpoint_texcoords_are_interpolated_and_seams_stay_split() {
        // Two triangles of a square meeting at the diagonal 0-2, which is a UV seam: the
        // second triangle uses copies 3, 4 of vertices 0, 2 with other texture coordinates.
        let positions = vec![Vec3::ZERO, Vec3::X, Vec3::ONE.with_z(0.0), Vec3::ZERO, Vec3::ONE.with_z(0.0), Vec3::Y];
        let mut g = geometry(positions, vec![[0, 1, 2], [3, 4, 5]]);
        g.texcoords = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [2.0, 0.0], [3.0, 1.0], [2.0, 1.0]]
            .map(glam::Vec2::from_array)
            .to_vec();
        subdivide(&mut g, 0.3, 1000).expect("within the cap");
        // Each side's texture coordinates stay the affine map of position of its triangle.
        let first = |p: Vec3| glam::Vec2::new(p.x, p.y);
        let second = |p: Vec3| glam::Vec2::new(2.0 + p.x, p.y);
        for (t, triangle) in g.triangles.iter().enumerate() {
            let expected = if g.triangle_materials[t] == 0 { first } else { second };
            for &v in triangle {
                let (p, uv) = (g.positions[v as usize], g.texcoords[v as usize]);
                assert!(uv.abs_diff_eq(expected(p), 1e-6), "triangle {t}: {p} has {uv}");
            }
        }
        // The diagonal's midpoint exists twice, once per side.
        let centre = Vec3::new(0.5, 0.5, 0.0);
        assert_eq!(g.positions.iter().filter(|&&p| p == centre).count(), 2);
    }

    #[test]
    fn the_triangle_cap_is_an_error() {
        let mut big = geometry(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]);
        assert_eq!(subdivide(&mut big, 1e-3, 10_000), Err(10_000));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        #[test]
        fn random_triangle_pairs_refine_conformingly(
            coords in prop::collection::vec(-3.0f32..3.0, 12),
            spacing in 0.3f32..2.0,
        ) {
            let p: Vec<Vec3> = coords.chunks(3).map(|c| Vec3::new(c[0], c[1], c[2])).collect();
            // Two triangles sharing the edge 0-2.
            let mut g = geometry(p, vec![[0, 1, 2], [0, 2, 3]]);
            let area = g.area();
            subdivide(&mut g, spacing, 1 << 20).expect("within the cap");
            prop_assert!(longest_edge(&g) <= spacing);
            prop_assert!((g.area() - area).abs() <= 1e-4 * area.max(1.0));
            // Conforming: an edge used once lies on the outline 0-1-2-3, never on the shared
            // edge 0-2 (which would be a T-junction or a crack).
            let outline = [(g.positions[0], g.positions[1]), (g.positions[1], g.positions[2]),
                (g.positions[2], g.positions[3]), (g.positions[3], g.positions[0])];
            let on_segment = |x: Vec3, (a, b): (Vec3, Vec3)| {
                let t = ((x - a).dot(b - a) / (b - a).length_squared()).clamp(0.0, 1.0);
                x.distance(a + t * (b - a)) <= 1e-4
            };
            for ((u, w), count) in edge_uses(&g) {
                prop_assert!(count <= 2);
                let (p, q) = (g.positions[u as usize], g.positions[w as usize]);
                if count == 1 {
                    prop_assert!(
                        outline.iter().any(|&s| on_segment(p, s) && on_segment(q, s)),
                        "open edge {} - {} inside the surface", p, q
                    );
                }
            }
        }
    }
}

//! Vertex normals: the OBJ's own, or area-weighted normals with a crease angle.
//!
//! With a crease angle, two triangles around a vertex share its normal only when they are
//! connected through edges at that vertex across which the faces bend by at most the crease
//! angle; a vertex whose faces fall into several such groups is split into one vertex per
//! group. Box edges and wall corners stay sharp, a scanned bunny stays smooth.
//!
//! Faces are adjacent when they share an edge in position, whatever the texture coordinates
//! of its ends: the vertices on either side of a UV seam keep their own texture coordinates
//! but get one normal where the surface is smooth across the seam.

use glam::{Vec2, Vec3};

use super::Geometry;
use super::hash::fast_hash_map;

/// Dihedral angle above which an edge is a crease, degrees.
pub(crate) const CREASE_ANGLE_DEG: f32 = 45.0;

/// Normal given to a vertex that touches only zero-area triangles.
const FALLBACK_NORMAL: Vec3 = Vec3::Y;

/// Twice-area-weighted normal `(b - a) x (c - a)` of each triangle.
fn face_normals(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<Vec3> {
    triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| positions[v as usize]);
            (b - a).cross(c - a)
        })
        .collect()
}

/// Area-weighted normal of every vertex over all its triangles, ignoring creases; `None` where
/// every incident triangle has zero area.
fn smooth_normals(positions: &[Vec3], triangles: &[[u32; 3]], faces: &[Vec3]) -> Vec<Option<Vec3>> {
    let mut sums = vec![Vec3::ZERO; positions.len()];
    for (triangle, &face) in triangles.iter().zip(faces) {
        for &v in triangle {
            sums[v as usize] += face;
        }
    }
    sums.into_iter().map(Vec3::try_normalize).collect()
}

/// Uses the OBJ's normals, renormalised. A zero or non-finite normal is replaced by the
/// area-weighted normal of the vertex's triangles (or +Y when they all have zero area).
pub(crate) fn with_given_normals(
    positions: Vec<Vec3>,
    mut normals: Vec<Vec3>,
    texcoords: Vec<Vec2>,
    triangles: Vec<[u32; 3]>,
) -> Geometry {
    let mut smooth: Option<Vec<Option<Vec3>>> = None;
    let mut replaced = 0usize;
    for (v, normal) in normals.iter_mut().enumerate() {
        if let Some(unit) = normal.try_normalize() {
            *normal = unit;
            continue;
        }
        let smooth =
            smooth.get_or_insert_with(|| smooth_normals(&positions, &triangles, &face_normals(&positions, &triangles)));
        *normal = smooth[v].unwrap_or(FALLBACK_NORMAL);
        replaced += 1;
    }
    if replaced > 0 {
        tracing::warn!("{replaced} zero or non-finite OBJ normals replaced by face normals");
    }
    Geometry { positions, normals, texcoords, triangles, triangle_materials: Vec::new() }
}

/// Computes area-weighted vertex normals with a crease angle (radians), splitting vertices so
/// that each has a single normal. Triangles keep their order; only their indices change.
/// Vertices with the same position are one point of the surface for adjacency and normals;
/// they stay distinct vertices (with their own texture coordinates) in the result.
pub(crate) fn crease_normals(
    positions: &[Vec3],
    texcoords: &[Vec2],
    triangles: &[[u32; 3]],
    crease_angle: f32,
) -> Geometry {
    let faces = face_normals(positions, triangles);
    let units: Vec<Option<Vec3>> = faces.iter().map(|f| f.try_normalize()).collect();
    let cos_crease = crease_angle.cos();
    // Triangles over points: each vertex replaced by the first vertex at its position.
    let points = point_triangles(positions, triangles);

    // Every (edge, triangle) incidence, sorted so that the triangles of an edge are adjacent.
    // Corners are numbered 3 * triangle + k.
    let mut incidences: Vec<Incidence> = Vec::with_capacity(3 * triangles.len());
    for (t, triangle) in points.iter().enumerate() {
        for k in 0..3 {
            let (u, w) = (triangle[k], triangle[(k + 1) % 3]);
            let (corner_u, corner_w) = (3 * t + k, 3 * t + (k + 1) % 3);
            let (key, lo, hi) = if u < w { ((u, w), corner_u, corner_w) } else { ((w, u), corner_w, corner_u) };
            incidences.push((key, lo as u32, hi as u32));
        }
    }
    incidences.sort_unstable();

    let mut clusters = UnionFind::new(3 * triangles.len());
    for run in incidences.chunk_by(|a, b| a.0 == b.0) {
        if run.len() <= PAIRWISE_MAX {
            join_pairwise(run, &units, cos_crease, &mut clusters);
        } else {
            let ((u, w), _, _) = run[0];
            let edge = positions[w as usize] - positions[u as usize];
            join_by_angle(run, edge, &units, cos_crease.clamp(-1.0, 1.0).acos(), &mut clusters);
        }
    }

    // One normal per cluster of corners, and one new vertex per (cluster, original vertex):
    // the corners of a cluster share a position but may differ in texture coordinates. Both
    // are numbered in order of first corner.
    const UNASSIGNED: u32 = u32::MAX;
    let mut cluster_of_root = vec![UNASSIGNED; 3 * triangles.len()];
    let mut sums: Vec<Vec3> = Vec::with_capacity(positions.len());
    let mut cluster_point: Vec<u32> = Vec::with_capacity(positions.len());
    let mut vertex_of = fast_hash_map::<(u32, u32), u32>(positions.len());
    let mut new_positions = Vec::with_capacity(positions.len());
    let mut new_texcoords = Vec::with_capacity(positions.len());
    let mut vertex_cluster: Vec<u32> = Vec::with_capacity(positions.len());
    let mut new_triangles = Vec::with_capacity(triangles.len());
    for (t, triangle) in triangles.iter().enumerate() {
        let mut new_triangle = [0u32; 3];
        for k in 0..3 {
            let root = clusters.find((3 * t + k) as u32) as usize;
            if cluster_of_root[root] == UNASSIGNED {
                cluster_of_root[root] = sums.len() as u32;
                sums.push(Vec3::ZERO);
                cluster_point.push(points[t][k]);
            }
            let cluster = cluster_of_root[root];
            sums[cluster as usize] += faces[t];
            let original = triangle[k];
            let vertex = *vertex_of.entry((cluster, original)).or_insert_with(|| {
                new_positions.push(positions[original as usize]);
                new_texcoords.push(texcoords[original as usize]);
                vertex_cluster.push(cluster);
                (new_positions.len() - 1) as u32
            });
            new_triangle[k] = vertex;
        }
        new_triangles.push(new_triangle);
    }

    let mut smooth: Option<Vec<Option<Vec3>>> = None;
    let cluster_normals: Vec<Vec3> = sums
        .iter()
        .zip(&cluster_point)
        .map(|(sum, &point)| {
            sum.try_normalize().unwrap_or_else(|| {
                let smooth = smooth.get_or_insert_with(|| smooth_normals(positions, &points, &faces));
                smooth[point as usize].unwrap_or(FALLBACK_NORMAL)
            })
        })
        .collect();
    Geometry {
        positions: new_positions,
        normals: vertex_cluster.iter().map(|&c| cluster_normals[c as usize]).collect(),
        texcoords: new_texcoords,
        triangles: new_triangles,
        triangle_materials: Vec::new(),
    }
}

/// Triangles around one edge compared pairwise at most; more (a non-manifold edge: a fan of
/// sheets, or one triangle repeated) are sorted by angle around the edge instead, so that
/// loading stays O(n log n) in triangles whatever the connectivity.
const PAIRWISE_MAX: usize = 8;

/// One (edge, triangle) incidence: the edge's points (lower first), and the triangle's corners
/// at the lower and at the higher point.
type Incidence = ((u32, u32), u32, u32);

/// Joins the corners of every two triangles of `run` (one edge's incidences) whose faces bend
/// by at most the crease angle across the edge: each pair of unit normals compared.
fn join_pairwise(run: &[Incidence], units: &[Option<Vec3>], cos_crease: f32, clusters: &mut UnionFind) {
    for (i, &(_, lo_i, hi_i)) in run.iter().enumerate() {
        for &(_, lo_j, hi_j) in &run[i + 1..] {
            let (Some(a), Some(b)) = (units[lo_i as usize / 3], units[lo_j as usize / 3]) else {
                continue;
            };
            if a.dot(b) >= cos_crease {
                clusters.union(lo_i, lo_j);
                clusters.union(hi_i, hi_j);
            }
        }
    }
}

/// What [`join_pairwise`] joins, in O(k log k) for k triangles: the unit normals of triangles
/// around an edge are perpendicular to it (`edge`, from the lower point to the higher), so each
/// is an angle on a circle and two bend by at most `crease` (radians) exactly when their angles
/// are at most `crease` apart. The pairs that close connect the same groups as the neighbours
/// in angle order that are, the last and the first included (around the circle).
fn join_by_angle(run: &[Incidence], edge: Vec3, units: &[Option<Vec3>], crease: f32, clusters: &mut UnionFind) {
    let Some(axis) = edge.try_normalize() else {
        return;
    };
    let x = axis.any_orthonormal_vector();
    let y = axis.cross(x);
    let mut around: Vec<(f32, Incidence)> = run
        .iter()
        .filter_map(|&incidence| units[incidence.1 as usize / 3].map(|n| (n.dot(y).atan2(n.dot(x)), incidence)))
        .collect();
    around.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let mut join = |(_, lo_a, hi_a): Incidence, (_, lo_b, hi_b): Incidence| {
        clusters.union(lo_a, lo_b);
        clusters.union(hi_a, hi_b);
    };
    for pair in around.windows(2) {
        if pair[1].0 - pair[0].0 <= crease {
            join(pair[0].1, pair[1].1);
        }
    }
    if let [first, .., last] = around.as_slice()
        && first.0 + std::f32::consts::TAU - last.0 <= crease
    {
        join(first.1, last.1);
    }
}

/// `triangles` with each vertex replaced by the first vertex with a bit-identical position
/// (`-0.0` and `0.0` alike).
fn point_triangles(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<[u32; 3]> {
    let bits = |v: Vec3| (v + Vec3::ZERO).to_array().map(f32::to_bits);
    let mut first = fast_hash_map::<[u32; 3], u32>(positions.len());
    let point: Vec<u32> =
        positions.iter().enumerate().map(|(i, &p)| *first.entry(bits(p)).or_insert(i as u32)).collect();
    triangles.iter().map(|t| t.map(|v| point[v as usize])).collect()
}

/// Disjoint sets over `0..n` with path halving and union by index (deterministic roots).
struct UnionFind {
    parent: Vec<u32>,
}

impl UnionFind {
    fn new(n: usize) -> UnionFind {
        UnionFind { parent: (0..n as u32).collect() }
    }

    fn find(&mut self, mut x: u32) -> u32 {
        while self.parent[x as usize] != x {
            let grandparent = self.parent[self.parent[x as usize] as usize];
            self.parent[x as usize] = grandparent;
            x = grandparent;
        }
        x
    }

    fn union(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            let (keep, child) = if ra < rb { (ra, rb) } else { (rb, ra) };
            self.parent[child as usize] = keep;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Zero texture coordinates for `positions`.
    fn zeros(positions: &[Vec3]) -> Vec<Vec2> {
        vec![Vec2::ZERO; positions.len()]
    }

    /// A unit cube with outward counter-clockwise quads, triangulated as tobj fans them.
    fn cube() -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let positions =
            (0..8).map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32)).collect();
        let quads = [
            [0, 2, 3, 1], // z = 0, normal -Z
            [4, 5, 7, 6], // z = 1, +Z
            [0, 1, 5, 4], // y = 0, -Y
            [2, 6, 7, 3], // y = 1, +Y
            [0, 4, 6, 2], // x = 0, -X
            [1, 3, 7, 5], // x = 1, +X
        ];
        let triangles = quads.iter().flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]]).collect();
        (positions, triangles)
    }

    #[test]
    fn cube_gets_24_vertices_with_axis_aligned_normals() {
        let (positions, triangles) = cube();
        let geometry = crease_normals(&positions, &zeros(&positions), &triangles, CREASE_ANGLE_DEG.to_radians());
        assert_eq!(geometry.positions.len(), 24);
        assert_eq!(geometry.triangles.len(), 12);
        for (t, triangle) in geometry.triangles.iter().enumerate() {
            let face = {
                let [a, b, c] = triangle.map(|v| geometry.positions[v as usize]);
                (b - a).cross(c - a).normalize()
            };
            for &v in triangle {
                let n = geometry.normals[v as usize];
                assert_eq!(n, face, "triangle {t} vertex {v}");
                assert_eq!(n.abs().max_element(), 1.0, "axis-aligned: {n}");
            }
            // Positions are unchanged by splitting.
            let original = triangles[t].map(|v| positions[v as usize]);
            assert_eq!(triangle.map(|v| geometry.positions[v as usize]), original);
        }
    }

    #[test]
    fn gentle_bends_stay_smooth() {
        // Two triangles folded by 30 degrees along the shared edge 0-1.
        let fold = 30f32.to_radians();
        let positions = vec![Vec3::ZERO, Vec3::X, Vec3::new(0.5, 1.0, 0.0), Vec3::new(0.5, -fold.cos(), fold.sin())];
        let triangles = vec![[0, 1, 2], [1, 0, 3]];
        let geometry = crease_normals(&positions, &zeros(&positions), &triangles, CREASE_ANGLE_DEG.to_radians());
        assert_eq!(geometry.positions.len(), 4, "no split below the crease angle");
        let sharp = crease_normals(&positions, &zeros(&positions), &triangles, 20f32.to_radians());
        assert_eq!(sharp.positions.len(), 6, "split above the crease angle");
        for n in geometry.normals.iter().chain(&sharp.normals) {
            assert!((n.length() - 1.0).abs() < 1e-6);
        }
    }

    #[test]
    fn degenerate_triangles_get_finite_normals() {
        let positions = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(2.0, 0.0, 0.0), Vec3::new(5.0, 5.0, 5.0)];
        // A good triangle, a zero-area sliver sharing its edge, and an isolated collapsed one.
        let triangles = vec![[0, 1, 2], [0, 3, 1], [4, 4, 4]];
        let geometry = crease_normals(&positions, &zeros(&positions), &triangles, CREASE_ANGLE_DEG.to_radians());
        for n in &geometry.normals {
            assert!(n.is_finite() && (n.length() - 1.0).abs() < 1e-6, "{n}");
        }
        let given = with_given_normals(
            positions.clone(),
            vec![Vec3::ZERO, Vec3::NAN, Vec3::new(0.0, 0.0, 3.0), Vec3::Z, Vec3::ZERO],
            zeros(&positions),
            triangles,
        );
        assert_eq!(given.normals[0], Vec3::Z);
        assert_eq!(given.normals[1], Vec3::Z);
        assert_eq!(given.normals[2], Vec3::Z);
        assert_eq!(given.normals[4], FALLBACK_NORMAL);
    }

    #[test]
    fn uv_seams_keep_their_texcoords_and_share_smooth_normals() {
        // The 30-degree fold of `gentle_bends_stay_smooth`, with the fold edge 0-1 a UV seam:
        // the second triangle has its own copies 4, 5 of vertices 0, 1.
        let fold = 30f32.to_radians();
        let positions = vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::new(0.5, 1.0, 0.0),
            Vec3::new(0.5, -fold.cos(), fold.sin()),
            Vec3::ZERO,
            Vec3::X,
        ];
        let texcoords = vec![
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(0.5, 1.0),
            Vec2::new(0.5, 0.5),
            Vec2::new(0.0, 0.9),
            Vec2::new(1.0, 0.9),
        ];
        let triangles = vec![[0, 1, 2], [5, 4, 3]];
        let geometry = crease_normals(&positions, &texcoords, &triangles, CREASE_ANGLE_DEG.to_radians());
        assert_eq!(geometry.positions.len(), 6, "the seam stays split");
        assert_eq!(geometry.texcoords.len(), 6);
        for (t, triangle) in geometry.triangles.iter().enumerate() {
            for k in 0..3 {
                let (new, old) = (triangle[k] as usize, triangles[t][k] as usize);
                assert_eq!(geometry.positions[new], positions[old]);
                assert_eq!(geometry.texcoords[new], texcoords[old]);
            }
        }
        // Smooth across the seam: the two copies of each seam vertex have one normal.
        let normal_at = |t: usize, k: usize| geometry.normals[geometry.triangles[t][k] as usize];
        assert_eq!(normal_at(0, 0), normal_at(1, 1));
        assert_eq!(normal_at(0, 1), normal_at(1, 0));
        assert!(normal_at(0, 0).dot(Vec3::Z) < 0.999, "averaged over both faces");

        // Sharp across the seam: each side keeps its face normal.
        let sharp = crease_normals(&positions, &texcoords, &triangles, 20f32.to_radians());
        assert_eq!(sharp.positions.len(), 6);
        assert_eq!(sharp.normals[sharp.triangles[0][0] as usize], Vec3::Z);
    }

    /// The corner pairs `join` puts in one cluster, over `corners` corners.
    fn partition(corners: usize, join: impl FnOnce(&mut UnionFind)) -> Vec<u32> {
        let mut clusters = UnionFind::new(corners);
        join(&mut clusters);
        (0..corners as u32).map(|c| clusters.find(c)).collect()
    }

    proptest::proptest! {
        /// A high-valence edge (a fan of sheets around the edge 0-1, some repeated, some
        /// flipped, some degenerate): joining by angle gives exactly the clusters of the
        /// pairwise comparison, except where two faces bend by within 1e-4 radians of the
        /// crease angle (where float rounding may decide either way, in both methods).
        #[test]
        fn joining_by_angle_equals_joining_pairwise(
            sheets in proptest::collection::vec((0.0f32..std::f32::consts::TAU, 0.1f32..3.0, 0u8..8), 9..60),
            crease_deg in 1.0f32..179.0,
            axis in (-1.0f32..1.0, -1.0f32..1.0, 0.2f32..1.0),
        ) {
            let axis = Vec3::new(axis.0, axis.1, axis.2).normalize();
            let (x, y) = axis.any_orthonormal_pair();
            let mut positions = vec![Vec3::ZERO, axis * 2.0];
            let mut triangles = Vec::new();
            for &(angle, radius, kind) in &sheets {
                let apex = axis + (x * angle.cos() + y * angle.sin()) * radius;
                positions.push(if kind == 0 { axis * 0.5 } else { apex });
                let v = (positions.len() - 1) as u32;
                triangles.push(if kind == 1 { [1, 0, v] } else { [0, 1, v] });
                if kind == 2 {
                    triangles.push([0, 1, v]);
                }
            }
            let units: Vec<Option<Vec3>> = face_normals(&positions, &triangles).iter().map(|f| f.try_normalize()).collect();
            let crease = crease_deg.to_radians();
            let near_crease = units.iter().flatten().enumerate().any(|(i, a)| {
                units.iter().flatten().skip(i + 1).any(|b| (a.dot(*b).clamp(-1.0, 1.0).acos() - crease).abs() < 1e-4)
            });
            proptest::prop_assume!(!near_crease);
            let run: Vec<Incidence> = triangles
                .iter()
                .enumerate()
                .map(|(t, triangle)| {
                    let k = (0..3)
                        .find(|&k| triangle[k] + triangle[(k + 1) % 3] == 1)
                        .expect("the edge 0-1");
                    let (lo, hi) = if triangle[k] == 0 { (k, (k + 1) % 3) } else { ((k + 1) % 3, k) };
                    ((0, 1), (3 * t + lo) as u32, (3 * t + hi) as u32)
                })
                .collect();
            let corners = 3 * triangles.len();
            let pairwise = partition(corners, |c| join_pairwise(&run, &units, crease.cos(), c));
            let by_angle = partition(corners, |c| join_by_angle(&run, axis * 2.0, &units, crease, c));
            proptest::prop_assert_eq!(pairwise, by_angle);
        }
    }

    #[test]
    fn one_triangle_repeated_is_one_smooth_sheet() {
        let positions = vec![Vec3::ZERO, Vec3::X, Vec3::Y];
        let triangles = vec![[0, 1, 2]; 5000];
        let geometry = crease_normals(&positions, &zeros(&positions), &triangles, CREASE_ANGLE_DEG.to_radians());
        assert_eq!(geometry.positions.len(), 3, "every copy shares the three vertices");
        assert!(geometry.normals.iter().all(|&n| n == Vec3::Z));
        assert_eq!(geometry.triangles, triangles);
    }
}

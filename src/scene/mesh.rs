//! A loaded mesh, its sparse points, and its world-space arrays under a transform.

use glam::{Mat3, Mat4, Vec2, Vec3};

/// One mesh: an OBJ file after subdivision and crease splitting, in model space, with its
/// sparse points.
#[derive(Clone, Debug)]
pub struct Mesh {
    /// Name, from the mesh file's stem (OBJ or glTF).
    pub name: String,
    /// Model to the scene's local world frame (world minus [`Scene::origin`]): the
    /// description's transform (scale, then Euler XYZ rotation, then translation) after the
    /// anchor, composed in f64 with the origin's translation and then rounded to f32.
    pub model_to_world: Mat4,
    /// Model-space vertex positions.
    pub positions: Vec<Vec3>,
    /// Model-space unit vertex normals, one per vertex.
    pub normals: Vec<Vec3>,
    /// Texture coordinates, one per vertex, in the OBJ's `vt` convention (v up, as in the
    /// file); zero where the OBJ has none. Vertices at one position with different texture
    /// coordinates (a UV seam) stay separate vertices.
    pub texcoords: Vec<Vec2>,
    /// Triangles as vertex indices, counter-clockwise as in the OBJ.
    pub triangles: Vec<[u32; 3]>,
    /// Per-triangle index into [`Scene::materials`].
    pub triangle_materials: Vec<u32>,
    /// The sparse points of this mesh and the vertex-to-point links.
    pub sparse: SparsePoints,
}

/// Sparse shading points of one mesh (docs/design.md §4 step 0). Points are stored as triangle +
/// barycentrics, so they follow a deformation of the mesh; positions and normals are the
/// model-space evaluation at load.
#[derive(Clone, Debug, Default)]
pub struct SparsePoints {
    /// Triangle index (into [`Mesh::triangles`]) of each point.
    pub triangles: Vec<u32>,
    /// Barycentrics `(b1, b2)` of each point: `p = (1 - b1 - b2) p0 + b1 p1 + b2 p2`.
    pub barycentrics: Vec<glam::Vec2>,
    /// Model-space positions of the points.
    pub positions: Vec<Vec3>,
    /// Model-space unit normals (interpolated vertex normals, renormalised).
    pub normals: Vec<Vec3>,
    /// Model-space occluder-disc radius of each point: the largest distance to a mesh vertex
    /// whose nearest sparse point it is; 0 when no vertex is nearest to it.
    pub occluder_radii: Vec<f32>,
    /// Sparse points per vertex in [`SparsePoints::vertex_neighbours`].
    pub neighbours: usize,
    /// `neighbours` entries per mesh vertex: indices of its nearest sparse points, nearest
    /// first, padded with `u32::MAX` when the mesh has fewer points.
    pub vertex_neighbours: Vec<u32>,
    /// How many of the points, at the end of the arrays, are adaptive candidates
    /// (`settings.sparse.adaptive`): gathered only in the frames that choose them, else given
    /// the light interpolated from their neighbours among the other points. 0 without.
    pub candidates: usize,
    /// `neighbours` entries per candidate: its nearest points that are not candidates, nearest
    /// first, `u32::MAX` padded.
    pub candidate_neighbours: Vec<u32>,
    /// `neighbours` entries per mesh vertex, with candidates only: its nearest candidates (as
    /// indices of the points, so at least `len() - candidates`), nearest first, `u32::MAX`
    /// padded. `vertex_neighbours` then holds the nearest points that are not candidates.
    pub vertex_candidates: Vec<u32>,
}

impl Mesh {
    /// Whether one part of the mesh can hide another from a third: false for a convex object
    /// (every vertex behind every face's plane) and for a convex room seen from inside (every
    /// vertex in front of or on every plane). Checked on up to 256 faces against up to 4096
    /// vertices, spread evenly; a relative tolerance absorbs flat subdivided faces.
    pub fn may_occlude_itself(&self) -> bool {
        let (lo, hi) = self
            .positions
            .iter()
            .fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
        let tolerance = 1e-4 * (hi - lo).length();
        let faces = self.triangles.iter().step_by(self.triangles.len().div_ceil(256).max(1));
        let vertices: Vec<Vec3> =
            self.positions.iter().step_by(self.positions.len().div_ceil(4096).max(1)).copied().collect();
        let (mut in_front, mut behind) = (false, false);
        for t in faces {
            let [a, b, c] = t.map(|i| self.positions[i as usize]);
            let n = (b - a).cross(c - a).normalize_or_zero();
            for v in &vertices {
                let side = n.dot(*v - a);
                in_front |= side > tolerance;
                behind |= side < -tolerance;
            }
            if in_front && behind {
                return true;
            }
        }
        false
    }
}

impl SparsePoints {
    /// Number of sparse points, adaptive candidates included.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// Number of sparse points gathered every frame: all but the adaptive candidates.
    pub fn base_len(&self) -> usize {
        self.positions.len() - self.candidates
    }

    /// Whether there are no sparse points (never the case for a loaded mesh).
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
}

impl Mesh {
    /// Vertex positions in world space, m.
    pub fn world_positions(&self) -> Vec<Vec3> {
        self.placed(self.model_to_world).positions()
    }

    /// Unit vertex normals in world space.
    pub fn world_normals(&self) -> Vec<Vec3> {
        self.placed(self.model_to_world).normals()
    }

    /// Sparse point positions in world space, m.
    pub fn sparse_world_positions(&self) -> Vec<Vec3> {
        self.placed(self.model_to_world).sparse_positions()
    }

    /// Unit sparse point normals in world space.
    pub fn sparse_world_normals(&self) -> Vec<Vec3> {
        self.placed(self.model_to_world).sparse_normals()
    }

    /// Occluder radii in world space, m (see [`PlacedMesh::occluder_radii`]).
    pub fn world_occluder_radii(&self) -> Vec<f32> {
        self.placed(self.model_to_world).occluder_radii()
    }

    /// This mesh under another model-to-world transform (a moved model: the sparse points,
    /// in model space, move with it).
    pub fn placed(&self, model_to_world: Mat4) -> PlacedMesh<'_> {
        PlacedMesh { mesh: self, model_to_world }
    }
}

/// A mesh under a model-to-world transform: its world-space arrays.
pub struct PlacedMesh<'a> {
    mesh: &'a Mesh,
    model_to_world: Mat4,
}

impl PlacedMesh<'_> {
    pub fn positions(&self) -> Vec<Vec3> {
        transform_points(self.model_to_world, &self.mesh.positions)
    }

    pub fn normals(&self) -> Vec<Vec3> {
        transform_normals(normal_matrix(self.model_to_world), &self.mesh.normals)
    }

    pub fn sparse_positions(&self) -> Vec<Vec3> {
        transform_points(self.model_to_world, &self.mesh.sparse.positions)
    }

    pub fn sparse_normals(&self) -> Vec<Vec3> {
        transform_normals(normal_matrix(self.model_to_world), &self.mesh.sparse.normals)
    }

    /// Occluder radii in world space, m: the model-space radii times the largest axis scale of
    /// the transform (exact for uniform scale, conservative otherwise).
    pub fn occluder_radii(&self) -> Vec<f32> {
        let linear = Mat3::from_mat4(self.model_to_world);
        let scale = linear.x_axis.length().max(linear.y_axis.length()).max(linear.z_axis.length());
        self.mesh.sparse.occluder_radii.iter().map(|r| r * scale).collect()
    }
}

/// Matrix that takes model-space normals to world space (inverse transpose of the upper 3x3
/// of `model_to_world`); results need renormalising.
fn normal_matrix(model_to_world: Mat4) -> Mat3 {
    Mat3::from_mat4(model_to_world).inverse().transpose()
}

fn transform_points(matrix: Mat4, points: &[Vec3]) -> Vec<Vec3> {
    points.iter().map(|&p| matrix.transform_point3(p)).collect()
}

fn transform_normals(normal_matrix: Mat3, normals: &[Vec3]) -> Vec<Vec3> {
    normals.iter().map(|&n| (normal_matrix * n).normalize_or(n)).collect()
}

//! The scene flattened into world-space arrays (all meshes concatenated), as the GPU sees them
//! and the CPU twins read them; `gpu::scene` uploads it. Also the decoded visibility texel
//! ([`Hit`]) the twins resolve against it.

use super::raw::{RawMaterial, RawSparsePoint, RawVertex};
use crate::scene::Scene;
use crate::twin;
use glam::{Mat4, Vec3};

/// World-space arrays of a whole scene, as the GPU sees them (also the CPU twins' input).
#[derive(Clone, Debug, Default)]
pub struct FlatScene {
    pub vertices: Vec<RawVertex>,
    /// Three per triangle, into `vertices`.
    pub indices: Vec<u32>,
    pub triangle_materials: Vec<u32>,
    /// Per triangle, its mesh's sparse points per m² (as placed): where the scene wants detail,
    /// which the imperfect shadow maps' points follow.
    pub triangle_sparse_density: Vec<f32>,
    pub materials: Vec<RawMaterial>,
    pub sparse_points: Vec<RawSparsePoint>,
    /// Sparse points per vertex in `vertex_neighbours` (the scene's `interpolation_neighbours`).
    pub neighbours: u32,
    /// `neighbours` sparse point indices per vertex, nearest first, `u32::MAX` padded.
    pub vertex_neighbours: Vec<u32>,
    /// How many of `sparse_points`, at the start, lie on a material with a glossy lobe (with
    /// `settings.glossy`): the gather sums the lobe over these only.
    pub glossy_points: u32,
    /// How many of `sparse_points`, at the end, are adaptive candidates (every mesh's; the
    /// points gathered every frame come first): 0 without `settings.sparse.adaptive`.
    pub candidates: u32,
    /// `neighbours` indices per candidate, into the points before the candidates: its mesh's
    /// nearest points gathered every frame, nearest first, `u32::MAX` padded.
    pub candidate_neighbours: Vec<u32>,
    /// `neighbours` indices per vertex, with candidates only: its mesh's nearest candidates,
    /// nearest first, `u32::MAX` padded.
    pub vertex_candidates: Vec<u32>,
    /// The most adaptive candidates a frame gathers (the meshes' budgets summed).
    pub adaptive_budget: u32,
    /// Every diffuse texture, resized to one size; `None` when the scene has none.
    pub textures: Option<TextureArray>,
}

/// Diffuse textures as layers of one size: sRGB-encoded RGBA8, rows from the top.
#[derive(Clone, Debug)]
pub struct TextureArray {
    pub width: u32,
    pub height: u32,
    pub layers: Vec<Vec<u8>>,
}

impl TextureArray {
    /// Layers at the largest width and height among `textures` (others resized bilinearly).
    pub(crate) fn from_textures(textures: &[crate::scene::Texture]) -> Option<Self> {
        let width = textures.iter().map(|t| t.width).max()?;
        let height = textures.iter().map(|t| t.height).max()?;
        let layers = textures
            .iter()
            .map(|t| match ::image::RgbaImage::from_raw(t.width, t.height, t.rgba8.clone()) {
                Some(img) if (t.width, t.height) != (width, height) => {
                    ::image::imageops::resize(&img, width, height, ::image::imageops::FilterType::Triangle).into_raw()
                }
                Some(img) => img.into_raw(),
                None => vec![255; (4 * width * height) as usize],
            })
            .collect();
        Some(Self { width, height, layers })
    }
}

/// A set of triangles over a scene's vertices: three corner indices per triangle and a
/// material per triangle. The scene's own ([`FlatScene::triangles`]) or the camera's simplified
/// copy ([`FlatScene::lod_triangles`]), which the per-pixel passes decode the camera's
/// visibility buffer with.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Triangles {
    pub indices: Vec<u32>,
    pub materials: Vec<u32>,
}

impl Triangles {
    pub fn count(&self) -> u32 {
        (self.indices.len() / 3) as u32
    }

    /// The vertices the triangles use, ascending, each once.
    pub fn vertices(&self) -> Vec<u32> {
        let mut used = self.indices.clone();
        used.sort_unstable();
        used.dedup();
        used
    }
}

/// Triangles longer than this fraction of the scene's extent keep their corners in
/// [`FlatScene::simplified_indices`]: nothing merges into them.
pub const PROXY_LONGEST_EDGE: f32 = 0.02;

/// Cosine of the largest angle between the triangles around a vertex that
/// [`FlatScene::simplified_indices`] counts as flat (about 1°).
const PROXY_FLAT_COS: f32 = 0.9998;

impl FlatScene {
    /// The scene's triangles, where they are now, in the BVH the CPU references trace their
    /// shadow rays through.
    pub fn trace_bvh(&self) -> twin::bvh::TraceBvh {
        let positions: Vec<Vec3> = self.vertices.iter().map(|v| v.position.into()).collect();
        let triangles: Vec<[u32; 3]> = self.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
        twin::bvh::TraceBvh::build(&positions, &triangles)
    }

    /// Apply every mesh's model transform and concatenate.
    pub fn from_scene(scene: &Scene) -> Self {
        let transforms: Vec<Mat4> = scene.meshes.iter().map(|m| m.model_to_world).collect();
        let mut flat = Self::geometry_placed(scene, &transforms);
        flat.textures = TextureArray::from_textures(&scene.textures);
        flat
    }

    /// The arrays of [`FlatScene::from_scene`] but the textures, with mesh `i` placed by
    /// `model_to_world[i]`.
    pub fn geometry_placed(scene: &Scene, model_to_world: &[Mat4]) -> Self {
        assert_eq!(model_to_world.len(), scene.meshes.len(), "one transform per mesh");
        let mut flat = FlatScene {
            materials: scene
                .materials
                .iter()
                .map(|m| RawMaterial {
                    diffuse: m.diffuse.into(),
                    exponent: m.exponent,
                    specular: m.specular.into(),
                    diffuse_texture: m.diffuse_texture.map_or(-1, |t| t as i32),
                })
                .collect(),
            neighbours: scene.settings.interpolation_neighbours,
            ..Default::default()
        };
        // Every mesh's points gathered every frame first, those with a glossy lobe ahead of the
        // rest (the gather sums the lobe only over the first ones), then every mesh's adaptive
        // candidates.
        let lobe = |mesh: &crate::scene::Mesh, i: usize| {
            let material = mesh.triangle_materials[mesh.sparse.triangles[i] as usize] as usize;
            scene.settings.glossy && scene.materials[material].is_glossy()
        };
        let glossy_total: usize =
            scene.meshes.iter().map(|m| (0..m.sparse.base_len()).filter(|&i| lobe(m, i)).count()).sum();
        let base_total: usize = scene.meshes.iter().map(|m| m.sparse.base_len()).sum();
        let any_candidates = scene.meshes.iter().any(|m| m.sparse.candidates > 0);
        let (mut glossy_offset, mut plain_offset) = (0u32, glossy_total as u32);
        let mut candidate_offset = base_total as u32;
        let mut points = vec![RawSparsePoint::default(); base_total];
        let mut candidates = Vec::new();
        for (mesh, &transform) in scene.meshes.iter().zip(model_to_world) {
            let placed = mesh.placed(transform);
            let vertex_base = flat.vertices.len() as u32;
            let positions = placed.positions();
            let area = crate::scene::surface_area(&positions, &mesh.triangles);
            let sparse = &mesh.sparse;
            let base = sparse.base_len();
            let density = if area > 0.0 { (base as f64 / area) as f32 } else { 0.0 };
            for ((p, n), uv) in positions.into_iter().zip(placed.normals()).zip(&mesh.texcoords) {
                flat.vertices.push(RawVertex { position: p.into(), s: uv.x, normal: n.into(), t: 1.0 - uv.y });
            }
            for (t, m) in mesh.triangles.iter().zip(&mesh.triangle_materials) {
                flat.indices.extend(t.iter().map(|i| i + vertex_base));
                flat.triangle_materials.push(*m);
                flat.triangle_sparse_density.push(density);
            }
            // Where each of the mesh's points goes: its glossy ones, then the rest, in order;
            // its candidate j at `candidate_offset + j`.
            let mut at = Vec::with_capacity(sparse.len());
            for i in 0..base {
                let offset = if lobe(mesh, i) { &mut glossy_offset } else { &mut plain_offset };
                at.push(*offset);
                *offset += 1;
            }
            at.extend((0..sparse.candidates as u32).map(|j| candidate_offset + j));
            let world = placed.sparse_positions().into_iter().zip(placed.sparse_normals());
            for (i, (((p, n), radius), triangle)) in
                world.zip(placed.occluder_radii()).zip(&sparse.triangles).enumerate()
            {
                let material = mesh.triangle_materials[*triangle as usize] as usize;
                let corners = mesh.triangles[*triangle as usize]
                    .map(|v| Vec3::from(flat.vertices[(vertex_base + v) as usize].position));
                let face = (corners[1] - corners[0]).cross(corners[2] - corners[0]).normalize_or(n);
                let point = RawSparsePoint {
                    position: p.into(),
                    occluder_radius: radius,
                    normal: n.into(),
                    exponent: scene.materials[material].exponent,
                    geometric: super::oriented_face_normal(face, n).into(),
                    pad: 0.0,
                };
                if i < base { points[at[i] as usize] = point } else { candidates.push(point) }
            }
            let flat_index = |i: u32| if i == u32::MAX { i } else { at[i as usize] };
            flat.vertex_neighbours.extend(sparse.vertex_neighbours.iter().map(|&i| flat_index(i)));
            flat.candidate_neighbours.extend(sparse.candidate_neighbours.iter().map(|&i| flat_index(i)));
            if any_candidates && sparse.candidates == 0 {
                // A row per vertex all the same: none near.
                flat.vertex_candidates.extend(std::iter::repeat_n(u32::MAX, sparse.vertex_neighbours.len()));
            }
            flat.vertex_candidates.extend(sparse.vertex_candidates.iter().map(|&i| flat_index(i)));
            let budget = crate::scene::adaptive_budget(base, scene.settings.sparse.adaptive).min(sparse.candidates);
            flat.adaptive_budget += budget as u32;
            candidate_offset += sparse.candidates as u32;
        }
        flat.glossy_points = glossy_total as u32;
        flat.sparse_points = points;
        flat.candidates = candidates.len() as u32;
        flat.sparse_points.extend(candidates);
        flat
    }

    pub fn vertex_count(&self) -> u32 {
        self.vertices.len() as u32
    }

    pub fn triangle_count(&self) -> u32 {
        self.triangle_materials.len() as u32
    }

    /// The triangles simplified for depth-only use (shadow maps): corner indices into
    /// `vertices`, three per triangle, of a surface about `error` from the meshes' at most (a
    /// fraction of the largest side of all vertices' box; meshoptimizer's quadric measure, which
    /// the unit test finds within twice the distance), and that fraction as reached.
    /// Corners at the same position are welded first, so that seams of normals or texture
    /// coordinates, which a depth map cannot see, do not hold the simplification back; mesh
    /// borders stay where they are, and so do flat vertices (every triangle around them within
    /// about a degree of one plane) and the corners of triangles longer than
    /// [`PROXY_LONGEST_EDGE`] of the extent: a flat region costs no error to merge and would
    /// become a few large triangles, which a paraboloid map's raster draws with straight edges
    /// where the projection bends them. `error` 0 keeps every triangle.
    pub fn simplified_indices(&self, error: f32) -> (Vec<u32>, f32) {
        if error <= 0.0 || self.indices.is_empty() {
            return (self.indices.clone(), 0.0);
        }
        let points: Vec<[f32; 3]> = self.vertices.iter().map(|v| v.position).collect();
        let (count, remap) = meshopt::generate_vertex_remap(&points, Some(&self.indices));
        let welded = meshopt::remap_vertex_buffer(&points, count, &remap);
        let indices = meshopt::remap_index_buffer(Some(&self.indices), count, &remap);
        // One original vertex per welded one (they share its position).
        let mut original = vec![0u32; count];
        for (i, &w) in remap.iter().enumerate() {
            if w != u32::MAX {
                original[w as usize] = i as u32;
            }
        }
        let position = |i: u32| glam::Vec3::from(welded[i as usize]);
        // The extent meshoptimizer measures `error` in: the largest side of the vertices' box.
        let longest = PROXY_LONGEST_EDGE * meshopt::simplify_scale_decoder(&welded);
        let edge = |t: &[u32]| {
            let [a, b, c] = [t[0], t[1], t[2]].map(position);
            a.distance(b).max(b.distance(c)).max(c.distance(a))
        };
        // Locked: flat vertices, and the corners of triangles longer than the bound.
        let normal = |t: &[u32]| {
            let [a, b, c] = [t[0], t[1], t[2]].map(position);
            (b - a).cross(c - a).normalize_or_zero()
        };
        let mut first_normal = vec![glam::Vec3::ZERO; count];
        let mut lock = vec![true; count];
        for t in indices.chunks_exact(3) {
            let n = normal(t);
            for &i in t {
                let i = i as usize;
                if first_normal[i] == glam::Vec3::ZERO {
                    first_normal[i] = n;
                } else if first_normal[i].dot(n) < PROXY_FLAT_COS {
                    lock[i] = false;
                }
            }
        }
        for t in indices.chunks_exact(3) {
            if edge(t) > longest {
                t.iter().for_each(|&i| lock[i as usize] = true);
            }
        }
        let options = meshopt::SimplifyOptions::LockBorder;
        let mut reached = 0.0f32;
        let kept =
            meshopt::simplify_with_locks_decoder(&indices, &welded, &lock, 0, error, options, Some(&mut reached));
        (kept.into_iter().map(|w| original[w as usize]).collect(), reached)
    }

    /// The camera's simplified copy of the triangles (the frame budget's cheapest rung,
    /// `renderer::budget`): every run of consecutive triangles of one material simplified on its
    /// own by meshoptimizer over the original vertices (so that every per-vertex array, the
    /// sparse neighbours, the interpolated lights, stays valid for it; seams of normals and
    /// texture coordinates stay where they are), to at most `ratio` of the run's triangles,
    /// stopping short of that where the surface would move more than `error` (a fraction of
    /// the extent of all vertices, meshoptimizer's relative measure). `ratio` 1 or `error` 0
    /// keeps every triangle.
    pub fn lod_triangles(&self, ratio: f32, error: f32) -> Triangles {
        if ratio >= 1.0 || error <= 0.0 || self.indices.is_empty() {
            return Triangles { indices: self.indices.clone(), materials: self.triangle_materials.clone() };
        }
        let points: Vec<[f32; 3]> = self.vertices.iter().map(|v| v.position).collect();
        let adapter = meshopt::VertexDataAdapter::new(bytemuck::cast_slice(&points), 12, 0)
            .expect("three f32 per vertex make a position stream");
        let mut out = Triangles::default();
        let mut start = 0;
        for run in self.triangle_materials.chunk_by(|a, b| a == b) {
            let indices = &self.indices[3 * start..3 * (start + run.len())];
            let target = 3 * ((run.len() as f32 * ratio.max(0.0)).ceil() as usize).max(1);
            let kept = meshopt::simplify(indices, &adapter, target, error, meshopt::SimplifyOptions::None, None);
            out.materials.extend(std::iter::repeat_n(run[0], kept.len() / 3));
            out.indices.extend(kept);
            start += run.len();
        }
        out
    }

    pub fn sparse_count(&self) -> u32 {
        self.sparse_points.len() as u32
    }

    /// The sparse points gathered every frame: all but the adaptive candidates, which follow them.
    pub fn base_sparse_count(&self) -> u32 {
        self.sparse_count() - self.candidates
    }

    /// Interpolated surface of `triangle` at barycentrics `b`: (position, unit normal, material).
    /// Twin of `surface_at` in `shader/scene.wgsl`.
    pub fn surface_at(&self, triangle: u32, b: glam::Vec2) -> (Vec3, Vec3, crate::twin::Material) {
        self.surface_on(&self.indices, &self.triangle_materials, triangle, b)
    }

    /// [`Self::surface_at`] on other triangles over the same vertices (`indices`, three per
    /// triangle, and `materials`, one per triangle).
    pub fn surface_on(
        &self,
        indices: &[u32],
        materials: &[u32],
        triangle: u32,
        b: glam::Vec2,
    ) -> (Vec3, Vec3, crate::twin::Material) {
        let t = 3 * triangle as usize;
        let v = [0, 1, 2].map(|k| self.vertices[indices[t + k] as usize]);
        let p = v.map(|v| Vec3::from(v.position));
        let n = twin::barycentric(b, v[0].normal.into(), v[1].normal.into(), v[2].normal.into());
        let normal =
            if n.length_squared() > 1e-20 { n.normalize() } else { (p[1] - p[0]).cross(p[2] - p[0]).normalize() };
        let m = self.materials[materials[triangle as usize] as usize];
        let mut diffuse = Vec3::from(m.diffuse);
        if let (Ok(layer), Some(textures)) = (usize::try_from(m.diffuse_texture), &self.textures) {
            let st = |v: RawVertex| Vec3::new(v.s, v.t, 0.0);
            let st = twin::barycentric(b, st(v[0]), st(v[1]), st(v[2])).truncate();
            diffuse *= twin::sample_bilinear(&textures.layers[layer], textures.width, textures.height, st);
        }
        let surface =
            twin::Material { diffuse, specular: m.specular.into(), exponent: m.exponent, diffuse_texture: None };
        (twin::barycentric(b, p[0], p[1], p[2]), normal, surface)
    }

    /// The unit face normal of `triangle` turned to the side of `shading` (the geometric normal
    /// of `shader/scene.wgsl`'s `surface_at`; docs/design.md §3, shading and geometric normals).
    pub fn geometric_normal(&self, triangle: u32, shading: Vec3) -> Vec3 {
        self.geometric_normal_on(&self.indices, triangle, shading)
    }

    fn geometric_normal_on(&self, indices: &[u32], triangle: u32, shading: Vec3) -> Vec3 {
        let t = 3 * triangle as usize;
        let p = [0, 1, 2].map(|k| Vec3::from(self.vertices[indices[t + k] as usize].position));
        twin::oriented_face_normal((p[1] - p[0]).cross(p[2] - p[0]).normalize(), shading)
    }

    /// The receiver a viewer at `eye` sees at barycentrics `b` of `triangle`: [`Self::surface_at`]
    /// with its geometric normal, both normals facing the viewer (`facing_viewer` of
    /// `surface_at` in the per-pixel passes).
    pub fn receiver_at(&self, triangle: u32, b: glam::Vec2, eye: Vec3) -> twin::exact_cpu::Receiver {
        self.receiver_on(&self.indices, &self.triangle_materials, triangle, b, eye)
    }

    /// [`Self::receiver_at`] on other triangles over the same vertices ([`Self::surface_on`]).
    pub fn receiver_on(
        &self,
        indices: &[u32],
        materials: &[u32],
        triangle: u32,
        b: glam::Vec2,
        eye: Vec3,
    ) -> twin::exact_cpu::Receiver {
        let (p, n, m) = self.surface_on(indices, materials, triangle, b);
        let geometric = self.geometric_normal_on(indices, triangle, n);
        twin::exact_cpu::Receiver::sided(p, n, geometric, m, eye)
    }

    /// Centre and radius of a sphere bounding every vertex (m).
    pub fn bounding_sphere(&self) -> (Vec3, f32) {
        let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
        for v in &self.vertices {
            lo = lo.min(v.position.into());
            hi = hi.max(v.position.into());
        }
        let centre = (lo + hi) * 0.5;
        (centre, (hi - lo).length() * 0.5)
    }

    /// Near and far planes (m) that hold the whole scene for a viewpoint at `eye`: far just past
    /// the bounding sphere, near 1e-4 of it.
    pub fn depth_range(&self, eye: Vec3) -> (f32, f32) {
        depth_range_around(self.bounding_sphere(), eye)
    }
}

/// [`FlatScene::depth_range`] for the scene's bounding sphere `sphere` (centre, radius), computed
/// once for many viewpoints.
pub fn depth_range_around(sphere: (Vec3, f32), eye: Vec3) -> (f32, f32) {
    let (centre, radius) = sphere;
    let far = (eye.distance(centre) + radius).max(1e-3) * 1.01;
    (far * 1e-4, far)
}

/// A decoded visibility texel: the triangle hit and its barycentrics, if any.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub triangle: u32,
    pub barycentrics: glam::Vec2,
}

#[cfg(test)]
mod proxy_tests {
    use super::*;
    use glam::Vec3;

    /// A flat grid of `n`² quads on z = 0 (1 m square) and a UV sphere of radius 0.2 m at
    /// height 0.5, in one scene.
    fn plane_and_sphere(n: u32) -> FlatScene {
        let mut positions = Vec::new();
        let mut indices = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                positions.push(Vec3::new(i as f32 / n as f32, j as f32 / n as f32, 0.0));
            }
        }
        for j in 0..n {
            for i in 0..n {
                let k = j * (n + 1) + i;
                indices.extend([k, k + 1, k + n + 2, k, k + n + 2, k + n + 1]);
            }
        }
        let (rings, segments) = (48u32, 96u32);
        let first = positions.len() as u32;
        for r in 0..=rings {
            let theta = std::f32::consts::PI * r as f32 / rings as f32;
            for s in 0..segments {
                let phi = 2.0 * std::f32::consts::PI * s as f32 / segments as f32;
                let d = Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos());
                positions.push(Vec3::new(0.5, 0.5, 0.5) + 0.2 * d);
            }
        }
        for r in 0..rings {
            for s in 0..segments {
                let at = |r: u32, s: u32| first + r * segments + s % segments;
                let (a, b, c, d) = (at(r, s), at(r, s + 1), at(r + 1, s), at(r + 1, s + 1));
                indices.extend([a, c, b, b, c, d]);
            }
        }
        let vertices = positions.iter().map(|p| RawVertex { position: p.to_array(), ..Default::default() }).collect();
        let triangles = indices.len() / 3;
        FlatScene { vertices, indices, triangle_materials: vec![0; triangles], ..Default::default() }
    }

    /// The sphere simplifies within the error it reports, the flat grid keeps every triangle
    /// (merging it would make triangles the size of the plane), the indices name the scene's
    /// own vertices, and error 0 keeps everything.
    #[test]
    fn the_simplified_copy_keeps_flat_regions_and_stays_within_its_error() {
        let flat = plane_and_sphere(16);
        let plane_triangles = 2 * 16 * 16;
        let (kept, reached) = flat.simplified_indices(0.002);
        assert!(reached <= 0.002 && reached > 0.0, "reached {reached}");
        assert!(kept.iter().all(|&i| (i as usize) < flat.vertices.len()));
        let at = |i: u32| Vec3::from(flat.vertices[i as usize].position);
        let on_plane = kept.chunks_exact(3).filter(|t| t.iter().all(|&i| at(i).z == 0.0)).count();
        assert_eq!(on_plane, plane_triangles, "the flat grid is kept whole");
        let sphere = kept.len() / 3 - on_plane;
        let full_sphere = flat.indices.len() / 3 - plane_triangles;
        assert!(sphere * 4 < full_sphere, "the sphere simplifies: {sphere} of {full_sphere} triangles");
        // Every face's centroid (the point of a face furthest inside the sphere) within twice
        // the reached error (of the 1 m extent) of the sphere: meshoptimizer's error is a
        // quadric's, close to the distance but not a bound on it.
        for t in kept.chunks_exact(3).filter(|t| t.iter().any(|&i| at(i).z != 0.0)) {
            let c = (at(t[0]) + at(t[1]) + at(t[2])) / 3.0;
            let off = (c.distance(Vec3::splat(0.5)) - 0.2).abs();
            assert!(off <= 2.0 * reached, "a face {off} m off the sphere (reached {reached})");
        }
        assert_eq!(flat.simplified_indices(0.0).0, flat.indices);
    }

    /// The camera's copy simplifies each material's run on its own to at most its share of
    /// the triangles, keeps every triangle's material, names only the run's own vertices, stays
    /// within twice its error of the surface, and ratio 1 keeps everything.
    #[test]
    fn the_cameras_copy_simplifies_each_material_within_its_error() {
        let mut flat = plane_and_sphere(16);
        let plane_triangles = 2 * 16 * 16;
        let sphere_triangles = flat.indices.len() / 3 - plane_triangles;
        flat.triangle_materials[plane_triangles..].iter_mut().for_each(|m| *m = 1);
        let error = 0.01;
        let lod = flat.lod_triangles(0.25, error);
        assert_eq!(lod.materials.len(), lod.indices.len() / 3);
        let at = |i: u32| Vec3::from(flat.vertices[i as usize].position);
        let first_sphere_vertex = flat.indices[3 * plane_triangles..].iter().min().copied().unwrap();
        let mut counts = [0usize; 2];
        for (t, &m) in lod.indices.chunks_exact(3).zip(&lod.materials) {
            counts[m as usize] += 1;
            let on_sphere = t.iter().map(|&i| i >= first_sphere_vertex).collect::<Vec<_>>();
            assert!(on_sphere.iter().all(|&s| s == (m == 1)), "triangle {t:?} of material {m} mixes the runs");
            if m == 1 {
                let c = (at(t[0]) + at(t[1]) + at(t[2])) / 3.0;
                let off = (c.distance(Vec3::splat(0.5)) - 0.2).abs();
                assert!(off <= 2.0 * error, "a face {off} m off the sphere");
            }
        }
        assert!(counts[1] > 0 && counts[1] <= sphere_triangles.div_ceil(4), "sphere {counts:?} of {sphere_triangles}");
        assert!(counts[0] > 0 && counts[0] <= plane_triangles / 4, "plane {counts:?} of {plane_triangles}");
        let all = flat.lod_triangles(1.0, error);
        assert_eq!((all.indices, all.materials), (flat.indices.clone(), flat.triangle_materials.clone()));
    }
}

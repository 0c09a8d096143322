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
                let point = RawSparsePoint {
                    position: p.into(),
                    occluder_radius: radius,
                    normal: n.into(),
                    exponent: scene.materials[material].exponent,
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
        let t = 3 * triangle as usize;
        let v = [0, 1, 2].map(|k| self.vertices[self.indices[t + k] as usize]);
        let p = v.map(|v| Vec3::from(v.position));
        let n = twin::barycentric(b, v[0].normal.into(), v[1].normal.into(), v[2].normal.into());
        let normal =
            if n.length_squared() > 1e-20 { n.normalize() } else { (p[1] - p[0]).cross(p[2] - p[0]).normalize() };
        let m = self.materials[self.triangle_materials[triangle as usize] as usize];
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
        let t = 3 * triangle as usize;
        let p = [0, 1, 2].map(|k| Vec3::from(self.vertices[self.indices[t + k] as usize].position));
        twin::oriented_face_normal((p[1] - p[0]).cross(p[2] - p[0]).normalize(), shading)
    }

    /// The receiver a viewer at `eye` sees at barycentrics `b` of `triangle`: [`Self::surface_at`]
    /// with its geometric normal, both normals facing the viewer (`facing_viewer` of
    /// `surface_at` in the per-pixel passes).
    pub fn receiver_at(&self, triangle: u32, b: glam::Vec2, eye: Vec3) -> twin::exact_cpu::Receiver {
        let (p, n, m) = self.surface_at(triangle, b);
        let geometric = self.geometric_normal(triangle, n);
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

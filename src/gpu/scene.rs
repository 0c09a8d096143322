//! The scene uploaded: the group(1) bind group every pass shares, plus the sparse points and
//! vertex neighbours. The world-space arrays it uploads ([`FlatScene`]) are the CPU twins' input
//! too and live with them (`twin::flat`).

use super::raw::RawFrame;
use super::visibility::disks::DiscOccluders;
use super::{Gpu, GpuError};
pub use crate::twin::flat::{FlatScene, TextureArray, Triangles, depth_range_around};
use crate::twin::raw::RawSparsePoint;

/// The camera's simplified copy of the scene's triangles over the same vertices
/// ([`FlatScene::lod_triangles`]), and the group(1) that binds it: the camera's raster and the
/// passes that decode the camera's visibility buffer draw and read these triangles in a frame
/// that asks for them (`Frame::camera_triangles`).
pub struct CameraLod {
    /// The `ratio` and `error` it was simplified with.
    pub parameters: (f32, f32),
    pub triangles: Triangles,
    pub bind_group: wgpu::BindGroup,
    /// The vertices its triangles use, ascending, and how many: the per-vertex light the
    /// camera's pixels read ([`GpuScene::camera_vertices`]).
    pub vertices: (wgpu::Buffer, u32),
}

/// The uploaded scene.
pub struct GpuScene {
    pub flat: FlatScene,
    /// Layout of group(1) (`shader/scene.wgsl`).
    pub layout: wgpu::BindGroupLayout,
    pub bind_group: wgpu::BindGroup,
    /// The `Frame` uniform, rewritten every frame.
    pub frame: wgpu::Buffer,
    pub vertices: wgpu::Buffer,
    pub indices: wgpu::Buffer,
    pub sparse_points: wgpu::Buffer,
    /// The sparse points as disc occluders in a Morton order, and their groups' bounds
    /// ([`DiscOccluders`]: the `occlusion` pass reads them).
    pub disc_occluders: wgpu::Buffer,
    pub disc_groups: wgpu::Buffer,
    pub vertex_neighbours: wgpu::Buffer,
    /// Only with adaptive candidates: [`FlatScene::vertex_candidates`].
    pub vertex_candidates: Option<wgpu::Buffer>,
    /// The camera's simplified copy of the triangles, once built ([`GpuScene::build_camera_lod`]).
    pub camera_lod: Option<CameraLod>,
    /// Every vertex's index, ascending: the vertices the interpolation lights when the camera
    /// draws the full meshes.
    all_vertices: wgpu::Buffer,
    /// The rest of group(1), for [`GpuScene::bind_group_with_indices`].
    triangle_materials: wgpu::Buffer,
    materials: wgpu::Buffer,
    textures: Option<(wgpu::TextureView, wgpu::Sampler)>,
}

impl GpuScene {
    pub fn new(gpu: &Gpu, flat: FlatScene) -> Result<Self, GpuError> {
        let frame = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("scene.frame"),
            size: std::mem::size_of::<RawFrame>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let none = wgpu::BufferUsages::empty();
        let vertices = gpu.storage_buffer("scene.vertices", &flat.vertices, none)?;
        let indices = gpu.storage_buffer("scene.indices", &flat.indices, none)?;
        let triangle_materials = gpu.storage_buffer("scene.triangle_materials", &flat.triangle_materials, none)?;
        let materials = gpu.storage_buffer("scene.materials", &flat.materials, none)?;
        let sparse_points = gpu.storage_buffer("scene.sparse_points", &flat.sparse_points, none)?;
        let discs = DiscOccluders::new(&flat.sparse_points);
        let disc_occluders = gpu.storage_buffer("scene.disc_occluders", &discs.occluders, none)?;
        let disc_groups = gpu.storage_buffer("scene.disc_groups", &discs.groups, none)?;
        let vertex_neighbours = gpu.storage_buffer("scene.vertex_neighbours", &flat.vertex_neighbours, none)?;
        let every: Vec<u32> = (0..flat.vertex_count()).collect();
        let all_vertices = gpu.storage_buffer("scene.all_vertices", &every, none)?;
        let vertex_candidates = (flat.candidates > 0)
            .then(|| gpu.storage_buffer("scene.vertex_candidates", &flat.vertex_candidates, none))
            .transpose()?;
        let textures = match &flat.textures {
            Some(t) => Some(upload_textures(gpu, t)?),
            None => None,
        };

        let visibility = wgpu::ShaderStages::COMPUTE | wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT;
        let entry = |binding, ty| wgpu::BindGroupLayoutEntry { binding, visibility, ty, count: None };
        let buffer = |ty| wgpu::BindingType::Buffer { ty, has_dynamic_offset: false, min_binding_size: None };
        let storage = buffer(wgpu::BufferBindingType::Storage { read_only: true });
        let mut layout_entries = vec![
            entry(0, buffer(wgpu::BufferBindingType::Uniform)),
            entry(1, storage),
            entry(2, storage),
            entry(3, storage),
            entry(4, storage),
        ];
        if textures.is_some() {
            layout_entries.push(entry(
                5,
                wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: true },
                    view_dimension: wgpu::TextureViewDimension::D2Array,
                    multisampled: false,
                },
            ));
            layout_entries.push(entry(6, wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering)));
        }
        let layout = gpu.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("scene.layout"),
            entries: &layout_entries,
        });
        let entries = group_entries(&frame, &vertices, &indices, &triangle_materials, &materials, textures.as_ref());
        let bind_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("scene.bind_group"),
            layout: &layout,
            entries: &entries,
        });
        Ok(Self {
            flat,
            layout,
            bind_group,
            frame,
            vertices,
            indices,
            sparse_points,
            disc_occluders,
            disc_groups,
            vertex_neighbours,
            vertex_candidates,
            camera_lod: None,
            all_vertices,
            triangle_materials,
            materials,
            textures,
        })
    }

    /// Build (or build again, for other parameters) the camera's simplified copy of the
    /// triangles: [`FlatScene::lod_triangles`] of `ratio` and `error`, uploaded with a group(1)
    /// that binds it in place of the scene's triangles.
    pub fn build_camera_lod(&mut self, gpu: &Gpu, ratio: f32, error: f32) -> Result<(), GpuError> {
        if self.camera_lod.as_ref().is_some_and(|l| l.parameters == (ratio, error)) {
            return Ok(());
        }
        let triangles = self.flat.lod_triangles(ratio, error);
        let none = wgpu::BufferUsages::empty();
        let indices = gpu.storage_buffer("scene.lod_indices", &triangles.indices, none)?;
        let materials = gpu.storage_buffer("scene.lod_triangle_materials", &triangles.materials, none)?;
        let entries =
            group_entries(&self.frame, &self.vertices, &indices, &materials, &self.materials, self.textures.as_ref());
        let bind_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("scene.lod_bind_group"),
            layout: &self.layout,
            entries: &entries,
        });
        let used = triangles.vertices();
        let vertices = (gpu.storage_buffer("scene.lod_vertices", &used, none)?, used.len() as u32);
        self.camera_lod = Some(CameraLod { parameters: (ratio, error), triangles, bind_group, vertices });
        Ok(())
    }

    /// The vertices whose light the camera's pixels read, and how many: those of the simplified
    /// copy when `lod` and it is built, else every vertex ([`GpuScene::camera_triangles`]).
    pub fn camera_vertices(&self, lod: bool) -> (&wgpu::Buffer, u32) {
        match &self.camera_lod {
            Some(l) if lod => (&l.vertices.0, l.vertices.1),
            _ => (&self.all_vertices, self.flat.vertex_count()),
        }
    }

    /// The camera's triangles: group(1) binding them and how many there are; the simplified
    /// copy when `lod` and it is built, else the scene's own.
    pub fn camera_triangles(&self, lod: bool) -> (&wgpu::BindGroup, u32) {
        match &self.camera_lod {
            Some(l) if lod => (&l.bind_group, l.triangles.count()),
            _ => (&self.bind_group, self.flat.triangle_count()),
        }
    }

    /// Upload the sparse points placed anew (same count as at creation): the points, and the
    /// occluders' order and groups made from them.
    pub fn write_sparse_points(&self, gpu: &Gpu, points: &[RawSparsePoint]) {
        gpu.queue.write_buffer(&self.sparse_points, 0, bytemuck::cast_slice(points));
        let discs = DiscOccluders::new(points);
        gpu.queue.write_buffer(&self.disc_occluders, 0, bytemuck::cast_slice(&discs.occluders));
        gpu.queue.write_buffer(&self.disc_groups, 0, bytemuck::cast_slice(&discs.groups));
    }

    /// Group(1) with `indices` in place of the scene's triangles (three corner indices into
    /// its vertices per triangle): a depth-only pass draws a simplified copy of the scene
    /// through the same shader prelude.
    pub fn bind_group_with_indices(&self, gpu: &Gpu, label: &str, indices: &wgpu::Buffer) -> wgpu::BindGroup {
        let entries = group_entries(
            &self.frame,
            &self.vertices,
            indices,
            &self.triangle_materials,
            &self.materials,
            self.textures.as_ref(),
        );
        gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout: &self.layout,
            entries: &entries,
        })
    }

    /// Whether the scene binds diffuse textures (`shader/scene_textures.wgsl`).
    pub fn textured(&self) -> bool {
        self.flat.textures.is_some()
    }

    /// Whether any triangle's material has a specular albedo.
    pub fn has_glossy_material(&self) -> bool {
        self.flat.triangle_materials.iter().any(|&m| {
            let s = self.flat.materials[m as usize].specular;
            s.iter().any(|c| *c > 0.0)
        })
    }
}

/// The texture array (sRGB, one layer per texture) and its bilinear repeat sampler.
fn upload_textures(gpu: &Gpu, t: &TextureArray) -> Result<(wgpu::TextureView, wgpu::Sampler), GpuError> {
    let limits = gpu.device.limits();
    let (side, layers) = (t.width.max(t.height), t.layers.len() as u32);
    if side > limits.max_texture_dimension_2d || layers > limits.max_texture_array_layers {
        return Err(GpuError::TooLarge {
            what: format!("{layers} diffuse textures of {}x{}", t.width, t.height),
            needed: side.max(layers) as u64,
            limit: limits.max_texture_dimension_2d.min(limits.max_texture_array_layers) as u64,
        });
    }
    let texture = gpu.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("scene.diffuse_textures"),
        size: wgpu::Extent3d { width: t.width, height: t.height, depth_or_array_layers: layers },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba8UnormSrgb,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    for (layer, data) in t.layers.iter().enumerate() {
        gpu.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &texture,
                mip_level: 0,
                origin: wgpu::Origin3d { x: 0, y: 0, z: layer as u32 },
                aspect: wgpu::TextureAspect::All,
            },
            data,
            wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(4 * t.width), rows_per_image: Some(t.height) },
            wgpu::Extent3d { width: t.width, height: t.height, depth_or_array_layers: 1 },
        );
    }
    let view = texture.create_view(&wgpu::TextureViewDescriptor {
        label: Some("scene.diffuse_textures.view"),
        dimension: Some(wgpu::TextureViewDimension::D2Array),
        ..Default::default()
    });
    let sampler = gpu.device.create_sampler(&wgpu::SamplerDescriptor {
        label: Some("scene.diffuse_sampler"),
        address_mode_u: wgpu::AddressMode::Repeat,
        address_mode_v: wgpu::AddressMode::Repeat,
        mag_filter: wgpu::FilterMode::Linear,
        min_filter: wgpu::FilterMode::Linear,
        ..Default::default()
    });
    Ok((view, sampler))
}

/// Group(1)'s entries (`shader/scene.wgsl`).
fn group_entries<'a>(
    frame: &'a wgpu::Buffer,
    vertices: &'a wgpu::Buffer,
    indices: &'a wgpu::Buffer,
    triangle_materials: &'a wgpu::Buffer,
    materials: &'a wgpu::Buffer,
    textures: Option<&'a (wgpu::TextureView, wgpu::Sampler)>,
) -> Vec<wgpu::BindGroupEntry<'a>> {
    let mut entries = vec![
        wgpu::BindGroupEntry { binding: 0, resource: frame.as_entire_binding() },
        wgpu::BindGroupEntry { binding: 1, resource: vertices.as_entire_binding() },
        wgpu::BindGroupEntry { binding: 2, resource: indices.as_entire_binding() },
        wgpu::BindGroupEntry { binding: 3, resource: triangle_materials.as_entire_binding() },
        wgpu::BindGroupEntry { binding: 4, resource: materials.as_entire_binding() },
    ];
    if let Some((view, sampler)) = textures {
        entries.push(wgpu::BindGroupEntry { binding: 5, resource: wgpu::BindingResource::TextureView(view) });
        entries.push(wgpu::BindGroupEntry { binding: 6, resource: wgpu::BindingResource::Sampler(sampler) });
    }
    entries
}

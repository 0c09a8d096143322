//! The clusters' paraboloid depth maps (`shadow_maps.wgsl`), all in one atlas: the raster of
//! every cluster's map, and its readback for tests and tools. The many-light direct pass draws
//! its maps with it too (`gpu::lights::many`).

use super::{SHADOW_MAPS_STAGE, SceneScale, header, shadow_maps_source_after, twin};
use crate::gpu::pass::module_from_source;
use crate::gpu::raster::DEPTH_FORMAT;
use crate::gpu::scene::GpuScene;
use crate::gpu::timing::Recorder;
use crate::gpu::{Gpu, GpuError};
use crate::scene::ClusterSettings;

/// Paraboloid depth maps of a buffer of [`RawCluster`]s, in one atlas (also the many-light
/// direct pass's, `gpu::lights::many`).
pub(crate) struct ShadowMaps {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::RenderPipeline,
    atlas: wgpu::Texture,
    pub(crate) atlas_view: wgpu::TextureView,
    /// The simplified triangles drawn instead of the scene's when every map draws everything
    /// (`ClusterSettings::proxy_error`): group(1) with their indices, and their count.
    proxy: Option<(wgpu::BindGroup, u32)>,
}

impl ShadowMaps {
    pub(crate) fn new(
        gpu: &Gpu,
        scene: &GpuScene,
        settings: &ClusterSettings,
        scale: SceneScale,
    ) -> Result<Self, GpuError> {
        Self::after(gpu, scene, settings, &header(settings, scale))
    }

    /// The maps with the constants `head` (e.g. focused on the meshes, [`header_focused`]),
    /// drawn from the scene's triangles simplified within `settings.proxy_error`.
    pub(super) fn after(gpu: &Gpu, scene: &GpuScene, settings: &ClusterSettings, head: &str) -> Result<Self, GpuError> {
        let label = SHADOW_MAPS_STAGE;
        let module = module_from_source(gpu, label, shadow_maps_source_after(head, scene.textured()))?;
        let side = settings.atlas_columns() * settings.shadow_map_resolution;
        let limit = gpu.device.limits().max_texture_dimension_2d;
        if side > limit {
            return Err(GpuError::TooLarge {
                what: format!("{label}.atlas side (texels)"),
                needed: side.into(),
                limit: limit.into(),
            });
        }
        let (layout, pipeline) = gpu.build_checked(label, || {
            let layout = gpu.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some(&format!("{label}.layout")),
                entries: &[wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: true },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                }],
            });
            let pipeline = crate::gpu::raster::scene_raster_pipeline(gpu, label, &module, &layout, &scene.layout, &[]);
            (layout, pipeline)
        })?;
        let atlas = gpu.device.create_texture(&wgpu::TextureDescriptor {
            label: Some(&format!("{label}.atlas")),
            size: wgpu::Extent3d { width: side, height: side, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: DEPTH_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let atlas_view = atlas.create_view(&Default::default());
        // With `proxy_error` 0 (the many-light maps, which draw culled chunks of the full
        // meshes) nothing is simplified.
        let simplified = (settings.proxy_error > 0.0).then(|| scene.flat.simplified_indices(settings.proxy_error).0);
        let proxy = match simplified {
            Some(indices) if indices.len() < scene.flat.indices.len() => {
                let none = wgpu::BufferUsages::empty();
                let buffer = gpu.storage_buffer(&format!("{label}.proxy_indices"), &indices, none)?;
                let group = scene.bind_group_with_indices(gpu, &format!("{label}.proxy"), &buffer);
                Some((group, (indices.len() / 3) as u32))
            }
            _ => None,
        };
        Ok(Self { layout, pipeline, atlas, atlas_view, proxy })
    }
}

impl ShadowMaps {
    /// Every cluster's map: distances (m) beyond its near distance (`twin::MapFrame::near`),
    /// `f32::INFINITY` where nothing was drawn.
    pub(crate) fn read(
        &self,
        gpu: &Gpu,
        settings: &ClusterSettings,
        scale: SceneScale,
    ) -> Result<Vec<Vec<f32>>, GpuError> {
        let m = settings.count as usize;
        let res = settings.shadow_map_resolution;
        let side = settings.atlas_columns() * res;
        let row = (side * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let staging = gpu.storage_buffer_sized::<u8>("cluster_shadow_maps.readback", (row * side) as usize)?;
        let mut encoder = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("cluster_shadow_maps.readback") });
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture: &self.atlas,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::DepthOnly,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &staging,
                layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(row), rows_per_image: None },
            },
            wgpu::Extent3d { width: side, height: side, depth_or_array_layers: 1 },
        );
        gpu.submit_and_wait(encoder)?;
        let words: Vec<f32> = gpu.read_buffer(&staging, (row / 4 * side) as usize)?;
        let columns = settings.atlas_columns();
        Ok((0..m)
            .map(|k| {
                let (cx, cy) = ((k as u32 % columns) * res, (k as u32 / columns) * res);
                (0..res * res)
                    .map(|i| {
                        twin::decode_map_depth(
                            words[((cy + i / res) * row / 4 + cx + i % res) as usize],
                            scale.diagonal,
                        )
                    })
                    .collect()
            })
            .collect())
    }

    /// Draw every cluster's map, in the stage `stage`: every triangle, or with `draws` only
    /// map k's triangle ranges `draws[k]` (a depth-only map keeps the nearest depth whatever
    /// the order).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn record(
        &self,
        gpu: &Gpu,
        scene: &GpuScene,
        clusters: &wgpu::Buffer,
        settings: &ClusterSettings,
        draws: Option<&[Vec<std::ops::Range<u32>>]>,
        stage: &'static str,
        rec: &mut Recorder<'_>,
    ) -> Result<(), GpuError> {
        let m = settings.count;
        let bind_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(&format!("{SHADOW_MAPS_STAGE}.bind_group")),
            layout: &self.layout,
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: clusters.as_entire_binding() }],
        });
        rec.stage(stage, |e, s| {
            let mut pass = e.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some(stage),
                color_attachments: &[],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &self.atlas_view,
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Store }),
                    stencil_ops: None,
                }),
                timestamp_writes: s.as_ref().map(|s| s.render()),
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            // Every map draws everything: the simplified triangles where there are some.
            let (group, triangles) = match (&self.proxy, draws) {
                (Some((group, count)), None) => (group, *count),
                _ => (&scene.bind_group, scene.flat.triangle_count()),
            };
            pass.set_bind_group(1, group, &[]);
            let (res, columns) = (settings.shadow_map_resolution, settings.atlas_columns());
            let everything = 0..triangles;
            let all = std::slice::from_ref(&everything);
            for k in 0..m {
                let ranges = draws.map_or(all, |d| &d[k as usize][..]);
                if ranges.is_empty() {
                    continue;
                }
                let (x, y) = ((k % columns) * res, (k / columns) * res);
                pass.set_viewport(x as f32, y as f32, res as f32, res as f32, 0.0, 1.0);
                pass.set_scissor_rect(x, y, res, res);
                for t in ranges {
                    pass.draw(3 * t.start..3 * t.end, k..k + 1);
                }
            }
        })
    }
}

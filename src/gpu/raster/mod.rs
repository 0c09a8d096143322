//! Visibility buffer pass (`visibility.wgsl`): rasterises the scene from a viewpoint
//! into an `Rgba32Uint` target holding, per texel, the nearest triangle and its barycentrics.
//! Used from the camera and from the spot light (the RSM).

pub mod cull;

use crate::gpu::scene::GpuScene;
use crate::gpu::shader::Wgsl;
use crate::gpu::technique::{Frame, Technique};
use crate::gpu::timing::{Recorder, Span};
use crate::gpu::{Gpu, GpuError};
use glam::Mat4;

pub const WGSL: &str = include_str!("visibility.wgsl");
/// The visibility buffer's vertex output, vertex function and fragment stage, which every
/// visibility raster prepends to its own vertex entry.
pub const STAGES_WGSL: &str = include_str!("visibility_stages.wgsl");
pub(crate) const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Uint;
pub(crate) const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// The pass's complete WGSL (a render pipeline: vertex and fragment stages).
pub fn source(textured: bool) -> String {
    crate::gpu::shader::source(&Wgsl::new().include(STAGES_WGSL).include(WGSL).finish(), textured)
}

#[derive(Clone)]
pub struct Visibility {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::RenderPipeline,
}

/// One viewpoint's visibility buffer and its view transform.
pub struct VisibilityTarget {
    pub label: String,
    pub width: u32,
    pub height: u32,
    pub texture: wgpu::Texture,
    pub view: wgpu::TextureView,
    depth: wgpu::TextureView,
    world_to_clip: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
}

impl Visibility {
    pub fn new(gpu: &Gpu, scene: &GpuScene) -> Result<Self, GpuError> {
        let module = crate::gpu::pass::module_from_source(gpu, "visibility", source(scene.textured()))?;
        let (layout, pipeline) = gpu.build_checked("visibility", || {
            let layout = gpu.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("visibility.layout"),
                entries: &[wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::VERTEX,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                }],
            });
            let target = wgpu::ColorTargetState { format: FORMAT, blend: None, write_mask: wgpu::ColorWrites::ALL };
            let pipeline = scene_raster_pipeline(gpu, "visibility", &module, &layout, &scene.layout, &[Some(target)]);
            (layout, pipeline)
        })?;
        Ok(Self { layout, pipeline })
    }

    /// Textures and uniform for a `width` x `height` viewpoint named `label`.
    pub fn target(&self, gpu: &Gpu, label: &str, width: u32, height: u32) -> VisibilityTarget {
        let (visibility, depth) = visibility_textures(gpu, label, width, height);
        let world_to_clip = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(&format!("{label}.world_to_clip")),
            size: 64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(&format!("{label}.bind_group")),
            layout: &self.layout,
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: world_to_clip.as_entire_binding() }],
        });
        VisibilityTarget {
            label: label.to_owned(),
            width,
            height,
            view: visibility.create_view(&Default::default()),
            texture: visibility,
            depth,
            world_to_clip,
            bind_group,
        }
    }

    /// Rasterise the scene into `target` as seen through `world_to_clip`.
    pub fn record(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        scene: &GpuScene,
        target: &VisibilityTarget,
        world_to_clip: Mat4,
        span: Option<Span<'_>>,
    ) {
        let triangles = (&scene.bind_group, scene.flat.triangle_count());
        self.record_on(gpu, encoder, triangles, target, world_to_clip, span);
    }

    /// [`Visibility::record`] of other triangles over the scene's vertices: `triangles` is
    /// the group(1) that binds them and their count (`GpuScene::camera_triangles`).
    pub fn record_on(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        triangles: (&wgpu::BindGroup, u32),
        target: &VisibilityTarget,
        world_to_clip: Mat4,
        span: Option<Span<'_>>,
    ) {
        gpu.queue.write_buffer(&target.world_to_clip, 0, bytemuck::bytes_of(&world_to_clip.to_cols_array_2d()));
        let mut pass = begin_visibility_pass(encoder, &target.label, &target.view, &target.depth, span);
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &target.bind_group, &[]);
        pass.set_bind_group(1, triangles.0, &[]);
        pass.draw(0..3 * triangles.1, 0..1);
    }
}

/// A render pass that clears the visibility texture `view` (nothing covered) and its depth
/// buffer `depth`, keeps the texture and discards the depths: every visibility raster's pass
/// (the camera's, the RSMs').
pub(crate) fn begin_visibility_pass<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    label: &str,
    view: &wgpu::TextureView,
    depth: &wgpu::TextureView,
    span: Option<Span<'_>>,
) -> wgpu::RenderPass<'e> {
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT), store: wgpu::StoreOp::Store },
        })],
        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
            view: depth,
            depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Discard }),
            stencil_ops: None,
        }),
        timestamp_writes: span.as_ref().map(Span::render),
        occlusion_query_set: None,
        multiview_mask: None,
    })
}

/// A `width` x `height` visibility texture named `label.visibility` (a render target that passes
/// read and copy from) and the view of its depth buffer `label.depth`.
pub(crate) fn visibility_textures(
    gpu: &Gpu,
    label: &str,
    width: u32,
    height: u32,
) -> (wgpu::Texture, wgpu::TextureView) {
    let texture = |name: &str, format, usage| {
        gpu.device.create_texture(&wgpu::TextureDescriptor {
            label: Some(&format!("{label}.{name}")),
            size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        })
    };
    let usage =
        wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_SRC;
    let visibility = texture("visibility", FORMAT, usage);
    let depth = texture("depth", DEPTH_FORMAT, wgpu::TextureUsages::RENDER_ATTACHMENT).create_view(&Default::default());
    (visibility, depth)
}

/// The camera's visibility buffer, the first technique of every camera image.
pub struct CameraView {
    raster: Visibility,
}

impl CameraView {
    /// Stage name.
    pub const STAGE: &str = "visibility";

    pub fn new(raster: &Visibility) -> Self {
        Self { raster: raster.clone() }
    }
}

impl Technique for CameraView {
    fn stages(&self) -> Vec<&'static str> {
        vec![Self::STAGE]
    }

    fn record(&self, gpu: &Gpu, frame: &Frame<'_>, rec: &mut Recorder<'_>) -> Result<(), GpuError> {
        rec.stage(Self::STAGE, |e, s| {
            self.raster.record_on(gpu, e, frame.camera_triangles(), &frame.camera.view, frame.camera_to_clip, s)
        })
    }
}

/// A decoded visibility texel (defined with the twins that resolve it, `twin::flat`).
pub use crate::twin::flat::Hit;

impl VisibilityTarget {
    /// Read the visibility buffer back, row-major from the top (for the CPU twins and tests).
    pub fn read(&self, gpu: &Gpu) -> Result<Vec<Option<Hit>>, GpuError> {
        read_visibility(gpu, &self.texture, self.width, self.height)
    }
}

/// Read a `width` x `height` visibility texture back, row-major from the top.
pub(crate) fn read_visibility(
    gpu: &Gpu,
    texture: &wgpu::Texture,
    width: u32,
    height: u32,
) -> Result<Vec<Option<Hit>>, GpuError> {
    let row = (width * 16).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
    let buffer = gpu.storage_buffer_sized::<u8>("visibility.readback", (row * height) as usize)?;
    let mut encoder =
        gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("visibility.readback") });
    encoder.copy_texture_to_buffer(
        texture.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(row), rows_per_image: None },
        },
        wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
    );
    gpu.submit_and_wait(encoder)?;
    let words: Vec<u32> = gpu.read_buffer(&buffer, (row / 4 * height) as usize)?;
    let mut out = Vec::with_capacity((width * height) as usize);
    for y in 0..height {
        for x in 0..width {
            let t = ((y * row / 4) + 4 * x) as usize;
            out.push((words[t] != 0).then(|| Hit {
                triangle: words[t] - 1,
                barycentrics: glam::Vec2::new(f32::from_bits(words[t + 1]), f32::from_bits(words[t + 2])),
            }));
        }
    }
    Ok(out)
}

/// A render pipeline that rasterises the flattened scene (`vs_main` over its triangles, no
/// vertex buffers, no culling) with a `Less` depth test into [`DEPTH_FORMAT`], `fs_main`
/// writing `targets` (none for a depth-only map); bind groups 0 (`layout`) and 1 (the scene).
pub(crate) fn scene_raster_pipeline(
    gpu: &Gpu,
    label: &str,
    module: &wgpu::ShaderModule,
    layout: &wgpu::BindGroupLayout,
    scene_layout: &wgpu::BindGroupLayout,
    targets: &[Option<wgpu::ColorTargetState>],
) -> wgpu::RenderPipeline {
    let pipeline_layout = gpu.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(&format!("{label}.pipeline_layout")),
        bind_group_layouts: &[Some(layout), Some(scene_layout)],
        immediate_size: 0,
    });
    gpu.device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(&format!("{label}.pipeline")),
        layout: Some(&pipeline_layout),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: &[],
        },
        primitive: wgpu::PrimitiveState { cull_mode: None, ..Default::default() },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Less),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets,
        }),
        multiview_mask: None,
        cache: None,
    })
}

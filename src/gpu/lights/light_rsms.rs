//! VALs from the RSMs of the scene's `lights` (docs/measurements/many-lights.md; docs/design.md §2): one
//! VAL budget (`settings.direct.val_budget`) split among the lights by emitted flux
//! ([`split_val_budget`]), each light's RSM at the resolution its share allows (a spot: one
//! perspective view over its cone, as the scene's `light`; a point light: six cube faces), all
//! views rasterised into one visibility atlas (`light_rsms_raster.wgsl`), then every texel that
//! sees a surface appended as a VAL (`light_rsms.wgsl`). Rust twins: `twin::light_rsms`.
//!
//! Exists only for a scene with `lights`; its VALs join the frame's VAL buffer after the spot
//! light's, so every VAL consumer takes them as it takes the spot's.
//!
//! Each view draws only the scene's triangle chunks that may meet its frustum and, for a point
//! light with a `range`, lie partly within it (`raster::cull`); a view with none draws nothing.
//! The VALs are the same as without the cull: what it drops makes no fragment in the view, or
//! (beyond the range) only texels whose VAL has no flux, and those are never appended.

use super::compact::{self, Compact};
use crate::gpu::pass::{Entry, Kernel, PassDesc, buffer, module_from_source, read, read_write, texture, view};
use crate::gpu::raster::cull::TriangleChunks;
use crate::gpu::raster::{self, Hit, begin_visibility_pass};
use crate::gpu::scene::{GpuScene, depth_range_around};
use crate::gpu::shader::WORKGROUP_SIZE;
use crate::gpu::shader::Wgsl;
use crate::gpu::technique::{Frame, Technique};
use crate::gpu::timing::Recorder;
use crate::gpu::{Gpu, GpuError};
use crate::scene::Light;
use crate::twin::light_rsms::{RsmView, emitted_flux, light_views, split_val_budget, view_to_clip, views_of};
use bytemuck::{Pod, Zeroable};
use std::ops::Range;

pub const WGSL: &str = include_str!("light_rsms.wgsl");
const RASTER_WGSL: &str = include_str!("light_rsms_raster.wgsl");
/// WGSL `RsmView`, shared by the raster and the VAL pass.
pub const VIEW_WGSL: &str = include_str!("light_rsms_view.wgsl");

/// Stage names.
pub const RASTER_STAGE: &str = "lights_rsm_raster";
pub const VALS_STAGE: &str = "lights_rsm_vals";

/// `main`: one invocation per texel of every view, writing the texel's candidate; `compact`
/// appends the candidates to `vals` (stopping at its capacity) after the `val_count` already
/// there.
pub const PASS: PassDesc = PassDesc {
    label: VALS_STAGE,
    bindings: &[
        texture("atlas"),
        read("rsm_views"),
        read_write("vals"),
        read_write("val_count"),
        read_write("candidates"),
    ],
    entries: &[
        Entry { name: "main", bindings: 5, except: &["vals", "val_count"] },
        Entry { name: "compact", bindings: 5, except: &["atlas", "rsm_views"] },
    ],
    workgroup: [WORKGROUP_SIZE, 1, 1],
    default_source: |textured| PASS.source(&body(), textured),
};

/// The VAL pass's WGSL after the shader prelude.
fn body() -> String {
    Wgsl::new().include(VIEW_WGSL).include(WGSL).include(compact::WGSL).finish()
}

/// The raster's complete WGSL (a render pipeline: vertex and fragment stages).
pub fn raster_source(textured: bool) -> String {
    let stages = crate::gpu::raster::STAGES_WGSL;
    crate::gpu::shader::source(&Wgsl::new().include(VIEW_WGSL).include(stages).include(RASTER_WGSL).finish(), textured)
}

/// WGSL `RsmView`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RawRsmView {
    pub world_to_clip: [[f32; 4]; 4],
    pub position: [f32; 3],
    pub resolution: u32,
    pub direction: [f32; 3],
    pub tan_half: f32,
    pub intensity: [f32; 3],
    pub inner_angle: f32,
    pub origin: [u32; 2],
    pub first_texel: u32,
    pub outer_angle: f32,
    pub omega_scale: f32,
    pub range: f32,
    pub _pad0: u32,
    pub _pad1: u32,
}

/// One view placed in the atlas.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlacedView {
    /// Index of its light in the scene's `lights`.
    pub light: u32,
    pub view: RsmView,
    /// Top-left texel in the atlas.
    pub origin: [u32; 2],
    /// Its first texel in the VAL pass's flat numbering.
    pub first_texel: u32,
}

/// Shelf-pack square tiles of sides `sides` into a `width`-wide atlas, largest first: each
/// tile's top-left corner, and the atlas height.
fn pack(sides: &[u32], width: u32) -> (Vec<[u32; 2]>, u32) {
    let mut order: Vec<usize> = (0..sides.len()).collect();
    order.sort_by(|&a, &b| sides[b].cmp(&sides[a]).then(a.cmp(&b)));
    let mut origins = vec![[0u32; 2]; sides.len()];
    let (mut x, mut y, mut shelf) = (0u32, 0u32, 0u32);
    for i in order {
        let s = sides[i];
        if x + s > width {
            (x, y, shelf) = (0, y + shelf, 0);
        }
        origins[i] = [x, y];
        x += s;
        shelf = shelf.max(s);
    }
    (origins, y + shelf)
}

/// The RSMs of the scene's `lights` and the VALs they make.
pub struct LightRsms {
    /// Per light of `lights`: its RSM's texels per view side (0: it makes no VAL).
    pub resolutions: Vec<u32>,
    /// Every view of every light with a resolution, in the VAL pass's order.
    pub views: Vec<PlacedView>,
    /// Texels of all views (the most VALs a frame can get from them).
    pub texels: u32,
    /// Atlas size, texels.
    pub atlas_size: [u32; 2],
    atlas: wgpu::Texture,
    atlas_view: wgpu::TextureView,
    depth: wgpu::TextureView,
    /// `array<RsmView>`, rewritten every frame (the near and far planes follow the scene).
    rsm_views: wgpu::Buffer,
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::RenderPipeline,
    vals: Kernel,
    /// `vals`' bindings: the atlas, the views and the candidates.
    vals_group: wgpu::BindGroup,
    compact: Compact,
    /// Whether each view draws only what its cull keeps (on unless a test or benchmark turns it
    /// off to compare).
    culling: bool,
}

impl LightRsms {
    /// The RSMs of `lights` for a budget of `budget` VALs; `None` when no light emits anything.
    pub fn new(gpu: &Gpu, scene: &GpuScene, lights: &[Light], budget: u32) -> Result<Option<Self>, GpuError> {
        let flux: Vec<f32> = lights.iter().map(emitted_flux).collect();
        let views_per_light: Vec<u32> = lights.iter().map(views_of).collect();
        let resolutions = split_val_budget(&flux, &views_per_light, budget);
        let mut views = Vec::new();
        let mut texels = 0u32;
        for (i, (light, &r)) in lights.iter().zip(&resolutions).enumerate() {
            if r == 0 {
                continue;
            }
            for view in light_views(light, r) {
                views.push(PlacedView { light: i as u32, view, origin: [0, 0], first_texel: texels });
                texels += r * r;
            }
        }
        if views.is_empty() {
            return Ok(None);
        }
        let sides: Vec<u32> = views.iter().map(|v| v.view.resolution).collect();
        let widest = *sides.iter().max().expect("views is not empty");
        let width = widest.max((texels as f64).sqrt().ceil() as u32);
        let (origins, height) = pack(&sides, width);
        for (v, o) in views.iter_mut().zip(origins) {
            v.origin = o;
        }
        let limit = gpu.device.limits().max_texture_dimension_2d;
        if width.max(height) > limit {
            return Err(GpuError::Unsupported(format!(
                "the lights' RSM atlas needs {width} x {height} texels, over the device's {limit}: lower settings.direct.val_budget"
            )));
        }
        let (atlas, depth) = raster::visibility_textures(gpu, "lights_rsm", width, height);
        let atlas_view = atlas.create_view(&Default::default());
        let rsm_views = gpu.storage_buffer_sized::<RawRsmView>("lights_rsm.rsm_views", views.len())?;
        let module = crate::gpu::pass::module_from_source(gpu, RASTER_STAGE, raster_source(scene.textured()))?;
        let (layout, pipeline) = gpu.build_checked(RASTER_STAGE, || {
            let layout = gpu.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("lights_rsm_raster.layout"),
                entries: &[wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::VERTEX,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: true },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                }],
            });
            let target =
                wgpu::ColorTargetState { format: raster::FORMAT, blend: None, write_mask: wgpu::ColorWrites::ALL };
            let pipeline =
                raster::scene_raster_pipeline(gpu, RASTER_STAGE, &module, &layout, &scene.layout, &[Some(target)]);
            (layout, pipeline)
        })?;
        let vals_module = module_from_source(gpu, VALS_STAGE, PASS.source(&body(), scene.textured()))?;
        let vals = Kernel::build(gpu, scene, &PASS, &vals_module, PASS.entry("main"), &[], PASS.workgroup)?;
        let compact = Compact::new(gpu, scene, &PASS, &vals_module, texels)?;
        let vals_group = vals.bind(
            gpu,
            &[view("atlas", &atlas_view), buffer("rsm_views", &rsm_views), buffer("candidates", &compact.candidates)],
        );
        Ok(Some(Self {
            resolutions,
            views,
            texels,
            atlas_size: [width, height],
            atlas,
            atlas_view,
            depth,
            rsm_views,
            layout,
            pipeline,
            vals,
            vals_group,
            compact,
            culling: true,
        }))
    }

    /// The views as the GPU takes them, near and far fitted to the scene from each light.
    pub fn raw_views(&self, scene: &GpuScene) -> Vec<RawRsmView> {
        let sphere = scene.flat.bounding_sphere();
        self.views
            .iter()
            .map(|p| {
                let v = &p.view;
                let s = &v.frame;
                RawRsmView {
                    world_to_clip: view_to_clip(v, depth_range_around(sphere, s.position)).to_cols_array_2d(),
                    position: s.position.into(),
                    resolution: v.resolution,
                    direction: s.direction.into(),
                    tan_half: v.tan_half,
                    intensity: s.intensity.into(),
                    inner_angle: s.inner_angle,
                    origin: p.origin,
                    first_texel: p.first_texel,
                    outer_angle: s.outer_angle,
                    omega_scale: v.omega_scale,
                    range: v.range.unwrap_or(0.0),
                    _pad0: 0,
                    _pad1: 0,
                }
            })
            .collect()
    }

    /// Draw every triangle into every view (`false`) or only what each view's cull keeps (the
    /// default); the VALs are the same either way, only the raster's cost differs.
    pub fn set_culling(&mut self, on: bool) {
        self.culling = on;
    }

    /// Per view, in order, the triangle ranges its draw covers for the scene as placed now:
    /// everything without the cull; with it, the chunks that may meet the view's frustum (near
    /// and far as in `raw`) and a point light's `range` sphere.
    pub fn draws(&self, scene: &GpuScene, raw: &[RawRsmView]) -> Vec<Vec<Range<u32>>> {
        let triangles = scene.flat.triangle_count();
        if !self.culling {
            return vec![vec![0..triangles]; self.views.len()];
        }
        let chunks = TriangleChunks::new(&scene.flat);
        self.views
            .iter()
            .zip(raw)
            .map(|(p, r)| {
                let sphere = p.view.range.map(|range| (p.view.frame.position, range));
                chunks.visible(glam::Mat4::from_cols_array_2d(&r.world_to_clip), sphere)
            })
            .collect()
    }

    /// The atlas of the last frame, row-major from the top (for the twins and tests).
    pub fn read_atlas(&self, gpu: &Gpu) -> Result<Vec<Option<Hit>>, GpuError> {
        raster::read_visibility(gpu, &self.atlas, self.atlas_size[0], self.atlas_size[1])
    }
}

impl Technique for LightRsms {
    fn stages(&self) -> Vec<&'static str> {
        vec![RASTER_STAGE, VALS_STAGE]
    }

    fn record(&self, gpu: &Gpu, frame: &Frame<'_>, rec: &mut Recorder<'_>) -> Result<(), GpuError> {
        let scene = frame.scene;
        let raw = self.raw_views(scene);
        gpu.queue.write_buffer(&self.rsm_views, 0, bytemuck::cast_slice(&raw));
        let draws = self.draws(scene, &raw);
        let bind_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("lights_rsm_raster.bind_group"),
            layout: &self.layout,
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: self.rsm_views.as_entire_binding() }],
        });
        rec.stage(RASTER_STAGE, |e, s| {
            let mut pass = begin_visibility_pass(e, RASTER_STAGE, &self.atlas_view, &self.depth, s);
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.set_bind_group(1, &scene.bind_group, &[]);
            for (k, (v, ranges)) in self.views.iter().zip(&draws).enumerate() {
                if ranges.is_empty() {
                    continue;
                }
                let ([x, y], r) = (v.origin, v.view.resolution);
                pass.set_viewport(x as f32, y as f32, r as f32, r as f32, 0.0, 1.0);
                pass.set_scissor_rect(x, y, r, r);
                for t in ranges {
                    // Vertex i is corner i % 3 of triangle i / 3 (`light_rsms_raster.wgsl`).
                    pass.draw(3 * t.start..3 * t.end, k as u32..k as u32 + 1);
                }
            }
        })?;
        let vals = (buffer("vals", &frame.vals.buffer), &frame.vals.count);
        let texels = [self.texels, 1, 1];
        rec.stage(VALS_STAGE, |e, s| {
            self.compact.record_after(gpu, e, scene, &[(&self.vals, &self.vals_group, texels)], vals, s)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Largest first along shelves: 4 and 3 on the first shelf of a 7-wide atlas, 2, 2 and 1 on
    /// the next (4 high), so the atlas is 4 + 2 = 6 high.
    #[test]
    fn shelf_packing_known_answer() {
        let (origins, height) = pack(&[2, 4, 1, 3, 2], 7);
        assert_eq!(origins, vec![[0, 4], [0, 0], [4, 4], [4, 0], [2, 4]]);
        assert_eq!(height, 6);
    }
}

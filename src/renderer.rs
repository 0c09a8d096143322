//! A frame: the passes of `gpu/` called in order (DESIGN.md §4), each in a debug group and a
//! timing span. No frame graph; stages and buffers exist only when the scene and the method
//! need them.

use crate::gpu::brute_force::BruteForce;
use crate::gpu::direct::Direct;
use crate::gpu::exact::Exact;
use crate::gpu::gather::Gather;
use crate::gpu::interpolate::Interpolate;
use crate::gpu::occlusion::Occlusion;
use crate::gpu::raw::{RawFrame, RawGathered, RawPointLight, RawVal};
use crate::gpu::renormalise::Renormalise;
use crate::gpu::rsm::{Rsm, RsmOutputs};
use crate::gpu::scene::{FlatScene, GpuScene};
use crate::gpu::shade::Shade;
use crate::gpu::timing::{Recorder, StageTimings};
use crate::gpu::visibility::{Visibility, VisibilityTarget};
use crate::gpu::{Gpu, GpuError, Lobes};
use crate::image::LinearImage;
use crate::reference::rsm::Spot;
use crate::scene::{self, Camera, Scene};
use glam::{Mat4, Vec3};

/// How the indirect light is computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// The sparse model-space method (DESIGN.md §4).
    Sparse,
    /// Every VAL at every visible pixel (DESIGN.md §5).
    BruteForce,
    /// Brute force with a shadow ray per pixel and VAL through a BVH (DESIGN.md §5); see
    /// [`Renderer::set_exact_val_stride`].
    Exact,
}

/// Stage names, as reported in timings.
pub mod stage {
    pub const RSM_RASTER: &str = "rsm_raster";
    pub const RSM_VALS: &str = "rsm_vals";
    pub const VISIBILITY: &str = "visibility";
    pub const GATHER: &str = "gather";
    pub const OCCLUSION: &str = "occlusion";
    pub const RENORMALISE: &str = "renormalise";
    pub const INTERPOLATE: &str = "interpolate";
    pub const SHADE: &str = "shade";
    pub const BRUTE_FORCE: &str = "brute_force";
    pub const EXACT: &str = "exact";
    pub const DIRECT: &str = "direct";
    /// The stages that compute indirect light with the sparse method.
    pub const SPARSE_INDIRECT: &[&str] = &[GATHER, OCCLUSION, RENORMALISE, INTERPOLATE, SHADE];
    /// The stages that compute indirect light by brute force.
    pub const BRUTE_FORCE_INDIRECT: &[&str] = &[BRUTE_FORCE];
}

/// One rendered frame: linear radiance (W/(m² sr)), alpha = 1 where geometry covers the pixel.
pub struct Rendered {
    pub direct: LinearImage,
    pub indirect: LinearImage,
    pub timings: StageTimings,
    /// VALs with non-zero flux this frame.
    pub val_count: u32,
}

struct SparsePasses {
    gather: Gather,
    /// Only when the scene asks for occlusion.
    occlusion: Option<Occlusion>,
    renormalise: Renormalise,
    interpolate: Interpolate,
    shade: Shade,
    gathered: Lobes,
    sparse_lights: Lobes,
    vertex_lights: Lobes,
}

struct CameraTarget {
    view: VisibilityTarget,
    indirect: wgpu::Buffer,
    direct: wgpu::Buffer,
}

pub struct Renderer {
    pub scene: GpuScene,
    glossy: bool,
    spot: Spot,
    camera: Camera,
    rsm_resolution: u32,
    occlusion: scene::Occlusion,
    occlusion_rule: scene::OcclusionRule,
    visibility: Visibility,
    rsm: Rsm,
    direct: Direct,
    /// The light's visibility buffer (the RSM).
    pub rsm_view: VisibilityTarget,
    /// `array<Val>` with capacity R².
    pub vals: wgpu::Buffer,
    /// One `u32`: how many of `vals` are live.
    pub val_count: wgpu::Buffer,
    light_distance: wgpu::Buffer,
    sparse: Option<SparsePasses>,
    brute_force: Option<BruteForce>,
    exact: Option<Exact>,
    exact_val_stride: u32,
    target: Option<CameraTarget>,
}

impl Renderer {
    pub fn new(gpu: &Gpu, scene: &Scene) -> Result<Self, GpuError> {
        let scene_gpu = GpuScene::new(gpu, FlatScene::from_scene(scene))?;
        let glossy = scene.settings.glossy && scene_gpu.has_glossy_material();
        let r = scene.settings.rsm_resolution;
        let texels = (r * r) as usize;
        let visibility = Visibility::new(gpu, &scene_gpu)?;
        let rsm_view = visibility.target(gpu, "rsm", r, r);
        Ok(Self {
            rsm: Rsm::new(gpu, &scene_gpu)?,
            direct: Direct::new(gpu, &scene_gpu)?,
            vals: gpu.storage_buffer_sized::<RawVal>("rsm.vals", texels)?,
            val_count: gpu.storage_buffer_sized::<u32>("rsm.val_count", 1)?,
            light_distance: gpu.storage_buffer_sized::<f32>("rsm.light_distance", texels)?,
            visibility,
            rsm_view,
            glossy,
            spot: Spot {
                position: scene.light.position,
                direction: scene.light.direction,
                inner_angle: scene.light.inner_angle,
                outer_angle: scene.light.outer_angle,
                intensity: scene.light.intensity,
            },
            camera: scene.camera,
            rsm_resolution: r,
            occlusion: scene.settings.occlusion,
            occlusion_rule: scene.settings.occlusion_rule,
            scene: scene_gpu,
            sparse: None,
            brute_force: None,
            exact: None,
            exact_val_stride: 1,
            target: None,
        })
    }

    /// Use every `stride`-th VAL (flux scaled by `stride`) in the exact reference, whose cost
    /// is pixels x VALs x BVH traversal. 1 (the default) uses them all.
    pub fn set_exact_val_stride(&mut self, stride: u32) {
        if stride.max(1) != self.exact_val_stride {
            self.exact_val_stride = stride.max(1);
            self.exact = None;
        }
    }

    /// Change the occlusion mode; the sparse passes are rebuilt on the next sparse frame.
    pub fn set_occlusion(&mut self, occlusion: scene::Occlusion, rule: scene::OcclusionRule) {
        if (occlusion, rule) != (self.occlusion, self.occlusion_rule) {
            self.occlusion = occlusion;
            self.occlusion_rule = rule;
            self.sparse = None;
        }
    }

    /// Whether the glossy stages run for this scene.
    pub fn glossy(&self) -> bool {
        self.glossy
    }

    pub fn spot(&self) -> Spot {
        self.spot
    }

    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// Render the next frames from `camera` (its `width` and `height` are ignored: each frame
    /// is rendered at the size passed to [`Renderer::render`]).
    pub fn set_camera(&mut self, camera: Camera) {
        self.camera = camera;
    }

    /// Light the next frames with `light` instead of the scene's spot light. The RSM and its
    /// VALs are rebuilt every frame, so nothing else changes.
    pub fn set_spot_light(&mut self, light: &scene::SpotLight) {
        self.spot = Spot {
            position: light.position,
            direction: light.direction,
            inner_angle: light.inner_angle,
            outer_angle: light.outer_angle,
            intensity: light.intensity,
        };
    }

    /// Render at `width` x `height` with the scene's camera.
    pub fn render(&mut self, gpu: &Gpu, method: Method, width: u32, height: u32) -> Result<Rendered, GpuError> {
        self.prepare(gpu, method, width, height)?;
        let (camera_to_clip, light_to_clip) = self.view_transforms(width, height);
        let frame = self.frame_uniforms(camera_to_clip, light_to_clip, width, height);
        gpu.queue.write_buffer(&self.scene.frame, 0, bytemuck::bytes_of(&frame));

        let mut rec = Recorder::new(gpu, "relume.frame", 12);
        let scene = &self.scene;
        rec.stage(stage::RSM_RASTER, |e, s| self.visibility.record(gpu, e, scene, &self.rsm_view, light_to_clip, s))?;
        let rsm_out = RsmOutputs { vals: &self.vals, val_count: &self.val_count, light_distance: &self.light_distance };
        rec.stage(stage::RSM_VALS, |e, s| self.rsm.record(gpu, e, scene, &self.rsm_view, &rsm_out, s))?;
        let target = self.target.as_ref().expect("prepared above");
        rec.stage(stage::VISIBILITY, |e, s| self.visibility.record(gpu, e, scene, &target.view, camera_to_clip, s))?;
        match method {
            Method::Sparse => {
                let p = self.sparse.as_ref().expect("prepared above");
                rec.stage(stage::GATHER, |e, s| {
                    p.gather.record(gpu, e, scene, &self.vals, &self.val_count, &p.gathered, s)
                })?;
                if let Some(o) = &p.occlusion {
                    rec.stage(stage::OCCLUSION, |e, s| o.record(gpu, e, scene, &p.gathered, s))?;
                }
                rec.stage(stage::RENORMALISE, |e, s| {
                    p.renormalise.record(gpu, e, scene, &p.gathered, &p.sparse_lights, s)
                })?;
                rec.stage(stage::INTERPOLATE, |e, s| {
                    p.interpolate.record(gpu, e, scene, &p.sparse_lights, &p.vertex_lights, s)
                })?;
                rec.stage(stage::SHADE, |e, s| {
                    p.shade.record(gpu, e, scene, &target.view, &p.vertex_lights, &target.indirect, s)
                })?;
            }
            Method::BruteForce => {
                let b = self.brute_force.as_ref().expect("prepared above");
                rec.stage(stage::BRUTE_FORCE, |e, s| {
                    b.record(gpu, e, scene, &target.view, &self.vals, &self.val_count, &target.indirect, s)
                })?;
            }
            Method::Exact => {
                let x = self.exact.as_ref().expect("prepared above");
                rec.stage(stage::EXACT, |e, s| {
                    x.record(gpu, e, scene, &target.view, &self.vals, &self.val_count, &target.indirect, s)
                })?;
            }
        }
        rec.stage(stage::DIRECT, |e, s| {
            self.direct.record(gpu, e, scene, &target.view, &self.light_distance, &target.direct, s)
        })?;
        let timings = rec.finish()?;

        let pixels = (width * height) as usize;
        let indirect = gpu.read_buffer::<[f32; 4]>(&target.indirect, pixels)?;
        let direct = gpu.read_buffer::<[f32; 4]>(&target.direct, pixels)?;
        let val_count = gpu.read_buffer::<u32>(&self.val_count, 1)?[0];
        Ok(Rendered {
            direct: LinearImage { width, height, pixels: direct },
            indirect: LinearImage { width, height, pixels: indirect },
            timings,
            val_count,
        })
    }

    /// Build the pipelines and buffers `method` needs at this size, once.
    fn prepare(&mut self, gpu: &Gpu, method: Method, width: u32, height: u32) -> Result<(), GpuError> {
        let scene = &self.scene;
        match method {
            Method::Sparse if self.sparse.is_none() => {
                let glossy = self.glossy;
                let n = scene.flat.sparse_points.len();
                let v = scene.flat.vertices.len();
                self.sparse = Some(SparsePasses {
                    gather: Gather::new(gpu, scene, glossy)?,
                    occlusion: match self.occlusion {
                        scene::Occlusion::Off => None,
                        scene::Occlusion::Disks => {
                            let product = self.occlusion_rule == scene::OcclusionRule::Product;
                            Some(Occlusion::new(gpu, scene, glossy, product)?)
                        }
                    },
                    renormalise: Renormalise::new(gpu, scene, glossy)?,
                    interpolate: Interpolate::new(gpu, scene, glossy)?,
                    shade: Shade::new(gpu, scene, glossy)?,
                    gathered: Lobes::new::<RawGathered>(gpu, "gather.gathered", n, glossy)?,
                    sparse_lights: Lobes::new::<RawPointLight>(gpu, "renormalise.sparse_lights", n, glossy)?,
                    vertex_lights: Lobes::new::<RawPointLight>(gpu, "interpolate.vertex_lights", v, glossy)?,
                });
            }
            Method::BruteForce if self.brute_force.is_none() => {
                self.brute_force = Some(BruteForce::new(gpu, scene, self.glossy)?);
            }
            Method::Exact if self.exact.is_none() => {
                self.exact = Some(Exact::new(gpu, scene, self.glossy, self.exact_val_stride)?);
            }
            _ => {}
        }
        let size_matches = self.target.as_ref().is_some_and(|t| t.view.width == width && t.view.height == height);
        if !size_matches {
            let pixels = (width * height) as usize;
            self.target = Some(CameraTarget {
                view: self.visibility.target(gpu, "camera", width, height),
                indirect: gpu.storage_buffer_sized::<[f32; 4]>("frame.indirect", pixels)?,
                direct: gpu.storage_buffer_sized::<[f32; 4]>("frame.direct", pixels)?,
            });
        }
        Ok(())
    }

    /// (camera world-to-clip, light world-to-clip), with near and far planes fitted to the scene.
    pub fn view_transforms(&self, width: u32, height: u32) -> (Mat4, Mat4) {
        let (centre, radius) = self.scene.flat.bounding_sphere();
        let fit = |eye: Vec3| {
            let far = (eye.distance(centre) + radius).max(1e-3) * 1.01;
            (far * 1e-4, far)
        };
        let c = &self.camera;
        let (near, far) = fit(c.position);
        let camera = glam::camera::rh::proj::directx::perspective(c.fov_y, width as f32 / height as f32, near, far)
            * glam::camera::rh::view::look_at_mat4(c.position, c.target, c.up);
        let s = &self.spot;
        let up = if s.direction.y.abs() > 0.99 { Vec3::Z } else { Vec3::Y };
        let (near, far) = fit(s.position);
        let light = glam::camera::rh::proj::directx::perspective(2.0 * s.outer_angle, 1.0, near, far)
            * glam::camera::rh::view::look_at_mat4(s.position, s.position + s.direction, up);
        (camera, light)
    }

    fn frame_uniforms(&self, camera: Mat4, light: Mat4, width: u32, height: u32) -> RawFrame {
        let flat = &self.scene.flat;
        RawFrame {
            world_to_clip: camera.to_cols_array_2d(),
            light_world_to_clip: light.to_cols_array_2d(),
            eye: self.camera.position.into(),
            width,
            light_position: self.spot.position.into(),
            height,
            light_direction: self.spot.direction.into(),
            rsm_resolution: self.rsm_resolution,
            light_intensity: self.spot.intensity.into(),
            light_inner_angle: self.spot.inner_angle,
            light_outer_angle: self.spot.outer_angle,
            sparse_count: flat.sparse_count(),
            vertex_count: flat.vertex_count(),
            triangle_count: flat.triangle_count(),
        }
    }

    /// The camera's visibility buffer of the last frame.
    pub fn camera_view(&self) -> Option<&VisibilityTarget> {
        self.target.as_ref().map(|t| &t.view)
    }

    /// The live VALs of the last frame (for the CPU twins and diagnostics).
    pub fn read_vals(&self, gpu: &Gpu) -> Result<Vec<crate::reference::Val>, GpuError> {
        let n = gpu.read_buffer::<u32>(&self.val_count, 1)?[0] as usize;
        Ok(gpu.read_buffer::<RawVal>(&self.vals, n)?.iter().map(Into::into).collect())
    }

    /// The last sparse frame's intermediate buffers: (gathered, sparse lights, vertex lights),
    /// each per lobe (glossy empty when the scene has none).
    pub fn read_sparse_intermediates(&self, gpu: &Gpu) -> Result<SparseIntermediates, GpuError> {
        let Some(p) = &self.sparse else {
            return Ok(SparseIntermediates::default());
        };
        let n = self.scene.flat.sparse_points.len();
        let v = self.scene.flat.vertices.len();
        let (gathered_diffuse, gathered_glossy) = read_lobes::<RawGathered>(gpu, &p.gathered, n)?;
        let (sparse_diffuse, sparse_glossy) = read_lobes::<RawPointLight>(gpu, &p.sparse_lights, n)?;
        let (vertex_diffuse, vertex_glossy) = read_lobes::<RawPointLight>(gpu, &p.vertex_lights, v)?;
        Ok(SparseIntermediates {
            gathered_diffuse,
            gathered_glossy,
            sparse_diffuse,
            sparse_glossy,
            vertex_diffuse,
            vertex_glossy,
        })
    }
}

/// Both lobes of `l` (the glossy one empty when absent).
fn read_lobes<T: bytemuck::Pod>(gpu: &Gpu, l: &Lobes, count: usize) -> Result<(Vec<T>, Vec<T>), GpuError> {
    let glossy = match &l.glossy {
        Some(b) => gpu.read_buffer::<T>(b, count)?,
        None => Vec::new(),
    };
    Ok((gpu.read_buffer::<T>(&l.diffuse, count)?, glossy))
}

/// GPU intermediates of the sparse pipeline, read back.
#[derive(Default)]
pub struct SparseIntermediates {
    pub gathered_diffuse: Vec<RawGathered>,
    pub gathered_glossy: Vec<RawGathered>,
    pub sparse_diffuse: Vec<RawPointLight>,
    pub sparse_glossy: Vec<RawPointLight>,
    pub vertex_diffuse: Vec<RawPointLight>,
    pub vertex_glossy: Vec<RawPointLight>,
}

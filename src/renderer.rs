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
use crate::gpu::rgbd::RgbdVals;
use crate::gpu::rsm::{Rsm, RsmOutputs};
use crate::gpu::scene::{FlatScene, GpuScene};
use crate::gpu::shade::Shade;
use crate::gpu::timing::{Recorder, StageTimings};
use crate::gpu::visibility::{Visibility, VisibilityTarget};
use crate::gpu::{Gpu, GpuError, Lobes};
use crate::image::LinearImage;
use crate::reference::rsm::Spot;
use crate::rgbd::{Intrinsics, RgbdFrame, RgbdSettings};
use crate::scene::{self, Camera, Scene};
use glam::{Affine3A, Mat4, Vec3, Vec4};

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
    pub const RGBD_VALS: &str = "rgbd_vals";
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
    /// Method::Exact: the rounds it took (see `gpu::exact`); 0 for the other methods.
    pub exact_rounds: u32,
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

/// The spot light's stages and buffers: only for scenes with a spot light.
struct SpotPasses {
    spot: Spot,
    resolution: u32,
    rsm: Rsm,
    direct: Direct,
    /// The light's visibility buffer (the RSM).
    view: VisibilityTarget,
    /// Distance from the light to the surface each RSM texel sees: the direct pass's shadow map.
    light_distance: wgpu::Buffer,
}

/// Where the camera image is rendered from.
#[derive(Clone, Copy, Debug)]
pub enum View {
    /// The scene file's perspective camera.
    Scene(Camera),
    /// A pinhole camera (an RGB-D frame's): intrinsics, scaled to the render size, and a
    /// camera-to-world pose in optical axes (x right, y down, z forward).
    Pinhole { intrinsics: Intrinsics, camera_to_world: Affine3A },
}

impl View {
    /// World-space position of the eye.
    pub fn eye(&self) -> Vec3 {
        match self {
            View::Scene(c) => c.position,
            View::Pinhole { camera_to_world, .. } => camera_to_world.translation.into(),
        }
    }
}

pub struct Renderer {
    pub scene: GpuScene,
    glossy: bool,
    view: View,
    occlusion: scene::Occlusion,
    occlusion_rule: scene::OcclusionRule,
    visibility: Visibility,
    spot: Option<SpotPasses>,
    /// `array<Val>`: the spot light's VALs (R² at most) after the uploaded ones.
    pub vals: wgpu::Buffer,
    val_capacity: u32,
    /// One `u32`: how many VALs were appended (readers clamp it to the capacity).
    pub val_count: wgpu::Buffer,
    /// How many VALs [`Renderer::set_vals`] put at the front of `vals`, kept every frame.
    uploaded_vals: u32,
    /// The RGB-D VAL pass for the intrinsics and settings it was built for, once a frame was
    /// given; it runs while `rgbd_active`.
    rgbd: Option<(Intrinsics, RgbdSettings, RgbdVals)>,
    rgbd_active: bool,
    sparse: Option<SparsePasses>,
    brute_force: Option<BruteForce>,
    exact: Option<Exact>,
    exact_val_stride: u32,
    target: Option<CameraTarget>,
    /// Model-to-world of each mesh, as uploaded.
    placement: Vec<Mat4>,
}

impl Renderer {
    pub fn new(gpu: &Gpu, scene: &Scene) -> Result<Self, GpuError> {
        let scene_gpu = GpuScene::new(gpu, FlatScene::from_scene(scene))?;
        let glossy = scene.settings.glossy && scene_gpu.has_glossy_material();
        let visibility = Visibility::new(gpu, &scene_gpu)?;
        let spot = match &scene.light {
            None => None,
            Some(light) => {
                let r = scene.settings.rsm_resolution;
                Some(SpotPasses {
                    spot: spot_of(light),
                    resolution: r,
                    rsm: Rsm::new(gpu, &scene_gpu)?,
                    direct: Direct::new(gpu, &scene_gpu)?,
                    view: visibility.target(gpu, "rsm", r, r),
                    light_distance: gpu.storage_buffer_sized::<f32>("rsm.light_distance", (r * r) as usize)?,
                })
            }
        };
        let val_capacity = spot.as_ref().map_or(1, |s| s.resolution * s.resolution);
        Ok(Self {
            vals: gpu.storage_buffer_sized::<RawVal>("vals", val_capacity as usize)?,
            val_capacity,
            val_count: gpu.storage_buffer_sized::<u32>("val_count", 1)?,
            uploaded_vals: 0,
            rgbd: None,
            rgbd_active: false,
            visibility,
            spot,
            glossy,
            view: View::Scene(scene.camera),
            occlusion: scene.settings.occlusion,
            occlusion_rule: scene.settings.occlusion_rule,
            scene: scene_gpu,
            sparse: None,
            brute_force: None,
            exact: None,
            exact_val_stride: 1,
            target: None,
            placement: scene.meshes.iter().map(|m| m.model_to_world).collect(),
        })
    }

    /// Place mesh `i` of `scene` (the scene this renderer was built from) by
    /// `model_to_world[i]` from the next frame on: the vertices and the sparse points, which
    /// live in model space, move with it; nothing is rebuilt but the exact reference's BVH.
    /// Nothing happens when the placement is unchanged.
    pub fn place_meshes(&mut self, gpu: &Gpu, scene: &Scene, model_to_world: &[Mat4]) {
        if model_to_world == self.placement.as_slice() {
            return;
        }
        let mut flat = FlatScene::geometry_placed(scene, model_to_world);
        assert!(
            (flat.vertex_count(), flat.sparse_count())
                == (self.scene.flat.vertex_count(), self.scene.flat.sparse_count()),
            "place_meshes needs the scene the renderer was built from"
        );
        gpu.queue.write_buffer(&self.scene.vertices, 0, bytemuck::cast_slice(&flat.vertices));
        gpu.queue.write_buffer(&self.scene.sparse_points, 0, bytemuck::cast_slice(&flat.sparse_points));
        flat.textures = self.scene.flat.textures.take();
        self.scene.flat = flat;
        self.placement = model_to_world.to_vec();
        self.exact = None;
    }

    /// Stop lighting with an RGB-D frame's or uploaded VALs: the scene's spot light alone.
    pub fn clear_vals(&mut self) {
        self.rgbd_active = false;
        self.uploaded_vals = 0;
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

    /// Allow or forbid the glossy gather (it still runs only when a material is glossy); the
    /// passes are rebuilt on the next frame when this changes whether it runs.
    pub fn set_glossy(&mut self, allowed: bool) {
        let glossy = allowed && self.scene.has_glossy_material();
        if glossy != self.glossy {
            self.glossy = glossy;
            self.sparse = None;
            self.brute_force = None;
            self.exact = None;
        }
    }

    /// Drop the brute-force and exact passes (the exact one holds the BVH's buffers); they are
    /// rebuilt when next asked for.
    pub fn release_reference_passes(&mut self) {
        self.brute_force = None;
        self.exact = None;
    }

    /// Whether the glossy stages run for this scene.
    pub fn glossy(&self) -> bool {
        self.glossy
    }

    /// The spot light, when the scene has one.
    pub fn spot(&self) -> Option<Spot> {
        self.spot.as_ref().map(|s| s.spot)
    }

    /// The spot light's visibility buffer (its RSM), when the scene has a spot light.
    pub fn rsm_view(&self) -> Option<&VisibilityTarget> {
        self.spot.as_ref().map(|s| &s.view)
    }

    pub fn view(&self) -> &View {
        &self.view
    }

    /// Render from `view` from now on.
    pub fn set_view(&mut self, view: View) {
        self.view = view;
    }

    /// Light every following frame with `vals` (e.g. RGB-D VALs accumulated over frames), plus
    /// the spot light's when the scene has one, instead of an RGB-D frame's. An empty slice
    /// removes them.
    pub fn set_vals(&mut self, gpu: &Gpu, vals: &[crate::reference::Val]) -> Result<(), GpuError> {
        self.rgbd_active = false;
        self.uploaded_vals = vals.len() as u32;
        self.ensure_val_capacity(gpu)?;
        let raw: Vec<RawVal> = vals.iter().map(RawVal::from).collect();
        if !raw.is_empty() {
            gpu.queue.write_buffer(&self.vals, 0, bytemuck::cast_slice(&raw));
        }
        Ok(())
    }

    /// Light every following frame with `frame`'s VALs (DESIGN.md §2 "RGB-D frames"), made on
    /// the GPU in the frame's `rgbd_vals` stage, plus the spot light's when the scene has one.
    pub fn set_rgbd_frame(&mut self, gpu: &Gpu, frame: &RgbdFrame, settings: &RgbdSettings) -> Result<(), GpuError> {
        let built_for_frame = self.rgbd.as_ref().is_some_and(|(k, s, _)| (*k, *s) == (frame.intrinsics, *settings));
        if !built_for_frame {
            let pass = RgbdVals::new(gpu, &self.scene, frame.intrinsics, settings)?;
            self.rgbd = Some((frame.intrinsics, *settings, pass));
        }
        self.uploaded_vals = 0;
        self.rgbd_active = true;
        self.ensure_val_capacity(gpu)?;
        self.rgbd.as_ref().expect("built above").2.upload(gpu, frame)
    }

    /// `frame`'s VALs alone, made on the GPU and read back (for accumulation across frames).
    /// The RGB-D stage stays off for the following frames: give them VALs with `set_vals`.
    pub fn rgbd_frame_vals(
        &mut self,
        gpu: &Gpu,
        frame: &RgbdFrame,
        settings: &RgbdSettings,
    ) -> Result<Vec<crate::reference::Val>, GpuError> {
        self.set_rgbd_frame(gpu, frame, settings)?;
        self.rgbd_active = false;
        let (_, _, pass) = self.rgbd.as_ref().expect("built above");
        gpu.queue.write_buffer(&self.val_count, 0, bytemuck::bytes_of(&0u32));
        let mut encoder = gpu.device.create_command_encoder(&Default::default());
        pass.record(gpu, &mut encoder, &self.vals, &self.val_count, self.val_capacity, None);
        gpu.submit_and_wait(encoder)?;
        self.read_vals(gpu)
    }

    /// Grow `vals` to hold the uploaded VALs, the RGB-D frame's and the spot light's. A new
    /// buffer starts empty: callers write the uploaded VALs after this.
    fn ensure_val_capacity(&mut self, gpu: &Gpu) -> Result<(), GpuError> {
        let rsm = self.spot.as_ref().map_or(0, |s| s.resolution * s.resolution);
        let rgbd = match (&self.rgbd, self.rgbd_active) {
            (Some((_, _, pass)), true) => pass.max_vals(),
            _ => 0,
        };
        let needed = self.uploaded_vals + rgbd + rsm;
        if needed > self.val_capacity {
            self.val_capacity = needed.next_power_of_two();
            self.vals = gpu.storage_buffer_sized::<RawVal>("vals", self.val_capacity as usize)?;
        }
        Ok(())
    }

    /// Render the next frames from `camera` (its `width` and `height` are ignored: each frame
    /// is rendered at the size passed to [`Renderer::render`]).
    pub fn set_camera(&mut self, camera: Camera) {
        self.view = View::Scene(camera);
    }

    /// Light the next frames with `light` instead of the scene's spot light. The RSM and its
    /// VALs are rebuilt every frame, so nothing else changes. A scene without a spot light has
    /// no RSM stages: nothing happens (the service refuses such overrides before).
    pub fn set_spot_light(&mut self, light: &scene::SpotLight) {
        if let Some(sp) = &mut self.spot {
            sp.spot = spot_of(light);
        }
    }

    /// Render at `width` x `height` with the scene's camera.
    pub fn render(&mut self, gpu: &Gpu, method: Method, width: u32, height: u32) -> Result<Rendered, GpuError> {
        self.prepare(gpu, method, width, height)?;
        let (camera_to_clip, light_to_clip) = self.view_transforms(width, height);
        let frame = self.frame_uniforms(camera_to_clip, light_to_clip.unwrap_or(Mat4::IDENTITY), width, height);
        gpu.queue.write_buffer(&self.scene.frame, 0, bytemuck::bytes_of(&frame));

        // Uploaded VALs stay at the front; the RGB-D frame's and the spot light's are appended.
        gpu.queue.write_buffer(&self.val_count, 0, bytemuck::bytes_of(&self.uploaded_vals));

        let mut rec = Recorder::new(gpu, "relume.frame", 12);
        let scene = &self.scene;
        if let Some(sp) = &self.spot {
            let light_to_clip = light_to_clip.expect("a spot light has a view");
            rec.stage(stage::RSM_RASTER, |e, s| self.visibility.record(gpu, e, scene, &sp.view, light_to_clip, s))?;
            let rsm_out =
                RsmOutputs { vals: &self.vals, val_count: &self.val_count, light_distance: &sp.light_distance };
            rec.stage(stage::RSM_VALS, |e, s| sp.rsm.record(gpu, e, scene, &sp.view, &rsm_out, s))?;
        }
        if let (true, Some((_, _, pass))) = (self.rgbd_active, &self.rgbd) {
            rec.stage(stage::RGBD_VALS, |e, s| pass.record(gpu, e, &self.vals, &self.val_count, self.val_capacity, s))?;
        }
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
        if let Some(sp) = &self.spot {
            rec.stage(stage::DIRECT, |e, s| {
                sp.direct.record(gpu, e, scene, &target.view, &sp.light_distance, &target.direct, s)
            })?;
        }
        let mut timings = rec.finish()?;
        let mut exact_rounds = 0;
        if let (Method::Exact, Some(x)) = (method, &self.exact) {
            let rounds = x.finish(gpu, scene, &target.view, &self.vals, &self.val_count, &target.indirect)?;
            // Rounds after the first are timed by wall clock, whatever timed the first.
            if let Some((_, ms)) = timings.stages.iter_mut().find(|(name, _)| name == stage::EXACT) {
                *ms += rounds.extra_ms;
            }
            exact_rounds = rounds.count;
        }

        let pixels = (width * height) as usize;
        let indirect = gpu.read_buffer::<[f32; 4]>(&target.indirect, pixels)?;
        let direct = match self.spot {
            Some(_) => gpu.read_buffer::<[f32; 4]>(&target.direct, pixels)?,
            // No light of its own: the direct image is black where the geometry is.
            None => indirect.iter().map(|p| [0.0, 0.0, 0.0, p[3]]).collect(),
        };
        let val_count = self.live_val_count(gpu)?;
        Ok(Rendered {
            direct: LinearImage { width, height, pixels: direct },
            indirect: LinearImage { width, height, pixels: indirect },
            timings,
            val_count,
            exact_rounds,
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
        if let (Method::Exact, Some(x)) = (method, &mut self.exact) {
            x.fit(gpu, (width * height) as usize)?;
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
        if let Some(p) = self.sparse.as_mut() {
            p.gather.fit(gpu, &self.scene, self.val_capacity)?;
        }
        if let Some(b) = self.brute_force.as_mut() {
            b.fit(gpu, &self.scene, self.val_capacity)?;
        }
        Ok(())
    }

    /// How many VALs the VAL buffer holds at most (what the frame's passes must cover).
    pub fn val_capacity(&self) -> u32 {
        self.val_capacity
    }

    /// (camera world-to-clip, light world-to-clip when there is a spot light), with near and far
    /// planes fitted to the scene.
    pub fn view_transforms(&self, width: u32, height: u32) -> (Mat4, Option<Mat4>) {
        let (centre, radius) = self.scene.flat.bounding_sphere();
        let fit = |eye: Vec3| {
            let far = (eye.distance(centre) + radius).max(1e-3) * 1.01;
            (far * 1e-4, far)
        };
        let (near, far) = fit(self.view.eye());
        let camera = match &self.view {
            View::Scene(c) => {
                glam::camera::rh::proj::directx::perspective(c.fov_y, width as f32 / height as f32, near, far)
                    * glam::camera::rh::view::look_at_mat4(c.position, c.target, c.up)
            }
            View::Pinhole { intrinsics, camera_to_world } => {
                pinhole_to_clip(&intrinsics.scaled_to(width, height), near, far) * Mat4::from(camera_to_world.inverse())
            }
        };
        let light = self.spot.as_ref().map(|sp| {
            let s = &sp.spot;
            let up = if s.direction.y.abs() > 0.99 { Vec3::Z } else { Vec3::Y };
            let (near, far) = fit(s.position);
            glam::camera::rh::proj::directx::perspective(2.0 * s.outer_angle, 1.0, near, far)
                * glam::camera::rh::view::look_at_mat4(s.position, s.position + s.direction, up)
        });
        (camera, light)
    }

    fn frame_uniforms(&self, camera: Mat4, light: Mat4, width: u32, height: u32) -> RawFrame {
        let flat = &self.scene.flat;
        // Without a spot light its fields are unused: zero intensity, a valid cone.
        let (spot, resolution) = match &self.spot {
            Some(sp) => (sp.spot, sp.resolution),
            None => (
                Spot {
                    position: Vec3::ZERO,
                    direction: Vec3::NEG_Y,
                    inner_angle: 0.0,
                    outer_angle: 0.5,
                    intensity: Vec3::ZERO,
                },
                0,
            ),
        };
        RawFrame {
            world_to_clip: camera.to_cols_array_2d(),
            light_world_to_clip: light.to_cols_array_2d(),
            eye: self.view.eye().into(),
            width,
            light_position: spot.position.into(),
            height,
            light_direction: spot.direction.into(),
            rsm_resolution: resolution,
            light_intensity: spot.intensity.into(),
            light_inner_angle: spot.inner_angle,
            light_outer_angle: spot.outer_angle,
            sparse_count: flat.sparse_count(),
            vertex_count: flat.vertex_count(),
            triangle_count: flat.triangle_count(),
        }
    }

    /// The camera's visibility buffer of the last frame.
    pub fn camera_view(&self) -> Option<&VisibilityTarget> {
        self.target.as_ref().map(|t| &t.view)
    }

    /// How many VALs lit the last frame (appends past the capacity are dropped).
    fn live_val_count(&self, gpu: &Gpu) -> Result<u32, GpuError> {
        Ok(gpu.read_buffer::<u32>(&self.val_count, 1)?[0].min(self.val_capacity))
    }

    /// The live VALs of the last frame (for the CPU twins and diagnostics).
    pub fn read_vals(&self, gpu: &Gpu) -> Result<Vec<crate::reference::Val>, GpuError> {
        let n = self.live_val_count(gpu)? as usize;
        Ok(gpu.read_buffer::<RawVal>(&self.vals, n)?.iter().map(Into::into).collect())
    }

    /// Diffuse irradiance (W/m²) the last sparse frame gathered at each sparse point (after
    /// occlusion); empty before the first sparse frame.
    pub fn read_gathered_irradiance(&self, gpu: &Gpu) -> Result<Vec<Vec3>, GpuError> {
        let Some(p) = &self.sparse else {
            return Ok(Vec::new());
        };
        let gathered = gpu.read_buffer::<RawGathered>(&p.gathered.diffuse, self.scene.flat.sparse_points.len())?;
        Ok(gathered.iter().map(|g| Vec3::from(g.irradiance)).collect())
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

/// The spot light as the RSM and direct passes take it.
fn spot_of(light: &scene::SpotLight) -> Spot {
    Spot {
        position: light.position,
        direction: light.direction,
        inner_angle: light.inner_angle,
        outer_angle: light.outer_angle,
        intensity: light.intensity,
    }
}

/// Optical camera coordinates (x right, y down, z forward) to wgpu clip space for a pinhole
/// camera whose pixel centres sit at integer coordinates: the image spans u in [-0.5, w - 0.5].
/// Depth maps `near..far` to `0..1` like `perspective` (DirectX convention).
pub fn pinhole_to_clip(k: &Intrinsics, near: f32, far: f32) -> Mat4 {
    let (w, h) = (k.width as f32, k.height as f32);
    let depth = far / (far - near);
    Mat4::from_cols(
        Vec4::new(2.0 * k.fx / w, 0.0, 0.0, 0.0),
        Vec4::new(0.0, -2.0 * k.fy / h, 0.0, 0.0),
        Vec4::new(2.0 * (k.cx + 0.5) / w - 1.0, 1.0 - 2.0 * (k.cy + 0.5) / h, depth, 1.0),
        Vec4::new(0.0, 0.0, -near * depth, 0.0),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The clip transform lands a point on the pixel the intrinsics project it to, and maps the
    /// near and far planes to depth 0 and 1.
    #[test]
    fn pinhole_to_clip_matches_intrinsics() {
        let k = Intrinsics { width: 64, height: 48, fx: 50.0, fy: 55.0, cx: 30.2, cy: 25.7 };
        let m = pinhole_to_clip(&k, 0.1, 10.0);
        for p in [Vec3::new(0.3, -0.2, 1.5), Vec3::new(-1.0, 0.7, 4.0), Vec3::new(0.0, 0.0, 0.1)] {
            let clip = m * p.extend(1.0);
            let ndc = clip.truncate() / clip.w;
            let pixel = glam::Vec2::new((ndc.x + 1.0) * 0.5 * 64.0 - 0.5, (1.0 - ndc.y) * 0.5 * 48.0 - 0.5);
            assert!((pixel - k.project(p)).abs().max_element() < 1e-4, "{p}: {pixel} vs {}", k.project(p));
        }
        let depth = |z: f32| {
            let c = m * Vec4::new(0.0, 0.0, z, 1.0);
            c.z / c.w
        };
        assert!(depth(0.1).abs() < 1e-6 && (depth(10.0) - 1.0).abs() < 1e-6);
    }

    /// Scaling the intrinsics keeps the image of a point at the same fraction of the image.
    #[test]
    fn scaled_intrinsics_keep_image_fractions() {
        let k = Intrinsics::TUM;
        let half = k.scaled_to(320, 240);
        let p = Vec3::new(0.4, -0.3, 2.0);
        let (a, b) = (k.project(p), half.project(p));
        assert!(((a.x + 0.5) / 640.0 - (b.x + 0.5) / 320.0).abs() < 1e-6);
        assert!(((a.y + 0.5) / 480.0 - (b.y + 0.5) / 240.0).abs() < 1e-6);
    }
}

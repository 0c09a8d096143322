//! A frame: the ordered list of the techniques the scene and the request need
//! (`gpu::technique`), each pass in a debug group and a timing span. A list, not a frame graph;
//! stages and buffers exist only when the scene, the method and the components asked for need
//! them.
//!
//! ```text
//! spot light:  SpotVals (rsm_raster, rsm_vals)  ─┐
//! `lights`:    LightRsms (lights_rsm_raster,     │
//!              lights_rsm_vals)                  ├─ VALs
//! RGB-D frame: RgbdVals (rgbd_vals)             ─┘
//! bounces 2:   SecondBounce ([bounce2_ism_sampling, bounce2_ism_splat, bounce2_ism_pull_push,
//!              bounce2_visibility: the first bounce's maps at its points, sparse `ism` or
//!              `clusters` only], bounce2_points, [bounce2_occlusion: sparse `disks` only],
//!              bounce2_vals): appends the second bounce's VALs
//! camera:      CameraView (visibility)
//! indirect:    SparseMethod (gather, [visibility mode], renormalise, interpolate, shade)
//!              | BruteForce (brute_force) | BruteForce for brute_force_ism
//!              (brute_force_ism_sampling, _splat, _pull_push, _visibility, brute_force)
//!              | BruteForce for brute_force_clusters (brute_force_clusters_clustering,
//!              _shadow_maps, brute_force: the maps looked up in it) | Exact (exact)
//! direct:      DirectLight (direct), then for the scene's `lights`
//!              ManyLights (lights_shadow_maps, lights_direct)
//! ```

use crate::gpu::lights::bounce::SecondBounce;
use crate::gpu::lights::light_rsms::LightRsms;
use crate::gpu::lights::many::ManyLights;
use crate::gpu::lights::rgbd::RgbdVals;
use crate::gpu::lights::spot::{DirectLight, SpotVals};
use crate::gpu::raster::{CameraView, Visibility, VisibilityTarget};
use crate::gpu::raw::{RawFrame, RawVal};
use crate::gpu::references::brute_force::BruteForce;
use crate::gpu::references::estimator::{self, Estimator};
use crate::gpu::references::exact::Exact;
use crate::gpu::scene::{FlatScene, GpuScene};
use crate::gpu::sparse::{SparseMethod, SparseSettings};
use crate::gpu::technique::{CameraTarget, Frame, Technique, Vals};
use crate::gpu::timing::Recorder;
use crate::gpu::visibility::VisibilitySettings;
use crate::gpu::{Gpu, GpuError};
use crate::image::LinearImage;
use crate::rgbd::{Intrinsics, RgbdFrame, RgbdSettings};
use crate::scene::{self, Camera, Scene, SpotLight};
use glam::{Affine3A, DAffine3, Mat4, Vec3};

pub mod budget;
mod cache;
pub mod estimate;
mod method;
mod readback;
pub mod stage;
mod view;

use cache::{Built, Indirect, built_for};
pub use method::{Component, Components, Method, Rendered};
pub use readback::SparseIntermediates;
pub use view::{View, pinhole_to_clip};

/// The spot light's two techniques: only for scenes with a spot light.
struct Spot {
    vals: SpotVals,
    direct: DirectLight,
}

pub struct Renderer {
    pub scene: GpuScene,
    /// Shared by the camera and the spot light's views.
    raster: Visibility,
    camera: CameraView,
    glossy: bool,
    view: View,
    /// The sparse method's visibility mode and every mode's settings.
    visibility: VisibilitySettings,
    /// The sparse method's shading settings (`settings.sparse`).
    sparse_shading: scene::SparseShading,
    /// `settings.sparse.near_field` as a radius (m): that many of the scene's sparse spacings.
    near_radius: f32,
    /// The scene's sparse point spacing (m), the near field's unit.
    sparse_spacing: f32,
    /// The error estimate run after every frame with indirect light, when asked for
    /// ([`Renderer::set_error_estimate`]), and the frames it has looked at (its seed).
    estimate: Option<(estimate::Estimator, estimate::EstimateOptions)>,
    estimated_frames: u64,
    exact_val_stride: u32,
    /// The RSM side of the scene's `reference` level ([`Renderer::reference_spot`]).
    reference_rsm_resolution: u32,
    /// [`Method::Estimator`]'s shadow rays per pixel and seed.
    estimator: (u32, u32),
    spot: Option<Spot>,
    /// The scene's `lights` and their direct light (`gpu::lights::many`), when it has any.
    lights: Vec<scene::Light>,
    many: Option<ManyLights>,
    /// The VALs of the `lights`' RSMs (`settings.direct.val_budget`), when the scene has lights
    /// that emit anything.
    light_rsms: Option<LightRsms>,
    /// The budget `light_rsms` was split for.
    lights_val_budget: u32,
    /// The eye LightCluster's view scaling measures from (the scene's camera).
    lights_eye: Vec3,
    /// The spot light's VALs (R² at most) after the uploaded ones.
    pub vals: Vals,
    /// How many VALs [`Renderer::set_vals`] put at the front of `vals`, kept every frame.
    uploaded_vals: u32,
    /// The RGB-D VAL pass for the intrinsics and settings it was built for, once a frame was
    /// given; it runs while `rgbd_active`.
    rgbd: Option<Built<(Intrinsics, RgbdSettings), RgbdVals>>,
    rgbd_active: bool,
    /// The second bounce (`settings.bounces: 2`), run before every indirect technique; `None`
    /// with one bounce (no stage, no buffer).
    bounce: Option<SecondBounce>,
    indirect: Indirect,
    /// The camera's images at the size of the last frame.
    target: Option<CameraTarget>,
    /// Whether frames of the sparse method draw the camera's simplified copy of the triangles
    /// ([`Renderer::set_camera_lod`]), and whether the last frame did.
    camera_lod: bool,
    camera_lod_drawn: bool,
    /// Model-to-world of each mesh, as uploaded, and how many times it changed.
    placement: Vec<Mat4>,
    placement_generation: u64,
    /// The scene's floating origin ([`scene::Scene::origin`]): RGB-D poses are made relative
    /// to it.
    origin: glam::DVec3,
}

impl Renderer {
    pub fn new(gpu: &Gpu, scene: &Scene) -> Result<Self, GpuError> {
        let scene_gpu = GpuScene::new(gpu, FlatScene::from_scene(scene))?;
        let glossy = scene.settings.glossy && scene_gpu.has_glossy_material();
        let raster = Visibility::new(gpu, &scene_gpu)?;
        let spot = match &scene.light {
            None => None,
            Some(light) => {
                let vals = SpotVals::new(gpu, &scene_gpu, &raster, *light, scene.settings.rsm_resolution)?;
                let direct = DirectLight::new(gpu, &scene_gpu, &vals)?;
                Some(Spot { vals, direct })
            }
        };
        let bounce = match scene.settings.bounces {
            2 => Some(SecondBounce::new(gpu, &scene_gpu, scene.settings.second_bounce, scene.settings.seed)?),
            _ => None,
        };
        let rsm = spot.as_ref().map_or(0, |s| s.vals.resolution * s.vals.resolution);
        let light_rsms = match scene.lights.is_empty() {
            true => None,
            false => LightRsms::new(gpu, &scene_gpu, &scene.lights, scene.settings.direct.val_budget)?,
        };
        let lights_vals = light_rsms.as_ref().map_or(0, |l| l.texels);
        let capacity = (rsm + lights_vals + bounce.as_ref().map_or(0, |b| b.settings.vals)).max(1);
        let many = match scene.lights.is_empty() {
            true => None,
            false => Some(ManyLights::new(
                gpu,
                &scene_gpu,
                &scene.lights,
                &scene.settings.direct,
                scene.camera.position,
                spot.is_some(),
            )?),
        };
        Ok(Self {
            bounce,
            lights: scene.lights.clone(),
            many,
            light_rsms,
            lights_val_budget: scene.settings.direct.val_budget,
            lights_eye: scene.camera.position,
            vals: Vals {
                buffer: gpu.storage_buffer_sized::<RawVal>("vals", capacity as usize)?,
                count: gpu.storage_buffer_sized::<u32>("val_count", 1)?,
                capacity,
            },
            uploaded_vals: 0,
            rgbd: None,
            rgbd_active: false,
            camera: CameraView::new(&raster),
            raster,
            spot,
            glossy,
            view: View::Scene(scene.camera),
            visibility: scene.settings.visibility,
            sparse_shading: scene.settings.sparse,
            near_radius: scene.settings.sparse.near_field * scene.sparse_spacing(),
            sparse_spacing: scene.sparse_spacing(),
            estimate: None,
            estimated_frames: 0,
            exact_val_stride: 1,
            reference_rsm_resolution: scene.settings.reference_rsm_resolution,
            estimator: (
                scene.resolved.estimator_draws.unwrap_or(estimator::DEFAULT_SAMPLES),
                scene.settings.seed as u32,
            ),
            scene: scene_gpu,
            indirect: Indirect::default(),
            target: None,
            camera_lod: false,
            camera_lod_drawn: false,
            placement: scene.meshes.iter().map(|m| m.model_to_world).collect(),
            placement_generation: 0,
            origin: scene.origin,
        })
    }

    /// Place mesh `i` of `scene` (the scene this renderer was built from) by
    /// `model_to_world[i]` from the next frame on: the vertices and the sparse points, which
    /// live in model space, move with it; nothing is rebuilt but the BVHs (the exact reference's,
    /// and the sparse method's with `clusters.shadow_maps: "rays"`).
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
        self.scene.write_sparse_points(gpu, &flat.sparse_points);
        flat.textures = self.scene.flat.textures.take();
        self.scene.flat = flat;
        self.placement = model_to_world.to_vec();
        self.placement_generation += 1;
    }

    /// Model-to-world of each mesh as uploaded (the scene's local frame, as [`Renderer::place_meshes`]
    /// takes it).
    pub fn placement(&self) -> &[Mat4] {
        &self.placement
    }

    /// Stop lighting with an RGB-D frame's or uploaded VALs: the scene's spot light alone.
    pub fn clear_vals(&mut self) {
        self.rgbd_active = false;
        self.uploaded_vals = 0;
    }

    /// Use every `stride`-th VAL (flux scaled by `stride`) in the exact reference, whose cost
    /// is pixels x VALs x BVH traversal. 1 (the default) uses them all.
    pub fn set_exact_val_stride(&mut self, stride: u32) {
        self.exact_val_stride = stride.max(1);
    }

    /// [`Method::Estimator`]'s shadow rays per pixel (1..=[`estimator::MAX_SAMPLES`]) and the
    /// seed of its draws (the scene's `settings.seed` until set).
    pub fn set_estimator(&mut self, samples: u32, seed: u32) {
        self.estimator = (samples.clamp(1, estimator::MAX_SAMPLES), seed);
    }

    /// [`Method::Estimator`]'s draws per pixel and seed.
    pub fn estimator(&self) -> (u32, u32) {
        self.estimator
    }

    /// Change the visibility mode and its settings from the next sparse frame on.
    pub fn set_visibility(&mut self, visibility: VisibilitySettings) {
        self.visibility = visibility;
    }

    /// The visibility mode and its settings.
    pub fn visibility(&self) -> VisibilitySettings {
        self.visibility
    }

    /// Change the occlusion mode from the next sparse frame on (the modes' settings stay).
    pub fn set_occlusion(&mut self, occlusion: scene::Occlusion, rule: scene::OcclusionRule) {
        (self.visibility.mode, self.visibility.rule) = (occlusion, rule);
    }

    /// Change `sparse.near_field` (in sparse point spacings; 0: off) from the next sparse frame
    /// on; the sparse method's passes are rebuilt when it changes.
    pub fn set_near_field(&mut self, spacings: f32) {
        self.near_radius = spacings.max(0.0) * self.sparse_spacing;
    }

    /// Allow or forbid the glossy lobe (it still runs only when a material is glossy) from the
    /// next frame on.
    pub fn set_glossy(&mut self, allowed: bool) {
        self.glossy = allowed && self.scene.has_glossy_material();
    }

    /// Drop the brute-force and exact techniques (the exact one holds the BVH's buffers); they
    /// are built again when next asked for.
    pub fn release_reference_passes(&mut self) {
        self.indirect.brute_force = None;
        self.indirect.brute_force_grouped = None;
        self.indirect.exact = None;
        self.indirect.estimator = None;
    }

    /// Whether the glossy stages run for this scene.
    pub fn glossy(&self) -> bool {
        self.glossy
    }

    /// The spot light, when the scene has one.
    pub fn spot(&self) -> Option<SpotLight> {
        self.spot.as_ref().map(|s| s.vals.light)
    }

    /// The spot light and the RSM side of the scene's `reference` level, when the frame's VALs
    /// are that light's alone but drawn at another side (a level with a coarser RSM): the VALs
    /// the error estimate traces to sum over what the exact reference of `relume bench
    /// --levels` sums over. `None` when the frame's VALs are already those, or when uploaded,
    /// RGB-D, `lights` or second-bounce VALs join the spot light's (the estimate then keeps the
    /// frame's own).
    pub fn reference_spot(&self) -> Option<(SpotLight, u32)> {
        let spot = self.spot.as_ref()?;
        let alone = self.uploaded_vals == 0 && !self.rgbd_active && self.light_rsms.is_none() && self.bounce.is_none();
        let side = self.reference_rsm_resolution;
        (alone && spot.vals.resolution != side).then_some((spot.vals.light, side))
    }

    /// The spot light's visibility buffer (its RSM), when the scene has a spot light.
    pub fn rsm_view(&self) -> Option<&VisibilityTarget> {
        self.spot.as_ref().map(|s| &s.vals.view)
    }

    pub fn view(&self) -> &View {
        &self.view
    }

    /// Render from a pinhole camera (an RGB-D frame's) from now on: `camera_to_world` in the
    /// user's world coordinates (f64, as recorded), kept relative to the scene's origin.
    pub fn set_pinhole_view(&mut self, intrinsics: Intrinsics, camera_to_world: &DAffine3) {
        self.view = View::Pinhole { intrinsics, camera_to_world: self.local_pose(camera_to_world) };
    }

    /// `pose`, in the user's world coordinates (f64), relative to the scene's origin (the
    /// translation subtracted in f64, then rounded to f32), as the GPU buffers are.
    pub fn local_pose(&self, pose: &DAffine3) -> Affine3A {
        scene::local_pose(self.origin, pose)
    }

    /// Light every following frame with `vals` (e.g. RGB-D VALs accumulated over frames), plus
    /// the spot light's when the scene has one, instead of an RGB-D frame's. An empty slice
    /// removes them.
    pub fn set_vals(&mut self, gpu: &Gpu, vals: &[crate::twin::Val]) -> Result<(), GpuError> {
        self.rgbd_active = false;
        self.uploaded_vals = vals.len() as u32;
        self.ensure_val_capacity(gpu)?;
        let raw: Vec<RawVal> = vals.iter().map(RawVal::from).collect();
        if !raw.is_empty() {
            gpu.queue.write_buffer(&self.vals.buffer, 0, bytemuck::cast_slice(&raw));
        }
        Ok(())
    }

    /// Light every following frame with `frame`'s VALs (docs/design.md §2 "RGB-D frames"), made on
    /// the GPU in the frame's `rgbd_vals` stage, plus the spot light's when the scene has one.
    pub fn set_rgbd_frame(&mut self, gpu: &Gpu, frame: &RgbdFrame, settings: &RgbdSettings) -> Result<(), GpuError> {
        let scene = &self.scene;
        built_for(&mut self.rgbd, (frame.intrinsics, *settings), || {
            RgbdVals::new(gpu, scene, frame.intrinsics, settings)
        })?;
        self.uploaded_vals = 0;
        self.rgbd_active = true;
        self.ensure_val_capacity(gpu)?;
        let camera_to_world = self.local_pose(&frame.camera_to_world);
        self.rgbd.as_ref().expect("built above").technique.upload(gpu, frame, &camera_to_world)
    }

    /// `frame`'s VALs alone, made on the GPU and read back (for accumulation across frames).
    /// The RGB-D stage stays off for the following frames: give them VALs with `set_vals`.
    pub fn rgbd_frame_vals(
        &mut self,
        gpu: &Gpu,
        frame: &RgbdFrame,
        settings: &RgbdSettings,
    ) -> Result<Vec<crate::twin::Val>, GpuError> {
        self.set_rgbd_frame(gpu, frame, settings)?;
        self.rgbd_active = false;
        let pass = &self.rgbd.as_ref().expect("built above").technique;
        let vals = &self.vals;
        gpu.queue.write_buffer(&vals.count, 0, bytemuck::bytes_of(&0u32));
        let mut encoder = gpu.device.create_command_encoder(&Default::default());
        pass.append(gpu, &mut encoder, &self.scene, vals, None);
        gpu.submit_and_wait(encoder)?;
        self.read_vals(gpu)
    }

    /// Grow the VAL buffer to hold the uploaded VALs, the RGB-D frame's, the spot light's and
    /// the `lights`' RSMs'. A new buffer starts empty: callers write the uploaded VALs after
    /// this.
    fn ensure_val_capacity(&mut self, gpu: &Gpu) -> Result<(), GpuError> {
        let rsm = self.spot.as_ref().map_or(0, |s| s.vals.resolution * s.vals.resolution)
            + self.light_rsms.as_ref().map_or(0, |l| l.texels);
        let rgbd = match (&self.rgbd, self.rgbd_active) {
            (Some(b), true) => b.technique.max_vals(),
            _ => 0,
        };
        let second = self.bounce.as_ref().map_or(0, |b| b.settings.vals);
        let needed = self.uploaded_vals + rgbd + rsm + second;
        if needed > self.vals.capacity {
            self.vals.capacity = needed.next_power_of_two();
            self.vals.buffer = gpu.storage_buffer_sized::<RawVal>("vals", self.vals.capacity as usize)?;
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
    pub fn set_spot_light(&mut self, light: &SpotLight) {
        if let Some(sp) = &mut self.spot {
            sp.vals.light = *light;
        }
    }

    /// Shadow the scene's `lights` as `settings` says from the next frame on (rebuilds their
    /// groups, maps and pass), and split `settings.val_budget` among their RSMs (rebuilt when
    /// it changed; the VAL buffer grows, keeping the uploaded VALs, when it must); nothing for
    /// a scene without `lights`.
    pub fn set_direct_settings(&mut self, gpu: &Gpu, settings: &scene::DirectSettings) -> Result<(), GpuError> {
        if self.lights.is_empty() {
            return Ok(());
        }
        let add = self.spot.is_some();
        self.many = Some(ManyLights::new(gpu, &self.scene, &self.lights, settings, self.lights_eye, add)?);
        if self.lights_val_budget != settings.val_budget {
            self.light_rsms = LightRsms::new(gpu, &self.scene, &self.lights, settings.val_budget)?;
            self.lights_val_budget = settings.val_budget;
            let old = (self.vals.buffer.clone(), self.vals.capacity);
            self.ensure_val_capacity(gpu)?;
            if self.vals.capacity != old.1 && self.uploaded_vals > 0 {
                let mut encoder = gpu.device.create_command_encoder(&Default::default());
                let bytes = u64::from(self.uploaded_vals) * std::mem::size_of::<RawVal>() as u64;
                encoder.copy_buffer_to_buffer(&old.0, 0, &self.vals.buffer, 0, bytes);
                gpu.submit_and_wait(encoder)?;
            }
        }
        Ok(())
    }

    /// The RSMs of the scene's `lights`, when it has lights that emit anything.
    pub fn light_rsms(&self) -> Option<&LightRsms> {
        self.light_rsms.as_ref()
    }

    /// The same, to change how it draws ([`LightRsms::set_culling`]).
    pub fn light_rsms_mut(&mut self) -> Option<&mut LightRsms> {
        self.light_rsms.as_mut()
    }

    /// The many-light direct technique of the scene's `lights`, if it has any.
    pub fn many_lights(&self) -> Option<&ManyLights> {
        self.many.as_ref()
    }

    /// The same, to change how it draws ([`ManyLights::set_culling`]).
    pub fn many_lights_mut(&mut self) -> Option<&mut ManyLights> {
        self.many.as_mut()
    }

    /// Render both components at `width` x `height`.
    pub fn render(&mut self, gpu: &Gpu, method: Method, width: u32, height: u32) -> Result<Rendered, GpuError> {
        self.render_components(gpu, method, width, height, Components::ALL)
    }

    /// Render `components` at `width` x `height`: prepare the frame's techniques, record them
    /// in order, submit, and read back the images they wrote.
    pub fn render_components(
        &mut self,
        gpu: &Gpu,
        method: Method,
        width: u32,
        height: u32,
        components: Components,
    ) -> Result<Rendered, GpuError> {
        self.prepare(gpu, method, components, width, height)?;
        let camera_to_clip = self.camera_to_clip(width, height);
        let uniforms = self.frame_uniforms(camera_to_clip, width, height);
        gpu.queue.write_buffer(&self.scene.frame, 0, bytemuck::bytes_of(&uniforms));
        // Uploaded VALs stay at the front; the RGB-D frame's, the spot light's and the `lights`' RSMs' are appended.
        gpu.queue.write_buffer(&self.vals.count, 0, bytemuck::bytes_of(&self.uploaded_vals));

        let target = self.target.as_ref().expect("prepare sizes the camera target");
        // The simplified triangles only under the sparse method, whose per-pixel passes (and the
        // direct light's) bind the camera's triangles; the other methods' per-pixel passes
        // decode the camera's visibility buffer with the scene's own.
        self.camera_lod_drawn = self.camera_lod && method == Method::Sparse && self.scene.camera_lod.is_some();
        let frame = Frame {
            scene: &self.scene,
            vals: &self.vals,
            camera: target,
            camera_to_clip,
            camera_lod: self.camera_lod_drawn,
        };
        let (techniques, indirect) = self.techniques(method, components);
        let stage_count = techniques.iter().map(|t| t.stages().len()).sum();
        let mut rec = Recorder::new(gpu, "relume.frame", stage_count);
        for t in &techniques {
            t.record(gpu, &frame, &mut rec)?;
        }
        let mut timings = rec.finish()?;
        let mut exact_rounds = 0;
        for t in &techniques {
            exact_rounds = exact_rounds.max(t.finish(gpu, &frame, &mut timings)?);
        }
        let indirect_stages = indirect.map_or_else(Vec::new, |t| t.stages());

        let has_direct = self.spot.is_some() || self.many.is_some();
        let (indirect, direct) =
            readback::camera_images(gpu, target, components.indirect, components.direct && has_direct)?;
        let val_count = self.live_val_count(gpu)?;
        let mut rendered = Rendered {
            direct: LinearImage { width, height, pixels: direct },
            indirect: LinearImage { width, height, pixels: indirect },
            timings,
            indirect_stages,
            val_count,
            exact_rounds,
            error_estimate: None,
        };
        if components.indirect {
            self.estimate_error(gpu, &mut rendered)?;
        }
        Ok(rendered)
    }

    /// The frame's techniques in order, and which of them computes the indirect light. Call
    /// after [`Renderer::prepare`] for the same method and components.
    fn techniques(&self, method: Method, components: Components) -> (Vec<&dyn Technique>, Option<&dyn Technique>) {
        let indirect: Option<&dyn Technique> = match (components.indirect, method) {
            (false, _) => None,
            (true, Method::Sparse) => self.indirect.sparse.as_ref().map(|b| &b.technique as &dyn Technique),
            (true, Method::BruteForce) => self.indirect.brute_force.as_ref().map(|b| &b.technique as &dyn Technique),
            (true, Method::BruteForceIsm | Method::BruteForceClusters) => {
                self.indirect.brute_force_grouped.as_ref().map(|b| &b.technique as &dyn Technique)
            }
            (true, Method::Exact) => self.indirect.exact.as_ref().map(|b| &b.technique as &dyn Technique),
            (true, Method::Estimator) => self.indirect.estimator.as_ref().map(|b| &b.technique as &dyn Technique),
        };
        let mut list: Vec<&dyn Technique> = Vec::new();
        // The spot light's RSM also makes the direct light's shadow map.
        list.extend(self.spot.as_ref().map(|s| &s.vals as &dyn Technique));
        // Every frame, as the spot's: a direct-only frame makes the first bounce's VALs that
        // the CPU exact reference reads (`bench::compare`).
        list.extend(self.light_rsms.as_ref().map(|l| l as &dyn Technique));
        if components.indirect && self.rgbd_active {
            list.extend(self.rgbd.as_ref().map(|b| &b.technique as &dyn Technique));
        }
        // After every first-bounce source: it lights its points with their VALs.
        if components.indirect {
            list.extend(self.bounce.as_ref().map(|b| b as &dyn Technique));
        }
        list.push(&self.camera);
        list.extend(indirect);
        if components.direct {
            list.extend(self.spot.as_ref().map(|s| &s.direct as &dyn Technique));
            // After the spot's direct pass, which it adds to.
            list.extend(self.many.as_ref().map(|m| m as &dyn Technique));
        }
        (list, indirect)
    }

    /// From now on, frames of the sparse method draw the camera's view of the meshes simplified
    /// (`Some((ratio, error))`: [`crate::twin::flat::FlatScene::lod_triangles`], built on first
    /// use) or in full (`None`): the frame budget's cheapest rung, where the camera's raster and
    /// the per-vertex interpolation cost per triangle and vertex. The interpolation then lights
    /// only the copy's vertices; the sparse points and every other view (the spot light's, the
    /// maps) keep the full meshes.
    pub fn set_camera_lod(&mut self, gpu: &Gpu, lod: Option<(f32, f32)>) -> Result<(), GpuError> {
        if let Some((ratio, error)) = lod {
            self.scene.build_camera_lod(gpu, ratio, error)?;
        }
        self.camera_lod = lod.is_some();
        Ok(())
    }

    /// The simplified triangles the last frame's camera drew, if it drew them
    /// ([`Renderer::set_camera_lod`]).
    pub fn camera_lod_drawn(&self) -> Option<&crate::twin::flat::Triangles> {
        self.scene.camera_lod.as_ref().filter(|_| self.camera_lod_drawn).map(|l| &l.triangles)
    }

    /// The visibility settings of a grouped brute force's groups (`brute_force_ism`: the
    /// scene's `ism`; `brute_force_clusters`: its `clusters`); `None` for the other methods.
    fn grouped_visibility(&self, method: Method) -> Option<VisibilitySettings> {
        let mode = match method {
            Method::BruteForceIsm => scene::Occlusion::Ism,
            Method::BruteForceClusters => scene::Occlusion::Clusters,
            _ => return None,
        };
        Some(VisibilitySettings { mode, ..self.visibility })
    }

    /// Build the techniques the frame needs that are not built for the current settings, and
    /// fit them and the camera's images to this frame.
    fn prepare(
        &mut self,
        gpu: &Gpu,
        method: Method,
        components: Components,
        width: u32,
        height: u32,
    ) -> Result<(), GpuError> {
        let (scene, glossy, capacity) = (&self.scene, self.glossy, self.vals.capacity);
        let pixels = (width * height) as usize;
        let grouped = self.grouped_visibility(method);
        if components.indirect && method == Method::BruteForceIsm {
            // Refused before anything is built for it: its table of (pixel, group) lookups
            // must fit one storage binding (`brute_force_clusters` looks its maps up in its
            // pass, with no table).
            let count = self.visibility.ism.count;
            gpu.check_size(
                &format!(
                    "brute_force_ism's visibility table ({width}x{height} pixels x settings.ism.count {count} floats)"
                ),
                pixels as u64 * u64::from(count) * 4,
            )?;
        }
        if components.indirect {
            if let Some(b) = &mut self.bounce {
                if matches!(method, Method::Exact | Method::Estimator) {
                    return Err(GpuError::Unsupported(
                        "settings.bounces: 2 has no GPU exact reference (its second bounce needs shadow rays from \
                         the bounce points); use the CPU one (--reference-device cpu)"
                            .into(),
                    ));
                }
                // The sparse method's group visibility mode lights the points through the first
                // bounce's maps, and its disks occlude their light spheres as the sparse
                // points'; the brute force (no visibility) and `off` leave them unoccluded.
                // `brute_force_ism` and `brute_force_clusters` see them through their groups'
                // maps, as the sparse method's `ism` and `clusters` do.
                let occluding = self.visibility.mode != scene::Occlusion::Off;
                let visibility = match method {
                    Method::Sparse if occluding => Some(self.visibility),
                    _ => grouped,
                };
                b.set_visibility(gpu, scene, visibility)?;
                b.fit(gpu, scene, capacity)?;
            }
            match method {
                Method::Sparse => {
                    let shading = self.sparse_shading;
                    let settings = SparseSettings {
                        glossy,
                        visibility: self.visibility,
                        kernel: shading.kernel,
                        bound: shading.bound,
                        near_radius: self.near_radius,
                        near_interleave: shading.near_field_interleave,
                        glossy_interpolation: shading.glossy_interpolation,
                    };
                    let rays = settings.visibility.mode == scene::Occlusion::Clusters
                        && settings.visibility.clusters.shadow_maps == scene::ShadowMapSource::Rays;
                    let generation = if rays { self.placement_generation } else { 0 };
                    built_for(&mut self.indirect.sparse, (settings, generation), || {
                        SparseMethod::new(gpu, scene, settings)
                    })?
                    .fit(gpu, scene, capacity)?;
                }
                Method::BruteForce => {
                    built_for(&mut self.indirect.brute_force, glossy, || BruteForce::new(gpu, scene, glossy, None))?
                        .fit(gpu, scene, capacity, width * height)?;
                }
                Method::BruteForceIsm | Method::BruteForceClusters => {
                    let groups = grouped.expect("a grouped brute force has groups");
                    built_for(&mut self.indirect.brute_force_grouped, (glossy, groups), || {
                        BruteForce::new(gpu, scene, glossy, Some(&groups))
                    })?
                    .fit(gpu, scene, capacity, width * height)?;
                }
                Method::Exact => {
                    let (stride, generation) = (self.exact_val_stride, self.placement_generation);
                    built_for(&mut self.indirect.exact, (glossy, stride, generation), || {
                        Exact::new(gpu, scene, glossy, stride)
                    })?
                    .fit(gpu, pixels)?;
                }
                Method::Estimator => {
                    let ((samples, seed), generation) = (self.estimator, self.placement_generation);
                    built_for(&mut self.indirect.estimator, (glossy, samples, seed, generation), || {
                        Estimator::new(gpu, scene, glossy, samples, seed)
                    })?
                    .fit(gpu, scene, capacity, pixels)?;
                }
            }
        }
        let size_matches = self.target.as_ref().is_some_and(|t| t.view.width == width && t.view.height == height);
        if !size_matches {
            self.target = Some(CameraTarget {
                view: self.raster.target(gpu, "camera", width, height),
                indirect: gpu.storage_buffer_sized::<[f32; 4]>("frame.indirect", pixels)?,
                direct: gpu.storage_buffer_sized::<[f32; 4]>("frame.direct", pixels)?,
            });
        }
        Ok(())
    }

    /// How many VALs the VAL buffer holds at most (what the frame's passes must cover).
    pub fn val_capacity(&self) -> u32 {
        self.vals.capacity
    }

    /// World to the camera's clip space at `width` x `height`, near and far fitted to the scene.
    pub fn camera_to_clip(&self, width: u32, height: u32) -> Mat4 {
        let (near, far) = self.scene.flat.depth_range(self.view.eye());
        match &self.view {
            View::Scene(c) => {
                glam::camera::rh::proj::directx::perspective(c.fov_y, width as f32 / height as f32, near, far)
                    * glam::camera::rh::view::look_at_mat4(c.position, c.target, c.up)
            }
            View::Pinhole { intrinsics, camera_to_world } => {
                pinhole_to_clip(&intrinsics.scaled_to(width, height), near, far) * Mat4::from(camera_to_world.inverse())
            }
        }
    }

    /// World to the spot light's clip space, when the scene has a spot light.
    pub fn light_to_clip(&self) -> Option<Mat4> {
        self.spot.as_ref().map(|s| s.vals.light_to_clip(&self.scene))
    }

    fn frame_uniforms(&self, camera: Mat4, width: u32, height: u32) -> RawFrame {
        let flat = &self.scene.flat;
        // Without a spot light its fields are unused: zero intensity, a valid cone.
        let (spot, resolution, light) = match &self.spot {
            Some(sp) => (sp.vals.light, sp.vals.resolution, sp.vals.light_to_clip(&self.scene)),
            None => (
                SpotLight {
                    position: Vec3::ZERO,
                    direction: Vec3::NEG_Y,
                    inner_angle: 0.0,
                    outer_angle: 0.5,
                    intensity: Vec3::ZERO,
                    up: Vec3::Z,
                },
                0,
                Mat4::IDENTITY,
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

    /// How many VALs lit the last frame (appends past the capacity are dropped).
    fn live_val_count(&self, gpu: &Gpu) -> Result<u32, GpuError> {
        Ok(gpu.read_buffer::<u32>(&self.vals.count, 1)?[0].min(self.vals.capacity))
    }
}

//! Direct light from the scene's `lights` (docs/measurements/many-lights.md, `many_lights.wgsl`):
//! the lights are grouped on the CPU (each alone in the `"per_light"` mode; LightCluster's
//! minimum-distance groups, paper 003 §3.1, in the `"light_cluster"` mode), every group gets
//! two paraboloid shadow maps at its centre light (the clusters module's raster, one atlas),
//! and every pixel adds each light's direct radiance times its group's visibility there (one
//! texel per light, or PCSS with the group's extent as the disc light's radius). Rust twins:
//! `twin::many_lights` (the grouping is itself CPU code, as in the paper).
//!
//! On a CPU adapter a shader's loops end after [`crate::gpu::LLVMPIPE_LOOP_LIMIT`] iterations;
//! a pixel runs at most `groups x (1 + 2 SHADOW_TAPS²) + lights` of them, 53,248 at the most
//! lights ([`crate::scene::MAX_DIRECT_LIGHTS`]).

use crate::gpu::pass::{
    Entry, Kernel, PassDesc, buffer, depth_texture, module_from_source, read, read_write, texture, view,
};
use crate::gpu::raster::cull::{TriangleChunks, box_outside_plane, box_reaches_front, clip_planes};
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::IMAGE_TILE;
use crate::gpu::shader::Wgsl;
use crate::gpu::technique::{Frame, Technique};
use crate::gpu::timing::Recorder;
use crate::gpu::visibility::clusters::{self, RawCluster, SceneScale, ShadowMaps};
use crate::gpu::{Gpu, GpuError};
use crate::scene::{ClusterSettings, DirectSettings, DirectShadows, Light, SoftShadows};
use crate::twin::many_lights::{AXIS, LightGroups, light_range, min_distance_clusters};
use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3};

pub const WGSL: &str = include_str!("many_lights.wgsl");

/// Stage names.
pub const SHADOW_MAPS_STAGE: &str = "lights_shadow_maps";
pub const SHADE_STAGE: &str = "lights_direct";

/// The shading pass: the clusters' lookup (`clusters::lookup_body`: binding 1 the maps'
/// centres, binding 2 the atlas) around its own bindings.
pub const PASS: PassDesc = PassDesc {
    label: SHADE_STAGE,
    bindings: &[
        texture("visibility"),
        read("clusters"),
        depth_texture("shadow_atlas"),
        read_write("direct"),
        read("lights"),
        read("group_lights"),
    ],
    entries: &[Entry::first("shade_lights", 6)],
    workgroup: IMAGE_TILE,
    default_source: |textured| {
        let maps = maps_settings(1, 128, SoftShadows::Pcss);
        PASS.source(&body(&maps, SceneScale { diagonal: 1.0 }, 1, false), textured)
    },
};

/// WGSL `ManyLight`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RawManyLight {
    pub position: [f32; 3],
    pub range: f32,
    pub direction: [f32; 3],
    pub inner_angle: f32,
    pub intensity: [f32; 3],
    pub outer_angle: f32,
}

impl From<&Light> for RawManyLight {
    fn from(light: &Light) -> Self {
        let spot = crate::twin::many_lights::as_spot(light);
        let range = match light {
            Light::Point(p) => p.range.unwrap_or(0.0),
            Light::Spot(_) => 0.0,
        };
        Self {
            position: spot.position.into(),
            range,
            direction: spot.direction.into(),
            inner_angle: spot.inner_angle,
            intensity: spot.intensity.into(),
            outer_angle: spot.outer_angle,
        }
    }
}

/// The clusters module's settings for `groups` groups' maps (two each).
fn maps_settings(groups: u32, resolution: u32, soft: SoftShadows) -> ClusterSettings {
    // Each map draws the triangle chunks its cull keeps, of the full meshes.
    ClusterSettings {
        count: 2 * groups,
        shadow_map_resolution: resolution,
        soft,
        proxy_error: 0.0,
        ..ClusterSettings::default()
    }
}

/// The pass's WGSL after the shader prelude.
fn body(maps: &ClusterSettings, scale: SceneScale, groups: u32, add: bool) -> String {
    let head = clusters::header(maps, scale);
    Wgsl::new()
        .include(&clusters::lookup_body(&head, [1, 2]))
        .u32("GROUP_COUNT", groups)
        .vec3_f32("AXIS", AXIS.to_array())
        .bool("ADD_TO_DIRECT", add)
        .include(WGSL)
        .finish()
}

/// The groups `settings` asks for: every light alone, or LightCluster's (with the view
/// scaling from `camera` when `settings.z_far` is given).
pub fn groups_of(lights: &[Light], settings: &DirectSettings, camera: Vec3) -> LightGroups {
    match settings.shadows {
        DirectShadows::PerLight => LightGroups::singletons(lights.len()),
        DirectShadows::LightCluster => {
            let positions: Vec<Vec3> = lights.iter().map(Light::position).collect();
            let ranges: Vec<f32> = lights.iter().map(light_range).collect();
            min_distance_clusters(&positions, &ranges, settings.d_init, settings.z_far.map(|z| (camera, z)))
        }
    }
}

/// The many-light direct technique for fixed lights and groups.
pub struct ManyLights {
    pub groups: LightGroups,
    maps_settings: ClusterSettings,
    scale: SceneScale,
    maps: ShadowMaps,
    kernel: Kernel,
    /// `array<Cluster>`: two per group.
    clusters: wgpu::Buffer,
    /// `array<ManyLight>`, sorted by group.
    lights: wgpu::Buffer,
    /// `array<vec2<u32>>`: per group, its first light and count.
    group_lights: wgpu::Buffer,
    /// Per map: its centre and its axis.
    map_bounds: Vec<(Vec3, Vec3)>,
    /// Whether each map draws only what its cull keeps ([`ManyLights::draws`]; on unless a
    /// test or benchmark turns it off to compare).
    culling: bool,
    /// Per light, its position and its `range` (infinite for none and for spots).
    reach: Vec<(Vec3, f32)>,
    /// Whether a frame skips the maps of groups whose lights all lie out of the camera's view
    /// ([`ManyLights::groups_in_view`]; on unless a test or benchmark turns it off to compare).
    light_culling: bool,
}

impl ManyLights {
    /// `lights` (at least one) grouped as `settings` says; `add` when the pass adds to a
    /// direct image another pass wrote first (the spot light's).
    pub fn new(
        gpu: &Gpu,
        scene: &GpuScene,
        lights: &[Light],
        settings: &DirectSettings,
        camera: Vec3,
        add: bool,
    ) -> Result<Self, GpuError> {
        let groups = groups_of(lights, settings, camera);
        let soft = match settings.shadows {
            DirectShadows::PerLight => SoftShadows::Hard,
            DirectShadows::LightCluster => SoftShadows::Pcss,
        };
        Self::with_groups(gpu, scene, lights, groups, settings.shadow_map_resolution, soft, add)
    }

    /// `lights` in the given groups, their maps `resolution` texels a side, filtered by `soft`
    /// ([`SoftShadows::Hard`]: one texel).
    pub fn with_groups(
        gpu: &Gpu,
        scene: &GpuScene,
        lights: &[Light],
        groups: LightGroups,
        resolution: u32,
        soft: SoftShadows,
        add: bool,
    ) -> Result<Self, GpuError> {
        let m = groups.len() as u32;
        let maps_settings = maps_settings(m, resolution, soft);
        let scale = SceneScale::of(scene);
        let maps = ShadowMaps::new(gpu, scene, &maps_settings, scale)?;
        let source = PASS.source(&body(&maps_settings, scale, m, add), scene.textured());
        let module = module_from_source(gpu, PASS.label, source)?;
        let kernel = Kernel::build(gpu, scene, &PASS, &module, PASS.entry("shade_lights"), &[], PASS.workgroup)?;
        let positions: Vec<Vec3> = lights.iter().map(Light::position).collect();
        let raw_clusters: Vec<RawCluster> = groups
            .maps(&positions)
            .iter()
            .map(|c| RawCluster {
                position: c.position.into(),
                count: c.count,
                normal: c.normal.into(),
                radius: c.radius,
            })
            .collect();
        let map_bounds = groups.maps(&positions).iter().map(|c| (c.position, c.normal)).collect();
        let mut sorted = Vec::with_capacity(lights.len());
        let mut ranges = Vec::with_capacity(groups.len());
        for g in 0..m {
            let first = sorted.len() as u32;
            sorted.extend(
                lights.iter().zip(&groups.group_of_light).filter(|(_, k)| **k == g).map(|(l, _)| RawManyLight::from(l)),
            );
            ranges.push([first, sorted.len() as u32 - first]);
        }
        let none = wgpu::BufferUsages::empty();
        Ok(Self {
            clusters: gpu.storage_buffer("many_lights.clusters", &raw_clusters, none)?,
            lights: gpu.storage_buffer("many_lights.lights", &sorted, none)?,
            group_lights: gpu.storage_buffer("many_lights.group_lights", &ranges, none)?,
            groups,
            maps_settings,
            scale,
            maps,
            kernel,
            map_bounds,
            culling: true,
            reach: lights.iter().map(|l| (l.position(), light_range(l))).collect(),
            light_culling: true,
        })
    }

    /// Skip the maps of groups out of the camera's view (`true`, the default) or draw every
    /// group's maps every frame (`false`).
    pub fn set_light_culling(&mut self, on: bool) {
        self.light_culling = on;
    }

    /// Per group, whether any of its lights can light what the camera sees (paper 003's
    /// view-frustum culling of lights, applied to the shadow maps): a light with a `range`
    /// whose sphere (taken as its bounding box) lies wholly outside a plane of the camera's clip
    /// volume `world_to_clip` adds nothing to any visible pixel (its window is 0 from `range`
    /// on), so its group's maps are never looked up there; lights without a range, and spots,
    /// are always in view. The groups stay as they were built: the lights' RSMs (their
    /// indirect light) do not depend on the view.
    pub fn groups_in_view(&self, world_to_clip: Mat4) -> Vec<bool> {
        let planes = clip_planes(world_to_clip);
        let mut seen = vec![false; self.groups.len()];
        for (&(position, range), &g) in self.reach.iter().zip(&self.groups.group_of_light) {
            let r = Vec3::splat(range);
            let in_view =
                !range.is_finite() || !planes.iter().any(|&p| box_outside_plane(p, position - r, position + r));
            seen[g as usize] |= in_view;
        }
        seen
    }

    /// Draw every triangle into every map (`false`) or only what each map's cull keeps (the
    /// default).
    pub fn set_culling(&mut self, on: bool) {
        self.culling = on;
    }

    /// Per map, the triangle ranges it draws for the scene as placed now: everything without
    /// the cull; with it, the chunks (`raster::cull`) that reach the front of the map's
    /// hemisphere (a triangle wholly behind it makes no fragment: every texel's ray leaves the
    /// centre into the hemisphere, and the raster's barycentric slack is allowed for), so the
    /// maps are the same texel for texel. Not culled against the lights' `range`: a lookup's
    /// receiver-plane depth at a grazed receiver reaches past it, so far surfaces still count
    /// (docs/measurements/many-lights.md).
    pub fn draws(&self, scene: &GpuScene) -> Vec<Vec<std::ops::Range<u32>>> {
        if !self.culling {
            return vec![vec![0..scene.flat.triangle_count()]; self.map_bounds.len()];
        }
        let chunks = TriangleChunks::new(&scene.flat);
        let slack = 3.0 * crate::gpu::visibility::clusters::twin::SHADOW_RASTER_SLACK;
        self.map_bounds
            .iter()
            .map(|&(centre, axis)| chunks.kept(|(lo, hi)| box_reaches_front(lo, hi, centre, axis, slack)))
            .collect()
    }

    /// Every map, two per group (`2g`: +AXIS, `2g + 1`: -AXIS): distances (m), infinite where
    /// nothing was drawn.
    pub fn read_maps(&self, gpu: &Gpu) -> Result<Vec<Vec<f32>>, GpuError> {
        self.maps.read(gpu, &self.maps_settings, self.scale)
    }

    /// Texels per map side.
    pub fn map_resolution(&self) -> u32 {
        self.maps_settings.shadow_map_resolution
    }

    /// The maps' filter.
    pub fn soft(&self) -> SoftShadows {
        self.maps_settings.soft
    }
}

impl Technique for ManyLights {
    fn stages(&self) -> Vec<&'static str> {
        vec![SHADOW_MAPS_STAGE, SHADE_STAGE]
    }

    fn record(&self, gpu: &Gpu, frame: &Frame<'_>, rec: &mut Recorder<'_>) -> Result<(), GpuError> {
        let scene = frame.scene;
        let mut draws = self.draws(scene);
        if self.light_culling {
            // A group out of view draws nothing: its maps stay empty, and no visible pixel
            // looks them up (its lights add no radiance there).
            for (g, _) in self.groups_in_view(frame.camera_to_clip).iter().enumerate().filter(|(_, seen)| !**seen) {
                draws[2 * g].clear();
                draws[2 * g + 1].clear();
            }
        }
        self.maps.record(gpu, scene, &self.clusters, &self.maps_settings, Some(&draws), SHADOW_MAPS_STAGE, rec)?;
        let camera = frame.camera;
        let group = self.kernel.bind(
            gpu,
            &[
                view("visibility", &camera.view.view),
                buffer("clusters", &self.clusters),
                view("shadow_atlas", &self.maps.atlas_view),
                buffer("direct", &camera.direct),
                buffer("lights", &self.lights),
                buffer("group_lights", &self.group_lights),
            ],
        );
        let pixels = [camera.view.width, camera.view.height, 1];
        rec.stage(SHADE_STAGE, |e, s| {
            self.kernel.dispatch_on(e, &group, frame.camera_triangles().0, pixels, s.as_ref().map(|s| s.compute()))
        })
    }
}

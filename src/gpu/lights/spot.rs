//! The spot light (docs/design.md §2 "RSM of a spot light", §4 step 6): two techniques. [`SpotVals`]
//! rasterises the scene from the light (its RSM) and turns each lit texel into a VAL and a
//! light-distance shadow map; [`DirectLight`] shades the camera's pixels with the light through
//! that shadow map.

use super::compact::Compact;
use super::{direct, rsm};
use crate::gpu::pass::{Kernel, Kernels, buffer, module_from_source, view};
use crate::gpu::raster::{Visibility, VisibilityTarget};
use crate::gpu::scene::GpuScene;
use crate::gpu::technique::{Frame, Technique};
use crate::gpu::timing::Recorder;
use crate::gpu::{Gpu, GpuError};
use crate::scene::SpotLight;
use glam::Mat4;

/// Stage names.
pub const RSM_RASTER: &str = "rsm_raster";
pub const RSM_VALS: &str = "rsm_vals";
pub const DIRECT: &str = "direct";

/// The light's RSM and the VALs it makes.
pub struct SpotVals {
    pub light: SpotLight,
    /// RSM texels per side.
    pub resolution: u32,
    raster: Visibility,
    rsm: Kernel,
    /// `rsm`'s bindings: the RSM, the shadow map and the candidates.
    rsm_group: wgpu::BindGroup,
    compact: Compact,
    /// The light's visibility buffer (the RSM).
    pub view: VisibilityTarget,
    /// Distance from the light to the surface each RSM texel sees: [`DirectLight`]'s shadow map.
    pub light_distance: wgpu::Buffer,
}

impl SpotVals {
    pub fn new(
        gpu: &Gpu,
        scene: &GpuScene,
        raster: &Visibility,
        light: SpotLight,
        resolution: u32,
    ) -> Result<Self, GpuError> {
        let r = resolution;
        let desc = &rsm::PASS;
        let module = module_from_source(gpu, desc.label, desc.source(&rsm::body(), scene.textured()))?;
        let rsm = Kernel::build(gpu, scene, desc, &module, desc.entry("main"), &[], desc.workgroup)?;
        let compact = Compact::new(gpu, scene, desc, &module, r * r)?;
        let target = raster.target(gpu, "rsm", r, r);
        let light_distance = gpu.storage_buffer_sized::<f32>("rsm.light_distance", (r * r) as usize)?;
        let rsm_group = rsm.bind(
            gpu,
            &[
                view("visibility", &target.view),
                buffer("light_distance", &light_distance),
                buffer("candidates", &compact.candidates),
            ],
        );
        Ok(Self { light, resolution, raster: raster.clone(), rsm, rsm_group, compact, view: target, light_distance })
    }

    /// World to the light's clip space: a square perspective over the outer cone, near and far
    /// fitted to the scene, its rows across the light's `up` ([`SpotLight::world_to_light`]).
    pub fn light_to_clip(&self, scene: &GpuScene) -> Mat4 {
        let s = &self.light;
        let (near, far) = scene.flat.depth_range(s.position);
        glam::camera::rh::proj::directx::perspective(2.0 * s.outer_angle, 1.0, near, far) * s.world_to_light()
    }
}

impl Technique for SpotVals {
    fn stages(&self) -> Vec<&'static str> {
        vec![RSM_RASTER, RSM_VALS]
    }

    fn record(&self, gpu: &Gpu, frame: &Frame<'_>, rec: &mut Recorder<'_>) -> Result<(), GpuError> {
        let scene = frame.scene;
        let light_to_clip = self.light_to_clip(scene);
        rec.stage(RSM_RASTER, |e, s| self.raster.record(gpu, e, scene, &self.view, light_to_clip, s))?;
        let texels = [self.resolution, self.resolution, 1];
        let vals = (buffer("vals", &frame.vals.buffer), &frame.vals.count);
        rec.stage(RSM_VALS, |e, s| {
            self.compact.record_after(gpu, e, scene, &[(&self.rsm, &self.rsm_group, texels)], vals, s)
        })
    }
}

/// The spot light's direct light at the camera's pixels.
pub struct DirectLight {
    pass: Kernels,
    /// [`SpotVals::light_distance`].
    light_distance: wgpu::Buffer,
}

impl DirectLight {
    pub fn new(gpu: &Gpu, scene: &GpuScene, vals: &SpotVals) -> Result<Self, GpuError> {
        let pass = Kernels::lobes(gpu, scene, &direct::PASS, direct::WGSL, false)?;
        Ok(Self { pass, light_distance: vals.light_distance.clone() })
    }
}

impl Technique for DirectLight {
    fn stages(&self) -> Vec<&'static str> {
        vec![DIRECT]
    }

    fn record(&self, gpu: &Gpu, frame: &Frame<'_>, rec: &mut Recorder<'_>) -> Result<(), GpuError> {
        let camera = frame.camera;
        let resources = [
            view("visibility", &camera.view.view),
            buffer("direct", &camera.direct),
            buffer("light_distance", &self.light_distance),
        ];
        let pixels = [camera.view.width, camera.view.height, 1];
        rec.stage(DIRECT, |e, s| self.pass.run_on(gpu, e, frame.camera_triangles().0, &resources, pixels, s))
    }
}

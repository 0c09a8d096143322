//! The sparse model-space method (docs/design.md §4), one technique: gather at the sparse points,
//! the visibility mode (`gpu::visibility`), renormalise, interpolate per vertex, shade per
//! pixel.

pub mod adaptive;
pub mod gather;
pub mod interpolate;
pub mod near_field;
pub mod renormalise;
pub mod shade;

use crate::gpu::pass::{Kernels, buffer, view, with_lobes};
use crate::gpu::raw::{RawGathered, RawPointLight};
use crate::gpu::scene::GpuScene;
use crate::gpu::technique::{Frame, Technique};
use crate::gpu::timing::Recorder;
use crate::gpu::visibility::{self, Mode, VisibilitySettings};
use crate::gpu::{Gpu, GpuError, Lobes};
use crate::scene::{GlossyInterpolation, InterpolationKernel, LightBound};
use adaptive::Adaptive;
use gather::{Gather, GatherInput, GatherLobes, Receivers};
use near_field::NearField;

/// What the sparse technique is built for: a change rebuilds it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SparseSettings {
    pub glossy: bool,
    pub visibility: VisibilitySettings,
    pub kernel: InterpolationKernel,
    pub bound: LightBound,
    /// The near-field radius (m): VALs closer than it to a receiver are applied per pixel
    /// (`near_field` stage) rather than through the sparse points; 0 is off.
    pub near_radius: f32,
    /// The near field's interleaving block side (`settings.sparse.near_field_interleave`).
    pub near_interleave: u32,
    /// How pixels take the sparse points' glossy light (with `glossy` only).
    pub glossy_interpolation: GlossyInterpolation,
}

/// The sparse method's passes and the buffers between them.
pub struct SparseMethod {
    /// At the points with a glossy lobe (all, for a scene without one), with the lobe when the
    /// scene has one; then at the others, without it (`plain_gather`), in the same stage.
    gather: Gather,
    plain_gather: Option<Gather>,
    /// `None` when visibility is off.
    pub visibility: Option<Mode>,
    renormalise: Kernels,
    interpolate: Kernels,
    shade: Kernels,
    /// The per-pixel near field; `None` when `near_radius` is 0.
    near_field: Option<NearField>,
    /// Per sparse point: the gathered sums (after visibility).
    pub gathered: Lobes,
    /// Per sparse point: the renormalised point lights.
    pub sparse_lights: Lobes,
    /// Per vertex: the interpolated point lights.
    pub vertex_lights: Lobes,
    /// Per vertex, with `glossy_interpolation: "radiance"` only: the interpolated glossy sums
    /// (`vec4`, `w` unused). The sparse and vertex lights then have no glossy lobe.
    pub vertex_glossy_radiance: Option<wgpu::Buffer>,
    /// Only for a scene with adaptive candidates (`settings.sparse.adaptive`): their choice, and
    /// the gather at the chosen ones.
    pub adaptive: Option<(Adaptive, Gather)>,
}

impl SparseMethod {
    pub fn new(gpu: &Gpu, scene: &GpuScene, settings: SparseSettings) -> Result<Self, GpuError> {
        let glossy = settings.glossy;
        let n = scene.flat.sparse_points.len();
        let v = scene.flat.vertices.len();
        let visibility = visibility::for_settings(gpu, scene, &settings.visibility, glossy)?;
        let groups = match &visibility {
            Some(Mode::Groups(g)) => Some(g.table().groups),
            _ => None,
        };
        let adaptive_points = (scene.flat.candidates > 0).then(|| scene.flat.base_sparse_count());
        let interpolate_body =
            interpolate::body(scene.flat.neighbours, settings.kernel, settings.bound, adaptive_points);
        let interpolate_pass = interpolate::pass(adaptive_points.is_some());
        let lobes = match (glossy, settings.glossy_interpolation) {
            (false, _) => GatherLobes::Diffuse,
            (true, GlossyInterpolation::Lights) => GatherLobes::GlossyLights,
            (true, GlossyInterpolation::Radiance) => GatherLobes::GlossyRadiance,
        };
        // With the glossy radiance interpolated, only the diffuse lobe has point lights.
        let radiance = lobes == GatherLobes::GlossyRadiance;
        let glossy_lights = lobes == GatherLobes::GlossyLights;
        let (interpolate, shade) = if radiance {
            let entry = "main_glossy_radiance";
            (
                Kernels::entry(gpu, scene, interpolate_pass, &interpolate_body, interpolate_pass.entry(entry))?,
                Kernels::entry(gpu, scene, &shade::PASS, shade::WGSL, shade::PASS.entry(entry))?,
            )
        } else {
            (
                Kernels::lobes(gpu, scene, interpolate_pass, &interpolate_body, glossy)?,
                Kernels::lobes(gpu, scene, &shade::PASS, shade::WGSL, glossy)?,
            )
        };
        let adaptive = (scene.flat.candidates > 0)
            .then(|| -> Result<_, GpuError> {
                Ok((
                    Adaptive::new(gpu, scene, settings.kernel, glossy)?,
                    Gather::new(gpu, scene, lobes, groups, settings.near_radius, Receivers::Chosen)?,
                ))
            })
            .transpose()?;
        // The points with a glossy lobe come first (`FlatScene::glossy_points`): only they pay
        // for it (on CPU adapters a branch per point saves nothing, both sides run).
        let (glossy_points, base) = (scene.flat.glossy_points, scene.flat.base_sparse_count());
        let near_radius = settings.near_radius;
        let span = |first, end| Receivers::Span { first, end };
        let (gather, plain_gather) = if lobes.glossy() && glossy_points > 0 {
            let plain = (base > glossy_points)
                .then(|| Gather::new(gpu, scene, GatherLobes::Diffuse, groups, near_radius, span(glossy_points, base)))
                .transpose()?;
            (Gather::new(gpu, scene, lobes, groups, near_radius, span(0, glossy_points))?, plain)
        } else {
            // No point has a glossy lobe (or the scene none): the glossy sums stay 0.
            (Gather::new(gpu, scene, GatherLobes::Diffuse, groups, near_radius, span(0, base))?, None)
        };
        Ok(Self {
            adaptive,
            gather,
            plain_gather,
            visibility,
            renormalise: Kernels::lobes(gpu, scene, &renormalise::PASS, renormalise::WGSL, glossy_lights)?,
            interpolate,
            shade,
            near_field: (settings.near_radius > 0.0)
                .then(|| {
                    let near = (settings.near_radius, settings.near_interleave);
                    NearField::new(gpu, scene, glossy, near, interpolate_pass, &interpolate_body)
                })
                .transpose()?,
            gathered: Lobes::new::<RawGathered>(gpu, "gather.gathered", n, glossy)?,
            sparse_lights: Lobes::new::<RawPointLight>(gpu, "renormalise.sparse_lights", n, glossy_lights)?,
            vertex_lights: Lobes::new::<RawPointLight>(gpu, "interpolate.vertex_lights", v, glossy_lights)?,
            vertex_glossy_radiance: radiance
                .then(|| gpu.storage_buffer_sized::<[f32; 4]>("interpolate.vertex_glossy_radiance", v))
                .transpose()?,
        })
    }

    /// Cover frames of up to `max_vals` VALs.
    pub fn fit(&mut self, gpu: &Gpu, scene: &GpuScene, max_vals: u32) -> Result<(), GpuError> {
        if let Some(Mode::Groups(g)) = &mut self.visibility {
            g.fit(gpu, max_vals)?;
        }
        if let Some(n) = &mut self.near_field {
            n.fit(gpu, scene, max_vals)?;
        }
        if let Some((_, gather)) = &mut self.adaptive {
            gather.fit(gpu, scene, max_vals)?;
        }
        if let Some(plain) = &mut self.plain_gather {
            plain.fit(gpu, scene, max_vals)?;
        }
        self.gather.fit(gpu, scene, max_vals)
    }
}

impl Technique for SparseMethod {
    fn stages(&self) -> Vec<&'static str> {
        let mut stages = Vec::new();
        if let Some(Mode::Groups(g)) = &self.visibility {
            stages.extend(g.stages());
        }
        stages.push(gather::PASS.label);
        if self.adaptive.is_some() {
            stages.extend([adaptive::SELECT_STAGE, adaptive::GATHER_STAGE]);
        }
        if let Some(Mode::Scale(v)) = &self.visibility {
            stages.push(v.stage());
        }

        stages.extend([renormalise::PASS.label, interpolate::PASS.label, shade::PASS.label]);
        if let Some(n) = &self.near_field {
            stages.extend(n.stages());
        }
        stages
    }

    fn record(&self, gpu: &Gpu, frame: &Frame<'_>, rec: &mut Recorder<'_>) -> Result<(), GpuError> {
        let (scene, vals) = (frame.scene, frame.vals);
        let table = match &self.visibility {
            Some(Mode::Groups(g)) => {
                g.record(gpu, frame, rec)?;
                Some(g.table())
            }
            _ => None,
        };
        let input = GatherInput { scene, vals, gathered: &self.gathered, groups: table.as_ref() };
        rec.stage(gather::PASS.label, |e, s| {
            let first = self.gather.parts();
            let parts = first + self.plain_gather.as_ref().map_or(0, Gather::parts);
            self.gather.record(gpu, e, &input, s.map(|s| s.share(0, parts)));
            if let Some(plain) = &self.plain_gather {
                plain.record(gpu, e, &input, s.map(|s| s.share(first, parts)));
            }
        })?;
        if let Some((adaptive, gather)) = &self.adaptive {
            adaptive.record_select(gpu, scene, &self.gathered, rec)?;
            let chosen = adaptive.chosen_list();
            rec.stage(adaptive::GATHER_STAGE, |e, s| gather.record_chosen(gpu, e, (&input, &chosen), s))?;
        }
        if let Some(Mode::Scale(v)) = &self.visibility {
            rec.stage(v.stage(), |e, s| v.record(gpu, e, scene, &self.gathered, s))?;
        }

        let points = scene.flat.sparse_count();
        // With the glossy radiance interpolated, the point lights have no glossy lobe, so
        // `with_lobes` binds the diffuse buffers alone (the gathered glossy sums go to the
        // interpolation instead).
        let resources = with_lobes(
            vec![buffer("sparse_points", &scene.sparse_points)],
            &[
                (&self.gathered, "gathered_diffuse", "gathered_glossy"),
                (&self.sparse_lights, "sparse_diffuse", "sparse_glossy"),
            ],
        );
        rec.stage(renormalise::PASS.label, |e, s| self.renormalise.run(gpu, e, scene, &resources, [points, 1, 1], s))?;
        let mut resources = with_lobes(
            vec![buffer("sparse_points", &scene.sparse_points), buffer("vertex_neighbours", &scene.vertex_neighbours)],
            &[
                (&self.sparse_lights, "sparse_diffuse", "sparse_glossy"),
                (&self.vertex_lights, "vertex_diffuse", "vertex_glossy"),
            ],
        );
        let radiance = self.gathered.glossy.as_ref().zip(self.vertex_glossy_radiance.as_ref());
        if let Some((gathered, out)) = radiance {
            resources.extend([buffer("gathered_glossy", gathered), buffer("vertex_glossy_radiance", out)]);
        }
        let chosen = self.adaptive.as_ref().map(|(a, _)| &a.chosen);
        resources.extend(chosen.into_iter().flat_map(|c| interpolate::adaptive_resources(scene, c)));
        let (vertex_list, vertices) = frame.camera_vertices();
        resources.push(buffer("vertex_list", vertex_list));
        rec.stage(interpolate::PASS.label, |e, s| {
            self.interpolate.run(gpu, e, scene, &resources, [vertices, 1, 1], s)
        })?;
        let camera = frame.camera;
        let mut resources = with_lobes(
            vec![view("visibility", &camera.view.view), buffer("indirect", &camera.indirect)],
            &[(&self.vertex_lights, "vertex_diffuse", "vertex_glossy")],
        );
        resources.extend(radiance.map(|(_, g)| buffer("vertex_glossy_radiance", g)));
        let pixels = [camera.view.width, camera.view.height, 1];
        rec.stage(shade::PASS.label, |e, s| {
            self.shade.run_on(gpu, e, frame.camera_triangles().0, &resources, pixels, s)
        })?;
        match &self.near_field {
            Some(n) => n.record(gpu, frame, chosen, rec),
            None => Ok(()),
        }
    }
}

//! Mixed reality (DESIGN.md §6): virtual content lit by a real room's RGB-D frames, rendered
//! from each frame's camera and composited over its colour image, the real depth hiding the
//! virtual object where real surfaces are nearer.
//!
//! [`MrRenderer`] is the per-frame loop of `relume replay`: frame in, composited image +
//! indirect image + timings out. The service's streams use [`virtual_depth`] and [`composite`]
//! with the scene's shared renderer.

pub mod differential;
pub mod environment;
pub mod replay;
pub mod synthetic;

use crate::gpu::differential::Differential;
use crate::gpu::timing::StageTimings;
use crate::gpu::{Gpu, GpuError};
use crate::image::{LinearImage, encode_srgb};
use crate::renderer::{Method, Renderer};
use crate::rgbd::accumulate::ValAccumulator;
use crate::rgbd::{RgbdFrame, RgbdSettings};
use crate::scene::Scene;
use differential::{Emitter, LightField, MrSettings};
use environment::Environment;
use glam::{DAffine3, Vec3};
use std::time::Instant;

/// How replayed frames are lit and rendered.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MrOptions {
    /// Output size; the frame's intrinsics are scaled to it.
    pub width: u32,
    pub height: u32,
    /// Exposure of the virtual object in the composite, on the camera's scale: its radiance is
    /// divided by `radiance_scale` (camera value = radiance / `radiance_scale`, as the room's
    /// VALs were made) and multiplied by this before sRGB encoding ([`display_scale`]). The
    /// default 1 shows a virtual surface as the camera would show a real one of the same
    /// radiance, whatever `radiance_scale` is.
    pub exposure: f32,
    /// Accumulate VALs across frames into a world-space set (None: each frame's VALs only).
    pub accumulate: Option<AccumulateOptions>,
}

/// The persistent VAL set of [`ValAccumulator`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AccumulateOptions {
    /// Grid cell (m): one VAL per cell, the newest.
    pub cell_size: f32,
    /// Memory bound: VALs kept at most (the oldest go first).
    pub max_vals: usize,
    /// VALs older than this many frames are dropped.
    pub max_age_frames: u32,
}

impl Default for AccumulateOptions {
    fn default() -> Self {
        Self { cell_size: 0.05, max_vals: 65_536, max_age_frames: 300 }
    }
}

/// One relit frame.
pub struct MrFrame {
    /// The camera image with the virtual object composited in (sRGB, row-major).
    pub composited: Vec<[u8; 3]>,
    /// Indirect light on the virtual object alone (linear radiance; alpha = coverage).
    pub indirect: LinearImage,
    /// Direct light of the scene's own spot light, if it has one.
    pub direct: LinearImage,
    pub timings: StageTimings,
    /// VALs that lit the frame (the frame's, or the accumulated set, plus the spot's).
    pub val_count: u32,
    /// Diffuse irradiance (W/m²) at each sparse point of the virtual object: view-independent,
    /// so its change between frames measures how steady the light is.
    pub sparse_irradiance: Vec<Vec3>,
}

pub struct MrRenderer {
    renderer: Renderer,
    settings: RgbdSettings,
    mr: MrSettings,
    options: MrOptions,
    accumulator: Option<ValAccumulator>,
    frames: u64,
    /// Only with `settings.mr.differential`.
    differential: Option<DifferentialState>,
    environment: Environment,
    /// Centre of the virtual content's bounding sphere: the environment's VALs surround it.
    centre: Vec3,
}

/// The differential pass (its BVH of the virtual meshes as placed) and the virtual content's
/// re-emitters and bounds.
struct DifferentialState {
    pass: Differential,
    emitters: Vec<Emitter>,
    bounds: (Vec3, Vec3),
}

/// Stage name of the differential rendering in a replay's timings (wall time: receivers on the
/// CPU, the GPU rounds, the composite's relighting).
pub const DIFFERENTIAL_STAGE: &str = "differential";

/// Stage name of the environment's VALs (CPU: the `auto` estimate and the VALs' upload).
pub const ENVIRONMENT_STAGE: &str = "environment";

impl MrRenderer {
    pub fn new(gpu: &Gpu, scene: &Scene, options: MrOptions) -> anyhow::Result<Self> {
        let accumulator = match options.accumulate {
            Some(a) => Some(ValAccumulator::new(a.cell_size, a.max_vals, a.max_age_frames)?),
            None => None,
        };
        let renderer = Renderer::new(gpu, scene)?;
        let differential = match scene.settings.mr.differential {
            false => None,
            true => Some(DifferentialState {
                pass: Differential::on(gpu, &renderer.scene, scene.settings.mr.device)?,
                emitters: differential::emitters(scene),
                bounds: differential::bounds(renderer.scene.flat.vertices.iter().map(|v| Vec3::from(v.position))),
            }),
        };
        let centre = renderer.scene.flat.bounding_sphere().0;
        Ok(Self {
            renderer,
            settings: scene.settings.rgbd,
            mr: scene.settings.mr,
            options,
            accumulator,
            frames: 0,
            differential,
            environment: Environment::None,
            centre,
        })
    }

    /// Light the following frames with `environment` too (`settings.environment`, read by
    /// [`Environment::from_settings`]).
    pub fn set_environment(&mut self, environment: Environment) {
        self.environment = environment;
    }

    /// Relight `frame`: its VALs (or the accumulated set), the scene's spot light if any, the
    /// virtual object seen from the frame's camera and composited over its colour.
    pub fn render_frame(&mut self, gpu: &Gpu, frame: &RgbdFrame) -> Result<MrFrame, GpuError> {
        let (w, h) = (self.options.width, self.options.height);
        let settings = self.settings;
        // The differential pass and the environment need the real VALs on the CPU: they are
        // read back, and the readback is timed as the `rgbd_vals` stage; the environment's VALs
        // follow them.
        let start = Instant::now();
        let on_cpu = self.differential.is_some() || self.environment != Environment::None;
        let real_vals = match (&mut self.accumulator, on_cpu) {
            (None, false) => {
                self.renderer.set_rgbd_frame(gpu, frame, &settings)?;
                None
            }
            (None, true) => Some(self.renderer.rgbd_frame_vals(gpu, frame, &settings)?),
            (Some(acc), _) => {
                let vals = self.renderer.rgbd_frame_vals(gpu, frame, &settings)?;
                acc.insert(self.frames, &vals);
                Some(acc.vals())
            }
        };
        let rgbd_ms = start.elapsed().as_secs_f64() * 1e3;
        // The differential pass's receivers: its stage, and the `auto` environment's level.
        let start = Instant::now();
        let grid = self.differential.as_ref().map(|d| {
            let pose = self.renderer.local_pose(&frame.camera_to_world);
            differential::receivers(frame, &pose, &settings, &self.mr, d.bounds)
        });
        let receivers_ms = start.elapsed().as_secs_f64() * 1e3;
        let start = Instant::now();
        let real_vals = real_vals.map(|mut vals| {
            let environment = self.environment.vals(self.centre, frame, &settings, &vals, grid.as_ref());
            vals.extend(environment);
            vals
        });
        if let Some(vals) = &real_vals {
            self.renderer.set_vals(gpu, vals)?;
        }
        let environment_ms = start.elapsed().as_secs_f64() * 1e3;
        self.frames += 1;
        self.renderer.set_pinhole_view(frame.intrinsics, &frame.camera_to_world);
        let mut rendered = self.renderer.render(gpu, Method::Sparse, w, h)?;
        if real_vals.is_some() {
            rendered.timings.stages.insert(0, (crate::renderer::stage::RGBD_VALS.to_owned(), rgbd_ms));
        }
        if self.environment != Environment::None {
            rendered.timings.stages.insert(1, (ENVIRONMENT_STAGE.to_owned(), environment_ms));
        }
        let virtual_depth = virtual_depth(gpu, &self.renderer, &frame.camera_to_world)?;
        let sparse_irradiance = self.renderer.read_gathered_irradiance(gpu)?;
        let background = match (&mut self.differential, &real_vals, &grid) {
            (Some(d), Some(vals), Some(grid)) => {
                let start = Instant::now();
                let mut all = vals.clone();
                all.extend(differential::emitter_vals(&d.emitters, &sparse_irradiance));
                let (light, _) = d.pass.run(gpu, &self.renderer.scene, &grid.receivers, &all, vals.len())?;
                if tracing::enabled!(tracing::Level::DEBUG) {
                    let fraction = |l: &crate::gpu::differential::ReceiverLight| {
                        l.blocked.max_element() / l.unoccluded.max_element().max(1e-12)
                    };
                    let net = |l: &crate::gpu::differential::ReceiverLight| {
                        l.change().element_sum() / l.unoccluded.element_sum().max(1e-12)
                    };
                    let shadowed = light.iter().filter(|l| fraction(l) > 0.1).count();
                    let darkened = light.iter().filter(|l| net(l) < -0.1).count();
                    let most = light.iter().map(fraction).fold(0.0f32, f32::max);
                    let darkest = light.iter().map(net).fold(0.0f32, f32::min);
                    // The same, over the receivers the virtual object does not hide (the shadow
                    // one can see).
                    let shown = visible_receivers(grid, frame, &virtual_depth, w, h);
                    let visible = light.iter().zip(&shown).filter(|(_, v)| **v).map(|(l, _)| l);
                    let visible_darkened = visible.clone().filter(|l| net(l) < -0.1).count();
                    let visible_darkest = visible.map(net).fold(0.0f32, f32::min);
                    tracing::debug!(
                        receivers = light.len(),
                        shadowed,
                        darkened,
                        most,
                        darkest,
                        visible = shown.iter().filter(|v| **v).count(),
                        visible_darkened,
                        visible_darkest,
                        "differential: blocked fraction (over 10 %: shadowed) and net change (under -10 %: darkened)"
                    );
                }
                let field = LightField { grid, light: &light };
                let background = differential::relight_camera(frame, &field, w, h, settings.radiance_scale);
                let ms = receivers_ms + start.elapsed().as_secs_f64() * 1e3;
                rendered.timings.stages.push((DIFFERENTIAL_STAGE.to_owned(), ms));
                Some(background)
            }
            _ => None,
        };
        let virtual_rgb = rendered.direct.add(&rendered.indirect);
        let composited = composite_over(
            frame,
            background.as_deref(),
            &virtual_rgb,
            &virtual_depth,
            display_scale(self.options.exposure, settings.radiance_scale),
        );
        Ok(MrFrame {
            composited,
            indirect: rendered.indirect,
            direct: rendered.direct,
            timings: rendered.timings,
            val_count: rendered.val_count,
            sparse_irradiance,
        })
    }
}

/// Per receiver of `grid`, whether the composite shows it: the virtual content (its optical
/// depth per output pixel, `width` x `height`) is absent or behind the real surface at the
/// receiver's cell centre, as [`composite_over`] decides.
fn visible_receivers(
    grid: &differential::ReceiverGrid,
    frame: &RgbdFrame,
    virtual_depth: &[Option<f32>],
    width: u32,
    height: u32,
) -> Vec<bool> {
    let (fw, fh) = (frame.intrinsics.width, frame.intrinsics.height);
    let step = grid.settings.grid_step.max(1);
    let mut shown = vec![true; grid.receivers.len()];
    for (cell, r) in grid.cells.iter().enumerate() {
        let Some(r) = r else { continue };
        let (cx, cy) = (cell as u32 % grid.size.x, cell as u32 / grid.size.x);
        let (u, v) = ((cx * step + (step - 1) / 2).min(fw - 1), (cy * step + (step - 1) / 2).min(fh - 1));
        let (x, y) = ((u * width / fw).min(width - 1), (v * height / fh).min(height - 1));
        let real = frame.depth[(v * fw + u) as usize];
        if let Some(Some(z)) = virtual_depth.get((y * width + x) as usize) {
            shown[*r as usize] = real.is_finite() && real > 0.0 && *z >= real;
        }
    }
    shown
}

/// Optical depth (m, along `camera_to_world`'s z) of the virtual content at each pixel of the
/// last frame `renderer` rendered (from that camera, given in the user's world coordinates);
/// `None` where no geometry covers it.
pub fn virtual_depth(gpu: &Gpu, renderer: &Renderer, camera_to_world: &DAffine3) -> Result<Vec<Option<f32>>, GpuError> {
    let Some(view) = renderer.camera_view() else {
        return Ok(Vec::new());
    };
    // The flat scene is relative to the scene's origin: so must the pose be.
    let world_to_camera = renderer.local_pose(camera_to_world).inverse();
    let flat = &renderer.scene.flat;
    Ok(view
        .read(gpu)?
        .iter()
        .map(|hit| hit.map(|h| world_to_camera.transform_point3(flat.surface_at(h.triangle, h.barycentrics).0).z))
        .collect())
}

/// The factor from the virtual object's radiance (W/(m² sr)) to the camera's linear value in
/// the composite: `exposure / radiance_scale`, the inverse of the calibration that made the
/// room's VALs (`L = radiance_scale * srgb_to_linear(rgb)`), so the object and the room are on
/// one scale; `exposure` alone when `radiance_scale` is 0 (a room that emits nothing).
pub fn display_scale(exposure: f32, radiance_scale: f32) -> f32 {
    if radiance_scale > 0.0 { exposure / radiance_scale } else { exposure }
}

/// The camera image with the virtual object drawn where it is visible: where it covers the
/// pixel and is nearer than the real surface (or the real depth is missing). `virtual_rgb` is
/// linear radiance at the output size, `virtual_depth` its optical depth per pixel (m), and
/// the colour and depth of `frame` are sampled at the nearest pixel when the sizes differ.
pub fn composite(
    frame: &RgbdFrame,
    virtual_rgb: &LinearImage,
    virtual_depth: &[Option<f32>],
    exposure: f32,
) -> Vec<[u8; 3]> {
    composite_over(frame, None, virtual_rgb, virtual_depth, exposure)
}

/// [`composite`] over `background` (sRGB at the output size, e.g. the camera image relit by
/// [`differential::relight_camera`]) instead of the frame's colour where it is given.
pub fn composite_over(
    frame: &RgbdFrame,
    background: Option<&[[u8; 3]]>,
    virtual_rgb: &LinearImage,
    virtual_depth: &[Option<f32>],
    exposure: f32,
) -> Vec<[u8; 3]> {
    let (w, h) = (virtual_rgb.width as usize, virtual_rgb.height as usize);
    let (fw, fh) = (frame.intrinsics.width as usize, frame.intrinsics.height as usize);
    (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let source = (y * fh / h) * fw + x * fw / w;
            let real_depth = frame.depth[source];
            let real_valid = real_depth.is_finite() && real_depth > 0.0;
            match virtual_depth[i] {
                Some(z) if !real_valid || z < real_depth => {
                    let c = virtual_rgb.rgb(i) * exposure;
                    [encode_srgb(c.x), encode_srgb(c.y), encode_srgb(c.z)]
                }
                _ => background.map_or(frame.color[source], |b| b[i]),
            }
        })
        .collect()
}

/// Mean relative change between two frames' per-point irradiance:
/// `sum |E_t - E_{t-1}| / sum |E_{t-1}|` over points and channels (0 = identical).
pub fn relative_change(previous: &[Vec3], current: &[Vec3]) -> f64 {
    let (mut diff, mut total) = (0.0f64, 0.0f64);
    for (p, c) in previous.iter().zip(current) {
        diff += f64::from((*c - *p).abs().element_sum());
        total += f64::from(p.abs().element_sum());
    }
    if total > 0.0 { diff / total } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rgbd::Intrinsics;

    fn frame(w: u32, h: u32, depth: f32) -> RgbdFrame {
        RgbdFrame {
            timestamp: 0.0,
            intrinsics: Intrinsics { width: w, height: h, fx: 10.0, fy: 10.0, cx: 1.5, cy: 1.5 },
            color: (0..w * h).map(|i| [i as u8, 7, 9]).collect(),
            depth: vec![depth; (w * h) as usize],
            camera_to_world: DAffine3::IDENTITY,
        }
    }

    /// A virtual surface of the radiance a room pixel was calibrated to (`L = radiance_scale *
    /// linear(rgb)`) is shown at that pixel's own value at exposure 1, whatever the scale.
    #[test]
    fn the_composite_shows_radiance_on_the_cameras_scale() {
        for radiance_scale in [0.5f32, 1.0, 3.0, 40.0] {
            let linear = crate::twin::rgbd::srgb_to_linear(Vec3::new(0.6, 0.3, 0.9));
            let shown = display_scale(1.0, radiance_scale) * (radiance_scale * linear);
            assert!(shown.abs_diff_eq(linear, 1e-6), "scale {radiance_scale}: {shown} vs {linear}");
            assert_eq!(display_scale(2.0, radiance_scale), 2.0 * display_scale(1.0, radiance_scale));
        }
        assert_eq!(display_scale(0.7, 0.0), 0.7, "a room that emits nothing leaves the exposure as it is");
    }

    /// The camera image passes through where the virtual object is absent or behind the real
    /// surface; the object shows where it is nearer or the real depth is missing.
    #[test]
    fn composite_respects_real_depth() {
        let mut f = frame(4, 4, 2.0);
        f.depth[5] = 0.0;
        let image = LinearImage { width: 4, height: 4, pixels: vec![[1.0, 0.0, 0.0, 1.0]; 16] };
        let mut depth = vec![None; 16];
        depth[1] = Some(1.0); // in front
        depth[2] = Some(3.0); // behind
        depth[5] = Some(9.0); // no real depth
        let out = composite(&f, &image, &depth, 1.0);
        for (i, (got, camera)) in out.iter().zip(&f.color).enumerate() {
            let expected = if i == 1 || i == 5 { [255, 0, 0] } else { *camera };
            assert_eq!(*got, expected, "pixel {i}");
        }
    }

    #[test]
    fn relative_change_of_identical_and_doubled() {
        let a = vec![Vec3::ONE, Vec3::splat(2.0)];
        assert_eq!(relative_change(&a, &a), 0.0);
        let b: Vec<Vec3> = a.iter().map(|v| *v * 2.0).collect();
        assert!((relative_change(&a, &b) - 1.0).abs() < 1e-12);
        assert_eq!(relative_change(&[], &[]), 0.0);
    }
}

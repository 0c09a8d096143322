//! Differential rendering (Debevec 1998, Knecht et al. 2010): what the virtual
//! content does to the real surfaces around it, its shadow and its reflected light.
//!
//! 1. **Receivers.** The depth frame's surfaces within `settings.mr.receiver_margin` of the
//!    virtual content's bounding box, one per `receiver_step`-pixel cell: position and normal
//!    are those of the RGB-D VAL rules (`twin::rgbd`: bilateral depth, normal from the
//!    neighbouring cells) at that step.
//! 2. **Change of irradiance** (`gpu::differential`): per receiver, the real VALs' irradiance
//!    without visibility `E`, the part of it a virtual triangle blocks, and the irradiance of
//!    the virtual content's sparse points re-emitting what they gathered (each a Lambertian disc
//!    of the sparse point's share of its mesh's area, flux `rho_d E_x a`). `dE = added - blocked`.
//! 3. **Composite.** `L' = L + rho_real dE / pi`, the real albedo estimated from the frame as
//!    `rho_real = clamp(pi L / E, 0, MAX_REAL_ALBEDO)` per channel (`L` the pixel's radiance,
//!    `radiance_scale * srgb_to_linear(rgb)`; `E = 0` gives the maximum). Unclamped this is
//!    `L (E + dE) / E`: the ratio of the irradiance with and without the virtual content, so
//!    `radiance_scale` cancels. The clamp keeps a pixel brighter than its estimated irradiance
//!    explains (lit by light no VAL stands for) from darkening more than a white surface would.
//!    Receiver values are interpolated bilinearly to pixels, from the receivers on the pixel's
//!    own surface only (the RGB-D rules' test of a depth step, `twin::rgbd::same_surface`): the
//!    change does not bleed across a silhouette onto a surface behind or in front.

use crate::gpu::differential::groups::{EMITTER_GROUP_SIZE, GROUP_SIZE, REACH, group_vals};
use crate::gpu::differential::twin::ContentSphere;
use crate::gpu::differential::{Differential, Receiver, ReceiverLight, Sums};
use crate::gpu::scene::GpuScene;
use crate::gpu::{Gpu, GpuError};
use crate::rgbd::{RgbdFrame, RgbdSettings};
use crate::scene::Scene;
use crate::scene::settings::DifferentialMethod;
use crate::twin::Val;
use crate::twin::rgbd::{grid_size, same_surface, srgb8_to_linear};
use glam::{Affine3A, Mat4, UVec2, Vec3};
use std::f32::consts::PI;

/// Upper bound of the estimated real albedo (module docs, step 3).
pub const MAX_REAL_ALBEDO: f32 = 1.0;

pub use crate::scene::settings::MrSettings;

/// Per-channel real albedo from a pixel's radiance `camera_radiance` (W/(m² sr)) and the
/// irradiance its surface is estimated to receive (W/m²).
pub fn real_albedo(camera_radiance: Vec3, irradiance: Vec3) -> Vec3 {
    let channel = |l: f32, e: f32| if e > 0.0 { (PI * l / e).clamp(0.0, MAX_REAL_ALBEDO) } else { MAX_REAL_ALBEDO };
    Vec3::new(
        channel(camera_radiance.x, irradiance.x),
        channel(camera_radiance.y, irradiance.y),
        channel(camera_radiance.z, irradiance.z),
    )
}

/// The radiance of a real pixel after the virtual content's change `light` (module docs,
/// step 3), never negative.
pub fn relit_radiance(camera_radiance: Vec3, light: &ReceiverLight) -> Vec3 {
    (camera_radiance + real_albedo(camera_radiance, light.unoccluded) * light.change() / PI).max(Vec3::ZERO)
}

/// The receivers of one frame on their grid.
#[derive(Clone, Debug, Default)]
pub struct ReceiverGrid {
    /// The RGB-D rules at the receiver step.
    pub settings: RgbdSettings,
    /// Grid size in cells.
    pub size: UVec2,
    /// Per cell (row-major): its index in `receivers`, if it has one.
    pub cells: Vec<Option<u32>>,
    pub receivers: Vec<Receiver>,
    /// Per receiver, the camera's radiance there (W/(m² sr)): its RGB-D VAL's `flux / (pi a)`.
    pub radiance: Vec<Vec3>,
    /// Per receiver, its depth along the camera's optical axis (m); empty when not known (the
    /// interpolation then tests no surface).
    pub depth: Vec<f32>,
    /// The depth camera's horizontal focal length (pixels), which turns pixels across the
    /// image into metres at a depth.
    pub focal: f32,
}

/// The receivers of `frame`, its camera at `camera_to_world` (the scene's frame: relative to
/// its floating origin, as the flattened scene and `bounds` are), within `mr.receiver_margin`
/// of the box `bounds` (min, max corners, m).
pub fn receivers(
    frame: &RgbdFrame,
    camera_to_world: &Affine3A,
    rgbd: &RgbdSettings,
    mr: &MrSettings,
    bounds: (Vec3, Vec3),
) -> ReceiverGrid {
    let settings = RgbdSettings { grid_step: mr.receiver_step.max(1), ..*rgbd };
    let size = grid_size(&frame.intrinsics, &settings);
    let (lo, hi) = (bounds.0 - mr.receiver_margin, bounds.1 + mr.receiver_margin);
    let focal = frame.intrinsics.fx;
    let mut grid =
        ReceiverGrid { settings, size, cells: vec![None; (size.x * size.y) as usize], focal, ..Default::default() };
    let world_to_camera = camera_to_world.inverse();
    for (cell, val) in crate::twin::rgbd::rgbd_vals_by_cell_posed(frame, camera_to_world, &settings) {
        if val.position.cmpge(lo).all() && val.position.cmple(hi).all() {
            grid.cells[(cell.y * size.x + cell.x) as usize] = Some(grid.receivers.len() as u32);
            grid.receivers.push(Receiver { position: val.position, normal: val.normal });
            grid.radiance.push(if val.area > 0.0 { val.flux / (PI * val.area) } else { Vec3::ZERO });
            grid.depth.push(world_to_camera.transform_point3(val.position).z);
        }
    }
    grid
}

/// The receivers' light, interpolated to pixels.
pub struct LightField<'a> {
    pub grid: &'a ReceiverGrid,
    pub light: &'a [ReceiverLight],
}

impl LightField<'_> {
    /// Bilinear interpolation at depth-image pixel (`u`, `v`), whose depth is `depth` (m; 0 or
    /// NaN when unknown), between the four nearest cell centres that have receivers on the
    /// pixel's surface (their weights renormalised); `None` when none has one. A receiver is on
    /// the pixel's surface when the depth step between them is no steeper than the RGB-D rules
    /// allow a surface (`twin::rgbd::same_surface`, over at least a cell's width: the
    /// receiver's depth is the cell's filtered one).
    pub fn at(&self, u: f32, v: f32, depth: f32) -> Option<ReceiverLight> {
        let step = self.grid.settings.grid_step.max(1);
        // Cell g's centre pixel is g s + floor((s - 1) / 2) (`twin::rgbd::cell_centre`).
        let (s, centre) = (step as f32, ((step - 1) / 2) as f32);
        let gx = (u - centre) / s;
        let gy = (v - centre) / s;
        let (x0, y0) = (gx.floor(), gy.floor());
        let (fx, fy) = (gx - x0, gy - y0);
        let mut sum = ReceiverLight::default();
        let mut weight = 0.0;
        for (dx, dy, w) in
            [(0, 0, (1.0 - fx) * (1.0 - fy)), (1, 0, fx * (1.0 - fy)), (0, 1, (1.0 - fx) * fy), (1, 1, fx * fy)]
        {
            let (cx, cy) = (x0 as i64 + dx, y0 as i64 + dy);
            if cx < 0 || cy < 0 || cx >= i64::from(self.grid.size.x) || cy >= i64::from(self.grid.size.y) || w <= 0.0 {
                continue;
            }
            if let Some(r) = self.grid.cells[(cy as u32 * self.grid.size.x + cx as u32) as usize] {
                if depth > 0.0
                    && self.grid.focal > 0.0
                    && let Some(&z) = self.grid.depth.get(r as usize)
                {
                    let pixels = (cx as f32 * s + centre - u).hypot(cy as f32 * s + centre - v).max(s);
                    let lateral = pixels * depth / self.grid.focal;
                    if !same_surface(depth, z, lateral, self.grid.settings.min_cosine) {
                        continue;
                    }
                }
                let l = &self.light[r as usize];
                sum.unoccluded += l.unoccluded * w;
                sum.blocked += l.blocked * w;
                sum.added += l.added * w;
                weight += w;
            }
        }
        (weight > 0.0).then(|| ReceiverLight {
            unoccluded: sum.unoccluded / weight,
            blocked: sum.blocked / weight,
            added: sum.added / weight,
        })
    }
}

/// The camera image of `frame` at `width` x `height` (nearest source pixel, as
/// [`super::composite`] samples it) with the virtual content's change applied where `field` has
/// receivers; sRGB.
pub fn relight_camera(
    frame: &RgbdFrame,
    field: &LightField<'_>,
    width: u32,
    height: u32,
    radiance_scale: f32,
) -> Vec<[u8; 3]> {
    use rayon::prelude::*;
    let (w, h) = (width as usize, height as usize);
    let (fw, fh) = (frame.intrinsics.width as usize, frame.intrinsics.height as usize);
    // Each pixel on its own: over the cores (30 ms a 640x480 frame on one of this machine's).
    (0..w * h)
        .into_par_iter()
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let (u, v) = (x * fw / w, y * fh / h);
            let c = frame.color[v * fw + u];
            let light = match field.at(u as f32, v as f32, frame.depth[v * fw + u]) {
                Some(l) if radiance_scale > 0.0 => l,
                _ => return c,
            };
            let linear = srgb8_to_linear(c);
            let out = relit_radiance(linear * radiance_scale, &light) / radiance_scale;
            [out.x, out.y, out.z].map(crate::image::encode_srgb)
        })
        .collect()
}

/// The light at every receiver of `grid` by `method`: `vals[.. real_count]` the real VALs, the
/// rest the content's re-emitters, `bounds` the content's box. `exact` sums every VAL at every
/// receiver ([`Differential::run`]); `fast` groups the VALs ([`group_vals`]) with `fast`'s
/// parameters, sums them with [`Differential::run`] and computes only the receivers
/// [`adaptive_light`] asks for.
#[allow(clippy::too_many_arguments)]
pub fn receiver_light(
    pass: &mut Differential,
    gpu: &Gpu,
    scene: &GpuScene,
    grid: &ReceiverGrid,
    vals: &[Val],
    real_count: usize,
    bounds: (Vec3, Vec3),
    (method, fast): (DifferentialMethod, &FastSettings),
) -> Result<(Vec<ReceiverLight>, AdaptiveCounts), GpuError> {
    match method {
        DifferentialMethod::Exact => {
            let (light, _) = pass.run(gpu, scene, &grid.receivers, Sums::Exact { vals, real_count })?;
            let counts = AdaptiveCounts { computed: light.len(), ..Default::default() };
            Ok((light, counts))
        }
        DifferentialMethod::Fast => {
            let grouped = group_vals(vals, real_count, (fast.group_size, fast.emitter_group_size), fast.reach);
            let content = ContentSphere::around(bounds);
            let sums = Sums::Fast { grouped: &grouped, content: &content, ray_share: fast.ray_share };
            adaptive_light(grid, fast, |receivers| pass.run(gpu, scene, receivers, sums).map(|l| l.0))
        }
    }
}

/// The fast pass's parameters; the default is what `settings.mr.differential_method: "fast"`
/// runs (`examples/mr_differential.rs` varies them).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FastSettings {
    /// Real VALs per group at most ([`GROUP_SIZE`]).
    pub group_size: usize,
    /// Re-emitters per group at most ([`EMITTER_GROUP_SIZE`]).
    pub emitter_group_size: usize,
    /// Group radii beyond which a group is summed as one ([`REACH`]).
    pub reach: f32,
    /// [`ADAPTIVE_SPACING`].
    pub spacing: u32,
    /// [`ADAPTIVE_CHANGE_SPREAD`].
    pub change_spread: f32,
    /// [`ADAPTIVE_IRRADIANCE_RATIO`].
    pub irradiance_ratio: f32,
    /// [`RAY_SHARE`].
    pub ray_share: f32,
}

impl Default for FastSettings {
    fn default() -> Self {
        Self {
            group_size: GROUP_SIZE,
            emitter_group_size: EMITTER_GROUP_SIZE,
            reach: REACH,
            spacing: ADAPTIVE_SPACING,
            change_spread: ADAPTIVE_CHANGE_SPREAD,
            irradiance_ratio: ADAPTIVE_IRRADIANCE_RATIO,
            ray_share: RAY_SHARE,
        }
    }
}

/// How one frame's fast sums agree with the exact ones at the same receivers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Agreement {
    /// `sqrt(sum |dE_fast - dE_exact|² / sum |dE_exact|²)` over the receivers (RGB), `dE` the
    /// change of irradiance `added - blocked`.
    pub change_rel_rmse: f64,
    /// The same of the unoccluded irradiance `E`.
    pub unoccluded_rel_rmse: f64,
    /// The darkest net change `sum dE / sum E` (over the channels) among the receivers the
    /// composite shows: the contact shadow's darkest value, exact and fast.
    pub darkest_exact: f32,
    pub darkest_fast: f32,
}

impl Agreement {
    /// Compare `fast` with `exact` at the same receivers, the darkest value over the receivers
    /// `visible` marks.
    pub fn of(exact: &[ReceiverLight], fast: &[ReceiverLight], visible: &[bool]) -> Self {
        let rel = |f: fn(&ReceiverLight) -> Vec3| {
            let (mut e, mut n) = (0.0f64, 0.0f64);
            for (a, b) in fast.iter().zip(exact) {
                e += f64::from((f(a) - f(b)).length_squared());
                n += f64::from(f(b).length_squared());
            }
            if n > 0.0 { (e / n).sqrt() } else { 0.0 }
        };
        let darkest = |light: &[ReceiverLight]| {
            light.iter().zip(visible).filter(|(_, v)| **v).map(|(l, _)| net_change(l)).fold(0.0f32, f32::min)
        };
        Self {
            change_rel_rmse: rel(ReceiverLight::change),
            unoccluded_rel_rmse: rel(|l| l.unoccluded),
            darkest_exact: darkest(exact),
            darkest_fast: darkest(fast),
        }
    }

    /// `|darkest_fast - darkest_exact| / |darkest_exact|` (0 when both are 0).
    pub fn darkest_rel_error(&self) -> f32 {
        let d = (self.darkest_fast - self.darkest_exact).abs();
        if d == 0.0 { 0.0 } else { d / self.darkest_exact.abs().max(1e-12) }
    }
}

/// A receiver's net relative change of irradiance, `sum dE / sum E` over the channels.
pub fn net_change(l: &ReceiverLight) -> f32 {
    l.change().element_sum() / l.unoccluded.element_sum().max(1e-12)
}

/// A member of a VAL group that the fast pass opens (a group near the receiver) and that lights
/// the receiver with less than this share of its estimated irradiance gets no shadow ray of its
/// own: a real group's member takes the visibility of its group's representative member; a
/// re-emitter that faint, and a far re-emitter group that faint, is counted as seen
/// (`gpu::differential::twin::receiver_light_fast`). On the TUM replay 70 % of the rays to
/// opened groups' members carried 1 % of their irradiance; at this share the fast pass casts
/// 3.3x fewer rays and agrees with the exact pass as closely as with every ray cast; counting
/// the faint re-emitters as seen casts a fifth fewer again, for a contact shadow about 2 %
/// lighter (docs/measurements/differential.md, "Faint members").
pub const RAY_SHARE: f32 = 3e-4;

/// Coarsest spacing (in receiver cells) of the fast pass's adaptive receivers: every
/// `ADAPTIVE_SPACING`-th cell in each direction is computed, then cells at half that spacing, and
/// so on down to every cell, each computed only where its neighbours at the spacing above
/// disagree ([`adaptive_light`]).
pub const ADAPTIVE_SPACING: u32 = 8;

/// Largest spread, over the corners a cell would be interpolated from, of the share of their
/// unoccluded irradiance that the content blocks or adds (luminance): beyond it the cell is
/// computed.
pub const ADAPTIVE_CHANGE_SPREAD: f32 = 0.03;

/// Largest ratio between the corners' unoccluded irradiances (luminance) for interpolation.
pub const ADAPTIVE_IRRADIANCE_RATIO: f32 = 1.1;

/// Smallest cosine between a cell's normal and a corner's for interpolation (about 32°: the
/// receivers' normals come from noisy depth).
const ADAPTIVE_NORMAL_COS: f32 = 0.85;

/// Largest distance of a corner from a cell's plane for interpolation, per metre between them.
const ADAPTIVE_PLANE_SLOPE: f32 = 0.3;

/// How the fast pass filled one frame's receivers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AdaptiveCounts {
    /// Receivers whose sums were computed.
    pub computed: usize,
    /// Receivers interpolated from computed (or interpolated) neighbours.
    pub interpolated: usize,
    /// Receivers computed below the coarsest level because a corner had no receiver (or lay
    /// off the grid), lay on another surface, or disagreed.
    pub missing: usize,
    pub surface: usize,
    pub changing: usize,
}

/// Why a receiver could not be interpolated.
enum Refusal {
    Missing,
    Surface,
    Changing,
}

/// The receivers' light on the grid, most of it interpolated: cells on a grid of spacing
/// [`ADAPTIVE_SPACING`] are computed by `compute` (which sums the light at the receivers it is
/// given), then, halving the spacing down to 1, each cell not yet filled is interpolated
/// bilinearly from the filled cells at the spacing above that surround it when they lie on its
/// surface (normals within about 32°, within 0.3 of their distance of its plane) and agree
/// (their unoccluded irradiance within [`ADAPTIVE_IRRADIANCE_RATIO`], the share of it blocked
/// and added within [`ADAPTIVE_CHANGE_SPREAD`] of each other); otherwise it is computed. The
/// content's effect is smooth away from its contact, so far from it most cells are
/// interpolated and near it most are computed.
pub fn adaptive_light<E>(
    grid: &ReceiverGrid,
    fast: &FastSettings,
    mut compute: impl FnMut(&[Receiver]) -> Result<Vec<ReceiverLight>, E>,
) -> Result<(Vec<ReceiverLight>, AdaptiveCounts), E> {
    let (w, h) = (grid.size.x, grid.size.y);
    let mut light: Vec<Option<ReceiverLight>> = vec![None; grid.receivers.len()];
    let mut counts = AdaptiveCounts::default();
    let receiver_at = |x: u32, y: u32| if x < w && y < h { grid.cells[(y * w + x) as usize] } else { None };
    let mut spacing = fast.spacing.max(1).next_power_of_two();
    // The coarsest level: every cell on the grid of `spacing`.
    let mut todo: Vec<u32> = Vec::new();
    for y in (0..h).step_by(spacing as usize) {
        for x in (0..w).step_by(spacing as usize) {
            todo.extend(receiver_at(x, y));
        }
    }
    let mut fill = |todo: &[u32], light: &mut Vec<Option<ReceiverLight>>| -> Result<usize, E> {
        let receivers: Vec<Receiver> = todo.iter().map(|r| grid.receivers[*r as usize]).collect();
        for (r, l) in todo.iter().zip(compute(&receivers)?) {
            light[*r as usize] = Some(l);
        }
        Ok(todo.len())
    };
    counts.computed += fill(&todo, &mut light)?;
    while spacing > 1 {
        let half = spacing / 2;
        todo.clear();
        let mut interpolated = Vec::new();
        for y in (0..h).step_by(half as usize) {
            for x in (0..w).step_by(half as usize) {
                let Some(r) = receiver_at(x, y) else { continue };
                if light[r as usize].is_some() {
                    continue;
                }
                match interpolate(grid, &light, r, x, y, spacing, fast) {
                    Ok(l) => interpolated.push((r, l)),
                    Err(why) => {
                        todo.push(r);
                        match why {
                            Refusal::Missing => counts.missing += 1,
                            Refusal::Surface => counts.surface += 1,
                            Refusal::Changing => counts.changing += 1,
                        }
                    }
                }
            }
        }
        // Written after the level's decisions: a cell is interpolated from the level above only.
        counts.interpolated += interpolated.len();
        for (r, l) in interpolated {
            light[r as usize] = Some(l);
        }
        counts.computed += fill(&todo, &mut light)?;
        spacing = half;
    }
    Ok((light.into_iter().map(Option::unwrap_or_default).collect(), counts))
}

/// The light of receiver `r` at cell (`x`, `y`) interpolated from the filled cells of the grid
/// of `spacing` around it ([`adaptive_light`]), or why they do not allow it.
fn interpolate(
    grid: &ReceiverGrid,
    light: &[Option<ReceiverLight>],
    r: u32,
    x: u32,
    y: u32,
    spacing: u32,
    fast: &FastSettings,
) -> Result<ReceiverLight, Refusal> {
    let here = grid.receivers[r as usize];
    let (x0, y0) = (x / spacing * spacing, y / spacing * spacing);
    let (fx, fy) = ((x - x0) as f32 / spacing as f32, (y - y0) as f32 / spacing as f32);
    let xs: &[(u32, f32)] = if fx == 0.0 { &[(x0, 1.0)] } else { &[(x0, 1.0 - fx), (x0 + spacing, fx)] };
    let ys: &[(u32, f32)] = if fy == 0.0 { &[(y0, 1.0)] } else { &[(y0, 1.0 - fy), (y0 + spacing, fy)] };
    let (mut sum, mut weight) = (ReceiverLight::default(), 0.0);
    let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
    for &(cx, wx) in xs {
        for &(cy, wy) in ys {
            if cx >= grid.size.x || cy >= grid.size.y {
                return Err(Refusal::Missing);
            }
            let c = grid.cells[(cy * grid.size.x + cx) as usize].ok_or(Refusal::Missing)?;
            let corner = grid.receivers[c as usize];
            let l = light[c as usize].ok_or(Refusal::Missing)?;
            let d = corner.position - here.position;
            if here.normal.dot(corner.normal) < ADAPTIVE_NORMAL_COS
                || here.normal.dot(d).abs() > ADAPTIVE_PLANE_SLOPE * d.length()
            {
                return Err(Refusal::Surface);
            }
            let e = luminance(l.unoccluded);
            let shares = [e, luminance(l.blocked) / e.max(1e-12), luminance(l.added) / e.max(1e-12)];
            for k in 0..3 {
                lo[k] = lo[k].min(shares[k]);
                hi[k] = hi[k].max(shares[k]);
            }
            let w = wx * wy;
            sum.unoccluded += l.unoccluded * w;
            sum.blocked += l.blocked * w;
            sum.added += l.added * w;
            weight += w;
        }
    }
    let smooth = hi[0] <= fast.irradiance_ratio * lo[0]
        && hi[1] - lo[1] <= fast.change_spread
        && hi[2] - lo[2] <= fast.change_spread;
    if !(smooth && weight > 0.0) {
        return Err(Refusal::Changing);
    }
    Ok(ReceiverLight { unoccluded: sum.unoccluded / weight, blocked: sum.blocked / weight, added: sum.added / weight })
}

/// Rec. 709 luminance.
fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

/// One sparse point as a re-emitter: where it is and what share of its mesh it stands for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Emitter {
    pub position: Vec3,
    pub normal: Vec3,
    /// Its mesh's area over its mesh's sparse point count (m²).
    pub area: f32,
    /// Diffuse albedo of its material (textures not sampled).
    pub albedo: Vec3,
}

/// The sparse points of `scene` as placed by its meshes' transforms, in the flattened order
/// (`gpu::scene::FlatScene`).
pub fn emitters(scene: &Scene) -> Vec<Emitter> {
    let placement: Vec<Mat4> = scene.meshes.iter().map(|m| m.model_to_world).collect();
    emitters_placed(scene, &placement)
}

/// [`emitters`] with mesh `i` placed by `model_to_world[i]` (as `Renderer::place_meshes`
/// places it): positions, normals and areas follow the placement.
pub fn emitters_placed(scene: &Scene, model_to_world: &[Mat4]) -> Vec<Emitter> {
    let mut out = Vec::new();
    for (mesh, &transform) in scene.meshes.iter().zip(model_to_world) {
        let placed = mesh.placed(transform);
        let positions = placed.positions();
        let area = crate::scene::surface_area(&positions, &mesh.triangles) as f32;
        // The points gathered every frame (the adaptive candidates lie between them).
        let base = mesh.sparse.base_len();
        let count = base.max(1) as f32;
        let points =
            placed.sparse_positions().into_iter().zip(placed.sparse_normals()).zip(&mesh.sparse.triangles).take(base);
        for ((position, normal), triangle) in points {
            let material = mesh.triangle_materials[*triangle as usize] as usize;
            let albedo = scene.materials[material].diffuse;
            out.push(Emitter { position, normal, area: area / count, albedo });
        }
    }
    out
}

/// The re-emitters as VALs, given the diffuse irradiance each sparse point gathered (W/m²):
/// flux `albedo * E * area`, the radiosity of the patch times its area.
pub fn emitter_vals(emitters: &[Emitter], irradiance: &[Vec3]) -> Vec<Val> {
    emitters
        .iter()
        .zip(irradiance)
        .map(|(e, irr)| Val { position: e.position, normal: e.normal, area: e.area, flux: e.albedo * *irr * e.area })
        .collect()
}

/// Corners (min, max) of the box around `positions` (m).
pub fn bounds(positions: impl IntoIterator<Item = Vec3>) -> (Vec3, Vec3) {
    positions.into_iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), p| (lo.min(p), hi.max(p)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Unclamped, the relit radiance is the ratio of irradiance with and without the virtual
    /// content; a clamped albedo darkens no more than a white surface would.
    #[test]
    fn relit_radiance_is_the_irradiance_ratio() {
        let light = ReceiverLight { unoccluded: Vec3::splat(10.0), blocked: Vec3::splat(4.0), added: Vec3::splat(1.0) };
        let l = Vec3::new(0.5, 1.0, 2.0); // albedos pi/20, pi/10, pi/5: unclamped
        let out = relit_radiance(l, &light);
        assert!((out - l * 0.7).abs().max_element() < 1e-6, "{out}");
        let bright = Vec3::splat(100.0); // pi L / E > 1: albedo 1
        let out = relit_radiance(bright, &light);
        assert!((out - (bright - Vec3::splat(3.0 / PI))).abs().max_element() < 1e-4, "{out}");
        let none = ReceiverLight { unoccluded: Vec3::ZERO, blocked: Vec3::ZERO, added: Vec3::ZERO };
        assert_eq!(relit_radiance(l, &none), l);
    }

    /// Interpolation reproduces a receiver at its cell centre and blends two cells linearly.
    #[test]
    fn light_field_interpolates_between_cell_centres() {
        let grid = ReceiverGrid {
            settings: RgbdSettings { grid_step: 4, ..Default::default() },
            size: UVec2::new(2, 1),
            cells: vec![Some(0), Some(1)],
            receivers: vec![Receiver { position: Vec3::ZERO, normal: Vec3::Z }; 2],
            radiance: vec![Vec3::ONE; 2],
            ..Default::default()
        };
        let light = [
            ReceiverLight { unoccluded: Vec3::ONE, blocked: Vec3::ZERO, added: Vec3::ZERO },
            ReceiverLight { unoccluded: Vec3::splat(3.0), blocked: Vec3::ONE, added: Vec3::ZERO },
        ];
        let field = LightField { grid: &grid, light: &light };
        // Centres at pixels 1 and 5.
        assert_eq!(field.at(1.0, 1.0, 0.0).map(|l| l.unoccluded), Some(Vec3::ONE));
        let mid = field.at(3.0, 1.0, 0.0).expect("between two receivers");
        assert!((mid.unoccluded - Vec3::splat(2.0)).abs().max_element() < 1e-6);
        assert!((mid.blocked - Vec3::splat(0.5)).abs().max_element() < 1e-6);
        let empty = ReceiverGrid { cells: vec![None, None], ..grid.clone() };
        assert!(LightField { grid: &empty, light: &light }.at(3.0, 1.0, 0.0).is_none());

        // With depths: receiver 0 on a desk 1 m away, receiver 1 on a wall 2 m away (a step
        // no surface seen at the grazing cosine makes over a few millimetres).
        let (desk, wall) = (1.0, 2.0);
        let stepped = ReceiverGrid { depth: vec![desk, wall], focal: 500.0, ..grid.clone() };
        let field = LightField { grid: &stepped, light: &light };
        // A desk pixel between the two takes the desk's receiver alone, a wall pixel the wall's.
        assert_eq!(field.at(3.0, 1.0, desk).map(|l| l.unoccluded), Some(Vec3::ONE));
        assert_eq!(field.at(3.0, 1.0, wall).map(|l| l.unoccluded), Some(Vec3::splat(3.0)));
        // A pixel on neither (the bunny's own depth, say) takes no change.
        assert!(field.at(3.0, 1.0, 0.5).is_none());
        // Unknown depth: the plain bilinear blend.
        let mid = field.at(3.0, 1.0, f32::NAN).expect("between two receivers");
        assert!((mid.unoccluded - Vec3::splat(2.0)).abs().max_element() < 1e-6);
        // A slanted surface: the two receivers 2 cm apart in depth across 4 pixels at 1 m
        // (8 mm across the image: 68 degrees from the view direction) blend as before.
        let slanted = ReceiverGrid { depth: vec![1.0, 1.02], ..stepped.clone() };
        let mid = LightField { grid: &slanted, light: &light }.at(3.0, 1.0, 1.01).expect("one surface");
        assert!((mid.unoccluded - Vec3::splat(2.0)).abs().max_element() < 1e-6);
    }
}

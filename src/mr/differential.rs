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
//!    Receiver values are interpolated bilinearly to pixels.

use crate::gpu::differential::{Receiver, ReceiverLight};
use crate::rgbd::{RgbdFrame, RgbdSettings};
use crate::scene::Scene;
use crate::twin::Val;
use crate::twin::rgbd::{grid_size, srgb_to_linear};
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
    let mut grid = ReceiverGrid { settings, size, cells: vec![None; (size.x * size.y) as usize], ..Default::default() };
    for (cell, val) in crate::twin::rgbd::rgbd_vals_by_cell_posed(frame, camera_to_world, &settings) {
        if val.position.cmpge(lo).all() && val.position.cmple(hi).all() {
            grid.cells[(cell.y * size.x + cell.x) as usize] = Some(grid.receivers.len() as u32);
            grid.receivers.push(Receiver { position: val.position, normal: val.normal });
            grid.radiance.push(if val.area > 0.0 { val.flux / (PI * val.area) } else { Vec3::ZERO });
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
    /// Bilinear interpolation at depth-image pixel (`u`, `v`) between the four nearest cell
    /// centres that have receivers (their weights renormalised); `None` when none has one.
    pub fn at(&self, u: f32, v: f32) -> Option<ReceiverLight> {
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
    let (w, h) = (width as usize, height as usize);
    let (fw, fh) = (frame.intrinsics.width as usize, frame.intrinsics.height as usize);
    (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let (u, v) = (x * fw / w, y * fh / h);
            let c = frame.color[v * fw + u];
            let light = match field.at(u as f32, v as f32) {
                Some(l) if radiance_scale > 0.0 => l,
                _ => return c,
            };
            let linear = srgb_to_linear(Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32) / 255.0);
            let out = relit_radiance(linear * radiance_scale, &light) / radiance_scale;
            [out.x, out.y, out.z].map(crate::image::encode_srgb)
        })
        .collect()
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
        };
        let light = [
            ReceiverLight { unoccluded: Vec3::ONE, blocked: Vec3::ZERO, added: Vec3::ZERO },
            ReceiverLight { unoccluded: Vec3::splat(3.0), blocked: Vec3::ONE, added: Vec3::ZERO },
        ];
        let field = LightField { grid: &grid, light: &light };
        // Centres at pixels 1 and 5.
        assert_eq!(field.at(1.0, 1.0).map(|l| l.unoccluded), Some(Vec3::ONE));
        let mid = field.at(3.0, 1.0).expect("between two receivers");
        assert!((mid.unoccluded - Vec3::splat(2.0)).abs().max_element() < 1e-6);
        assert!((mid.blocked - Vec3::splat(0.5)).abs().max_element() < 1e-6);
        let empty = ReceiverGrid { cells: vec![None, None], ..grid.clone() };
        assert!(LightField { grid: &empty, light: &light }.at(3.0, 1.0).is_none());
    }
}

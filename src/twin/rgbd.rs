//! CPU twin of the RGB-D VAL generation (docs/design.md §2 "RGB-D frames"); the GPU pass is
//! `gpu::lights::rgbd` with `shaders/rgbd.wgsl`, whose functions have the same names and argument
//! order. Where a function here takes the depth or colour image, its WGSL twin reads it from the
//! pass's binding instead; where one returns `None`, its WGSL twin returns a zero vector.
//!
//! A frame becomes at most one VAL per cell of a grid over the depth image:
//!
//! - **Grid.** With `s = max(grid_step, 1)`, cell `(gx, gy)` covers the pixels
//!   `[gx s, min(gx s + s, w)) x [gy s, min(gy s + s, h))`; the grid is `ceil(w/s) x ceil(h/s)`.
//! - **Depth.** The bilateral filter evaluated at the cell's centre pixel
//!   ([`cell_centre`], the block's middle pixel, rounded down): a Gaussian of `sigma = radius/2`
//!   pixels times `exp(-(dz/sigma_z)^2)` with `dz` relative to the centre pixel's depth, over
//!   the valid pixels of the `(2 radius + 1)^2` window. Chosen over the block's median because it
//!   is the filter docs/design.md names, costs one fixed window per cell with no sort, and never
//!   mixes two surfaces across a depth edge (the range weight drops the far one). A cell whose
//!   centre pixel has no valid depth yields no VAL: holes are not filled from their rims.
//! - **Validity.** A depth is valid when it is finite, `> 0` and in `[min_depth, max_depth]`;
//!   invalid pixels are skipped by the filter and never produce VALs.
//! - **Position.** The centre pixel unprojected at the filtered depth ([`unproject`]).
//! - **Normal.** From the neighbouring cells' positions ([`grid_normal`]): per image axis the
//!   central difference when both neighbours are usable, else the one-sided difference to the
//!   usable one; the cross product of the two, oriented toward the camera. A neighbour is usable
//!   when its depth is valid and it lies on the same surface ([`same_surface`]: the depth step
//!   to it is no steeper than the grazing limit `min_cosine`), so a cell on a silhouette takes
//!   its normal from its own side instead of from the wall behind it. A cell with no usable
//!   neighbour on some axis (isolated cells, a 1-cell grid) faces the camera.
//! - **Area.** The block's footprint on the surface, [`footprint_area`]:
//!   `(z/fx)(z/fy) n_px cos_alpha / max(cos, c_min)`, `n_px` the block's pixel count (`s^2` for
//!   full blocks), `cos` between the normal and the direction to the camera and `cos_alpha`
//!   between that direction and the optical axis. docs/design.md's `(z/fx)(z/fy)/max(cos, c_min)`
//!   is this with `cos_alpha = 1`; off the optical axis it overstates every footprint by
//!   `1/cos_alpha` (25 % in the corners of a TUM frame, 10 % summed over it), so a wall would
//!   emit more than it reflects. With `cos_alpha` the footprints of a plane sum to its area.
//! - **Flux.** `Phi = pi L a`, `L = radiance_scale * c`, `c` the mean of the block's colours,
//!   each linearised first ([`block_color`]; every pixel of the block counts, with or without
//!   depth, since the area is the whole block's).
//! - **World.** Position and normal go through `camera_to_world` (a rigid pose).

use super::Val;
use crate::rgbd::{Intrinsics, RgbdFrame, RgbdSettings};
use glam::{Affine3A, UVec2, UVec4, Vec3};
use std::f32::consts::PI;

/// Floor of the footprint's cosine whatever `min_cosine` says (a `min_cosine <= 0` setting
/// would otherwise divide by zero for a cell seen exactly edge-on).
pub const MIN_FOOTPRINT_COSINE: f32 = 1e-3;

/// The sRGB decoding (IEC 61966-2-1) of each channel of `c` in [0, 1].
pub fn srgb_to_linear(c: Vec3) -> Vec3 {
    let f = |s: f32| if s <= 0.040_45 { s / 12.92 } else { ((s + 0.055) / 1.055).powf(2.4) };
    Vec3::new(f(c.x), f(c.y), f(c.z))
}

/// [`srgb_to_linear`] of an 8-bit colour (each channel over 255), from a table of the 256
/// values: the same floats, without three `powf` per pixel (the camera image's pixels are
/// decoded several times a mixed-reality frame).
pub fn srgb8_to_linear(c: [u8; 3]) -> Vec3 {
    static TABLE: std::sync::LazyLock<[f32; 256]> =
        std::sync::LazyLock::new(|| std::array::from_fn(|i| srgb_to_linear(Vec3::splat(i as f32 / 255.0)).x));
    Vec3::new(TABLE[c[0] as usize], TABLE[c[1] as usize], TABLE[c[2] as usize])
}

/// Whether depth `z` (m) is a measurement: finite, positive and in `[min_depth, max_depth]`.
pub fn valid_depth(z: f32, settings: &RgbdSettings) -> bool {
    z.is_finite() && z > 0.0 && z >= settings.min_depth && z <= settings.max_depth
}

/// Pixels per cell side: `grid_step`, at least 1.
pub fn grid_step(settings: &RgbdSettings) -> u32 {
    settings.grid_step.max(1)
}

/// Cells of the grid: `ceil(w / s) x ceil(h / s)`.
pub fn grid_size(intrinsics: &Intrinsics, settings: &RgbdSettings) -> UVec2 {
    let s = grid_step(settings);
    UVec2::new(intrinsics.width.div_ceil(s), intrinsics.height.div_ceil(s))
}

/// The pixels cell `cell` (inside the grid) covers: `(x0, y0, x1, y1)`, ends exclusive and
/// clipped to the image.
pub fn cell_block(intrinsics: &Intrinsics, cell: UVec2, settings: &RgbdSettings) -> UVec4 {
    let s = grid_step(settings);
    let size = UVec2::new(intrinsics.width, intrinsics.height);
    let start = cell * s;
    let end = start + (size - start).min(UVec2::splat(s));
    UVec4::new(start.x, start.y, end.x, end.y)
}

/// The block's middle pixel (rounded down for even sizes): where the cell samples its depth.
pub fn cell_centre(block: UVec4) -> UVec2 {
    UVec2::new((block.x + block.z - 1) / 2, (block.y + block.w - 1) / 2)
}

/// Range weight of the bilateral filter for a depth difference `dz` (m): `exp(-(dz/sigma)^2)`;
/// with `sigma <= 0` only equal depths count.
pub fn bilateral_range_weight(dz: f32, sigma: f32) -> f32 {
    if sigma > 0.0 {
        let t = dz / sigma;
        (-t * t).exp()
    } else if dz == 0.0 {
        1.0
    } else {
        0.0
    }
}

/// Bilateral-filtered depth (m) at pixel (`u`, `v`) of `depth` (row-major, `intrinsics` size),
/// or 0 where that pixel's own depth is invalid. Spatial sigma `radius / 2` pixels, range
/// weight [`bilateral_range_weight`] relative to the pixel's depth; invalid and out-of-image
/// pixels are skipped. Always a weighted mean of valid depths, so itself valid.
pub fn bilateral_depth(depth: &[f32], intrinsics: &Intrinsics, u: u32, v: u32, settings: &RgbdSettings) -> f32 {
    let (w, h) = (intrinsics.width as i64, intrinsics.height as i64);
    let at = |x: i64, y: i64| depth.get((y * w + x) as usize).copied().unwrap_or(0.0);
    let zc = at(u as i64, v as i64);
    if !valid_depth(zc, settings) {
        return 0.0;
    }
    let r = settings.bilateral_radius as i64;
    if r == 0 {
        return zc;
    }
    // Gaussian exp(-d^2 / (2 sigma^2)) with sigma = r / 2.
    let spatial = -2.0 / (r * r) as f32;
    let (mut sum, mut weight) = (0.0f32, 0.0f32);
    for dy in -r..=r {
        let y = v as i64 + dy;
        if y < 0 || y >= h {
            continue;
        }
        for dx in -r..=r {
            let x = u as i64 + dx;
            if x < 0 || x >= w {
                continue;
            }
            let z = at(x, y);
            if !valid_depth(z, settings) {
                continue;
            }
            let wt = (spatial * (dx * dx + dy * dy) as f32).exp()
                * bilateral_range_weight(z - zc, settings.bilateral_depth_sigma);
            sum += wt * z;
            weight += wt;
        }
    }
    // The centre has weight 1, so `weight >= 1`.
    sum / weight
}

/// Camera-space point (optical axes, m) seen at pixel (`u`, `v`) (centres at integer
/// coordinates) at depth `z` along the optical axis.
pub fn unproject(intrinsics: &Intrinsics, u: f32, v: f32, z: f32) -> Vec3 {
    Vec3::new((u - intrinsics.cx) * z / intrinsics.fx, (v - intrinsics.cy) * z / intrinsics.fy, z)
}

/// Whether a neighbour at depth `z_neighbour` belongs to the same surface as a cell at depth
/// `z`, `lateral` metres apart across the image: the slope `|dz| / lateral` must not exceed
/// that of a surface seen at the grazing cosine `min_cosine`, `sqrt(1 - c^2) / c`. A steeper
/// step is a depth discontinuity (a silhouette), not a surface.
pub fn same_surface(z: f32, z_neighbour: f32, lateral: f32, min_cosine: f32) -> bool {
    let c = min_cosine.clamp(MIN_FOOTPRINT_COSINE, 1.0);
    (z_neighbour - z).abs() * c <= lateral * (1.0 - c * c).sqrt()
}

/// Position difference along one image axis around `p` from its usable neighbours `before`
/// and `after`: central when both are there, else one-sided, `None` when neither is.
pub fn axis_difference(p: Vec3, before: Option<Vec3>, after: Option<Vec3>) -> Option<Vec3> {
    match (before, after) {
        (Some(b), Some(a)) => Some(a - b),
        (None, Some(a)) => Some(a - p),
        (Some(b), None) => Some(p - b),
        (None, None) => None,
    }
}

/// Unit normal at camera-space position `p` from its usable neighbouring cells' positions
/// (`left` = gx - 1, `right` = gx + 1, `up` = gy - 1, `down` = gy + 1): the cross product of
/// the two [`axis_difference`]s; `None` when an axis has no usable neighbour or the two
/// differences are parallel. Oriented toward the camera (the origin).
pub fn grid_normal(
    p: Vec3,
    left: Option<Vec3>,
    right: Option<Vec3>,
    up: Option<Vec3>,
    down: Option<Vec3>,
) -> Option<Vec3> {
    let dx = axis_difference(p, left, right)?;
    let dy = axis_difference(p, up, down)?;
    let n = dx.cross(dy);
    let len2 = n.length_squared();
    // Parallel (or vanishing) differences: sin^2 of their angle below 1e-12.
    if len2.is_nan() || len2 <= 1e-12 * dx.length_squared() * dy.length_squared() {
        return None;
    }
    let n = n / len2.sqrt();
    Some(if n.dot(p) > 0.0 { -n } else { n })
}

/// Area (m²) of the surface a block of `pixels` pixels sees around camera-space `p` with unit
/// normal `n`: `(z/fx)(z/fy) pixels cos_alpha / max(cos, c_min)` (module docs), `c_min` at
/// least [`MIN_FOOTPRINT_COSINE`].
pub fn footprint_area(intrinsics: &Intrinsics, p: Vec3, n: Vec3, pixels: u32, min_cosine: f32) -> f32 {
    let d = p.length();
    let cos_alpha = p.z / d;
    let cos_view = -n.dot(p) / d;
    let front = (p.z / intrinsics.fx) * (p.z / intrinsics.fy) * pixels as f32;
    front * cos_alpha / cos_view.max(min_cosine.max(MIN_FOOTPRINT_COSINE))
}

/// Mean linear colour of the block's pixels (each decoded from sRGB first).
pub fn block_color(color: &[[u8; 3]], intrinsics: &Intrinsics, block: UVec4) -> Vec3 {
    let mut sum = Vec3::ZERO;
    for y in block.y..block.w {
        for x in block.x..block.z {
            let c = color.get((y * intrinsics.width + x) as usize).copied().unwrap_or([0; 3]);
            sum += srgb8_to_linear(c);
        }
    }
    sum / ((block.z - block.x) * (block.w - block.y)) as f32
}

/// The filtered depth of every cell in grid order (0 = no VAL): the first GPU dispatch.
pub fn grid_depths(frame: &RgbdFrame, settings: &RgbdSettings) -> Vec<f32> {
    use rayon::prelude::*;
    let i = &frame.intrinsics;
    let g = grid_size(i, settings);
    // Each cell on its own, over the cores (the differential pass's receivers are this grid).
    (0..g.x * g.y)
        .into_par_iter()
        .map(|k| {
            let c = cell_centre(cell_block(i, UVec2::new(k % g.x, k / g.x), settings));
            bilateral_depth(&frame.depth, i, c.x, c.y, settings)
        })
        .collect()
}

/// The camera-space position of the cell `cell + offset` if it exists, has depth and lies on
/// the same surface as the cell at depth `z` (see [`same_surface`]).
pub fn grid_neighbour(
    grid: &[f32],
    intrinsics: &Intrinsics,
    settings: &RgbdSettings,
    z: f32,
    cell: UVec2,
    offset: glam::IVec2,
) -> Option<Vec3> {
    let g = grid_size(intrinsics, settings);
    let n = cell.as_ivec2() + offset;
    if n.x < 0 || n.y < 0 || n.x >= g.x as i32 || n.y >= g.y as i32 {
        return None;
    }
    let n = n.as_uvec2();
    let zn = grid.get((n.y * g.x + n.x) as usize).copied().unwrap_or(0.0);
    if zn <= 0.0 {
        return None;
    }
    let here = cell_centre(cell_block(intrinsics, cell, settings)).as_vec2();
    let there = cell_centre(cell_block(intrinsics, n, settings)).as_vec2();
    let lateral = z * ((there.x - here.x).abs() / intrinsics.fx + (there.y - here.y).abs() / intrinsics.fy);
    if !same_surface(z, zn, lateral, settings.min_cosine) {
        return None;
    }
    Some(unproject(intrinsics, there.x, there.y, zn))
}

/// The VAL of grid cell `cell` from the filtered grid depths, or `None` if the cell has no
/// depth: the second GPU dispatch.
pub fn grid_cell_val(
    grid: &[f32],
    color: &[[u8; 3]],
    intrinsics: &Intrinsics,
    camera_to_world: &Affine3A,
    settings: &RgbdSettings,
    cell: UVec2,
) -> Option<Val> {
    let g = grid_size(intrinsics, settings);
    let z = grid.get((cell.y * g.x + cell.x) as usize).copied().unwrap_or(0.0);
    if z <= 0.0 {
        return None;
    }
    let block = cell_block(intrinsics, cell, settings);
    let c = cell_centre(block).as_vec2();
    let p = unproject(intrinsics, c.x, c.y, z);
    let nb = |dx: i32, dy: i32| grid_neighbour(grid, intrinsics, settings, z, cell, glam::IVec2::new(dx, dy));
    let n = grid_normal(p, nb(-1, 0), nb(1, 0), nb(0, -1), nb(0, 1)).unwrap_or(-p / p.length());
    let pixels = (block.z - block.x) * (block.w - block.y);
    let area = footprint_area(intrinsics, p, n, pixels, settings.min_cosine);
    let radiance = settings.radiance_scale * block_color(color, intrinsics, block);
    Some(Val {
        position: camera_to_world.transform_point3(p),
        normal: camera_to_world.transform_vector3(n).normalize(),
        area,
        flux: PI * radiance * area,
    })
}

/// Every VAL of `frame` (docs/design.md §2 "RGB-D frames"), in grid order (row-major cells).
pub fn rgbd_vals(frame: &RgbdFrame, settings: &RgbdSettings) -> Vec<Val> {
    rgbd_vals_by_cell(frame, settings).into_iter().map(|(_, v)| v).collect()
}

/// [`rgbd_vals`] with each VAL's grid cell, in the grid's row-major order (the GPU's order too).
/// The frame's pose is rounded to f32 as it is (relative to the user's origin).
pub fn rgbd_vals_by_cell(frame: &RgbdFrame, settings: &RgbdSettings) -> Vec<(UVec2, Val)> {
    let camera_to_world = crate::scene::local_pose(glam::DVec3::ZERO, &frame.camera_to_world);
    rgbd_vals_by_cell_posed(frame, &camera_to_world, settings)
}

/// [`rgbd_vals_by_cell`] with the camera at `camera_to_world` instead of the frame's own pose
/// (e.g. the pose relative to a scene's floating origin, `Renderer::local_pose`).
pub fn rgbd_vals_by_cell_posed(
    frame: &RgbdFrame,
    camera_to_world: &Affine3A,
    settings: &RgbdSettings,
) -> Vec<(UVec2, Val)> {
    use rayon::prelude::*;
    let i = &frame.intrinsics;
    let grid = grid_depths(frame, settings);
    let g = grid_size(i, settings);
    (0..g.x * g.y)
        .into_par_iter()
        .map(|k| UVec2::new(k % g.x, k / g.x))
        .filter_map(|cell| grid_cell_val(&grid, &frame.color, i, camera_to_world, settings, cell).map(|v| (cell, v)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec2;

    const TUM: Intrinsics = Intrinsics::TUM;

    /// The table is the function, bit for bit, at every 8-bit value of every channel.
    #[test]
    fn the_8_bit_table_is_the_function() {
        for v in 0..=255u8 {
            let c = [v, 255 - v, v / 2];
            let direct = srgb_to_linear(Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32) / 255.0);
            assert_eq!(srgb8_to_linear(c).to_array().map(f32::to_bits), direct.to_array().map(f32::to_bits));
        }
    }

    fn frame(
        intrinsics: Intrinsics,
        depth: impl Fn(u32, u32) -> f32,
        color: impl Fn(u32, u32) -> [u8; 3],
    ) -> RgbdFrame {
        let (w, h) = (intrinsics.width, intrinsics.height);
        let pixels = || (0..h).flat_map(|v| (0..w).map(move |u| (u, v)));
        RgbdFrame {
            timestamp: 0.0,
            intrinsics,
            color: pixels().map(|(u, v)| color(u, v)).collect(),
            depth: pixels().map(|(u, v)| depth(u, v)).collect(),
            camera_to_world: glam::DAffine3::IDENTITY,
        }
    }

    fn grey(_: u32, _: u32) -> [u8; 3] {
        [128, 128, 128]
    }

    /// Area (m²) the frustum of `intrinsics` (pixel edges at -0.5 and size - 0.5) cuts from the
    /// plane `dot(m, X) = d`: the planar quadrilateral of its four corner rays.
    fn frustum_area_on_plane(i: &Intrinsics, m: Vec3, d: f32) -> f32 {
        let corner = |u: f32, v: f32| {
            let r = unproject(i, u, v, 1.0);
            r * (d / m.dot(r))
        };
        let (u1, v1) = (i.width as f32 - 0.5, i.height as f32 - 0.5);
        let (a, b, c, e) = (corner(-0.5, -0.5), corner(u1, -0.5), corner(u1, v1), corner(-0.5, v1));
        0.5 * (c - a).cross(e - b).length()
    }

    /// Depth along the optical axis of pixel (u, v) on the plane `dot(m, X) = d`.
    fn plane_depth(i: &Intrinsics, m: Vec3, d: f32, u: u32, v: u32) -> f32 {
        d / m.dot(unproject(i, u as f32, v as f32, 1.0))
    }

    #[test]
    fn srgb_decoding_matches_the_standard() {
        assert_eq!(srgb_to_linear(Vec3::ZERO), Vec3::ZERO);
        assert!((srgb_to_linear(Vec3::ONE) - Vec3::ONE).abs().max_element() < 1e-6);
        assert!((srgb_to_linear(Vec3::splat(0.5)).x - 0.214_04).abs() < 1e-4);
        for b in 0..=255u8 {
            let c = srgb_to_linear(Vec3::splat(b as f32 / 255.0)).x;
            assert_eq!(c, crate::image::decode_srgb(b));
        }
    }

    #[test]
    fn unproject_inverts_the_pinhole_projection() {
        let p = unproject(&TUM, 100.0, 400.0, 2.5);
        assert!((p.x / p.z * TUM.fx + TUM.cx - 100.0).abs() < 1e-4);
        assert!((p.y / p.z * TUM.fy + TUM.cy - 400.0).abs() < 1e-4);
        assert_eq!(unproject(&TUM, TUM.cx, TUM.cy, 3.0), Vec3::new(0.0, 0.0, 3.0));
    }

    #[test]
    fn grid_covers_the_image_with_clipped_edge_cells() {
        let s = RgbdSettings { grid_step: 8, ..Default::default() };
        assert_eq!(grid_size(&TUM, &s), UVec2::new(80, 60));
        let small = Intrinsics { width: 21, height: 10, ..TUM };
        assert_eq!(grid_size(&small, &s), UVec2::new(3, 2));
        assert_eq!(cell_block(&small, UVec2::new(2, 1), &s), UVec4::new(16, 8, 21, 10));
        assert_eq!(cell_centre(UVec4::new(16, 8, 21, 10)), UVec2::new(18, 8));
        assert_eq!(cell_centre(UVec4::new(8, 0, 16, 8)), UVec2::new(11, 3));
        let zero = RgbdSettings { grid_step: 0, ..s };
        assert_eq!(grid_size(&small, &zero), UVec2::new(21, 10));
    }

    /// A wall facing the camera 2 m away, TUM intrinsics, grid step 8: every footprint is exact
    /// (cos = cos_alpha on a fronto-parallel plane, and the filter of a constant depth is that
    /// depth), so positions, normals and the total area agree to float rounding: 1e-5 m, 1e-5
    /// and 1e-5 relative (each area is a handful of f32 operations; the sum is taken in f64).
    /// There are no partial edge cells at 640x480.
    #[test]
    fn wall_facing_the_camera_gives_its_frustum_area() {
        let z = 2.0;
        let f = frame(TUM, |_, _| z, grey);
        let s = RgbdSettings::default();
        let vals = rgbd_vals(&f, &s);
        assert_eq!(vals.len(), 80 * 60);
        for v in &vals {
            assert!((v.position.z - z).abs() <= 1e-5, "{v:?} off the plane");
            assert!((v.normal - Vec3::NEG_Z).length() <= 1e-5, "{v:?} does not face the camera");
        }
        let total: f64 = vals.iter().map(|v| v.area as f64).sum();
        let want = (TUM.width as f64 / TUM.fx as f64 * z as f64) * (TUM.height as f64 / TUM.fy as f64 * z as f64);
        assert!((total - want).abs() <= 1e-5 * want, "area {total} vs {want}");
    }

    /// A plane tilted 50° about the camera's x axis (depth 1.3-4.4 m across the frame). Each
    /// footprint divides by its cosine, so the areas sum to the plane's true area. Tolerance
    /// 1 % at step 8: a cell samples its footprint at the block's middle pixel rounded down,
    /// half a pixel before the block's centre in both axes, where the footprint (~ z^3) is
    /// smaller by ~0.3 %; with an odd step (centred sample) the error is a midpoint rule's,
    /// 0.1 %. Positions lie on the plane to 1e-4 m (the filter averages z, which is not linear
    /// across a tilted plane: ~1e-5 m), normals match to 1e-4.
    #[test]
    fn tilted_plane_areas_sum_to_its_true_area() {
        let t = 50f32.to_radians();
        let m = Vec3::new(0.0, t.sin(), t.cos());
        let d = 2.0 * t.cos();
        let f = frame(TUM, |u, v| plane_depth(&TUM, m, d, u, v), grey);
        let want = frustum_area_on_plane(&TUM, m, d);
        for (step, tolerance) in [(8, 0.01), (5, 0.001)] {
            let s = RgbdSettings { grid_step: step, ..Default::default() };
            let vals = rgbd_vals(&f, &s);
            assert_eq!(vals.len() as u32, grid_size(&TUM, &s).element_product());
            for v in &vals {
                assert!((m.dot(v.position) - d).abs() <= 1e-4, "{v:?} off the plane");
                assert!((v.normal + m).length() <= 1e-4, "{v:?}: normal is not {}", -m);
                assert!(-v.normal.dot(v.position.normalize()) > s.min_cosine);
            }
            let total = vals.iter().map(|v| v.area as f64).sum::<f64>() as f32;
            let err = (total - want).abs() / want;
            assert!(err <= tolerance, "step {step}: area {total} vs {want} ({:.3} %)", err * 100.0);
        }
    }

    #[test]
    fn constant_colour_gives_flux_pi_radiance_area() {
        let rgb = [200u8, 100, 50];
        let f = frame(TUM, |u, _| 1.5 + u as f32 * 1e-3, |_, _| rgb);
        let s = RgbdSettings { radiance_scale: 3.5, ..Default::default() };
        let l = s.radiance_scale * srgb_to_linear(Vec3::new(200.0, 100.0, 50.0) / 255.0);
        let vals = rgbd_vals(&f, &s);
        assert!(!vals.is_empty());
        for v in &vals {
            let want = PI * l * v.area;
            assert!((v.flux - want).abs().max_element() <= 1e-5 * want.max_element(), "{v:?} vs {want}");
        }
    }

    /// Invalid depth at a cell's centre pixel removes that cell; inside the filter window it
    /// is skipped (the wall's depth stays exact).
    #[test]
    fn invalid_depth_gives_no_val() {
        let s = RgbdSettings::default();
        let bad = [
            (UVec2::new(3, 2), 0.0),
            (UVec2::new(5, 5), f32::NAN),
            (UVec2::new(7, 1), -1.0),
            (UVec2::new(10, 10), 20.0),
            (UVec2::new(11, 3), 0.05),
            (UVec2::new(12, 4), f32::INFINITY),
        ];
        let centre = |c: UVec2| cell_centre(cell_block(&TUM, c, &s));
        let f = frame(
            TUM,
            |u, v| {
                let p = UVec2::new(u, v);
                if let Some((_, z)) = bad.iter().find(|(c, _)| centre(*c) == p) {
                    return *z;
                }
                // Invalid pixels next to the centre of cell (20, 20) must not disturb it.
                let c = centre(UVec2::new(20, 20));
                if p == c + UVec2::X || p == c + UVec2::Y {
                    f32::NAN
                } else if p == c - UVec2::X {
                    0.0
                } else {
                    2.0
                }
            },
            grey,
        );
        let by_cell = rgbd_vals_by_cell(&f, &s);
        assert_eq!(by_cell.len(), 80 * 60 - bad.len());
        for (cell, _) in &bad {
            assert!(by_cell.iter().all(|(c, _)| c != cell), "cell {cell} has a VAL");
        }
        for (_, v) in &by_cell {
            assert!(v.position.is_finite() && v.area.is_finite() && v.flux.is_finite());
            assert!((v.position.z - 2.0).abs() <= 1e-5);
        }
        for depth in [0.0, f32::NAN, -2.0, 100.0] {
            let empty = frame(TUM, |_, _| depth, grey);
            assert!(rgbd_vals(&empty, &s).is_empty(), "depth {depth} gave VALs");
        }
    }

    /// A box 1.5 m away in front of a wall at 3 m: both are fronto-parallel, so every normal
    /// faces the camera, also on the box's silhouette (the wall behind is not the same surface).
    #[test]
    fn silhouettes_take_their_normal_from_their_own_surface() {
        let f = frame(TUM, |u, v| if (200..400).contains(&u) && (150..330).contains(&v) { 1.5 } else { 3.0 }, grey);
        let vals = rgbd_vals(&f, &RgbdSettings::default());
        assert_eq!(vals.len(), 80 * 60);
        for v in &vals {
            assert!((v.normal - Vec3::NEG_Z).length() <= 1e-5, "{v:?}");
        }
        assert!(same_surface(2.0, 2.0 + 0.1, 0.03, 0.2));
        assert!(!same_surface(2.0, 2.0 + 0.2, 0.03, 0.2));
    }

    #[test]
    fn normals_fall_back_to_one_sided_differences_and_face_the_camera() {
        let p = Vec3::new(0.0, 0.0, 2.0);
        let (l, r, u, d) = (p - Vec3::X, p + Vec3::X, p - Vec3::Y, p + Vec3::Y);
        for (left, right, up, down) in
            [(Some(l), Some(r), Some(u), Some(d)), (None, Some(r), Some(u), None), (Some(l), None, None, Some(d))]
        {
            assert_eq!(grid_normal(p, left, right, up, down), Some(Vec3::NEG_Z));
        }
        assert_eq!(grid_normal(p, None, None, Some(u), Some(d)), None);
        assert_eq!(grid_normal(p, Some(l), Some(r), Some(l), Some(r)), None, "parallel differences");
    }

    #[test]
    fn the_pose_moves_positions_and_turns_normals() {
        let t = 30f32.to_radians();
        let m = Vec3::new(t.sin(), 0.0, t.cos());
        let mut f = frame(TUM, |u, v| plane_depth(&TUM, m, 2.0, u, v), |u, v| [(u % 256) as u8, (v % 256) as u8, 9]);
        let s = RgbdSettings { grid_step: 16, ..Default::default() };
        let camera = rgbd_vals(&f, &s);
        let pose = glam::DAffine3::from_rotation_translation(
            glam::DQuat::from_axis_angle(glam::DVec3::new(1.0, 2.0, -0.5).normalize(), 1.1),
            glam::DVec3::new(0.5, -2.0, 3.0),
        );
        f.camera_to_world = pose;
        let pose = crate::scene::local_pose(glam::DVec3::ZERO, &pose);
        let world = rgbd_vals(&f, &s);
        assert_eq!(world.len(), camera.len());
        for (c, w) in camera.iter().zip(&world) {
            assert!((pose.transform_point3(c.position) - w.position).length() <= 1e-5);
            assert!((pose.transform_vector3(c.normal) - w.normal).length() <= 1e-5);
            assert!((w.normal.length() - 1.0).abs() <= 1e-6);
            assert_eq!((c.area, c.flux), (w.area, w.flux));
        }
    }

    #[test]
    fn extremes_stay_finite() {
        let finite = |vals: &[Val]| {
            vals.iter()
                .all(|v| v.position.is_finite() && v.normal.is_finite() && v.area.is_finite() && v.flux.is_finite())
        };
        // Huge depth near the far limit, a tilted plane out there.
        let s = RgbdSettings { max_depth: 1e4, ..Default::default() };
        let far = frame(TUM, |u, v| 9_000.0 + (u + v) as f32 * 0.5, grey);
        let vals = rgbd_vals(&far, &s);
        assert_eq!(vals.len(), 4800);
        assert!(finite(&vals) && vals.iter().all(|v| v.area > 0.0));
        // A tiny radiance scale.
        let s = RgbdSettings { radiance_scale: 1e-30, ..Default::default() };
        let vals = rgbd_vals(&frame(TUM, |_, _| 2.0, grey), &s);
        assert!(finite(&vals) && vals.iter().all(|v| v.flux.min_element() >= 0.0));
        // Step 1 (one VAL per pixel) on a small image with a discontinuity.
        let small = Intrinsics { width: 32, height: 24, fx: 30.0, fy: 30.0, cx: 15.5, cy: 11.5 };
        let s = RgbdSettings { grid_step: 1, ..Default::default() };
        let step1 = frame(small, |u, v| if u < 10 { 1.0 } else { 2.0 + v as f32 * 0.01 }, grey);
        let vals = rgbd_vals(&step1, &s);
        assert_eq!(vals.len(), 32 * 24);
        assert!(finite(&vals));
        // A step larger than the image: one cell, which faces the camera (no neighbours) and
        // covers the whole frame.
        let s = RgbdSettings { grid_step: 1000, ..Default::default() };
        let vals = rgbd_vals(&frame(TUM, |_, _| 2.0, grey), &s);
        assert_eq!(vals.len(), 1);
        assert!(finite(&vals));
        let want = (640.0 / TUM.fx * 2.0) * (480.0 / TUM.fy * 2.0);
        assert!((vals[0].area - want).abs() <= 1e-4 * want, "{} vs {want}", vals[0].area);
        // Grazing: a plane at 88° has its footprints bounded by min_cosine.
        let t = 88f32.to_radians();
        let m = Vec3::new(0.0, t.sin(), t.cos());
        let graze = frame(TUM, |u, v| plane_depth(&TUM, m, 0.05, u, v), grey);
        let s = RgbdSettings::default();
        for v in rgbd_vals(&graze, &s) {
            let z = v.position.z;
            let bound = (z / TUM.fx) * (z / TUM.fy) * 64.0 / s.min_cosine;
            assert!(v.area.is_finite() && v.area <= bound * 1.0001, "{v:?} over {bound}");
        }
        // A frame whose buffers are shorter than its intrinsics say: no panic.
        let mut short = frame(TUM, |_, _| 2.0, grey);
        short.depth.truncate(1000);
        short.color.truncate(10);
        assert!(finite(&rgbd_vals(&short, &RgbdSettings::default())));
        let _ = Vec2::ZERO;
    }
}

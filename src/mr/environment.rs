//! Light from directions the camera never saw: a distant environment of radiance
//! `L(w)` (W/(m² sr)), sampled on a latitude-longitude grid of `rows x 2 rows` directions
//! about the world's `up` and turned into distant VALs, so it lights the sparse points through
//! the same gather and occlusion as every VAL, and the real receivers of the differential pass
//! through the same shadow rays.
//!
//! A cell of solid angle `Omega` around unit direction `w` becomes a disc VAL at
//! `centre + D w` facing the centre (`D` = [`ENVIRONMENT_DISTANCE`]), of area `a = D² Omega`
//! and flux `L Omega (pi D² + a)`: at the centre, `E = Phi cos_x / (pi D² + a) = L Omega
//! cos_x`, the cell's term of `E = integral L cos`. Points away from the centre see the VAL at
//! a relative distance error of `|x - centre| / D`.
//!
//! Sources (`settings.environment.source`):
//! - `none`: no environment;
//! - `map`: an equirectangular map (`.hdr` or `.exr`; top row toward `up`, the left edge at
//!   azimuth 0 about `up` from the world axis nearest perpendicular to it, azimuth growing
//!   counter-clockwise about `up`), each cell the mean of `SUBSAMPLES²` nearest-pixel samples,
//!   times `scale`, turned by `rotation_deg` about `up`;
//! - `auto`: one radiance in every cell that no real VAL's direction from the virtual content's
//!   centre falls in (filling only the cells the camera did not see keeps what it did see from
//!   counting twice). Its level is the frame's mean observed radiance (over pixels with valid
//!   depth), raised, when the differential pass has receivers, to the least level that lets
//!   the receivers' brightness be reflected light ([`explaining_level`]): a real surface
//!   reflects at most what it receives (albedo <= 1), so a desk brighter than the seen VALs can
//!   light it is lit from where the camera did not look, by at least that much. Both are
//!   estimates: the mean is the one figure the frame gives for the room as a whole; the
//!   receivers' level is a lower bound on the light the camera did not see.
//!
//! How `auto` spreads that level over the unseen cells (`settings.environment.distribution`):
//! - `uniform`: alike in every unseen direction;
//! - `overcast`: the CIE standard overcast sky (Moon and Spencer 1942; CIE S 011/E:2003 type
//!   1), `L(theta) = L_z (1 + 2 cos theta) / 3` at `theta` from up above the horizon, and the
//!   horizon's `L_z / 3` below it (a floor of albedo 0.3 under that sky would send `0.23 L_z`).
//!   Rooms are lit from above (ceiling lamps and the bright ceiling the camera rarely looks
//!   at); the CIE sky is the standard parameter-free model of light from above that is still
//!   diffuse, where a cosine-power lobe would need an exponent this recording cannot tell. The
//!   weights are scaled to a solid-angle mean of 1 over the sphere, so the level is still the
//!   environment's mean radiance. Up is the frame's own ([`estimate_up`]): the normal of the
//!   support plane among the differential receivers (the desk under the object), the
//!   configured `up` when there are no receivers or no such plane.

use super::differential::ReceiverGrid;
use crate::gpu::differential::Receiver;
use crate::twin::{Val, val_irradiance};
use glam::Vec3;
use std::f32::consts::PI;
use std::path::Path;

/// Distance (m) of the environment's VALs from the virtual content's centre.
pub const ENVIRONMENT_DISTANCE: f32 = 1000.0;
/// Map samples per cell and axis.
pub const SUBSAMPLES: u32 = 4;
/// Largest map side (pixels) read.
pub const MAX_MAP_SIDE: u32 = 8192;

pub use crate::scene::settings::{
    EnvironmentDistribution, EnvironmentSettings, EnvironmentSource, MAX_ENVIRONMENT_ROWS,
};

/// Errors reading a map.
#[derive(Debug, thiserror::Error)]
pub enum EnvironmentError {
    #[error("settings.environment.map: reading {path}: {message}")]
    Read { path: String, message: String },
    #[error("settings.environment.map: {path} is {width}x{height}; maps up to {MAX_MAP_SIDE} pixels a side are read")]
    TooLarge { path: String, width: u32, height: u32 },
    #[error("settings.environment.map: {path} is {width}x{height}, over the limit of {max_pixels} pixels")]
    TooManyPixels { path: String, width: u32, height: u32, max_pixels: u64 },
    #[error("settings.environment.map: source \"map\" needs a map path")]
    Missing,
}

/// An equirectangular map: linear RGB, rows from the top.
#[derive(Clone, Debug, PartialEq)]
pub struct EquirectMap {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<Vec3>,
}

impl EquirectMap {
    /// Read an `.hdr` or `.exr` file (any format the `image` crate decodes to float RGB).
    pub fn read(path: &Path) -> Result<Self, EnvironmentError> {
        Self::read_within(path, u64::MAX)
    }

    /// [`EquirectMap::read`] of a map of at most `max_pixels` pixels (and [`MAX_MAP_SIDE`] a
    /// side), checked on the file's header before anything is decoded.
    pub fn read_within(path: &Path, max_pixels: u64) -> Result<Self, EnvironmentError> {
        let err = |message: String| EnvironmentError::Read { path: path.display().to_string(), message };
        let reader = ::image::ImageReader::open(path).map_err(|e| err(e.to_string()))?;
        let reader = reader.with_guessed_format().map_err(|e| err(e.to_string()))?;
        let (width, height) = reader.into_dimensions().map_err(|e| err(e.to_string()))?;
        if width > MAX_MAP_SIDE || height > MAX_MAP_SIDE || width == 0 || height == 0 {
            return Err(EnvironmentError::TooLarge { path: path.display().to_string(), width, height });
        }
        if u64::from(width) * u64::from(height) > max_pixels {
            let path = path.display().to_string();
            return Err(EnvironmentError::TooManyPixels { path, width, height, max_pixels });
        }
        let image = ::image::open(path).map_err(|e| err(e.to_string()))?.into_rgb32f();
        let pixels = image.pixels().map(|p| Vec3::new(p[0], p[1], p[2]).max(Vec3::ZERO)).collect();
        Ok(Self { width, height, pixels })
    }

    /// The nearest pixel at map coordinates (`u`, `v`) in [0, 1) (u wraps).
    fn at(&self, u: f32, v: f32) -> Vec3 {
        let x = ((u.rem_euclid(1.0) * self.width as f32) as u32).min(self.width - 1);
        let y = ((v.clamp(0.0, 1.0) * self.height as f32) as u32).min(self.height - 1);
        self.pixels[(y * self.width + x) as usize]
    }
}

/// The direction grid: cell `(row, column)` spans polar angles `[row, row + 1] pi / rows` from
/// `up` and azimuths `[column, column + 1] pi / rows`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DirectionGrid {
    pub rows: u32,
    up: Vec3,
    east: Vec3,
    north: Vec3,
}

impl DirectionGrid {
    pub fn new(rows: u32, up: Vec3) -> Self {
        let up = up.try_normalize().unwrap_or(Vec3::Z);
        // The world axis least aligned with up, made perpendicular: azimuth 0.
        let axis = [Vec3::X, Vec3::Y, Vec3::Z].into_iter().min_by(|a, b| a.dot(up).abs().total_cmp(&b.dot(up).abs()));
        let east = (axis.unwrap_or(Vec3::X) - up * axis.unwrap_or(Vec3::X).dot(up)).normalize();
        Self { rows: rows.max(1), up, east, north: up.cross(east) }
    }

    /// The grid's pole (unit).
    pub fn up(&self) -> Vec3 {
        self.up
    }

    pub fn columns(&self) -> u32 {
        2 * self.rows
    }

    pub fn cells(&self) -> usize {
        (self.rows * self.columns()) as usize
    }

    /// Unit direction at polar angle `theta` from up and azimuth `phi`.
    pub fn direction(&self, theta: f32, phi: f32) -> Vec3 {
        self.up * theta.cos() + (self.east * phi.cos() + self.north * phi.sin()) * theta.sin()
    }

    /// Centre direction and solid angle (sr) of cell `i` (row-major).
    pub fn cell(&self, i: usize) -> (Vec3, f32) {
        let (row, column) = (i as u32 / self.columns(), i as u32 % self.columns());
        let step = PI / self.rows as f32;
        let (t0, t1) = (row as f32 * step, (row + 1) as f32 * step);
        let solid_angle = step * (t0.cos() - t1.cos());
        (self.direction((t0 + t1) * 0.5, (column as f32 + 0.5) * step), solid_angle)
    }

    /// The cell that unit direction `w` falls in.
    pub fn cell_of(&self, w: Vec3) -> usize {
        let theta = w.dot(self.up).clamp(-1.0, 1.0).acos();
        let phi = w.dot(self.north).atan2(w.dot(self.east)).rem_euclid(2.0 * PI);
        let step = PI / self.rows as f32;
        let row = ((theta / step) as u32).min(self.rows - 1);
        let column = ((phi / step) as u32).min(self.columns() - 1);
        (row * self.columns() + column) as usize
    }

    /// Radiance of each cell from `map` times `scale`, the map turned by `rotation` (radians)
    /// about up: the mean of `SUBSAMPLES²` samples spread evenly over the cell's angles.
    pub fn sample_map(&self, map: &EquirectMap, scale: f32, rotation: f32) -> Vec<Vec3> {
        let step = PI / self.rows as f32;
        (0..self.cells())
            .map(|i| {
                let (row, column) = (i as u32 / self.columns(), i as u32 % self.columns());
                let mut sum = Vec3::ZERO;
                for sy in 0..SUBSAMPLES {
                    for sx in 0..SUBSAMPLES {
                        let theta = (row as f32 + (sy as f32 + 0.5) / SUBSAMPLES as f32) * step;
                        let phi = (column as f32 + (sx as f32 + 0.5) / SUBSAMPLES as f32) * step;
                        sum += map.at((phi - rotation) / (2.0 * PI), theta / PI);
                    }
                }
                sum * scale / (SUBSAMPLES * SUBSAMPLES) as f32
            })
            .collect()
    }

    /// The `auto` estimate: `radiance` in every cell no direction from `centre` to a VAL of
    /// `vals` falls in, zero in the others.
    pub fn unseen(&self, centre: Vec3, vals: &[Val], radiance: Vec3) -> Vec<Vec3> {
        let mut seen = vec![false; self.cells()];
        for v in vals {
            if let Some(w) = (v.position - centre).try_normalize() {
                seen[self.cell_of(w)] = true;
            }
        }
        seen.iter().map(|&s| if s { Vec3::ZERO } else { radiance }).collect()
    }

    /// Relative radiance of each cell under `distribution` about unit `up` (which need not be
    /// the grid's pole), scaled so that its mean over the sphere, weighted by the cells' solid
    /// angles, is 1: `uniform` gives 1 in every cell.
    pub fn weights(&self, distribution: EnvironmentDistribution, up: Vec3) -> Vec<f32> {
        match distribution {
            EnvironmentDistribution::Uniform => vec![1.0; self.cells()],
            EnvironmentDistribution::Overcast => {
                let cells: Vec<(f32, f32)> = (0..self.cells())
                    .map(|i| {
                        let (w, solid_angle) = self.cell(i);
                        (overcast_radiance(w.dot(up)), solid_angle)
                    })
                    .collect();
                let sphere: f32 = cells.iter().map(|c| c.1).sum();
                let mean = cells.iter().map(|(l, o)| l * o).sum::<f32>() / sphere;
                cells.iter().map(|(l, _)| l / mean).collect()
            }
        }
    }

    /// Mean luminance of `radiance` (one value per cell) over the sphere, each cell weighted
    /// by its solid angle.
    pub fn mean_luminance(&self, radiance: &[Vec3]) -> f32 {
        let (sum, solid) = radiance.iter().enumerate().fold((0.0, 0.0), |(sum, solid), (i, r)| {
            let omega = self.cell(i).1;
            (sum + crate::twin::luminance(*r) * omega, solid + omega)
        });
        if solid > 0.0 { sum / solid } else { 0.0 }
    }

    /// Distant VALs around `centre` for cell radiances `radiance` (module docs); cells without
    /// light make none.
    pub fn vals(&self, centre: Vec3, radiance: &[Vec3]) -> Vec<Val> {
        let d = ENVIRONMENT_DISTANCE;
        radiance
            .iter()
            .enumerate()
            .filter(|(_, l)| l.max_element() > 0.0)
            .map(|(i, l)| {
                let (w, solid_angle) = self.cell(i);
                let area = d * d * solid_angle;
                Val { position: centre + w * d, normal: -w, area, flux: *l * solid_angle * (PI * d * d + area) }
            })
            .collect()
    }
}

/// The environment of a replay or of a scene's stream frames, ready to make VALs each frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum Environment {
    #[default]
    None,
    /// [`EnvironmentSource::Auto`] on this grid, spread by `distribution`, its level calibrated
    /// at the receivers' known `albedo` if given (else the least at albedo <= 1).
    Auto { grid: DirectionGrid, distribution: EnvironmentDistribution, albedo: Option<f32> },
    /// A map's radiance per cell of `grid`; with `calibrate`, scaled each frame to the receivers
    /// at that albedo (1: the least scale at albedo <= 1).
    Map { grid: DirectionGrid, radiance: Vec<Vec3>, calibrate: Option<f32> },
}

impl Environment {
    /// The environment `settings` ask for, its map read relative to `base_dir`.
    pub fn from_settings(settings: &EnvironmentSettings, base_dir: &Path) -> Result<Self, EnvironmentError> {
        Self::from_settings_within(settings, base_dir, u64::MAX)
    }

    /// [`Environment::from_settings`] with a map of at most `max_pixels` pixels
    /// ([`EquirectMap::read_within`]).
    pub fn from_settings_within(
        settings: &EnvironmentSettings,
        base_dir: &Path,
        max_pixels: u64,
    ) -> Result<Self, EnvironmentError> {
        let grid = DirectionGrid::new(settings.rows, Vec3::from(settings.up));
        Ok(match settings.source {
            EnvironmentSource::None => Environment::None,
            EnvironmentSource::Auto => {
                Environment::Auto { grid, distribution: settings.distribution, albedo: settings.albedo }
            }
            EnvironmentSource::Map => {
                let path = settings.map.as_ref().ok_or(EnvironmentError::Missing)?;
                let map = EquirectMap::read_within(&base_dir.join(path), max_pixels)?;
                let radiance = grid.sample_map(&map, settings.scale, settings.rotation_deg.to_radians());
                let calibrate = settings.calibrate_map.then_some(settings.albedo.unwrap_or(1.0));
                Environment::Map { grid, radiance, calibrate }
            }
        })
    }

    /// This frame's environment VALs around `centre` (the virtual content's), given the real
    /// VALs lighting it and, with the differential pass, its receivers (`auto` fills the cells
    /// the real VALs leave empty; module docs).
    pub fn vals(
        &self,
        centre: Vec3,
        frame: &crate::rgbd::RgbdFrame,
        settings: &crate::rgbd::RgbdSettings,
        real: &[Val],
        receivers: Option<&ReceiverGrid>,
    ) -> Vec<Val> {
        match self {
            Environment::None => Vec::new(),
            Environment::Auto { grid, distribution, albedo } => {
                let mean = mean_radiance(frame, settings);
                let estimate = auto_estimate(grid, *distribution, centre, real, receivers, mean, *albedo);
                let (level, up) = (estimate.level, estimate.up);
                tracing::debug!(%mean, %level, %up, ?distribution, "auto environment level");
                grid.vals(centre, &estimate.radiance)
            }
            Environment::Map { grid, radiance, calibrate: None } => grid.vals(centre, radiance),
            Environment::Map { grid, radiance, calibrate: Some(albedo) } => {
                calibrated_map_vals(grid, radiance, centre, real, receivers, *albedo)
            }
        }
    }
}

/// A map's VALs around `centre`, calibrated to `receivers`: the map at a mean radiance of 1
/// over the sphere (its own scale drops out), times the [`map_calibration`] level at which the
/// receivers reflect with `albedo`. Without receivers that can tell, the map at its own scale.
pub fn calibrated_map_vals(
    grid: &DirectionGrid,
    radiance: &[Vec3],
    centre: Vec3,
    real: &[Val],
    receivers: Option<&ReceiverGrid>,
    albedo: f32,
) -> Vec<Val> {
    let mean = grid.mean_luminance(radiance);
    if mean <= 0.0 {
        return grid.vals(centre, radiance);
    }
    let unit: Vec<Vec3> = radiance.iter().map(|r| *r / mean).collect();
    let mut vals = grid.vals(centre, &unit);
    match receivers.and_then(|r| map_calibration(r, real, &vals, albedo)) {
        Some(level) => {
            tracing::debug!(level, albedo, "environment map calibrated to the frame");
            // A cell's flux is linear in its radiance.
            vals.iter_mut().for_each(|v| v.flux *= level);
            vals
        }
        None => grid.vals(centre, radiance),
    }
}

/// The `auto` environment of one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct AutoEstimate {
    /// Radiance of each cell of the grid (W/(m² sr)): zero where a real VAL is seen.
    pub radiance: Vec<Vec3>,
    /// The level (W/(m² sr)): the environment's mean radiance over the whole sphere if no cell
    /// were seen.
    pub level: Vec3,
    /// The up its distribution was laid about (unit).
    pub up: Vec3,
}

/// The `auto` estimate (module docs): the unseen cells from `centre` given the `real` VALs,
/// weighted by `distribution` about the receivers' up ([`estimate_up`]; the grid's own
/// without receivers or a support plane), at the level `mean` raised to the
/// [`explaining_level`] of the weighted unit environment when there are receivers; or, with
/// the receivers' `albedo` known, at the [`calibrated_level`] for it (a measurement, not a
/// bound, so not raised to `mean`), `mean` where no receiver can tell.
pub fn auto_estimate(
    grid: &DirectionGrid,
    distribution: EnvironmentDistribution,
    centre: Vec3,
    real: &[Val],
    receivers: Option<&ReceiverGrid>,
    mean: Vec3,
    albedo: Option<f32>,
) -> AutoEstimate {
    let up = match (distribution, receivers) {
        (EnvironmentDistribution::Uniform, _) | (_, None) => grid.up(),
        (_, Some(r)) => estimate_up(&r.receivers, grid.up()).unwrap_or(grid.up()),
    };
    let weights = grid.weights(distribution, up);
    let unit: Vec<Vec3> = grid.unseen(centre, real, Vec3::ONE).iter().zip(&weights).map(|(u, w)| *u * *w).collect();
    let level = match (receivers, albedo) {
        (Some(r), Some(albedo)) => calibrated_level(r, real, &grid.vals(centre, &unit), albedo).unwrap_or(mean),
        (Some(r), None) => mean.max(explaining_level(r, real, &grid.vals(centre, &unit))),
        (None, _) => mean,
    };
    AutoEstimate { radiance: unit.iter().map(|u| *u * level).collect(), level, up }
}

/// The CIE standard overcast sky's radiance at `cos_theta` from the zenith, relative to the
/// zenith's: `(1 + 2 cos theta) / 3` above the horizon, the horizon's 1/3 below it.
pub fn overcast_radiance(cos_theta: f32) -> f32 {
    (1.0 + 2.0 * cos_theta.clamp(0.0, 1.0)) / 3.0
}

/// Receivers whose normals lie within this cosine of a candidate's support its plane (10°:
/// the RGB-D normals of a desk scatter by a few degrees).
pub const UP_INLIER_COSINE: f32 = 0.984_807_8;
/// A support plane must face within this cosine of the configured up (45°): the frame refines
/// which way is up, it does not overturn it.
pub const UP_MAX_TILT_COSINE: f32 = std::f32::consts::FRAC_1_SQRT_2;
/// ... and hold at least this share of the receivers.
pub const UP_MIN_SUPPORT: f32 = 0.2;
/// Receivers [`estimate_up`] tries as candidates, and counts support among, at most (evenly
/// strided).
pub const UP_CANDIDATES: usize = 256;
pub const UP_SAMPLES: usize = 4096;

/// The frame's up: the normal of the support plane among `receivers`, the near-horizontal
/// surface (within 45° of `up`, the configured one) whose normal most receivers share
/// (within 10°), as the mean of those receivers' normals. `None` when no candidate is
/// shared by [`UP_MIN_SUPPORT`] of the receivers (a cluttered or wall-only view).
pub fn estimate_up(receivers: &[Receiver], up: Vec3) -> Option<Vec3> {
    let up = up.try_normalize()?;
    let stride = |cap: usize| receivers.len().div_ceil(cap).max(1);
    let samples: Vec<Vec3> = receivers.iter().step_by(stride(UP_SAMPLES)).map(|r| r.normal).collect();
    let support = |c: Vec3| samples.iter().filter(|n| n.dot(c) >= UP_INLIER_COSINE).count();
    let (best, count) = receivers
        .iter()
        .step_by(stride(UP_CANDIDATES))
        .map(|r| r.normal)
        .filter(|n| n.dot(up) >= UP_MAX_TILT_COSINE)
        .map(|n| (n, support(n)))
        .max_by_key(|c| c.1)?;
    if (count as f32) < UP_MIN_SUPPORT * samples.len() as f32 {
        return None;
    }
    let sum: Vec3 = samples.iter().filter(|n| n.dot(best) >= UP_INLIER_COSINE).sum();
    sum.try_normalize().filter(|n| n.dot(up) >= UP_MAX_TILT_COSINE)
}

/// Receivers [`explaining_level`] looks at, at most (evenly strided): the median needs few, and
/// each costs a sum over every real VAL.
pub const CALIBRATION_RECEIVERS: usize = 256;

/// A receiver's unit environment (`unit`'s VALs: radiance 1 in the unseen cells) must give it
/// at least this irradiance (W/m², out of pi for a whole unseen hemisphere) to take part:
/// where almost nothing is unseen, the level it would ask for is noise.
pub const MIN_UNSEEN_IRRADIANCE: f32 = 0.05 * PI;

/// The least environment radiance (per channel, W/(m² sr)) that lets the receivers' camera
/// radiance be reflected light: at a receiver of radiance `L`, seen-VAL irradiance `E_seen`
/// (no visibility, as the differential pass's `unoccluded`) and unit-environment irradiance
/// `E_unit`, albedo <= 1 needs `pi L <= E_seen + level E_unit`, so `level >= (pi L - E_seen) /
/// E_unit`. The median over the receivers (at most [`CALIBRATION_RECEIVERS`], those with
/// `E_unit >= MIN_UNSEEN_IRRADIANCE`), so that a few specular highlights or mis-placed
/// receivers do not set it; zero without receivers.
pub fn explaining_level(receivers: &ReceiverGrid, real: &[Val], unit: &[Val]) -> Vec3 {
    calibrated_level(receivers, real, unit, 1.0).unwrap_or(Vec3::ZERO)
}

/// The environment level (per channel) at which the receivers reflect with `albedo`:
/// `pi L = albedo (E_seen + level E_unit)`, so `level = (pi L / albedo - E_seen) / E_unit`
/// (at least 0), the median over the receivers as in [`explaining_level`] (which is this at
/// albedo 1: the least level any albedo allows). `None` when no receiver takes part.
pub fn calibrated_level(receivers: &ReceiverGrid, real: &[Val], unit: &[Val], albedo: f32) -> Option<Vec3> {
    use rayon::prelude::*;
    let n = receivers.receivers.len();
    let stride = n.div_ceil(CALIBRATION_RECEIVERS).max(1);
    // Each receiver's level on its own, over the cores.
    let levels: Vec<Option<Vec3>> = (0..n)
        .into_par_iter()
        .step_by(stride)
        .map(|i| {
            let (r, l) = (&receivers.receivers[i], receivers.radiance[i]);
            let irradiance =
                |vals: &[Val]| -> Vec3 { vals.iter().map(|v| val_irradiance(r.position, r.normal, v)).sum() };
            let e_unit = irradiance(unit);
            (e_unit.min_element() >= MIN_UNSEEN_IRRADIANCE)
                .then(|| ((PI * l / albedo - irradiance(real)) / e_unit).max(Vec3::ZERO))
        })
        .collect();
    let mut needed: [Vec<f32>; 3] = Default::default();
    for level in levels.into_iter().flatten() {
        for (c, values) in needed.iter_mut().enumerate() {
            values.push(level[c]);
        }
    }
    if needed[0].is_empty() {
        return None;
    }
    let median = |values: &mut Vec<f32>| {
        let mid = values.len() / 2;
        *values.select_nth_unstable_by(mid, f32::total_cmp).1
    };
    Some(Vec3::new(median(&mut needed[0]), median(&mut needed[1]), median(&mut needed[2])))
}

/// The factor a map's VALs (`map`, at the map's own scale) need for the receivers to reflect
/// with `albedo`: [`calibrated_level`] with the map as the unit environment, one factor for
/// all channels (their luminance-weighted mean) so the map keeps its colour. `None` when no
/// receiver can tell or the factor is not positive.
pub fn map_calibration(receivers: &ReceiverGrid, real: &[Val], map: &[Val], albedo: f32) -> Option<f32> {
    let level = calibrated_level(receivers, real, map, albedo)?;
    let factor = crate::twin::luminance(level);
    (factor.is_finite() && factor > 0.0).then_some(factor)
}

/// Mean observed radiance of `frame` (W/(m² sr)): `radiance_scale * srgb_to_linear(rgb)` over
/// its pixels with valid depth (all pixels when none has).
pub fn mean_radiance(frame: &crate::rgbd::RgbdFrame, settings: &crate::rgbd::RgbdSettings) -> Vec3 {
    let linear = |c: &[u8; 3]| crate::twin::rgbd::srgb8_to_linear(*c);
    let (mut sum, mut n) = (Vec3::ZERO, 0usize);
    for (c, z) in frame.color.iter().zip(&frame.depth) {
        if crate::twin::rgbd::valid_depth(*z, settings) {
            sum += linear(c);
            n += 1;
        }
    }
    if n == 0 {
        sum = frame.color.iter().map(linear).sum();
        n = frame.color.len();
    }
    settings.radiance_scale * sum / n.max(1) as f32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::twin::val_irradiance;

    fn irradiance(vals: &[Val], x: Vec3, n: Vec3) -> Vec3 {
        vals.iter().map(|v| val_irradiance(x, n, v)).sum()
    }

    /// White furnace on the CPU: a uniform environment of radiance L gives irradiance pi L at
    /// the centre for every normal, within the grid's quadrature error (the cell-centre rule:
    /// measured 1.53 % at worst over these normals at 8 rows; bounds 2 % and 0.6 %).
    #[test]
    fn uniform_environment_gives_pi_l() {
        for (rows, tolerance) in [(8, 0.02), (16, 0.006)] {
            let grid = DirectionGrid::new(rows, Vec3::Z);
            let vals = grid.vals(Vec3::ZERO, &vec![Vec3::splat(2.0); grid.cells()]);
            let mut worst = 0.0f32;
            for i in 0..200 {
                // Normals spread over the sphere (a Fibonacci lattice).
                let z = 1.0 - 2.0 * (i as f32 + 0.5) / 200.0;
                let phi = i as f32 * 2.399_963;
                let n = Vec3::new((1.0 - z * z).sqrt() * phi.cos(), (1.0 - z * z).sqrt() * phi.sin(), z);
                let e = irradiance(&vals, Vec3::ZERO, n);
                worst = worst.max((e.x / (2.0 * PI) - 1.0).abs());
            }
            eprintln!("{rows} rows: worst relative error {worst:.5}");
            assert!(worst < tolerance, "{rows} rows: {worst}");
        }
    }

    /// The level that explains a receiver's radiance: under a whole unseen sky (`E_unit` = pi
    /// within the 8-row grid's 2 %), a receiver of radiance `L` lit by nothing seen needs `L`
    /// (albedo 1); a seen VAL's irradiance lowers it by `E_seen / E_unit`; a receiver that the
    /// unseen cells barely reach takes no part, and the median ignores one outlier of three.
    #[test]
    fn explaining_level_is_the_least_that_keeps_albedo_at_most_one() {
        use crate::gpu::differential::Receiver;
        let grid = DirectionGrid::new(8, Vec3::Z);
        let unit = grid.vals(Vec3::ZERO, &grid.unseen(Vec3::ZERO, &[], Vec3::ONE));
        let up = Receiver { position: Vec3::ZERO, normal: Vec3::Z };
        let receivers =
            |radiance: Vec<Vec3>| ReceiverGrid { receivers: vec![up; radiance.len()], radiance, ..Default::default() };
        let l = Vec3::new(2.0, 1.0, 0.5);
        let level = explaining_level(&receivers(vec![l]), &[], &unit);
        assert!((level / l - 1.0).abs().max_element() < 0.02, "{level}");

        let lamp = Val { position: Vec3::new(0.0, 0.0, 2.0), normal: -Vec3::Z, area: 0.01, flux: Vec3::splat(30.0) };
        let e_seen = val_irradiance(Vec3::ZERO, Vec3::Z, &lamp);
        let e_unit = irradiance(&unit, Vec3::ZERO, Vec3::Z);
        let want = ((PI * l - e_seen) / e_unit).max(Vec3::ZERO);
        let level = explaining_level(&receivers(vec![l]), &[lamp], &unit);
        assert!((level - want).abs().max_element() < 1e-5, "{level} vs {want}");
        assert!(want.z == 0.0 && want.x > 0.0, "the lamp explains the blue channel alone: {want}");

        let bright = Vec3::splat(100.0);
        let level = explaining_level(&receivers(vec![l, bright, l]), &[], &unit);
        assert!((level / l - 1.0).abs().max_element() < 0.02, "the median: {level}");
        // Only the sky below the horizon is unseen: a receiver facing up gets none of it.
        let below: Vec<Vec3> =
            (0..grid.cells()).map(|i| if grid.cell(i).0.z < 0.0 { Vec3::ONE } else { Vec3::ZERO }).collect();
        let level = explaining_level(&receivers(vec![l]), &[], &grid.vals(Vec3::ZERO, &below));
        assert_eq!(level, Vec3::ZERO);
    }

    /// A known albedo calibrates the level: receivers lit by a lamp and an unseen sky at level
    /// 2, reflecting with albedo 0.5, give back 2 at albedo 0.5 (where the least level at albedo
    /// <= 1 is lower), and the map calibration recovers the same sky from a map in other units.
    #[test]
    fn a_known_albedo_calibrates_the_level_and_the_map() {
        use crate::gpu::differential::Receiver;
        let grid = DirectionGrid::new(8, Vec3::Z);
        let lamp = Val { position: Vec3::new(0.3, 0.0, 2.0), normal: -Vec3::Z, area: 0.01, flux: Vec3::splat(20.0) };
        let unit = grid.vals(Vec3::ZERO, &grid.unseen(Vec3::ZERO, &[lamp], Vec3::ONE));
        let (albedo, level) = (0.5, 2.0);
        let normals = [Vec3::Z, Vec3::new(0.5, 0.0, 0.866), Vec3::new(0.0, -0.6, 0.8)];
        let receivers: Vec<Receiver> =
            normals.iter().map(|&normal| Receiver { position: Vec3::ZERO, normal }).collect();
        let radiance: Vec<Vec3> = receivers
            .iter()
            .map(|r| {
                let e = val_irradiance(r.position, r.normal, &lamp) + level * irradiance(&unit, r.position, r.normal);
                albedo * e / PI
            })
            .collect();
        let grid_of = ReceiverGrid { receivers, radiance, ..Default::default() };
        let got = calibrated_level(&grid_of, &[lamp], &unit, albedo).unwrap();
        assert!((got - Vec3::splat(level)).abs().max_element() < 1e-3, "{got}");
        let least = explaining_level(&grid_of, &[lamp], &unit);
        assert!(least.x < 0.5 * level, "albedo <= 1 allows a lower level: {least}");
        assert_eq!(calibrated_level(&ReceiverGrid::default(), &[lamp], &unit, albedo), None);

        // The same sky as a map of radiance 1000 (a probe in other units), calibrated in vals().
        let map = grid.unseen(Vec3::ZERO, &[lamp], Vec3::splat(1000.0));
        let vals = calibrated_map_vals(&grid, &map, Vec3::ZERO, &[lamp], Some(&grid_of), albedo);
        for r in &grid_of.receivers {
            let want = level * irradiance(&unit, r.position, r.normal);
            let got = irradiance(&vals, r.position, r.normal);
            assert!((got - want).abs().max_element() < 1e-3 * want.max_element(), "{got} vs {want}");
        }
        // Without receivers the map keeps its own scale.
        let vals = calibrated_map_vals(&grid, &map, Vec3::ZERO, &[lamp], None, albedo);
        let own = irradiance(&grid.vals(Vec3::ZERO, &map), Vec3::ZERO, Vec3::Z);
        assert_eq!(irradiance(&vals, Vec3::ZERO, Vec3::Z), own);
    }

    /// A map whose columns are shifted by a quarter of its width is the map turned by 90
    /// degrees about up: irradiance at a normal under it equals irradiance at that normal turned
    /// back under the original.
    #[test]
    fn turned_map_turns_the_light() {
        let (w, h) = (64u32, 32u32);
        // One bright patch above the horizon at azimuth ~45 degrees, a dim sky elsewhere.
        let pixels: Vec<Vec3> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                if (4..12).contains(&x) && (6..12).contains(&y) {
                    Vec3::new(50.0, 40.0, 30.0)
                } else {
                    Vec3::splat(0.5)
                }
            })
            .collect();
        let map = EquirectMap { width: w, height: h, pixels: pixels.clone() };
        let turned = EquirectMap {
            width: w,
            height: h,
            pixels: (0..w * h).map(|i| pixels[((i / w) * w + (i % w + w - w / 4) % w) as usize]).collect(),
        };
        let grid = DirectionGrid::new(8, Vec3::Z);
        let a = grid.vals(Vec3::ZERO, &grid.sample_map(&map, 1.0, 0.0));
        let b = grid.vals(Vec3::ZERO, &grid.sample_map(&turned, 1.0, 0.0));
        let c = grid.vals(Vec3::ZERO, &grid.sample_map(&map, 1.0, PI / 2.0));
        let turn = glam::Quat::from_rotation_z(PI / 2.0);
        let toward = grid.direction(1.0, PI / 4.0);
        for n in [toward, Vec3::X, Vec3::Y, -Vec3::X, Vec3::new(1.0, 1.0, 0.5).normalize()] {
            let (ea, eb, ec) = (
                irradiance(&a, Vec3::ZERO, n),
                irradiance(&b, Vec3::ZERO, turn * n),
                irradiance(&c, Vec3::ZERO, turn * n),
            );
            assert!((ea - eb).abs().max_element() <= 1e-4 * ea.max_element(), "{n}: {ea} vs turned map {eb}");
            assert!((ea - ec).abs().max_element() <= 1e-4 * ea.max_element(), "{n}: {ea} vs rotation_deg 90 {ec}");
        }
        // And the light did move: the patch faces `toward`, not its turned direction.
        let (here, turned_away) = (irradiance(&a, Vec3::ZERO, toward), irradiance(&a, Vec3::ZERO, turn * toward));
        assert!(here.x > 2.0 * turned_away.x, "{here} vs {turned_away}");
    }

    /// The overcast weights: above brighter than below, the zenith three times the horizon,
    /// a solid-angle mean of 1 over the sphere (so `auto`'s level keeps its meaning), the
    /// furnace property that `uniform` is 1 everywhere (the environment as before), and the
    /// weights follow the `up` they are given, not the grid's pole.
    #[test]
    fn overcast_weights_light_from_above() {
        let grid = DirectionGrid::new(8, Vec3::Z);
        assert_eq!(grid.weights(EnvironmentDistribution::Uniform, Vec3::Z), vec![1.0; grid.cells()]);
        let w = grid.weights(EnvironmentDistribution::Overcast, Vec3::Z);
        let mean = (0..grid.cells()).map(|i| w[i] * grid.cell(i).1).sum::<f32>() / (4.0 * PI);
        assert!((mean - 1.0).abs() < 1e-4, "solid-angle mean {mean}");
        for i in 0..grid.cells() {
            let (d, _) = grid.cell(i);
            let want = overcast_radiance(d.z) / overcast_radiance(grid.cell(0).0.z);
            assert!((w[i] / w[0] - want).abs() < 1e-5, "cell {i}: {} vs {want}", w[i] / w[0]);
            // A cell above the horizon outshines its mirror image below it.
            let below = grid.cell_of(Vec3::new(d.x, d.y, -d.z));
            if d.z > 0.0 {
                assert!(w[i] > w[below], "cell {i} ({d}) {} vs below {}", w[i], w[below]);
            }
        }
        assert_eq!(overcast_radiance(1.0), 1.0);
        assert_eq!(overcast_radiance(0.0), 1.0 / 3.0);
        assert_eq!(overcast_radiance(-0.7), 1.0 / 3.0);
        // About a tilted up: the brightest cell is the one nearest it.
        let tilted = Vec3::new(0.6, 0.0, 0.8);
        let w = grid.weights(EnvironmentDistribution::Overcast, tilted);
        let brightest = (0..grid.cells()).max_by(|a, b| w[*a].total_cmp(&w[*b])).unwrap();
        let nearest =
            (0..grid.cells()).max_by(|a, b| grid.cell(*a).0.dot(tilted).total_cmp(&grid.cell(*b).0.dot(tilted)));
        assert_eq!(Some(brightest), nearest);
    }

    /// Receivers on a desk tilted 12° (normals scattered by up to ~4°), beside a wall and a
    /// mug's side that together outnumber it, give the desk's normal within 1°; a view of walls
    /// alone, or a desk that holds too few receivers, gives none.
    #[test]
    fn estimate_up_finds_the_support_plane() {
        let desk = Vec3::new(12f32.to_radians().sin(), 0.0, 12f32.to_radians().cos());
        let jitter = |i: usize, n: Vec3| {
            let (a, b) = ((i as f32 * 0.618).fract() - 0.5, (i as f32 * 0.414).fract() - 0.5);
            (n + Vec3::new(a, b, 0.0) * 0.14).normalize()
        };
        let at = |n: Vec3, i: usize| Receiver { position: Vec3::new(i as f32 * 0.01, 0.0, 0.0), normal: jitter(i, n) };
        let mut receivers: Vec<Receiver> = (0..400).map(|i| at(desk, i)).collect();
        receivers.extend((0..300).map(|i| at(Vec3::Y, i)));
        receivers.extend((0..300).map(|i| at(Vec3::new(-0.7, 0.7, 0.1).normalize(), i)));
        let up = estimate_up(&receivers, Vec3::Z).expect("the desk");
        let error = up.dot(desk).clamp(-1.0, 1.0).acos().to_degrees();
        assert!(error < 1.0, "{up} vs {desk}: {error}°");
        let walls: Vec<Receiver> = receivers[400..].to_vec();
        assert_eq!(estimate_up(&walls, Vec3::Z), None);
        let few: Vec<Receiver> = receivers[300..].to_vec(); // 100 desk receivers of 700
        assert_eq!(estimate_up(&few, Vec3::Z), None);
        assert_eq!(estimate_up(&[], Vec3::Z), None);
    }

    /// `explaining_level` with the overcast unit: the least level that keeps every channel's
    /// albedo at most 1 (`pi L = E_seen + level E_unit` at the median receiver), for receivers
    /// facing up and tilted ones; a level any lower leaves the receiver brighter than a white
    /// surface could be. Overhead weights light an upward receiver more per unit level than
    /// uniform ones do, so it needs a lower level.
    #[test]
    fn overcast_explaining_level_keeps_albedo_at_most_one() {
        use crate::gpu::differential::Receiver;
        let grid = DirectionGrid::new(8, Vec3::Z);
        let lamp = Val { position: Vec3::new(0.3, 0.0, 2.0), normal: -Vec3::Z, area: 0.01, flux: Vec3::splat(20.0) };
        let l = Vec3::new(2.0, 1.5, 1.0);
        for normal in [Vec3::Z, Vec3::new(0.5, 0.0, 0.866)] {
            let r = Receiver { position: Vec3::ZERO, normal };
            let receivers = ReceiverGrid { receivers: vec![r], radiance: vec![l], ..Default::default() };
            let levels = [EnvironmentDistribution::Uniform, EnvironmentDistribution::Overcast].map(|d| {
                let w = grid.weights(d, Vec3::Z);
                let unit: Vec<Vec3> =
                    grid.unseen(Vec3::ZERO, &[lamp], Vec3::ONE).iter().zip(&w).map(|(u, w)| *u * *w).collect();
                let unit = grid.vals(Vec3::ZERO, &unit);
                let level = explaining_level(&receivers, &[lamp], &unit);
                let e = |level: Vec3| {
                    val_irradiance(r.position, r.normal, &lamp) + level * irradiance(&unit, r.position, r.normal)
                };
                let albedo = PI * l / e(level);
                assert!(albedo.max_element() <= 1.0 + 1e-4, "{d:?} {normal}: albedo {albedo}");
                assert!(albedo.min_element() >= 1.0 - 1e-4, "{d:?} {normal}: not the least level: {albedo}");
                assert!((PI * l / e(level * 0.95)).max_element() > 1.0);
                level
            });
            assert!(levels[1].x < levels[0].x, "{normal}: overcast {} vs uniform {}", levels[1], levels[0]);
        }
    }

    /// `auto_estimate` lays the overcast sky about the receivers' own up and falls back to the
    /// grid's without receivers; `uniform` ignores the receivers' up.
    #[test]
    fn auto_estimate_uses_the_receivers_up() {
        use crate::gpu::differential::Receiver;
        let grid = DirectionGrid::new(8, Vec3::Z);
        let desk = Vec3::new(0.2, 0.0, 0.98).normalize();
        let receivers = ReceiverGrid {
            receivers: vec![Receiver { position: Vec3::ZERO, normal: desk }; 10],
            radiance: vec![Vec3::ONE; 10],
            ..Default::default()
        };
        let mean = Vec3::splat(0.1);
        let e = auto_estimate(&grid, EnvironmentDistribution::Overcast, Vec3::ZERO, &[], Some(&receivers), mean, None);
        assert!((e.up - desk).length() < 1e-5, "{}", e.up);
        assert!(e.level.x > mean.x, "the receivers raise the level: {}", e.level);
        let e = auto_estimate(&grid, EnvironmentDistribution::Overcast, Vec3::ZERO, &[], None, mean, None);
        assert_eq!((e.up, e.level), (Vec3::Z, mean));
        let e = auto_estimate(&grid, EnvironmentDistribution::Uniform, Vec3::ZERO, &[], Some(&receivers), mean, None);
        assert_eq!(e.up, Vec3::Z);
        assert!(e.radiance.iter().all(|r| *r == e.level));
    }

    /// `auto` fills exactly the cells no VAL direction falls in.
    #[test]
    fn auto_fills_the_unseen_cells() {
        let grid = DirectionGrid::new(4, Vec3::Z);
        let below = Val { position: Vec3::new(0.1, 0.1, -1.0), normal: Vec3::Z, area: 0.01, flux: Vec3::ONE };
        let cells = grid.unseen(Vec3::ZERO, &[below], Vec3::ONE);
        let seen = grid.cell_of((below.position).normalize());
        assert_eq!(cells.iter().filter(|c| **c == Vec3::ZERO).count(), 1);
        assert_eq!(cells[seen], Vec3::ZERO);
    }
}

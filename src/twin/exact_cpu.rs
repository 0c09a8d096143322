//! The exact-visibility reference on the CPU (docs/design.md §5): the same physics as
//! `shaders/exact.wgsl` (every VAL at every receiver, the disc form factor and Phong of
//! [`val_radiance_sided`], one shadow ray per receiver-VAL pair from `p + n_g RAY_OFFSET`, `n_g`
//! the receiver's geometric normal, to `l + n_l RAY_OFFSET`), over rayon's threads, through [`TraceBvh`] (obvhs's CWBVH): each
//! receiver's shadow rays go to the VALs in Morton order, as packets or one by one
//! ([`ShadowTraversal`], chosen per frame by timing both on a few pixels: the image is the same
//! either way). For CPU adapters and CI, where the GPU pass runs on lavapipe.
//!
//! Beyond the GPU pass it can estimate instead of sum ([`ValSampling::Importance`]: VALs drawn
//! per receiver in proportion to their unoccluded contribution, an unbiased estimate) and
//! average over the pixel's area ([`PixelSampling`]), and it reports each pixel's noise: the
//! variance of its estimate, from two independent halves of the estimate.
//!
//! Receivers come either from the GPU's visibility buffer ([`Receivers::Hits`]: exactly the
//! pixels the GPU methods shade) or from primary rays through the same BVH
//! ([`Receivers::Traced`]): through the pixel centre, the rasteriser's sample position, at one
//! sample per pixel; at uniformly random positions inside the pixel (a jittered box filter)
//! otherwise.

use super::bvh::{ShadowTraversal, TraceBvh};
use super::{Material, Val, luminance, pcg_hash, val_radiance_sided, view_direction};
use crate::image::LinearImage;
use glam::{Mat4, Vec3, Vec4};
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

/// Distance (m) receivers and VALs are pushed along their normals before a shadow ray is cast
/// between them (the GPU passes' `RAY_OFFSET`, which the shader prelude takes from here).
pub const RAY_OFFSET: f32 = 1e-3;

/// The CPU reference's stage name in a frame's timings (BVH build and tracing).
pub const STAGE: &str = "exact_cpu";

/// Sub-pixel samples per pixel at most (`--spp`): receivers are made per pixel as it is shaded,
/// so memory does not grow with it, but time does, linearly.
pub const MAX_SPP: u32 = 256;
/// VALs drawn per receiver at most (`--reference-samples`); memory per thread is one cumulative
/// distribution over the VALs whatever the count.
pub const MAX_VAL_SAMPLES: u32 = 1 << 20;

/// A point that receives indirect light: position (m), unit shading normal, unit geometric
/// normal (its triangle's, on the shading normal's side; both facing the eye), material and the
/// unit direction toward the eye.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Receiver {
    pub position: Vec3,
    pub normal: Vec3,
    pub geometric: Vec3,
    pub surface: Material,
    pub view: Vec3,
}

impl Receiver {
    /// A receiver on a flat surface (shading normal = geometric normal), seen from `eye`.
    pub fn new(position: Vec3, normal: Vec3, surface: Material, eye: Vec3) -> Self {
        Self::sided(position, normal, normal, surface, eye)
    }

    /// A receiver with shading normal `normal` and geometric normal `geometric`, both turned to
    /// face `eye` ([`super::facing_viewer`]).
    pub fn sided(position: Vec3, normal: Vec3, geometric: Vec3, surface: Material, eye: Vec3) -> Self {
        let (normal, geometric) = super::facing_viewer(position, normal, geometric, eye);
        Self { position, normal, geometric, surface, view: view_direction(position, normal, eye) }
    }
}

/// Where each pixel's receivers come from.
pub enum Receivers<'a> {
    /// One receiver per pixel, given (row-major from the top; `None` = background): the GPU
    /// visibility buffer's hits, resolved with `FlatScene::surface_at`.
    Hits(&'a [Option<Receiver>]),
    /// Primary rays through `camera`, traced in the BVH and resolved by `surface`.
    Traced { camera: &'a CameraRays, sampling: PixelSampling, surface: &'a SurfaceFn<'a> },
}

/// The receiver at barycentrics `b` of a scene triangle (e.g. `FlatScene::surface_at` with the
/// eye).
pub type SurfaceFn<'a> = dyn Fn(u32, glam::Vec2) -> Receiver + Sync + 'a;

/// Sample positions inside each pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelSampling {
    /// Samples per pixel, 1..=[`MAX_SPP`]; 1 samples the pixel centre.
    pub spp: u32,
    /// Seed of the positions (with more than one sample).
    pub seed: u64,
}

/// Which VALs a receiver sums.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ValSampling {
    /// Every VAL: the exact sum.
    All,
    /// Every n-th VAL in list order, flux x n (the GPU pass's `VAL_STRIDE`): a deterministic
    /// subsample whose error is not estimated.
    Stride(u32),
    /// `samples` VALs (2..=[`MAX_VAL_SAMPLES`]) drawn with replacement per receiver, with
    /// probability proportional to the luminance of their unoccluded contribution (the brute
    /// force's own term); each draw weighted by 1 / probability, so the estimate is unbiased.
    Importance { samples: u32, seed: u64 },
    /// `samples` VALs (1..) drawn systematically per receiver, in list order, with probability
    /// proportional to the luminance of their unoccluded contribution: the thresholds
    /// `(m + xi) total / samples` of the running sum, `xi` = [`pixel_offset`] (the GPU
    /// estimator's draws, `gpu/references/estimator.wgsl`, in f32 as it adds them). Unbiased; its
    /// noise is not estimated.
    Systematic { samples: u32, seed: u32 },
}

/// Pixel `pixel`'s offset `xi` in [0, 1) of the systematic draws with `seed` (24 bits), as
/// `estimator.wgsl`'s `pixel_offset`.
pub fn pixel_offset(pixel: u32, seed: u32) -> f32 {
    super::unit_float(pcg_hash(pixel ^ pcg_hash(seed)))
}

/// Thresholds `(m + xi) step`, `m < samples`, below `sum` (`estimator.wgsl`'s).
fn thresholds_below(sum: f32, step: f32, xi: f32, samples: u32) -> u32 {
    (sum / step - xi).ceil().clamp(0.0, samples as f32) as u32
}

/// A camera as rays: world-to-clip (wgpu's clip space, z in [0, 1]) inverted.
#[derive(Clone, Copy, Debug)]
pub struct CameraRays {
    pub width: u32,
    pub height: u32,
    clip_to_world: Mat4,
}

impl CameraRays {
    pub fn new(world_to_clip: Mat4, width: u32, height: u32) -> Self {
        Self { width, height, clip_to_world: world_to_clip.inverse() }
    }

    /// The ray through image position (`x`, `y`) in pixels from the top left (pixel `i`'s centre
    /// is `i + 0.5`, as the rasteriser samples): origin on the near plane, unit direction.
    pub fn ray(&self, x: f32, y: f32) -> (Vec3, Vec3) {
        let ndc_x = 2.0 * x / self.width as f32 - 1.0;
        let ndc_y = 1.0 - 2.0 * y / self.height as f32;
        let at = |z: f32| {
            let p = self.clip_to_world * Vec4::new(ndc_x, ndc_y, z, 1.0);
            p.truncate() / p.w
        };
        let (near, far) = (at(0.0), at(0.5));
        (near, (far - near).normalize())
    }
}

/// The reference image and what it cost.
pub struct ExactImage {
    /// Radiance (W/(m² sr)); alpha is the fraction of the pixel's samples that hit geometry.
    pub image: LinearImage,
    /// Per pixel and channel, the variance of the pixel's estimate ((W/(m² sr))²): zero for the
    /// exact sum at the pixel centre, `None` for a stride (not estimated).
    pub variance: Option<Vec<Vec3>>,
    /// Shadow rays cast (receiver-VAL pairs with a non-zero unoccluded contribution).
    pub shadow_rays: u64,
    /// How the shadow rays were traced (the image does not depend on it).
    pub traversal: ShadowTraversal,
}

/// Everything one reference frame needs besides the receivers.
pub struct ExactScene<'a> {
    pub bvh: &'a TraceBvh,
    pub vals: &'a [Val],
    pub glossy: bool,
    /// Shadow rays ignore blockers nearer the receiver than this (m): 0 in every reference. An
    /// analysis of which occluders an approximate visibility misses (`examples/exact_split.rs`):
    /// what the image loses where only blockers this close to the receiver are left out.
    pub blockers_from: f32,
}

/// Frames of at least this many pixels choose their shadow-ray traversal by timing both on
/// [`PILOT_PIXELS`] of their pixels first (smaller ones take packets): which is faster depends
/// on the scene (see [`ShadowTraversal`]), and both give the same image.
pub const PILOT_MIN_PIXELS: usize = 4096;
/// Pixels, spread evenly over the frame, that the pilot traces once with each traversal.
pub const PILOT_PIXELS: usize = 64;

/// Render the exact-visibility reference: `width` x `height` pixels from `receivers`, each
/// summing (or estimating, per `vals`) the visible VALs' [`val_radiance_sided`], with the faster
/// shadow-ray traversal for the scene (a pilot on a few pixels times both).
pub fn render(scene: &ExactScene, receivers: &Receivers, width: u32, height: u32, sampling: ValSampling) -> ExactImage {
    render_with(scene, receivers, width, height, sampling, None)
}

/// [`render`] with the shadow-ray traversal given (`None`: chosen by the pilot).
pub fn render_with(
    scene: &ExactScene,
    receivers: &Receivers,
    width: u32,
    height: u32,
    sampling: ValSampling,
    traversal: Option<ShadowTraversal>,
) -> ExactImage {
    let pixels = (width as usize) * (height as usize);
    let (vals, scale) = summed_vals(scene.vals, sampling);
    let targets: Vec<Vec3> = vals.iter().map(|v| v.position + v.normal * RAY_OFFSET).collect();
    let frame = Frame {
        bvh: scene.bvh,
        vals: &vals,
        targets: &targets,
        scale,
        glossy: scene.glossy,
        receivers,
        width,
        sampling,
        blockers_from: scene.blockers_from,
    };
    let traversal = traversal.unwrap_or_else(|| frame.pilot(pixels));
    let results: Vec<(Pixel, u64)> =
        (0..pixels).into_par_iter().map_init(Workspace::default, |ws, i| frame.pixel(i, traversal, ws)).collect();
    let deterministic = matches!(sampling, ValSampling::Stride(_) | ValSampling::Systematic { .. });
    let image = LinearImage { width, height, pixels: results.iter().map(|(p, _)| p.rgba).collect() };
    let variance = (!deterministic).then(|| results.iter().map(|(p, _)| p.variance).collect());
    ExactImage { image, variance, shadow_rays: results.iter().map(|(_, r)| r).sum(), traversal }
}

/// The VALs a receiver sums (a stride's subsample, taken in list order as the GPU pass takes
/// it) sorted along a Morton curve over their bounding box, so that a receiver's consecutive
/// shadow rays go to neighbouring VALs (what [`TraceBvh::shadow_rays`] gains from), and the
/// flux scale of each (the stride).
fn summed_vals(vals: &[Val], sampling: ValSampling) -> (Vec<Val>, f32) {
    let (mut selected, scale): (Vec<Val>, f32) = match sampling {
        ValSampling::Stride(s) => {
            let s = s.max(1) as usize;
            (vals.iter().step_by(s).take(vals.len() / s).copied().collect(), s as f32)
        }
        ValSampling::All | ValSampling::Importance { .. } => (vals.to_vec(), 1.0),
        // Drawn from the running sum in list order, as the GPU walks them.
        ValSampling::Systematic { .. } => return (vals.to_vec(), 1.0),
    };
    sort_along_curve(&mut selected);
    (selected, scale)
}

/// Sort `vals` along a Morton curve over their bounding box (the order the reference traces a
/// receiver's shadow rays in).
pub fn sort_along_curve(vals: &mut [Val]) {
    let (lo, hi) =
        vals.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), v| (lo.min(v.position), hi.max(v.position)));
    vals.sort_by_cached_key(|v| morton_code(v.position, lo, hi));
}

/// The 30-bit Morton code (obvhs's) of `p` on a 1024³ grid over the box `lo`..`hi`.
pub(crate) fn morton_code(p: Vec3, lo: Vec3, hi: Vec3) -> u32 {
    let cell = ((p - lo) / (hi - lo).max(Vec3::splat(1e-12)) * 1023.0).clamp(Vec3::ZERO, Vec3::splat(1023.0));
    obvhs::ploc::morton::morton_encode_u32(cell.x as u16, cell.y as u16, cell.z as u16)
}

/// One reference frame as its pixels are shaded: the VALs in curve order with their flux scale.
struct Frame<'a> {
    bvh: &'a TraceBvh,
    vals: &'a [Val],
    /// Where each VAL's shadow rays end: `l + n_l RAY_OFFSET`, the same for every receiver.
    targets: &'a [Vec3],
    scale: f32,
    glossy: bool,
    receivers: &'a Receivers<'a>,
    width: u32,
    sampling: ValSampling,
    blockers_from: f32,
}

impl Frame<'_> {
    /// Pixel `i`: its estimate and the shadow rays it cast.
    fn pixel(&self, i: usize, traversal: ShadowTraversal, ws: &mut Workspace) -> (Pixel, u64) {
        let mut rays = 0;
        let samples = pixel_receivers(self.receivers, self.bvh, i, self.width);
        let estimates: Vec<Option<Halves>> = samples
            .iter()
            .enumerate()
            .map(|(k, r)| r.map(|r| self.estimate(&r, i, k, traversal, ws, &mut rays)))
            .collect();
        (combine(&estimates), rays)
    }

    /// The faster traversal for this frame, timed on [`PILOT_PIXELS`] pixels each (the pilot's
    /// results are thrown away).
    fn pilot(&self, pixels: usize) -> ShadowTraversal {
        if pixels < PILOT_MIN_PIXELS {
            return ShadowTraversal::Packets;
        }
        let time = |traversal| {
            let start = std::time::Instant::now();
            (0..PILOT_PIXELS).into_par_iter().for_each_init(Workspace::default, |ws, k| {
                self.pixel((2 * k + 1) * pixels / (2 * PILOT_PIXELS), traversal, ws);
            });
            start.elapsed()
        };
        let single = time(ShadowTraversal::Single);
        let packets = time(ShadowTraversal::Packets);
        tracing::debug!(?single, ?packets, "exact reference: shadow-ray traversal pilot");
        if packets <= single { ShadowTraversal::Packets } else { ShadowTraversal::Single }
    }

    /// Receiver `r`'s sum or estimate (sample `k` of pixel `pixel`, for the random streams).
    fn estimate(
        &self,
        r: &Receiver,
        pixel: usize,
        k: usize,
        traversal: ShadowTraversal,
        ws: &mut Workspace,
        rays: &mut u64,
    ) -> Halves {
        let term =
            |val: &Val| val_radiance_sided(r.position, r.normal, r.geometric, &r.surface, r.view, val, self.glossy);
        // Pushed off the surface along its geometric normal: the shading normal may point
        // along the surface, or into it (docs/design.md §3, shading and geometric normals).
        let origin = r.position + r.geometric * RAY_OFFSET;
        match self.sampling {
            ValSampling::All | ValSampling::Stride(_) => {
                ws.terms.clear();
                ws.targets.clear();
                for (val, &target) in self.vals.iter().zip(self.targets) {
                    let f = term(val);
                    if f != Vec3::ZERO {
                        ws.terms.push(f * self.scale);
                        ws.targets.push(target);
                    }
                }
                let l = ws.visible_sum(self.bvh, origin, traversal, self.blockers_from, rays);
                Halves { a: l, b: l, n: (1, 0) }
            }
            ValSampling::Systematic { samples, seed } => {
                let samples = samples.max(1);
                ws.contributions.clear();
                ws.contributions.extend(self.vals.iter().map(term));
                let total = luminance(ws.contributions.iter().sum::<Vec3>());
                if total.is_nan() || total <= 0.0 {
                    return Halves { a: Vec3::ZERO, b: Vec3::ZERO, n: (1, 0) };
                }
                let step = total / samples as f32;
                let xi = match k {
                    0 => pixel_offset(pixel as u32, seed),
                    k => pixel_offset(pcg_hash(pixel as u32 ^ pcg_hash(seed)).wrapping_add(k as u32), seed),
                };
                ws.terms.clear();
                ws.targets.clear();
                let (mut sum, mut passed) = (0.0f32, 0);
                for (j, f) in ws.contributions.iter().enumerate() {
                    if passed >= samples {
                        break;
                    }
                    let lum = luminance(*f);
                    let after = sum + lum;
                    let draws = thresholds_below(after, step, xi, samples) - passed;
                    if draws > 0 && lum > 0.0 {
                        ws.terms.push(*f * (draws as f32 * step / lum));
                        ws.targets.push(self.targets[j]);
                    }
                    sum = after;
                    passed = thresholds_below(sum, step, xi, samples);
                }
                let l = ws.visible_sum(self.bvh, origin, traversal, self.blockers_from, rays);
                Halves { a: l, b: l, n: (1, 0) }
            }
            ValSampling::Importance { samples, seed } => {
                ws.contributions.clear();
                ws.cdf.clear();
                let mut total = 0.0f64;
                for val in self.vals {
                    let f = term(val);
                    total += luminance(f) as f64;
                    ws.contributions.push(f);
                    ws.cdf.push(total);
                }
                let n = samples.max(2);
                let (na, nb) = (n / 2, n - n / 2);
                if total <= 0.0 {
                    return Halves { a: Vec3::ZERO, b: Vec3::ZERO, n: (na, nb) };
                }
                let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ 0x9e37_79b9_7f4a_7c15);
                rng.set_stream(((pixel as u64) << 16) ^ k as u64);
                let mut half = |draws: u32, ws: &mut Workspace| {
                    // The draws in VAL (curve) order, each weighted by 1 / its probability.
                    ws.draws.clear();
                    for _ in 0..draws {
                        let u = rng.random::<f64>() * total;
                        let j = ws.cdf.partition_point(|&c| c <= u).min(self.vals.len() - 1);
                        let f = ws.contributions[j];
                        let p = luminance(f) as f64 / total;
                        if p > 0.0 {
                            ws.draws.push((j as u32, f / p as f32));
                        }
                    }
                    ws.draws.sort_unstable_by_key(|&(j, _)| j);
                    ws.terms.clear();
                    ws.targets.clear();
                    for &(j, f) in &ws.draws {
                        ws.terms.push(f);
                        ws.targets.push(self.targets[j as usize]);
                    }
                    ws.visible_sum(self.bvh, origin, traversal, self.blockers_from, rays) / draws as f32
                };
                let a = half(na, ws);
                let b = half(nb, ws);
                Halves { a, b, n: (na, nb) }
            }
        }
    }
}

/// Pixel `i`'s receivers (one per sample; `None` where the sample sees background).
fn pixel_receivers(receivers: &Receivers, bvh: &TraceBvh, i: usize, width: u32) -> Vec<Option<Receiver>> {
    match receivers {
        Receivers::Hits(hits) => vec![hits[i]],
        Receivers::Traced { camera, sampling, surface } => {
            let (px, py) = ((i % width as usize) as f32, (i / width as usize) as f32);
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(sampling.seed);
            rng.set_stream(i as u64);
            (0..sampling.spp.max(1))
                .map(|_| {
                    let (sx, sy) =
                        if sampling.spp <= 1 { (0.5, 0.5) } else { (rng.random::<f32>(), rng.random::<f32>()) };
                    let (origin, direction) = camera.ray(px + sx, py + sy);
                    bvh.closest_hit(origin, direction).map(|h| surface(h.triangle, h.barycentrics))
                })
                .collect()
        }
    }
}

/// One receiver's estimate as two independent halves (equal when it is not random).
#[derive(Clone, Copy, Debug)]
struct Halves {
    a: Vec3,
    b: Vec3,
    /// Draws in each half (1 and 0 when the estimate is not split).
    n: (u32, u32),
}

#[derive(Clone, Copy, Debug)]
struct Pixel {
    rgba: [f32; 4],
    variance: Vec3,
}

/// Per-thread scratch: the cumulative distribution of the VALs' contributions, and one
/// receiver's shadow rays (their targets, the terms they carry, the draws behind them).
#[derive(Default)]
struct Workspace {
    contributions: Vec<Vec3>,
    cdf: Vec<f64>,
    draws: Vec<(u32, Vec3)>,
    terms: Vec<Vec3>,
    targets: Vec<Vec3>,
    blocked: Vec<bool>,
}

impl Workspace {
    /// The sum of `terms` whose shadow ray from `origin` to the matching `targets` is clear
    /// beyond `blockers_from` (m) of the origin (0: the whole segment).
    fn visible_sum(
        &mut self,
        bvh: &TraceBvh,
        origin: Vec3,
        traversal: ShadowTraversal,
        blockers_from: f32,
        rays: &mut u64,
    ) -> Vec3 {
        *rays += self.targets.len() as u64;
        if blockers_from > 0.0 {
            self.blocked.clear();
            self.blocked.extend(self.targets.iter().map(|&t| {
                let d = t - origin;
                let length = d.length();
                length > blockers_from && bvh.segment_blocked(origin + d * (blockers_from / length), t)
            }));
        } else {
            bvh.shadow_rays(origin, &self.targets, traversal, &mut self.blocked);
        }
        self.terms.iter().zip(&self.blocked).filter(|(_, b)| !**b).map(|(f, _)| *f).sum()
    }
}

/// A pixel from its samples' estimates: the mean, and the variance of the mean from two
/// independent halves `A` (of `n_a` draws) and `B` (`n_b`): with `n = n_a + n_b` iid draws of
/// variance `σ²`, `E[(A - B)²] = σ² (1/n_a + 1/n_b)` and the mean's variance is `σ² / n`, so
/// `s² = (A - B)² n_a n_b / n²`. With several sub-pixel samples the halves are the even and odd
/// samples (independent positions, each with its own draws); with one, the two halves of its
/// draws. Background samples count as zero radiance.
fn combine(estimates: &[Option<Halves>]) -> Pixel {
    let zero = Halves { a: Vec3::ZERO, b: Vec3::ZERO, n: (1, 0) };
    let covered = estimates.iter().filter(|e| e.is_some()).count();
    let alpha = covered as f32 / estimates.len().max(1) as f32;
    let mean_of = |h: &Halves| {
        let (na, nb) = (h.n.0 as f32, h.n.1 as f32);
        (h.a * na + h.b * nb) / (na + nb)
    };
    let (mean, variance) = if let [single] = estimates {
        let h = single.unwrap_or(zero);
        let (na, nb) = (h.n.0 as f32, h.n.1 as f32);
        let s2 = if h.n.1 == 0 { Vec3::ZERO } else { (h.a - h.b) * (h.a - h.b) * (na * nb / ((na + nb) * (na + nb))) };
        (mean_of(&h), s2)
    } else {
        let values: Vec<Vec3> = estimates.iter().map(|e| e.as_ref().map_or(Vec3::ZERO, mean_of)).collect();
        let n = values.len() as f32;
        let (na, nb) = (values.len().div_ceil(2) as f32, (values.len() / 2) as f32);
        let a = values.iter().step_by(2).sum::<Vec3>() / na;
        let b = values.iter().skip(1).step_by(2).sum::<Vec3>() / nb;
        (values.iter().sum::<Vec3>() / n, (a - b) * (a - b) * (na * nb / (n * n)))
    };
    Pixel { rgba: [mean.x, mean.y, mean.z, alpha], variance }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::twin::bvh::Bvh;
    use crate::twin::shade_brute_force;
    use glam::Vec2;

    /// A 4 m x 4 m floor (y = 0, two triangles) under a 1 m x 1 m occluder quad at y = 0.5, lit
    /// by 300 VALs facing down between y = 1 and 1.5 with random colours.
    struct Room {
        positions: Vec<Vec3>,
        triangles: Vec<[u32; 3]>,
        /// The GPU layout's tree, for `Bvh::occluded` (the twin of `bvh.wgsl`).
        bvh: Bvh,
        trace: TraceBvh,
        vals: Vec<Val>,
    }

    const SURFACE: Material = Material {
        diffuse: Vec3::new(0.6, 0.5, 0.4),
        specular: Vec3::splat(0.3),
        exponent: 12.0,
        diffuse_texture: None,
    };
    const EYE: Vec3 = Vec3::new(0.0, 2.5, 3.0);

    fn room() -> Room {
        let positions = vec![
            Vec3::new(-2.0, 0.0, -2.0),
            Vec3::new(2.0, 0.0, -2.0),
            Vec3::new(2.0, 0.0, 2.0),
            Vec3::new(-2.0, 0.0, 2.0),
            Vec3::new(-0.5, 0.5, -0.5),
            Vec3::new(0.5, 0.5, -0.5),
            Vec3::new(0.5, 0.5, 0.5),
            Vec3::new(-0.5, 0.5, 0.5),
        ];
        let triangles = vec![[0, 2, 1], [0, 3, 2], [4, 6, 5], [4, 7, 6]];
        let bvh = Bvh::build(&positions, &triangles);
        let trace = TraceBvh::build(&positions, &triangles);
        let vals = vals_above(1, 300, 1.5, 1.0..1.5, 1e-3);
        Room { positions, triangles, bvh, trace, vals }
    }

    /// `n` VALs of `area` facing down, spread uniformly over `-half_width..half_width` in x and
    /// z at `heights`, with random flux (seeded by `seed`).
    fn vals_above(seed: u64, n: usize, half_width: f32, heights: std::ops::Range<f32>, area: f32) -> Vec<Val> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut random = |range: std::ops::Range<f32>| rng.random_range(range);
        (0..n)
            .map(|_| {
                let (x, y, z) =
                    (random(-half_width..half_width), random(heights.clone()), random(-half_width..half_width));
                let flux = Vec3::new(random(0.0..1.0), random(0.0..1.0), random(0.0..1.0));
                Val { position: Vec3::new(x, y, z), normal: Vec3::NEG_Y, area, flux }
            })
            .collect()
    }

    /// Floor receivers along a line through the occluder's shadow: lit, penumbra and umbra.
    fn floor_receivers() -> Vec<Option<Receiver>> {
        (0..8)
            .map(|i| Some(Receiver::new(Vec3::new(-1.8 + 0.45 * i as f32, 0.0, 0.1), Vec3::Y, SURFACE, EYE)))
            .collect()
    }

    /// `blockers_from`: the room's occluder lies 0.5 m or more along every floor receiver's
    /// shadow rays, so ignoring blockers within 0.3 m changes nothing (to float rounding),
    /// within 3 m (past the occluder on every ray: at most 1.9 m along the longest) leaves every
    /// receiver unoccluded, the brute force over every VAL; and the occluder must shadow some
    /// receivers at 0 for either to mean anything.
    #[test]
    fn blockers_from_ignores_only_the_blockers_that_near() {
        let room = room();
        let hits = floor_receivers();
        let image = |blockers_from| {
            let scene = ExactScene { bvh: &room.trace, vals: &room.vals, glossy: true, blockers_from };
            render(&scene, &Receivers::Hits(&hits), hits.len() as u32, 1, ValSampling::All).image
        };
        let (every, near_left_out, none) = (image(0.0), image(0.3), image(3.0));
        let mut shadowed = 0;
        for (i, r) in hits.iter().enumerate() {
            let r = r.unwrap();
            let unoccluded = shade_brute_force(r.position, r.normal, &r.surface, EYE, &room.vals, true);
            let (a, b, c) = (every.rgb(i), near_left_out.rgb(i), none.rgb(i));
            assert!((a - b).abs().max_element() <= 1e-5 * a.max_element(), "receiver {i}: {a} vs {b}");
            assert!((c - unoccluded).abs().max_element() <= 1e-5 * unoccluded.max_element(), "receiver {i}: {c}");
            shadowed += usize::from(a.element_sum() < 0.9 * unoccluded.element_sum());
        }
        assert!(shadowed >= 2, "the occluder must shadow some receivers, shadowed {shadowed}");
    }

    /// Every VAL at the centre: the brute-force twin over the VALs the GPU layout's traversal
    /// (`Bvh::occluded`, twin of `bvh.wgsl`) finds visible, to float rounding (1e-5 relative),
    /// and noise-free; the occluder must darken some receivers for the test to mean anything.
    #[test]
    fn every_val_equals_brute_force_over_visible_vals() {
        let room = room();
        let hits = floor_receivers();
        let scene = ExactScene { bvh: &room.trace, vals: &room.vals, glossy: true, blockers_from: 0.0 };
        let out = render(&scene, &Receivers::Hits(&hits), hits.len() as u32, 1, ValSampling::All);
        let mut shadowed = 0;
        for (i, r) in hits.iter().enumerate() {
            let r = r.unwrap();
            let origin = r.position + r.normal * RAY_OFFSET;
            let visible: Vec<Val> = room
                .vals
                .iter()
                .filter(|v| {
                    !room.bvh.occluded(&room.positions, &room.triangles, origin, v.position + v.normal * RAY_OFFSET)
                })
                .copied()
                .collect();
            let want = shade_brute_force(r.position, r.normal, &r.surface, EYE, &visible, true);
            let unoccluded = shade_brute_force(r.position, r.normal, &r.surface, EYE, &room.vals, true);
            shadowed += usize::from(want.element_sum() < 0.9 * unoccluded.element_sum());
            let got = out.image.rgb(i);
            assert!((got - want).abs().max_element() <= 1e-5 * want.max_element(), "receiver {i}: {got} vs {want}");
            assert_eq!(out.image.pixels[i][3], 1.0);
        }
        assert!(shadowed >= 2, "the occluder must shadow some receivers, shadowed {shadowed}");
        assert!(out.variance.unwrap().iter().all(|v| *v == Vec3::ZERO), "the full sum has no noise");
        assert!(out.shadow_rays > 0 && out.shadow_rays <= (hits.len() * room.vals.len()) as u64);
    }

    /// The shadow-ray traversal changes the cost, never the image: with 4,000 VALs packed over
    /// the occluder (so a floor receiver's neighbouring VALs are ~0.01 rad apart and full packets
    /// form) the packets and the single rays give the same pixels, bit for bit, and cast the
    /// same rays, for the full sum, a stride and the importance estimate.
    #[test]
    fn packets_and_single_rays_give_the_same_image() {
        let mut room = room();
        room.vals = vals_above(4, 4000, 0.6, 1.0..1.1, 1e-4);
        let hits = floor_receivers();
        let scene = ExactScene { bvh: &room.trace, vals: &room.vals, glossy: true, blockers_from: 0.0 };
        let n = hits.len() as u32;
        for sampling in [ValSampling::All, ValSampling::Stride(3), ValSampling::Importance { samples: 64, seed: 2 }] {
            let render = |t| render_with(&scene, &Receivers::Hits(&hits), n, 1, sampling, Some(t));
            let (single, packets) = (render(ShadowTraversal::Single), render(ShadowTraversal::Packets));
            assert_eq!(single.image.pixels, packets.image.pixels, "{sampling:?}");
            assert_eq!(single.shadow_rays, packets.shadow_rays, "{sampling:?}");
            assert_eq!(packets.traversal, ShadowTraversal::Packets);
        }
        let lit = render(&scene, &Receivers::Hits(&hits), n, 1, ValSampling::All).image;
        let darkest = (0..hits.len()).map(|i| lit.rgb(i).x).fold(f32::INFINITY, f32::min);
        let brightest = (0..hits.len()).map(|i| lit.rgb(i).x).fold(0.0, f32::max);
        assert!(darkest < 0.5 * brightest, "the occluder must shadow part of the line: {darkest} vs {brightest}");
    }

    /// Importance sampling is unbiased and its noise estimate is right: over 200 independent
    /// seeds (16 draws each) the mean estimate at every receiver and channel lies within 4
    /// standard errors of the full sum (a z-test; standard error from the spread over seeds;
    /// with 24 z-values a false failure has probability ~1e-3), and the mean of the two-halves
    /// variance estimate matches the variance observed across seeds within [0.6, 1.6] (each
    /// side has ~10 % relative noise at 200 seeds, so that is a ~4-sigma band).
    #[test]
    fn importance_estimate_mean_over_seeds_converges_to_the_full_sum() {
        let room = room();
        let hits = floor_receivers();
        let scene = ExactScene { bvh: &room.trace, vals: &room.vals, glossy: true, blockers_from: 0.0 };
        let n = hits.len() as u32;
        let full = render(&scene, &Receivers::Hits(&hits), n, 1, ValSampling::All).image;
        let seeds = 200;
        let runs: Vec<ExactImage> = (0..seeds)
            .map(|seed| render(&scene, &Receivers::Hits(&hits), n, 1, ValSampling::Importance { samples: 16, seed }))
            .collect();
        for i in 0..hits.len() {
            let values: Vec<Vec3> = runs.iter().map(|r| r.image.rgb(i)).collect();
            let mean = values.iter().sum::<Vec3>() / seeds as f32;
            let spread = values.iter().map(|v| (*v - mean) * (*v - mean)).sum::<Vec3>() / (seeds - 1) as f32;
            let estimated = runs.iter().map(|r| r.variance.as_ref().unwrap()[i]).sum::<Vec3>() / seeds as f32;
            let want = full.rgb(i);
            for c in 0..3 {
                if spread[c] == 0.0 {
                    assert!(
                        (mean[c] - want[c]).abs() <= 1e-5 * want[c].abs().max(1e-12),
                        "receiver {i}: noiseless yet off"
                    );
                    continue;
                }
                let z = (mean[c] - want[c]) / (spread[c] / seeds as f32).sqrt();
                assert!(z.abs() < 4.0, "receiver {i} channel {c}: mean {} vs full {}, z = {z}", mean[c], want[c]);
                let ratio = estimated[c] / spread[c];
                assert!(
                    (0.6..1.6).contains(&ratio),
                    "receiver {i} channel {c}: half-split variance / observed {ratio}"
                );
            }
        }
        assert!(runs[0].shadow_rays <= 16 * n as u64, "one shadow ray per draw at most");
    }

    /// Shading and geometric normals (docs/design.md §3), in closed form: a receiver on a floor
    /// (y = 0, geometric normal +Y) whose shading normal is bent by 60 and by 90 degrees toward a
    /// Lambertian wall (x = 1, y and z in [-1, 1], facing -X, radiance `L_e`) that reaches below
    /// the floor. The irradiance is `L_e` times the integral over the wall of
    /// `cos_wall max(0, n_s . w) / d²` over the part above the floor only: light from below the
    /// geometric surface does not count, though the bent shading normal faces it. That integral
    /// by midpoint quadrature (600 x 300 cells on the upper half) must equal the brute force's
    /// sum over the wall as 40 x 40 VALs (no visibility) and the exact reference's (shadow rays
    /// through the floor, from the receiver pushed along its geometric normal) within 1 %; a
    /// receiver that took the lower half too, as the shading normal alone would, is 20-100 % over.
    #[test]
    fn bent_shading_normals_take_light_from_above_the_geometric_surface_only() {
        let l_e = 2.0f32;
        let n = 40;
        let side = 2.0 / n as f32;
        let vals: Vec<Val> = (0..n * n)
            .map(|k| {
                let (i, j) = ((k % n) as f32, (k / n) as f32);
                Val {
                    position: Vec3::new(1.0, -1.0 + (j + 0.5) * side, -1.0 + (i + 0.5) * side),
                    normal: Vec3::NEG_X,
                    area: side * side,
                    flux: Vec3::splat(std::f32::consts::PI * l_e * side * side),
                }
            })
            .collect();
        let positions = vec![
            Vec3::new(-4.0, 0.0, -4.0),
            Vec3::new(4.0, 0.0, -4.0),
            Vec3::new(4.0, 0.0, 4.0),
            Vec3::new(-4.0, 0.0, 4.0),
        ];
        let trace = TraceBvh::build(&positions, &[[0, 2, 1], [0, 3, 2]]);
        let matte = Material { diffuse: Vec3::splat(0.5), specular: Vec3::ZERO, exponent: 1.0, diffuse_texture: None };
        let eye = Vec3::new(-1.0, 2.0, 0.3);
        for degrees in [60.0f32, 90.0] {
            let bent = Vec3::new(degrees.to_radians().sin(), degrees.to_radians().cos(), 0.0);
            // The quadrature, in f64: the wall's upper half, where d is at least 1 m.
            let (cells_z, cells_y) = (600, 300);
            let (dz, dy) = (2.0 / cells_z as f64, 1.0 / cells_y as f64);
            let mut above = 0.0f64;
            let mut below = 0.0f64;
            for iy in 0..2 * cells_y {
                for iz in 0..cells_z {
                    let y = -1.0 + (iy as f64 + 0.5) * dy;
                    let z = -1.0 + (iz as f64 + 0.5) * dz;
                    let (vx, vy, vz) = (1.0f64, y, z);
                    let d2 = vx * vx + vy * vy + vz * vz;
                    let d = d2.sqrt();
                    let cos_wall = vx / d;
                    let cos_shading = ((bent.x as f64) * vx + (bent.y as f64) * vy) / d;
                    let term = l_e as f64 * cos_wall * cos_shading.max(0.0) / d2 * dy * dz;
                    if y > 0.0 { above += term } else { below += term }
                }
            }
            let want = 0.5 / std::f64::consts::PI * above;
            let r = Receiver::sided(Vec3::ZERO, bent, Vec3::Y, matte, eye);
            let brute =
                crate::twin::shade_brute_force_sided(r.position, r.normal, r.geometric, &matte, eye, &vals, false);
            let scene = ExactScene { bvh: &trace, vals: &vals, glossy: false, blockers_from: 0.0 };
            let exact = render(&scene, &Receivers::Hits(&[Some(r)]), 1, 1, ValSampling::All).image.rgb(0);
            for (name, got) in [("brute force", brute), ("exact", exact)] {
                let ratio = got.x as f64 / want;
                assert!((ratio - 1.0).abs() < 0.01, "{degrees} degrees, {name}: {} vs quadrature {want}", got.x);
            }
            // The test can fail: the shading normal alone (the flat surface's sum, `n_g = n_s`)
            // adds the lower half.
            assert!(below > 0.2 * above, "{degrees} degrees: the lower half must matter ({below} vs {above})");
            let unsided = crate::twin::shade_brute_force(r.position, r.normal, &matte, eye, &vals, false);
            assert!(unsided.x as f64 > 1.15 * want, "{degrees} degrees: {} vs {want}", unsided.x);
        }
    }

    /// Primary rays: at one sample per pixel through the pixel centre (the analytic ray-plane
    /// intersection, to 1e-4 m), and with 256 jittered samples a pixel the floor's edge halves is
    /// half covered (alpha 0.5 within 4 standard deviations of a binomial, 4 * 0.031).
    #[test]
    fn traced_receivers_sample_the_pixel_centre_or_its_area() {
        let room = room();
        let (w, h) = (32, 32);
        let world_to_clip = glam::camera::rh::proj::directx::perspective(1.0, 1.0, 0.01, 20.0)
            * glam::camera::rh::view::look_at_mat4(EYE, Vec3::ZERO, Vec3::Y);
        let camera = CameraRays::new(world_to_clip, w, h);
        let surface = |t: u32, b: Vec2| {
            let [p0, p1, p2] = room.triangles[t as usize].map(|i| room.positions[i as usize]);
            let n = (p1 - p0).cross(p2 - p0).normalize();
            Receiver::new(crate::twin::barycentric(b, p0, p1, p2), n, SURFACE, EYE)
        };
        let no_vals = ExactScene { bvh: &room.trace, vals: &[], glossy: true, blockers_from: 0.0 };
        for (x, y) in [(3u32, 30u32), (16, 16), (28, 25)] {
            let (o, d) = camera.ray(x as f32 + 0.5, y as f32 + 0.5);
            let sampling = PixelSampling { spp: 1, seed: 0 };
            let r = pixel_receivers(
                &Receivers::Traced { camera: &camera, sampling, surface: &surface },
                &room.trace,
                (y * w + x) as usize,
                w,
            );
            let [Some(r)] = r[..] else { panic!("pixel ({x}, {y}) must see the room: {r:?}") };
            let t_floor = -o.y / d.y;
            let t_box = (0.5 - o.y) / d.y;
            let on_box = (o + d * t_box).abs().max_element() <= 0.5 && (o + d * t_box).y > 0.4;
            let want = if on_box { o + d * t_box } else { o + d * t_floor };
            assert!((r.position - want).length() < 1e-4, "pixel ({x}, {y}): {} vs {want}", r.position);
        }
        // The floor's far edge (z = -2) crosses some column: find a pixel whose centre sees the
        // floor and whose upper neighbour does not, then place a camera that halves it.
        let edge_camera = CameraRays::new(world_to_clip, w, h);
        let sampling = PixelSampling { spp: 256, seed: 3 };
        let receivers = Receivers::Traced { camera: &edge_camera, sampling, surface: &surface };
        let out = render(&no_vals, &receivers, w, h, ValSampling::All);
        let column = 16;
        let alphas: Vec<f32> = (0..h).map(|y| out.image.pixels[(y * w + column) as usize][3]).collect();
        let partial: Vec<f32> = alphas.iter().copied().filter(|a| *a > 0.0 && *a < 1.0).collect();
        assert!(!partial.is_empty(), "the edge must cut a pixel: {alphas:?}");
        // Where the edge crosses the pixel (sub-pixel row): from where the centre ray meets z = -2.
        let y_edge = (0..h * 64)
            .map(|k| k as f32 / 64.0)
            .find(|&y| {
                let (o, d) = edge_camera.ray(column as f32 + 0.5, y);
                let t = -o.y / d.y;
                t > 0.0 && (o + d * t).z >= -2.0
            })
            .unwrap();
        let row = y_edge.floor() as u32;
        let expected = 1.0 - (y_edge - row as f32);
        let alpha = alphas[row as usize];
        assert!(
            (alpha - expected).abs() < 4.0 * (expected * (1.0 - expected) / 256.0).sqrt() + 0.02,
            "row {row}: alpha {alpha} vs {expected}"
        );
    }
}

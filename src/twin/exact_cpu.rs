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
mod tests;

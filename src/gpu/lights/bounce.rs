//! The second bounce of indirect light (paper 004 §4.1, imperfect reflective shadow maps), one
//! technique run after the first bounce's VAL sources and before the indirect technique: points
//! spread over the meshes by area (`twin::bounce::bounce_points`, at build) are lit by the
//! first-bounce VALs and become candidate VALs (`bounce2_points`, `bounce_points.wgsl`); then
//! `settings.second_bounce.vals` of them are drawn by flux, stratified (the imperfect shadow
//! maps' draw, `visibility/ism/flux_draw.wgsl`), and appended to the frame's VALs with their
//! flux divided by their probability (`bounce2_vals`, `bounce_draw.wgsl`). Every later stage
//! (the sparse method with its visibility mode, the brute force) lights with them unchanged.
//!
//! The candidates see the first bounce's VALs without visibility on the GPU (the sparse method
//! and the brute force); the CPU exact reference makes its own second bounce through shadow
//! rays (`twin::bounce::candidate_vals` with its BVH). Built only when `settings.bounces` is 2.
//! Rust twin: [`crate::twin::bounce`].

use crate::gpu::pass::{Entry, Kernel, Kernels, PassDesc, buffer, module_from_source, read, read_write};
use crate::gpu::raw::RawVal;
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::{TILE_SIZE, VAL_TILES, WORKGROUP_SIZE};
use crate::gpu::technique::{Frame, Technique};
use crate::gpu::timing::Recorder;
use crate::gpu::visibility::ism::{FLUX_DRAW_WGSL, SAMPLE_BLOCK};
use crate::gpu::{Gpu, GpuError};
use crate::scene::SecondBounceSettings;
use crate::twin::bounce::{self as twin, BouncePoint};
use bytemuck::{Pod, Zeroable};
use glam::Vec3;

pub const POINTS_WGSL: &str = include_str!("bounce_points.wgsl");
pub const DRAW_WGSL: &str = include_str!("bounce_draw.wgsl");

/// Stage names in the frame's timings.
pub const POINTS_STAGE: &str = "bounce2_points";
pub const DRAW_STAGE: &str = "bounce2_vals";

/// WGSL `BouncePoint`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RawBouncePoint {
    pub triangle: u32,
    pub u: f32,
    pub v: f32,
    pub area: f32,
}

impl From<&BouncePoint> for RawBouncePoint {
    fn from(p: &BouncePoint) -> Self {
        Self { triangle: p.triangle, u: p.barycentrics.x, v: p.barycentrics.y, area: p.area }
    }
}

/// Every bounce point lit by every first-bounce VAL: one invocation per point, the VALs in
/// tiles of `TILE_SIZE` (and in ranges on CPU adapters).
pub const POINTS: PassDesc = PassDesc {
    label: POINTS_STAGE,
    bindings: &[read("bounce_points"), read("vals"), read("val_count"), read_write("candidates")],
    entries: &[Entry::first("main", 4)],
    workgroup: [TILE_SIZE, 1, 1],
    default_source: |textured| POINTS.source(&format!("{VAL_TILES}\n{POINTS_WGSL}"), textured),
};

/// The draw: the flux sums over the candidates (the draw's `vals`), the draw appending to the
/// frame's VALs, and the count.
pub const DRAW: PassDesc = PassDesc {
    label: DRAW_STAGE,
    bindings: &[
        read("vals"),
        read("val_count"),
        read_write("flux_prefix"),
        read_write("all_vals"),
        read_write("all_val_count"),
    ],
    entries: &[
        Entry::first("flux_blocks", 3),
        Entry::first("flux_scan", 3),
        Entry::first("bounce_sample", 5),
        Entry { name: "bounce_count", bindings: 5, except: &["vals", "val_count", "flux_prefix", "all_vals"] },
    ],
    workgroup: [WORKGROUP_SIZE, 1, 1],
    default_source: |textured| DRAW.source(&draw_body(&SecondBounceSettings::default(), 1.0), textured),
};

/// The draw's WGSL: its constants, the shared flux draw, then `bounce_draw.wgsl`.
fn draw_body(settings: &SecondBounceSettings, area: f32) -> String {
    format!(
        "const SAMPLE_BLOCK: u32 = {SAMPLE_BLOCK}u;\nconst SECOND_BOUNCE_VALS: u32 = {}u;\n\
         const SECOND_BOUNCE_AREA: f32 = {area:e};\n{FLUX_DRAW_WGSL}\n{DRAW_WGSL}",
        settings.vals
    )
}

/// The second bounce's passes, its points and the candidates between them.
pub struct SecondBounce {
    pub settings: SecondBounceSettings,
    /// The points as built (world space of the scene as uploaded; they follow its vertices).
    pub points: Vec<BouncePoint>,
    /// Area (m²) of each drawn VAL.
    pub drawn_area: f32,
    light_points: Kernels,
    blocks: Kernel,
    scan: Kernel,
    sample: Kernel,
    count: Kernel,
    bounce_points: wgpu::Buffer,
    /// `array<Val>`, one per point: the candidates.
    pub candidates: wgpu::Buffer,
    /// One `u32`: how many candidates (the draw's `val_count`).
    candidate_count: wgpu::Buffer,
    /// `array<f32>`: block sums, then their running sums.
    flux_prefix: wgpu::Buffer,
}

impl SecondBounce {
    pub fn new(gpu: &Gpu, scene: &GpuScene, settings: SecondBounceSettings, seed: u64) -> Result<Self, GpuError> {
        let flat = &scene.flat;
        let positions: Vec<Vec3> = flat.vertices.iter().map(|v| Vec3::from(v.position)).collect();
        let points = twin::bounce_points(&positions, &flat.indices, settings.points, seed);
        let drawn_area = twin::drawn_area(&points);
        let raw: Vec<RawBouncePoint> = points.iter().map(RawBouncePoint::from).collect();
        let n = raw.len().max(1);
        let empty = [RawBouncePoint::default()];
        let textured = scene.textured();
        let light_points = Kernels::val_ranges(
            gpu,
            scene,
            &POINTS,
            POINTS.source(&format!("{VAL_TILES}\n{POINTS_WGSL}"), textured),
            POINTS.entry("main"),
            POINTS.workgroup,
            TILE_SIZE,
        )?;
        let module = module_from_source(gpu, DRAW.label, DRAW.source(&draw_body(&settings, drawn_area), textured))?;
        let kernel = |name: &str| Kernel::build(gpu, scene, &DRAW, &module, DRAW.entry(name), &[], DRAW.workgroup);
        let blocks = (raw.len() as u32).div_ceil(SAMPLE_BLOCK).max(1) as usize;
        Ok(Self {
            settings,
            drawn_area,
            light_points,
            blocks: kernel("flux_blocks")?,
            scan: kernel("flux_scan")?,
            sample: kernel("bounce_sample")?,
            count: kernel("bounce_count")?,
            bounce_points: gpu.storage_buffer(
                "bounce2_points.bounce_points",
                if raw.is_empty() { &empty[..] } else { &raw },
                wgpu::BufferUsages::empty(),
            )?,
            candidates: gpu.storage_buffer_sized::<RawVal>("bounce2_points.candidates", n)?,
            candidate_count: gpu.storage_buffer(
                "bounce2_vals.candidate_count",
                &[raw.len() as u32],
                wgpu::BufferUsages::empty(),
            )?,
            flux_prefix: gpu.storage_buffer_sized::<f32>("bounce2_vals.flux_prefix", blocks + 1)?,
            points,
        })
    }

    /// Cover frames of up to `max_vals` first-bounce VALs.
    pub fn fit(&mut self, gpu: &Gpu, scene: &GpuScene, max_vals: u32) -> Result<(), GpuError> {
        self.light_points.fit(gpu, scene, max_vals)
    }

    /// The candidates of the last frame (for the twins).
    pub fn read_candidates(&self, gpu: &Gpu) -> Result<Vec<crate::twin::Val>, GpuError> {
        Ok(gpu.read_buffer::<RawVal>(&self.candidates, self.points.len())?.iter().map(Into::into).collect())
    }
}

impl Technique for SecondBounce {
    fn stages(&self) -> Vec<&'static str> {
        vec![POINTS_STAGE, DRAW_STAGE]
    }

    fn record(&self, gpu: &Gpu, frame: &Frame<'_>, rec: &mut Recorder<'_>) -> Result<(), GpuError> {
        let (scene, vals) = (frame.scene, frame.vals);
        let resources = [
            buffer("bounce_points", &self.bounce_points),
            buffer("vals", &vals.buffer),
            buffer("val_count", &vals.count),
            buffer("candidates", &self.candidates),
        ];
        let points = self.points.len() as u32;
        rec.stage(POINTS_STAGE, |e, s| self.light_points.run(gpu, e, scene, &resources, [points, 1, 1], s))?;
        let all = [
            buffer("vals", &self.candidates),
            buffer("val_count", &self.candidate_count),
            buffer("flux_prefix", &self.flux_prefix),
            buffer("all_vals", &vals.buffer),
            buffer("all_val_count", &vals.count),
        ];
        let blocks = points.div_ceil(SAMPLE_BLOCK).max(1);
        let steps = [
            (&self.blocks, self.blocks.bind(gpu, &all[..3]), blocks),
            (&self.scan, self.scan.bind(gpu, &all[..3]), 1),
            (&self.sample, self.sample.bind(gpu, &all), self.settings.vals),
            (&self.count, self.count.bind(gpu, &all[4..]), 1),
        ];
        rec.stage(DRAW_STAGE, |e, s| {
            for (part, (kernel, group, invocations)) in steps.iter().enumerate() {
                let timestamps = s.as_ref().map(|s| s.compute_part(part, steps.len()));
                kernel.dispatch(e, group, scene, [*invocations, 1, 1], timestamps);
            }
        })
    }
}

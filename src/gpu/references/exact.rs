//! Exact-visibility reference (`exact.wgsl` + `bvh.wgsl`, docs/design.md §5): the
//! brute force with a shadow ray per pixel and VAL through a BVH built on the CPU. Rust twins:
//! `twin::shade_brute_force` over the VALs `twin::bvh::Bvh::occluded` lets through.

use super::rounds::{BVH_WGSL, PixelRounds};
use crate::gpu::pass::{Entry, PassDesc, read, read_write, texture};
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::Wgsl;
use crate::gpu::shader::{IMAGE_TILE, ROUNDS};
use crate::gpu::technique::{Frame, Technique};
use crate::gpu::timing::{Recorder, StageTimings};
use crate::gpu::{Gpu, GpuError, LLVMPIPE_LOOP_LIMIT};

pub const WGSL: &str = include_str!("exact.wgsl");

/// Loop iterations (VAL loop and BVH traversal together) one invocation runs per round.
/// llvmpipe silently ends all loops of an invocation after [`LLVMPIPE_LOOP_LIMIT`] iterations
/// in total, which cut the VAL loop short on pixels with many or long shadow rays; this stays
/// below it with a margin. GPUs have no such limit but are just as right in rounds.
pub const EXACT_LOOP_BUDGET: u32 = 60_000;
const _: () = assert!(EXACT_LOOP_BUDGET < LLVMPIPE_LOOP_LIMIT);

/// The pass's own WGSL using every `val_stride`-th VAL.
pub fn body(val_stride: u32) -> String {
    Wgsl::new()
        .u32("VAL_STRIDE", val_stride)
        .u32("EXACT_LOOP_BUDGET", EXACT_LOOP_BUDGET)
        .include(BVH_WGSL)
        .include(ROUNDS)
        .include(WGSL)
        .finish()
}

/// One invocation per pixel, in rounds (see [`Exact::finish`]).
pub const PASS: PassDesc = PassDesc {
    label: "exact",
    bindings: &[
        texture("visibility"),
        read_write("indirect"),
        read("vals"),
        read("val_count"),
        read("bvh_nodes"),
        read("bvh_triangles"),
        read_write("progress"),
        read_write("status"),
    ],
    entries: &[Entry::first("main", 8), Entry::first("main_glossy", 8)],
    workgroup: IMAGE_TILE,
    default_source: |textured| PASS.source(&body(4), textured),
};

/// Workgroups: [`IMAGE_TILE`] on GPUs. On CPU adapters 1x1: llvmpipe runs a workgroup's invocations as
/// SIMD lanes, and with lanes diverging in the BVH traversal whole 8x8 blocks came out wrong
/// (bright squares on the bunny at 192x192). Most likely
/// the same loop limit as [`EXACT_LOOP_BUDGET`]: llvmpipe counts it per SIMD vector, so lanes
/// that diverge use up one limit together, which a per-invocation budget cannot account for.
/// With one invocation per workgroup the budget is that invocation's own.
fn workgroup(gpu: &Gpu) -> [u32; 3] {
    if gpu.is_cpu() { [1, 1, 1] } else { IMAGE_TILE }
}

pub struct Exact {
    rounds: PixelRounds,
}

impl Exact {
    /// Build the BVH of `scene` and the pass over every `val_stride`-th VAL (>= 1).
    pub fn new(gpu: &Gpu, scene: &GpuScene, glossy: bool, val_stride: u32) -> Result<Self, GpuError> {
        let rounds = PixelRounds::new(gpu, scene, &PASS, &body(val_stride.max(1)), glossy, workgroup(gpu))?;
        Ok(Self { rounds })
    }

    /// Make room for an image of `pixels` pixels.
    pub fn fit(&mut self, gpu: &Gpu, pixels: usize) -> Result<(), GpuError> {
        self.rounds.fit(gpu, pixels).map(|_| ())
    }
}

impl Technique for Exact {
    fn stages(&self) -> Vec<&'static str> {
        vec![PASS.label]
    }

    /// The first round (after [`Exact::fit`] for this image); [`Technique::finish`] runs the
    /// rest once it has been submitted.
    fn record(&self, gpu: &Gpu, frame: &Frame<'_>, rec: &mut Recorder<'_>) -> Result<(), GpuError> {
        let group = self.rounds.bind(gpu, frame, Vec::new());
        rec.stage(PASS.label, |e, s| self.rounds.first_round(e, frame, &group, s))
    }

    /// Dispatch further rounds, each submitted and waited for, until every pixel has seen every
    /// VAL; their wall time is added to the stage, whatever timed the first round.
    fn finish(&self, gpu: &Gpu, frame: &Frame<'_>, timings: &mut StageTimings) -> Result<u32, GpuError> {
        let group = self.rounds.bind(gpu, frame, Vec::new());
        self.rounds.finish(gpu, frame, &group, timings, "exact visibility: pixels", EXACT_LOOP_BUDGET)
    }
}

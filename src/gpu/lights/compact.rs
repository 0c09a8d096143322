//! A VAL pass's candidates appended in order (`compact_vals.wgsl`): the pass writes one
//! candidate VAL per texel or grid cell (area -1: none) and one workgroup appends them, in the
//! slots' order, after the VALs already in the frame's buffer. An atomic append would order
//! them by the threads' timing, which changes from run to run, and with the order every float
//! sum over the VALs, the clusters' k-means seeds and the flux draw of the imperfect shadow
//! maps. Used by the spot light's RSM, the `lights`' RSMs and the RGB-D frames.

use crate::gpu::pass::{Kernel, PassDesc, Res, buffer};
use crate::gpu::raw::RawVal;
use crate::gpu::scene::GpuScene;
use crate::gpu::timing::Span;
use crate::gpu::{Gpu, GpuError, LLVMPIPE_LOOP_LIMIT};

/// The WGSL of `compact`; a pass that includes it binds `vals`, `val_count` and `candidates`.
pub const WGSL: &str = include_str!("compact_vals.wgsl");

/// Consecutive slots each invocation takes in a chunk (`COMPACT_RUN` in `compact_vals.wgsl`).
const RUN: u32 = 4;

/// Slots one dispatch may append on a CPU adapter with `threads` invocations per workgroup:
/// each chunk of `threads x RUN` slots costs an invocation `2 RUN + log2(threads)` loop
/// iterations and its own, and the chunks of a dispatch stay under llvmpipe's limit.
fn cpu_span(threads: u32) -> u32 {
    let per_chunk = 2 * RUN + threads.ilog2() + 1;
    (LLVMPIPE_LOOP_LIMIT / per_chunk - 1) * threads * RUN
}

/// A pass's candidate slots and its `compact` kernels (one; on a CPU adapter one per
/// [`cpu_span`] slots).
pub struct Compact {
    kernels: Vec<Kernel>,
    /// One VAL per slot, written by the pass.
    pub candidates: wgpu::Buffer,
}

impl Compact {
    /// Entry `compact` of `desc`'s `module`, with `slots` candidate slots (at least one).
    pub fn new(
        gpu: &Gpu,
        scene: &GpuScene,
        desc: &PassDesc,
        module: &wgpu::ShaderModule,
        slots: u32,
    ) -> Result<Self, GpuError> {
        let threads = desc.workgroup.iter().product();
        let span = if gpu.is_cpu() { cpu_span(threads) } else { u32::MAX };
        Self::with_span(gpu, scene, desc, module, slots, span)
    }

    /// [`Compact::new`] appending `span` slots per dispatch (the tests' small spans; `u32::MAX`:
    /// all in one).
    pub fn with_span(
        gpu: &Gpu,
        scene: &GpuScene,
        desc: &PassDesc,
        module: &wgpu::ShaderModule,
        slots: u32,
        span: u32,
    ) -> Result<Self, GpuError> {
        let threads: u32 = desc.workgroup.iter().product();
        assert!(threads.is_power_of_two(), "{}: compact takes a power-of-two workgroup", desc.label);
        let entry = desc.entry("compact");
        let ranges: Vec<Vec<(&str, f64)>> = if span == u32::MAX {
            vec![Vec::new()]
        } else {
            let range = |i: u32| vec![("COMPACT_BEGIN", f64::from(i * span)), ("COMPACT_SPAN", f64::from(span))];
            (0..slots.div_ceil(span).max(1)).map(range).collect()
        };
        let kernels = ranges
            .iter()
            .map(|constants| Kernel::build(gpu, scene, desc, module, entry, constants, desc.workgroup))
            .collect::<Result<_, _>>()?;
        let label = format!("{}.candidates", desc.label);
        let candidates = gpu.storage_buffer_sized::<RawVal>(&label, slots.max(1) as usize)?;
        Ok(Self { kernels, candidates })
    }

    /// How many dispatches of its own [`Compact::record_after`] makes.
    pub fn parts(&self) -> usize {
        self.kernels.len()
    }

    /// Record a VAL pass's stage: `before`, the pass's own dispatches in order (kernel, bind
    /// group, invocations), which write the candidates, then their append to `vals` (bound as its
    /// capacity) after `val_count`'s, all timed by `span` as one stage.
    pub fn record_after(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        scene: &GpuScene,
        before: &[(&Kernel, &wgpu::BindGroup, [u32; 3])],
        (vals, val_count): (Res<'_>, &wgpu::Buffer),
        span: Option<Span<'_>>,
    ) {
        let parts = before.len() + self.kernels.len();
        let timestamps = |part| span.as_ref().and_then(|s| s.compute_part(part, parts));
        for (part, (kernel, group, invocations)) in before.iter().enumerate() {
            kernel.dispatch(encoder, group, scene, *invocations, timestamps(part));
        }
        let resources = [vals, buffer("val_count", val_count), buffer("candidates", &self.candidates)];
        for (i, kernel) in self.kernels.iter().enumerate() {
            let group = kernel.bind(gpu, &resources);
            // One workgroup.
            kernel.dispatch(encoder, &group, scene, [1, 1, 1], timestamps(before.len() + i));
        }
    }
}

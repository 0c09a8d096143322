//! Adaptive sparse points (`settings.sparse.adaptive`, beyond the paper; `adaptive.wgsl`).
//! Rust twins: `twin::adaptive`.
//!
//! The scene's adaptive candidates (the last [`crate::gpu::scene::FlatScene::candidates`]
//! sparse points) are scored every frame from what their neighbours gathered, the best within
//! the frame's budget are gathered too (`adaptive_select`, then `adaptive_gather`: the gather
//! over the chosen list, [`super::gather::Receivers::Chosen`]), and the interpolation weighs the
//! chosen ones among each vertex's points (`adaptive_candidates.wgsl`). The choice of the
//! frame before raises a candidate's score ([`twin::adaptive::HYSTERESIS`]), so this state is
//! kept between frames.

use crate::gpu::pass::{Entry, Kernel, PassDesc, buffer, module_from_source, read, read_write, with_lobes};
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::WORKGROUP_SIZE;
use crate::gpu::shader::Wgsl;
use crate::gpu::timing::Recorder;
use crate::gpu::{Gpu, GpuError, Lobes};
use crate::scene::InterpolationKernel;
use crate::twin;

use super::gather::ChosenList;
use super::interpolate;

pub const WGSL: &str = include_str!("adaptive.wgsl");

/// Its stages, in frame order, after the gather of the points gathered every frame.
pub const SELECT_STAGE: &str = "adaptive_select";
pub const GATHER_STAGE: &str = "adaptive_gather";

/// The pass's own WGSL for a scene of `base` points gathered every frame, `candidates`
/// candidates after them and a `budget` of candidates per frame, with the interpolation's
/// `neighbours` and `kernel`.
pub fn body(base: u32, candidates: u32, budget: u32, neighbours: u32, kernel: InterpolationKernel) -> String {
    use twin::adaptive::{BINS_PER_OCTAVE, HYSTERESIS, SCORE_BINS, SCORE_LOG2_MIN};
    Wgsl::new()
        .include(&interpolate::weights_head(neighbours, kernel))
        .u32("BASE_POINTS", base)
        .u32("CANDIDATES", candidates)
        .u32("BUDGET", budget)
        .u32("SCORE_BINS", SCORE_BINS)
        .f32("BINS_PER_OCTAVE", BINS_PER_OCTAVE)
        .f32("SCORE_LOG2_MIN", SCORE_LOG2_MIN)
        .f32("HYSTERESIS", HYSTERESIS)
        .include(WGSL)
        .finish()
}

const NOT_SELECTING: &[&str] = &["threshold", "receiver_list", "receiver_count"];

/// One invocation per candidate (`choose_threshold`: one).
pub const PASS: PassDesc = PassDesc {
    label: "adaptive",
    bindings: &[
        read("sparse_points"),
        read("candidate_neighbours"),
        read_write("scores"),
        read_write("histogram"),
        read_write("chosen"),
        read_write("threshold"),
        read_write("receiver_list"),
        read_write("receiver_count"),
        read("gathered_diffuse"),
        read("gathered_glossy"),
    ],
    entries: &[
        Entry { name: "score", bindings: 9, except: NOT_SELECTING },
        Entry { name: "score_glossy", bindings: 10, except: NOT_SELECTING },
        Entry {
            name: "choose_threshold",
            bindings: 6,
            except: &["sparse_points", "candidate_neighbours", "scores", "chosen"],
        },
        Entry { name: "compact", bindings: 8, except: &["sparse_points", "candidate_neighbours", "histogram"] },
    ],
    workgroup: [WORKGROUP_SIZE, 1, 1],
    default_source: |textured| PASS.source(&body(64, 256, 32, 8, InterpolationKernel::default()), textured),
};

/// The adaptive points' kernels and the state they keep between frames.
pub struct Adaptive {
    score: Kernel,
    threshold: Kernel,
    compact: Kernel,
    /// `neighbours` point indices per candidate.
    candidate_neighbours: wgpu::Buffer,
    /// Per candidate, this frame's score.
    pub scores: wgpu::Buffer,
    histogram: wgpu::Buffer,
    /// Per candidate, 1 when chosen (kept for the next frame's hysteresis).
    pub chosen: wgpu::Buffer,
    threshold_bin: wgpu::Buffer,
    /// The chosen candidates' point indices, `budget` slots, and their count.
    pub list: wgpu::Buffer,
    pub count: wgpu::Buffer,
    candidates: u32,
    budget: u32,
}

impl Adaptive {
    /// For a scene with adaptive candidates (`scene.flat.candidates > 0`), interpolating with
    /// `kernel`, whose gathered sums are `glossy` or not.
    pub fn new(gpu: &Gpu, scene: &GpuScene, kernel: InterpolationKernel, glossy: bool) -> Result<Self, GpuError> {
        let flat = &scene.flat;
        let (candidates, budget) = (flat.candidates, flat.adaptive_budget);
        let source = body(flat.base_sparse_count(), candidates, budget, flat.neighbours, kernel);
        let module = module_from_source(gpu, PASS.label, PASS.source(&source, scene.textured()))?;
        let kernel = |name: &str| Kernel::build(gpu, scene, &PASS, &module, PASS.entry(name), &[], PASS.workgroup);
        let score = if glossy { "score_glossy" } else { "score" };
        let none = wgpu::BufferUsages::empty();

        Ok(Self {
            score: kernel(score)?,
            threshold: kernel("choose_threshold")?,
            compact: kernel("compact")?,
            candidate_neighbours: gpu.storage_buffer(
                "adaptive.candidate_neighbours",
                &flat.candidate_neighbours,
                none,
            )?,
            scores: gpu.storage_buffer_sized::<f32>("adaptive.scores", candidates as usize)?,
            histogram: gpu.storage_buffer_sized::<u32>("adaptive.histogram", twin::adaptive::SCORE_BINS as usize)?,
            chosen: gpu.storage_buffer_sized::<u32>("adaptive.chosen", candidates as usize)?,
            threshold_bin: gpu.storage_buffer_sized::<u32>("adaptive.threshold", 1)?,
            list: gpu.storage_buffer_sized::<u32>("adaptive.list", budget.max(1) as usize)?,
            count: gpu.storage_buffer_sized::<u32>("adaptive.count", 1)?,
            candidates,
            budget,
        })
    }

    /// The list [`super::gather::Gather::record_chosen`] gathers at.
    pub fn chosen_list(&self) -> ChosenList<'_> {
        ChosenList { list: &self.list, count: &self.count, slots: self.budget }
    }

    /// Score every candidate from `gathered` (the points gathered every frame) and list the
    /// frame's choice.
    pub fn record_select(
        &self,
        gpu: &Gpu,
        scene: &GpuScene,
        gathered: &Lobes,
        rec: &mut Recorder<'_>,
    ) -> Result<(), GpuError> {
        let score = self.score.bind(
            gpu,
            &with_lobes(
                vec![
                    buffer("sparse_points", &scene.sparse_points),
                    buffer("candidate_neighbours", &self.candidate_neighbours),
                    buffer("scores", &self.scores),
                    buffer("histogram", &self.histogram),
                    buffer("chosen", &self.chosen),
                ],
                &[(gathered, "gathered_diffuse", "gathered_glossy")],
            ),
        );
        let threshold =
            self.threshold.bind(gpu, &[buffer("histogram", &self.histogram), buffer("threshold", &self.threshold_bin)]);
        let compact = self.compact.bind(
            gpu,
            &[
                buffer("scores", &self.scores),
                buffer("chosen", &self.chosen),
                buffer("threshold", &self.threshold_bin),
                buffer("receiver_list", &self.list),
                buffer("receiver_count", &self.count),
            ],
        );
        let n = self.candidates;
        rec.stage(SELECT_STAGE, |e, s| {
            e.clear_buffer(&self.histogram, 0, None);
            e.clear_buffer(&self.count, 0, None);
            let part = |i| s.as_ref().and_then(|s| s.compute_part(i, 3));
            self.score.dispatch(e, &score, scene, [n, 1, 1], part(0));
            self.threshold.dispatch(e, &threshold, scene, [1, 1, 1], part(1));
            self.compact.dispatch(e, &compact, scene, [n, 1, 1], part(2));
        })
    }
}

//! The frame budget controller (`budget_ms` of streams and `relume replay --budget-ms`): it
//! moves a stream's frames along a ladder of parameter sets ([`FrameParameters`], cheapest
//! first) to hold the measured frame time under the budget, as dynamic resolution does in game
//! engines.
//!
//! It acts on what it measures, never on an assumed split of the frame's cost: it keeps, per
//! rung, a smoothed frame time (an exponential moving average, weight [`SMOOTHING`] on the
//! newest frame) of the frames that ran there. The rungs' costs drift together (the content a
//! recording shows grows, another process takes the cores): when the current rung's smoothed
//! time changes by a factor, every other measured rung's cost is multiplied by it, so that a
//! rung measured long ago is judged at today's cost, its ratio to the others as measured.
//! After each frame:
//!
//! - over the budget (smoothed, or this frame alone over [`MISS`] x budget): one rung down, two
//!   when over 1.5x the budget, or straight to the richest lower rung already measured under
//!   [`TARGET`] x budget; a lower rung whose cost is over that target is passed;
//! - under [`TARGET`] x budget for [`HOLD_FRAMES`] frames in a row: one rung up when that rung
//!   was measured under the target, or, not yet measured or measured over it (a cost that may
//!   be stale: a first frame building its pipelines), when this one is under
//!   [`PROBE_HEADROOM`] x the target (a probe). A rung left for being over the budget is not
//!   tried again for [`BACKOFF_FRAMES`] frames, doubled at each failed probe;
//! - otherwise it holds.
//!
//! The stream's first frame (pipelines built, caches filled) moves it down when over the budget
//! but is not kept as its rung's cost and blocks no rung.
//!
//! The hold, the target below the budget and the back-off are the hysteresis: rungs change
//! seldom, so the image does not pop from one frame to the next (the change it adds is measured
//! by `relume replay --budget-ms`, docs/measurements/budget.md).

use rayon::prelude::*;
use serde::Serialize;

use crate::scene::settings::{SceneAnalysis, SettingsDescription, resolve};
use crate::scene::{Occlusion, Quality, Settings};

/// The controller aims at this fraction of the budget, so that noise stays under it.
pub const TARGET: f64 = 0.9;
/// Weight of the newest frame in a rung's smoothed frame time.
pub const SMOOTHING: f64 = 0.5;
/// A frame over this multiple of the budget moves the controller down whatever the smoothed
/// time says: the budget's target allows 10 % over at the 90th percentile, and averaging it
/// with earlier frames would add a second such frame before the move.
pub const MISS: f64 = 1.1;
/// Frames under the target in a row before the controller tries a richer rung.
pub const HOLD_FRAMES: u32 = 6;
/// A rung not yet measured is tried only when the current one is under this fraction of the
/// target.
pub const PROBE_HEADROOM: f64 = 0.75;
/// Frames a rung that went over the budget is not tried again (doubled at each failure).
pub const BACKOFF_FRAMES: u64 = 16;
/// The cheapest rung's camera draws at most this fraction of each material's triangles
/// (`FrameParameters::camera_detail`, `twin::flat::FlatScene::lod_triangles`): the camera's
/// raster and the shading of its pixels cost per triangle drawn, not per pixel, so that
/// below half the render size they are most of what is left of a frame.
pub const CAMERA_LOD_RATIO: f32 = 0.25;
/// ...simplified no further than this error, a fraction of the extent of the scene's vertices
/// (meshoptimizer's relative measure): 0.4 mm on the TUM replay's bunny.
pub const CAMERA_LOD_ERROR: f32 = 0.002;
/// Below `fast`'s own parameters a scene with the differential pass takes every
/// `RECEIVERS_STEP`-th receiver in each direction (`FrameParameters::receivers_step`), and on
/// the half-size rungs every `RECEIVERS_STEP`²-th: on the TUM replay the pass is most of a frame
/// at every rung (649 of 760 ms at the cheapest before), its cost follows the receivers it
/// computes, and neither the render size nor the VALs change it; the composite interpolates
/// between the receivers.
pub const RECEIVERS_STEP: u32 = 2;

/// What one frame runs at: the parameters a loaded scene's renderer can change from one frame
/// to the next.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, utoipa::ToSchema)]
pub struct FrameParameters {
    /// The level these parameters are, or, between two levels' own, the richer one they lead to
    /// (below `fast`'s own, `fast`).
    pub level: Quality,
    /// The visibility mode of the indirect light.
    pub occlusion: Occlusion,
    /// `sparse.near_field`, in sparse point spacings (0: off).
    pub near_field: f32,
    /// Multiplier of the RGB-D `grid_step`: a frame's depth pixels give 1/`vals_step`² of the
    /// VALs (frames lit by RGB-D only).
    pub vals_step: u32,
    /// Render size over output size; the composite is scaled back up to the output size
    /// (dynamic resolution).
    pub resolution_scale: f32,
    /// The most of each material's triangles the camera draws: 1, the full meshes; below it
    /// ([`CAMERA_LOD_RATIO`]) the simplified copy (the sparse method's frames: the interpolation
    /// lights only the copy's vertices; the sparse points keep the full meshes).
    pub camera_detail: f32,
    /// Multiplier of `settings.mr.receiver_step`: the differential pass computes 1/`receivers_step`²
    /// of its receivers ([`RECEIVERS_STEP`] below `fast`'s own parameters of a scene with the
    /// differential pass; 1 otherwise).
    pub receivers_step: u32,
}

impl FrameParameters {
    /// The runtime parameters of `settings` (a level's resolved settings) at full resolution.
    pub fn of(level: Quality, settings: &Settings) -> FrameParameters {
        FrameParameters {
            level,
            occlusion: settings.visibility.mode,
            near_field: settings.sparse.near_field,
            vals_step: 1,
            resolution_scale: 1.0,
            camera_detail: 1.0,
            receivers_step: 1,
        }
    }

    /// What [`crate::renderer::Renderer::set_camera_lod`] takes for `camera_detail`.
    pub fn camera_lod(&self) -> Option<(f32, f32)> {
        (self.camera_detail < 1.0).then_some((self.camera_detail, CAMERA_LOD_ERROR))
    }

    /// The parameters as `name=value` pairs, as frames report them.
    pub fn pairs(&self) -> Vec<(String, String)> {
        let occlusion = serde_json::to_value(self.occlusion).ok().and_then(|v| v.as_str().map(str::to_owned));
        vec![
            ("level".to_owned(), self.level.name().to_owned()),
            ("visibility".to_owned(), occlusion.unwrap_or_default()),
            ("near_field".to_owned(), format!("{}", self.near_field)),
            ("vals_step".to_owned(), self.vals_step.to_string()),
            ("resolution_scale".to_owned(), format!("{}", self.resolution_scale)),
            ("camera_detail".to_owned(), format!("{}", self.camera_detail)),
            ("receivers_step".to_owned(), self.receivers_step.to_string()),
        ]
    }

    /// [`Self::pairs`] and `method`, the frame's indirect technique ([`Method::name`]): a level
    /// may name one (`settings.levels`), and a stream runs the sparse method at every level.
    pub fn pairs_with_method(&self, method: crate::renderer::Method) -> Vec<(String, String)> {
        let mut pairs = self.pairs();
        pairs.insert(1, ("method".to_owned(), method.name().to_owned()));
        pairs
    }

    /// Output size scaled by `resolution_scale` (at least 1 x 1).
    pub fn scaled(&self, width: u32, height: u32) -> (u32, u32) {
        let s = self.resolution_scale.clamp(0.05, 1.0);
        (((width as f32 * s).round() as u32).max(1), ((height as f32 * s).round() as u32).max(1))
    }
}

/// The runtime parameters of `level` on a loaded scene: the level resolved for the scene's
/// analysis and the scene file's settings (whose tuning still wins). Parameters fixed when the
/// meshes loaded (the RSM size, subdivision, adaptive points) keep their loaded values.
pub fn level_parameters(level: Quality, analysis: &SceneAnalysis, settings: &SettingsDescription) -> FrameParameters {
    let (resolved, _) = resolve(level, analysis, settings);
    FrameParameters::of(level, &resolved)
}

/// The ladder of a budgeted stream, cheapest first: below `fast`'s own parameters, the VALs of
/// an RGB-D frame halved then thirded on each side and (with `scale`) the render size scaled
/// down to half, visibility off, and last the camera drawing the meshes simplified
/// ([`CAMERA_LOD_RATIO`]: on the TUM replay the camera's raster and the per-vertex light are
/// most of the frame at half size); then each level's own parameters, `fast`, `balanced`,
/// `accurate`, with between the last two balanced's visibility and accurate's near field (on
/// the TUM replay accurate's imperfect shadow maps cost about five times the disks' frame, the
/// near field alone about 1.2-2x: a step a budget of twice the balanced frame can take). With
/// the differential pass (`settings.mr.differential`) every rung below `fast`'s own also thins
/// its receivers ([`RECEIVERS_STEP`], squared at half size), and a rung of `fast`'s parameters
/// with them comes before `fast`.
/// Consecutive rungs with the same parameters are merged (the richer level's name kept). Without `scale` no rung changes the render size (a stream whose frames are not
/// composited, or a render).
pub fn ladder(analysis: &SceneAnalysis, settings: &SettingsDescription, scale: bool) -> Vec<FrameParameters> {
    let [fast, balanced, accurate] =
        [Quality::Fast, Quality::Balanced, Quality::Accurate].map(|q| level_parameters(q, analysis, settings));
    // The differential pass's receivers thinned (a no-op for frames it does not relight: a
    // stream's frames seen from a virtual camera, or not composited).
    let receivers_step = if settings.mr.differential { RECEIVERS_STEP } else { 1 };
    let below = |occlusion, vals_step, resolution_scale: f32| FrameParameters {
        occlusion,
        vals_step,
        resolution_scale: if scale { resolution_scale } else { 1.0 },
        // The half-size rungs are where a budget far under the frame lands: they thin the
        // receivers again, the one part of the frame the other parameters leave whole.
        receivers_step: if resolution_scale <= 0.5 { receivers_step * receivers_step } else { receivers_step },
        ..fast
    };
    let mut rungs = vec![
        FrameParameters { camera_detail: CAMERA_LOD_RATIO, ..below(Occlusion::Off, 3, 0.5) },
        below(Occlusion::Off, 3, 0.5),
        below(Occlusion::Off, 2, 0.5),
        below(fast.occlusion, 2, 0.5),
        below(fast.occlusion, 2, 0.6),
        below(fast.occlusion, 2, 0.7),
        below(fast.occlusion, 1, 0.7),
        below(fast.occlusion, 1, 0.85),
        FrameParameters { receivers_step, ..fast },
        fast,
        balanced,
        FrameParameters { level: Quality::Accurate, near_field: accurate.near_field, ..balanced },
        accurate,
    ];
    let same = |a: &FrameParameters, b: &FrameParameters| FrameParameters { level: b.level, ..*a } == *b;
    rungs.dedup_by(|richer, cheaper| {
        if same(cheaper, richer) {
            cheaper.level = richer.level;
            true
        } else {
            false
        }
    });
    rungs
}

/// What the controller decided after a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Move {
    Hold,
    Down,
    Up,
}

/// Holds a stream's frame time under its budget by moving along a ladder of parameters.
#[derive(Clone, Debug)]
pub struct BudgetController {
    budget_ms: f64,
    ladder: Vec<FrameParameters>,
    rung: usize,
    /// Smoothed frame time (ms) per rung, once a frame ran there.
    cost: Vec<Option<f64>>,
    /// Frames under the target in a row at the current rung.
    under: u32,
    /// Per rung: the frame before which it is not tried again, and the next back-off.
    blocked_until: Vec<u64>,
    backoff: Vec<u64>,
    /// Whether the current rung was reached by a probe (a move up to an unmeasured rung).
    probing: bool,
    frames: u64,
}

impl BudgetController {
    /// A controller for `budget_ms` starting at `start` (an index into `ladder`, clamped).
    pub fn new(budget_ms: f32, ladder: Vec<FrameParameters>, start: usize) -> BudgetController {
        assert!(!ladder.is_empty(), "a ladder has at least one rung");
        let n = ladder.len();
        BudgetController {
            budget_ms: f64::from(budget_ms),
            rung: start.min(n - 1),
            ladder,
            cost: vec![None; n],
            under: 0,
            blocked_until: vec![0; n],
            backoff: vec![BACKOFF_FRAMES; n],
            probing: false,
            frames: 0,
        }
    }

    /// A controller starting at `level`'s own rung (the richest rung of that level).
    pub fn at_level(budget_ms: f32, ladder: Vec<FrameParameters>, level: Quality) -> BudgetController {
        let level = match level {
            Quality::Reference => Quality::Accurate,
            other => other,
        };
        let start = ladder.iter().rposition(|p| p.level == level).unwrap_or(ladder.len() - 1);
        BudgetController::new(budget_ms, ladder, start)
    }

    pub fn budget_ms(&self) -> f64 {
        self.budget_ms
    }

    /// Change the budget; the measured costs stay.
    pub fn set_budget_ms(&mut self, budget_ms: f32) {
        self.budget_ms = f64::from(budget_ms);
        self.under = 0;
    }

    /// The parameters of the next frame.
    pub fn parameters(&self) -> FrameParameters {
        self.ladder[self.rung]
    }

    pub fn rung(&self) -> usize {
        self.rung
    }

    pub fn ladder(&self) -> &[FrameParameters] {
        &self.ladder
    }

    /// Records the time of a frame that ran at [`Self::parameters`] and picks the next frame's.
    pub fn observe(&mut self, frame_ms: f64) -> Move {
        self.frames += 1;
        let r = self.rung;
        // The stream's first frame builds the pipelines and fills the caches: over the budget it
        // moves the controller down, but it does not measure its rung (its time is not kept as
        // the rung's cost, and the rung is not blocked).
        let warm_up = self.frames == 1;
        let smoothed = match self.cost[r] {
            Some(previous) => SMOOTHING * frame_ms + (1.0 - SMOOTHING) * previous,
            None => frame_ms,
        };
        if !warm_up {
            // The other rungs' costs follow this one's change (see the module's documentation).
            if let Some(previous) = self.cost[r].filter(|&c| c > 0.0) {
                let drift = smoothed / previous;
                for (i, cost) in self.cost.iter_mut().enumerate() {
                    if i != r {
                        *cost = cost.map(|c| c * drift);
                    }
                }
            }
            self.cost[r] = Some(smoothed);
        }
        let target = self.budget_ms * TARGET;
        // A frame over the budget by more than the miss allowed does not wait for the average.
        let over = smoothed.max(if frame_ms > MISS * self.budget_ms { frame_ms } else { 0.0 });
        if over > self.budget_ms && r > 0 {
            // The rung left is not tried again for its back-off; the back-off doubles when a
            // probe failed.
            if !warm_up {
                self.blocked_until[r] = self.frames + self.backoff[r];
            }
            if self.probing {
                self.backoff[r] = self.backoff[r].saturating_mul(2);
            }
            let measured = (0..r).rev().find(|&i| self.cost[i].is_some_and(|c| c <= target));
            let steps = if over > 1.5 * self.budget_ms { 2 } else { 1 };
            let mut next = measured.map_or(r.saturating_sub(steps), |i| i.max(r.saturating_sub(steps)));
            // A lower rung whose cost (as drifted) is over the target is passed too, down to
            // one that fits or was not measured yet.
            while next > 0 && self.cost[next].is_some_and(|c| c > target) {
                next -= 1;
            }
            self.rung = next;
            self.under = 0;
            self.probing = false;
            return Move::Down;
        }
        if smoothed >= target || r + 1 == self.ladder.len() {
            self.under = 0;
            self.probing = false;
            return Move::Hold;
        }
        self.under += 1;
        if self.under < HOLD_FRAMES || self.frames < self.blocked_until[r + 1] {
            return Move::Hold;
        }
        // A rung measured under the target is taken; one not measured, or measured over it
        // (its cost may be stale: a first frame's pipeline builds, a passing load), is probed
        // when this one has the headroom, its back-off over.
        let measured_fits = self.cost[r + 1].is_some_and(|cost| cost <= target);
        if !measured_fits && smoothed > target * PROBE_HEADROOM {
            return Move::Hold;
        }
        self.probing = !measured_fits;
        self.rung = r + 1;
        self.under = 0;
        Move::Up
    }
}

/// `pixels` (`width` x `height`, row-major sRGB) resized to `out_width` x `out_height` by
/// bilinear interpolation, pixel centres aligned: how a composite rendered at a lower
/// resolution is brought back to the output size. Each output column's and row's two source
/// texels and weight are found once, and the rows are filled over rayon's threads (it runs on
/// the host after every scaled frame).
pub fn upscale_rgb(pixels: &[[u8; 3]], width: u32, height: u32, out_width: u32, out_height: u32) -> Vec<[u8; 3]> {
    if (width, height) == (out_width, out_height) {
        return pixels.to_vec();
    }
    // (first texel, second texel, weight of the second) along one axis.
    let taps = |from: u32, to: u32| -> Vec<(usize, usize, f32)> {
        let (n, scale) = (from as usize, from as f32 / to as f32);
        (0..to)
            .map(|o| {
                let x = ((o as f32 + 0.5) * scale - 0.5).clamp(0.0, (n - 1) as f32);
                let x0 = x.floor() as usize;
                (x0, (x0 + 1).min(n - 1), x - x0 as f32)
            })
            .collect()
    };
    let (columns, rows) = (taps(width, out_width), taps(height, out_height));
    let w = width as usize;
    let mut out = vec![[0u8; 3]; out_width as usize * out_height as usize];
    out.par_chunks_mut(out_width as usize).zip(&rows).for_each(|(line, &(y0, y1, fy))| {
        let (top, bottom) = (&pixels[y0 * w..(y0 + 1) * w], &pixels[y1 * w..(y1 + 1) * w]);
        for (o, &(x0, x1, fx)) in line.iter_mut().zip(&columns) {
            *o = std::array::from_fn(|c| {
                let p = |row: &[[u8; 3]], x: usize| f32::from(row[x][c]);
                let t = p(top, x0) * (1.0 - fx) + p(top, x1) * fx;
                let b = p(bottom, x0) * (1.0 - fx) + p(bottom, x1) * fx;
                (t * (1.0 - fy) + b * fy).round().clamp(0.0, 255.0) as u8
            });
        }
    });
    out
}

/// Mean absolute difference of two sRGB images of the same size, in 8-bit levels per channel:
/// the frame-to-frame change of a replay's composites.
pub fn mean_abs_change(a: &[[u8; 3]], b: &[[u8; 3]]) -> f64 {
    if a.len() != b.len() || a.is_empty() {
        return 0.0;
    }
    let sum: u64 = a.iter().zip(b).map(|(p, q)| (0..3).map(|c| u64::from(p[c].abs_diff(q[c]))).sum::<u64>()).sum();
    sum as f64 / (a.len() * 3) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::settings::MrSettings;

    fn rungs(n: usize) -> Vec<FrameParameters> {
        let levels = [Quality::Fast, Quality::Balanced, Quality::Accurate];
        (0..n)
            .map(|i| FrameParameters {
                level: levels[(i * 3 / n).min(2)],
                occlusion: Occlusion::Disks,
                near_field: 0.0,
                vals_step: 1,
                resolution_scale: 0.5 + 0.5 * i as f32 / (n - 1) as f32,
                camera_detail: 1.0,
                receivers_step: 1,
            })
            .collect()
    }

    /// A synthetic cost model: the frame's time grows with the rung (a fixed part, and a part
    /// that grows with the rung), with noise of +-`noise` (a fixed pseudo-random sequence).
    fn run(budget: f32, cost: impl Fn(usize) -> f64, noise: f64, frames: usize) -> (Vec<f64>, Vec<usize>, usize) {
        run_in_time(budget, |rung, _| cost(rung), noise, frames)
    }

    /// [`run`] with a cost that also depends on the frame's index.
    fn run_in_time(
        budget: f32,
        cost: impl Fn(usize, usize) -> f64,
        noise: f64,
        frames: usize,
    ) -> (Vec<f64>, Vec<usize>, usize) {
        let mut c = BudgetController::new(budget, rungs(10), 7);
        let mut times = Vec::new();
        let mut rungs = Vec::new();
        let mut moves = 0;
        let mut state = 12345u64;
        for frame in 0..frames {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let u = (state >> 33) as f64 / (1u64 << 31) as f64;
            let ms = cost(c.rung(), frame) * (1.0 + noise * (2.0 * u - 1.0));
            times.push(ms);
            rungs.push(c.rung());
            if c.observe(ms) != Move::Hold {
                moves += 1;
            }
        }
        (times, rungs, moves)
    }

    fn p90(v: &[f64]) -> f64 {
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        s[(s.len() * 9).div_ceil(10) - 1]
    }

    #[test]
    fn a_tight_budget_falls_and_holds_within_ten_percent() {
        // Rung 7 takes 1000 ms; a budget of 500 ms is met from rung 3 down.
        let cost = |r: usize| 300.0 + 100.0 * r as f64;
        let (times, rungs, moves) = run(500.0, cost, 0.08, 60);
        let after = &times[5..];
        assert!(p90(after) <= 550.0, "p90 {} over the budget + 10 %: {times:?}", p90(after));
        assert!(rungs[5..].iter().all(|&r| r < 7), "it fell: {rungs:?}");
        assert!(moves <= 12, "{moves} moves in 60 frames: popping ({rungs:?})");
        // It does not sit far below: the richest rung that fits is 1 (400 ms at most +8 %).
        let settled = &rungs[30..];
        assert!(settled.iter().filter(|&&r| r >= 1).count() * 10 >= settled.len() * 8, "{rungs:?}");
    }

    #[test]
    fn costs_that_grow_together_are_followed_down() {
        // The upper rungs cost about the same (one pass, the differential one, is most of the
        // frame and only the lowest rungs thin it); the controller climbs to the top and
        // measures them on the way. At frame 30 every rung's cost grows by 80 % (another
        // process takes the cores). The rungs it measured on the way up must be judged at
        // their grown cost: at their old one each looks as if it fitted, and the frames over
        // the budget go on rung after rung.
        let cost = |r: usize, frame: usize| {
            let load = if frame >= 30 { 1.8 } else { 1.0 };
            load * if r < 4 { 300.0 } else { 480.0 + 20.0 * r as f64 }
        };
        let (times, rungs, moves) = run_in_time(1000.0, cost, 0.03, 70);
        assert_eq!(rungs[29], 9, "it climbed to the top first: {rungs:?}");
        let over = times[30..].iter().filter(|&&t| t > 1100.0).count();
        assert!(over <= 3, "{over} frames over the budget + 10 % after the change: {times:?} {rungs:?}");
        // It settles where the frames fit (probing the rung above now and then).
        let settled = rungs[40..].iter().filter(|&&r| r < 4).count();
        assert!(settled * 10 >= (rungs.len() - 40) * 9, "it settled where the frames fit: {rungs:?}");
        assert!(moves <= 12, "{moves} moves in 70 frames: popping ({rungs:?})");
    }

    #[test]
    fn a_loose_budget_rises_to_the_top() {
        let cost = |r: usize| 100.0 + 20.0 * r as f64;
        let (times, rungs, _) = run(1000.0, cost, 0.05, 60);
        assert_eq!(*rungs.last().unwrap(), 9, "{rungs:?}");
        assert!(times.iter().all(|&t| t < 1000.0));
    }

    #[test]
    fn a_slow_first_frame_does_not_keep_a_loose_budget_low() {
        // The first frame at the starting rung takes 10x (pipelines built): the controller
        // falls, then must come back once the rung's later frames would fit.
        let mut c = BudgetController::new(1000.0, rungs(10), 7);
        let mut first = true;
        let mut rungs_seen = Vec::new();
        for _ in 0..120 {
            let ms = if first { 5000.0 } else { 100.0 + 20.0 * c.rung() as f64 };
            first = false;
            rungs_seen.push(c.rung());
            c.observe(ms);
        }
        assert!(rungs_seen[1] < 7, "it fell after the slow frame: {rungs_seen:?}");
        // The first frame measured nothing: the starting rung is not blocked for a back-off,
        // so the controller climbs back one rung per hold.
        let back = 1 + 2 * HOLD_FRAMES as usize + 1;
        assert!(rungs_seen[back] >= 7, "back at the starting rung by frame {back}: {rungs_seen:?}");
        assert_eq!(*rungs_seen.last().unwrap(), 9, "it rose to the top again: {rungs_seen:?}");
    }

    #[test]
    fn a_failed_probe_backs_off() {
        // Rung 8 is far over a budget that rung 7 meets with room: probes of 8 must not repeat
        // every few frames.
        let cost = |r: usize| if r >= 8 { 2000.0 } else { 500.0 };
        let (_, rungs, _) = run(1000.0, cost, 0.0, 120);
        let probes = rungs.windows(2).filter(|w| w[0] == 7 && w[1] == 8).count();
        assert!((1..=3).contains(&probes), "{probes} probes in 120 frames: {rungs:?}");
    }

    #[test]
    fn the_ladder_is_cheapest_first_and_names_the_levels() {
        let analysis = SceneAnalysis { meshes: 2, spot_light: true, ..SceneAnalysis::default() };
        let settings = SettingsDescription::default();
        let ladder = ladder(&analysis, &settings, true);
        assert_eq!(ladder.first().unwrap().occlusion, Occlusion::Off);
        // Only the cheapest rung draws the simplified meshes; every level's own draws them whole.
        assert_eq!(ladder[0].camera_lod(), Some((CAMERA_LOD_RATIO, CAMERA_LOD_ERROR)));
        assert_eq!(FrameParameters { camera_detail: 1.0, ..ladder[0] }, ladder[1]);
        assert!(ladder[1..].iter().all(|p| p.camera_lod().is_none()), "{ladder:?}");
        assert_eq!(ladder.last().unwrap().level, Quality::Accurate);
        assert_eq!(ladder.last().unwrap().occlusion, Occlusion::Clusters);
        // Between balanced and accurate: balanced's visibility with accurate's near field.
        let step = ladder[ladder.len() - 2];
        assert_eq!((step.level, step.occlusion, step.near_field), (Quality::Accurate, Occlusion::Disks, 4.0));
        assert!(ladder.iter().any(|p| p.level == Quality::Balanced));
        let c = BudgetController::at_level(100.0, ladder.clone(), Quality::Balanced);
        assert_eq!(c.parameters().level, Quality::Balanced);
        assert_eq!(c.parameters(), level_parameters(Quality::Balanced, &analysis, &settings));
        assert!(super::ladder(&analysis, &settings, false).iter().all(|p| p.resolution_scale == 1.0));
        // With the differential pass (the default `settings.mr`): every rung below fast's own
        // thins the receivers, the rung before fast is fast's parameters with them.
        // (fast's own rung may carry balanced's name: here their parameters are the same.)
        let own = level_parameters(Quality::Fast, &analysis, &settings);
        let fast = ladder.iter().position(|p| FrameParameters { level: Quality::Fast, ..*p } == own).unwrap();
        // At half size they are thinned again.
        let thinned = |p: &FrameParameters| match p.resolution_scale <= 0.5 {
            true => RECEIVERS_STEP * RECEIVERS_STEP,
            false => RECEIVERS_STEP,
        };
        assert!(ladder[..fast].iter().all(|p| p.receivers_step == thinned(p)), "{ladder:?}");
        assert_eq!(ladder[0].receivers_step, RECEIVERS_STEP * RECEIVERS_STEP);
        assert!(ladder[fast..].iter().all(|p| p.receivers_step == 1), "{ladder:?}");
        assert_eq!(ladder[fast - 1], FrameParameters { receivers_step: RECEIVERS_STEP, ..own });
        // Without it no rung does, and that rung is gone; without scaling (a stream) they still do.
        let mut plain = settings.clone();
        plain.mr = MrSettings { differential: false, ..settings.mr };
        let plain = super::ladder(&analysis, &plain, true);
        assert_eq!(plain.len(), ladder.len() - 1, "{plain:?}");
        assert!(plain.iter().all(|p| p.receivers_step == 1), "{plain:?}");
        let stream = super::ladder(&analysis, &settings, false);
        assert!(stream.iter().any(|p| p.receivers_step == RECEIVERS_STEP), "{stream:?}");
        assert_eq!(stream[0].receivers_step, RECEIVERS_STEP * RECEIVERS_STEP, "{stream:?}");
    }

    /// The upscale is bilinear with pixel centres aligned: every output pixel equals the
    /// textbook formula evaluated on its own (here on a gradient and noise, 5x3 to 13x7), and
    /// a single texel fills the output.
    #[test]
    fn upscaling_is_bilinear_with_centres_aligned() {
        let (w, h, ow, oh) = (5usize, 3usize, 13usize, 7usize);
        let src: Vec<[u8; 3]> =
            (0..w * h).map(|i| [(i * 17 % 256) as u8, (i * 40 % 256) as u8, ((i * i * 7) % 256) as u8]).collect();
        let up = upscale_rgb(&src, w as u32, h as u32, ow as u32, oh as u32);
        for (i, got) in up.iter().enumerate() {
            let (ox, oy) = (i % ow, i / ow);
            let x = ((ox as f32 + 0.5) * w as f32 / ow as f32 - 0.5).clamp(0.0, (w - 1) as f32);
            let y = ((oy as f32 + 0.5) * h as f32 / oh as f32 - 0.5).clamp(0.0, (h - 1) as f32);
            let (x0, y0) = (x.floor() as usize, y.floor() as usize);
            let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
            let (fx, fy) = (x - x0 as f32, y - y0 as f32);
            for c in 0..3 {
                let p = |x: usize, y: usize| f32::from(src[y * w + x][c]);
                let top = p(x0, y0) * (1.0 - fx) + p(x1, y0) * fx;
                let bottom = p(x0, y1) * (1.0 - fx) + p(x1, y1) * fx;
                let want = (top * (1.0 - fy) + bottom * fy).round().clamp(0.0, 255.0) as u8;
                assert_eq!(got[c], want, "pixel ({ox}, {oy}) channel {c}");
            }
        }
        // A single texel fills the whole output.
        assert_eq!(upscale_rgb(&[[7, 8, 9]], 1, 1, 3, 2), vec![[7, 8, 9]; 6]);
    }

    #[test]
    fn upscaling_keeps_a_flat_image_and_its_size() {
        let flat = vec![[10, 20, 30]; 4 * 3];
        let up = upscale_rgb(&flat, 4, 3, 8, 6);
        assert_eq!(up.len(), 48);
        assert!(up.iter().all(|p| *p == [10, 20, 30]));
        assert_eq!(mean_abs_change(&flat, &flat), 0.0);
        assert_eq!(mean_abs_change(&[[0, 0, 0]], &[[3, 6, 9]]), 6.0);
    }
}

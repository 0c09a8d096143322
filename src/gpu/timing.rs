//! Per-stage timing: GPU timestamp queries where the adapter has them, otherwise wall time of
//! each stage submitted and waited for on its own. Every report says which one it is.

use super::{Gpu, GpuError};
use std::time::Instant;

/// Where a stage's duration came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TimingSource {
    GpuTimestamps,
    WallClock,
}

impl TimingSource {
    /// The name reports use (as serialised).
    pub fn as_str(self) -> &'static str {
        match self {
            TimingSource::GpuTimestamps => "gpu_timestamps",
            TimingSource::WallClock => "wall_clock",
        }
    }
}

/// Durations of named stages (ms), in recording order.
#[derive(Clone, Debug, serde::Serialize)]
pub struct StageTimings {
    pub source: TimingSource,
    pub stages: Vec<(String, f64)>,
}

impl StageTimings {
    /// Add `ms` to stage `name` (work of the stage done after the frame was submitted).
    pub fn add(&mut self, name: &str, ms: f64) {
        if let Some((_, total)) = self.stages.iter_mut().find(|(n, _)| n == name) {
            *total += ms;
        }
    }

    /// Sum of the stages whose names are in `names` (ms).
    pub fn total_of(&self, names: &[&str]) -> f64 {
        self.stages.iter().filter(|(n, _)| names.contains(&n.as_str())).map(|(_, ms)| ms).sum()
    }
}

/// The timestamp pair of one stage.
#[derive(Clone, Copy)]
pub struct Span<'a> {
    query_set: &'a wgpu::QuerySet,
    index: u32,
    /// With [`Span::share`]: this pass's first part, and the stage's parts in all.
    shared: Option<(usize, usize)>,
}

impl<'a> Span<'a> {
    pub fn compute(&self) -> wgpu::ComputePassTimestampWrites<'a> {
        wgpu::ComputePassTimestampWrites {
            query_set: self.query_set,
            beginning_of_pass_write_index: Some(2 * self.index),
            end_of_pass_write_index: Some(2 * self.index + 1),
        }
    }

    /// The span of a pass whose compute passes are parts `first..` of the `parts` that make
    /// the stage (two passes in one stage): its [`Span::compute_part`] counts from `first`
    /// and ends the stage at part `parts - 1` only.
    pub fn share(self, first: usize, parts: usize) -> Self {
        Self { shared: Some((first, parts)), ..self }
    }

    /// Pass `part` of `parts` compute passes that make one stage (of the stage's parts, with
    /// [`Span::share`]): the first writes the beginning timestamp, the last the end, and a pass
    /// in between none (`None`: wgpu refuses timestamp writes with neither index).
    pub fn compute_part(&self, part: usize, parts: usize) -> Option<wgpu::ComputePassTimestampWrites<'a>> {
        let (part, parts) = self.shared.map_or((part, parts), |(first, all)| (first + part, all));
        let begin = (part == 0).then_some(2 * self.index);
        let end = (part + 1 == parts).then_some(2 * self.index + 1);
        (begin.is_some() || end.is_some()).then_some(wgpu::ComputePassTimestampWrites {
            query_set: self.query_set,
            beginning_of_pass_write_index: begin,
            end_of_pass_write_index: end,
        })
    }

    pub fn render(&self) -> wgpu::RenderPassTimestampWrites<'a> {
        wgpu::RenderPassTimestampWrites {
            query_set: self.query_set,
            beginning_of_pass_write_index: Some(2 * self.index),
            end_of_pass_write_index: Some(2 * self.index + 1),
        }
    }
}

/// Records a frame's stages into one encoder and times each.
pub struct Recorder<'g> {
    gpu: &'g Gpu,
    encoder: wgpu::CommandEncoder,
    queries: Option<(wgpu::QuerySet, wgpu::Buffer)>,
    capacity: u32,
    names: Vec<String>,
    wall: Vec<f64>,
}

impl<'g> Recorder<'g> {
    /// A recorder for at most `stages` stages (the frame's techniques say how many).
    pub fn new(gpu: &'g Gpu, label: &str, stages: usize) -> Self {
        let capacity = stages.max(1) as u32;
        let queries = gpu.timestamps.then(|| {
            let set = gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some(&format!("{label}.timestamps")),
                ty: wgpu::QueryType::Timestamp,
                count: 2 * capacity,
            });
            let resolve = gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(&format!("{label}.timestamps_resolve")),
                size: 16 * capacity as u64,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            (set, resolve)
        });
        let encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) });
        Self { gpu, encoder, queries, capacity, names: Vec::new(), wall: Vec::new() }
    }

    /// Record stage `name`: `f` gets the encoder and, with timestamps, the span to pass to its
    /// pass descriptor. Without timestamps the stage is submitted and waited for on its own.
    pub fn stage<R>(
        &mut self,
        name: &str,
        f: impl FnOnce(&mut wgpu::CommandEncoder, Option<Span<'_>>) -> R,
    ) -> Result<R, GpuError> {
        assert!((self.names.len() as u32) < self.capacity, "Recorder capacity {} exceeded", self.capacity);
        let index = self.names.len() as u32;
        self.names.push(name.to_owned());
        if self.queries.is_none() {
            self.flush()?;
        }
        self.encoder.push_debug_group(name);
        match &self.queries {
            Some((set, _)) => {
                let r = f(&mut self.encoder, Some(Span { query_set: set, index, shared: None }));
                self.encoder.pop_debug_group();
                Ok(r)
            }
            None => {
                let start = Instant::now();
                let r = f(&mut self.encoder, None);
                self.encoder.pop_debug_group();
                self.flush()?;
                self.wall.push(start.elapsed().as_secs_f64() * 1e3);
                Ok(r)
            }
        }
    }

    /// Record work that is not a timed stage (copies, clears).
    pub fn encoder(&mut self) -> &mut wgpu::CommandEncoder {
        &mut self.encoder
    }

    fn flush(&mut self) -> Result<(), GpuError> {
        let encoder = std::mem::replace(
            &mut self.encoder,
            self.gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("relume.frame") }),
        );
        self.gpu.submit_and_wait(encoder)
    }

    /// Submit everything, wait, and return the stage durations.
    pub fn finish(mut self) -> Result<StageTimings, GpuError> {
        let n = self.names.len() as u32;
        if let Some((set, resolve)) = &self.queries
            && n > 0
        {
            self.encoder.resolve_query_set(set, 0..2 * n, resolve, 0);
        }
        self.flush()?;
        let (source, ms) = match &self.queries {
            Some((_, resolve)) => {
                let ticks: Vec<u64> = self.gpu.read_buffer(resolve, 2 * n as usize)?;
                let period = self.gpu.queue.get_timestamp_period() as f64;
                let ms = ticks.chunks(2).map(|t| t[1].saturating_sub(t[0]) as f64 * period * 1e-6).collect();
                (TimingSource::GpuTimestamps, ms)
            }
            None => (TimingSource::WallClock, self.wall),
        };
        Ok(StageTimings { source, stages: self.names.into_iter().zip(ms).collect() })
    }
}

//! Prometheus metrics in the text exposition format (version 0.0.4), written by hand: a few
//! counters, gauges and fixed-bucket histograms behind one mutex.

use std::collections::BTreeMap;
use std::fmt::Write;
use std::sync::Mutex;

use crate::gpu::timing::StageTimings;

/// Upper bounds of every histogram's buckets, seconds (lavapipe frames take seconds).
const BUCKETS: [f64; 16] =
    [0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0, 300.0];

/// Upper bounds of the error estimate's histogram (relative RMSE).
const ERROR_BUCKETS: [f64; 12] = [0.005, 0.01, 0.02, 0.03, 0.05, 0.075, 0.1, 0.15, 0.2, 0.3, 0.5, 1.0];

#[derive(Clone, Debug)]
struct Histogram {
    bounds: &'static [f64],
    /// Per bucket (not cumulative); the last counts values above every bound.
    counts: Vec<u64>,
    sum: f64,
    count: u64,
}

impl Default for Histogram {
    /// A histogram of durations, seconds.
    fn default() -> Self {
        Histogram::new(&BUCKETS)
    }
}

impl Histogram {
    fn new(bounds: &'static [f64]) -> Self {
        Histogram { bounds, counts: vec![0; bounds.len() + 1], sum: 0.0, count: 0 }
    }

    fn observe(&mut self, value: f64) {
        let bucket = self.bounds.iter().position(|&le| value <= le).unwrap_or(self.bounds.len());
        self.counts[bucket] += 1;
        self.sum += value;
        self.count += 1;
    }

    fn write(&self, out: &mut String, name: &str, labels: &str) {
        let mut cumulative = 0;
        let sep = if labels.is_empty() { "" } else { "," };
        for (le, count) in self.bounds.iter().zip(&self.counts) {
            cumulative += count;
            let _ = writeln!(out, "{name}_bucket{{{labels}{sep}le=\"{le}\"}} {cumulative}");
        }
        let _ = writeln!(out, "{name}_bucket{{{labels}{sep}le=\"+Inf\"}} {}", self.count);
        let braces = if labels.is_empty() { String::new() } else { format!("{{{labels}}}") };
        let _ = writeln!(out, "{name}_sum{braces} {}", self.sum);
        let _ = writeln!(out, "{name}_count{braces} {}", self.count);
    }
}

/// What the frames ran at and how far from exact they were estimated to be.
#[derive(Clone, Debug)]
struct FrameQuality {
    error_estimate: Histogram,
    frames_by_level: BTreeMap<String, u64>,
    /// The last frame's parameters (name, value), numeric ones only.
    parameters: BTreeMap<String, f64>,
    over_budget: u64,
    within_budget: u64,
}

impl Default for FrameQuality {
    fn default() -> Self {
        FrameQuality {
            error_estimate: Histogram::new(&ERROR_BUCKETS),
            frames_by_level: BTreeMap::new(),
            parameters: BTreeMap::new(),
            over_budget: 0,
            within_budget: 0,
        }
    }
}

#[derive(Default)]
struct Inner {
    quality: FrameQuality,
    /// (route, method, status) -> count.
    requests: BTreeMap<(String, String, u16), u64>,
    request_seconds: BTreeMap<String, Histogram>,
    frame_seconds: Histogram,
    gpu_seconds: BTreeMap<String, f64>,
    renders_rejected: u64,
    connections_refused: u64,
    dropped_frames: u64,
    stream_messages: BTreeMap<String, u64>,
    stream_errors: BTreeMap<String, u64>,
    gpu_memory: Option<GpuMemory>,
}

/// What the GPU device holds, as wgpu counts it (its `counters` feature), read by the GPU
/// thread after every job.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GpuMemory {
    /// Live buffers.
    pub buffers: u64,
    /// Live textures.
    pub textures: u64,
    /// Memory allocated to buffers, bytes.
    pub buffer_bytes: u64,
    /// Memory allocated to textures, bytes.
    pub texture_bytes: u64,
    /// Device memory allocations (blocks that buffers and textures are placed in).
    pub allocations: u64,
}

/// The service's metrics.
#[derive(Default)]
pub struct Metrics {
    inner: Mutex<Inner>,
    /// What each GPU worker counts, by its number (the `worker` label).
    workers: Mutex<BTreeMap<usize, WorkerCounts>>,
}

/// The counters of one GPU worker.
#[derive(Clone, Copy, Debug, Default)]
struct WorkerCounts {
    frames: u64,
    frame_seconds: f64,
    gpu_memory: Option<GpuMemory>,
}

/// A per-worker metric family: name, type, help, and its value for one worker.
type WorkerFamily = (&'static str, &'static str, &'static str, fn(&WorkerGauges, &WorkerCounts) -> String);

/// One GPU worker's gauges, read when the metrics are scraped.
pub struct WorkerGauges {
    /// Its number: the `worker` label.
    pub worker: usize,
    pub adapter: String,
    /// 0 while it gets no new work after its device was lost.
    pub up: bool,
    pub queue_depth: usize,
    pub scenes: usize,
    pub streams: usize,
    pub device_losses: u64,
}

/// Values read when the metrics are scraped.
pub struct Gauges {
    pub queue_depth: usize,
    pub queue_capacity: usize,
    pub scenes: usize,
    pub streams: usize,
    /// HTTP connections open (upgraded streams not included).
    pub connections: usize,
}

impl Metrics {
    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        // A panic while holding the lock leaves counters, which stay usable.
        self.inner.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// One answered HTTP request; `route` is the matched route pattern.
    pub fn record_request(&self, route: &str, method: &str, status: u16, seconds: f64) {
        let mut inner = self.lock();
        *inner.requests.entry((route.to_owned(), method.to_owned(), status)).or_default() += 1;
        inner.request_seconds.entry(route.to_owned()).or_default().observe(seconds);
    }

    /// One frame rendered on the GPU thread: its wall time and its stages' times.
    pub fn record_frame(&self, seconds: f64, timings: &StageTimings) {
        let mut inner = self.lock();
        inner.frame_seconds.observe(seconds);
        for (stage, ms) in &timings.stages {
            *inner.gpu_seconds.entry(stage.clone()).or_default() += ms / 1e3;
        }
    }

    /// A rendered frame's error estimate (relative RMSE, when it had one), the level and
    /// parameters it ran at, and whether it went over its budget (when it had one).
    pub fn record_frame_quality(
        &self,
        error_estimate: Option<f64>,
        parameters: &crate::renderer::budget::FrameParameters,
        over_budget: Option<bool>,
    ) {
        let mut inner = self.lock();
        let q = &mut inner.quality;
        if let Some(e) = error_estimate {
            q.error_estimate.observe(e);
        }
        *q.frames_by_level.entry(parameters.level.name().to_owned()).or_default() += 1;
        for (name, value) in parameters.pairs() {
            if let Ok(value) = value.parse::<f64>() {
                q.parameters.insert(name, value);
            }
        }
        match over_budget {
            Some(true) => q.over_budget += 1,
            Some(false) => q.within_budget += 1,
            None => {}
        }
    }

    /// A frame rendered by GPU worker `worker`: [`Metrics::record_frame`], and its own count.
    pub fn record_worker_frame(&self, worker: usize, seconds: f64, timings: &StageTimings) {
        self.record_frame(seconds, timings);
        let mut workers = self.workers.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        let counts = workers.entry(worker).or_default();
        counts.frames += 1;
        counts.frame_seconds += seconds;
    }

    /// What worker `worker`'s device holds now; the unlabelled gauges are the sum over the
    /// workers.
    pub fn set_worker_gpu_memory(&self, worker: usize, memory: Option<GpuMemory>) {
        let mut workers = self.workers.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        workers.entry(worker).or_default().gpu_memory = memory;
        let total = workers.values().filter_map(|w| w.gpu_memory).reduce(|a, b| GpuMemory {
            buffers: a.buffers + b.buffers,
            textures: a.textures + b.textures,
            buffer_bytes: a.buffer_bytes + b.buffer_bytes,
            texture_bytes: a.texture_bytes + b.texture_bytes,
            allocations: a.allocations + b.allocations,
        });
        drop(workers);
        self.set_gpu_memory(total);
    }

    /// The per-worker families (label `worker`), appended to `out` (text from
    /// [`Metrics::render`]).
    pub fn render_workers(&self, workers: &[WorkerGauges], out: &mut String) {
        let counts = self.workers.lock().unwrap_or_else(|poisoned| poisoned.into_inner()).clone();
        let header = |out: &mut String, name: &str, kind: &str, help: &str| {
            let _ = writeln!(out, "# HELP {name} {help}\n# TYPE {name} {kind}");
        };
        let count = |w: &WorkerGauges| counts.get(&w.worker).copied().unwrap_or_default();
        header(out, "relume_worker_info", "gauge", "GPU workers, one per device: the adapter (always 1).");
        for w in workers {
            let _ = writeln!(out, "relume_worker_info{{worker=\"{}\",adapter=\"{}\"}} 1", w.worker, escape(&w.adapter));
        }
        let families: [WorkerFamily; 7] = [
            ("relume_worker_up", "gauge", "1 when the worker takes new work, 0 after its device was lost.", |w, _| {
                u8::from(w.up).to_string()
            }),
            ("relume_worker_queue_depth", "gauge", "Renders waiting for the worker.", |w, _| w.queue_depth.to_string()),
            ("relume_worker_scenes", "gauge", "Scenes uploaded to the worker.", |w, _| w.scenes.to_string()),
            ("relume_worker_streams", "gauge", "Streams pinned to the worker.", |w, _| w.streams.to_string()),
            ("relume_worker_device_losses_total", "counter", "Devices the worker lost.", |w, _| {
                w.device_losses.to_string()
            }),
            ("relume_worker_frames_total", "counter", "Frames the worker rendered.", |_, c| c.frames.to_string()),
            ("relume_worker_frame_seconds_total", "counter", "Wall time of the worker's frames.", |_, c| {
                c.frame_seconds.to_string()
            }),
        ];
        for (name, kind, help, value) in families {
            header(out, name, kind, help);
            for w in workers {
                let _ = writeln!(out, "{name}{{worker=\"{}\"}} {}", w.worker, value(w, &count(w)));
            }
        }
    }

    /// A render refused because the queue was full.
    pub fn record_rejected_render(&self) {
        self.lock().renders_rejected += 1;
    }

    /// A connection refused because `max_connections` were open.
    pub fn record_refused_connection(&self) {
        self.lock().connections_refused += 1;
    }

    /// A stream frame dropped (a newer one replaced it, or the queue was full).
    pub fn record_dropped_frame(&self) {
        self.lock().dropped_frames += 1;
    }

    /// A stream message received, by kind (`rgbd_frame`, `control`, `invalid`).
    pub fn record_stream_message(&self, kind: &str) {
        *self.lock().stream_messages.entry(kind.to_owned()).or_default() += 1;
    }

    /// An `Error` sent on a stream, by code.
    pub fn record_stream_error(&self, code: &str) {
        *self.lock().stream_errors.entry(code.to_owned()).or_default() += 1;
    }

    /// What the GPU device holds now (`None`: the backend does not count it).
    pub fn set_gpu_memory(&self, memory: Option<GpuMemory>) {
        self.lock().gpu_memory = memory;
    }

    pub fn gpu_memory(&self) -> Option<GpuMemory> {
        self.lock().gpu_memory
    }

    /// Mean wall time of the frames so far, seconds (None before the first).
    pub fn mean_frame_seconds(&self) -> Option<f64> {
        let inner = self.lock();
        (inner.frame_seconds.count > 0).then(|| inner.frame_seconds.sum / inner.frame_seconds.count as f64)
    }

    /// The text exposition format.
    pub fn render(&self, gauges: &Gauges) -> String {
        let inner = self.lock().clone_for_render();
        let mut out = String::new();
        let header = |out: &mut String, name: &str, kind: &str, help: &str| {
            let _ = writeln!(out, "# HELP {name} {help}\n# TYPE {name} {kind}");
        };

        header(&mut out, "relume_http_requests_total", "counter", "HTTP requests answered.");
        for ((route, method, status), count) in &inner.requests {
            let _ = writeln!(
                out,
                "relume_http_requests_total{{route=\"{}\",method=\"{}\",status=\"{status}\"}} {count}",
                escape(route),
                escape(method)
            );
        }
        header(&mut out, "relume_http_request_duration_seconds", "histogram", "HTTP request latency.");
        for (route, histogram) in &inner.request_seconds {
            histogram.write(&mut out, "relume_http_request_duration_seconds", &format!("route=\"{}\"", escape(route)));
        }
        header(&mut out, "relume_frame_duration_seconds", "histogram", "Wall time of a frame on the GPU thread.");
        inner.frame_seconds.write(&mut out, "relume_frame_duration_seconds", "");
        let q = &inner.quality;
        header(
            &mut out,
            "relume_frame_error_estimate",
            "histogram",
            "Estimated relative RMSE of each frame's indirect light against the exact reference.",
        );
        q.error_estimate.write(&mut out, "relume_frame_error_estimate", "");
        header(&mut out, "relume_frames_by_level_total", "counter", "Frames rendered, by the level they ran at.");
        for (level, count) in &q.frames_by_level {
            let _ = writeln!(out, "relume_frames_by_level_total{{level=\"{}\"}} {count}", escape(level));
        }
        header(
            &mut out,
            "relume_frame_parameter",
            "gauge",
            "The last frame's parameters (vals_step, near_field, ...).",
        );
        for (name, value) in &q.parameters {
            let _ = writeln!(out, "relume_frame_parameter{{name=\"{}\"}} {value}", escape(name));
        }
        header(&mut out, "relume_frames_budget_total", "counter", "Frames with a budget, by whether they met it.");
        let _ = writeln!(out, "relume_frames_budget_total{{met=\"true\"}} {}", q.within_budget);
        let _ = writeln!(out, "relume_frames_budget_total{{met=\"false\"}} {}", q.over_budget);
        header(&mut out, "relume_gpu_seconds_total", "counter", "Time spent in each GPU stage.");
        for (stage, seconds) in &inner.gpu_seconds {
            let _ = writeln!(out, "relume_gpu_seconds_total{{stage=\"{}\"}} {seconds}", escape(stage));
        }
        let counts: [(&str, &str, &str, &dyn std::fmt::Display); 8] = [
            ("relume_render_queue_depth", "gauge", "Renders waiting for the GPU thread.", &gauges.queue_depth),
            (
                "relume_render_queue_capacity",
                "gauge",
                "Most renders that may wait (max_queue).",
                &gauges.queue_capacity,
            ),
            (
                "relume_renders_rejected_total",
                "counter",
                "Renders refused because the queue was full.",
                &inner.renders_rejected,
            ),
            (
                "relume_dropped_frames_total",
                "counter",
                "Stream frames dropped before rendering.",
                &inner.dropped_frames,
            ),
            ("relume_scenes", "gauge", "Scenes held.", &gauges.scenes),
            ("relume_streams", "gauge", "Open WebSocket streams.", &gauges.streams),
            (
                "relume_connections",
                "gauge",
                "HTTP connections open (upgraded streams not included).",
                &gauges.connections,
            ),
            (
                "relume_connections_refused_total",
                "counter",
                "Connections refused at max_connections.",
                &inner.connections_refused,
            ),
        ];
        for (name, kind, help, value) in counts {
            header(&mut out, name, kind, help);
            let _ = writeln!(out, "{name} {value}");
        }
        header(&mut out, "relume_stream_messages_total", "counter", "Stream messages received, by kind.");
        for (kind, count) in &inner.stream_messages {
            let _ = writeln!(out, "relume_stream_messages_total{{kind=\"{}\"}} {count}", escape(kind));
        }
        header(&mut out, "relume_stream_errors_total", "counter", "Error messages sent on streams, by code.");
        for (code, count) in &inner.stream_errors {
            let _ = writeln!(out, "relume_stream_errors_total{{code=\"{}\"}} {count}", escape(code));
        }
        if let Some(memory) = inner.gpu_memory {
            for (name, help, value) in [
                ("relume_gpu_buffers", "Live GPU buffers (wgpu's count).", memory.buffers),
                ("relume_gpu_textures", "Live GPU textures (wgpu's count).", memory.textures),
                ("relume_gpu_buffer_bytes", "GPU memory allocated to buffers, bytes.", memory.buffer_bytes),
                ("relume_gpu_texture_bytes", "GPU memory allocated to textures, bytes.", memory.texture_bytes),
                ("relume_gpu_memory_allocations", "GPU memory allocations.", memory.allocations),
            ] {
                header(&mut out, name, "gauge", help);
                let _ = writeln!(out, "{name} {value}");
            }
        }
        out
    }
}

impl Inner {
    /// A copy, so the lock is not held while formatting.
    fn clone_for_render(&self) -> Inner {
        Inner {
            quality: self.quality.clone(),
            requests: self.requests.clone(),
            request_seconds: self.request_seconds.clone(),
            frame_seconds: self.frame_seconds.clone(),
            gpu_seconds: self.gpu_seconds.clone(),
            renders_rejected: self.renders_rejected,
            connections_refused: self.connections_refused,
            dropped_frames: self.dropped_frames,
            stream_messages: self.stream_messages.clone(),
            stream_errors: self.stream_errors.clone(),
            gpu_memory: self.gpu_memory,
        }
    }
}

/// A label value with `\`, `"` and newlines escaped.
fn escape(value: &str) -> String {
    value.replace('\\', "\\\\").replace('"', "\\\"").replace('\n', "\\n")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::timing::TimingSource;

    #[test]
    fn histograms_are_cumulative_and_labels_escaped() {
        let metrics = Metrics::default();
        metrics.record_request("/v1/scenes", "POST", 201, 0.003);
        metrics.record_request("/v1/scenes", "POST", 201, 2.0);
        metrics.record_request("/a\"b", "GET", 404, 1e6);
        let timings = StageTimings { source: TimingSource::WallClock, stages: vec![("gather".to_owned(), 250.0)] };
        metrics.record_frame(0.3, &timings);
        metrics.record_frame(0.1, &timings);
        let parameters = crate::renderer::budget::FrameParameters {
            level: crate::scene::Quality::Fast,
            occlusion: crate::scene::Occlusion::Disks,
            near_field: 0.0,
            vals_step: 2,
            resolution_scale: 1.0,
            camera_detail: 1.0,
            receivers_step: 1,
        };
        metrics.record_frame_quality(Some(0.04), &parameters, Some(true));
        metrics.record_frame_quality(None, &parameters, None);
        let text = metrics.render(&Gauges { queue_depth: 2, queue_capacity: 8, scenes: 1, streams: 0, connections: 1 });
        assert!(text.contains("relume_http_requests_total{route=\"/v1/scenes\",method=\"POST\",status=\"201\"} 2"));
        assert!(text.contains("relume_http_request_duration_seconds_bucket{route=\"/v1/scenes\",le=\"0.001\"} 0"));
        assert!(text.contains("relume_http_request_duration_seconds_bucket{route=\"/v1/scenes\",le=\"0.005\"} 1"));
        assert!(text.contains("relume_http_request_duration_seconds_bucket{route=\"/v1/scenes\",le=\"2.5\"} 2"));
        assert!(text.contains("relume_http_request_duration_seconds_bucket{route=\"/a\\\"b\",le=\"300\"} 0"));
        assert!(text.contains("relume_http_request_duration_seconds_bucket{route=\"/a\\\"b\",le=\"+Inf\"} 1"));
        assert!(text.contains("relume_frame_duration_seconds_count 2"));
        assert!(text.contains("relume_frame_duration_seconds_bucket{le=\"0.25\"} 1"));
        assert!(text.contains("relume_gpu_seconds_total{stage=\"gather\"} 0.5"));
        assert!(text.contains("relume_render_queue_depth 2"));
        assert!(text.contains("relume_frame_error_estimate_bucket{le=\"0.03\"} 0"), "{text}");
        assert!(text.contains("relume_frame_error_estimate_bucket{le=\"0.05\"} 1"));
        assert!(text.contains("relume_frame_error_estimate_count 1"));
        assert!(text.contains("relume_frames_by_level_total{level=\"fast\"} 2"));
        assert!(text.contains("relume_frame_parameter{name=\"vals_step\"} 2"));
        assert!(text.contains("relume_frames_budget_total{met=\"false\"} 1"));
        assert!(!text.contains("relume_gpu_buffer_bytes"), "unknown until a backend counts it");
        metrics.set_gpu_memory(Some(GpuMemory { buffers: 3, buffer_bytes: 4096, ..GpuMemory::default() }));
        let text = metrics.render(&Gauges { queue_depth: 2, queue_capacity: 8, scenes: 1, streams: 0, connections: 1 });
        assert!(text.contains("# TYPE relume_gpu_buffer_bytes gauge\nrelume_gpu_buffer_bytes 4096\n"), "{text}");
        assert!(text.contains("relume_gpu_buffers 3\n"));
        assert!((metrics.mean_frame_seconds().expect("frames") - 0.2).abs() < 1e-12);
        // Every sample line belongs to a declared metric family.
        for line in text.lines().filter(|l| !l.starts_with('#')) {
            let name = line.split(['{', ' ']).next().expect("name");
            let family = name.trim_end_matches("_bucket").trim_end_matches("_sum").trim_end_matches("_count");
            assert!(text.contains(&format!("# TYPE {family} ")) || text.contains(&format!("# TYPE {name} ")), "{line}");
        }
    }
}

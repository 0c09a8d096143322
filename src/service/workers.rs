//! The GPU workers of one process (`--adapters`): one [`GpuWorker`] (thread and device) per
//! GPU, and the routing between them.
//!
//! - A scene is created on one worker: the least loaded, fewest scenes on a tie. With several
//!   workers the loaded scene is also kept ([`SceneSource`]), and another worker uploads it on
//!   its own thread the first time a render or stream frame routed there needs it.
//! - An HTTP render goes to the least-loaded worker holding the scene, else to any (which
//!   uploads it). When every holder has [`SPILL_LOAD`] renders or streams and another worker is
//!   idle, the idle one takes it, so a busy scene spreads over the GPUs. A worker whose queue is
//!   full passes the render to the next; a render that fails because the device was lost is
//!   run again once on another worker that is up.
//! - A stream is pinned to one worker for its life ([`StreamPin`]); it moves only when that
//!   worker's device is lost.
//! - A worker whose device was lost gets no new work for `worker_quarantine_seconds` while
//!   another is up (its thread opens a new device and keeps its scenes meanwhile).
//!
//! Load is a worker's renders waiting and running plus its pinned streams. The queue limits
//! (`max_queue`, `max_client_queue`) hold per worker.

use std::collections::HashMap;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::oneshot;

use crate::gpu::Gpu;
use crate::mr::environment::Environment;
use crate::scene::Scene;

use super::config::{AdapterSelection, Config};
use super::gpu_worker::{
    FrameJob, GpuWorker, RenderJob, RenderOutput, SceneSource, StreamFrameJob, WorkerError, WorkerStatus,
};
use super::metrics::{Metrics, WorkerGauges};
use super::schedule::ClientId;

/// Load (renders waiting or running, streams) of every worker holding a scene at or above
/// which an idle worker that does not hold it takes its next render.
pub const SPILL_LOAD: usize = 2;

/// The workers and where each scene is.
pub struct Workers {
    workers: Vec<GpuWorker>,
    /// The loaded scenes, by id, for uploads to more workers (kept only with several).
    sources: Mutex<HashMap<String, Arc<SceneSource>>>,
    quarantine: Duration,
}

impl Workers {
    /// Starts one worker per adapter `config.adapters` selects, each waiting until its device
    /// is open. Blocks: call it from `spawn_blocking`.
    pub fn start(config: &Config, metrics: Arc<Metrics>) -> Result<Workers, WorkerError> {
        // One worker takes wgpu's own choice: no need to list the adapters.
        let names: Vec<String> = match config.adapters {
            AdapterSelection::Count(1) => Vec::new(),
            _ => Gpu::adapters().iter().map(|info| format!("{} ({:?})", info.name, info.backend)).collect(),
        };
        let adapters = config
            .adapters
            .workers(&names)
            .map_err(|message| WorkerError::Gpu(crate::gpu::GpuError::Unsupported(format!("--adapters: {message}"))))?;
        if adapters.len() > names.len().max(1) {
            tracing::warn!(workers = adapters.len(), adapters = names.len(), "several devices share one adapter");
        }
        let workers = adapters
            .into_iter()
            .enumerate()
            .map(|(index, adapter)| GpuWorker::start_on(index, adapter, &config.limits, metrics.clone()))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Workers::new(workers, Duration::from_secs(config.worker_quarantine_seconds)))
    }

    /// The workers given (numbered 0.. in order), a lost device keeping a worker out of
    /// routing for `quarantine`.
    pub fn new(workers: Vec<GpuWorker>, quarantine: Duration) -> Workers {
        assert!(!workers.is_empty(), "at least one GPU worker");
        Workers { workers, sources: Mutex::default(), quarantine }
    }

    pub fn len(&self) -> usize {
        self.workers.len()
    }

    pub fn is_empty(&self) -> bool {
        self.workers.is_empty()
    }

    pub fn get(&self, index: usize) -> Option<&GpuWorker> {
        self.workers.get(index)
    }

    /// The adapters, once each, `; ` between them.
    pub fn adapter(&self) -> String {
        let mut names: Vec<&str> = Vec::new();
        for worker in &self.workers {
            if !names.contains(&worker.adapter()) {
                names.push(worker.adapter());
            }
        }
        names.join("; ")
    }

    /// Renders waiting, all workers.
    pub fn queue_depth(&self) -> usize {
        self.workers.iter().map(GpuWorker::queue_depth).sum()
    }

    /// Most renders that may wait, all workers.
    pub fn queue_capacity(&self) -> usize {
        self.workers.iter().map(GpuWorker::queue_capacity).sum()
    }

    /// Workers that take new work now.
    pub fn up(&self) -> usize {
        self.workers.iter().filter(|w| w.healthy(self.quarantine)).count()
    }

    /// Whether every worker that is up (every worker, when none is) has its queue full.
    pub fn saturated(&self) -> bool {
        let full = |w: &&GpuWorker| w.queue_depth() >= w.queue_capacity();
        match self.up() {
            0 => self.workers.iter().all(|w| full(&w)),
            _ => self.workers.iter().filter(|w| w.healthy(self.quarantine)).all(|w| full(&w)),
        }
    }

    fn sources(&self) -> std::sync::MutexGuard<'_, HashMap<String, Arc<SceneSource>>> {
        self.sources.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    fn source(&self, id: &str) -> Option<Arc<SceneSource>> {
        self.sources().get(id).cloned()
    }

    /// The workers in the order scene `id`'s next job should try them, leaving out `tried`.
    fn candidates(&self, id: &str, tried: &[usize]) -> Vec<usize> {
        let up = |w: &GpuWorker| w.healthy(self.quarantine);
        let remaining = || self.workers.iter().filter(|w| !tried.contains(&w.index()));
        let mut holders: Vec<&GpuWorker> = remaining().filter(|w| up(w) && w.holds(id)).collect();
        holders.sort_by_key(|w| (w.load(), w.index()));
        // Workers that do not hold it can take it only when it can be uploaded there.
        let mut others: Vec<&GpuWorker> = if self.workers.len() == 1 || self.source(id).is_some() {
            remaining().filter(|w| up(w) && !w.holds(id)).collect()
        } else {
            Vec::new()
        };
        others.sort_by_key(|w| (w.load(), w.scenes(), w.index()));
        if let (Some(holder), Some(other)) = (holders.first(), others.first())
            && holder.load() >= SPILL_LOAD
            && other.load() == 0
        {
            holders.insert(0, others.remove(0));
        }
        let mut down: Vec<&GpuWorker> = remaining().filter(|w| !up(w)).collect();
        down.sort_by_key(|w| (w.load(), w.index()));
        let order: Vec<usize> = holders.into_iter().chain(others).chain(down).map(GpuWorker::index).collect();
        if order.is_empty() && tried.is_empty() {
            // A scene being deleted that no worker holds: any worker answers (not found).
            return vec![0];
        }
        order
    }

    /// The first of [`Workers::candidates`] with nothing tried.
    fn first(&self, id: &str) -> usize {
        self.candidates(id, &[]).first().copied().unwrap_or(0)
    }

    /// Builds the scene on the worker [`Workers::candidates`] puts first; with several
    /// workers, keeps it for the others.
    pub async fn add_scene(&self, id: &str, scene: Scene, environment: Environment) -> Result<(), WorkerError> {
        if self.workers.len() > 1 {
            let source = Arc::new(SceneSource::new(scene.clone(), environment.clone()));
            self.sources().insert(id.to_owned(), source);
        }
        let first = self.first(id);
        let result = self.workers[first].add_scene(id, scene, environment).await;
        if result.is_err() {
            self.sources().remove(id);
        }
        result
    }

    /// Drops the scene from every worker; false when none held it. Renders of it still queued
    /// fail with [`WorkerError::SceneNotFound`] and upload it nowhere.
    pub async fn remove_scene(&self, id: &str) -> Result<bool, WorkerError> {
        if let Some(source) = self.sources().remove(id) {
            source.deleted.store(true, Ordering::SeqCst);
        }
        let mut removed = false;
        for worker in &self.workers {
            removed |= worker.remove_scene(id).await?;
        }
        Ok(removed)
    }

    /// Renders scene `id` (see the module docs for where).
    pub async fn render(&self, client: ClientId, id: &str, job: RenderJob) -> Result<RenderOutput, WorkerError> {
        let source = self.source(id);
        let mut tried = Vec::new();
        let mut refused = None;
        let mut lost = false;
        while let Some(&index) = self.candidates(id, &tried).first() {
            if lost && !self.workers[index].healthy(self.quarantine) {
                break;
            }
            tried.push(index);
            let answer = match self.workers[index].try_render(client, id, FrameJob::Render(job.clone()), source.clone())
            {
                Ok(answer) => answer,
                Err(error @ WorkerError::QueueFull { .. }) => {
                    refused.get_or_insert(error);
                    continue;
                }
                Err(error) => return Err(error),
            };
            match answer.await.map_err(|_| WorkerError::Stopped)? {
                Err(WorkerError::DeviceLost) if !lost && self.workers.len() > 1 => {
                    tracing::warn!(worker = index, scene = %id, "device lost during a render: trying another worker");
                    lost = true;
                }
                result => return result,
            }
        }
        Err(if lost { WorkerError::DeviceLost } else { refused.unwrap_or(WorkerError::Stopped) })
    }

    /// Pins a new stream of scene `id` to the worker [`Workers::candidates`] puts first.
    pub fn pin(&self, id: &str) -> StreamPin {
        StreamPin::new(&self.workers[self.first(id)])
    }

    /// Queues a stream frame on the stream's worker; when that worker's device was lost and
    /// another is up, the stream moves there first.
    pub fn try_render_stream_frame(
        &self,
        pin: &mut StreamPin,
        client: ClientId,
        id: &str,
        job: StreamFrameJob,
    ) -> Result<oneshot::Receiver<Result<RenderOutput, WorkerError>>, WorkerError> {
        if !self.workers[pin.worker].healthy(self.quarantine) {
            let best = self.first(id);
            if best != pin.worker && self.workers[best].healthy(self.quarantine) {
                tracing::warn!(from = pin.worker, to = best, scene = %id, "stream moved: its worker lost its device");
                *pin = StreamPin::new(&self.workers[best]);
            }
        }
        self.workers[pin.worker].try_render(client, id, FrameJob::Stream(Box::new(job)), self.source(id))
    }

    /// Test hook: worker 0 loses its device during its next render ([`GpuWorker::lose_device`]).
    pub fn lose_device(&self) -> Result<(), WorkerError> {
        self.workers[0].lose_device()
    }

    /// Lets every worker finish the jobs queued, then stops and joins their threads.
    pub async fn stop(&self) {
        for worker in &self.workers {
            worker.stop().await;
        }
    }

    /// Every worker's gauges for `/metrics`.
    pub fn gauges(&self) -> Vec<WorkerGauges> {
        self.workers
            .iter()
            .map(|w| WorkerGauges {
                worker: w.index(),
                adapter: w.adapter().to_owned(),
                up: w.healthy(self.quarantine),
                queue_depth: w.queue_depth(),
                scenes: w.scenes(),
                streams: w.streams(),
                device_losses: w.device_losses(),
            })
            .collect()
    }
}

/// A stream's worker, counted in its load while the stream lives.
pub struct StreamPin {
    worker: usize,
    status: Arc<WorkerStatus>,
}

impl StreamPin {
    fn new(worker: &GpuWorker) -> StreamPin {
        worker.status().streams.fetch_add(1, Ordering::SeqCst);
        StreamPin { worker: worker.index(), status: worker.status().clone() }
    }

    /// The worker's number.
    pub fn worker(&self) -> usize {
        self.worker
    }
}

impl Drop for StreamPin {
    fn drop(&mut self) {
        self.status.streams.fetch_sub(1, Ordering::SeqCst);
    }
}

//! The one thread that owns the GPU. It holds a [`Backend`] (in the service the [`Gpu`] and
//! one [`Renderer`] and [`MrPipeline`] per scene: [`GpuBackend`]) and takes jobs from the [`FairQueue`]; every job
//! answers on its own oneshot channel. Handlers never touch the device and never block a
//! tokio worker on it.
//!
//! Renders (HTTP renders and stream frames) wait per client and are counted against
//! `max_client_queue` and `max_queue`: one more is refused at once ([`WorkerError::QueueFull`],
//! HTTP 503). Scene creation and deletion go ahead of renders. A render whose requester has
//! gone (client disconnected, stream closed) leaves the queue, freeing its place, and is never
//! run. A panic inside a job (wgpu reports validation errors by
//! panicking) fails that job only.
//!
//! A process may run several workers, one per GPU ([`super::workers`] routes between them).
//! A render may carry its scene's [`SceneSource`]: a worker that does not hold the scene yet
//! uploads it on its own thread before rendering (lazily, the first time it needs it).
//!
//! The backend is a trait so that the service's scheduling, limits and error paths can be
//! driven without a GPU (the tests' fake backend sleeps and answers black images).

use std::collections::{HashMap, HashSet};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use glam::Mat4;
use tokio::sync::oneshot;

use crate::bench::compare::{ExactOptions, ReferenceDevice, traced_level_frame};
use crate::gpu::{Gpu, GpuError};
use crate::mr::{self, MrPipeline, environment::Environment};
use crate::renderer::{Method, Rendered, Renderer};
use crate::rgbd::{RgbdFrame, RgbdSettings};
use crate::scene::{Camera, Occlusion, Quality, Scene, SpotLight};

use super::api::Component;
use super::config::{Limits, limit};
use super::metrics::{GpuMemory, Metrics};
use super::schedule::{ClientId, FairQueue, Refused};
use super::wire::StreamImageFormat;

/// Why a job failed.
#[derive(Debug, thiserror::Error)]
pub enum WorkerError {
    #[error("the render queue is full ({waiting} renders waiting, the limit {limit})")]
    QueueFull {
        waiting: usize,
        /// `max_queue` (all clients) or `max_client_queue` (this client).
        limit: &'static str,
        /// The measured queue wait, when there is one.
        retry_after: Option<Duration>,
    },
    #[error("no scene with id `{0}`")]
    SceneNotFound(String),
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error("the GPU thread panicked during this job: {0}")]
    Panicked(String),
    #[error("the GPU thread has stopped")]
    Stopped,
    #[error("the GPU device was lost during this job; a new one has been opened and the scenes re-uploaded")]
    DeviceLost,
}

impl From<Refused> for WorkerError {
    fn from(refused: Refused) -> WorkerError {
        match refused {
            Refused::Full { waiting, retry_after } => {
                WorkerError::QueueFull { waiting, limit: limit::MAX_QUEUE, retry_after }
            }
            Refused::ClientFull { waiting, retry_after } => {
                WorkerError::QueueFull { waiting, limit: limit::MAX_CLIENT_QUEUE, retry_after }
            }
            Refused::Closed => WorkerError::Stopped,
        }
    }
}

/// What the GPU thread runs jobs on: one device and the scenes loaded on it.
pub trait Backend {
    /// The adapter's name and backend, for `/healthz`.
    fn adapter(&self) -> String;
    /// Prepares the scene's resources (pipelines, buffers); its stream frames are lit by
    /// `environment` too (`settings.environment`, read off the GPU thread).
    fn add_scene(&mut self, id: &str, scene: Scene, environment: Environment) -> Result<(), WorkerError>;
    /// Drops the scene's resources; false when there were none.
    fn remove_scene(&mut self, id: &str) -> bool;
    /// One HTTP render ([`WorkerError::SceneNotFound`] for an unknown scene).
    fn render(&mut self, id: &str, job: &RenderJob) -> Result<Frame, WorkerError>;
    /// One stream frame.
    fn render_stream_frame(&mut self, id: &str, job: &StreamFrameJob) -> Result<Frame, WorkerError>;
    /// Called before every job and after every failed one: when the device has been lost,
    /// opens a new one, rebuilds every scene's resources from the scene and answers true.
    fn recover(&mut self) -> bool {
        false
    }
    /// Test hook: lose the device during the next render (the next job on a fake backend).
    fn lose_device(&mut self) {}
    /// The GPU memory and objects the device holds now, where the backend counts them.
    fn memory(&self) -> Option<GpuMemory> {
        None
    }
}

/// A rendered frame and, for stream frames seen from their own camera, the composite.
pub type Frame = (Rendered, Option<Composite>);

/// One HTTP render: the scene's renderer with this camera and light.
#[derive(Clone, Debug)]
pub struct RenderJob {
    pub camera: Camera,
    /// The spot light, for scenes that have one.
    pub light: Option<SpotLight>,
    pub method: Method,
    /// The request's level (at `reference` the exact frame carries no error estimate).
    pub level: Quality,
    /// The level's estimator draws per pixel, where its technique is the estimator.
    pub draws: Option<u32>,
    pub width: u32,
    pub height: u32,
    /// The request's level's visibility mode and near field (sparse point spacings).
    pub occlusion: Occlusion,
    pub near_field: f32,
    /// The camera's simplified triangles, ratio and error (`FrameParameters::camera_lod`).
    pub camera_lod: Option<(f32, f32)>,
}
/// A composited stream frame (sRGB, row-major) and how long compositing took, ms.
pub type Composite = (Vec<[u8; 3]>, f64);

/// A finished render and where its time went.
pub struct RenderOutput {
    pub frame: Rendered,
    /// Stream frames seen from their own camera: the camera image with the virtual content
    /// composited in (sRGB, row-major, the size of `frame`), and how long that took (ms).
    pub composited: Option<Composite>,
    /// Time in the queue before the GPU thread took the job, ms.
    pub queue_ms: f64,
    /// Time the GPU thread spent on the job (all stages and read-back), ms.
    pub gpu_ms: f64,
}

/// Everything a stream frame is rendered with: the frame and the stream's settings when it
/// was submitted.
#[derive(Clone, Debug)]
pub struct StreamFrameJob {
    pub frame_id: u64,
    pub frame: RgbdFrame,
    /// A virtual camera to render from instead of the frame's own (no composite then).
    pub camera: Option<Camera>,
    pub light: Option<SpotLight>,
    /// Model-to-world overrides, by mesh index.
    /// Replacements of meshes' transforms, in user coordinates (composed in f64).
    pub model_transforms: Vec<(u32, glam::DMat4)>,
    pub method: Method,
    pub component: Component,
    pub exposure: Option<f32>,
    pub format: StreamImageFormat,
    pub rgbd: RgbdSettings,
    /// Indirect occlusion and whether the glossy gather may run (the scene's settings unless
    /// the stream changed them).
    pub occlusion: Occlusion,
    pub glossy: bool,
    /// `sparse.near_field` of the stream's level (sparse point spacings).
    pub near_field: f32,
    /// The camera's simplified triangles, ratio and error (`FrameParameters::camera_lod`).
    pub camera_lod: Option<(f32, f32)>,
    /// Multiplier of the differential pass's receiver step (`FrameParameters::receivers_step`).
    pub receivers_step: u32,
}

/// A scene as loaded, kept while several workers may need to upload it.
pub struct SceneSource {
    pub scene: Scene,
    pub environment: Environment,
    /// Set when the scene is deleted: a render of it still queued does not upload it again.
    pub deleted: AtomicBool,
}

impl SceneSource {
    pub fn new(scene: Scene, environment: Environment) -> SceneSource {
        SceneSource { scene, environment, deleted: AtomicBool::new(false) }
    }
}

/// What a worker's thread tells the router about itself.
#[derive(Default)]
pub struct WorkerStatus {
    /// Renders being run now (0 or 1).
    busy: AtomicUsize,
    /// The scenes the worker holds (uploaded and not removed).
    held: Mutex<HashSet<String>>,
    /// When the device was last lost.
    lost_at: Mutex<Option<Instant>>,
    /// Devices lost so far.
    device_losses: AtomicU64,
    /// Streams pinned to the worker ([`super::workers::StreamPin`]).
    pub(super) streams: AtomicUsize,
}

impl WorkerStatus {
    fn held(&self) -> std::sync::MutexGuard<'_, HashSet<String>> {
        self.held.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    fn lost_at(&self) -> std::sync::MutexGuard<'_, Option<Instant>> {
        self.lost_at.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

enum Job {
    AddScene {
        id: String,
        scene: Box<Scene>,
        environment: Box<Environment>,
        reply: oneshot::Sender<Result<(), WorkerError>>,
    },
    RemoveScene {
        id: String,
        reply: oneshot::Sender<bool>,
    },
    Frame {
        id: String,
        job: FrameJob,
        source: Option<Arc<SceneSource>>,
        reply: oneshot::Sender<Result<RenderOutput, WorkerError>>,
    },
    LoseDevice,
}

/// A frame to render: an HTTP render or a stream frame.
pub enum FrameJob {
    Render(RenderJob),
    Stream(Box<StreamFrameJob>),
}

impl Job {
    /// Whether nobody waits for the answer any more: the HTTP client disconnected (its
    /// handler, holding the receiver, was dropped) or the stream closed.
    fn abandoned(&self) -> bool {
        match self {
            Job::Frame { reply, .. } => reply.is_closed(),
            Job::AddScene { .. } | Job::RemoveScene { .. } | Job::LoseDevice => false,
        }
    }
}

/// The handle the handlers hold.
pub struct GpuWorker {
    /// The worker's number in the process (its `worker` label in `/metrics`).
    index: usize,
    queue: Arc<FairQueue<Job>>,
    status: Arc<WorkerStatus>,
    adapter: String,
    thread: Mutex<Option<std::thread::JoinHandle<()>>>,
}

impl GpuWorker {
    /// Starts the GPU thread on the [`GpuBackend`] and waits until it has opened the device.
    /// Blocks: call it from `spawn_blocking` or outside the runtime.
    pub fn start(limits: &Limits, metrics: Arc<Metrics>) -> Result<GpuWorker, WorkerError> {
        GpuWorker::start_with(|| Ok(GpuBackend::new(Gpu::new()?)), limits, metrics)
    }

    /// Worker `index` on adapter `adapter` of [`Gpu::adapters`] (`None`: wgpu's choice).
    pub fn start_on(
        index: usize,
        adapter: Option<usize>,
        limits: &Limits,
        metrics: Arc<Metrics>,
    ) -> Result<GpuWorker, WorkerError> {
        GpuWorker::start_numbered(index, move || GpuBackend::on(adapter), limits, metrics)
    }

    /// Starts the GPU thread on the backend `open` makes there. Blocks until it is made.
    pub fn start_with<B: Backend>(
        open: impl FnOnce() -> Result<B, WorkerError> + Send + 'static,
        limits: &Limits,
        metrics: Arc<Metrics>,
    ) -> Result<GpuWorker, WorkerError> {
        GpuWorker::start_numbered(0, open, limits, metrics)
    }

    /// [`GpuWorker::start_with`] as worker `index` of the process.
    pub fn start_numbered<B: Backend>(
        index: usize,
        open: impl FnOnce() -> Result<B, WorkerError> + Send + 'static,
        limits: &Limits,
        metrics: Arc<Metrics>,
    ) -> Result<GpuWorker, WorkerError> {
        let queue =
            Arc::new(FairQueue::new(limits.max_queue, limits.max_client_queue).dropping_abandoned(Job::abandoned));
        let (ready, is_ready) = std::sync::mpsc::sync_channel(1);
        let thread_queue = queue.clone();
        let status = Arc::new(WorkerStatus::default());
        let thread_status = status.clone();
        let thread = std::thread::Builder::new()
            .name(format!("relume-gpu-{index}"))
            .spawn(move || {
                let backend = match open() {
                    Ok(backend) => backend,
                    Err(error) => {
                        let _ = ready.send(Err(error));
                        return;
                    }
                };
                let _ = ready.send(Ok(backend.adapter()));
                run(backend, &thread_queue, &Thread { index, metrics: &metrics, status: &thread_status });
            })
            .map_err(|e| WorkerError::Panicked(format!("cannot spawn the GPU thread: {e}")))?;
        let adapter = is_ready.recv().map_err(|_| WorkerError::Stopped)??;
        tracing::info!(worker = index, adapter = %adapter, limits.max_queue, limits.max_client_queue, "GPU thread ready");
        Ok(GpuWorker { index, queue, status, adapter, thread: Mutex::new(Some(thread)) })
    }

    /// The worker's number in the process.
    pub fn index(&self) -> usize {
        self.index
    }

    /// What the worker's thread reports.
    pub fn status(&self) -> &Arc<WorkerStatus> {
        &self.status
    }

    /// Renders waiting or running, and streams pinned: what the router balances.
    pub fn load(&self) -> usize {
        self.queue_depth() + self.status.busy.load(Ordering::SeqCst) + self.status.streams.load(Ordering::SeqCst)
    }

    /// Whether the worker has uploaded scene `id`.
    pub fn holds(&self, id: &str) -> bool {
        self.status.held().contains(id)
    }

    /// Scenes the worker holds.
    pub fn scenes(&self) -> usize {
        self.status.held().len()
    }

    /// Streams pinned to the worker.
    pub fn streams(&self) -> usize {
        self.status.streams.load(Ordering::SeqCst)
    }

    /// Devices lost so far.
    pub fn device_losses(&self) -> u64 {
        self.status.device_losses.load(Ordering::SeqCst)
    }

    /// False for `quarantine` after the device was lost.
    pub fn healthy(&self, quarantine: Duration) -> bool {
        self.status.lost_at().is_none_or(|at| at.elapsed() >= quarantine)
    }

    /// The adapter's name and backend.
    pub fn adapter(&self) -> &str {
        &self.adapter
    }

    /// Renders waiting for the GPU thread.
    pub fn queue_depth(&self) -> usize {
        self.queue.waiting()
    }

    pub fn queue_capacity(&self) -> usize {
        self.queue.capacity()
    }

    /// Builds the scene's renderer (pipelines, buffers) on the GPU thread; its stream frames
    /// are lit by `environment` too.
    pub async fn add_scene(&self, id: &str, scene: Scene, environment: Environment) -> Result<(), WorkerError> {
        let (reply, answer) = oneshot::channel();
        let (scene, environment) = (Box::new(scene), Box::new(environment));
        self.queue.push_control(Job::AddScene { id: id.to_owned(), scene, environment, reply })?;
        answer.await.map_err(|_| WorkerError::Stopped)?
    }

    /// Drops the scene's renderer; false when there was none. Renders of it still queued
    /// fail with [`WorkerError::SceneNotFound`].
    pub async fn remove_scene(&self, id: &str) -> Result<bool, WorkerError> {
        let (reply, answer) = oneshot::channel();
        self.queue.push_control(Job::RemoveScene { id: id.to_owned(), reply })?;
        answer.await.map_err(|_| WorkerError::Stopped)
    }

    /// Queues a render or stream frame of `client`, or refuses at once when its queue or the
    /// whole queue is full. With `source`, a worker that does not hold the scene uploads it
    /// first.
    pub fn try_render(
        &self,
        client: ClientId,
        id: &str,
        job: FrameJob,
        source: Option<Arc<SceneSource>>,
    ) -> Result<oneshot::Receiver<Result<RenderOutput, WorkerError>>, WorkerError> {
        let (reply, answer) = oneshot::channel();
        self.queue.push(client, Job::Frame { id: id.to_owned(), job, source, reply })?;
        Ok(answer)
    }

    /// Test hook ([`Backend::lose_device`]): the device is lost during the next render, as a
    /// driver reset would lose it.
    pub fn lose_device(&self) -> Result<(), WorkerError> {
        Ok(self.queue.push_control(Job::LoseDevice)?)
    }

    /// Lets the GPU thread finish every job already queued, then stops and joins it.
    pub async fn stop(&self) {
        self.queue.close();
        let thread = self.thread.lock().unwrap_or_else(|poisoned| poisoned.into_inner()).take();
        if let Some(thread) = thread
            && tokio::task::spawn_blocking(move || thread.join()).await.is_err()
        {
            tracing::error!("the GPU thread could not be joined");
        }
    }
}

/// What the GPU thread reports to: its number, the metrics and the router's view of it.
struct Thread<'a> {
    index: usize,
    metrics: &'a Metrics,
    status: &'a WorkerStatus,
}

/// The GPU thread's loop: one job at a time, in the queue's order, until it is closed and
/// empty. A job that fails because the device was lost answers [`WorkerError::DeviceLost`].
fn run(mut backend: impl Backend, queue: &FairQueue<Job>, thread: &Thread) {
    while let Some(taken) = queue.pop() {
        backend.recover();
        let queue_ms = taken.waited.unwrap_or_default().as_secs_f64() * 1e3;
        match taken.job {
            Job::AddScene { id, scene, environment, reply } => {
                let result = guarded(|| backend.add_scene(&id, *scene, *environment));
                let result = lost_or(&mut backend, thread, result);
                if result.is_ok() {
                    thread.status.held().insert(id);
                }
                let _ = reply.send(result);
            }
            Job::RemoveScene { id, reply } => {
                thread.status.held().remove(&id);
                let _ = reply.send(backend.remove_scene(&id));
            }
            Job::Frame { id, job, source, reply } => {
                if reply.is_closed() {
                    tracing::debug!(scene = %id, "frame skipped: the client has gone");
                    continue;
                }
                let result = render_held(&mut backend, thread, &id, source.as_deref(), queue_ms, |b| match &job {
                    FrameJob::Render(job) => b.render(&id, job),
                    FrameJob::Stream(job) => b.render_stream_frame(&id, job),
                });
                let _ = reply.send(result);
            }
            Job::LoseDevice => backend.lose_device(),
        }
        thread.metrics.set_worker_gpu_memory(thread.index, backend.memory());
    }
    tracing::info!(worker = thread.index, "GPU thread stopped");
}

/// Runs `render` on scene `id`, uploading it first from `source` when the worker does not hold
/// it (or no longer does: a scene a new device could not rebuild), timed and counted busy.
fn render_held<B: Backend>(
    backend: &mut B,
    thread: &Thread,
    id: &str,
    source: Option<&SceneSource>,
    queue_ms: f64,
    render: impl Fn(&mut B) -> Result<Frame, WorkerError>,
) -> Result<RenderOutput, WorkerError> {
    thread.status.busy.fetch_add(1, Ordering::SeqCst);
    let started = Instant::now();
    let mut result = upload_if_missing(backend, thread, id, source, false)
        .and_then(|()| timed(thread, queue_ms, started, || render(backend)));
    if matches!(result, Err(WorkerError::SceneNotFound(_))) && source.is_some() {
        result = upload_if_missing(backend, thread, id, source, true)
            .and_then(|()| timed(thread, queue_ms, started, || render(backend)));
    }
    let result = lost_or(backend, thread, result);
    thread.status.busy.fetch_sub(1, Ordering::SeqCst);
    result
}

/// Uploads scene `id` from `source` unless the worker holds it (`again`: whatever it thinks).
/// A deleted scene is not uploaded ([`WorkerError::SceneNotFound`]).
fn upload_if_missing(
    backend: &mut impl Backend,
    thread: &Thread,
    id: &str,
    source: Option<&SceneSource>,
    again: bool,
) -> Result<(), WorkerError> {
    let Some(source) = source else { return Ok(()) };
    if !again && thread.status.held().contains(id) {
        return Ok(());
    }
    if source.deleted.load(Ordering::SeqCst) {
        return Err(WorkerError::SceneNotFound(id.to_owned()));
    }
    let started = Instant::now();
    guarded(|| backend.add_scene(id, source.scene.clone(), source.environment.clone()))?;
    thread.status.held().insert(id.to_owned());
    tracing::info!(worker = thread.index, scene = %id, ms = started.elapsed().as_secs_f64() * 1e3, "scene uploaded");
    Ok(())
}

/// `result`, or [`WorkerError::DeviceLost`] when it failed because the device was lost (the
/// backend has recovered by the time this returns; the loss is reported to the router).
fn lost_or<T>(backend: &mut impl Backend, thread: &Thread, result: Result<T, WorkerError>) -> Result<T, WorkerError> {
    match result {
        Err(error) if backend.recover() => {
            tracing::warn!(worker = thread.index, "a job failed with the device lost: {error}");
            *thread.status.lost_at() = Some(Instant::now());
            thread.status.device_losses.fetch_add(1, Ordering::SeqCst);
            Err(WorkerError::DeviceLost)
        }
        result => result,
    }
}

/// The backend of the service: the device and one renderer per scene. Each scene is kept as
/// loaded, so that a lost device is replaced and every renderer rebuilt without the clients.
pub struct GpuBackend {
    gpu: Gpu,
    /// The adapter of [`Gpu::adapters`] a lost device is reopened on (`None`: wgpu's choice).
    adapter: Option<usize>,
    scenes: HashMap<String, Loaded>,
    /// Set by the device's lost callback.
    lost: Arc<AtomicBool>,
    /// [`Backend::lose_device`] was called: destroy the device during the next render.
    lose_during_next_render: bool,
}

impl GpuBackend {
    pub fn new(gpu: Gpu) -> GpuBackend {
        let lost = watch_for_loss(&gpu);
        GpuBackend { gpu, adapter: None, scenes: HashMap::new(), lost, lose_during_next_render: false }
    }

    /// A device on adapter `adapter` of [`Gpu::adapters`] (`None`: wgpu's choice).
    pub fn on(adapter: Option<usize>) -> Result<GpuBackend, WorkerError> {
        let gpu = match adapter {
            Some(index) => Gpu::on_adapter(index)?,
            None => Gpu::new()?,
        };
        Ok(GpuBackend { adapter, ..GpuBackend::new(gpu) })
    }

    /// Gives back the memory that no scene holds any more. wgpu keeps the staging copy of
    /// every `write_buffer` (a scene's uploads) until the next submission, and frees a dropped
    /// buffer or texture only once the device is polled after its last use; renders submit and
    /// poll, scene creation and deletion did not, so a loop of creations and deletions held
    /// about 5.5 MiB per deleted `cornell_bunny_small` until the next render. An empty
    /// submission flushes the uploads; the poll then frees them and whatever was dropped.
    /// Nothing else is in flight between jobs (every render waits for its read-back), so the
    /// wait is for the uploads only.
    fn settle(&self, during: &str) {
        self.gpu.queue.submit(std::iter::empty());
        if let Err(error) = self.gpu.device.poll(wgpu::PollType::wait_indefinitely()) {
            tracing::warn!("polling the device after {during}: {error}");
        }
    }

    /// Runs the test hook when armed: the device is destroyed under the render.
    fn maybe_lose_device(&mut self) {
        if std::mem::take(&mut self.lose_during_next_render) {
            tracing::warn!("test hook: destroying the GPU device");
            self.gpu.device.destroy();
        }
    }
}

/// A flag the device's lost callback sets.
fn watch_for_loss(gpu: &Gpu) -> Arc<AtomicBool> {
    let lost = Arc::new(AtomicBool::new(false));
    let flag = lost.clone();
    gpu.device.set_device_lost_callback(move |reason, message| {
        tracing::error!(?reason, message, "the GPU device was lost");
        flag.store(true, Ordering::SeqCst);
    });
    lost
}

impl Backend for GpuBackend {
    fn adapter(&self) -> String {
        self.gpu.adapter_name()
    }

    fn add_scene(&mut self, id: &str, scene: Scene, environment: Environment) -> Result<(), WorkerError> {
        let mut renderer = Renderer::new(&self.gpu, &scene)?;
        renderer.set_error_estimate(Some(crate::renderer::estimate::PER_FRAME));
        let mr = MrPipeline::new(scene.settings.mr, environment);
        self.scenes.insert(id.to_owned(), Loaded { scene, renderer, mr });
        self.settle("creating a scene");
        Ok(())
    }

    /// Drops the scene's renderer and pipeline and frees their memory at once
    /// ([`GpuBackend::settle`]).
    fn remove_scene(&mut self, id: &str) -> bool {
        let removed = self.scenes.remove(id).is_some();
        self.settle("deleting a scene");
        removed
    }

    fn render(&mut self, id: &str, job: &RenderJob) -> Result<Frame, WorkerError> {
        self.maybe_lose_device();
        let gpu = &self.gpu;
        let loaded = self.scenes.get_mut(id).ok_or_else(|| WorkerError::SceneNotFound(id.to_owned()))?;
        render(gpu, loaded, job)
    }

    fn render_stream_frame(&mut self, id: &str, job: &StreamFrameJob) -> Result<Frame, WorkerError> {
        self.maybe_lose_device();
        let gpu = &self.gpu;
        let loaded = self.scenes.get_mut(id).ok_or_else(|| WorkerError::SceneNotFound(id.to_owned()))?;
        render_stream_frame(gpu, loaded, job)
    }

    fn recover(&mut self) -> bool {
        if !self.lost.load(Ordering::SeqCst) {
            return false;
        }
        let reopened = match self.adapter {
            Some(index) => Gpu::on_adapter(index),
            None => Gpu::new(),
        };
        let gpu = match reopened {
            Ok(gpu) => gpu,
            Err(error) => {
                // Still lost: the next job tries again.
                tracing::error!("cannot open a new GPU device: {error}");
                return true;
            }
        };
        self.lost = watch_for_loss(&gpu);
        self.gpu = gpu;
        let gpu = &self.gpu;
        self.scenes.retain(|id, loaded| match guarded(|| Ok(Renderer::new(gpu, &loaded.scene)?)) {
            Ok(mut renderer) => {
                renderer.set_error_estimate(Some(crate::renderer::estimate::PER_FRAME));
                loaded.renderer = renderer;
                loaded.mr.forget_placement();
                true
            }
            Err(error) => {
                tracing::error!(scene = %id, "scene dropped: it cannot be re-uploaded to the new device: {error}");
                false
            }
        });
        tracing::warn!(adapter = %gpu.adapter_name(), scenes = self.scenes.len(), "GPU device recreated");
        true
    }

    fn lose_device(&mut self) {
        self.lose_during_next_render = true;
    }

    /// wgpu's own counts (its `counters` feature): what the device has allocated, live.
    fn memory(&self) -> Option<GpuMemory> {
        let hal = self.gpu.device.get_internal_counters().hal;
        let count = |value: isize| u64::try_from(value).unwrap_or(0);
        Some(GpuMemory {
            buffers: count(hal.buffers.read()),
            textures: count(hal.textures.read()),
            buffer_bytes: count(hal.buffer_memory.read()),
            texture_bytes: count(hal.texture_memory.read()),
            allocations: count(hal.memory_allocations.read()),
        })
    }
}

/// A scene on the GPU thread: the loaded scene (to place its meshes), its renderer, shared by
/// the scene's HTTP renders and streams, and the mixed-reality pipeline of its stream frames
/// (the differential pass built for the streams' last placement). Every job sets all the
/// state it renders with.
struct Loaded {
    scene: Scene,
    renderer: Renderer,
    mr: MrPipeline,
}

/// Runs `f` (a render) behind [`guarded`], timing it from `started` (an upload before it
/// included) and recording the frame's metrics.
fn timed(
    thread: &Thread,
    queue_ms: f64,
    started: Instant,
    f: impl FnOnce() -> Result<Frame, WorkerError>,
) -> Result<RenderOutput, WorkerError> {
    let (frame, composited) = guarded(f)?;
    let gpu_ms = started.elapsed().as_secs_f64() * 1e3;
    thread.metrics.record_worker_frame(thread.index, gpu_ms / 1e3, &frame.timings);
    Ok(RenderOutput { frame, composited, queue_ms, gpu_ms })
}

/// One HTTP render: the scene as loaded, lit by its spot light, from `job.camera`.
fn render(gpu: &Gpu, loaded: &mut Loaded, job: &RenderJob) -> Result<Frame, WorkerError> {
    let Loaded { scene, renderer, .. } = loaded;
    renderer.place_meshes(gpu, scene, &placement(scene, &[]));
    renderer.set_occlusion(job.occlusion, scene.settings.visibility.rule);
    renderer.set_near_field(job.near_field);
    renderer.set_camera_lod(gpu, job.camera_lod)?;
    renderer.set_glossy(scene.settings.glossy);
    renderer.clear_vals();
    renderer.set_camera(job.camera);
    if let Some(light) = &job.light {
        renderer.set_spot_light(light);
    }
    if job.method == Method::Estimator {
        // The request's level's draws, not the scene's level's the renderer was made with.
        let draws = job.draws.unwrap_or(crate::gpu::references::estimator::DEFAULT_SAMPLES);
        renderer.set_estimator(draws, scene.settings.seed as u32);
    }
    let frame = match ExactOptions::traced(job.method, ReferenceDevice::Auto) {
        // On a CPU adapter the CPU's, as `relume render` runs them.
        Some(options) => traced_level_frame(gpu, renderer, job.width, job.height, &options, job.level)?,
        None => renderer.render(gpu, job.method, job.width, job.height)?,
    };
    Ok((frame, None))
}

/// Model-to-world of every mesh of `scene`: as loaded, but where `transforms` (by mesh
/// index) replaces a mesh's own transform (the scene's anchor still applies).
fn placement(scene: &Scene, transforms: &[(u32, glam::DMat4)]) -> Vec<Mat4> {
    (0..scene.meshes.len())
        .map(|i| {
            let replaced = transforms.iter().find(|(mesh, _)| *mesh as usize == i).map(|(_, t)| *t);
            scene.mesh_to_world(i, replaced)
        })
        .collect()
}

/// Renders one RGB-D stream frame as `relume replay` renders a recording's
/// ([`MrPipeline`]): the meshes placed by the stream's model transforms (the differential
/// pass's BVH rebuilt only when that moves them), lit by the frame's VALs (made with
/// `job.rgbd`), the scene's environment (`auto`: its level raised by the differential pass's
/// receivers) and the stream's spot light if the scene has one, with the stream's occlusion
/// and glossy settings; seen from the frame's camera at the frame's size and, when
/// `job.component` is full, the real surfaces relit by the differential pass and the content
/// composited over them. From the stream's virtual camera, or for another component, the same
/// light without composite.
fn render_stream_frame(gpu: &Gpu, loaded: &mut Loaded, job: &StreamFrameJob) -> Result<Frame, WorkerError> {
    let Loaded { scene, renderer, mr } = loaded;
    mr.place(gpu, renderer, scene, &placement(scene, &job.model_transforms))?;
    renderer.set_occlusion(job.occlusion, scene.settings.visibility.rule);
    renderer.set_near_field(job.near_field);
    renderer.set_camera_lod(gpu, job.camera_lod)?;
    renderer.set_glossy(job.glossy);
    if let Some(light) = job.light.as_ref().or(scene.light.as_ref()) {
        renderer.set_spot_light(light);
    }
    let k = job.frame.intrinsics;
    let settings = mr::FrameSettings {
        width: k.width,
        height: k.height,
        exposure: job.exposure.unwrap_or(1.0),
        rgbd: job.rgbd,
        receivers_step: job.receivers_step,
        method: job.method,
    };
    let input = mr::FrameInput { frame: &job.frame, settings: &settings, accumulate: None };
    if job.camera.is_none() && job.component == Component::Full {
        let relit = mr.render_frame(gpu, renderer, input)?;
        return Ok((relit.rendered, Some((relit.composited, relit.composite_ms))));
    }
    let lighting = mr.light(gpu, renderer, input)?;
    let (width, height) = match job.camera {
        Some(camera) => {
            renderer.set_camera(camera);
            (camera.width, camera.height)
        }
        None => {
            renderer.set_pinhole_view(k, &job.frame.camera_to_world);
            (k.width, k.height)
        }
    };
    let mut rendered = renderer.render(gpu, job.method, width, height)?;
    lighting.add_stages(&mut rendered.timings);
    Ok((rendered, None))
}

/// Runs `f`, turning a panic into [`WorkerError::Panicked`] so one bad job cannot take the
/// GPU thread, and every other client, down.
fn guarded<T>(f: impl FnOnce() -> Result<T, WorkerError>) -> Result<T, WorkerError> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(result) => result,
        Err(payload) => {
            let message = payload
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| payload.downcast_ref::<&str>().map(|s| (*s).to_owned()))
                .unwrap_or_else(|| "unknown panic".to_owned());
            tracing::error!("GPU job panicked: {message}");
            Err(WorkerError::Panicked(message))
        }
    }
}

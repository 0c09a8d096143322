//! The one thread that owns the GPU. It holds the [`Gpu`] and one [`Renderer`] per scene, and
//! takes jobs from a bounded channel; every job answers on its own oneshot channel. Handlers
//! never touch the device and never block a tokio worker on it.
//!
//! Renders (HTTP renders and stream frames) are counted against `max_queue`: one more is
//! refused at once ([`WorkerError::QueueFull`], HTTP 503). Scene creation and deletion wait
//! for room instead, in a few channel slots kept for them. A job whose requester has gone
//! (client disconnected) is skipped. A panic inside a job (wgpu reports validation errors by
//! panicking) fails that job only.

use std::collections::HashMap;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use glam::Mat4;
use tokio::sync::{mpsc, oneshot};

use crate::gpu::{Gpu, GpuError};
use crate::mr;
use crate::renderer::{Method, Rendered, Renderer, View};
use crate::rgbd::{RgbdFrame, RgbdSettings};
use crate::scene::{Camera, Occlusion, Scene, SpotLight};

use super::api::Component;
use super::metrics::Metrics;
use super::wire::StreamImageFormat;

/// Channel slots beyond `max_queue`, for scene creation and deletion.
const CONTROL_SLOTS: usize = 16;

/// Why a job failed.
#[derive(Debug, thiserror::Error)]
pub enum WorkerError {
    #[error("the render queue is full ({0} renders waiting)")]
    QueueFull(usize),
    #[error("no scene with id `{0}`")]
    SceneNotFound(String),
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error("the GPU thread panicked during this job: {0}")]
    Panicked(String),
    #[error("the GPU thread has stopped")]
    Stopped,
}

/// One HTTP render: the scene's renderer with this camera and light.
#[derive(Clone, Debug)]
pub struct RenderJob {
    pub camera: Camera,
    /// The spot light, for scenes that have one.
    pub light: Option<SpotLight>,
    pub method: Method,
    pub width: u32,
    pub height: u32,
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
    pub model_transforms: Vec<(u32, Mat4)>,
    pub method: Method,
    pub component: Component,
    pub exposure: Option<f32>,
    pub format: StreamImageFormat,
    pub rgbd: RgbdSettings,
    /// Indirect occlusion and whether the glossy gather may run (the scene's settings unless
    /// the stream changed them).
    pub occlusion: Occlusion,
    pub glossy: bool,
}

enum Job {
    AddScene {
        id: String,
        scene: Box<Scene>,
        reply: oneshot::Sender<Result<(), WorkerError>>,
    },
    RemoveScene {
        id: String,
        reply: oneshot::Sender<bool>,
    },
    Render {
        id: String,
        job: RenderJob,
        enqueued: Instant,
        reply: oneshot::Sender<Result<RenderOutput, WorkerError>>,
    },
    StreamFrame {
        id: String,
        job: Box<StreamFrameJob>,
        enqueued: Instant,
        reply: oneshot::Sender<Result<RenderOutput, WorkerError>>,
    },
    Stop,
}

/// The handle the handlers hold.
pub struct GpuWorker {
    jobs: mpsc::Sender<Job>,
    /// Renders in the channel (not yet taken by the GPU thread).
    queued: Arc<AtomicUsize>,
    capacity: usize,
    adapter: String,
    thread: Mutex<Option<std::thread::JoinHandle<()>>>,
}

impl GpuWorker {
    /// Starts the GPU thread and waits until it has opened the device. Blocks: call it from
    /// `spawn_blocking` or outside the runtime.
    pub fn start(max_queue: usize, metrics: Arc<Metrics>) -> Result<GpuWorker, WorkerError> {
        let (jobs, receiver) = mpsc::channel(max_queue + CONTROL_SLOTS);
        let queued = Arc::new(AtomicUsize::new(0));
        let (ready, is_ready) = std::sync::mpsc::sync_channel(1);
        let thread_queued = queued.clone();
        let thread = std::thread::Builder::new()
            .name("relume-gpu".to_owned())
            .spawn(move || {
                let gpu = match Gpu::new() {
                    Ok(gpu) => gpu,
                    Err(error) => {
                        let _ = ready.send(Err(error));
                        return;
                    }
                };
                let _ = ready.send(Ok(gpu.adapter_name()));
                run(gpu, receiver, thread_queued, metrics);
            })
            .map_err(|e| WorkerError::Panicked(format!("cannot spawn the GPU thread: {e}")))?;
        let adapter = is_ready.recv().map_err(|_| WorkerError::Stopped)??;
        tracing::info!(adapter = %adapter, max_queue, "GPU thread ready");
        Ok(GpuWorker { jobs, queued, capacity: max_queue, adapter, thread: Mutex::new(Some(thread)) })
    }

    /// The adapter's name and backend.
    pub fn adapter(&self) -> &str {
        &self.adapter
    }

    /// Renders waiting for the GPU thread.
    pub fn queue_depth(&self) -> usize {
        self.queued.load(Ordering::SeqCst)
    }

    pub fn queue_capacity(&self) -> usize {
        self.capacity
    }

    /// Builds the scene's renderer (pipelines, buffers) on the GPU thread.
    pub async fn add_scene(&self, id: &str, scene: Scene) -> Result<(), WorkerError> {
        let (reply, answer) = oneshot::channel();
        self.send(Job::AddScene { id: id.to_owned(), scene: Box::new(scene), reply }).await?;
        answer.await.map_err(|_| WorkerError::Stopped)?
    }

    /// Drops the scene's renderer; false when there was none. Renders of it still queued
    /// fail with [`WorkerError::SceneNotFound`].
    pub async fn remove_scene(&self, id: &str) -> Result<bool, WorkerError> {
        let (reply, answer) = oneshot::channel();
        self.send(Job::RemoveScene { id: id.to_owned(), reply }).await?;
        answer.await.map_err(|_| WorkerError::Stopped)
    }

    /// Queues a render, or refuses at once when `max_queue` renders are waiting.
    pub fn try_render(
        &self,
        id: &str,
        job: RenderJob,
    ) -> Result<oneshot::Receiver<Result<RenderOutput, WorkerError>>, WorkerError> {
        let (reply, answer) = oneshot::channel();
        self.try_queue(Job::Render { id: id.to_owned(), job, enqueued: Instant::now(), reply })?;
        Ok(answer)
    }

    /// Queues a stream frame, or refuses at once when `max_queue` renders are waiting.
    pub fn try_render_stream_frame(
        &self,
        id: &str,
        job: StreamFrameJob,
    ) -> Result<oneshot::Receiver<Result<RenderOutput, WorkerError>>, WorkerError> {
        let (reply, answer) = oneshot::channel();
        self.try_queue(Job::StreamFrame { id: id.to_owned(), job: Box::new(job), enqueued: Instant::now(), reply })?;
        Ok(answer)
    }

    /// Lets the GPU thread finish every job already queued, then stops and joins it.
    pub async fn stop(&self) {
        let _ = self.jobs.send(Job::Stop).await;
        let thread = self.thread.lock().unwrap_or_else(|poisoned| poisoned.into_inner()).take();
        if let Some(thread) = thread
            && tokio::task::spawn_blocking(move || thread.join()).await.is_err()
        {
            tracing::error!("the GPU thread could not be joined");
        }
    }

    fn try_queue(&self, job: Job) -> Result<(), WorkerError> {
        let capacity = self.capacity;
        self.queued
            .fetch_update(Ordering::SeqCst, Ordering::SeqCst, |q| (q < capacity).then_some(q + 1))
            .map_err(WorkerError::QueueFull)?;
        self.jobs.try_send(job).map_err(|error| {
            self.queued.fetch_sub(1, Ordering::SeqCst);
            match error {
                mpsc::error::TrySendError::Full(_) => WorkerError::QueueFull(self.queue_depth()),
                mpsc::error::TrySendError::Closed(_) => WorkerError::Stopped,
            }
        })
    }

    async fn send(&self, job: Job) -> Result<(), WorkerError> {
        self.jobs.send(job).await.map_err(|_| WorkerError::Stopped)
    }
}

/// The GPU thread's loop: one job at a time, in order, until [`Job::Stop`] or every sender
/// is gone.
fn run(gpu: Gpu, mut jobs: mpsc::Receiver<Job>, queued: Arc<AtomicUsize>, metrics: Arc<Metrics>) {
    let mut renderers: HashMap<String, Loaded> = HashMap::new();
    while let Some(job) = jobs.blocking_recv() {
        match job {
            Job::AddScene { id, scene, reply } => {
                let result = guarded(|| Renderer::new(&gpu, &scene).map_err(WorkerError::from)).map(|renderer| {
                    renderers.insert(id, Loaded { scene: *scene, renderer });
                });
                let _ = reply.send(result);
            }
            Job::RemoveScene { id, reply } => {
                let _ = reply.send(renderers.remove(&id).is_some());
            }
            Job::Render { id, job, enqueued, reply } => {
                queued.fetch_sub(1, Ordering::SeqCst);
                if reply.is_closed() {
                    tracing::debug!(scene = %id, "render skipped: the client has gone");
                    continue;
                }
                let result = timed(&metrics, enqueued, || match renderers.get_mut(&id) {
                    None => Err(WorkerError::SceneNotFound(id.clone())),
                    Some(loaded) => render(&gpu, loaded, &job),
                });
                let _ = reply.send(result);
            }
            Job::StreamFrame { id, job, enqueued, reply } => {
                queued.fetch_sub(1, Ordering::SeqCst);
                if reply.is_closed() {
                    continue;
                }
                let result = timed(&metrics, enqueued, || match renderers.get_mut(&id) {
                    None => Err(WorkerError::SceneNotFound(id.clone())),
                    Some(loaded) => render_stream_frame(&gpu, loaded, &job),
                });
                let _ = reply.send(result);
            }
            Job::Stop => break,
        }
    }
    tracing::info!("GPU thread stopped");
}

/// A scene on the GPU thread: the loaded scene (to place its meshes) and its renderer, shared
/// by the scene's HTTP renders and streams. Every job sets all the state it renders with.
struct Loaded {
    scene: Scene,
    renderer: Renderer,
}

/// Runs `f` (a render) behind [`guarded`], timing it and recording the frame's metrics.
fn timed(
    metrics: &Metrics,
    enqueued: Instant,
    f: impl FnOnce() -> Result<(Rendered, Option<Composite>), WorkerError>,
) -> Result<RenderOutput, WorkerError> {
    let queue_ms = enqueued.elapsed().as_secs_f64() * 1e3;
    let started = Instant::now();
    let (frame, composited) = guarded(f)?;
    let gpu_ms = started.elapsed().as_secs_f64() * 1e3;
    metrics.record_frame(gpu_ms / 1e3, &frame.timings);
    Ok(RenderOutput { frame, composited, queue_ms, gpu_ms })
}

/// One HTTP render: the scene as loaded, lit by its spot light, from `job.camera`.
fn render(gpu: &Gpu, loaded: &mut Loaded, job: &RenderJob) -> Result<(Rendered, Option<Composite>), WorkerError> {
    let Loaded { scene, renderer } = loaded;
    renderer.place_meshes(gpu, scene, &placement(scene, &[]));
    renderer.set_occlusion(scene.settings.occlusion, scene.settings.occlusion_rule);
    renderer.set_glossy(scene.settings.glossy);
    renderer.clear_vals();
    renderer.set_camera(job.camera);
    if let Some(light) = &job.light {
        renderer.set_spot_light(light);
    }
    Ok((renderer.render(gpu, job.method, job.width, job.height)?, None))
}

/// Model-to-world of every mesh of `scene`: as loaded, but where `transforms` (by mesh
/// index) replaces a mesh's own transform (the scene's anchor still applies).
fn placement(scene: &Scene, transforms: &[(u32, Mat4)]) -> Vec<Mat4> {
    (0..scene.meshes.len())
        .map(|i| {
            let replaced = transforms.iter().find(|(mesh, _)| *mesh as usize == i).map(|(_, t)| *t);
            scene.mesh_to_world(i, replaced)
        })
        .collect()
}

/// Renders one RGB-D stream frame: the meshes placed by the stream's model transforms, lit
/// by the frame's VALs (made on the GPU with `job.rgbd`) and the scene's spot light if it has
/// one, with the stream's occlusion and glossy settings, seen from the frame's camera at the
/// frame's size (composited over the frame's colour when `job.component` is full), or from
/// the stream's virtual camera when it set one.
fn render_stream_frame(
    gpu: &Gpu,
    loaded: &mut Loaded,
    job: &StreamFrameJob,
) -> Result<(Rendered, Option<Composite>), WorkerError> {
    let Loaded { scene, renderer } = loaded;
    renderer.place_meshes(gpu, scene, &placement(scene, &job.model_transforms));
    renderer.set_occlusion(job.occlusion, scene.settings.occlusion_rule);
    renderer.set_glossy(job.glossy);
    if let Some(light) = job.light.as_ref().or(scene.light.as_ref()) {
        renderer.set_spot_light(light);
    }
    renderer.set_rgbd_frame(gpu, &job.frame, &job.rgbd)?;
    let Some(camera) = job.camera else {
        let k = job.frame.intrinsics;
        renderer.set_view(View::Pinhole { intrinsics: k, camera_to_world: job.frame.camera_to_world });
        let rendered = renderer.render(gpu, job.method, k.width, k.height)?;
        if job.component != Component::Full {
            return Ok((rendered, None));
        }
        let started = Instant::now();
        let depth = mr::virtual_depth(gpu, renderer, job.frame.camera_to_world)?;
        let image =
            mr::composite(&job.frame, &rendered.direct.add(&rendered.indirect), &depth, job.exposure.unwrap_or(1.0));
        return Ok((rendered, Some((image, started.elapsed().as_secs_f64() * 1e3))));
    };
    renderer.set_camera(camera);
    Ok((renderer.render(gpu, job.method, camera.width, camera.height)?, None))
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

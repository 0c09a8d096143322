//! `relume serve`: the renderer as an HTTP + WebSocket service.
//!
//! - [`http`]: the routes (`/v1/scenes`, `/v1/scenes/{id}`, `/v1/scenes/{id}/render`,
//!   `/healthz`, `/metrics`, `/openapi.json`) and the OpenAPI document generated from them.
//! - [`stream`]: `/v1/scenes/{id}/stream`, the WebSocket stream (protobuf messages of
//!   `proto/relume.proto`, decoded and encoded by [`wire`]): RGB-D frames in, relit frames
//!   out.
//! - [`tickets`]: `POST /v1/tickets`, single-use tickets that open a stream without the bearer
//!   token, for browsers (which cannot set a WebSocket's headers).
//! - [`recordings`]: `/v1/recordings`, the RGB-D recordings under the asset directory, frame by
//!   frame as stream messages; [`viewer`]: the browser viewer at `/`, files built into the
//!   binary.
//! - [`gpu_worker`]: the one thread that owns the GPU; handlers send it jobs through the
//!   [`schedule`] queue, fair between clients, and a full queue is a 503.
//! - [`listen`]: the connection loop: header and body timeouts, the connection cap.
//! - [`scenes`]: admitting scene descriptions (limits, paths confined to the asset directory)
//!   and the registry of scenes held.
//! - [`config`]: flags, environment variables and limits; [`metrics`]: Prometheus text.
//! - [`client`]: a client of the service (`relume replay --server`); [`load`]: its load
//!   benchmark (`relume load`).
//!
//! Shutdown (SIGINT, SIGTERM, or the future given to [`Server::run`]): the server stops
//! accepting connections, answers new work with 503 `shutting_down`, lets in-flight requests
//! and queued renders finish, closes streams with 1001 (going away) after an `Error` of code
//! `SHUTTING_DOWN`, then stops the GPU thread. After `shutdown_grace_seconds` whatever is
//! left is dropped.

pub mod api;
pub mod client;
pub mod config;
pub mod error;
pub mod gpu_worker;
pub mod http;
pub mod listen;
pub mod load;
pub mod metrics;
pub mod recordings;
pub mod scenes;
pub mod schedule;
pub mod stream;
pub mod tickets;
pub mod viewer;
pub mod wire;

use std::future::Future;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use tokio::sync::{Notify, watch};

pub use config::{Config, LimitExceeded, Limits, Timeouts};
pub use gpu_worker::{Backend, GpuWorker, WorkerError};
pub use http::{openapi, openapi_json, router};
pub use metrics::Metrics;

/// Why the service could not start or stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    #[error("asset directory {}: {source}", path.display())]
    Assets { path: PathBuf, source: std::io::Error },
    #[error("asset directory {}: not a directory", .0.display())]
    AssetsNotADirectory(PathBuf),
    #[error("starting the GPU thread: {0}")]
    Gpu(#[from] WorkerError),
    #[error("listening on {addr}: {source}")]
    Bind { addr: SocketAddr, source: std::io::Error },
    #[error("serving: {0}")]
    Io(#[from] std::io::Error),
}

/// What every handler shares.
pub struct AppState {
    pub config: Config,
    /// The asset directory, canonical.
    pub assets: PathBuf,
    pub scenes: scenes::SceneRegistry,
    pub recordings: recordings::Recordings,
    /// Tickets issued by `POST /v1/tickets` and not yet used.
    pub tickets: tickets::Tickets,
    pub worker: GpuWorker,
    pub metrics: Arc<Metrics>,
    shutdown: watch::Sender<bool>,
    streams: AtomicUsize,
    streams_closed: Notify,
    connections: listen::Connections,
}

impl AppState {
    /// Checks the asset directory and starts the GPU thread with the worker `start` makes (on
    /// a blocking thread): everything the router needs, without a socket, so that the router
    /// can also be driven as a tower service ([`router`] + `tower::ServiceExt::oneshot`; each
    /// request then needs a `ConnectInfo<SocketAddr>` extension, which [`listen`] inserts for
    /// real connections).
    pub async fn start(
        config: Config,
        start: impl FnOnce(Arc<Metrics>) -> Result<GpuWorker, WorkerError> + Send + 'static,
    ) -> Result<Arc<AppState>, ServeError> {
        let assets = std::fs::canonicalize(&config.assets)
            .map_err(|source| ServeError::Assets { path: config.assets.clone(), source })?;
        if !assets.is_dir() {
            return Err(ServeError::AssetsNotADirectory(assets));
        }
        let metrics = Arc::new(Metrics::default());
        let worker_metrics = metrics.clone();
        let worker = tokio::task::spawn_blocking(move || start(worker_metrics))
            .await
            .map_err(|e| WorkerError::Panicked(e.to_string()))??;
        let max_connections = config.limits.max_connections;
        Ok(Arc::new(AppState {
            scenes: scenes::SceneRegistry::new(config.limits.max_scenes),
            recordings: recordings::Recordings::new(&assets),
            tickets: tickets::Tickets::new(config.ticket_seconds, config.limits.max_tickets),
            config,
            assets,
            worker,
            metrics,
            shutdown: watch::Sender::new(false),
            streams: AtomicUsize::new(0),
            streams_closed: Notify::new(),
            connections: listen::Connections::new(max_connections),
        }))
    }

    /// Whether shutdown has begun (new work is refused).
    pub fn shutting_down(&self) -> bool {
        *self.shutdown.borrow()
    }

    /// Becomes `true` when shutdown begins.
    pub fn shutdown_receiver(&self) -> watch::Receiver<bool> {
        self.shutdown.subscribe()
    }

    fn begin_shutdown(&self) {
        self.shutdown.send_replace(true);
    }

    /// Holds a stream's slot until the guard is dropped, or refuses when `max_streams` are
    /// open.
    pub fn open_stream(self: &Arc<Self>) -> Result<StreamGuard, LimitExceeded> {
        let max = self.config.limits.max_streams;
        self.streams
            .fetch_update(Ordering::SeqCst, Ordering::SeqCst, |open| (open < max).then_some(open + 1))
            .map_err(|open| LimitExceeded {
                limit: config::limit::MAX_STREAMS,
                field: None,
                message: format!("{open} streams are open, the limit; retry later"),
            })?;
        Ok(StreamGuard(self.clone()))
    }

    async fn all_streams_closed(&self) {
        loop {
            let notified = self.streams_closed.notified();
            if self.streams.load(Ordering::SeqCst) == 0 {
                return;
            }
            notified.await;
        }
    }

    /// The metrics' gauges, read now.
    pub fn gauges(&self) -> metrics::Gauges {
        metrics::Gauges {
            queue_depth: self.worker.queue_depth(),
            queue_capacity: self.worker.queue_capacity(),
            scenes: self.scenes.len(),
            streams: self.streams.load(Ordering::SeqCst),
            connections: self.connections.open(),
        }
    }
}

/// An open stream, counted while it lives.
pub struct StreamGuard(Arc<AppState>);

impl Drop for StreamGuard {
    fn drop(&mut self) {
        self.0.streams.fetch_sub(1, Ordering::SeqCst);
        self.0.streams_closed.notify_waiters();
    }
}

/// A bound, ready server: the GPU thread is up and the socket listens.
pub struct Server {
    listener: tokio::net::TcpListener,
    state: Arc<AppState>,
}

impl Server {
    /// Checks the asset directory, starts the GPU thread and binds `config.addr`.
    pub async fn bind(config: Config) -> Result<Server, ServeError> {
        let limits = config.limits;
        Server::bind_with(config, move |metrics| GpuWorker::start(&limits, metrics)).await
    }

    /// [`Server::bind`] with the worker `start` makes (on a blocking thread), e.g. one on
    /// another [`Backend`].
    pub async fn bind_with(
        config: Config,
        start: impl FnOnce(Arc<Metrics>) -> Result<GpuWorker, WorkerError> + Send + 'static,
    ) -> Result<Server, ServeError> {
        let addr = config.addr;
        let state = AppState::start(config, start).await?;
        let listener = tokio::net::TcpListener::bind(addr).await.map_err(|source| ServeError::Bind { addr, source })?;
        Ok(Server { listener, state })
    }

    /// The address actually bound (port 0 resolved).
    pub fn local_addr(&self) -> SocketAddr {
        self.listener.local_addr().expect("a bound TCP listener has an address")
    }

    pub fn state(&self) -> &Arc<AppState> {
        &self.state
    }

    /// Serves until `shutdown` completes, then shuts down gracefully (see the module docs).
    pub async fn run(self, shutdown: impl Future<Output = ()> + Send + 'static) -> Result<(), ServeError> {
        let Server { listener, state } = self;
        let grace = Duration::from_secs(state.config.shutdown_grace_seconds);
        tracing::info!(
            addr = %listener.local_addr()?,
            assets = %state.assets.display(),
            adapter = state.worker.adapter(),
            token = state.config.token.is_some(),
            "serving"
        );
        let signalled = state.clone();
        let graceful = async move {
            shutdown.await;
            tracing::info!("shutting down: refusing new work, finishing in-flight requests and queued renders");
            signalled.begin_shutdown();
        };
        let mut stopping = state.shutdown_receiver();
        let deadline = async move {
            let _ = stopping.wait_for(|&s| s).await;
            tokio::time::sleep(grace).await;
        };
        let serve = listen::serve(listener, router(state.clone()), state.clone(), graceful);
        let completed = tokio::select! {
            result = serve => {
                result?;
                true
            }
            () = deadline => false,
        };
        if completed {
            // Streams were told to close when shutdown began.
            if tokio::time::timeout(grace, state.all_streams_closed()).await.is_err() {
                tracing::warn!("streams still open after the grace period; dropping them");
            }
        } else {
            tracing::warn!(?grace, "grace period over: dropping the requests still in flight");
        }
        state.worker.stop().await;
        tracing::info!("stopped");
        Ok(())
    }
}

/// Runs the service until SIGINT or SIGTERM.
pub async fn serve(config: Config) -> Result<(), ServeError> {
    let server = Server::bind(config).await?;
    // Listen for the signals before `run` logs "serving": a supervisor (or a test) may signal
    // as soon as it reads that line, and a signal that arrives before its handler is
    // registered kills the process instead of shutting it down.
    let shutdown = shutdown_signal();
    server.run(shutdown).await
}

/// Completes on SIGINT (Ctrl-C) or, on Unix, SIGTERM. The handlers are registered when this is
/// called, not when the future is first polled, so no signal sent after the call is missed.
pub fn shutdown_signal() -> impl Future<Output = ()> + Send + 'static {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        let interrupt = signal(SignalKind::interrupt());
        let terminate = signal(SignalKind::terminate());
        async move {
            let wait = |listener: std::io::Result<tokio::signal::unix::Signal>, name: &'static str| async move {
                match listener {
                    Ok(mut listener) => {
                        listener.recv().await;
                    }
                    Err(error) => {
                        tracing::error!("cannot listen for {name}: {error}");
                        std::future::pending::<()>().await;
                    }
                }
            };
            tokio::select! {
                () = wait(interrupt, "SIGINT") => tracing::info!("SIGINT received"),
                () = wait(terminate, "SIGTERM") => tracing::info!("SIGTERM received"),
            }
        }
    }
    #[cfg(not(unix))]
    async {
        if let Err(error) = tokio::signal::ctrl_c().await {
            tracing::error!("cannot listen for Ctrl-C: {error}");
            std::future::pending::<()>().await;
        }
        tracing::info!("SIGINT received");
    }
}

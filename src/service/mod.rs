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
//! - [`gpu_worker`]: a thread that owns one GPU device; handlers send it jobs through the
//!   [`schedule`] queue, fair between clients, and a full queue is a 503. [`workers`]: one
//!   such worker per GPU (`--adapters`) and the routing of scenes, renders and streams
//!   between them.
//! - [`store`]: the scene store shared by backends behind a load balancer (`--scene-store`);
//!   [`ready`]: `/readyz`, whether a load balancer should send this process new work.
//! - [`listen`]: the connection loop: header and body timeouts, the connection cap.
//! - [`scenes`]: admitting scene descriptions (limits, paths confined to the asset directory)
//!   and the registry of scenes held.
//! - [`config`]: flags, environment variables and limits; [`metrics`]: Prometheus text.
//! - [`client`]: a client of the service (`relume replay --server`); [`load`]: its load
//!   benchmark (`relume load`).
//!
//! Shutdown (SIGINT, SIGTERM, or the future given to [`Server::run`]): `/readyz` answers 503
//! `draining` at once; after `drain_delay_seconds` (0 by default) the server stops
//! accepting connections, answers new work with 503 `shutting_down`, lets in-flight requests
//! and queued renders finish, closes streams with 1001 (going away) after an `Error` of code
//! `SHUTTING_DOWN`, then stops the GPU threads. After `shutdown_grace_seconds` whatever is
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
pub mod ready;
pub mod recordings;
pub mod scenes;
pub mod schedule;
pub mod store;
pub mod stream;
pub mod tickets;
pub mod viewer;
pub mod wire;
pub mod workers;

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
pub use workers::Workers;

/// Why the service could not start or stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    #[error("asset directory {}: {source}", path.display())]
    Assets { path: PathBuf, source: std::io::Error },
    #[error("asset directory {}: not a directory", .0.display())]
    AssetsNotADirectory(PathBuf),
    #[error("scene store {}: {source}", path.display())]
    Store { path: PathBuf, source: std::io::Error },
    #[error("stream tickets: {0}")]
    Tickets(String),
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
    /// Tickets issued by `POST /v1/tickets`: their key, those outstanding, where used ones
    /// are marked.
    pub tickets: tickets::Tickets,
    /// The GPU workers, one per device.
    pub workers: Workers,
    /// The scene store shared with other backends (`--scene-store`).
    pub store: Option<store::SceneStore>,
    /// Held while a scene is loaded from the store.
    store_loads: tokio::sync::Mutex<()>,
    pub metrics: Arc<Metrics>,
    shutdown: watch::Sender<bool>,
    /// A signal came: `/readyz` says `draining` (shutdown begins `drain_delay_seconds` later).
    draining: std::sync::atomic::AtomicBool,
    streams: AtomicUsize,
    streams_closed: Notify,
    connections: listen::Connections,
}

/// The tickets of `config`: keyed by `--ticket-key-file`, else `--token`, else a random key;
/// single use across the processes sharing `store` when there is one.
fn start_tickets(config: &Config, store: Option<&store::SceneStore>) -> Result<tickets::Tickets, ServeError> {
    let (key, source) = match (&config.ticket_key, &config.token) {
        (Some(key), _) => (key.clone(), tickets::KeySource::File),
        (None, Some(token)) => (tickets::TicketKey::from_secret(token.as_bytes()), tickets::KeySource::Token),
        (None, None) => (
            tickets::TicketKey::random().map_err(|e| ServeError::Tickets(format!("no random key: {e}")))?,
            tickets::KeySource::Random,
        ),
    };
    let spent = match store {
        Some(store) => {
            Some(store.open_tickets().map_err(|source| ServeError::Store { path: store.dir().to_owned(), source })?)
        }
        None => None,
    };
    Ok(tickets::Tickets::with_key(config.ticket_seconds, config.limits.max_tickets, key, spent).keyed_by(source))
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
        let quarantine = Duration::from_secs(config.worker_quarantine_seconds);
        AppState::start_workers(config, move |metrics| Ok(Workers::new(vec![start(metrics)?], quarantine))).await
    }

    /// [`AppState::start`] with the workers `start` makes (on a blocking thread).
    pub async fn start_workers(
        config: Config,
        start: impl FnOnce(Arc<Metrics>) -> Result<Workers, WorkerError> + Send + 'static,
    ) -> Result<Arc<AppState>, ServeError> {
        let store = match &config.scene_store {
            Some(dir) => {
                Some(store::SceneStore::open(dir).map_err(|source| ServeError::Store { path: dir.clone(), source })?)
            }
            None => None,
        };
        let assets = std::fs::canonicalize(&config.assets)
            .map_err(|source| ServeError::Assets { path: config.assets.clone(), source })?;
        if !assets.is_dir() {
            return Err(ServeError::AssetsNotADirectory(assets));
        }
        let tickets = start_tickets(&config, store.as_ref())?;
        let metrics = Arc::new(Metrics::default());
        let worker_metrics = metrics.clone();
        let workers = tokio::task::spawn_blocking(move || start(worker_metrics))
            .await
            .map_err(|e| WorkerError::Panicked(e.to_string()))??;
        let max_connections = config.limits.max_connections;
        Ok(Arc::new(AppState {
            scenes: scenes::SceneRegistry::new(config.limits.max_scenes),
            recordings: recordings::Recordings::new(&assets),
            tickets,
            config,
            assets,
            workers,
            store,
            store_loads: tokio::sync::Mutex::new(()),
            metrics,
            shutdown: watch::Sender::new(false),
            draining: std::sync::atomic::AtomicBool::new(false),
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

    /// Whether a signal came: from then on the process is draining, shut down or not yet.
    pub fn draining(&self) -> bool {
        self.draining.load(Ordering::SeqCst) || self.shutting_down()
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

    /// Open streams.
    pub fn streams(&self) -> usize {
        self.streams.load(Ordering::SeqCst)
    }

    /// The metrics' text: [`Metrics::render`] and the per-worker families.
    pub fn metrics_text(&self) -> String {
        let mut text = self.metrics.render(&self.gauges());
        self.metrics.render_workers(&self.workers.gauges(), &mut text);
        text
    }

    /// The metrics' gauges, read now.
    pub fn gauges(&self) -> metrics::Gauges {
        metrics::Gauges {
            queue_depth: self.workers.queue_depth(),
            queue_capacity: self.workers.queue_capacity(),
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
    /// Checks the asset directory, starts the GPU workers (`config.adapters`) and binds
    /// `config.addr`.
    pub async fn bind(config: Config) -> Result<Server, ServeError> {
        let workers_config = config.clone();
        Server::bind_workers(config, move |metrics| Workers::start(&workers_config, metrics)).await
    }

    /// [`Server::bind`] with the worker `start` makes (on a blocking thread), e.g. one on
    /// another [`Backend`].
    pub async fn bind_with(
        config: Config,
        start: impl FnOnce(Arc<Metrics>) -> Result<GpuWorker, WorkerError> + Send + 'static,
    ) -> Result<Server, ServeError> {
        let quarantine = Duration::from_secs(config.worker_quarantine_seconds);
        Server::bind_workers(config, move |metrics| Ok(Workers::new(vec![start(metrics)?], quarantine))).await
    }

    /// [`Server::bind`] with the workers `start` makes (on a blocking thread).
    pub async fn bind_workers(
        config: Config,
        start: impl FnOnce(Arc<Metrics>) -> Result<Workers, WorkerError> + Send + 'static,
    ) -> Result<Server, ServeError> {
        let addr = config.addr;
        let state = AppState::start_workers(config, start).await?;
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
            adapter = state.workers.adapter(),
            workers = state.workers.len(),
            scene_store = state.store.is_some(),
            token = state.config.token.is_some(),
            ticket_key = state.tickets.key_source().as_str(),
            tickets_shared = state.tickets.shared(),
            "serving"
        );
        let signalled = state.clone();
        let drain_delay = Duration::from_secs(state.config.drain_delay_seconds);
        let graceful = async move {
            shutdown.await;
            signalled.draining.store(true, Ordering::SeqCst);
            if !drain_delay.is_zero() {
                tracing::info!(
                    ?drain_delay,
                    "draining: /readyz answers 503, serving as before until the delay is over"
                );
                tokio::time::sleep(drain_delay).await;
            }
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
        state.workers.stop().await;
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

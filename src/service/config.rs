//! The service's settings: every one a `relume serve` flag with an environment variable and a
//! default. Limits are enforced at the boundary (HTTP handler or stream decoder) with an error
//! that names the setting.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use super::tickets::TicketKey;

/// The default of [`Config::ticket_seconds`].
pub const DEFAULT_TICKET_SECONDS: u64 = 30;

/// The largest [`Config::ticket_seconds`] the command line takes (an hour); longer values set
/// in code are treated as this.
pub const MAX_TICKET_SECONDS: u64 = 3600;

/// The bounds of [`Limits::max_header_bytes`]: hyper's smallest read buffer, and 64 KiB (a
/// request target of 65,535 bytes or more, which the `http` crate cannot hold, is then over
/// the limit too). Values set in code outside these are treated as the nearest bound.
pub const HEADER_BYTES_RANGE: std::ops::RangeInclusive<usize> = 8192..=65_536;

/// The largest [`Config::drain_delay_seconds`] (ten minutes).
pub const MAX_DRAIN_DELAY_SECONDS: u64 = 600;

/// The default of [`Config::worker_quarantine_seconds`].
pub const DEFAULT_QUARANTINE_SECONDS: u64 = 30;

/// The most workers `--adapters N` starts.
pub const MAX_WORKERS: usize = 64;

/// `--ticket-key-file`: the key derived from the file's secret, or why there is none (the
/// file unreadable, or under [`super::tickets::MIN_KEY_FILE_BYTES`]).
fn ticket_key_file(path: &str) -> Result<TicketKey, String> {
    TicketKey::from_file(Path::new(path))
}

/// Which GPU adapters get a worker (`--adapters`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum AdapterSelection {
    /// One worker per adapter found.
    All,
    /// This many workers, on the adapters found in turn (the first adapter alone for 1, as
    /// wgpu chooses it).
    Count(usize),
    /// One worker per adapter whose name contains one of these (case-insensitive).
    Names(Vec<String>),
}

impl std::str::FromStr for AdapterSelection {
    type Err = String;

    fn from_str(text: &str) -> Result<AdapterSelection, String> {
        let text = text.trim();
        if text.eq_ignore_ascii_case("all") {
            return Ok(AdapterSelection::All);
        }
        if let Ok(count) = text.parse::<usize>() {
            return match count {
                1..=MAX_WORKERS => Ok(AdapterSelection::Count(count)),
                _ => Err(format!("{count} workers: between 1 and {MAX_WORKERS}")),
            };
        }
        let names: Vec<String> = text.split(',').map(|name| name.trim().to_owned()).collect();
        if names.iter().any(String::is_empty) {
            return Err(format!("`{text}`: `all`, a count, or adapter names separated by commas (none empty)"));
        }
        Ok(AdapterSelection::Names(names))
    }
}

impl AdapterSelection {
    /// The adapter of each worker, as an index into `adapters` (the names of
    /// [`crate::gpu::Gpu::adapters`]); `None` for wgpu's own choice (a single worker). Errors
    /// name the name that matches no adapter.
    pub fn workers(&self, adapters: &[String]) -> Result<Vec<Option<usize>>, String> {
        match self {
            AdapterSelection::Count(1) => Ok(vec![None]),
            AdapterSelection::Count(count) => Ok((0..*count).map(|i| Some(i % adapters.len().max(1))).collect()),
            AdapterSelection::All if adapters.is_empty() => Ok(vec![None]),
            AdapterSelection::All => Ok((0..adapters.len()).map(Some).collect()),
            AdapterSelection::Names(names) => {
                let mut chosen = Vec::new();
                for name in names {
                    let wanted = name.to_lowercase();
                    let matches: Vec<usize> =
                        (0..adapters.len()).filter(|&i| adapters[i].to_lowercase().contains(&wanted)).collect();
                    if matches.is_empty() {
                        return Err(format!("no adapter named `{name}` (found: {})", adapters.join("; ")));
                    }
                    for index in matches {
                        if !chosen.contains(&Some(index)) {
                            chosen.push(Some(index));
                        }
                    }
                }
                Ok(chosen)
            }
        }
    }
}

/// How `relume serve` runs.
#[derive(Clone, Debug, clap::Args)]
pub struct Config {
    /// Address to listen on (use port 0 for any free port).
    #[arg(long, env = "RELUME_ADDR", default_value = "127.0.0.1:8080")]
    pub addr: SocketAddr,
    /// Directory that scene mesh and texture paths are relative to; paths that resolve outside
    /// it (`..`, absolute paths, symbolic links) are refused.
    #[arg(long, env = "RELUME_ASSETS", default_value = ".")]
    pub assets: PathBuf,
    /// Bearer token required on every `/v1` route (`Authorization: Bearer <token>`); without
    /// it the API is open. `/healthz` and `/metrics` never need it. A stream may present a
    /// ticket from `POST /v1/tickets` instead (`?ticket=`), for browsers, which cannot set a
    /// WebSocket's headers.
    #[arg(long, env = "RELUME_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// Seconds a ticket from `POST /v1/tickets` stays valid (1..=3600); it is also single use.
    #[arg(long, env = "RELUME_TICKET_SECONDS", default_value_t = DEFAULT_TICKET_SECONDS,
        value_parser = clap::value_parser!(u64).range(1..=MAX_TICKET_SECONDS))]
    pub ticket_seconds: u64,
    /// A file holding a secret (at least 32 bytes; surrounding whitespace ignored) shared by
    /// the backends behind one load balancer: tickets are signed with a key derived from it,
    /// so a ticket one backend issued opens a stream on another that shares the key and the
    /// `--scene-store` (once in all). Without it the key comes from `--token`, else it is
    /// random per process. Read and checked when the command line is parsed.
    #[arg(long = "ticket-key-file", env = "RELUME_TICKET_KEY_FILE", value_name = "PATH",
        value_parser = ticket_key_file)]
    pub ticket_key: Option<TicketKey>,
    /// Seconds that in-flight requests, queued renders and open streams get to finish after
    /// SIGINT or SIGTERM before they are dropped.
    #[arg(long, env = "RELUME_SHUTDOWN_GRACE_SECONDS", default_value_t = 30)]
    pub shutdown_grace_seconds: u64,
    /// Seconds between SIGTERM (or SIGINT) and the start of the shutdown, during which the
    /// process serves as before but `/readyz` answers 503 `draining`, so that load balancers
    /// and Kubernetes stop sending it work before it stops accepting connections.
    #[arg(long, env = "RELUME_DRAIN_DELAY_SECONDS", default_value_t = 0,
        value_parser = clap::value_parser!(u64).range(0..=MAX_DRAIN_DELAY_SECONDS))]
    pub drain_delay_seconds: u64,
    /// GPU workers, one thread and one device each: `all` (one per adapter found), `N`
    /// (1..=64; N workers on the adapters found in turn, so N above the adapter count opens
    /// several devices on one adapter) or a comma-separated list of names (each a
    /// case-insensitive part of an adapter's name; every adapter it matches gets a worker).
    #[arg(long, env = "RELUME_ADAPTERS", default_value = "1")]
    pub adapters: AdapterSelection,
    /// Seconds a worker whose device was lost gets no new work while another worker is up
    /// (its streams move to another worker too).
    #[arg(long, env = "RELUME_WORKER_QUARANTINE_SECONDS", default_value_t = DEFAULT_QUARANTINE_SECONDS)]
    pub worker_quarantine_seconds: u64,
    /// A directory the backends behind one load balancer share: every scene created is also
    /// written there (its description, by id), and a request for a scene this process does not
    /// hold loads it from there, so a scene outlives the backend that created it. A scene
    /// whose file is gone (deleted through another backend) is dropped here too.
    #[arg(long, env = "RELUME_SCENE_STORE")]
    pub scene_store: Option<PathBuf>,
    #[command(flatten)]
    pub limits: Limits,
    #[command(flatten)]
    pub timeouts: Timeouts,
}

impl Config {
    /// The defaults, listening on `addr` and reading meshes from `assets` (for tests and
    /// embedding; the command line fills the same struct).
    pub fn new(addr: SocketAddr, assets: impl Into<PathBuf>) -> Config {
        Config {
            addr,
            assets: assets.into(),
            token: None,
            ticket_seconds: DEFAULT_TICKET_SECONDS,
            ticket_key: None,
            shutdown_grace_seconds: 30,
            drain_delay_seconds: 0,
            adapters: AdapterSelection::Count(1),
            worker_quarantine_seconds: DEFAULT_QUARANTINE_SECONDS,
            scene_store: None,
            limits: Limits::default(),
            timeouts: Timeouts::default(),
        }
    }
}

/// Every limit of the service. Exceeding one is an error naming it: HTTP 413 for sizes in bytes,
/// HTTP 400 for the others, an `Error` message with code `LIMIT_EXCEEDED` on a stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::Args, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct Limits {
    /// Largest HTTP request body, bytes (scene descriptions with inline OBJ text).
    #[arg(long, env = "RELUME_MAX_BODY_BYTES", default_value_t = Limits::default().max_body_bytes)]
    pub max_body_bytes: usize,
    /// Largest HTTP request head, bytes: the request line (with the URI) and the headers
    /// together (8192..=65536); a larger one is answered 431 and the connection closed.
    #[arg(long, env = "RELUME_MAX_HEADER_BYTES", default_value_t = Limits::default().max_header_bytes,
        value_parser = clap::builder::RangedU64ValueParser::<usize>::new()
            .range(*HEADER_BYTES_RANGE.start() as u64..=*HEADER_BYTES_RANGE.end() as u64))]
    pub max_header_bytes: usize,
    /// Most headers of an HTTP request; one more is answered 431 and the connection closed.
    #[arg(long, env = "RELUME_MAX_HEADERS", default_value_t = Limits::default().max_headers)]
    pub max_headers: usize,
    /// Largest stream message (one protobuf envelope), bytes.
    #[arg(long, env = "RELUME_MAX_MESSAGE_BYTES", default_value_t = Limits::default().max_message_bytes)]
    pub max_message_bytes: usize,
    /// Largest width or height, pixels, of a rendered image and of an RGB-D frame.
    #[arg(long, env = "RELUME_MAX_FRAME_SIDE", default_value_t = Limits::default().max_frame_side)]
    pub max_frame_side: u32,
    /// Most VALs one frame may have: a scene's `rsm_resolution²`, an RGB-D frame's grid cells.
    #[arg(long, env = "RELUME_MAX_VALS", default_value_t = Limits::default().max_vals)]
    pub max_vals: u32,
    /// Most scenes held at once.
    #[arg(long, env = "RELUME_MAX_SCENES", default_value_t = Limits::default().max_scenes)]
    pub max_scenes: usize,
    /// Largest OBJ, bytes (a file in the asset directory or inline `obj_text`).
    #[arg(long, env = "RELUME_MAX_MESH_BYTES", default_value_t = Limits::default().max_mesh_bytes)]
    pub max_mesh_bytes: usize,
    /// Most renders waiting for the GPU, all clients together; one more gets 503 with
    /// `Retry-After`.
    #[arg(long, env = "RELUME_MAX_QUEUE", default_value_t = Limits::default().max_queue)]
    pub max_queue: usize,
    /// Most renders one client (one IP address) may have waiting for the GPU; one more gets
    /// 503 with `Retry-After`. Clients are served round robin.
    #[arg(long, env = "RELUME_MAX_CLIENT_QUEUE", default_value_t = Limits::default().max_client_queue)]
    pub max_client_queue: usize,
    /// Most triangles of a scene after subdivision, all meshes together (checked on the OBJ's
    /// triangles before any work, and while subdividing).
    #[arg(long, env = "RELUME_MAX_TRIANGLES", default_value_t = Limits::default().max_triangles)]
    pub max_triangles: usize,
    /// Most sparse points of a scene, all meshes' `sparse_points` together.
    #[arg(long, env = "RELUME_MAX_SPARSE_POINTS", default_value_t = Limits::default().max_sparse_points)]
    pub max_sparse_points: u32,
    /// Most pixels (width x height) of a rendered image, a stream's camera or an RGB-D frame.
    #[arg(long, env = "RELUME_MAX_PIXELS", default_value_t = Limits::default().max_pixels)]
    pub max_pixels: u64,
    /// Most WebSocket streams open at once; one more gets 503 before the upgrade. Each buffers
    /// at most `2 * max_message_bytes` of an incoming message.
    #[arg(long, env = "RELUME_MAX_STREAMS", default_value_t = Limits::default().max_streams)]
    pub max_streams: usize,
    /// Most HTTP connections open at once (WebSocket streams not included once upgraded); one
    /// more is answered 503 and closed.
    #[arg(long, env = "RELUME_MAX_CONNECTIONS", default_value_t = Limits::default().max_connections)]
    pub max_connections: usize,
    /// Most tickets (`POST /v1/tickets`) issued and neither used nor expired; one more is
    /// refused with 503 and `Retry-After` (when the oldest expires). 0 turns tickets off.
    #[arg(long, env = "RELUME_MAX_TICKETS", default_value_t = Limits::default().max_tickets)]
    pub max_tickets: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_body_bytes: 32 << 20,
            max_header_bytes: 16 << 10,
            max_headers: 100,
            max_message_bytes: 16 << 20,
            max_frame_side: 4096,
            max_vals: 65_536,
            max_scenes: 16,
            max_mesh_bytes: 32 << 20,
            max_queue: 16,
            max_client_queue: 2,
            max_triangles: 2_000_000,
            max_sparse_points: 65_536,
            max_pixels: 4 << 20,
            max_streams: 8,
            max_connections: 128,
            max_tickets: 32,
        }
    }
}

/// Names of the limits as they appear in errors (`"limit": "max_vals"`) and on the command
/// line (`--max-vals`).
pub mod limit {
    pub const MAX_BODY_BYTES: &str = "max_body_bytes";
    pub const MAX_HEADER_BYTES: &str = "max_header_bytes";
    pub const MAX_HEADERS: &str = "max_headers";
    pub const MAX_MESSAGE_BYTES: &str = "max_message_bytes";
    pub const MAX_FRAME_SIDE: &str = "max_frame_side";
    pub const MAX_VALS: &str = "max_vals";
    pub const MAX_SCENES: &str = "max_scenes";
    pub const MAX_MESH_BYTES: &str = "max_mesh_bytes";
    pub const MAX_QUEUE: &str = "max_queue";
    pub const MAX_CLIENT_QUEUE: &str = "max_client_queue";
    pub const MAX_TRIANGLES: &str = "max_triangles";
    pub const MAX_SPARSE_POINTS: &str = "max_sparse_points";
    pub const MAX_PIXELS: &str = "max_pixels";
    pub const MAX_STREAMS: &str = "max_streams";
    pub const MAX_CONNECTIONS: &str = "max_connections";
    pub const MAX_TICKETS: &str = "max_tickets";
}

/// A limit exceeded by a request or stream message, before any work was done for it; the
/// HTTP and stream errors are made from it.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct LimitExceeded {
    /// The setting, one of [`limit`].
    pub limit: &'static str,
    /// The offending field, e.g. `camera.width`.
    pub field: Option<String>,
    /// For people; starts with the field's path when there is one.
    pub message: String,
}

impl LimitExceeded {
    fn new(limit: &'static str, field: String, message: impl std::fmt::Display) -> LimitExceeded {
        LimitExceeded { limit, message: format!("{field}: {message}"), field: Some(field) }
    }
}

impl Limits {
    /// [`Limits::max_header_bytes`] within [`HEADER_BYTES_RANGE`].
    pub fn header_bytes(&self) -> usize {
        self.max_header_bytes.clamp(*HEADER_BYTES_RANGE.start(), *HEADER_BYTES_RANGE.end())
    }

    /// An image `width` x `height` within `max_frame_side` and `max_pixels`; errors name
    /// `{field}.width` / `.height`, or `field` for the pixel count.
    pub fn check_image(&self, width: u32, height: u32, field: &str) -> Result<(), LimitExceeded> {
        for (name, value) in [("width", width), ("height", height)] {
            if value > self.max_frame_side {
                let message = format!("{value} pixels is over the limit of {}", self.max_frame_side);
                return Err(LimitExceeded::new(limit::MAX_FRAME_SIDE, format!("{field}.{name}"), message));
            }
        }
        let pixels = width as u64 * height as u64;
        if pixels > self.max_pixels {
            let message = format!("{width} x {height} = {pixels} pixels is over the limit of {}", self.max_pixels);
            return Err(LimitExceeded::new(limit::MAX_PIXELS, field.to_owned(), message));
        }
        Ok(())
    }
}

/// How long the service waits for a client before it closes the connection.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::Args)]
pub struct Timeouts {
    /// Seconds a connection may take to send a request's headers, counted from when it opened
    /// or its previous answer was sent: slow headers, silent sockets and idle keep-alive
    /// connections are closed after it.
    #[arg(long, env = "RELUME_HEADER_TIMEOUT_SECONDS", default_value_t = Timeouts::default().header_timeout_seconds,
        value_parser = clap::value_parser!(u64).range(1..))]
    pub header_timeout_seconds: u64,
    /// Seconds a request body may take to arrive; slower is answered 408.
    #[arg(long, env = "RELUME_BODY_TIMEOUT_SECONDS", default_value_t = Timeouts::default().body_timeout_seconds,
        value_parser = clap::value_parser!(u64).range(1..))]
    pub body_timeout_seconds: u64,
    /// Seconds between the pings the server sends on an open stream.
    #[arg(long, env = "RELUME_STREAM_PING_SECONDS", default_value_t = Timeouts::default().stream_ping_seconds,
        value_parser = clap::value_parser!(u64).range(1..))]
    pub stream_ping_seconds: u64,
    /// Seconds a stream may go without any message from the client (pongs included), and a
    /// message to the client may take to be sent, before the stream is closed (1001).
    #[arg(long, env = "RELUME_STREAM_IDLE_SECONDS", default_value_t = Timeouts::default().stream_idle_seconds,
        value_parser = clap::value_parser!(u64).range(1..))]
    pub stream_idle_seconds: u64,
}

impl Default for Timeouts {
    fn default() -> Self {
        Timeouts {
            header_timeout_seconds: 10,
            body_timeout_seconds: 30,
            stream_ping_seconds: 15,
            stream_idle_seconds: 60,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn adapters_are_chosen_by_count_all_or_name() {
        let found = ["NVIDIA H100 (Vulkan)".to_owned(), "llvmpipe (LLVM 15) (Vulkan)".to_owned()];
        let parse = |text: &str| text.parse::<AdapterSelection>();
        assert_eq!(parse("1").and_then(|s| s.workers(&found)), Ok(vec![None]));
        assert_eq!(parse("3").and_then(|s| s.workers(&found)), Ok(vec![Some(0), Some(1), Some(0)]));
        assert_eq!(parse("ALL").and_then(|s| s.workers(&found)), Ok(vec![Some(0), Some(1)]));
        assert_eq!(parse("h100, LLVMpipe,nvidia").and_then(|s| s.workers(&found)), Ok(vec![Some(0), Some(1)]));
        let error = parse("radeon").and_then(|s| s.workers(&found)).expect_err("no such adapter");
        assert!(error.contains("`radeon`") && error.contains("llvmpipe"), "{error}");
        assert!(parse("0").is_err() && parse("65").is_err() && parse("a,,b").is_err() && parse("").is_err());
    }
}

//! The service's settings: every one a `relume serve` flag with an environment variable and a
//! default. Limits are enforced at the boundary (HTTP handler or stream decoder) with an error
//! that names the setting.

use std::net::SocketAddr;
use std::path::PathBuf;

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
    /// it the API is open. `/healthz` and `/metrics` never need it.
    #[arg(long, env = "RELUME_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// Seconds that in-flight requests, queued renders and open streams get to finish after
    /// SIGINT or SIGTERM before they are dropped.
    #[arg(long, env = "RELUME_SHUTDOWN_GRACE_SECONDS", default_value_t = 30)]
    pub shutdown_grace_seconds: u64,
    #[command(flatten)]
    pub limits: Limits,
}

impl Config {
    /// The defaults, listening on `addr` and reading meshes from `assets` (for tests and
    /// embedding; the command line fills the same struct).
    pub fn new(addr: SocketAddr, assets: impl Into<PathBuf>) -> Config {
        Config { addr, assets: assets.into(), token: None, shutdown_grace_seconds: 30, limits: Limits::default() }
    }
}

/// Every limit of the service. Exceeding one is an error naming it: HTTP 413 for sizes in bytes,
/// HTTP 400 for the others, an `Error` message with code `LIMIT_EXCEEDED` on a stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::Args, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct Limits {
    /// Largest HTTP request body, bytes (scene descriptions with inline OBJ text).
    #[arg(long, env = "RELUME_MAX_BODY_BYTES", default_value_t = Limits::default().max_body_bytes)]
    pub max_body_bytes: usize,
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
    /// Most renders waiting for the GPU; one more gets 503 with `Retry-After`.
    #[arg(long, env = "RELUME_MAX_QUEUE", default_value_t = Limits::default().max_queue)]
    pub max_queue: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_body_bytes: 32 << 20,
            max_message_bytes: 16 << 20,
            max_frame_side: 4096,
            max_vals: 65_536,
            max_scenes: 16,
            max_mesh_bytes: 32 << 20,
            max_queue: 8,
        }
    }
}

/// Names of the limits as they appear in errors (`"limit": "max_vals"`) and on the command
/// line (`--max-vals`).
pub mod limit {
    pub const MAX_BODY_BYTES: &str = "max_body_bytes";
    pub const MAX_MESSAGE_BYTES: &str = "max_message_bytes";
    pub const MAX_FRAME_SIDE: &str = "max_frame_side";
    pub const MAX_VALS: &str = "max_vals";
    pub const MAX_SCENES: &str = "max_scenes";
    pub const MAX_MESH_BYTES: &str = "max_mesh_bytes";
    pub const MAX_QUEUE: &str = "max_queue";
}

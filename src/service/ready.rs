//! `GET /readyz`: whether a load balancer (or Kubernetes' readiness probe) should send this
//! process new work. Beside `/healthz` (is the process alive), it answers 503 while the
//! process drains after SIGTERM or SIGINT (from the signal: during `drain_delay_seconds` it
//! still serves, then it stops accepting) and while it is saturated: every GPU worker that is
//! up has `max_queue` renders waiting, or `max_streams` streams are open. Work already on the
//! process goes on either way.

use std::sync::Arc;

use axum::Json;
use axum::extract::State;
use axum::http::StatusCode;

use super::AppState;

/// The answer of `/readyz`.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Readiness {
    /// `ready` (200), or `draining` or `saturated` (503).
    pub status: String,
    /// GPU workers taking new work, and all of them.
    pub workers_up: usize,
    pub workers: usize,
    /// Renders waiting, all workers, and the most that may wait.
    pub queue_depth: usize,
    pub queue_capacity: usize,
    /// Open streams and `max_streams`.
    pub streams: usize,
    pub max_streams: usize,
}

/// 200 `ready`, or 503 `draining` / `saturated`.
pub async fn readyz(State(state): State<Arc<AppState>>) -> (StatusCode, Json<Readiness>) {
    let readiness = readiness(&state);
    let code = if readiness.status == "ready" { StatusCode::OK } else { StatusCode::SERVICE_UNAVAILABLE };
    (code, Json(readiness))
}

/// The process's readiness now.
pub fn readiness(state: &AppState) -> Readiness {
    let streams = state.streams();
    let max_streams = state.config.limits.max_streams;
    let status = if state.draining() {
        "draining"
    } else if state.workers.saturated() || streams >= max_streams {
        "saturated"
    } else {
        "ready"
    };
    Readiness {
        status: status.to_owned(),
        workers_up: state.workers.up(),
        workers: state.workers.len(),
        queue_depth: state.workers.queue_depth(),
        queue_capacity: state.workers.queue_capacity(),
        streams,
        max_streams,
    }
}

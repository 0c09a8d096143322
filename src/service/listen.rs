//! The connection loop of `relume serve` (in place of `axum::serve`, which has no timeouts):
//! HTTP/1.1 connections served by hyper with
//!
//! - a header timeout (`header_timeout_seconds`): hyper closes a connection whose request
//!   headers have not all arrived that long after it opened or after its previous answer, so
//!   half-sent headers, silent sockets and idle keep-alive connections all go;
//! - a cap on open connections (`max_connections`): one more is answered 503 and closed at
//!   once, so idle sockets cannot use up the process's descriptors (a connection that becomes
//!   a WebSocket stream leaves the count and is counted by `max_streams` instead);
//! - the peer's address in each request's extensions (`ConnectInfo`), which the fair queue
//!   uses as the client's identity.
//!
//! Shutdown stops accepting, lets open connections finish their requests and closes them, and
//! completes when every connection has closed.

use std::future::Future;
use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::extract::ConnectInfo;
use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use tokio::net::TcpListener;
use tokio::sync::Semaphore;
use tower::ServiceExt;

use super::AppState;
use super::config::limit;
use super::error::ApiError;

/// How long to wait before accepting again after `accept` failed (e.g. out of descriptors).
const ACCEPT_BACKOFF: Duration = Duration::from_millis(50);

/// The open connections, counted against `max_connections`.
pub struct Connections {
    slots: Arc<Semaphore>,
    max: usize,
}

impl Connections {
    pub fn new(max: usize) -> Connections {
        Connections { slots: Arc::new(Semaphore::new(max)), max }
    }

    /// Connections open now.
    pub fn open(&self) -> usize {
        self.max - self.slots.available_permits()
    }
}

/// Serves `router` on `listener` until `shutdown` completes, then waits for the open
/// connections to finish.
pub async fn serve(
    listener: TcpListener,
    router: Router,
    state: Arc<AppState>,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let (stopping, stop) = tokio::sync::watch::channel(false);
    let refusal = refusal(state.config.limits.max_connections).await;
    let header_timeout = Duration::from_secs(state.config.timeouts.header_timeout_seconds);
    let mut shutdown = std::pin::pin!(shutdown);
    loop {
        let (stream, peer) = tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok(accepted) => accepted,
                Err(error) => {
                    tracing::warn!("accepting a connection: {error}");
                    tokio::time::sleep(ACCEPT_BACKOFF).await;
                    continue;
                }
            },
            () = &mut shutdown => break,
        };
        let Ok(slot) = state.connections.slots.clone().try_acquire_owned() else {
            state.metrics.record_refused_connection();
            tracing::debug!(%peer, "connection refused: max_connections open");
            // Best effort and never blocking: a fresh socket's send buffer is empty.
            let _ = stream.try_write(&refusal);
            continue;
        };
        let router = router.clone();
        let service = hyper::service::service_fn(move |mut request: hyper::Request<Incoming>| {
            request.extensions_mut().insert(ConnectInfo(peer));
            router.clone().oneshot(request)
        });
        let connection = hyper::server::conn::http1::Builder::new()
            .timer(TokioTimer::new())
            .header_read_timeout(header_timeout)
            .serve_connection(TokioIo::new(stream), service)
            .with_upgrades();
        let mut stop = stop.clone();
        tokio::spawn(async move {
            let mut connection = std::pin::pin!(connection);
            let result = tokio::select! {
                result = connection.as_mut() => result,
                () = async { let _ = stop.wait_for(|&stopping| stopping).await; } => {
                    // Finish the request in flight, then close.
                    connection.as_mut().graceful_shutdown();
                    connection.await
                }
            };
            if let Err(error) = result {
                tracing::debug!(%peer, "connection closed: {error}");
            }
            drop(slot);
        });
    }
    drop(listener);
    stopping.send_replace(true);
    // Every slot back: every connection has closed.
    let all = u32::try_from(state.connections.max).unwrap_or(u32::MAX);
    let _ = state.connections.slots.acquire_many(all).await;
    Ok(())
}

/// The whole answer to a connection over `max_connections`, as bytes: 503 with the JSON error
/// (limit `max_connections`) and `Connection: close`.
async fn refusal(max: usize) -> Vec<u8> {
    use axum::response::IntoResponse;
    let mut error = ApiError::from(super::LimitExceeded {
        limit: limit::MAX_CONNECTIONS,
        field: None,
        message: format!("{max} connections are open, the limit; retry later"),
    });
    error.retry_after = Some(1);
    let (parts, body) = error.into_response().into_parts();
    let body = http_body_util::BodyExt::collect(body).await.map(|b| b.to_bytes()).unwrap_or_default();
    let mut head = format!("HTTP/1.1 {} {}\r\n", parts.status.as_u16(), parts.status.canonical_reason().unwrap_or(""));
    for (name, value) in &parts.headers {
        head.push_str(&format!("{name}: {}\r\n", value.to_str().unwrap_or("")));
    }
    head.push_str(&format!("content-length: {}\r\nconnection: close\r\n\r\n", body.len()));
    [head.as_bytes(), &body].concat()
}

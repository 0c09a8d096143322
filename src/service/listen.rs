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
//!   uses as the client's identity;
//! - limits on the request head (`max_header_bytes`, `max_headers`), which hyper enforces
//!   while parsing, and relume's JSON error in place of the empty-bodied answer hyper writes to
//!   a request it cannot parse or that is over them (400, 414, 431: [`JsonRefusals`]), so
//!   that every error the service sends is JSON.
//!
//! Shutdown stops accepting, lets open connections finish their requests and closes them, and
//! completes when every connection has closed.

use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll, ready};
use std::time::Duration;

use axum::Router;
use axum::extract::ConnectInfo;
use axum::http::StatusCode;
use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::TcpListener;
use tokio::sync::Semaphore;
use tower::ServiceExt;

use super::AppState;
use super::config::Limits;
use super::config::limit;
use super::error::{ApiError, Code};

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
    let refusal = refusal(state.config.limits.max_connections);
    let refusals = Arc::new(JsonRefusals::new(&state.config.limits));
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
        let limits = &state.config.limits;
        let connection = hyper::server::conn::http1::Builder::new()
            .timer(TokioTimer::new())
            .header_read_timeout(header_timeout)
            .max_buf_size(limits.header_bytes())
            .max_header_size(limits.header_bytes())
            .max_headers(limits.max_headers)
            .serve_connection(TokioIo::new(JsonErrors::new(stream, refusals.clone())), service)
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
fn refusal(max: usize) -> Vec<u8> {
    let mut error = ApiError::from(super::LimitExceeded {
        limit: limit::MAX_CONNECTIONS,
        field: None,
        message: format!("{max} connections are open, the limit; retry later"),
    });
    error.retry_after = Some(1);
    error.to_http1_bytes()
}

/// relume's answers, as bytes, in place of those hyper writes itself, with an empty body,
/// to a request it refuses while parsing its head.
pub struct JsonRefusals {
    /// 400: the request line, a header or the framing cannot be parsed (a negative
    /// `Content-Length`, TLS bytes where a request line belongs).
    malformed: Vec<u8>,
    /// 414: a request target too long for the `http` crate (65,535 bytes or more; within
    /// `max_header_bytes`, at most 65,536, such a head is refused 431 first).
    uri_too_long: Vec<u8>,
    /// 431: the head is over `max_header_bytes`.
    head_too_large: Vec<u8>,
    /// 431: more than `max_headers` headers.
    too_many_headers: Vec<u8>,
    max_header_bytes: usize,
}

impl JsonRefusals {
    pub fn new(limits: &Limits) -> JsonRefusals {
        let max_header_bytes = limits.header_bytes();
        let over = |status: StatusCode, limit: &'static str, message: String| ApiError {
            limit: Some(limit),
            ..ApiError::new(status, Code::LimitExceeded, message)
        };
        JsonRefusals {
            malformed: ApiError::new(
                StatusCode::BAD_REQUEST,
                Code::BadRequest,
                "not an HTTP/1.1 request: its request line, a header or its Content-Length cannot be parsed",
            )
            .to_http1_bytes(),
            uri_too_long: over(
                StatusCode::URI_TOO_LONG,
                limit::MAX_HEADER_BYTES,
                format!(
                    "the request target is too long: the request line and headers may take {max_header_bytes} bytes"
                ),
            )
            .to_http1_bytes(),
            head_too_large: over(
                StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE,
                limit::MAX_HEADER_BYTES,
                format!("the request line and headers are over the limit of {max_header_bytes} bytes"),
            )
            .to_http1_bytes(),
            too_many_headers: over(
                StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE,
                limit::MAX_HEADERS,
                format!("the request has more than {} headers, the limit", limits.max_headers),
            )
            .to_http1_bytes(),
            max_header_bytes,
        }
    }

    /// relume's answer in place of `written`, when that is a whole answer of hyper's to a
    /// request it refused: a head alone, of status 400, 414 or 431, with `content-length: 0`
    /// (relume's own error answers always have a body). `head_bytes` is how much the
    /// connection read since it last wrote: past `max_header_bytes`, a 431 is about the
    /// head's size, else about its header count.
    fn instead_of(&self, written: &[u8], head_bytes: usize) -> Option<&[u8]> {
        const END: &[u8] = b"\r\n\r\n";
        const EMPTY: &[u8] = b"\r\ncontent-length: 0\r\n";
        // Every write passes here (image bodies, stream frames): the status first, cheaply.
        let answer = match written.strip_prefix(b"HTTP/1.")?.get(1..6)? {
            b" 400 " => &self.malformed,
            b" 414 " => &self.uri_too_long,
            b" 431 " if head_bytes >= self.max_header_bytes => &self.head_too_large,
            b" 431 " => &self.too_many_headers,
            _ => return None,
        };
        let head_only = written.ends_with(END) && written.windows(END.len()).filter(|w| *w == END).count() == 1;
        let empty = written.windows(EMPTY.len()).any(|w| w.eq_ignore_ascii_case(EMPTY));
        (head_only && empty).then_some(answer.as_slice())
    }
}

/// A connection's socket as hyper sees it: writes that are hyper's own refusals
/// ([`JsonRefusals::instead_of`]) go out as relume's JSON answers instead. Writes are not
/// vectored, so that hyper hands over each answer's head in one piece.
struct JsonErrors<S> {
    inner: S,
    refusals: Arc<JsonRefusals>,
    /// Bytes read since the last write.
    read_since_write: usize,
    /// A replacement being written: its bytes, how many are out, and the length of hyper's
    /// write that it replaces (reported once all are out).
    replacing: Option<(Vec<u8>, usize, usize)>,
}

impl<S> JsonErrors<S> {
    fn new(inner: S, refusals: Arc<JsonRefusals>) -> JsonErrors<S> {
        JsonErrors { inner, refusals, read_since_write: 0, replacing: None }
    }
}

impl<S: AsyncRead + Unpin> AsyncRead for JsonErrors<S> {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<std::io::Result<()>> {
        let before = buf.filled().len();
        ready!(Pin::new(&mut self.inner).poll_read(cx, buf))?;
        self.read_since_write = self.read_since_write.saturating_add(buf.filled().len() - before);
        Poll::Ready(Ok(()))
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for JsonErrors<S> {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &[u8]) -> Poll<std::io::Result<usize>> {
        let this = &mut *self;
        // After `Pending`, hyper writes the same bytes again, as `poll_write` requires.
        let (answer, out, replaced) = match &mut this.replacing {
            Some(replacing) => replacing,
            None => {
                let head_bytes = std::mem::take(&mut this.read_since_write);
                match this.refusals.instead_of(buf, head_bytes) {
                    Some(answer) => this.replacing.insert((answer.to_vec(), 0, buf.len())),
                    None => return Pin::new(&mut this.inner).poll_write(cx, buf),
                }
            }
        };
        while *out < answer.len() {
            match ready!(Pin::new(&mut this.inner).poll_write(cx, &answer[*out..])) {
                Ok(0) => return Poll::Ready(Err(std::io::ErrorKind::WriteZero.into())),
                Ok(n) => *out += n,
                Err(error) => return Poll::Ready(Err(error)),
            }
        }
        let replaced = *replaced;
        this.replacing = None;
        Poll::Ready(Ok(replaced))
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn refusals() -> JsonRefusals {
        JsonRefusals::new(&Limits { max_header_bytes: 8192, max_headers: 10, ..Limits::default() })
    }

    fn json_of(answer: &[u8]) -> serde_json::Value {
        let text = std::str::from_utf8(answer).expect("UTF-8");
        let (head, body) = text.split_once("\r\n\r\n").expect("a head");
        assert!(head.contains("content-type: application/json\r\n"), "{head}");
        assert!(head.contains(&format!("content-length: {}\r\n", body.len())), "{head}");
        serde_json::from_str(body).expect("JSON")
    }

    #[test]
    fn hypers_empty_refusals_are_replaced_by_json() {
        let refusals = refusals();
        let hyper = |status: &str| format!("HTTP/1.1 {status}\r\ncontent-length: 0\r\ndate: x\r\n\r\n").into_bytes();
        let cases = [
            ("400 Bad Request", 0, "HTTP/1.1 400 ", "bad_request", None),
            ("414 URI Too Long", 0, "HTTP/1.1 414 ", "limit_exceeded", Some("max_header_bytes")),
            ("431 Request Header Fields Too Large", 8192, "HTTP/1.1 431 ", "limit_exceeded", Some("max_header_bytes")),
            ("431 Request Header Fields Too Large", 300, "HTTP/1.1 431 ", "limit_exceeded", Some("max_headers")),
        ];
        for (status, read, line, code, limit) in cases {
            let answer = refusals.instead_of(&hyper(status), read).unwrap_or_else(|| panic!("{status} replaced"));
            assert!(answer.starts_with(line.as_bytes()), "{status}");
            let json = json_of(answer);
            assert_eq!(json["error"]["code"], code, "{json}");
            assert_eq!(json["error"]["limit"].as_str(), limit, "{json}");
        }
    }

    #[test]
    fn other_writes_pass_through() {
        let refusals = refusals();
        for written in [
            // relume's own errors have bodies
            &b"HTTP/1.1 400 Bad Request\r\ncontent-type: application/json\r\ncontent-length: 2\r\n\r\n{}"[..],
            b"HTTP/1.1 200 OK\r\ncontent-length: 0\r\n\r\n",
            b"HTTP/1.1 204 No Content\r\n\r\n",
            // a head whose body comes in the same write
            b"HTTP/1.1 431 Request Header Fields Too Large\r\ncontent-length: 0\r\n\r\nHTTP/1.1 200 OK\r\n\r\n",
            b"\x82\x05HTTP/",
            b"",
        ] {
            assert!(refusals.instead_of(written, 1 << 20).is_none(), "{}", String::from_utf8_lossy(written));
        }
    }

    #[tokio::test]
    async fn a_replaced_answer_is_written_whole_and_reported_as_hypers() {
        use tokio::io::{AsyncReadExt, AsyncWriteExt};
        let (client, server) = tokio::io::duplex(64);
        let mut io = JsonErrors::new(server, Arc::new(refusals()));
        let hyper = b"HTTP/1.1 400 Bad Request\r\ncontent-length: 0\r\n\r\n";
        let reader = tokio::spawn(async move {
            let mut client = client;
            let mut received = Vec::new();
            client.read_to_end(&mut received).await.expect("read");
            received
        });
        // The duplex holds 64 bytes: the replacement goes out over several `Pending`s.
        let written = io.write(hyper).await.expect("written");
        assert_eq!(written, hyper.len());
        io.shutdown().await.expect("shut down");
        drop(io);
        let received = reader.await.expect("reader");
        assert_eq!(received, refusals().malformed);
        assert_eq!(json_of(&received)["error"]["code"], "bad_request");
    }
}

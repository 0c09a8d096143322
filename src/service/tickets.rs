//! `POST /v1/tickets`: short-lived, single-use tickets that open a stream in place of the
//! bearer token, for clients that cannot set a WebSocket handshake's `Authorization` header
//! (browsers, and so the viewer).
//!
//! A client that holds the token asks for a ticket and opens
//! `/v1/scenes/{id}/stream?ticket=<ticket>` within `ticket_seconds`, or, to keep the ticket out
//! of URLs (and so out of access logs and browser history), offers it as a WebSocket
//! subprotocol, `Sec-WebSocket-Protocol: relume.v1, relume.ticket.<ticket>` (the pattern of
//! Kubernetes' bearer-token subprotocol; browsers: `new WebSocket(url, ["relume.v1",
//! "relume.ticket." + ticket])`); the server selects `relume.v1`, which the client must offer
//! beside the ticket because a browser fails a handshake whose protocols it offered were all
//! left unselected. The first handshake that
//! presents a ticket consumes it, whatever the answer; an unknown, used or expired ticket is
//! refused with 401 `unauthorized` before the upgrade. A ticket is 32 bytes from the operating
//! system's CSPRNG (`getrandom`) in base64url without padding, URL-safe as it is. At most
//! `max_tickets` are outstanding (issued, neither used nor expired): one more is refused with
//! 503 `limit_exceeded` and a `Retry-After` of when the oldest expires, so what they hold is
//! bounded. Tickets open streams only; every other `/v1` route wants the token.
//!
//! Without `--token` the route still issues tickets and a stream still checks a ticket it is
//! given, so that a client can take the same path against either server.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use axum::Json;
use axum::extract::State;
use axum::http::{HeaderMap, HeaderValue, Uri, header};
use axum::response::{IntoResponse, Response};
use base64::Engine as _;
use serde::Serialize;

use super::AppState;
use super::config::{LimitExceeded, MAX_TICKET_SECONDS, limit};
use super::error::ApiError;

/// Random bytes in a ticket (256 bits).
pub const TICKET_BYTES: usize = 32;

/// The query parameter of a stream handshake that carries a ticket.
pub const TICKET_PARAMETER: &str = "ticket";

/// The WebSocket subprotocol of relume's stream, selected when a handshake offers it.
pub const STREAM_PROTOCOL: &str = "relume.v1";

/// A subprotocol offered as this followed by a ticket carries the ticket.
pub const TICKET_PROTOCOL_PREFIX: &str = "relume.ticket.";

/// A ticket, as `POST /v1/tickets` answers it.
#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct TicketInfo {
    /// Pass it once as `?ticket=` on a stream's WebSocket handshake (43 base64url characters,
    /// URL-safe as they are).
    #[schema(example = "q3Zt0bC1r8Xv0lH6J2mB4yQe5nW7kF9sD1aG3hU8pLo")]
    pub ticket: String,
    /// Seconds from now that the ticket stays valid (`ticket_seconds`).
    #[schema(example = 30)]
    pub expires_in_seconds: u64,
}

/// The tickets issued and neither used nor expired, at most `max` of them, each with the
/// instant it expires.
pub struct Tickets {
    lifetime: Duration,
    max: usize,
    outstanding: Mutex<HashMap<String, Instant>>,
}

impl Tickets {
    /// Tickets valid for `lifetime_seconds` (1..=[`MAX_TICKET_SECONDS`]; outside, the nearest
    /// end), at most `max` outstanding.
    pub fn new(lifetime_seconds: u64, max: usize) -> Tickets {
        let lifetime = Duration::from_secs(lifetime_seconds.clamp(1, MAX_TICKET_SECONDS));
        Tickets { lifetime, max, outstanding: Mutex::new(HashMap::new()) }
    }

    fn lock(&self) -> MutexGuard<'_, HashMap<String, Instant>> {
        // The map stays consistent whatever panicked while holding it.
        self.outstanding.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// A new ticket; expired ones are forgotten first. Refused (503 `limit_exceeded`, with
    /// `Retry-After`: until the oldest expires) when `max` are outstanding.
    pub fn issue(&self) -> Result<TicketInfo, ApiError> {
        let mut bytes = [0u8; TICKET_BYTES];
        getrandom::fill(&mut bytes).map_err(|e| ApiError::internal(format!("no random bytes for a ticket: {e}")))?;
        let ticket = base64::engine::general_purpose::URL_SAFE_NO_PAD.encode(bytes);
        let now = Instant::now();
        let mut outstanding = self.lock();
        outstanding.retain(|_, expires| *expires > now);
        if outstanding.len() >= self.max {
            let message = if self.max == 0 {
                "tickets are turned off (max_tickets is 0)".to_owned()
            } else {
                format!("{} tickets are outstanding, the limit; retry when one is used or expires", outstanding.len())
            };
            let wait = outstanding.values().min().map_or(self.lifetime, |oldest| oldest.saturating_duration_since(now));
            let error = LimitExceeded { limit: limit::MAX_TICKETS, field: None, message };
            return Err(ApiError { retry_after: Some(wait.as_secs_f64().ceil().max(1.0) as u32), ..error.into() });
        }
        outstanding.insert(ticket.clone(), now + self.lifetime);
        Ok(TicketInfo { ticket, expires_in_seconds: self.lifetime.as_secs() })
    }

    /// Whether `ticket` was issued and has not expired. Either way it is spent: a ticket opens
    /// at most one handshake.
    pub fn redeem(&self, ticket: &str) -> bool {
        let now = Instant::now();
        self.lock().remove(ticket).is_some_and(|expires| expires > now)
    }

    /// Tickets issued and neither used nor expired.
    pub fn outstanding(&self) -> usize {
        let now = Instant::now();
        self.lock().values().filter(|expires| **expires > now).count()
    }
}

/// The ticket a stream handshake presents, as `?ticket=` ([`from_query`]) or as a
/// `relume.ticket.<ticket>` subprotocol ([`from_protocols`]); 400 when it is given twice, in
/// one place or both.
pub fn presented(uri: &Uri, headers: &HeaderMap) -> Result<Option<String>, ApiError> {
    match (from_query(uri)?, from_protocols(headers)?) {
        (Some(_), Some(_)) => Err(ApiError::invalid_field(
            TICKET_PARAMETER,
            "given both as ?ticket= and as a Sec-WebSocket-Protocol; give it once",
        )),
        (query, protocol) => Ok(query.or(protocol)),
    }
}

/// The ticket of a `relume.ticket.<ticket>` entry of the `Sec-WebSocket-Protocol` headers, if
/// there is one; 400 when there are two, or when `relume.v1` is not offered beside it (a
/// browser would fail the handshake the server answers without a protocol it offered).
pub fn from_protocols(headers: &HeaderMap) -> Result<Option<String>, ApiError> {
    let mut found = None;
    let mut offers_stream_protocol = false;
    for value in headers.get_all(header::SEC_WEBSOCKET_PROTOCOL) {
        let Ok(value) = value.to_str() else {
            return Err(ApiError::invalid_field("Sec-WebSocket-Protocol", "not visible ASCII"));
        };
        for protocol in value.split(',').map(str::trim) {
            offers_stream_protocol |= protocol == STREAM_PROTOCOL;
            let Some(ticket) = protocol.strip_prefix(TICKET_PROTOCOL_PREFIX) else { continue };
            if found.is_some() {
                return Err(ApiError::invalid_field(TICKET_PARAMETER, "given more than once"));
            }
            found = Some(ticket.to_owned());
        }
    }
    if found.is_some() && !offers_stream_protocol {
        return Err(ApiError::invalid_field(
            "Sec-WebSocket-Protocol",
            format!("a {TICKET_PROTOCOL_PREFIX}<ticket> subprotocol needs {STREAM_PROTOCOL} offered beside it"),
        ));
    }
    Ok(found)
}

/// The `ticket` query parameter of `uri`, percent-decoded, if there is one; 400 when it is
/// given more than once. Other parameters are left to the route.
pub fn from_query(uri: &Uri) -> Result<Option<String>, ApiError> {
    let mut found = None;
    for pair in uri.query().unwrap_or("").split('&') {
        let (key, value) = pair.split_once('=').unwrap_or((pair, ""));
        if key != TICKET_PARAMETER {
            continue;
        }
        if found.is_some() {
            return Err(ApiError::invalid_field(TICKET_PARAMETER, "given more than once"));
        }
        found = Some(percent_encoding::percent_decode_str(value).decode_utf8_lossy().into_owned());
    }
    Ok(found)
}

/// Issues a ticket that opens one stream without the bearer token.
///
/// For browsers, which cannot set a WebSocket handshake's `Authorization` header: pass the
/// ticket as `?ticket=` on `GET /v1/scenes/{id}/stream` within `expires_in_seconds`
/// (`ticket_seconds`). The first handshake that presents it consumes it, whatever the answer.
/// Without a configured token tickets are issued all the same (and checked when given). No
/// request body.
#[utoipa::path(
    post,
    path = "/v1/tickets",
    tag = "tickets",
    responses(
        (status = 200, description = "A single-use ticket", body = TicketInfo,
            headers(("Cache-Control" = String, description = "`no-store`"))),
        (status = 401, description = "Missing or wrong bearer token", body = super::error::ErrorBody),
        (status = 503, description = "max_tickets tickets are outstanding (`limit` names it), or the server is \
            shutting down", body = super::error::ErrorBody,
            headers(("Retry-After" = u32, description = "Seconds, when the tickets are all taken: until the \
                oldest expires"))),
    ),
    security((), ("bearer" = []))
)]
pub async fn issue_ticket(State(state): State<Arc<AppState>>) -> Result<Response, ApiError> {
    if state.shutting_down() {
        return Err(ApiError::shutting_down());
    }
    let ticket = state.tickets.issue()?;
    Ok(([(header::CACHE_CONTROL, HeaderValue::from_static("no-store"))], Json(ticket)).into_response())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ticket_is_spent_by_its_first_use() {
        let tickets = Tickets::new(30, 4);
        let issued = tickets.issue().expect("a ticket");
        assert_eq!(issued.ticket.len(), 43);
        assert!(issued.ticket.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_'));
        assert_eq!(issued.expires_in_seconds, 30);
        assert_ne!(tickets.issue().expect("another").ticket, issued.ticket);
        assert_eq!(tickets.outstanding(), 2);
        assert!(tickets.redeem(&issued.ticket));
        assert!(!tickets.redeem(&issued.ticket));
        assert!(!tickets.redeem("nope"));
        assert_eq!(tickets.outstanding(), 1);
    }

    #[test]
    fn the_outstanding_tickets_are_bounded() {
        let tickets = Tickets::new(30, 2);
        let first = tickets.issue().expect("a ticket");
        tickets.issue().expect("a ticket");
        let refused = tickets.issue().expect_err("over max_tickets");
        assert_eq!((refused.status.as_u16(), refused.limit), (503, Some(limit::MAX_TICKETS)));
        assert!(refused.retry_after.is_some_and(|s| (1..=30).contains(&s)), "{:?}", refused.retry_after);
        assert!(tickets.redeem(&first.ticket));
        tickets.issue().expect("a ticket once one was used");
        let off = Tickets::new(30, 0).issue().expect_err("tickets off");
        assert_eq!(off.limit, Some(limit::MAX_TICKETS));
    }

    #[test]
    fn the_lifetime_is_clamped() {
        assert_eq!(Tickets::new(0, 1).issue().expect("a ticket").expires_in_seconds, 1);
        assert_eq!(Tickets::new(u64::MAX, 1).issue().expect("a ticket").expires_in_seconds, MAX_TICKET_SECONDS);
    }

    #[test]
    fn the_ticket_comes_from_the_query() {
        let uri = |s: &str| s.parse::<Uri>().expect("a URI");
        assert_eq!(from_query(&uri("/s")).expect("ok"), None);
        assert_eq!(from_query(&uri("/s?a=1&ticket=x%2Dy")).expect("ok").as_deref(), Some("x-y"));
        assert_eq!(from_query(&uri("/s?ticket")).expect("ok").as_deref(), Some(""));
        let twice = from_query(&uri("/s?ticket=a&ticket=b")).expect_err("twice");
        assert_eq!(twice.field.as_deref(), Some("ticket"));
    }
}

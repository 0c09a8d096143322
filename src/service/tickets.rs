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
//! left unselected. The first handshake that presents a ticket consumes it, whatever the
//! answer; an unknown, forged, used or expired ticket is refused with 401 `unauthorized` before
//! the upgrade. Tickets open streams only; every other `/v1` route wants the token.
//!
//! **What a ticket is.** 56 bytes in base64url without padding (75 characters, URL-safe as
//! they are): its expiry (milliseconds since the Unix epoch, 8 bytes big-endian), a nonce (16
//! bytes from the operating system's CSPRNG, `getrandom`) and HMAC-SHA256 of those 24 bytes
//! under the ticket key. So a ticket is unguessable without the key (the MAC is compared in
//! constant time), and any process holding the key can check one another issued. The key
//! ([`TicketKey`]) is derived from `--ticket-key-file` when given, else from `--token`, else
//! drawn at random when the process starts (so only that process accepts its tickets).
//!
//! **Single use.** Each process remembers the tickets it issued until they expire, at most
//! `max_tickets` of them; one more is refused with 503 `limit_exceeded` and a `Retry-After` of
//! when the oldest expires, so what they hold is bounded.
//! - Without a scene store, a ticket opens a stream only on the process that issued it: the
//!   handshake removes it from that memory, and a ticket not there (used, expired, issued by
//!   another process or before a restart) is refused. A used ticket frees its place.
//! - With a scene store (`--scene-store DIR`, `src/service/store.rs`), the first handshake that
//!   presents a valid ticket, on any process sharing the store, creates the file
//!   `DIR/tickets/<expiry>-<nonce>` with create-exclusive (`O_EXCL`); a handshake that finds it
//!   there is refused. So with the key and the store shared, a ticket from any backend opens
//!   one stream on any backend, once in all. Its expiry is judged by the clock of the process
//!   that checks it, so the backends' clocks must agree (to within [`CLOCK_SKEW`]); the files
//!   are removed [`CLOCK_SKEW`] after their ticket expired. Here a ticket counts against its
//!   issuer's `max_tickets` until it expires, used or not (its issuer does not learn of a use
//!   elsewhere), which bounds the files too: each backend issues at most `max_tickets` per
//!   `ticket_seconds`.
//!
//! Without `--token` the route still issues tickets and a stream still checks a ticket it is
//! given, so that a client can take the same path against either server.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use axum::Json;
use axum::extract::State;
use axum::http::{HeaderMap, HeaderValue, Uri, header};
use axum::response::{IntoResponse, Response};
use base64::Engine as _;
use hmac::{Hmac, Mac};
use serde::Serialize;
use sha2::Sha256;

use super::AppState;
use super::config::{LimitExceeded, MAX_TICKET_SECONDS, limit};
use super::error::ApiError;

type HmacSha256 = Hmac<Sha256>;

/// Bytes of a ticket's expiry: milliseconds since the Unix epoch, big-endian.
const EXPIRY_BYTES: usize = 8;

/// Random bytes in a ticket (128 bits).
pub const NONCE_BYTES: usize = 16;

/// Bytes of a ticket's MAC (HMAC-SHA256, untruncated).
const MAC_BYTES: usize = 32;

/// Bytes in a ticket: expiry, nonce, MAC.
pub const TICKET_BYTES: usize = EXPIRY_BYTES + NONCE_BYTES + MAC_BYTES;

/// Characters of a ticket (base64url of [`TICKET_BYTES`], no padding).
pub const TICKET_CHARS: usize = (TICKET_BYTES * 4).div_ceil(3);

/// The fewest bytes a `--ticket-key-file` holds (surrounding whitespace aside): 256 bits.
pub const MIN_KEY_FILE_BYTES: usize = 32;

/// How far the clocks of the processes sharing a scene store may disagree: a spent ticket's
/// file is kept this long past its expiry, so a process whose clock lags by less still finds
/// it; a ticket that claims to expire further ahead than `MAX_TICKET_SECONDS` plus this is
/// refused.
pub const CLOCK_SKEW: Duration = Duration::from_secs(60);

/// How often a process sweeps the spent tickets' files of a scene store, at most.
const SWEEP_INTERVAL: Duration = Duration::from_secs(10);

/// The subdirectory of a scene store that holds the spent tickets' files.
pub const SPENT_DIRECTORY: &str = "tickets";

/// The query parameter of a stream handshake that carries a ticket.
pub const TICKET_PARAMETER: &str = "ticket";

/// The WebSocket subprotocol of relume's stream, selected when a handshake offers it.
pub const STREAM_PROTOCOL: &str = "relume.v1";

/// A subprotocol offered as this followed by a ticket carries the ticket.
pub const TICKET_PROTOCOL_PREFIX: &str = "relume.ticket.";

/// A ticket, as `POST /v1/tickets` answers it.
#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct TicketInfo {
    /// Pass it once as `?ticket=` on a stream's WebSocket handshake (75 base64url characters,
    /// URL-safe as they are).
    #[schema(example = "AAABl2Xn3kA-OJflQ6lQgfYdCQjPQYpqXAb9xIEH4h_okYBGJ9CjVZBXsXHHE0qpbskbTU9qYK1lHCZ")]
    pub ticket: String,
    /// Seconds from now that the ticket stays valid (`ticket_seconds`).
    #[schema(example = 30)]
    pub expires_in_seconds: u64,
}

/// The key that signs and checks tickets: HMAC-SHA256 of a fixed label under the secret it
/// comes from. Processes with the same key accept each other's tickets.
#[derive(Clone)]
pub struct TicketKey([u8; 32]);

impl std::fmt::Debug for TicketKey {
    fn fmt(&self, formatter: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        formatter.write_str("TicketKey(..)")
    }
}

/// Where a process's [`TicketKey`] came from (logged when it starts).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KeySource {
    /// `--ticket-key-file`.
    File,
    /// `--token`.
    Token,
    /// Drawn at random when the process started.
    Random,
}

impl KeySource {
    pub fn as_str(self) -> &'static str {
        match self {
            KeySource::File => "file",
            KeySource::Token => "token",
            KeySource::Random => "random",
        }
    }
}

impl TicketKey {
    /// Separates the ticket key from any other use of the same secret.
    const LABEL: &'static [u8] = b"relume stream ticket key v1";

    /// The key derived from `secret` (a key file's bytes, or the bearer token).
    pub fn from_secret(secret: &[u8]) -> TicketKey {
        let mut mac = HmacSha256::new_from_slice(secret).expect("HMAC takes a key of any length");
        mac.update(Self::LABEL);
        TicketKey(mac.finalize().into_bytes().into())
    }

    /// A key of this process alone, from the operating system's CSPRNG.
    pub fn random() -> Result<TicketKey, getrandom::Error> {
        let mut secret = [0u8; 32];
        getrandom::fill(&mut secret)?;
        Ok(TicketKey::from_secret(&secret))
    }

    /// The key derived from the file at `path` (`--ticket-key-file`): its bytes with
    /// surrounding ASCII whitespace removed, at least [`MIN_KEY_FILE_BYTES`] of them.
    pub fn from_file(path: &Path) -> Result<TicketKey, String> {
        let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let secret = bytes.trim_ascii();
        if secret.len() < MIN_KEY_FILE_BYTES {
            return Err(format!(
                "{}: {} bytes, fewer than {MIN_KEY_FILE_BYTES} (e.g. `openssl rand -base64 48 > {}`)",
                path.display(),
                secret.len(),
                path.display()
            ));
        }
        Ok(TicketKey::from_secret(secret))
    }

    fn mac(&self) -> HmacSha256 {
        HmacSha256::new_from_slice(&self.0).expect("HMAC takes a key of any length")
    }

    /// `expiry || nonce || HMAC(expiry || nonce)`, in base64url.
    fn seal(&self, expiry_ms: u64, nonce: &[u8; NONCE_BYTES]) -> String {
        let mut bytes = [0u8; TICKET_BYTES];
        bytes[..EXPIRY_BYTES].copy_from_slice(&expiry_ms.to_be_bytes());
        bytes[EXPIRY_BYTES..EXPIRY_BYTES + NONCE_BYTES].copy_from_slice(nonce);
        let mut mac = self.mac();
        mac.update(&bytes[..EXPIRY_BYTES + NONCE_BYTES]);
        bytes[EXPIRY_BYTES + NONCE_BYTES..].copy_from_slice(&mac.finalize().into_bytes());
        base64::engine::general_purpose::URL_SAFE_NO_PAD.encode(bytes)
    }

    /// The expiry and nonce of `ticket` if this key signed it (the MAC compared in constant
    /// time); `None` for anything else.
    fn open(&self, ticket: &str) -> Option<(u64, [u8; NONCE_BYTES])> {
        if ticket.len() != TICKET_CHARS {
            return None;
        }
        let bytes = base64::engine::general_purpose::URL_SAFE_NO_PAD.decode(ticket).ok()?;
        if bytes.len() != TICKET_BYTES {
            return None;
        }
        let (signed, tag) = bytes.split_at(EXPIRY_BYTES + NONCE_BYTES);
        let mut mac = self.mac();
        mac.update(signed);
        mac.verify_slice(tag).ok()?;
        let expiry = u64::from_be_bytes(signed[..EXPIRY_BYTES].try_into().ok()?);
        let nonce = signed[EXPIRY_BYTES..].try_into().ok()?;
        Some((expiry, nonce))
    }
}

/// Milliseconds since the Unix epoch, now.
fn now_ms() -> u64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| u64::try_from(d.as_millis()).unwrap_or(u64::MAX))
}

/// The name of a spent ticket's file in a store's [`SPENT_DIRECTORY`].
fn spent_name(expiry_ms: u64, nonce: &[u8; NONCE_BYTES]) -> String {
    let hex: String = nonce.iter().map(|b| format!("{b:02x}")).collect();
    format!("{expiry_ms}-{hex}")
}

/// The tickets this process issued and that have not expired (nor, without a store, been
/// used), at most `max`, each with its expiry; the key; and where spent tickets are marked
/// when a scene store is shared.
pub struct Tickets {
    lifetime: Duration,
    max: usize,
    key: TicketKey,
    source: KeySource,
    /// `DIR/tickets` of the scene store, if there is one.
    spent: Option<PathBuf>,
    issued: Mutex<HashMap<[u8; NONCE_BYTES], u64>>,
    /// When the spent tickets' files were last swept (ms since the epoch).
    swept_ms: AtomicU64,
}

impl Tickets {
    /// Tickets valid for `lifetime_seconds` (1..=[`MAX_TICKET_SECONDS`]; outside, the nearest
    /// end), at most `max` outstanding, signed with a random key, single use in this process.
    pub fn new(lifetime_seconds: u64, max: usize) -> Result<Tickets, getrandom::Error> {
        Ok(Tickets::with_key(lifetime_seconds, max, TicketKey::random()?, None))
    }

    /// [`Tickets::new`] with `key`, spent tickets marked in `spent` (a scene store's
    /// [`SPENT_DIRECTORY`], which must exist) when given.
    pub fn with_key(lifetime_seconds: u64, max: usize, key: TicketKey, spent: Option<PathBuf>) -> Tickets {
        let lifetime = Duration::from_secs(lifetime_seconds.clamp(1, MAX_TICKET_SECONDS));
        let issued = Mutex::new(HashMap::new());
        Tickets { lifetime, max, key, source: KeySource::Random, spent, issued, swept_ms: AtomicU64::new(0) }
    }

    /// These tickets, their key said to come from `source` (for the log).
    pub fn keyed_by(self, source: KeySource) -> Tickets {
        Tickets { source, ..self }
    }

    /// Where the key came from.
    pub fn key_source(&self) -> KeySource {
        self.source
    }

    /// Whether another process could accept these tickets: the key is not this process's own
    /// random one and spent tickets are marked in a scene store.
    pub fn shared(&self) -> bool {
        self.spent.is_some() && self.source != KeySource::Random
    }

    fn lock(&self) -> MutexGuard<'_, HashMap<[u8; NONCE_BYTES], u64>> {
        // The map stays consistent whatever panicked while holding it.
        self.issued.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// A new ticket; expired ones are forgotten first. Refused (503 `limit_exceeded`, with
    /// `Retry-After`: until the oldest expires) when `max` are outstanding.
    pub fn issue(&self) -> Result<TicketInfo, ApiError> {
        self.issue_at(now_ms())
    }

    fn issue_at(&self, now: u64) -> Result<TicketInfo, ApiError> {
        let mut nonce = [0u8; NONCE_BYTES];
        getrandom::fill(&mut nonce).map_err(|e| ApiError::internal(format!("no random bytes for a ticket: {e}")))?;
        let mut issued = self.lock();
        issued.retain(|_, expiry| *expiry > now);
        if issued.len() >= self.max {
            let message = if self.max == 0 {
                "tickets are turned off (max_tickets is 0)".to_owned()
            } else {
                format!("{} tickets are outstanding, the limit; retry when one is used or expires", issued.len())
            };
            let lifetime_ms = self.lifetime.as_millis() as u64;
            let wait_ms = issued.values().min().map_or(lifetime_ms, |oldest| oldest.saturating_sub(now));
            let error = LimitExceeded { limit: limit::MAX_TICKETS, field: None, message };
            return Err(ApiError { retry_after: Some(wait_ms.div_ceil(1000).max(1) as u32), ..error.into() });
        }
        let expiry = now + self.lifetime.as_millis() as u64;
        issued.insert(nonce, expiry);
        drop(issued);
        self.sweep(now);
        Ok(TicketInfo { ticket: self.key.seal(expiry, &nonce), expires_in_seconds: self.lifetime.as_secs() })
    }

    /// Whether `ticket` is one this key signed, has not expired and was not used before (see
    /// the module's documentation for where "before" is remembered). Either way it is spent: a
    /// ticket opens at most one handshake.
    pub fn redeem(&self, ticket: &str) -> bool {
        self.redeem_at(ticket, now_ms())
    }

    fn redeem_at(&self, ticket: &str, now: u64) -> bool {
        if self.max == 0 {
            return false;
        }
        let Some((expiry, nonce)) = self.key.open(ticket) else { return false };
        let latest = now.saturating_add((MAX_TICKET_SECONDS * 1000) + CLOCK_SKEW.as_millis() as u64);
        let fresh = now < expiry && expiry <= latest;
        let Some(spent) = &self.spent else {
            // Issued here, and not before: removed, so never again.
            return self.lock().remove(&nonce).is_some() && fresh;
        };
        if !fresh {
            return false;
        }
        self.sweep(now);
        let mark = spent.join(spent_name(expiry, &nonce));
        match std::fs::OpenOptions::new().write(true).create_new(true).open(&mark) {
            Ok(_) => true,
            Err(error) if error.kind() == std::io::ErrorKind::AlreadyExists => false,
            Err(error) => {
                tracing::warn!("scene store: cannot mark a ticket spent ({error}); refusing it");
                false
            }
        }
    }

    /// Removes the spent tickets' files whose ticket expired more than [`CLOCK_SKEW`] ago, at
    /// most once per [`SWEEP_INTERVAL`]; other names are left alone.
    fn sweep(&self, now: u64) {
        let Some(spent) = &self.spent else { return };
        let last = self.swept_ms.load(Ordering::Relaxed);
        if now < last.saturating_add(SWEEP_INTERVAL.as_millis() as u64)
            || self.swept_ms.compare_exchange(last, now, Ordering::Relaxed, Ordering::Relaxed).is_err()
        {
            return;
        }
        let Ok(entries) = std::fs::read_dir(spent) else { return };
        let skew = CLOCK_SKEW.as_millis() as u64;
        for entry in entries.flatten() {
            let name = entry.file_name();
            let Some((expiry, _)) = name.to_str().and_then(|name| name.split_once('-')) else { continue };
            if expiry.parse::<u64>().is_ok_and(|expiry| expiry.saturating_add(skew) < now) {
                let _ = std::fs::remove_file(entry.path());
            }
        }
    }

    /// Tickets issued here and neither expired nor (without a scene store) used.
    pub fn outstanding(&self) -> usize {
        let now = now_ms();
        self.lock().values().filter(|expiry| **expiry > now).count()
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
/// Behind a load balancer, a backend that shares the ticket key (`--ticket-key-file` or the
/// same `--token`) and the scene store with the issuer accepts it too, once in all. Without a
/// configured token tickets are issued all the same (and checked when given). No
/// request body.
#[utoipa::path(
    post,
    path = "/v1/tickets",
    tag = "tickets",
    responses(
        (status = 200, description = "A single-use ticket", body = TicketInfo,
            headers(("Cache-Control" = String, description = "`no-store`"))),
        super::error::Unauthorized,
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

    /// A fresh scratch directory for spent tickets' files.
    fn spent_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("relume-tickets-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("scratch directory");
        dir
    }

    fn shared_key() -> TicketKey {
        TicketKey::from_secret(b"a secret the backends share, 32+ bytes")
    }

    #[test]
    fn a_ticket_is_spent_by_its_first_use() {
        let tickets = Tickets::new(30, 4).expect("tickets");
        let issued = tickets.issue().expect("a ticket");
        assert_eq!((issued.ticket.len(), TICKET_CHARS), (75, 75));
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
        let tickets = Tickets::new(30, 2).expect("tickets");
        let first = tickets.issue().expect("a ticket");
        tickets.issue().expect("a ticket");
        let refused = tickets.issue().expect_err("over max_tickets");
        assert_eq!((refused.status.as_u16(), refused.limit), (503, Some(limit::MAX_TICKETS)));
        assert!(refused.retry_after.is_some_and(|s| (1..=30).contains(&s)), "{:?}", refused.retry_after);
        assert!(tickets.redeem(&first.ticket));
        tickets.issue().expect("a ticket once one was used");
        let off = Tickets::new(30, 0).expect("tickets").issue().expect_err("tickets off");
        assert_eq!(off.limit, Some(limit::MAX_TICKETS));
    }

    #[test]
    fn the_lifetime_is_clamped() {
        let issue = |seconds| Tickets::new(seconds, 1).expect("tickets").issue().expect("a ticket");
        assert_eq!(issue(0).expires_in_seconds, 1);
        assert_eq!(issue(u64::MAX).expires_in_seconds, MAX_TICKET_SECONDS);
    }

    /// Every byte of a ticket is covered by its MAC: a ticket with any one bit flipped, or
    /// cut, lengthened or re-encoded, is refused, and its genuine self is still good after.
    #[test]
    fn a_forged_ticket_is_refused() {
        let tickets = Tickets::with_key(30, 4, shared_key(), None);
        let genuine = tickets.issue().expect("a ticket").ticket;
        let engine = base64::engine::general_purpose::URL_SAFE_NO_PAD;
        let bytes = engine.decode(&genuine).expect("base64url");
        for bit in 0..bytes.len() * 8 {
            let mut forged = bytes.clone();
            forged[bit / 8] ^= 1 << (bit % 8);
            assert!(!tickets.redeem(&engine.encode(&forged)), "bit {bit} flipped");
        }
        // A later expiry with the old MAC, a MAC of zeros, and shapes that are not a ticket.
        let mut later = bytes.clone();
        later[..EXPIRY_BYTES].copy_from_slice(&(now_ms() + 20_000_000).to_be_bytes());
        assert!(!tickets.redeem(&engine.encode(&later)));
        let mut zeros = bytes.clone();
        zeros[EXPIRY_BYTES + NONCE_BYTES..].fill(0);
        assert!(!tickets.redeem(&engine.encode(&zeros)));
        let shapes = [genuine[..74].to_owned(), format!("{genuine}A"), format!("{genuine}="), String::new()];
        for shape in shapes {
            assert!(!tickets.redeem(&shape), "{shape}");
        }
        assert!(tickets.redeem(&genuine));
    }

    #[test]
    fn an_expired_ticket_is_refused() {
        for spent in [None, Some(spent_dir("expired"))] {
            let tickets = Tickets::with_key(30, 4, shared_key(), spent.clone());
            let now = now_ms();
            let issued = tickets.issue_at(now).expect("a ticket").ticket;
            assert!(!tickets.redeem_at(&issued, now + 30_000), "at its expiry");
            let early = tickets.issue_at(now).expect("a ticket").ticket;
            assert!(tickets.redeem_at(&early, now + 29_999), "just before");
            // A ticket signed with the key that claims to outlive any lifetime is refused too.
            let far = shared_key().seal(now + (MAX_TICKET_SECONDS + 61) * 1000, &[7; NONCE_BYTES]);
            assert!(!tickets.redeem_at(&far, now));
            if let Some(dir) = spent {
                std::fs::remove_dir_all(dir).expect("cleaned");
            }
        }
    }

    #[test]
    fn a_reused_ticket_is_refused() {
        for spent in [None, Some(spent_dir("reused"))] {
            let tickets = Tickets::with_key(30, 4, shared_key(), spent.clone());
            let issued = tickets.issue().expect("a ticket").ticket;
            assert!(tickets.redeem(&issued));
            assert!(!tickets.redeem(&issued), "twice");
            assert!(!tickets.redeem(&issued), "three times");
            if let Some(dir) = spent {
                std::fs::remove_dir_all(dir).expect("cleaned");
            }
        }
    }

    /// Two "processes" (two `Tickets`) with the same key and the same store accept each
    /// other's tickets, once in all; without a store a ticket opens on its issuer only; with
    /// another key it opens nowhere but its issuer.
    #[test]
    fn the_same_key_and_store_make_tickets_good_on_every_process_once() {
        let dir = spent_dir("shared");
        let first = Tickets::with_key(30, 4, shared_key(), Some(dir.clone()));
        let second = Tickets::with_key(30, 4, shared_key(), Some(dir.clone()));
        let ticket = first.issue().expect("a ticket").ticket;
        assert!(second.redeem(&ticket), "issued by one, good on the other");
        assert!(!first.redeem(&ticket) && !second.redeem(&ticket), "used on either, refused on both");
        assert_eq!(std::fs::read_dir(&dir).expect("the store").count(), 1, "one file per spent ticket");
        let ticket = second.issue().expect("a ticket").ticket;
        assert!(second.redeem(&ticket), "its issuer too");
        assert!(!first.redeem(&ticket));
        // A used ticket keeps its place with a store (its issuer cannot tell where it was used).
        assert_eq!((first.outstanding(), second.outstanding()), (1, 1));

        // Another key: its tickets are refused here, and ours there, store or not.
        let other =
            Tickets::with_key(30, 4, TicketKey::from_secret(b"another secret, also 32 bytes long"), Some(dir.clone()));
        let theirs = other.issue().expect("a ticket").ticket;
        assert!(!first.redeem(&theirs) && !second.redeem(&theirs));
        let ours = first.issue().expect("a ticket").ticket;
        assert!(!other.redeem(&ours));
        assert!(first.redeem(&ours), "refused elsewhere, it is still unused");
        assert!(other.redeem(&theirs));

        // Without a store, a ticket opens only on the process that issued it, however keyed.
        let alone = Tickets::with_key(30, 4, shared_key(), None);
        let elsewhere = first.issue().expect("a ticket").ticket;
        assert!(!alone.redeem(&elsewhere));
        std::fs::remove_dir_all(dir).expect("cleaned");
    }

    /// A spent ticket's file is removed once its ticket expired more than `CLOCK_SKEW` ago,
    /// and not before; other files in the directory are left alone.
    #[test]
    fn spent_tickets_files_are_swept_after_their_expiry() {
        let dir = spent_dir("sweep");
        let tickets = Tickets::with_key(30, 4, shared_key(), Some(dir.clone()));
        let now = now_ms();
        let ticket = tickets.issue_at(now).expect("a ticket").ticket;
        assert!(tickets.redeem_at(&ticket, now + 1));
        std::fs::write(dir.join("README"), "not a ticket").expect("written");
        let files = || std::fs::read_dir(&dir).expect("the store").count();
        tickets.sweep(now + 30_000 + CLOCK_SKEW.as_millis() as u64);
        assert_eq!(files(), 2, "kept until CLOCK_SKEW past the expiry");
        tickets.sweep(now + 30_001 + CLOCK_SKEW.as_millis() as u64 + SWEEP_INTERVAL.as_millis() as u64);
        assert_eq!(files(), 1, "then removed");
        assert!(dir.join("README").is_file());
        std::fs::remove_dir_all(dir).expect("cleaned");
    }

    #[test]
    fn a_key_file_needs_32_bytes_and_its_whitespace_does_not_count() {
        let dir = spent_dir("keys");
        let short = dir.join("short");
        std::fs::write(&short, format!("  {}\n", "k".repeat(31))).expect("written");
        let error = TicketKey::from_file(&short).expect_err("too short");
        assert!(error.contains("31 bytes"), "{error}");
        assert!(TicketKey::from_file(&dir.join("missing")).is_err());
        let long = dir.join("long");
        std::fs::write(&long, format!("{}\n", "k".repeat(32))).expect("written");
        let from_file = TicketKey::from_file(&long).expect("a key");
        let same = TicketKey::from_secret("k".repeat(32).as_bytes());
        let ticket = Tickets::with_key(30, 1, from_file, None).key.seal(now_ms() + 1000, &[1; NONCE_BYTES]);
        assert!(same.open(&ticket).is_some(), "the trailing newline is not part of the secret");
        assert_eq!(format!("{same:?}"), "TicketKey(..)", "never printed");
        std::fs::remove_dir_all(dir).expect("cleaned");
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

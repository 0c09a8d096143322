//! The normal clients of a load run and of the soak: a stream that replays frames at a fixed
//! rate and an HTTP client that renders back to back, each counting what it saw.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use hyper::{Method, StatusCode};
use serde_json::json;

use super::{HttpTally, Recover, StreamTally};
use crate::rgbd::RgbdFrame;
use crate::service::client::{Backoff, Connection, describe_error};
use crate::service::wire::proto;
use crate::service::wire::proto::envelope::Body;

/// Sends a frame every `1 / fps` s until `deadline`, then waits (at most 60 s) for the answers
/// still owed. The server renders one frame per stream at a time and drops the older of two
/// waiting ones, so latency is measured per answered frame. When the stream ends (its backend
/// went away), the frames owed are lost and the stream is opened again ([`Recover`]); the
/// answer is the tally and the scene's id at the end (new if it was created again).
pub(super) async fn drive_stream(
    connection: &Connection,
    mut id: String,
    frames: &[RgbdFrame],
    fps: f64,
    deadline: tokio::time::Instant,
    recover: &Recover,
) -> anyhow::Result<(StreamTally, String)> {
    let mut stream = connection.open_stream(&id).await?;
    let mut tally = StreamTally::default();
    let mut sent_at: HashMap<u64, Instant> = HashMap::new();
    let mut ticker = tokio::time::interval(Duration::from_secs_f64(1.0 / fps));
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut sending = true;
    let mut drain_until = None;
    // Dropped frames counted by the streams closed before this one.
    let mut dropped_before = 0;
    loop {
        if sending && tokio::time::Instant::now() >= deadline {
            sending = false;
            drain_until = Some(tokio::time::Instant::now() + Duration::from_secs(60));
        }
        let owed = tally.sent.saturating_sub(tally.rendered + tally.errors + tally.dropped + tally.lost);
        if !sending && owed == 0 {
            break;
        }
        let ended = tokio::select! {
            _ = ticker.tick(), if sending => {
                let frame_id = tally.sent;
                let sent = stream.send_frame(frame_id, &frames[frame_id as usize % frames.len()]).await;
                sent_at.insert(frame_id, Instant::now());
                tally.sent += 1;
                sent.err()
            }
            _ = tokio::time::sleep_until(drain_until.unwrap_or(deadline)), if !sending => {
                tracing::warn!(stream = %id, owed, "answers still owed after 60 s");
                break;
            }
            message = stream.next() => match message {
                Ok(Some(Body::RenderedFrame(f))) => {
                    if let Some(sent) = sent_at.remove(&f.frame_id) {
                        tally.latency_ms.push(sent.elapsed().as_secs_f64() * 1e3);
                    }
                    tally.rendered += 1;
                    tally.dropped = dropped_before + f.dropped_frames;
                    None
                }
                Ok(Some(Body::Error(e))) if e.code() == proto::ErrorCode::ShuttingDown => {
                    Some(anyhow::anyhow!("{}", describe_error(&e)))
                }
                Ok(Some(Body::Error(e))) => {
                    tracing::warn!(stream = %id, "{}", describe_error(&e));
                    tally.errors += 1;
                    None
                }
                Ok(Some(_)) => None,
                Ok(None) => Some(anyhow::anyhow!("stream {id}: the server closed the stream")),
                Err(error) => Some(error),
            },
        };
        let Some(error) = ended else { continue };
        if recover.give_up.is_zero() {
            return Err(error);
        }
        // Every frame sent and not answered was in flight on the stream that ended.
        let owed = tally.sent.saturating_sub(tally.rendered + tally.errors + tally.dropped + tally.lost);
        tracing::warn!(stream = %id, lost = owed, "the stream ended ({error:#}); reconnecting");
        tally.lost += owed;
        sent_at.clear();
        dropped_before = tally.dropped;
        (stream, _) = connection.reopen_stream(&mut id, &recover.description, recover.give_up).await?;
        tally.reconnects += 1;
    }
    stream.close().await;
    Ok((tally, id))
}

/// Renders the scene back to back until `deadline`; a 503 waits its `Retry-After` (capped at
/// 1 s) before the next request. With [`Recover`], a render without an answer or answered
/// 502/504 (a load balancer without a backend) counts as failed and is tried again after a
/// [`Backoff`] wait, and a 404 (a backend that does not know the scene) creates it again; the
/// answer is the tally and the scene's id at the end.
pub(super) async fn drive_renders(
    connection: &Connection,
    mut id: String,
    deadline: tokio::time::Instant,
    recover: &Recover,
) -> anyhow::Result<(HttpTally, String)> {
    let mut tally = HttpTally::default();
    let body = json!({}).to_string();
    let mut backoff = Backoff::new(recover.give_up);
    while tokio::time::Instant::now() < deadline {
        let sent = Instant::now();
        let path = format!("/v1/scenes/{id}/render");
        let answer = connection.request(Method::POST, &path, body.clone().into()).await;
        let failure = match answer {
            Ok((StatusCode::OK, _)) => {
                tally.ok += 1;
                tally.latency_ms.push(sent.elapsed().as_secs_f64() * 1e3);
                backoff = Backoff::new(recover.give_up);
                continue;
            }
            Ok((StatusCode::SERVICE_UNAVAILABLE, _)) => {
                tally.refused += 1;
                tokio::time::sleep(Duration::from_millis(1000)).await;
                continue;
            }
            Ok((StatusCode::NOT_FOUND, answer)) if !recover.give_up.is_zero() => {
                tracing::warn!(scene = %id, "render: 404 ({}); creating the scene again", String::from_utf8_lossy(&answer));
                id = connection.create_scene(&recover.description).await?;
                continue;
            }
            Ok((status @ (StatusCode::BAD_GATEWAY | StatusCode::GATEWAY_TIMEOUT), answer)) => {
                anyhow::anyhow!("{status}: {}", String::from_utf8_lossy(&answer))
            }
            Ok((other, answer)) => {
                anyhow::bail!("render of scene {id}: {other}: {}", String::from_utf8_lossy(&answer))
            }
            Err(error) => error,
        };
        tally.failed += 1;
        tracing::warn!(scene = %id, "render failed: {failure:#}");
        if recover.give_up.is_zero() {
            return Err(failure.context(format!("render of scene {id}")));
        }
        if !backoff.wait().await {
            return Err(failure.context(format!("render of scene {id}: no answer within {:?}", recover.give_up)));
        }
    }
    Ok((tally, id))
}

//! What `relume serve` gives back and how it answers clients that misbehave at the HTTP
//! level: memory of deleted scenes, renders whose clients have gone, the HTTP layer's own
//! refusals (as JSON, like every other error), bodies refused from their `Content-Length`,
//! and empty stream messages. Each test drives a real server on a loopback port and fails
//! without the fix it guards.

use relume::service::wire::ErrorCode;
use relume::service::wire::proto::envelope::Body;

use super::hardening::fake_server;
use super::service::{envelope, frame, inline_scene};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_empty_stream_message_is_malformed() {
    let server = fake_server(0, |_| {}).await;
    let id = server.create(&inline_scene()).await;
    let mut ws = server.stream(&id).await;
    match ws.exchange(Vec::new()).await {
        Body::Error(error) => {
            assert_eq!(error.code(), ErrorCode::Malformed, "{error:?}");
            assert!(!error.message.is_empty());
        }
        other => panic!("expected an error, got {other:?}"),
    }
    // The stream stays open: a real frame is still answered.
    assert!(matches!(ws.exchange(envelope(Body::RgbdFrame(frame(2, 8, 6)))).await, Body::RenderedFrame(_)));
    server.stop().await;
}

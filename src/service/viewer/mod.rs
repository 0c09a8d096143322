//! The browser viewer: a page served at `/` that plays a server-side recording on a scene's
//! stream and shows the relit frames, their per-stage timings and the stream's settings.
//!
//! The files sit next to this module and are built into the binary (no build step, nothing
//! read from disk at run time). The page is an ordinary client of the public API: it creates
//! the scene with `POST /v1/scenes`, fetches frames from `/v1/recordings/...` and speaks the
//! protobuf stream protocol (`proto.js`, a hand-written codec for the messages it uses).
//! `GET /default-scene.json` is `fixtures/scenes/mr_bunny.json` with its mesh paths made
//! relative to `fixtures/` (run the server with `--assets fixtures`).

use std::sync::Arc;

use axum::Router;
use axum::http::{HeaderValue, header};
use axum::response::IntoResponse;
use axum::routing::get;

use super::AppState;

/// (URL path, content type, contents) of every file of the viewer.
pub const FILES: &[(&str, &str, &str)] = &[
    ("/", "text/html; charset=utf-8", include_str!("index.html")),
    ("/viewer.js", "text/javascript; charset=utf-8", include_str!("viewer.js")),
    ("/proto.js", "text/javascript; charset=utf-8", include_str!("proto.js")),
    ("/viewer.css", "text/css; charset=utf-8", include_str!("viewer.css")),
];

/// The scene the viewer creates unless told otherwise, as a scene file relative to the asset
/// directory `fixtures/`.
pub fn default_scene() -> String {
    include_str!("../../../fixtures/scenes/mr_bunny.json").replace("\"../meshes/", "\"meshes/")
}

/// The viewer's routes (outside `/v1`: no token needed to load the page).
pub fn routes() -> Router<Arc<AppState>> {
    let mut router = Router::new();
    for &(path, content_type, body) in FILES {
        router = router.route(path, get(move || async move { file(content_type, body.to_owned()) }));
    }
    router.route("/default-scene.json", get(|| async { file("application/json", default_scene()) }))
}

/// A viewer file; `no-cache` so that a rebuilt server's page is picked up at once.
fn file(content_type: &'static str, body: String) -> impl IntoResponse {
    (
        [
            (header::CONTENT_TYPE, HeaderValue::from_static(content_type)),
            (header::CACHE_CONTROL, HeaderValue::from_static("no-cache")),
        ],
        body,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_scene_is_the_fixture_relative_to_fixtures() {
        let scene: serde_json::Value = serde_json::from_str(&default_scene()).expect("JSON");
        let obj = scene["meshes"][0]["obj"].as_str().expect("a mesh path");
        assert_eq!(obj, "meshes/stanford_bunny/stanford-bunny.obj");
        let fixtures = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
        assert!(fixtures.join(obj).is_file());
    }

    #[test]
    fn the_page_loads_the_files_that_are_served() {
        let text = |path: &str| FILES.iter().find(|(p, _, _)| *p == path).map(|(_, _, text)| *text).expect(path);
        let html = text("/");
        assert!(html.contains(r#"src="/viewer.js""#) && html.contains(r#"href="/viewer.css""#));
        assert!(text("/viewer.js").contains(r#"from "./proto.js""#));
    }
}

//! The browser viewer: a page served at `/` that plays a server-side recording on a scene's
//! stream and shows the relit frames, their per-stage timings and the stream's settings.
//!
//! The files sit next to this module and are built into the binary (no build step, nothing
//! read from disk at run time). The page is an ordinary client of the public API: it creates
//! the scene with `POST /v1/scenes`, fetches frames from `/v1/recordings/...` and speaks the
//! protobuf stream protocol (`proto.js`): protobuf.js's `light` build, vendored unchanged in
//! `vendor/protobufjs/` (BSD-3-Clause, served with its licence), reading the descriptor
//! `relume.proto.json` of `proto/relume.proto`. `scripts/viewer-protobuf.mjs` writes both;
//! a test here checks the descriptor against the `.proto` file as prost-build reads it.
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
    ("/relume.proto.json", "application/json", include_str!("relume.proto.json")),
    (
        "/vendor/protobufjs/protobuf.min.js",
        "text/javascript; charset=utf-8",
        include_str!("vendor/protobufjs/protobuf.min.js"),
    ),
    ("/vendor/protobufjs/LICENSE", "text/plain; charset=utf-8", include_str!("vendor/protobufjs/LICENSE")),
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
        let proto = text("/proto.js");
        assert!(proto.contains(r#"import "./vendor/protobufjs/protobuf.min.js""#));
        assert!(proto.contains(r#""./relume.proto.json""#));
        assert!(text("/vendor/protobufjs/protobuf.min.js").starts_with("/*!\n * protobuf.js v"));
        assert!(text("/vendor/protobufjs/LICENSE").contains("Copyright (c) 2016, Daniel Wirtz"));
    }

    /// `relume.proto.json` (what protobuf.js encodes and decodes with) says what
    /// `proto/relume.proto` says, as protox reads it for prost in build.rs: every message's
    /// fields with their numbers, types, labels and oneofs, every enum's values.
    #[test]
    fn the_viewers_descriptor_is_the_proto_file() {
        let text = FILES.iter().find(|(p, _, _)| *p == "/relume.proto.json").expect("served").2;
        let json: serde_json::Value = serde_json::from_str(text).expect("JSON");
        let package = &json["nested"]["relume"]["nested"]["v1"]["nested"];
        let mut lines = Vec::new();
        for (name, item) in package.as_object().expect("the package's types") {
            if let Some(values) = item.get("values") {
                for (value, number) in values.as_object().expect("values") {
                    lines.push(format!("enum {name} {value} = {number}"));
                }
                continue;
            }
            let oneof = |field: &str| -> String {
                let oneofs = item.get("oneofs").and_then(|o| o.as_object());
                let real = oneofs.into_iter().flatten().filter(|(n, _)| !n.starts_with('_'));
                let mut found = real.filter(|(_, o)| o["oneof"].as_array().expect("names").iter().any(|f| f == field));
                found.next().map(|(n, _)| format!(" oneof {n}")).unwrap_or_default()
            };
            for (field, f) in item["fields"].as_object().expect("fields") {
                let label = match (f.get("rule").and_then(|r| r.as_str()), f["options"]["proto3_optional"].as_bool()) {
                    (Some(rule), _) => format!("{rule} "),
                    (None, Some(true)) => "optional ".to_owned(),
                    (None, _) => String::new(),
                };
                let (ty, id) = (f["type"].as_str().expect("type"), &f["id"]);
                lines.push(format!("message {name} {label}{ty} {field} = {id}{}", oneof(field)));
            }
            let synthetic = item.get("oneofs").and_then(|o| o.as_object()).into_iter().flatten();
            for (oneof, o) in synthetic.filter(|(n, _)| n.starts_with('_')) {
                let field = &o["oneof"][0];
                assert_eq!(format!("_{}", field.as_str().expect("a name")), *oneof, "{name}: {o}");
                assert_eq!(item["fields"][field.as_str().expect("a name")]["options"]["proto3_optional"], true);
            }
        }
        lines.sort();
        let proto = include_str!(concat!(env!("OUT_DIR"), "/relume.proto.txt"));
        let mut expected: Vec<String> = proto.lines().map(str::to_owned).collect();
        expected.sort();
        let only = |a: &[String], b: &[String]| a.iter().filter(|l| !b.contains(l)).cloned().collect::<Vec<_>>();
        assert!(
            lines == expected,
            "relume.proto.json is not proto/relume.proto (run `node scripts/viewer-protobuf.mjs` after \
             scripts/e2e-setup.sh): only in the .proto file {:?}, only in the descriptor {:?}",
            only(&expected, &lines),
            only(&lines, &expected)
        );
    }
}

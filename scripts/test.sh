#!/usr/bin/env bash
# Sets everything up, checks formatting and lints, runs the whole test suite (unit, property and
# GPU tests on lavapipe), then the browser viewer end to end (headless chromium), a local
# cluster losing a backend, and the GPU benchmark's script at tiny sizes.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
source scripts/e2e-setup.sh
# The viewer's vendored protobuf.js and protobuf descriptor are what the script writes.
node scripts/viewer-protobuf.mjs --check
cargo fmt --check
cargo clippy --all-targets --quiet -- -D warnings
cargo test
# `cargo test` built the binary the viewer test starts (`relume serve` on port 0).
RELUME_BIN="${CARGO_TARGET_DIR:-target}/debug/relume" node tests/e2e/viewer.test.mjs
# The Dockerfile, Kubernetes manifests and HAProxy configurations, checked offline (checkov).
deploy/check.sh
# A local cluster (HAProxy and three `relume serve`) losing a backend mid-stream: about a minute.
scripts/cluster-test.sh --bin "${CARGO_TARGET_DIR:-target}/debug/relume" --out out/cluster-test
# The GPU benchmark's script at tiny sizes on lavapipe, so that it works when a device is lent.
scripts/device-bench.sh --smoke --bin "${CARGO_TARGET_DIR:-target}/debug/relume" --out out/device-bench-smoke

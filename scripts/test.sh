#!/usr/bin/env bash
# Sets everything up, checks formatting, runs the whole test suite (unit, property and GPU tests
# on lavapipe) built with clippy's lints denied, then the browser viewer end to end (headless
# chromium), a local cluster losing a backend, and the GPU benchmark's script at tiny sizes.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
source scripts/e2e-setup.sh
# The viewer's vendored protobuf.js and protobuf descriptor are what the script writes.
node scripts/viewer-protobuf.mjs --check
cargo fmt --check
# Clippy's lints (`-D warnings`) run inside the test build rather than in a `cargo clippy` of
# their own: clippy-driver as the workspace's compiler, which is what `cargo clippy` sets up for
# `cargo check`. The dependencies are then compiled once instead of checked once and built once,
# which took 8.7 of a clean run's 31 minutes on 2 cores; the lints cost 14 s more than a plain
# build. `cargo test` builds what `cargo clippy --all-targets` checks (library, binary, tests,
# examples). Both variables change the workspace's fingerprint: a plain `cargo test` after this
# script rebuilds relume itself (not its dependencies).
clippy_driver="$(rustc --print sysroot)/bin/clippy-driver"
[ -x "$clippy_driver" ] || { echo "scripts/test.sh: no $clippy_driver: rustup component add clippy" >&2; exit 1; }
RUSTC_WORKSPACE_WRAPPER="$clippy_driver" CLIPPY_ARGS="-D__CLIPPY_HACKERY__warnings__CLIPPY_HACKERY__" cargo test
# `cargo test` built the binary the viewer test starts (`relume serve` on port 0).
RELUME_BIN="${CARGO_TARGET_DIR:-target}/debug/relume" node tests/e2e/viewer.test.mjs
# The Dockerfile, Kubernetes manifests and HAProxy configurations, checked offline (checkov).
deploy/check.sh
# A local cluster (HAProxy and three `relume serve`) losing a backend mid-stream: about a minute.
scripts/cluster-test.sh --bin "${CARGO_TARGET_DIR:-target}/debug/relume" --out out/cluster-test
# The GPU benchmark's script at tiny sizes on lavapipe, so that it works when a device is lent.
scripts/device-bench.sh --smoke --bin "${CARGO_TARGET_DIR:-target}/debug/relume" --out out/device-bench-smoke

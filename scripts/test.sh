#!/usr/bin/env bash
# Sets everything up and runs the whole test suite (unit, property and GPU tests on lavapipe),
# then the formatting and lint checks.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
cargo fmt --check
cargo clippy --all-targets --quiet -- -D warnings
cargo test

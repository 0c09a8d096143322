#!/usr/bin/env bash
# Sets everything up and runs the default job: the Stanford bunny placed on the desk of the
# TUM fr1_xyz recording and relit, frame by frame, by the room's RGB-D frames (composited and
# indirect-only frames in out/replay/), then the Cornell box + bunny fixture relit by its spot
# light's 20k VALs, all three components from one frame (out/cornell_bunny/{full,indirect,direct}
# .png and .exr).
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
cargo build --release --quiet
mkdir -p out
./target/release/relume replay fixtures/recordings/tum_fr1_xyz --scene fixtures/scenes/mr_bunny_differential.json --out out/replay
./target/release/relume render fixtures/scenes/cornell_bunny.json --out-dir out/cornell_bunny
echo "images in out/replay/ and out/"

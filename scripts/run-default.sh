#!/usr/bin/env bash
# Sets everything up and runs the default job: the Cornell box + bunny fixture relit by its
# spot light's 20k VALs with the sparse method, images written to out/. (The brute-force
# reference of the same image takes minutes on lavapipe: see `relume compare` in the README.)
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
cargo build --release --quiet
mkdir -p out
scene=fixtures/scenes/cornell_bunny.json
for component in full indirect direct; do
    ./target/release/relume render "$scene" --component "$component" --out "out/cornell_bunny_$component.png" --hdr "out/cornell_bunny_$component.exr"
done
echo "images in out/"

#!/usr/bin/env bash
# Sets everything up and runs the default job: the Cornell box + bunny fixture relit by its
# spot light's 20k VALs with the sparse method, images written to out/.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
cargo build --release --quiet
mkdir -p out
scene=fixtures/scenes/cornell_bunny.json
for component in full indirect direct; do
    ./target/release/relume render "$scene" --component "$component" --out "out/cornell_bunny_$component.png" --hdr "out/cornell_bunny_$component.exr"
done
./target/release/relume render "$scene" --method brute-force --component indirect --out out/cornell_bunny_indirect_brute_force.png
echo "images in out/"

#!/usr/bin/env bash
# Render every fixture scene with one relume binary, for comparing two builds (a refactor must
# leave every image and figure as it was: tools/compare-runs.py BEFORE AFTER).
#
#   scripts/compare-fixtures.sh BIN OUT
#
# Scenes with a spot light or lights: `relume compare` at 64x64 with the exact reference (JSON,
# images). Scenes lit by RGB-D frames: `relume replay` of the first 3 frames of the bundled TUM
# recording at 80x60 (composites, indirect images, summary). Run from the repository root of
# the build's own checkout (the fixtures are read from there).
set -euo pipefail
bin=$1
out=$2
mkdir -p "$out"
for scene in fixtures/scenes/*.json; do
  name=$(basename "$scene" .json)
  start=$(date +%s)
  if "$bin" compare "$scene" --width 64 --height 64 --reference exact --images "$out/$name" \
      >"$out/$name.json" 2>"$out/$name.err"; then
    echo "$name: compare, $(($(date +%s) - start)) s"
  elif grep -q "use \`replay\`" "$out/$name.err"; then
    rm -f "$out/$name.json"
    "$bin" replay fixtures/recordings/tum_fr1_xyz --scene "$scene" --frames 3 --width 80 --height 60 \
      --out "$out/replay_$name" >"$out/replay_$name.log" 2>&1
    echo "$name: replay, $(($(date +%s) - start)) s"
  else
    echo "$name: failed (see $out/$name.err)" >&2
    exit 1
  fi
done

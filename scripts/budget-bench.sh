#!/usr/bin/env bash
# The frame budget controller on the bundled TUM replay (docs/measurements/budget.md): the
# replay at the scene's level without a budget, then with a budget of half and of twice its
# median frame time after the first 5 frames, side by side in one run; prints (and writes) a
# table of each run's p90 frame time after the first 5 frames, the levels its frames ran at,
# its mean error estimate, the estimate's share of the frame, and the composite's mean
# frame-to-frame change (the popping the controller adds is the budgeted runs' change minus
# the unbudgeted run's).
#   scripts/budget-bench.sh [--bin PATH] [--frames N] [--out DIR] [--page FILE] [--scene FILE]
set -euo pipefail
cd "$(dirname "$0")/.."
bin=target/release/relume; frames=37; out=out/budget; page=docs/measurements/budget.md
scene=fixtures/scenes/mr_bunny.json
while [ $# -gt 0 ]; do
    case "$1" in
        --bin) bin="$2"; shift 2 ;;
        --frames) frames="$2"; shift 2 ;;
        --out) out="$2"; shift 2 ;;
        --page) page="$2"; shift 2 ;;
        --scene) scene="$2"; shift 2 ;;
        *) echo "budget-bench: unknown argument $1" >&2; exit 2 ;;
    esac
done
recording=fixtures/recordings/tum_fr1_xyz
run() { # name, extra args...
    local name="$1"; shift
    "$bin" replay "$recording" --scene "$scene" --frames "$frames" --out "$out/$name" "$@" 2>"$out/$name.log" \
        || { cat "$out/$name.log" >&2; exit 1; }
}
mkdir -p "$out"
run balanced
median=$(python3 -c "
import json, statistics, sys
s = json.load(open('$out/balanced/summary.json'))
print(round(statistics.median(s['frame_ms'][5:] or s['frame_ms']), 1))")
half=$(python3 -c "print(round($median / 2, 1))")
twice=$(python3 -c "print(round($median * 2, 1))")
run half --budget-ms "$half"
run twice --budget-ms "$twice"
python3 - "$out" "$median" "$frames" "$bin" "$scene" >"$out/budget.md" <<'EOF'
import json, statistics, sys
out, median, frames, binary, scene = sys.argv[1], float(sys.argv[2]), sys.argv[3], sys.argv[4], sys.argv[5]
rows = []
base_change = None
for name in ["balanced", "half", "twice"]:
    s = json.load(open(f"{out}/{name}/summary.json"))
    after = s["frame_ms"][5:] or s["frame_ms"]
    est = [e for e in s["error_estimate"] if e is not None]
    change = statistics.mean(s["composite_change"]) if s["composite_change"] else 0.0
    if name == "balanced":
        base_change = change
    levels = ", ".join(f"{k} {v}" for k, v in sorted(s["level_frames"].items()))
    last = s["parameters"][-1]
    budget = s["budget_ms"]
    p90 = s["p90_frame_ms_after_5"]
    within = "" if budget is None else f"{100 * (p90 / budget - 1):+.1f} %"
    rows.append((name, "none" if budget is None else f"{budget:.1f}", f"{p90:.1f}", within,
                 f"{statistics.median(after):.1f}", levels,
                 f"{last['level']}: {last['occlusion']}, vals_step {last['vals_step']}, scale {last['resolution_scale']}"
                 + ("" if last.get("camera_detail", 1.0) >= 1.0 else f", camera detail {last['camera_detail']}")
                 + ("" if last.get("receivers_step", 1) == 1 else f", receivers step {last['receivers_step']}"),
                 f"{statistics.mean(est):.4f}" if est else "-",
                 f"{100 * statistics.mean(s['error_estimate_ms']) / statistics.mean(s['frame_ms']):.1f} %",
                 f"{change:.3f}", f"{change - base_change:+.3f}", s["adapter"]))
print("| run | budget ms | p90 ms after 5 | p90 vs budget | median ms after 5 | frames per level | last frame ran at "
      "| mean error estimate | estimate's share of the frame | composite change (levels) | change added |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
for r in rows:
    print("| " + " | ".join(r[:-1]) + " |")
print()
# Where each run's frame goes: the median of every stage after the first 5 frames (the stages
# that do not fall with the render size set the floor of the cheapest rung).
runs = {name: json.load(open(f"{out}/{name}/summary.json")) for name in ["balanced", "half", "twice"]}
stages = list(dict.fromkeys(k for s in runs.values() for k in s["stage_ms"]))
print("| stage (median ms after 5) | " + " | ".join(runs) + " |")
print("|---|" + "---|" * len(runs))
for stage in stages + ["whole frame"]:
    cells = []
    for s in runs.values():
        values = s["frame_ms"] if stage == "whole frame" else s["stage_ms"].get(stage, [])
        values = [v for v in values[5:] if v is not None]
        cells.append(f"{statistics.median(values):.1f}" if values else "-")
    print(f"| {stage} | " + " | ".join(cells) + " |")
# The differential pass's receivers (its cost follows them; 0 without the pass).
cells = [f"{statistics.median(s['receivers_per_frame'][5:] or [0]):.0f}" for s in runs.values()]
print("| differential receivers (median count) | " + " | ".join(cells) + " |")
print()
print(f"Adapter: {rows[0][-1]}; {frames} frames of `fixtures/recordings/tum_fr1_xyz` with "
      f"`{scene}` at 640x480; balanced median frame {median} ms; binary `{binary}`.")
EOF
{
    echo "# The frame budget controller"
    echo
    echo "Generated by \`scripts/budget-bench.sh\`: \`relume replay fixtures/recordings/tum_fr1_xyz --scene"
    echo "$scene\` at the scene's level (balanced) without a budget, then with"
    echo "\`--budget-ms\` half and twice its median frame time after the first 5 frames, in one run."
    echo "Frame times are wall clock (lavapipe: the GPU is two CPU cores shared with other work, so"
    echo "they are noisy). \"p90 vs budget\" is the target's measure (within +10 %); \"frames per"
    echo "level\" is where the controller ran (src/renderer/budget.rs); \"composite change\" is the"
    echo "mean absolute difference of consecutive composites in 8-bit levels, and \"change added\""
    echo "is that of a budgeted run minus the unbudgeted run's (the popping the controller adds)."
    echo "The error estimate is the per-frame one (src/renderer/estimate.rs, \`PER_FRAME\`). The"
    echo "second table splits each run's frame by stage: a budget below the cheapest rung's frame"
    echo "cannot be held. The stages whose cost does not fall with the render size (the camera's"
    echo "raster and the per-vertex interpolation, which grow with the mesh; the environment) set"
    echo "the floor of the rungs that scale the render size; the cheapest rung lowers it by drawing"
    echo "the meshes simplified to a quarter of their triangles (camera detail 0.25). With the"
    echo "differential pass, every rung below \`fast\`'s own computes one receiver in 4 (receivers"
    echo "step 2), one in 16 at half size (step 4): the pass is most of the frame at every rung, and"
    echo "its cost follows its receivers."
    echo
    cat "$out/budget.md"
} >"$page"
cat "$page"

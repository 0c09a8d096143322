#!/usr/bin/env bash
# The one-shot GPU benchmark: everything relume reports as GPU figures, in one run
# of at most ~8 minutes on a lent device, or in seconds on lavapipe with --smoke (CI runs that,
# so the script cannot rot).
#
#   scripts/device-bench.sh [--smoke] [--bin PATH] [--out DIR] [--work DIR] [--deadline S]
#
# It builds nothing and downloads nothing: it runs a relume binary built elsewhere (default
# target/device/relume, made by `scripts/device-bench.sh --prepare`: the release binary,
# stripped, so that it and the working tree travel to the device machine) and, when the folder
# .gl/ holds Debian packages of the Vulkan loader (see README "GPU figures"), unpacks them
# first. Every step has a time limit; a step that fails or times out is recorded as such and
# the rest still run. What it writes to --out (default $OUT, else out/device-bench):
#   results.json  every step's status, wall time and its own JSON output
#   results.md    the headline figures as a Markdown table
#   log.txt       everything the steps printed
# The bulky per-step outputs (bench folders, replay frames) stay in --work.
# --deadline S (default 420): the whole run's wall-clock limit; a step never runs past it (its
# limit is cut to what is left, and a step with under 15 s left is recorded as skipped), so a
# device call with a little more than S seconds always gets the summary back.
set -euo pipefail
cd "$(dirname "$0")/.."

smoke=0
prepare=0
bin=target/device/relume
out="${OUT:-out/device-bench}"
work="${TMPDIR:-/tmp}/relume-device-bench"
deadline=420
while [ $# -gt 0 ]; do
    case "$1" in
        --smoke) smoke=1 ;;
        --prepare) prepare=1 ;;
        --bin) bin="$2"; shift ;;
        --out) out="$2"; shift ;;
        --work) work="$2"; shift ;;
        --deadline) deadline="$2"; shift ;;
        -h|--help) sed -n '2,21p' "$0"; exit 0 ;;
        *) echo "device-bench: unknown argument '$1' (see --help)" >&2; exit 2 ;;
    esac
    shift
done

if [ "$prepare" = 1 ]; then
    # Here, with the Rust toolchain: the release binary without symbols (~1/3 of its size).
    cargo build --release --quiet
    mkdir -p "$(dirname "$bin")"
    strip -o "$bin" target/release/relume
    ls -l "$bin"
    exit 0
fi

# The Vulkan loader carried to a bare device machine (only as root, only when present).
if compgen -G ".gl/*.deb" >/dev/null && [ "$(id -u)" -eq 0 ]; then
    for f in .gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
fi
if [ -z "${VK_DRIVER_FILES:-}" ] && [ -f /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json ]; then
    export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
fi
if [ -z "${__EGL_VENDOR_LIBRARY_FILENAMES:-}" ] && [ -f /usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json ]; then
    export __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
fi
[ -x "$bin" ] || { echo "device-bench: no relume binary at $bin (build one with --prepare, or pass --bin)" >&2; exit 2; }
command -v python3 >/dev/null || { echo "device-bench: python3 is needed for the summary" >&2; exit 2; }

mkdir -p "$out" "$work"
rm -rf "${work:?}"/*
log="$out/log.txt"
: >"$log"
steps="$work/steps.tsv"
: >"$steps"

started=$(date +%s)
# step NAME SECONDS COMMAND...: runs COMMAND with a time limit (cut to what --deadline leaves);
# its stdout goes to $work/NAME.out, both streams to the log; records status and wall time.
# A step with too little time left is recorded with status "skipped".
step() {
    local name="$1" limit="$2"
    shift 2
    local left=$((deadline - ($(date +%s) - started) - 15))
    if [ "$left" -lt 15 ]; then
        echo "== $name: skipped, ${left} s left before the deadline" | tee -a "$log"
        printf '%s\t%s\t%s\t%s\n' "$name" skipped 0 "$limit" >>"$steps"
        return 0
    fi
    [ "$limit" -le "$left" ] || limit=$left
    echo "== $name: $*" | tee -a "$log"
    local start status=0
    start=$(date +%s%N)
    timeout --kill-after=10 "$limit" "$@" >"$work/$name.out" 2> >(tee -a "$log" >&2) || status=$?
    local ms=$((($(date +%s%N) - start) / 1000000))
    cat "$work/$name.out" >>"$log"
    printf '%s\t%s\t%s\t%s\n' "$name" "$status" "$ms" "$limit" >>"$steps"
    echo "== $name: exit $status" | tee -a "$log"
}

scenes=fixtures/scenes
# The default job's scene with the differential pass on the CPU's cores (`settings.mr.device`),
# beside the scene's own files so that its relative paths hold; removed on exit.
# And with the fast differential pass on the GPU, where the exact one is the default: it was the
# faster there on the first device run (one dispatch, where the fast pass waits on the host
# between its adaptive levels); is it still?
mr_cpu="$scenes/.device-bench-mr-cpu.json"
mr_fast="$scenes/.device-bench-mr-fast.json"
# Sponza with the near field at four spacings, every pixel every near VAL, and interleaved over
# 4 x 4 blocks: what the near field costs on a GPU against the sparse frame without it
# (sponza_512), where lavapipe measured 7.3x and 2.1x the rest of the frame.
near1="$scenes/.device-bench-sponza-near1.json"
near4="$scenes/.device-bench-sponza-near4.json"
trap 'rm -f "$mr_cpu" "$mr_fast" "$near1" "$near4"' EXIT
python3 - "$scenes/mr_bunny_differential.json" "$mr_cpu" "$mr_fast" <<'PY'
import json, sys
for out, key, value in [(sys.argv[2], "device", "cpu"), (sys.argv[3], "differential_method", "fast")]:
    scene = json.load(open(sys.argv[1]))
    scene.setdefault("settings", {}).setdefault("mr", {})[key] = value
    json.dump(scene, open(out, "w"), indent=2)
PY
python3 - "$scenes/sponza_bunny.json" "$near1" "$near4" <<'PY'
import json, sys
for out, side in [(sys.argv[2], 1), (sys.argv[3], 4)]:
    scene = json.load(open(sys.argv[1]))
    tuning = scene.setdefault("settings", {}).setdefault("tuning", {})
    tuning["sparse"] = {"near_field": 4, "near_field_interleave": side}
    json.dump(scene, open(out, "w"), indent=2)
PY
if [ "$smoke" = 1 ]; then
    # Tiny sizes: checks every step's machinery on lavapipe in well under a minute.
    # GPU timestamps even on lavapipe, as on the device, so that their recording is checked too.
    export RELUME_TIMING=gpu
    step table1 120 "$bin" bench "$scenes/cornell_bunny_small.json" --table1 --quick --no-plots --no-temporal --out "$work/table1"
    step levels_1080 120 "$bin" bench "$scenes/cornell_bunny_small.json" --levels --width 24 --height 16 --out "$work/levels_1080"
    step mr_640 120 "$bin" replay fixtures/recordings/tum_fr1_xyz --scene "$scenes/mr_bunny_differential.json" --frames 2 --width 64 --height 48 --out "$work/mr_640"
    step mr_640_cpu 120 "$bin" replay fixtures/recordings/tum_fr1_xyz --scene "$mr_cpu" --frames 2 --width 64 --height 48 --out "$work/mr_640_cpu"
    step mr_640_fast 120 "$bin" replay fixtures/recordings/tum_fr1_xyz --scene "$mr_fast" --frames 2 --width 64 --height 48 --out "$work/mr_640_fast"
    step sweep 120 "$bin" bench "$scenes/cornell_bunny_small.json" --quick --no-plots --no-temporal --out "$work/sweep"
    step sparse_vs_brute 120 "$bin" compare "$scenes/cornell_bunny_small.json" --width 32 --height 18
    step exact 120 "$bin" compare "$scenes/cornell_bunny_small.json" --width 16 --height 16 --reference exact
    step sponza_512 120 "$bin" compare "$scenes/sponza_bunny.json" --width 32 --height 18
    step sponza_512_lanes1 120 env RELUME_GATHER_LANES=1 "$bin" compare "$scenes/sponza_bunny.json" --width 32 --height 18
    step sponza_512_near1 120 "$bin" compare "$near1" --width 32 --height 18
    step sponza_512_near4 120 "$bin" compare "$near4" --width 32 --height 18
    step levels_sponza 120 "$bin" bench "$scenes/cornell_bunny_small.json" --levels --width 16 --height 9 --gpu-estimator 4 --out "$work/levels_sponza"
    step load 60 "$bin" load --seconds 3 --streams 1 --http 1 --json
else
    # Ordered by what a first device run must answer; --deadline cuts the tail if need be.
    # The paper's Table 1 (36 configurations at 1920x1080), the FMA kernel and the gather's
    # tile sizes come with each bench run.
    step table1 150 "$bin" bench "$scenes/cornell_bunny_small.json" --table1 --no-plots --no-temporal --out "$work/table1"
    # Every quality level of the Table 1 scene at 1920x1080, against the exact reference. Its
    # accurate level is the brute force through the clusters' maps (the scene file's measured
    # level): every VAL at every pixel, so this step says what that level costs on a GPU at 1080p.
    step levels_1080 90 "$bin" bench "$scenes/cornell_bunny_small.json" --levels --width 1920 --height 1080 --out "$work/levels_1080"
    # The mixed-reality replay (all 37 frames) at 640x480 and 1280x720: does a stream hold 30
    # and 90 frames per second?
    step mr_640 60 "$bin" replay fixtures/recordings/tum_fr1_xyz --scene "$scenes/mr_bunny_differential.json" --width 640 --height 480 --out "$work/mr_640"
    step mr_1280 60 "$bin" replay fixtures/recordings/tum_fr1_xyz --scene "$scenes/mr_bunny_differential.json" --width 1280 --height 720 --out "$work/mr_1280"
    # The same replay at 640x480 with the differential pass on the device's CPU cores instead
    # (rayon over them, running the fast pass, the CPU's default).
    step mr_640_cpu 60 "$bin" replay fixtures/recordings/tum_fr1_xyz --scene "$mr_cpu" --width 640 --height 480 --out "$work/mr_640_cpu"
    # And the fast pass on the GPU (four adaptive levels, each read back) against the default
    # there, the exact pass in one dispatch.
    step mr_640_fast 60 "$bin" replay fixtures/recordings/tum_fr1_xyz --scene "$mr_fast" --width 640 --height 480 --out "$work/mr_640_fast"
    step sparse_vs_brute 45 "$bin" compare "$scenes/cornell_bunny.json" --width 1920 --height 1080
    # Sponza at 512 wide: the sparse frame against the brute force without visibility; then the
    # same with the gather's kernel before GPUs shared each sparse point among invocations
    # (one invocation a point), side by side.
    step sponza_512 45 "$bin" compare "$scenes/sponza_bunny.json" --width 512 --height 288
    step sponza_512_lanes1 45 env RELUME_GATHER_LANES=1 "$bin" compare "$scenes/sponza_bunny.json" --width 512 --height 288
    # The near field at four spacings, not interleaved and interleaved over 4 x 4 blocks.
    step sponza_512_near1 45 "$bin" compare "$near1" --width 512 --height 288
    step sponza_512_near4 45 "$bin" compare "$near4" --width 512 --height 288
    step exact 45 "$bin" compare "$scenes/cornell_bunny.json" --width 512 --height 512 --reference exact --reference-device gpu
    # Sponza's levels and their candidates on the GPU: on lavapipe balanced and accurate are
    # the estimator of the exact reference (16 and 64 draws, 0.070 and 0.035 from exact, 12x
    # and 13x the sparse level's time there; docs/measurements/level-parameters.md); which
    # levels would a GPU's measured fronts pick (the suggestion block of levels.md)?
    step levels_sponza 90 "$bin" bench "$scenes/sponza_bunny.json" --levels --candidates --width 512 --height 288 --out "$work/levels_sponza"
    step sweep 60 "$bin" bench "$scenes/cornell_bunny.json" --no-plots --out "$work/sweep" \
        --sweep sparse_points=1024,4096,16384 --sweep rsm_resolution=128,256,724 --sweep resolution=1920x1080
    # The service under load on one GPU: what one backend of a cluster delivers.
    step load 40 "$bin" load --seconds 20 --streams 4 --http 4 --json
fi

python3 scripts/device_bench_summary.py "$work" "$steps" "$out" "$smoke"
cat "$out/results.md"
# Fail when a step failed, after the summary is written, so CI notices.
! awk -F'\t' '$2 != 0 && $2 != "skipped" { bad = 1 } END { exit !bad }' "$steps"

#!/usr/bin/env bash
# The one-shot GPU benchmark: everything relume reports as GPU figures, in one run
# of at most ~8 minutes on a lent device, or in seconds on lavapipe with --smoke (CI runs that,
# so the script cannot rot).
#
#   scripts/device-bench.sh [--smoke] [--bin PATH] [--out DIR] [--work DIR]
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
set -euo pipefail
cd "$(dirname "$0")/.."

smoke=0
prepare=0
bin=target/device/relume
out="${OUT:-out/device-bench}"
work="${TMPDIR:-/tmp}/relume-device-bench"
while [ $# -gt 0 ]; do
    case "$1" in
        --smoke) smoke=1 ;;
        --prepare) prepare=1 ;;
        --bin) bin="$2"; shift ;;
        --out) out="$2"; shift ;;
        --work) work="$2"; shift ;;
        -h|--help) sed -n '2,18p' "$0"; exit 0 ;;
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
[ -x "$bin" ] || { echo "device-bench: no relume binary at $bin (build one with --prepare, or pass --bin)" >&2; exit 2; }
command -v python3 >/dev/null || { echo "device-bench: python3 is needed for the summary" >&2; exit 2; }

mkdir -p "$out" "$work"
rm -rf "${work:?}"/*
log="$out/log.txt"
: >"$log"
steps="$work/steps.tsv"
: >"$steps"

# step NAME SECONDS COMMAND...: runs COMMAND with a time limit; its stdout goes to
# $work/NAME.out, both streams to the log; records status and wall time.
step() {
    local name="$1" limit="$2"
    shift 2
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
if [ "$smoke" = 1 ]; then
    # Tiny sizes: checks every step's machinery on lavapipe in well under a minute.
    step table1 120 "$bin" bench "$scenes/cornell_bunny_small.json" --table1 --quick --no-plots --no-temporal --out "$work/table1"
    step sweep 120 "$bin" bench "$scenes/cornell_bunny_small.json" --quick --no-plots --no-temporal --out "$work/sweep"
    step sparse_vs_brute 120 "$bin" compare "$scenes/cornell_bunny_small.json" --width 32 --height 18
    step exact 120 "$bin" compare "$scenes/cornell_bunny_small.json" --width 16 --height 16 --reference exact
    step replay 120 "$bin" replay fixtures/recordings/tum_fr1_xyz --scene "$scenes/mr_bunny.json" --frames 2 --width 64 --height 48 --out "$work/replay"
    step mr_640 120 "$bin" replay fixtures/recordings/tum_fr1_xyz --scene "$scenes/mr_bunny_differential.json" --frames 2 --width 64 --height 48 --out "$work/mr_640"
else
    # The paper's Table 1 (36 configurations at 1920x1080), the FMA kernel and the gather's
    # tile sizes come with each bench run.
    step table1 240 "$bin" bench "$scenes/cornell_bunny_small.json" --table1 --no-plots --no-temporal --out "$work/table1"
    step sweep 90 "$bin" bench "$scenes/cornell_bunny.json" --no-plots --out "$work/sweep" \
        --sweep sparse_points=1024,4096,16384 --sweep rsm_resolution=128,256,724 --sweep resolution=1920x1080
    step sparse_vs_brute 60 "$bin" compare "$scenes/cornell_bunny.json" --width 1920 --height 1080
    step exact 60 "$bin" compare "$scenes/cornell_bunny.json" --width 512 --height 512 --reference exact --reference-device gpu
    step replay 60 "$bin" replay fixtures/recordings/tum_fr1_xyz --scene "$scenes/mr_bunny.json" --out "$work/replay"
    # Mixed reality at stream rate: the default job's scene (differential pass on, `auto`
    # environment) over the recording's 37 frames, per-stage times in its summary.json; does a
    # stream hold 30 and 90 frames per second?
    step mr_640 60 "$bin" replay fixtures/recordings/tum_fr1_xyz --scene "$scenes/mr_bunny_differential.json" --width 640 --height 480 --out "$work/mr_640"
    step mr_1280 60 "$bin" replay fixtures/recordings/tum_fr1_xyz --scene "$scenes/mr_bunny_differential.json" --width 1280 --height 720 --out "$work/mr_1280"
fi

python3 scripts/device_bench_summary.py "$work" "$steps" "$out" "$smoke"
cat "$out/results.md"
# Fail when a step failed, after the summary is written, so CI notices.
! awk -F'\t' '$2 != 0 { bad = 1 } END { exit !bad }' "$steps"

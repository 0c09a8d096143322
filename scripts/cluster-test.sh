#!/usr/bin/env bash
# A local cluster under a backend failure (docs/deploy.md): HAProxy (deploy/haproxy/haproxy.cfg)
# in front of three `relume serve` on loopback ports sharing a scene store. It measures HTTP
# render latency straight to one backend and through the balancer, then replays the fixture
# recording through the balancer (`relume replay --server`) beside two HTTP render clients
# (`relume load`) while the backend holding the stream is killed (SIGKILL) and restarted.
# Between the two, it asks the balancer for stream tickets and opens a stream through it with
# each (the backends share a ticket key, --ticket-key-file, and the store), then uses one again.
#
# It prints what it saw and ends with one JSON line:
#   frames_delivered, frames_lost, reconnects, requests_failed, renders_refused,
#   scene_renderable_after_kill, tickets_opened, tickets_tried, p50/p99 direct and balanced
#   (ms), seconds.
# It exits non-zero when a target is missed: no HTTP render fails while a backend is up; the
# stream comes back losing only the frame in flight (one per kill); every scene created before
# the kill renders through the balancer while the killed backend is down; every ticket opens a
# stream through the balancer, whichever backend issued it, and a used one is refused (401).
#
# Usage: scripts/cluster-test.sh [--bin PATH] [--out DIR] [--frames N]
#        scripts/cluster-test.sh --scaling [--seconds S] [--bin PATH]
# --scaling instead runs `relume load` (3 streams, 3 HTTP clients, S s, default 20) through
# the balancer with 1, 2 and 3 backends and writes docs/measurements/cluster-scaling.md.
# Installs only Debian's `haproxy` when missing (through scripts/apt-install.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
BIN="${CARGO_TARGET_DIR:-target}/debug/relume"
OUT=out/cluster-test
FRAMES=37
SCALING=false
SECONDS_PER_RUN=20
while [ $# -gt 0 ]; do
    case "$1" in
        --scaling) SCALING=true; shift ;;
        --seconds) SECONDS_PER_RUN="$2"; shift 2 ;;
        --bin) BIN="$2"; shift 2 ;;
        --out) OUT="$2"; shift 2 ;;
        --frames) FRAMES="$2"; shift 2 ;;
        *) echo "cluster-test: unknown argument $1" >&2; exit 2 ;;
    esac
done
started_at=$(date +%s)

command -v haproxy >/dev/null || scripts/apt-install.sh haproxy
source scripts/setup.sh
[ -x "$BIN" ] || cargo build --quiet
for tool in curl jq python3; do
    command -v "$tool" >/dev/null || { echo "cluster-test: $tool is needed" >&2; exit 2; }
done

rm -rf "$OUT"
mkdir -p "$OUT/scenes"
# The secret the backends share, so that any of them accepts a ticket another issued.
python3 -c 'import secrets; print(secrets.token_urlsafe(48))' >"$OUT/ticket.key"
# Four free loopback ports: the balancer's and three backends'.
read -r LB P1 P2 P3 < <(python3 -c '
import socket
socks = [socket.socket() for _ in range(4)]
for s in socks: s.bind(("127.0.0.1", 0))
print(*[s.getsockname()[1] for s in socks])')
PORTS=("$P1" "$P2" "$P3")
PIDS=("" "" "")
HAPROXY_PID=""
cleanup() {
    for pid in "${PIDS[@]}" $HAPROXY_PID; do
        [ -n "$pid" ] && kill "$pid" 2>/dev/null || true
    done
    wait 2>/dev/null || true
}
trap cleanup EXIT

start_backend() {  # index 0..2
    "$BIN" serve --addr "127.0.0.1:${PORTS[$1]}" --assets . --scene-store "$OUT/scenes" \
        --ticket-key-file "$OUT/ticket.key" --max-client-queue 8 >>"$OUT/backend$1.log" 2>&1 &
    PIDS[$1]=$!
}
wait_ready() {  # url
    for _ in $(seq 1 300); do
        [ "$(curl -s -o /dev/null -w '%{http_code}' "$1/readyz")" = 200 ] && return 0
        sleep 0.1
    done
    echo "cluster-test: $1 never became ready" >&2
    exit 1
}
start_balancer() {
    RELUME_LB_BIND="127.0.0.1:$LB" RELUME_BACKEND_1="127.0.0.1:$P1" RELUME_BACKEND_2="127.0.0.1:$P2" \
        RELUME_BACKEND_3="127.0.0.1:$P3" haproxy -db -f deploy/haproxy/haproxy.cfg >>"$OUT/haproxy.log" 2>&1 &
    HAPROXY_PID=$!
}
BALANCER="http://127.0.0.1:$LB"

if [ "$SCALING" = true ]; then
    page=docs/measurements/cluster-scaling.md
    loadavg=$(cut -d' ' -f1-3 /proc/loadavg)
    rows=""
    for n in 1 2 3; do
        for i in $(seq 0 $((n - 1))); do start_backend "$i"; done
        for i in $(seq 0 $((n - 1))); do wait_ready "http://127.0.0.1:${PORTS[$i]}"; done
        start_balancer
        wait_ready "$BALANCER"
        # Backends not started fail their checks twice (1 s apart) and leave the balancer.
        sleep 3
        "$BIN" load --server "$BALANCER" --streams 3 --http 3 --seconds "$SECONDS_PER_RUN" --json >"$OUT/scaling-$n.json"
        rows="$rows$(jq -r --arg n "$n" '"| \($n) | \(.frames_sent) | \(.frames_rendered) | \(.frames_per_second*100|round/100) | \(.frame_latency_p50_ms|round) / \(.frame_latency_p99_ms|round) ms | \(.renders_ok) | \(.renders_per_second*100|round/100) | \(.render_latency_p50_ms|round) / \(.render_latency_p99_ms|round) ms | \(.renders_refused) | \(.renders_failed) |"' "$OUT/scaling-$n.json")
"
        cleanup
        PIDS=("" "" "")
        HAPROXY_PID=""
    done
    {
        echo "# Throughput through the balancer with 1, 2 and 3 backends"
        echo
        echo "Written by \`scripts/cluster-test.sh --scaling --seconds $SECONDS_PER_RUN\` on $(date -u +%Y-%m-%d) ($(git rev-parse --short HEAD)):"
        echo "HAProxy (deploy/haproxy/haproxy.cfg) in front of N \`relume serve\` (dev profile, lavapipe) on"
        echo "this machine's $(nproc) cores, and one \`relume load --streams 3 --http 3 --seconds $SECONDS_PER_RUN\` through it:"
        echo "three streams of \`mr_bunny.json\` (640x480 frames at 10 fps, each on its own scene) and three"
        echo "HTTP clients rendering \`cornell_bunny_small.json\` (64x64) back to back; the load average"
        echo "when it started was $loadavg (other work sharing the cores). How it is run:"
        echo "[deploy](../deploy.md)."
        echo
        echo "| backends | frames sent | rendered | frames/s | frame p50 / p99 | renders | renders/s | render p50 / p99 | refused | failed |"
        echo "|---|---|---|---|---|---|---|---|---|---|"
        printf '%s' "$rows"
        echo
        echo "Every backend renders on lavapipe, which spreads one frame over all the cores: on this"
        echo "machine the backends share the same $(nproc) cores, so more backends bring no more compute. What"
        echo "grows from one backend to two comes from overlapping one process's serial parts (decoding,"
        echo "encoding, the waits between GPU submissions) with another's rendering, and is capped by the"
        echo "CPU. With one GPU per backend each backend's throughput would add: one backend on an H200"
        echo "is measured in [the service on one GPU](service-gpu.md)."
    } >"$page"
    echo "cluster-test: wrote $page"
    cat "$page"
    exit 0
fi

for i in 0 1 2; do start_backend "$i"; done
for port in "${PORTS[@]}"; do wait_ready "http://127.0.0.1:$port"; done
start_balancer
wait_ready "$BALANCER"
echo "cluster-test: HAProxy on $LB, backends on ${PORTS[*]}"

# Latency: one HTTP client rendering the 64x64 scene for 8 s, straight to a backend, then
# through the balancer.
"$BIN" load --server "http://127.0.0.1:$P1" --streams 0 --http 1 --seconds 8 --json >"$OUT/direct.json"
"$BIN" load --server "$BALANCER" --streams 0 --http 1 --seconds 8 --json >"$OUT/balanced.json"

# Tickets: a scene created through the balancer, TICKETS requested through it (spread over the
# backends, leastconn), then a browser-style handshake (no token) with each through the
# balancer, to the backend the scene hashes to; then the first again, which must be refused.
TICKETS=6
python3 - "$LB" "$TICKETS" >"$OUT/tickets.json" <<'PYTHON'
import base64, json, os, socket, sys, urllib.request
port, count = int(sys.argv[1]), int(sys.argv[2])
description = json.load(open("fixtures/scenes/cornell_bunny_small.json"))
for mesh in description["meshes"]:  # paths relative to the server's assets (the repository)
    mesh["obj"] = os.path.normpath(os.path.join("fixtures/scenes", mesh["obj"]))
request = urllib.request.Request(f"http://127.0.0.1:{port}/v1/scenes", data=json.dumps(description).encode(),
                                 method="POST", headers={"Content-Type": "application/json"})
scene = json.load(urllib.request.urlopen(request, timeout=60))["id"]
def ticket():
    request = urllib.request.Request(f"http://127.0.0.1:{port}/v1/tickets", data=b"", method="POST")
    return json.load(urllib.request.urlopen(request, timeout=10))["ticket"]
def handshake(ticket):
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        key = base64.b64encode(os.urandom(16)).decode()
        s.sendall((f"GET /v1/scenes/{scene}/stream?ticket={ticket} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n"
                   f"Upgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                   "Sec-WebSocket-Version: 13\r\n\r\n").encode())
        return int(s.recv(4096).split(b"\r\n", 1)[0].split()[1])
tickets = [ticket() for _ in range(count)]
statuses = [handshake(t) for t in tickets]
print(json.dumps({"scene": scene, "tried": count, "opened": statuses.count(101), "statuses": statuses,
                  "reused_status": handshake(tickets[0])}))
PYTHON
tickets_tried=$(jq .tried "$OUT/tickets.json")
tickets_opened=$(jq .opened "$OUT/tickets.json")
reused_status=$(jq .reused_status "$OUT/tickets.json")
scene=$(jq -r .scene "$OUT/tickets.json")
issuers=$(grep -o 'relume_any/relume[0-9]* .*"POST /v1/tickets' "$OUT/haproxy.log" | cut -d' ' -f1 | sort -u | tr '\n' ' ')
echo "cluster-test: tickets: $tickets_opened of $tickets_tried opened a stream of scene $scene (issued by ${issuers:-?}); reused: $reused_status"

# The failure: a replay through the balancer beside two HTTP clients (for 30 s); once a few
# frames are back, the backend holding the stream is killed, and restarted 5 s later.
"$BIN" load --server "$BALANCER" --streams 0 --http 2 --seconds 30 --json >"$OUT/load.json" 2>"$OUT/load.log" &
LOAD_PID=$!
"$BIN" replay fixtures/recordings/tum_fr1_xyz --scene fixtures/scenes/mr_bunny.json --server "$BALANCER" \
    --frames "$FRAMES" --out "$OUT/replay" >"$OUT/replay.log" 2>&1 &
REPLAY_PID=$!
for _ in $(seq 1 600); do
    [ "$(find "$OUT/replay/composited" -name '*.png' 2>/dev/null | wc -l)" -ge 5 ] && break
    sleep 0.1
done
# The backend that holds the replay's stream: the one whose gauge reads exactly 1. Polled for up
# to 10 s: a backend may still count a stream of the ticket check above whose client has just
# gone (one CI run found none at the first look, and the same check passed on the next).
killed=""
for _ in $(seq 1 100); do
    for i in 0 1 2; do
        if curl -s --max-time 2 "http://127.0.0.1:${PORTS[$i]}/metrics" | grep -qx 'relume_streams 1'; then killed=$i; fi
    done
    [ -n "$killed" ] && break
    sleep 0.1
done
[ -n "$killed" ] || { echo "cluster-test: no backend holds the stream" >&2; exit 1; }
kill -KILL "${PIDS[$killed]}"
wait "${PIDS[$killed]}" 2>/dev/null || true
echo "cluster-test: killed backend $((killed + 1)) (port ${PORTS[$killed]}) mid-stream"
# Every scene created before the kill (in the store: the replay's, the HTTP clients') renders
# through the balancer while that backend is down.
sleep 1
renderable=true
for file in "$OUT"/scenes/*.json; do
    id=$(basename "$file" .json)
    code=$(curl -s -o /dev/null -w '%{http_code}' -X POST "$BALANCER/v1/scenes/$id/render" -d '{}')
    echo "cluster-test: scene $id after the kill: $code"
    [ "$code" = 200 ] || renderable=false
done
sleep 4
start_backend "$killed"
wait_ready "http://127.0.0.1:${PORTS[$killed]}"
echo "cluster-test: restarted backend $((killed + 1))"
replay_status=0
wait "$REPLAY_PID" || replay_status=$?
load_status=0
wait "$LOAD_PID" || load_status=$?
cat "$OUT/replay.log" | grep -v '^\s*$' | tail -4

summary="$OUT/replay/summary.json"
if [ "$replay_status" -ne 0 ] || [ ! -f "$summary" ]; then
    echo "cluster-test: the replay failed ($replay_status); see $OUT/replay.log" >&2
    frames_lost=$FRAMES; delivered=0; reconnects=0
else
    frames_lost=$(jq .frames_lost "$summary")
    reconnects=$(jq .reconnects "$summary")
    delivered=$(( $(jq .frames "$summary") - frames_lost ))
fi
if [ "$load_status" -ne 0 ] || ! jq -e . "$OUT/load.json" >/dev/null 2>&1; then
    echo "cluster-test: the HTTP clients failed ($load_status); see $OUT/load.log" >&2
    failed=-1; refused=-1
else
    failed=$(jq .renders_failed "$OUT/load.json")
    refused=$(jq .renders_refused "$OUT/load.json")
fi
jq -r '"direct:   \(.renders_ok) renders, p50 \(.render_latency_p50_ms|floor) ms, p99 \(.render_latency_p99_ms|floor) ms"' "$OUT/direct.json"
jq -r '"balanced: \(.renders_ok) renders, p50 \(.render_latency_p50_ms|floor) ms, p99 \(.render_latency_p99_ms|floor) ms"' "$OUT/balanced.json"
echo "replay: $delivered frames delivered, $frames_lost lost, $reconnects reconnects; HTTP: $failed failed, $refused refused (503)"

ok=true
[ "$failed" -eq 0 ] || ok=false
[ "$delivered" -gt 0 ] && [ "$reconnects" -ge 1 ] && [ "$frames_lost" -le "$reconnects" ] || ok=false
[ "$renderable" = true ] || ok=false
[ "$tickets_opened" -eq "$tickets_tried" ] && [ "$reused_status" -eq 401 ] || ok=false
jq -cn --argjson delivered "$delivered" --argjson lost "$frames_lost" --argjson reconnects "$reconnects" \
    --argjson failed "$failed" --argjson refused "$refused" --argjson renderable "$renderable" \
    --argjson tickets_opened "$tickets_opened" --argjson tickets_tried "$tickets_tried" \
    --argjson ok "$ok" --argjson seconds "$(( $(date +%s) - started_at ))" \
    --slurpfile direct "$OUT/direct.json" --slurpfile balanced "$OUT/balanced.json" \
    '{frames_delivered: $delivered, frames_lost: $lost, reconnects: $reconnects, requests_failed: $failed,
      renders_refused: $refused, scene_renderable_after_kill: $renderable,
      tickets_opened: $tickets_opened, tickets_tried: $tickets_tried,
      direct_p50_ms: $direct[0].render_latency_p50_ms, direct_p99_ms: $direct[0].render_latency_p99_ms,
      balanced_p50_ms: $balanced[0].render_latency_p50_ms, balanced_p99_ms: $balanced[0].render_latency_p99_ms,
      targets_met: $ok, seconds: $seconds}'
[ "$ok" = true ]

#!/usr/bin/env bash
# Render admission under load: starts `l3 serve` (release build, default config, its default
# table trained first) and measures with wrk a 2 MP raw frame (1600×1250 u16) rendered to PNG
# by 1, 8 and 16 clients (req/s, p50/p99, non-2xx), then 4 slow uploads
# (`curl --limit-rate 20k`) of that frame while one normal client renders.
#
#   scripts/admission_bench.sh [SECONDS]        (default 15 s per wrk run)
# Env: BIN (default $CARGO_TARGET_DIR/release/l3), L3_* settings, SLOW (default 4 slow uploads).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
SECS=${1:-15}
BIN=${BIN:-${CARGO_TARGET_DIR:-$ROOT/target}/release/l3}
command -v wrk >/dev/null || { echo "wrk is not installed (apt-get install -y wrk)"; exit 1; }
WORK=$(mktemp -d -t l3-admission.XXXXXX)
PORT=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
URL="http://127.0.0.1:$PORT/v1/render?width=1600&height=1250&illuminant=Tungsten"
export L3_BIND=127.0.0.1:$PORT L3_DATA_DIR=$WORK/data
"$BIN" serve >"$WORK/server.log" 2>&1 &
PID=$!
SLOW_PIDS=()
cleanup() {
    for p in "${SLOW_PIDS[@]}"; do kill "$p" 2>/dev/null || true; done
    kill "$PID" 2>/dev/null && wait "$PID" 2>/dev/null || true
    rm -rf "$WORK"
}
trap cleanup EXIT
# a 2 MP frame: a smooth gradient with a little texture, 12-bit-ish levels
python3 - "$WORK/frame.raw" <<'PY'
import struct, sys, math
w, h = 1600, 1250
row = bytearray()
with open(sys.argv[1], "wb") as f:
    for y in range(h):
        vals = [max(0, int(4000 + 30000 * (x / w) * (0.5 + 0.5 * y / h) + 3000 * math.sin(x * 0.05) * math.cos(y * 0.07))) for x in range(w)]
        f.write(struct.pack(f"<{w}H", *vals))
PY
cat >"$WORK/post.lua" <<LUA
local f = io.open("$WORK/frame.raw", "rb")
wrk.method = "POST"
wrk.body = f:read("*all")
f:close()
wrk.headers["Content-Type"] = "application/octet-stream"
wrk.headers["Accept"] = "image/png"
LUA
for _ in $(seq 1 600); do
    curl -fsS "http://127.0.0.1:$PORT/readyz" >/dev/null 2>&1 && break
    kill -0 "$PID" 2>/dev/null || { cat "$WORK/server.log"; exit 1; }
    sleep 1
done
summary() {
    # req/s, p50, p99, non-2xx from wrk --latency output
    awk '/Requests\/sec/ {r=$2} /^ +50%/ {p50=$2} /^ +99%/ {p99=$2}
         /Non-2xx/ {n=$NF} / requests in / {t=$1}
         END {printf "%s req/s, p50 %s, p99 %s, %s responses, non-2xx %s\n", r, p50, p99, t, (n==""?0:n)}'
}
for c in 1 8 16; do
    t=$(( c < 2 ? 1 : 2 ))
    printf -- "-c%-3s " "$c"
    wrk -t"$t" -c"$c" -d"${SECS}s" --latency --timeout 30s -s "$WORK/post.lua" "$URL" | summary
done
echo "${SLOW:-4} slow uploads (curl --limit-rate 20k) while one client renders:"
for i in $(seq 1 "${SLOW:-4}"); do
    curl -s -o /dev/null -w "slow upload $i: %{http_code} after %{time_total} s\n" --limit-rate 20k \
        -H 'Content-Type: application/octet-stream' --data-binary @"$WORK/frame.raw" "$URL" &
    SLOW_PIDS+=($!)
done
sleep 2
printf -- "-c1 beside the slow uploads: "
wrk -t1 -c1 -d"${SECS}s" --latency --timeout 30s -s "$WORK/post.lua" "$URL" | summary
echo "waiting for the slow uploads' answers"
for p in "${SLOW_PIDS[@]}"; do wait "$p" || true; done
SLOW_PIDS=()
curl -s "http://127.0.0.1:$PORT/metrics" | grep -E '^l3_render_(body|budget|queue)|^l3_renders_canceled' || true

#!/usr/bin/env bash
# Render admission under load, with the acceptance checks of the render service: starts
# `l3 serve` (release build, default config, its default table trained first) and measures with
# wrk a 2 MP raw frame (1600×1250 u16) rendered to PNG:
#
#   1. 1 client, then 8 clients: zero non-2xx, 8-client throughput ≥ 0.9× one client's,
#      p99 ≤ 250 ms;
#   2. 32 clients: zero non-2xx (the default queue holds 64);
#   3. 4, then 16 slow uploads (`curl --limit-rate 20k`) beside 8 normal clients: the normal
#      clients keep ≥ 0.8× their throughput with no 503, the slow ones get 408 at the body
#      deadline;
#   4. a training job running beside 8 clients: render p99 within 2× of the same load without it;
#   5. 64 concurrent 12 MP uploads (24 MB each): the server's peak RSS against the body budget
#      plus the renderer's frame pool plus the render slots' working memory.
#
# Each check prints PASS or FAIL; the script exits 1 if any failed.
#
#   scripts/admission_bench.sh [SECONDS]        (default 30 s per wrk run)
# Env: BIN (default $CARGO_TARGET_DIR/release/l3), L3_* settings, PHASES (default "1 2 3 4 5").
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
SECS=${1:-30}
PHASES=${PHASES:-1 2 3 4 5}
BIN=${BIN:-${CARGO_TARGET_DIR:-$ROOT/target}/release/l3}
command -v wrk >/dev/null || { echo "wrk is not installed (apt-get install -y wrk)"; exit 1; }
WORK=$(mktemp -d -t l3-admission.XXXXXX)
PORT=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
BASE="http://127.0.0.1:$PORT"
URL="$BASE/v1/render?width=1600&height=1250&illuminant=Tungsten"
export L3_BIND=127.0.0.1:$PORT L3_DATA_DIR=$WORK/data
"$BIN" serve >"$WORK/server.log" 2>&1 &
PID=$!
BG_PIDS=()
cleanup() {
    for p in "${BG_PIDS[@]}"; do kill "$p" 2>/dev/null || true; done
    kill "$PID" 2>/dev/null && wait "$PID" 2>/dev/null || true
    rm -rf "$WORK"
}
trap cleanup EXIT
FAILED=0
check() { # check NAME CONDITION-EXIT-STATUS DETAIL
    if [ "$2" = 0 ]; then echo "PASS  $1 ($3)"; else echo "FAIL  $1 ($3)"; FAILED=1; fi
}
ge() { python3 -c "import sys; sys.exit(0 if float(sys.argv[1]) >= float(sys.argv[2]) else 1)" "$1" "$2"; }

# frames: a smooth gradient with a little texture, 12-bit-ish levels
python3 - "$WORK/frame.raw" 1600 1250 "$WORK/frame12.raw" 4000 3000 <<'PY'
import array, math, sys
for path, w, h in ((sys.argv[1], int(sys.argv[2]), int(sys.argv[3])), (sys.argv[4], int(sys.argv[5]), int(sys.argv[6]))):
    with open(path, "wb") as f:
        for y in range(h):
            f.write(array.array("H", (max(0, int(4000 + 30000 * (x / w) * (0.5 + 0.5 * y / h)
                + 3000 * math.sin(x * 0.05) * math.cos(y * 0.07))) for x in range(w))).tobytes())
PY
cat >"$WORK/post.lua" <<LUA
local f = io.open("$WORK/frame.raw", "rb")
wrk.method = "POST"
wrk.body = f:read("*all")
f:close()
wrk.headers["Content-Type"] = "application/octet-stream"
wrk.headers["Accept"] = "image/png"
done = function(summary, latency, requests)
  io.write(string.format("RESULT %d %d %.2f %.1f %.1f %.1f\n", summary.requests, summary.errors.status,
    summary.requests / (summary.duration / 1e6), latency:percentile(50) / 1000,
    latency:percentile(99) / 1000, latency.max / 1000))
end
LUA
for _ in $(seq 1 900); do
    curl -fsS "$BASE/readyz" >/dev/null 2>&1 && break
    kill -0 "$PID" 2>/dev/null || { cat "$WORK/server.log"; exit 1; }
    sleep 1
done
curl -fsS "$BASE/readyz" >/dev/null || { echo "the server did not become ready"; exit 1; }

# run_wrk CLIENTS: sets N (responses), NON2XX, RPS, P50, P99 (ms) and prints them
run_wrk() {
    local c=$1 t=$(( $1 < 2 ? 1 : 2 ))
    read -r _ N NON2XX RPS P50 P99 MAX < <(wrk -t"$t" -c"$c" -d"${SECS}s" --timeout 60s \
        -s "$WORK/post.lua" "$URL" | grep '^RESULT')
    printf -- "  -c%-3s %7s req/s, p50 %6s ms, p99 %6s ms, max %6s ms, %5s responses, %s non-2xx\n" \
        "$c" "$RPS" "$P50" "$P99" "$MAX" "$N" "$NON2XX"
}
metric() { curl -s "$BASE/metrics" | awk -v m="$1" '$1 == m {print $2}'; }
wrk -t1 -c1 -d3s -s "$WORK/post.lua" "$URL" >/dev/null # warm the kernel cache

R8=""
P99_8=""
if [[ " $PHASES " == *" 1 "* ]]; then
    echo "== 1. one client, then 8 clients (${SECS} s each)"
    run_wrk 1; R1=$RPS
    run_wrk 8; R8=$RPS; P99_8=$P99
    check "8 clients: no non-2xx" "$([ "$NON2XX" = 0 ]; echo $?)" "$NON2XX non-2xx"
    check "8 clients: throughput ≥ 0.9× one client" "$(ge "$R8" "$(python3 -c "print(0.9*$R1)")"; echo $?)" \
        "$R8 against $R1 req/s, ratio $(python3 -c "print(round($R8/$R1, 3))")"
    check "8 clients: p99 ≤ 250 ms" "$(ge 250 "$P99"; echo $?)" "p99 $P99 ms"
fi
if [ -z "$R8" ]; then run_wrk 8; R8=$RPS; P99_8=$P99; fi

if [[ " $PHASES " == *" 2 "* ]]; then
    echo "== 2. 32 clients"
    before=$(metric l3_render_queue_refusals_total)
    run_wrk 32
    after=$(metric l3_render_queue_refusals_total)
    check "32 clients: no non-2xx" "$([ "$NON2XX" = 0 ]; echo $?)" \
        "$NON2XX non-2xx; queue refusals ${before:-0} → ${after:-0}"
fi

if [[ " $PHASES " == *" 3 "* ]]; then
    for slow in 4 16; do
        echo "== 3. $slow slow uploads (20 KB/s) beside 8 clients"
        : >"$WORK/slow.txt"
        for i in $(seq 1 "$slow"); do
            curl -s -o /dev/null -w "%{http_code} %{time_total}\n" --limit-rate 20k \
                -H 'Content-Type: application/octet-stream' --data-binary @"$WORK/frame.raw" \
                "$URL" >>"$WORK/slow.txt" 2>/dev/null &
            BG_PIDS+=($!)
        done
        sleep 2
        run_wrk 8
        check "8 clients beside $slow slow uploads: no non-2xx" "$([ "$NON2XX" = 0 ]; echo $?)" "$NON2XX non-2xx"
        check "8 clients beside $slow slow uploads: ≥ 0.8× their throughput" \
            "$(ge "$RPS" "$(python3 -c "print(0.8*$R8)")"; echo $?)" "$RPS against $R8 req/s"
        for p in "${BG_PIDS[@]}"; do wait "$p" || true; done
        BG_PIDS=()
        codes=$(awk '{print $1}' "$WORK/slow.txt" | sort | uniq -c | xargs)
        times=$(awk '{print $2}' "$WORK/slow.txt" | sort -n | sed -n '1p;$p' | xargs)
        n408=$(awk '$1 == 408' "$WORK/slow.txt" | wc -l)
        check "$slow slow uploads: 408 at the body deadline" "$([ "$n408" = "$slow" ]; echo $?)" \
            "codes: $codes; answered after $times s"
    done
fi

if [[ " $PHASES " == *" 4 "* ]]; then
    echo "== 4. a training job beside 8 clients"
    job=$(curl -fsS -H 'Content-Type: application/json' -d '{"scenes": 400, "seed": 99}' \
        "$BASE/v1/training-jobs" | python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])')
    for _ in $(seq 1 60); do
        st=$(curl -fsS "$BASE/v1/training-jobs/$job" | python3 -c 'import json,sys; print(json.load(sys.stdin)["status"])')
        [ "$st" = running ] && break
        sleep 0.5
    done
    run_wrk 8
    st=$(curl -fsS "$BASE/v1/training-jobs/$job" | python3 -c 'import json,sys; j=json.load(sys.stdin); print(j["status"], j["progress"])')
    curl -fsS -X POST "$BASE/v1/training-jobs/$job/cancel" >/dev/null || true
    check "training beside renders: p99 ≤ 2× without training" \
        "$(ge "$(python3 -c "print(2*$P99_8)")" "$P99"; echo $?)" \
        "p99 $P99 against $P99_8 ms, $RPS against $R8 req/s; the job was '$st' at the end"
fi

if [[ " $PHASES " == *" 5 "* ]]; then
    echo "== 5. 64 concurrent 12 MP uploads (4000×3000 u16, 24 MB each)"
    sleep 2
    base_rss=$(awk '/VmRSS/ {print $2}' /proc/$PID/status)
    echo 5 >/proc/$PID/clear_refs 2>/dev/null || echo "  (cannot reset VmHWM; the peak below may be older)"
    : >"$WORK/big.txt"
    for i in $(seq 1 64); do
        curl -s -o /dev/null -w "%{http_code}\n" -H 'Content-Type: application/octet-stream' \
            -H 'Accept: image/png' --data-binary @"$WORK/frame12.raw" \
            "$BASE/v1/render?width=4000&height=3000&illuminant=Tungsten" >>"$WORK/big.txt" 2>/dev/null &
        BG_PIDS+=($!)
    done
    for p in "${BG_PIDS[@]}"; do wait "$p" || true; done
    BG_PIDS=()
    peak=$(awk '/VmHWM/ {print $2}' /proc/$PID/status)
    budget=$(( ${L3_BODY_BUDGET_BYTES:-1073741824} / 1024 ))
    conc=${L3_RENDER_CONCURRENCY:-4}
    # a render slot's working memory at 12 MP: the decoded mosaic (f32, 48 MB), the sRGB frame
    # (36 MB) and its PNG (≤ 36 MB)
    slots=$(( conc * 120 * 1024 ))
    pool=$(( 256 * 1024 ))
    bound=$(( base_rss + budget + pool + slots ))
    codes=$(sort "$WORK/big.txt" | uniq -c | xargs)
    echo "  answers: $codes"
    check "64 × 12 MP: peak RSS within the body budget + frame pool + render slots" \
        "$([ "$peak" -le "$bound" ]; echo $?)" \
        "peak $(( peak / 1024 )) MB; bound $(( bound / 1024 )) MB = RSS before $(( base_rss / 1024 )) + budget $(( budget / 1024 )) + frame pool $(( pool / 1024 )) + $conc slots × 120"
fi
curl -s "$BASE/metrics" | grep -E '^l3_render_(body|budget|queue)|^l3_renders_canceled' || true
exit $FAILED

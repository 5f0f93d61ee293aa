#!/usr/bin/env bash
# Load test of the l3 service: builds the release binary, starts `l3 serve` on a temporary data
# directory and a free port (it trains its default table first), waits for /readyz, runs
# scripts/load_test.py (default 32 clients for 60 s), stops the server and prints the summary.
# Exits non-zero on any 5xx other than 503 backpressure, any connection error, or a peak RSS
# over MAX_RSS_MB.
#
#   scripts/load_test.sh [--clients N] [--duration S]   (other args go to load_test.py)
# Env: CARGO_TARGET_DIR, L3_ISET_DIR (default ../shared/data/iset), MAX_RSS_MB (default 2048),
#      KEEP_DATA=1 keeps the data dir, SKIP_BUILD=1 uses the existing binary, L3_* settings.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
TARGET=${CARGO_TARGET_DIR:-$ROOT/target}
[ "${SKIP_BUILD:-0}" = 1 ] || cargo build --release --bin l3
BIN=$TARGET/release/l3
DATA=$(mktemp -d -t l3-load.XXXXXX)
PORT=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
URL=http://127.0.0.1:$PORT
LOG=$DATA/server.log
export L3_BIND=127.0.0.1:$PORT L3_DATA_DIR=$DATA
# the spectral data is built in; ../shared (or $L3_ISET_DIR) overrides it when present
[ -d "${L3_ISET_DIR:-$ROOT/../shared/data/iset}" ] && export L3_ISET_DIR=${L3_ISET_DIR:-$ROOT/../shared/data/iset}
"$BIN" serve >"$LOG" 2>&1 &
PID=$!
cleanup() {
    kill "$PID" 2>/dev/null && wait "$PID" 2>/dev/null || true
    if [ "${KEEP_DATA:-0}" = 1 ]; then echo "data and server log kept in $DATA"; else rm -rf "$DATA"; fi
}
trap cleanup EXIT
echo "server pid $PID on $URL, data $DATA; waiting for /readyz (the default table trains first)"
for _ in $(seq 1 600); do
    if curl -fsS "$URL/readyz" >/dev/null 2>&1; then break; fi
    kill -0 "$PID" 2>/dev/null || { echo "the server exited:"; cat "$LOG"; exit 1; }
    sleep 1
done
curl -fsS "$URL/readyz"; echo
echo "RSS before the load: $(grep VmRSS /proc/$PID/status)"
set +e
python3 "$ROOT/scripts/load_test.py" --url "$URL" --pid "$PID" --max-rss-mb "${MAX_RSS_MB:-2048}" \
    --json "$DATA/summary.json" "$@"
RC=$?
set -e
echo "server log: $(grep -c ' ERROR ' "$LOG" || true) ERROR line(s), $(grep -c ' WARN ' "$LOG" || true) WARN line(s)"
grep ' ERROR ' "$LOG" | head -5 || true
if [ -n "${SUMMARY_OUT:-}" ]; then cp "$DATA/summary.json" "$SUMMARY_OUT"; fi
exit $RC

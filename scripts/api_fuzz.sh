#!/usr/bin/env bash
# Property-based API fuzzing of the l3 service, driven by openapi.yaml (schemathesis).
# Creates a venv with schemathesis (PyPI), builds the release binary, starts `l3 serve` on a
# temporary data directory and a free port, waits for /readyz (the default table trains first),
# runs `schemathesis run openapi.yaml` with every check and a bounded number of examples, and
# exits non-zero on any failure (server errors, responses that break the schema, ...).
#
#   scripts/api_fuzz.sh [extra schemathesis args]
# Env: MAX_EXAMPLES (default 60 per operation), MAX_TIME (s, default 600), SEED (default 1),
#      VENV (default $CARGO_TARGET_DIR/api-fuzz-venv), CARGO_TARGET_DIR, L3_ISET_DIR,
#      KEEP_DATA=1 keeps the data dir with the server log and the reports, SKIP_BUILD=1.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
TARGET=${CARGO_TARGET_DIR:-$ROOT/target}
VENV=${VENV:-$TARGET/api-fuzz-venv}
if [ ! -x "$VENV/bin/schemathesis" ]; then
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install --quiet 'schemathesis>=4,<5'
fi
"$VENV/bin/schemathesis" --version
[ "${SKIP_BUILD:-0}" = 1 ] || cargo build --release --bin l3
BIN=$TARGET/release/l3
DATA=$(mktemp -d -t l3-fuzz.XXXXXX)
PORT=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
URL=http://127.0.0.1:$PORT
LOG=$DATA/server.log
export L3_BIND=127.0.0.1:$PORT L3_DATA_DIR=$DATA
# the spectral data is built in; ../shared (or $L3_ISET_DIR) overrides it when present
[ -d "${L3_ISET_DIR:-$ROOT/../shared/data/iset}" ] && export L3_ISET_DIR=${L3_ISET_DIR:-$ROOT/../shared/data/iset}
# (an evaluation can take long on a loaded 2-core machine while the fuzzer's jobs train)
export L3_REQUEST_TIMEOUT_S=${L3_REQUEST_TIMEOUT_S:-300}
"$BIN" serve >"$LOG" 2>&1 &
PID=$!
cleanup() {
    kill "$PID" 2>/dev/null && wait "$PID" 2>/dev/null || true
    if [ "${KEEP_DATA:-0}" = 1 ]; then echo "data, server log and reports kept in $DATA"; else rm -rf "$DATA"; fi
}
trap cleanup EXIT
echo "server pid $PID on $URL, data $DATA; waiting for /readyz"
for _ in $(seq 1 600); do
    if curl -fsS "$URL/readyz" >/dev/null 2>&1; then break; fi
    kill -0 "$PID" 2>/dev/null || { echo "the server exited:"; cat "$LOG"; exit 1; }
    sleep 1
done
curl -fsS "$URL/readyz"; echo
# Cancel the fuzzer's training jobs in the background so queued jobs do not pile up.
(
    while kill -0 "$PID" 2>/dev/null; do
        for id in $(curl -fsS "$URL/v1/training-jobs?status=running&limit=1000" 2>/dev/null |
            python3 -c 'import json,sys; print(" ".join(j["id"] for j in json.load(sys.stdin)["items"]))' 2>/dev/null) \
            $(curl -fsS "$URL/v1/training-jobs?status=queued&limit=1000" 2>/dev/null |
            python3 -c 'import json,sys; print(" ".join(j["id"] for j in json.load(sys.stdin)["items"]))' 2>/dev/null); do
            curl -fsS -X POST "$URL/v1/training-jobs/$id/cancel" >/dev/null 2>&1 || true
        done
        sleep 2
    done
) &
# Excluded checks, and why:
# - positive_data_acceptance (a schema-valid request must not get 400): validity depends on
#   what the document cannot express. A render body is a mosaic the schema can only call
#   "binary" (random bytes are rightly 400 invalid_image); jobs and evaluations name
#   illuminants that must be registered (a random string is rightly 400 unknown_illuminant);
#   an illuminant definition must be an invertible matrix or a spectrum over the visible range.
#   (schemathesis 4.32's per-operation `checks.*.enabled = false` did not take effect with
#   --checks all, so it is excluded everywhere.)
# - use_after_free: DELETE of a user definition that replaced a built-in illuminant (PUT
#   /v1/illuminants/Tungsten) restores the built-in, as documented; the check reads the
#   built-in's 200 as a deleted resource still available.
# Every other check (server errors, status codes, content types, headers, response schemas,
# negative-data rejection, unsupported methods, ...) runs on every operation.
set +e
cd "$DATA"  # schemathesis keeps a .schemathesis cache in the working directory
"$VENV/bin/schemathesis" run "$ROOT/openapi.yaml" --url "$URL" \
    --checks all \
    --exclude-checks positive_data_acceptance,use_after_free \
    --max-examples "${MAX_EXAMPLES:-60}" \
    --max-time "${MAX_TIME:-600}" \
    --seed "${SEED:-1}" \
    --request-timeout 320 \
    --max-response-time 320 \
    --workers 2 \
    --suppress-health-check too_slow,filter_too_much \
    --report junit,ndjson --report-dir "$DATA/report" \
    "$@"
RC=$?
set -e
echo "server log: $(grep -c ' ERROR ' "$LOG" || true) ERROR line(s)"
grep ' ERROR ' "$LOG" | head -20 || true
if grep -q 'panicked' "$LOG"; then echo "the server panicked:"; grep -A3 panicked "$LOG" | head -20; RC=1; fi
kill -0 "$PID" 2>/dev/null || { echo "the server died during the fuzzing"; RC=1; }
exit $RC

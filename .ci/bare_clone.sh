#!/usr/bin/env bash
# The README's quick start in a fresh clone with nothing beside it (no ../shared, no L3_ISET_DIR):
# start the service, simulate a tungsten frame, render it over HTTP, train a small table and
# evaluate it on Natural-100. Uses the l3 binary the test run built from this same source
# (argument 1), so CI does not build a second profile.
set -euo pipefail
BIN="$(realpath "$1")"
SRC="$(cd "$(dirname "$0")/.." && pwd)"
TMP="$(mktemp -d)"
trap 'kill "${SERVER:-0}" 2>/dev/null || true; rm -rf "$TMP"' EXIT
git clone -q "$SRC" "$TMP/l3"
cd "$TMP/l3"
unset L3_ISET_DIR
test ! -e ../shared

PORT=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
L3_BIND="127.0.0.1:$PORT" L3_DATA_DIR="$TMP/data" "$BIN" serve > "$TMP/serve.log" 2>&1 &
SERVER=$!
START=$SECONDS
# the first start trains the default table (seconds in release, longer in a debug build)
for _ in $(seq 1 1800); do
  if curl -sf "http://127.0.0.1:$PORT/readyz" > /dev/null; then break; fi
  if ! kill -0 "$SERVER" 2>/dev/null; then cat "$TMP/serve.log"; exit 1; fi
  sleep 0.5
done
curl -sf "http://127.0.0.1:$PORT/readyz" > /dev/null || { cat "$TMP/serve.log"; exit 1; }
echo "service ready after $((SECONDS - START)) s"
grep -q "built in" "$TMP/serve.log" || { echo "the service did not use the built-in spectral data"; cat "$TMP/serve.log"; exit 1; }

"$BIN" simulate --scene macbeth --illuminant Tungsten --out out/sim
code=$(curl -s -o out/l3.png -w '%{http_code}' -X POST -H 'Content-Type: application/octet-stream' \
  --data-binary @out/sim/mosaic.raw \
  "http://127.0.0.1:$PORT/v1/render?width=192&height=128&illuminant=Tungsten")
[ "$code" = 200 ] || { echo "render answered $code"; cat out/l3.png; exit 1; }
head -c 8 out/l3.png | od -An -tx1 | grep -q "89 50 4e 47 0d 0a 1a 0a" || { echo "not a PNG"; exit 1; }

"$BIN" train --scenes 4 --scene-size 64 --out out/small.safetensors
"$BIN" eval --table out/small.safetensors --illuminant Tungsten --out out/eval/report.json
grep -q '"chart": "natural100"' out/eval/report.json || { echo "the evaluation did not use Natural-100"; exit 1; }
echo "bare clone: serve, simulate, render (HTTP 200, PNG), train and eval on Natural-100 all work"

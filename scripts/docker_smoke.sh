#!/usr/bin/env bash
# Builds the l3 image from docker/Dockerfile and runs the topology of docker/compose.yaml
# (PostgreSQL, two replicas, nginx) under docker/compose.host.yaml: every container on the
# host's network, on loopback ports (nginx 18080, replicas 18081 and 18082, PostgreSQL 15432).
# Base images come from scripts/docker_local_images.sh (made with debootstrap when absent).
# Checks, each PASS or FAIL:
#   the image runs as a non-root user; no container has an address of its own
#   a tiny training job submitted through the proxy runs on one replica, is seen by both
#   /readyz through the proxy; a render through the proxy (a raw RGBW mosaic → PNG)
#   an illuminant PUT through the proxy is served by both replicas
#   start-up: a replica's container start to its /readyz 200
#   a replica killed (docker kill) while it runs a job, restarted: the job completes
#   the Docker health check reports healthy
# Prints the image size, the start-up time, the user and the health status; exits non-zero on
# any failure; removes its containers and volumes at the end.
# Needs root (debootstrap), docker, docker compose (or docker-compose), curl, jq, python3.
# Usage: scripts/docker_smoke.sh        (L3_SMOKE_KEEP=1 leaves the containers running;
#        L3_SMOKE_SKIP_BUILD=1 runs the image l3:smoke as it is)
set -euo pipefail

cd "$(dirname "$0")/.."
project=l3smoke
image=l3:smoke
proxy=http://127.0.0.1:18080
declare -A port=([l3-a]=18081 [l3-b]=18082)
tmp=$(mktemp -d)
failures=0
passes=0

if docker compose version >/dev/null 2>&1; then
    compose=(docker compose)
else
    compose=(docker-compose)
fi
dc() { "${compose[@]}" -p "$project" -f docker/compose.yaml -f docker/compose.host.yaml "$@"; }

cleanup() {
    if [ "${L3_SMOKE_KEEP:-0}" != 1 ]; then
        dc down -v --remove-orphans >/dev/null 2>&1 || true
    fi
    rm -rf "$tmp"
}
trap cleanup EXIT

say() { printf '%s\n' "$*"; }
check() {  # NAME DETAIL OK(0/1)
    if [ "$3" = 0 ]; then
        say "PASS  $1${2:+: $2}"
        passes=$((passes + 1))
    else
        say "FAIL  $1${2:+: $2}"
        failures=$((failures + 1))
    fi
}
now() { date +%s.%N; }
since() { awk -v a="$1" -v b="$(now)" 'BEGIN { printf "%.1f", b - a }'; }
# the HTTP status of GET URL (000 when nothing answers)
status() { curl -s -o /dev/null -w '%{http_code}' --max-time 5 "$1" || true; }
# waits up to SECONDS for GET URL to answer 200
wait_200() {
    local deadline=$(($(date +%s) + $2))
    while [ "$(status "$1")" != 200 ]; do
        [ "$(date +%s)" -lt "$deadline" ] || return 1
        sleep 0.2
    done
}
container() { dc ps -q "$1"; }
job_field() { curl -s --max-time 5 "$1/v1/training-jobs/$2" | jq -r ".$3" 2>/dev/null || true; }
# waits up to SECONDS for job ID (through URL) to reach status STATUS; prints the last status
wait_job() {
    local deadline=$(($(date +%s) + $4)) s
    while :; do
        s=$(job_field "$1" "$2" status)
        [ "$s" = "$3" ] && { echo "$s"; return 0; }
        case "$s" in failed | canceled) echo "$s"; return 1 ;; esac
        [ "$(date +%s)" -lt "$deadline" ] || { echo "$s"; return 1; }
        sleep 0.5
    done
}
submit_job() {  # BODY → job id
    curl -s --max-time 10 -X POST -H 'Content-Type: application/json' "$proxy/v1/training-jobs" \
        -d "$1" | jq -r .id || true
}
# the replica whose log says it started job ID
runner_of() {
    local r
    for r in l3-a l3-b; do
        if docker logs "$(container "$r")" 2>&1 | grep '"training job started"' | grep -q "$1"; then
            echo "$r"
        fi
    done
}

say "== local base images"
scripts/docker_local_images.sh

say "== image"
if [ "${L3_SMOKE_SKIP_BUILD:-0}" = 1 ]; then
    say "build skipped (L3_SMOKE_SKIP_BUILD=1): $image as it is"
else
    t0=$(now)
    docker build --network host -q \
        --build-arg BUILDER_IMAGE=l3-local/rust:1.95-bookworm \
        --build-arg RUNTIME_IMAGE=l3-local/debian:bookworm \
        -f docker/Dockerfile -t "$image" . >/dev/null
    say "build: $(since "$t0") s (cached layers reused)"
fi
size=$(docker image inspect -f '{{.Size}}' "$image")
say "image size: $((size / 1000000)) MB ($image; the runtime base alone: $(($(docker image inspect -f '{{.Size}}' l3-local/debian:bookworm) / 1000000)) MB)"
user=$(docker image inspect -f '{{.Config.User}}' "$image")
healthcheck=$(docker image inspect -f '{{join .Config.Healthcheck.Test " "}}' "$image")
say "image user: $user; health check: $healthcheck"

say "== topology"
dc down -v --remove-orphans >/dev/null 2>&1 || true
dc up -d --no-build postgres 2>&1 | grep -v '^WARNING' || true
t_start=$(now)
dc up -d --no-build l3-a l3-b proxy-host 2>&1 | grep -v '^WARNING' || true
for r in l3-a l3-b; do
    if wait_200 "http://127.0.0.1:${port[$r]}/healthz" 120; then
        say "$r: /healthz 200 $(since "$t_start") s after the start (no table yet: /readyz $(status "http://127.0.0.1:${port[$r]}/readyz"))"
    else
        say "$r never answered /healthz"; docker logs "$(container "$r")" 2>&1 | tail -20
    fi
done

a=$(container l3-a)
ids=$(docker exec "$a" id)
check "runtime user is not root" "$ids (image USER $user)" "$([[ "$ids" == uid=10001\(l3\)* ]] && echo 0 || echo 1)"
addrs=""
for c in $(dc ps -q); do
    addrs+="$(docker inspect -f '{{.Name}} network={{.HostConfig.NetworkMode}} ip=[{{range .NetworkSettings.Networks}}{{.IPAddress}}{{end}}]' "$c") "
done
check "host networking only, no container address" "$addrs" \
    "$([[ "$addrs" != *ip=\[[0-9]* ]] && echo 0 || echo 1)"

say "== a training job through the proxy"
job=$(submit_job '{"illuminants": ["D65", "Tungsten"], "scenes": 4, "scene_size": 48, "levels": 10, "activate": true}')
final=$(wait_job "$proxy" "$job" succeeded 600) || true
runner=$(runner_of "$job")
seen=""
for r in l3-a l3-b; do
    seen+="$r: $(job_field "http://127.0.0.1:${port[$r]}" "$job" status) "
done
check "tiny job $job ran once and is seen by both replicas" "ran on [${runner//$'\n'/ }]; $seen" \
    "$([ "$final" = succeeded ] && [ "$(echo "$runner" | wc -w)" = 1 ] \
        && [ "$seen" = "l3-a: succeeded l3-b: succeeded " ] && echo 0 || echo 1)"
table=$(job_field "$proxy" "$job" table_id)
say "job $job: $(job_field "$proxy" "$job" timings.running_ms) ms of training, table $table"

ok=1
for r in l3-a l3-b; do wait_200 "http://127.0.0.1:${port[$r]}/readyz" 30 || ok=0; done
check "/readyz through the proxy" "$(status "$proxy/readyz") (both replicas ready: $ok)" \
    "$([ "$(status "$proxy/readyz")" = 200 ] && [ $ok = 1 ] && echo 0 || echo 1)"

say "== a render through the proxy"
python3 - "$tmp/mosaic.raw" <<'PY'
import struct, sys
w, h = 64, 48
with open(sys.argv[1], "wb") as f:
    for y in range(h):
        for x in range(w):
            f.write(struct.pack("<H", 2000 + x * 40000 // w + y * 10000 // h))
PY
code=$(curl -s -o "$tmp/render.png" -D "$tmp/render.h" -w '%{http_code}' --max-time 60 \
    -X POST -H 'Content-Type: application/octet-stream' --data-binary @"$tmp/mosaic.raw" \
    "$proxy/v1/render?width=64&height=48&illuminant=D65")
rtable=$(grep -i '^x-l3-table:' "$tmp/render.h" | tr -d '\r' | awk '{print $2}')
magic=$(head -c 8 "$tmp/render.png" | od -An -tx1 | tr -d ' \n')
check "render of a 64 × 48 RGBW mosaic" "HTTP $code, $(stat -c %s "$tmp/render.png") bytes, table $rtable" \
    "$([ "$code" = 200 ] && [ "$magic" = 89504e470d0a1a0a ] && [ "$rtable" = "$table" ] && echo 0 || echo 1)"

say "== an illuminant PUT through the proxy"
code=$(curl -s -o /dev/null -w '%{http_code}' --max-time 10 -X PUT -H 'Content-Type: application/json' \
    "$proxy/v1/illuminants/smoke-3500K" -d '{"cct": 3500}')
seen=""
ok=0
for r in l3-a l3-b; do
    if wait_200 "http://127.0.0.1:${port[$r]}/v1/illuminants/smoke-3500K" 15; then
        seen+="$r: 200 "
    else
        seen+="$r: $(status "http://127.0.0.1:${port[$r]}/v1/illuminants/smoke-3500K") "; ok=1
    fi
done
check "illuminant PUT (HTTP $code) seen by both replicas" "$seen" \
    "$([ "$code" = 201 ] && [ $ok = 0 ] && echo 0 || echo 1)"

say "== start-up"
b=$(container l3-b)
docker stop "$b" >/dev/null
t0=$(now)
docker start "$b" >/dev/null
if wait_200 "http://127.0.0.1:${port[l3-b]}/readyz" 120; then
    startup=$(since "$t0")
    check "start-up (container start to /readyz 200, a table active in the cluster)" "$startup s" 0
else
    check "start-up (container start to /readyz 200)" "never ready" 1
fi

say "== a replica killed while it runs a job"
# long enough (tens of seconds here) that the kill lands while it runs
job=$(submit_job '{"illuminants": ["D65", "Tungsten", "Fluorescent"], "scenes": 32, "scene_size": 96, "levels": 16, "seed": 7}')
deadline=$(($(date +%s) + 120))
runner=""
while [ -z "$runner" ] && [ "$(date +%s)" -lt "$deadline" ]; do
    sleep 0.5
    runner=$(runner_of "$job")
done
if [ -z "$runner" ]; then
    check "kill and restart" "no replica started job $job" 1
else
    sleep 1
    before="$(job_field "$proxy" "$job" status) at $(job_field "$proxy" "$job" progress)"
    victim=$(container "$runner")
    docker kill "$victim" >/dev/null
    say "killed $runner while job $job was $before"
    other=l3-a; [ "$runner" = l3-a ] && other=l3-b
    docker start "$victim" >/dev/null
    final=$(wait_job "http://127.0.0.1:${port[$other]}" "$job" succeeded 900) || true
    attempts=$(job_field "http://127.0.0.1:${port[$other]}" "$job" attempts)
    check "job $job survives its replica's kill and restart" \
        "status before the kill: $before; after: $final, attempts $attempts, ran on [$(runner_of "$job" | tr '\n' ' ')]" \
        "$([[ "$before" == running* ]] && [ "$final" = succeeded ] && [ "$attempts" -ge 2 ] && echo 0 || echo 1)"
fi

say "== health"
health=""
ok=0
for r in l3-a l3-b; do
    c=$(container "$r")
    deadline=$(($(date +%s) + 90))
    while [ "$(docker inspect -f '{{.State.Health.Status}}' "$c")" = starting ] \
        && [ "$(date +%s)" -lt "$deadline" ]; do sleep 1; done
    h=$(docker inspect -f '{{.State.Health.Status}}' "$c")
    health+="$r: $h "
    [ "$h" = healthy ] || ok=1
done
check "Docker health status" "$health" $ok

say "== $passes passed, $failures failed"
[ "$failures" = 0 ]

#!/usr/bin/env python3
"""The on-demand table cache under renders spread over many tables (stdlib only).

Phase 1 starts `l3 serve` on a fresh data directory (it trains its default table), trains
--tables tables through POST /v1/training-jobs, one per catalogue sensor, and renders once
with the first of them to read one table's bytes from /metrics. It stops the server.

Phase 2 starts the server again on the same directory with L3_TABLE_CACHE_BYTES set to hold
--hold tables (and half of one more). It then renders --renders frames with the active table
only, the reference, and --renders frames spread over the trained tables with `?table=ID`
(every table used, a seeded order). After every render it reads l3_table_cache_bytes from
/metrics and the server's VmRSS, and at the end its VmHWM (the kernel's peak RSS). A render
naming a table that does not exist must be 404.

Exits non-zero if a render fails, the cache ever holds more than its bound, or the missing
table is not 404. Prints a markdown summary.

    scripts/table_cache_bench.py --bin target/release/l3
"""

import argparse
import http.client
import json
import os
import random
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time

SENSORS = [
    "rgbw-paper",
    "rgbw-ar0132at",
    "bayer-nikon-d5100",
    "bayer-canon-eos-5d-mark-ii",
    "bayer-sony-ilce-9",
    "bayer-sony-ilce-7m4",
    "bayer-nikon-d850",
    "bayer-canon-eos-r5",
    "bayer-fujifilm-x-t4",
    "bayer-panasonic-dc-gx9",
]


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


class Server:
    def __init__(self, binary, data, env_extra):
        self.port = free_port()
        env = dict(os.environ)
        env.update({"L3_BIND": f"127.0.0.1:{self.port}", "L3_DATA_DIR": data})
        env.update(env_extra)
        self.log = open(os.path.join(data, "server.log"), "ab")
        self.proc = subprocess.Popen([binary, "serve"], env=env, stdout=self.log, stderr=self.log)

    def request(self, method, path, body=None, headers=None):
        c = http.client.HTTPConnection("127.0.0.1", self.port, timeout=600)
        c.request(method, path, body=body, headers=headers or {})
        r = c.getresponse()
        data = r.read()
        out = (r.status, dict(r.getheaders()), data)
        c.close()
        return out

    def wait_ready(self, timeout_s=1800):
        t0 = time.time()
        while time.time() - t0 < timeout_s:
            if self.proc.poll() is not None:
                sys.exit(f"the server exited (code {self.proc.returncode}); see its log")
            try:
                if self.request("GET", "/readyz")[0] == 200:
                    return
            except OSError:
                pass
            time.sleep(0.5)
        sys.exit("the server did not become ready")

    def status(self, key):
        with open(f"/proc/{self.proc.pid}/status") as f:
            for line in f:
                if line.startswith(key + ":"):
                    return int(line.split()[1]) / 1024.0  # MiB
        return float("nan")

    def metric(self, name):
        _, _, text = self.request("GET", "/metrics")
        for line in text.decode().splitlines():
            if line.startswith(name + " "):
                return float(line.split()[1])
        sys.exit(f"no {name} in /metrics")

    def stop(self):
        self.proc.send_signal(signal.SIGTERM)
        self.proc.wait(timeout=120)
        self.log.close()


def gradient_raw(w, h):
    row = struct.pack("<%dH" % w, *[3000 + (x * 40000) // w for x in range(w)])
    return row * h


def train(server, sensors, args):
    jobs = []
    for name in sensors:
        body = json.dumps(
            {
                "sensor": name,
                "illuminants": ["D65"],
                "scenes": args.scenes,
                "scene_size": args.scene_size,
            }
        ).encode()
        st, _, data = server.request(
            "POST", "/v1/training-jobs", body, {"content-type": "application/json"}
        )
        if st not in (200, 201, 202):
            sys.exit(f"training job for {name}: {st} {data[:300]!r}")
        jobs.append((name, json.loads(data)["id"]))
    ids = []
    for name, job in jobs:
        while True:
            _, _, data = server.request("GET", f"/v1/training-jobs/{job}")
            j = json.loads(data)
            if j["status"] == "succeeded":
                ids.append((name, j["table_id"]))
                print(f"  trained {name}: table {j['table_id']}", flush=True)
                break
            if j["status"] in ("failed", "cancelled"):
                sys.exit(f"job {job} for {name}: {j['status']} {j.get('error')}")
            time.sleep(1)
    return ids


def render(server, frame, w, h, table=None):
    q = f"/v1/render?width={w}&height={h}&illuminant=D65"
    if table:
        q += f"&table={table}"
    t0 = time.time()
    st, hdr, data = server.request(
        "POST", q, frame, {"content-type": "application/octet-stream", "accept": "image/png"}
    )
    ms = (time.time() - t0) * 1e3
    hdr = {k.lower(): v for k, v in hdr.items()}
    return st, hdr.get("x-l3-table"), ms, data


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--bin", required=True)
    ap.add_argument("--tables", type=int, default=10)
    ap.add_argument("--renders", type=int, default=64)
    ap.add_argument("--hold", type=int, default=3, help="tables the cache's bound holds")
    ap.add_argument("--width", type=int, default=1024)
    ap.add_argument("--height", type=int, default=1024)
    ap.add_argument("--scenes", type=int, default=8)
    ap.add_argument("--scene-size", type=int, default=64)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--keep", action="store_true", help="keep the data directory")
    args = ap.parse_args()
    if args.tables > len(SENSORS):
        sys.exit(f"--tables: at most {len(SENSORS)}")
    data = tempfile.mkdtemp(prefix="l3-cache-")
    iset = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared", "data", "iset")
    env = {"L3_ISET_DIR": iset} if os.path.isdir(iset) and "L3_ISET_DIR" not in os.environ else {}
    w, h = args.width, args.height
    frame = gradient_raw(w, h)

    print(f"phase 1: data {data}; the default table, then {args.tables} tables", flush=True)
    s = Server(args.bin, data, env)
    s.wait_ready()
    tables = train(s, SENSORS[: args.tables], args)
    st, _, _, _ = render(s, frame, w, h, tables[0][1])
    if st != 200:
        sys.exit(f"render with {tables[0][1]}: {st}")
    one = s.metric("l3_table_cache_bytes")
    s.stop()

    bound = int(args.hold * one + one / 2)
    print(f"phase 2: one table's kernels {one / 2**20:.2f} MiB; bound {bound / 2**20:.2f} MiB ({args.hold}.5 tables)", flush=True)
    env["L3_TABLE_CACHE_BYTES"] = str(bound)
    s = Server(args.bin, data, env)
    s.wait_ready()
    rss_start = s.status("VmRSS")
    ref_ms = []
    for _ in range(args.renders):
        st, _, ms, _ = render(s, frame, w, h)
        if st != 200:
            sys.exit(f"render with the active table: {st}")
        ref_ms.append(ms)
    peak_active = s.status("VmHWM")
    rng = random.Random(args.seed)
    order = [t for _, t in tables] * (args.renders // len(tables) + 1)
    order = order[: args.renders]
    rng.shuffle(order)
    held_max, rss_max, spread_ms, fails = 0.0, 0.0, [], []
    for table in order:
        st, used, ms, _ = render(s, frame, w, h, table)
        if st != 200 or used != table:
            fails.append(f"render with {table}: {st}, x-l3-table {used}")
        spread_ms.append(ms)
        held = s.metric("l3_table_cache_bytes")
        held_max = max(held_max, held)
        if held > bound:
            fails.append(f"the cache holds {held} bytes over its bound {bound}")
        rss_max = max(rss_max, s.status("VmRSS"))
    peak = s.status("VmHWM")
    hits = s.metric("l3_table_cache_hits_total")
    misses = s.metric("l3_table_cache_misses_total")
    evictions = s.metric("l3_table_cache_evictions_total")
    st, _, _, _ = render(s, frame, w, h, "tbl-does-not-exist")
    if st != 404:
        fails.append(f"a missing table: {st}, 404 expected")
    s.stop()
    if not args.keep:
        subprocess.run(["rm", "-rf", data])

    med = lambda v: sorted(v)[len(v) // 2]
    print()
    print(f"| {args.renders} renders of {w}×{h} raw → PNG | median ms | peak RSS (VmHWM) |")
    print("|---|---|---|")
    print(f"| the active table only | {med(ref_ms):.1f} | {peak_active:.0f} MiB |")
    print(f"| spread over {len(tables)} tables (`?table=`) | {med(spread_ms):.1f} | {peak:.0f} MiB |")
    print()
    print(f"- RSS when ready {rss_start:.0f} MiB; largest sampled VmRSS during the spread renders {rss_max:.0f} MiB")
    print(f"- peak RSS added by the spread renders: {peak - peak_active:.0f} MiB; the cache's bound {bound / 2**20:.1f} MiB")
    print(f"- cache: held at most {held_max / 2**20:.2f} MiB; {misses:.0f} misses, {hits:.0f} hits, {evictions:.0f} evictions")
    print(f"- a render naming a missing table: {'404' if not any('missing' in f for f in fails) else 'NOT 404'}")
    if fails:
        print("FAILED:\n  " + "\n  ".join(fails))
        sys.exit(1)


if __name__ == "__main__":
    main()

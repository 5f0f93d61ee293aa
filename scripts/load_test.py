#!/usr/bin/env python3
"""Bounded load test of a running l3 service (stdlib only).

N client threads (default 32) for D seconds (default 60), each on its own keep-alive
connection, mix:
  render_2mp        raw u16 1920x1088 (2.1 MP), PNG / f32 / preview PNG, a few illuminants
  render_small      raw u16 256x256, PNG / f32 / TIFF, named, cct: and xy: illuminants
  evaluation        POST /v1/evaluations (small chart, l3 and baseline)
  job_submit        POST /v1/training-jobs (tiny spec); each client keeps at most one live job
  job_cancel        POST /v1/training-jobs/{id}/cancel of the client's previous job
  get_status        GET healthz, readyz, metrics, tables, jobs, illuminants, evaluations, a job

503 (with Retry-After) is expected backpressure: counted separately, the client waits the
Retry-After. Any other 5xx, a 503 without Retry-After, or a connection error is a failure
(exit 1). Reports per-kind counts by status, p50/p99/max latency of the answered requests,
throughput, and the server's RSS (sampled VmRSS and the kernel's VmHWM peak) given --pid.
"""

import argparse
import http.client
import json
import os
import random
import struct
import sys
import threading
import time
import urllib.parse
from collections import defaultdict

ILLUMINANTS = ["D65", "A", "Tungsten", "F11", "cct:3200", "cct:5000", "xy:0.3457,0.3585"]


def gradient_raw(w, h, seed):
    rnd = random.Random(seed)
    row = [3000 + (x * 40000) // w for x in range(w)]
    out = bytearray()
    for y in range(h):
        off = (y * 7 + rnd.randrange(50)) % 2000
        out += struct.pack("<%dH" % w, *[min(65535, v + off) for v in row])
    return bytes(out)


class Stats:
    def __init__(self):
        self.lock = threading.Lock()
        self.status = defaultdict(lambda: defaultdict(int))  # kind -> status -> n
        self.lat = defaultdict(list)  # kind -> seconds (answered, not 503)
        self.failures = []  # (kind, what)
        self.bytes_in = 0
        self.reconnects = 0  # keep-alive connections found closed, retried once

    def record(self, kind, status, secs, nbytes):
        with self.lock:
            self.status[kind][status] += 1
            if status != 503:
                self.lat[kind].append(secs)
            self.bytes_in += nbytes

    def fail(self, kind, what):
        with self.lock:
            self.failures.append((kind, what))


class Client(threading.Thread):
    def __init__(self, idx, args, stats, bodies, stop_at):
        super().__init__(daemon=True)
        self.idx = idx
        self.args = args
        self.stats = stats
        self.bodies = bodies
        self.stop_at = stop_at
        self.rnd = random.Random(1000 + idx)
        u = urllib.parse.urlparse(args.url)
        self.host, self.port = u.hostname, u.port or 80
        self.conn = None
        self.job = None  # the client's live training job

    def connect(self):
        self.conn = http.client.HTTPConnection(self.host, self.port, timeout=self.args.timeout)

    def request(self, kind, method, path, body=None, headers=None):
        """One request; returns (status, headers, body) or None after a connection failure."""
        hdrs = dict(headers or {})
        if self.args.token:
            hdrs["Authorization"] = "Bearer " + self.args.token
        for attempt in range(2):
            if self.conn is None:
                self.connect()
            t0 = time.perf_counter()
            try:
                self.conn.request(method, path, body=body, headers=hdrs)
                r = self.conn.getresponse()
                data = r.read()
            except (http.client.RemoteDisconnected, BrokenPipeError, ConnectionResetError) as e:
                # a keep-alive connection the server closed between requests: retry once
                self.conn.close()
                self.conn = None
                if attempt == 0:
                    with self.stats.lock:
                        self.stats.reconnects += 1
                    continue
                self.stats.fail(kind, "connection error: %r" % e)
                return None
            except Exception as e:  # timeouts, refused, ...
                self.conn.close()
                self.conn = None
                self.stats.fail(kind, "connection error: %r" % e)
                return None
            secs = time.perf_counter() - t0
            self.stats.record(kind, r.status, secs, len(data))
            if r.status >= 500:
                if r.status != 503:
                    self.stats.fail(kind, "%d %s %s: %s" % (r.status, method, path, data[:300]))
                elif r.getheader("Retry-After") is None:
                    self.stats.fail(kind, "503 without Retry-After on %s %s" % (method, path))
                else:
                    wait = float(r.getheader("Retry-After"))
                    time.sleep(min(wait, max(0.0, self.stop_at - time.time())) * self.rnd.uniform(0.5, 1.0))
            if r.getheader("Connection", "").lower() == "close":
                self.conn.close()
                self.conn = None
            return r.status, r, data
        return None

    def render(self, kind):
        big = kind == "render_2mp"
        body, w, h = self.bodies["big"] if big else self.bodies["small"]
        ill = self.rnd.choice(ILLUMINANTS)
        q = {"width": w, "height": h, "illuminant": ill}
        if big:
            accept = self.rnd.choice(["image/png", "application/octet-stream", "image/png"])
            if self.rnd.random() < 0.3:
                q["preview"] = 4
        else:
            accept = self.rnd.choice(["image/png", "application/octet-stream", "image/tiff"])
            if self.rnd.random() < 0.2:
                q["region"] = "16,16,128,128"
        path = "/v1/render?" + urllib.parse.urlencode(q)
        r = self.request(kind, "POST", path, body,
                         {"Content-Type": "application/octet-stream", "Accept": accept})
        if r and r[0] == 200 and accept == "application/octet-stream":
            ow, oh = int(r[1].getheader("x-l3-width")), int(r[1].getheader("x-l3-height"))
            if len(r[2]) != ow * oh * 12:
                self.stats.fail(kind, "f32 body has %d bytes for %dx%d" % (len(r[2]), ow, oh))

    def evaluation(self):
        body = {
            "method": self.rnd.choice(["l3", "l3", "baseline"]),
            "acquisition_illuminant": self.rnd.choice(["Tungsten", "D65", "A", "cct:4000"]),
            "patch_px": 8,
            "seed": self.rnd.randrange(1000),
            "noise": self.rnd.random() < 0.5,
        }
        self.request("evaluation", "POST", "/v1/evaluations", json.dumps(body).encode(),
                     {"Content-Type": "application/json"})

    def submit_job(self):
        # keep the queue bounded: cancel this client's previous job if it is still live
        if self.job is not None:
            r = self.request("job_cancel", "POST", "/v1/training-jobs/%s/cancel" % self.job, b"")
            self.job = None
            if r and r[0] not in (200, 409):
                self.stats.fail("job_cancel", "cancel answered %d: %s" % (r[0], r[2][:200]))
        body = {
            "illuminants": ["D65", "A"],
            "scenes": 2,
            "scene_size": 32,
            "levels": 6,
            "patch_size": self.rnd.choice([3, 5]),
            "seed": self.rnd.randrange(1 << 30),
        }
        r = self.request("job_submit", "POST", "/v1/training-jobs", json.dumps(body).encode(),
                         {"Content-Type": "application/json",
                          "Idempotency-Key": "load-%d-%d" % (self.idx, self.rnd.randrange(1 << 40))})
        if r and r[0] in (200, 202):
            self.job = json.loads(r[2])["id"]

    def status_get(self):
        paths = ["/healthz", "/readyz", "/metrics", "/v1/tables", "/v1/training-jobs?limit=20",
                 "/v1/illuminants", "/v1/illuminants/D65", "/v1/evaluations"]
        if self.job:
            paths.append("/v1/training-jobs/%s" % self.job)
        self.request("get_status", "GET", self.rnd.choice(paths))

    def run(self):
        mix = self.args.mix
        kinds, weights = zip(*mix.items())
        while time.time() < self.stop_at:
            k = self.rnd.choices(kinds, weights)[0]
            if k in ("render_2mp", "render_small"):
                self.render(k)
            elif k == "evaluation":
                self.evaluation()
            elif k == "job":
                self.submit_job()
            else:
                self.status_get()
        if self.job is not None:
            self.request("job_cancel", "POST", "/v1/training-jobs/%s/cancel" % self.job, b"")


def read_status(pid, key):
    try:
        with open("/proc/%d/status" % pid) as f:
            for line in f:
                if line.startswith(key + ":"):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def pct(xs, p):
    if not xs:
        return float("nan")
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(round(p / 100.0 * (len(xs) - 1))))]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--url", default="http://127.0.0.1:8080")
    ap.add_argument("--clients", type=int, default=32)
    ap.add_argument("--duration", type=float, default=60.0, help="seconds")
    ap.add_argument("--pid", type=int, help="server pid, for its RSS")
    ap.add_argument("--token", default=os.environ.get("L3_BEARER_TOKEN", ""))
    ap.add_argument("--timeout", type=float, default=180.0, help="per-request socket timeout (s)")
    ap.add_argument("--max-rss-mb", type=float, default=0, help="fail when the peak RSS exceeds this")
    ap.add_argument("--json", help="also write the summary as JSON to this file")
    args = ap.parse_args()
    args.mix = {"render_2mp": 10, "render_small": 40, "evaluation": 4, "job": 3, "get": 43}

    bodies = {"big": (gradient_raw(1920, 1088, 1), 1920, 1088),
              "small": (gradient_raw(256, 256, 2), 256, 256)}
    stats = Stats()
    rss = []
    start = time.time()
    stop_at = start + args.duration
    clients = [Client(i, args, stats, bodies, stop_at) for i in range(args.clients)]
    rss0 = read_status(args.pid, "VmRSS") if args.pid else None
    for c in clients:
        c.start()
    while any(c.is_alive() for c in clients):
        if args.pid:
            v = read_status(args.pid, "VmRSS")
            if v is not None:
                rss.append((time.time() - start, v))
        time.sleep(0.5)
    elapsed = time.time() - start

    mb = 1024 * 1024
    total = sum(sum(s.values()) for s in stats.status.values())
    n503 = sum(s.get(503, 0) for s in stats.status.values())
    n5xx = sum(n for s in stats.status.values() for st, n in s.items() if st >= 500 and st != 503)
    summary = {"clients": args.clients, "duration_s": round(elapsed, 1), "requests": total,
               "throughput_rps": round(total / elapsed, 1), "503": n503, "other_5xx": n5xx,
               "connection_errors": sum(1 for _, w in stats.failures if w.startswith("connection")),
               "reconnects": stats.reconnects,
               "received_mb": round(stats.bytes_in / mb, 1), "kinds": {}}
    print("\n%-13s %7s %7s %7s %9s %9s %9s  statuses" % ("kind", "n", "ok", "503", "p50 ms", "p99 ms", "max ms"))
    for kind in sorted(stats.status):
        st = stats.status[kind]
        lat = stats.lat[kind]
        ok = sum(n for s, n in st.items() if 200 <= s < 300)
        row = {"n": sum(st.values()), "ok": ok, "503": st.get(503, 0),
               "p50_ms": round(pct(lat, 50) * 1000, 1), "p99_ms": round(pct(lat, 99) * 1000, 1),
               "max_ms": round(max(lat) * 1000, 1) if lat else None,
               "statuses": {str(k): v for k, v in sorted(st.items())}}
        summary["kinds"][kind] = row
        print("%-13s %7d %7d %7d %9.1f %9.1f %9s  %s" % (kind, row["n"], ok, row["503"], row["p50_ms"],
              row["p99_ms"], row["max_ms"], dict(sorted(st.items()))))
    print("\nrequests %d in %.1f s (%.1f/s), 503 backpressure %d, other 5xx %d, connection errors %d "
          "(keep-alive reconnects retried: %d), received %.1f MB"
          % (total, elapsed, total / elapsed, n503, n5xx, summary["connection_errors"], stats.reconnects,
             summary["received_mb"]))
    if args.pid:
        hwm = read_status(args.pid, "VmHWM")
        peak = max([v for _, v in rss] + [hwm or 0])
        third = [v for t, v in rss if t > elapsed * 2 / 3]
        mid = [v for t, v in rss if elapsed / 3 < t <= elapsed * 2 / 3]
        summary.update({"rss_start_mb": round((rss0 or 0) / mb, 1), "rss_peak_mb": round(peak / mb, 1),
                        "vmhwm_mb": round((hwm or 0) / mb, 1),
                        "rss_mid_third_max_mb": round(max(mid, default=0) / mb, 1),
                        "rss_last_third_max_mb": round(max(third, default=0) / mb, 1),
                        "rss_end_mb": round(rss[-1][1] / mb, 1) if rss else None})
        series, nxt = [], 0.0
        for t, v in rss:
            if t >= nxt:
                series.append([round(t), round(v / mb)])
                nxt = t + max(5.0, elapsed / 24)
        summary["rss_series_s_mb"] = series
        print("server RSS series (s, MB): %s" % " ".join("%d:%d" % (t, v) for t, v in series))
        print("server RSS: start %.1f MB, peak %.1f MB (VmHWM %.1f MB), max in the middle third %.1f MB, "
              "max in the last third %.1f MB, end %s MB" % (
                  summary["rss_start_mb"], summary["rss_peak_mb"], summary["vmhwm_mb"],
                  summary["rss_mid_third_max_mb"], summary["rss_last_third_max_mb"], summary["rss_end_mb"]))
        if args.max_rss_mb and peak / mb > args.max_rss_mb:
            stats.fail("rss", "peak RSS %.1f MB over the %.1f MB bound" % (peak / mb, args.max_rss_mb))
    if args.json:
        summary["failures"] = stats.failures[:50]
        with open(args.json, "w") as f:
            json.dump(summary, f, indent=1)
    if stats.failures:
        print("\nFAILED: %d failure(s); first ones:" % len(stats.failures))
        for k, w in stats.failures[:20]:
            print("  %s: %s" % (k, w))
        sys.exit(1)
    print("PASS: no 5xx other than 503 backpressure, no connection errors")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Throughput and latency of POST /v1/render for one frame in several output formats (stdlib only).

N client threads, each on its own keep-alive connection, POST the same raw u16 frame for
D seconds per format; formats are run one after the other, repeated R rounds, so that each
ratio compares runs of the same server minutes apart. Prints per run: format, clients,
req/s, p50/p99 latency, mean answer bytes, non-2xx; then, per round, each format's req/s
as a ratio of the first format's.

  python3 scripts/encode_bench.py --frame /tmp/frame_2mp.raw --width 1600 --height 1250 \
      --accept image/x-portable-pixmap,image/png,image/jpeg --clients 8 --seconds 15 --rounds 2

The frame (1600×1250 little-endian u16) as in benches/render_http.lua.
"""

import argparse
import http.client
import threading
import time
import urllib.parse


def run(url, body, accept, query, clients, seconds):
    u = urllib.parse.urlparse(url)
    lat, sizes, bad = [], [], [0]
    lock = threading.Lock()
    stop = time.monotonic() + seconds

    def worker():
        conn = http.client.HTTPConnection(u.hostname, u.port or 80, timeout=60)
        while time.monotonic() < stop:
            t0 = time.monotonic()
            conn.request(
                "POST",
                "/v1/render?" + query,
                body=body,
                headers={"Content-Type": "application/octet-stream", "Accept": accept},
            )
            r = conn.getresponse()
            data = r.read()
            dt = time.monotonic() - t0
            with lock:
                if r.status != 200:
                    bad[0] += 1
                else:
                    lat.append(dt)
                    sizes.append(len(data))

    threads = [threading.Thread(target=worker) for _ in range(clients)]
    t0 = time.monotonic()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    wall = time.monotonic() - t0
    lat.sort()
    pct = lambda p: lat[min(len(lat) - 1, int(p * len(lat)))] * 1e3 if lat else float("nan")
    return {
        "accept": accept,
        "rps": len(lat) / wall,
        "p50": pct(0.5),
        "p99": pct(0.99),
        "bytes": sum(sizes) / max(1, len(sizes)),
        "bad": bad[0],
        "n": len(lat),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--url", default="http://127.0.0.1:8080")
    ap.add_argument("--frame", required=True)
    ap.add_argument("--width", type=int, required=True)
    ap.add_argument("--height", type=int, required=True)
    ap.add_argument("--accept", default="image/x-portable-pixmap,image/png,image/jpeg")
    ap.add_argument("--extra", default="", help="more query parameters, e.g. quality=80")
    ap.add_argument("--clients", type=int, default=8)
    ap.add_argument("--seconds", type=float, default=15)
    ap.add_argument("--rounds", type=int, default=1)
    a = ap.parse_args()
    body = open(a.frame, "rb").read()
    query = f"width={a.width}&height={a.height}&illuminant=Tungsten" + (f"&{a.extra}" if a.extra else "")
    # warm up: one request of each format
    for acc in a.accept.split(","):
        run(a.url, body, acc, query, 1, 0.001)
    for rnd in range(a.rounds):
        res = [run(a.url, body, acc, query, a.clients, a.seconds) for acc in a.accept.split(",")]
        for r in res:
            print(
                f"round {rnd + 1} {r['accept']:26} clients {a.clients}: {r['rps']:6.1f} req/s "
                f"p50 {r['p50']:6.1f} ms p99 {r['p99']:6.1f} ms {r['bytes'] / 1e6:7.3f} MB non-2xx {r['bad']} (n={r['n']})"
            )
        base = res[0]["rps"]
        print(
            f"round {rnd + 1} ratios to {res[0]['accept']}: "
            + ", ".join(f"{r['accept']} {r['rps'] / base:.2f}x" for r in res[1:])
        )


if __name__ == "__main__":
    main()

-- wrk script: POST a 2 MP raw mosaic to /v1/render and ask for a PNG.
-- Frame: 1600×1250 little-endian u16, e.g.
--   python3 -c "import array,math,random;random.seed(1);w,h=1600,1250;open('/tmp/frame_2mp.raw','wb').write(array.array('H',[max(0,min(65535,int(8000+6000*math.sin(x/37)*math.cos(y/23)+x*20000//w+random.randint(0,800)))) for y in range(h) for x in range(w)]).tobytes())"
-- Server (release): L3_RENDER_CONCURRENCY=8 target/release/l3 serve
-- Run: L3_FRAME=/tmp/frame_2mp.raw wrk -t1 -c1 -d20s --latency -s benches/render_http.lua http://127.0.0.1:8080
--      L3_FRAME=/tmp/frame_2mp.raw wrk -t2 -c8 -d30s --timeout 10s --latency -s benches/render_http.lua http://127.0.0.1:8080
local f = assert(io.open(os.getenv("L3_FRAME") or "/tmp/frame_2mp.raw", "rb"))
wrk.method = "POST"
wrk.body = f:read("*a")
f:close()
wrk.headers["Content-Type"] = "application/octet-stream"
wrk.headers["Accept"] = "image/png"
wrk.path = "/v1/render?width=1600&height=1250&illuminant=Tungsten"
done = function(summary, latency, requests)
  io.write(string.format("requests %d non-2xx %d p50 %.1f ms p90 %.1f ms p99 %.1f ms max %.1f ms\n",
    summary.requests, summary.errors.status, latency:percentile(50) / 1000,
    latency:percentile(90) / 1000, latency:percentile(99) / 1000, latency.max / 1000))
end

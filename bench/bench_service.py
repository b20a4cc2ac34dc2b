#!/usr/bin/env python3
"""bench_service.py - end-to-end throughput of kdrayd against the core's
in-process rate, measured in the same run. Not a test; bounded to < 1 min.

    bench_service.py KDRAYD KDRAY_TRACE [--scene PATH] [--seconds S]

For bundle batches of 1, 1K and 64K rays, sent and answered in JSON and in
base64, wrk (with a Lua script that POSTs the body) drives the daemon over
loopback for S seconds; the same request file is answered in-process by
kdray-trace with the daemon's traversal modes and thread count (the mean
rate of several runs: on a shared, loaded machine the best run would
flatter the core). The table gives rays/s both ways and their ratio (HTTP
rays/s / in-process rays/s; the gap is parsing, encoding and transport).
The 1-ray round-trip median comes from wrk --latency with one connection
and from a plain keep-alive Python loop.
"""

import argparse
import http.client
import json
import os
import random
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "clients"))
from kdray_client import Client, f32_b64  # noqa: E402

BATCHES = (1, 1024, 65536)
LATENCY_REQUESTS = 400
WRK_LUA = """
wrk.method = "POST"
wrk.headers["Content-Type"] = "application/json"
local f = assert(io.open(os.getenv("KDRAY_BODY"), "rb"))
wrk.body = f:read("*a")
f:close()
"""


def start_daemon(kdrayd, scene, threads):
    args = [kdrayd, "--listen", "127.0.0.1:0", "--threads", str(threads)]
    if scene:
        args += ["--scene", "default=" + scene]
    proc = subprocess.Popen(args, stderr=subprocess.PIPE, text=True)
    url = None
    for line in proc.stderr:
        m = re.search(r"listening on (http://\S+)", line)
        if m:
            url = m.group(1)
        if "ready:" in line or "error" in line:
            break
    if not url:
        raise SystemExit("kdrayd did not start")
    # Keep draining the log so the daemon never blocks on a full pipe.
    threading.Thread(target=lambda: [None for _ in proc.stderr], daemon=True).start()
    return proc, url


def rays(bounds, n, seed):
    rng = random.Random(seed)
    lo, hi = bounds["min"], bounds["max"]
    c = [(a + b) / 2 for a, b in zip(lo, hi)]
    size = max(b - a for a, b in zip(lo, hi)) or 1.0
    origin = [c[0], c[1] + 0.25 * size, c[2] + 1.5 * size]  # a camera-like point
    dirs = []
    for _ in range(n):
        t = [rng.uniform(a, b) for a, b in zip(lo, hi)]
        dirs += [t[i] - origin[i] for i in range(3)]
    return origin, dirs


def request_body(origin, dirs, enc):
    if enc == "base64":
        p = {"origins": f32_b64(origin), "directions": f32_b64(dirs),
             "encoding": "base64"}
    else:
        p = {"origins": origin, "directions": dirs, "encoding": "json"}
    return json.dumps(p).encode()


def wrk_rate(url, body_path, lua_path, seconds, conns, latency=False):
    env = dict(os.environ, KDRAY_BODY=body_path)
    args = ["wrk", "-t", str(min(conns, 2)), "-c", str(conns), "-d", "%ds" % max(1, round(seconds)),
            "-s", lua_path, url]
    if latency:
        args.insert(1, "--latency")
    out = subprocess.run(args, capture_output=True, text=True, env=env,
                         timeout=seconds + 60).stdout
    rps = float(re.search(r"Requests/sec:\s+([\d.]+)", out).group(1))
    bad = re.search(r"Non-2xx or 3xx responses: (\d+)", out)
    if bad:
        raise SystemExit("wrk saw %s error answers:\n%s" % (bad.group(1), out))
    p50 = re.search(r"50%\s+([\d.]+)(us|ms|s)", out)
    if p50:
        scale = {"us": 1e-6, "ms": 1e-3, "s": 1.0}[p50.group(2)]
        return rps, float(p50.group(1)) * scale
    return rps, None


def core_rate(trace, scene, body_path, threads, n):
    repeat = max(3, min(200, 2_000_000 // max(n, 1) // 50))
    args = [trace, "--kind", "bundle", "--mode", "fast", "--threads", str(threads),
            "--repeat", str(repeat), body_path]
    if scene:
        args[1:1] = ["--scene", scene]
    out = subprocess.run(args, capture_output=True, text=True, timeout=300)
    m = re.search(r"mean [\d.]+ ms, ([\d.]+) Mrays/s", out.stderr)
    if not m:
        raise SystemExit("kdray-trace: " + out.stderr)
    return float(m.group(1)) * 1e6


def python_rtt(url, body):
    host, port = url.split("//")[1].split(":")
    conn = http.client.HTTPConnection(host, int(port), timeout=30)
    times = []
    for _ in range(LATENCY_REQUESTS):
        t0 = time.perf_counter()
        conn.request("POST", "/v1/scenes/default/bundle", body,
                     {"Content-Type": "application/json"})
        resp = conn.getresponse()
        resp.read()
        times.append(time.perf_counter() - t0)
        if resp.status != 200:
            raise SystemExit("1-ray request failed: %d" % resp.status)
    conn.close()
    return statistics.median(times)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("kdrayd")
    ap.add_argument("trace")
    ap.add_argument("--scene", help="glTF file (default: the bundled scene)")
    ap.add_argument("--seconds", type=int, default=3, help="per wrk run")
    ap.add_argument("--threads", type=int, default=os.cpu_count() or 1)
    args = ap.parse_args()
    if not shutil.which("wrk"):
        raise SystemExit("wrk is not installed")
    t_start = time.time()
    proc, url = start_daemon(args.kdrayd, args.scene, args.threads)
    tmp = tempfile.mkdtemp(prefix="kdray-bench-")
    try:
        scene = Client(url).scene("default")
        print("kdrayd %s: scene default, %d triangles, %d threads, loopback"
              % (url, scene["triangles"], args.threads))
        lua = os.path.join(tmp, "post.lua")
        with open(lua, "w") as f:
            f.write(WRK_LUA)
        endpoint = url + "/v1/scenes/default/bundle"
        print("%-8s %-7s %10s %12s %14s %14s %7s" % (
            "rays", "enc", "body KiB", "HTTP req/s", "HTTP rays/s", "core rays/s",
            "ratio"))
        one_ray_body = None
        for n in BATCHES:
            origin, dirs = rays(scene["bounds"], n, seed=n)
            for enc in ("json", "base64"):
                body = request_body(origin, dirs, enc)
                path = os.path.join(tmp, "req-%d-%s.json" % (n, enc))
                with open(path, "wb") as f:
                    f.write(body)
                if n == 1 and enc == "json":
                    one_ray_body = (body, path)
                conns = 4 if n < 65536 else 2
                rps, _ = wrk_rate(endpoint, path, lua, args.seconds, conns)
                core = core_rate(args.trace, args.scene, path, args.threads, n)
                print("%-8d %-7s %10.1f %12.1f %14.3e %14.3e %7.3f" % (
                    n, enc, len(body) / 1024, rps, rps * n, core, rps * n / core),
                    flush=True)
        _, p50 = wrk_rate(endpoint, one_ray_body[1], lua, args.seconds, 1, True)
        py = python_rtt(url, one_ray_body[0])
        print("1-ray round trip, median: wrk 1 connection %.1f us, Python "
              "http.client keep-alive %.1f us" % (p50 * 1e6, py * 1e6))
    finally:
        proc.terminate()
        proc.wait(60)
        shutil.rmtree(tmp)
    print("bench_service: %.1f s" % (time.time() - t_start))


if __name__ == "__main__":
    main()

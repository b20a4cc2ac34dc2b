#!/usr/bin/env python3
"""bench_service.py - end-to-end throughput of kdrayd against the core's
in-process rate, measured in the same run. Not a test; bounded to < 1 min.

    bench_service.py KDRAYD KDRAY_TRACE [--scene PATH] [--seconds S]

For bundle batches of 1, 1K and 64K rays, sent and answered in JSON, in
base64 and in CBOR (application/cbor, float32 typed arrays), wrk (with a Lua script that POSTs the body) drives the daemon over
loopback for S seconds; the same request file is answered in-process by
kdray-trace with the daemon's traversal modes and thread count (the mean
rate of several runs: on a shared, loaded machine the best run would
flatter the core). The table gives rays/s both ways and their ratio (HTTP
rays/s / in-process rays/s; the gap is parsing, encoding and transport).
The 1-ray round-trip median comes from wrk --latency with one connection
and from a plain keep-alive Python loop.

    bench_service.py KDRAYD KDRAY_TRACE --large N [--large-only] [--large-repeat R]

adds (by default, N = 1M) one row per query kind and encoding for N-ray
requests (issue 16): bundle closest and any, cone-shadow (N / 64 points,
64 samples, one light), frustum closest and any (sqrt(N) x sqrt(N)), and a
"transport only" bundle whose rays all have tmin > tmax (nothing to trace),
each in JSON numbers, base64 and CBOR. Each is POSTed R times (keep-alive
http.client; best kept) and run R times in-process by kdray-trace (the same
file through the same executor, tracing time only; best kept); the row
gives both, their ratio, and kdrayd's own split of the best POST from its
Server-Timing header (body arrival, queue + parse, trace, encode; rest =
the answer's transfer). "tr+codec" = 1 - trace / HTTP time: the share of
that one request spent on transport and codecs, which neighbours' load
cannot skew the way it skews two runs at different moments. 0 skips them.

    bench_service.py KDRAYD KDRAY_TRACE --stream-only [--large N] [--large-repeat R]

gives the large requests in CBOR only, answered in one piece and streamed
(Accept: application/cbor-seq: chunk items sent while later chunks trace),
each in a fresh kdrayd: time to the answer's first data, total time,
kdrayd's trace time and the transport + codecs share, and kdrayd's peak RSS
growth (VmHWM over VmRSS before the requests). Needs python3-cbor2.

    bench_service.py KDRAYD KDRAY_TRACE --soak 60 [--soak-only]

adds a soak run (the issue's "zero errors and no growth in memory under a
60-second wrk run"): wrk on 127.0.0.1 for 60 s, its Lua script cycling
bundle (JSON and base64, closest and any), cone-shadow and frustum bodies;
kdrayd's VmRSS and open descriptors are sampled every second. It prints wrk's
non-2xx answers and socket errors (both must be 0), RSS after the warm-up
(5 s), half-way and at the end, and checks that the /metrics request
counters grew by wrk's request count (plus at most the requests still in
flight when wrk stopped) and that kdrayd logged nothing (it logs only
errors). Exit status 1 if any check fails.
"""

import argparse
import http.client
import json
import os
import random
import re
import shutil
import statistics
import struct
import subprocess
import sys
import tempfile
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "clients"))
from kdray_client import Client, f32_b64  # noqa: E402

BATCHES = (1, 1024, 65536)
SERVER_CHUNK_RAYS = 4096  # exec/kdr_exec.h KDR_EXEC_CHUNK_RAYS: rays per chunk
LATENCY_REQUESTS = 400
WRK_LUA = """
wrk.method = "POST"
wrk.headers["Content-Type"] = os.getenv("KDRAY_CT") or "application/json"
local f = assert(io.open(os.getenv("KDRAY_BODY"), "rb"))
wrk.body = f:read("*a")
f:close()
"""


SOAK_WARMUP_S = 5       # RSS reference point: caches, arenas, pools are warm
SOAK_CONNS = 4
SOAK_RSS_SLACK_KIB = 1024  # end - half-way RSS allowed (allocator noise)
SOAK_LUA = """
-- Cycles the bodies listed in KDRAY_SOAK (lines "PATH BODYFILE"); each wrk
-- thread starts at a different offset so every kind is always in flight.
local reqs = {}
local i = 0
function init(args)
  for line in io.lines(os.getenv("KDRAY_SOAK")) do
    local path, file = line:match("^(%S+) (%S+)$")
    local f = assert(io.open(file, "rb"))
    local body = f:read("*a")
    f:close()
    reqs[#reqs + 1] = wrk.format("POST", path,
      {["Content-Type"] = "application/json"}, body)
  end
  i = math.random(#reqs)
end
function request()
  i = i % #reqs + 1
  return reqs[i]
end
"""


def start_daemon(kdrayd, scene, threads):
    # A 1M-ray bundle in JSON numbers is ~40 MB. Workers at the HTTP threads'
    # priority (--worker-nice 0): kdray-trace, the in-process side, runs at
    # nice 0 too, and on a shared machine niced workers lose the CPU to the
    # neighbours.
    args = [kdrayd, "--listen", "127.0.0.1:0", "--threads", str(threads),
            "--max-body-mb", "256", "--worker-nice", "0"]
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
    # Keep draining the log so the daemon never blocks on a full pipe; the
    # soak counts what it logs (only errors and libmicrohttpd complaints).
    proc.log = []
    threading.Thread(target=lambda: [proc.log.append(l) for l in proc.stderr],
                     daemon=True).start()
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


def _cbor_head(major, n):
    if n < 24:
        return bytes([major << 5 | n])
    for code, size in ((24, 1), (25, 2), (26, 4), (27, 8)):
        if n < 1 << (8 * size):
            return bytes([major << 5 | code]) + n.to_bytes(size, "big")
    raise ValueError(n)


class F32(list):
    """A float array to send as an RFC 8746 float32 typed array (tag 85)."""


def _cbor_item(v, out):
    if isinstance(v, dict):
        _cbor_map(v, out)
    elif isinstance(v, F32):
        data = struct.pack("<%df" % len(v), *v)
        out += b"\xd8\x55" + _cbor_head(2, len(data)) + data
    elif isinstance(v, (list, tuple)):
        out += _cbor_head(4, len(v))
        for x in v:
            _cbor_item(x, out)
    elif isinstance(v, bool):
        out.append(0xf5 if v else 0xf4)
    elif isinstance(v, int):
        out += _cbor_head(0, v) if v >= 0 else _cbor_head(1, -1 - v)
    elif isinstance(v, float):
        out += b"\xfb" + struct.pack(">d", v)
    elif isinstance(v, str):
        out += _cbor_head(3, len(v.encode())) + v.encode()
    else:
        raise TypeError(type(v))


def _cbor_map(d, out):
    """An indefinite-length map, so that a padding member ("_p": "x..."; kdrayd
    ignores unknown members) can go before any typed array whose float32
    bytes would not start at a multiple of 4: kdrayd then reads it in place."""
    out.append(0xbf)
    for k, v in d.items():
        key = bytearray()
        _cbor_item(k, key)
        if isinstance(v, F32):
            at = len(out) + len(key) + 2 + len(_cbor_head(2, 4 * len(v)))
            if at % 4:
                out += b"\x62_p" + _cbor_head(3, 4 - at % 4) + b"x" * (4 - at % 4)
        out += key
        _cbor_item(v, out)
    out.append(0xff)


def cbor_body(payload):
    """payload (a dict; F32 values become typed arrays) as a CBOR body, by hand:
    this script runs without python3-cbor2."""
    out = bytearray()
    _cbor_map(payload, out)
    return bytes(out)


def cbor_request_body(origin, dirs):
    return cbor_body({"origins": F32(origin), "directions": F32(dirs)})


def wrk_rate(url, body_path, lua_path, seconds, conns, latency=False):
    ctype = "application/cbor" if body_path.endswith(".cbor") else "application/json"
    env = dict(os.environ, KDRAY_BODY=body_path, KDRAY_CT=ctype)
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
    # the answer on stdout is binary for CBOR requests: only stderr is text
    out = subprocess.run(args, capture_output=True, timeout=300)
    err = out.stderr.decode("utf-8", "replace")
    m = re.search(r"mean [\d.]+ ms, ([\d.]+) Mrays/s", err)
    if not m:
        raise SystemExit("kdray-trace: " + err)
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


def soak_bodies(bounds):
    """(path suffix, payload) pairs covering every query kind and both
    encodings; one 64K-ray batch for the large-buffer paths, the rest small
    enough that wrk completes thousands of each."""
    lo, hi = bounds["min"], bounds["max"]
    size = max(b - a for a, b in zip(lo, hi)) or 1.0
    c = [(a + b) / 2 for a, b in zip(lo, hi)]
    origin, dirs = rays(bounds, 65536, seed=7)
    rng = random.Random(11)
    pts = [rng.uniform(lo[k % 3], hi[k % 3]) for k in range(3 * 64)]
    nrm = [0.0, 1.0, 0.0] * 64
    light = {"center": [c[0], hi[1] + size, c[2]], "radius": 0.1 * size}
    light2 = {"center": [hi[0] + size, c[1], c[2]], "radius": 0.05 * size}
    origins = [origin[k % 3] for k in range(3 * 1024)]
    cam = {"eye": origin, "target": c, "up": [0, 1, 0], "fov_y_deg": 60}
    return [
        ("bundle", {"origins": origin, "directions": dirs[:3 * 1024]}),
        ("bundle", {"origins": f32_b64(origin), "directions": f32_b64(dirs[:3 * 4096]),
                    "encoding": "base64"}),
        ("bundle", {"origins": f32_b64(origin), "directions": f32_b64(dirs),
                    "encoding": "base64"}),
        ("bundle", {"origins": f32_b64(origins), "directions": f32_b64(dirs[:3 * 1024]),
                    "tmax": f32_b64([0.5] * 1024), "query": "any",
                    "encoding": "base64"}),
        ("bundle", {"origins": origin, "directions": dirs[:3]}),
        ("cone-shadow", {"points": pts, "normals": nrm, "lights": [light, light2],
                         "samples": 16, "seed": 3, "stats": True}),
        ("cone-shadow", {"points": f32_b64(pts), "lights": [light], "samples": 64,
                         "encoding": "base64"}),
        ("frustum", {"camera": dict(cam, width=128, height=96), "tile": 8,
                     "encoding": "base64"}),
        ("frustum", {"camera": dict(cam, width=32, height=32), "tile": 16,
                     "query": "any", "encoding": "json"}),
    ]


def scrape(url):
    """(requests answered on the query endpoints, error answers) from /metrics."""
    text = Client(url).metrics()
    total = errors = 0
    for m in re.finditer(r'^kdray_http_(requests|errors)_total\{endpoint="([^"]+)"'
                         r',status="\d+"\} (\d+)$', text, re.M):
        if m.group(2) in ("bundle", "cone-shadow", "frustum"):
            if m.group(1) == "requests":
                total += int(m.group(3))
            else:
                errors += int(m.group(3))
    return total, errors


def proc_sample(pid):
    """(VmRSS KiB, open descriptors) of a process."""
    with open("/proc/%d/status" % pid) as f:
        rss = int(re.search(r"^VmRSS:\s+(\d+) kB", f.read(), re.M).group(1))
    return rss, len(os.listdir("/proc/%d/fd" % pid))


def soak(url, proc, bounds, seconds, tmp):
    manifest = os.path.join(tmp, "soak.txt")
    with open(manifest, "w") as m:
        for k, (ep, payload) in enumerate(soak_bodies(bounds)):
            body = os.path.join(tmp, "soak-%d.json" % k)
            with open(body, "w") as f:
                json.dump(payload, f)
            m.write("/v1/scenes/default/%s %s\n" % (ep, body))
            status, _, _ = Client(url).request("POST", "/v1/scenes/default/" + ep,
                                            json.dumps(payload).encode())
            if status != 200:
                raise SystemExit("soak body %d (%s) answered %d" % (k, ep, status))
    lua = os.path.join(tmp, "soak.lua")
    with open(lua, "w") as f:
        f.write(SOAK_LUA)
    before, err_before = scrape(url)
    log_before = len(proc.log)
    samples, stop = [], threading.Event()

    def sampler():
        t0 = time.monotonic()
        while not stop.wait(max(0.0, len(samples) + 1 - (time.monotonic() - t0))):
            samples.append((time.monotonic() - t0,) + proc_sample(proc.pid))
    th = threading.Thread(target=sampler, daemon=True)
    th.start()
    args = ["wrk", "-t", "2", "-c", str(SOAK_CONNS), "-d", "%ds" % seconds,
            "--timeout", "10s", "-s", lua, url]
    out = subprocess.run(args, capture_output=True, text=True, timeout=seconds + 60,
                         env=dict(os.environ, KDRAY_SOAK=manifest)).stdout
    stop.set()
    th.join()
    after = scrape(url)
    logged = proc.log[log_before:]
    return soak_report(out, samples, seconds, before, err_before, after, logged)


def rss_at(samples, t):
    return min(samples, key=lambda s: abs(s[0] - t))


def soak_report(out, samples, seconds, before, err_before, after, logged):
    reqs = int(re.search(r"(\d+) requests in", out).group(1))
    bad = re.search(r"Non-2xx or 3xx responses: (\d+)", out)
    non2xx = int(bad.group(1)) if bad else 0
    sock = re.search(r"Socket errors: connect (\d+), read (\d+), write (\d+), "
                     r"timeout (\d+)", out)
    sockerr = sum(map(int, sock.groups())) if sock else 0
    served, errors = after[0] - before, after[1] - err_before
    warm, half, end = (rss_at(samples, seconds * f) for f in
                       (SOAK_WARMUP_S / seconds, 0.5, 1.0))
    peak = max(s[1] for s in samples)
    print("soak %d s, %d connections, 9 bodies (bundle 1 and 1K json, 4K and "
          "64K base64, 1K any; cone-shadow json/base64; frustum base64/json):"
          % (seconds, SOAK_CONNS))
    print("  wrk: %d requests (%.1f req/s), non-2xx %d, socket errors %d%s" % (
        reqs, reqs / seconds, non2xx, sockerr,
        " (%s)" % sock.group(0) if sock else ""))
    print("  /metrics: %d query requests answered (wrk saw %d; up to %d may "
          "finish after wrk stops), %d error answers" % (served, reqs, SOAK_CONNS,
                                                         errors))
    print("  kdrayd VmRSS: %.1f MiB at %.0f s, %.1f MiB at %.0f s, %.1f MiB at "
          "%.0f s (end); growth %+d KiB since warm-up, %+d KiB over the second "
          "half; peak %.1f MiB; open fds %d -> %d" % (
              warm[1] / 1024, warm[0], half[1] / 1024, half[0], end[1] / 1024,
              end[0], end[1] - warm[1], end[1] - half[1], peak / 1024, warm[2],
              end[2]))
    print("  kdrayd log lines during the soak: %d%s" % (
        len(logged), "".join("\n    " + l.rstrip() for l in logged[:5])))
    ok = (non2xx == 0 and sockerr == 0 and errors == 0 and not logged
          and 0 <= served - reqs <= SOAK_CONNS and end[2] <= warm[2]
          and end[1] - half[1] <= SOAK_RSS_SLACK_KIB)
    print("  soak: %s" % ("PASS" if ok else "FAIL"))
    if not ok:
        print(out)
    return ok


def throughput_table(args, url, scene, tmp):
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
        for enc in ("json", "base64", "cbor"):
            if enc == "cbor":  # the same rays; kdray-trace reads .cbor as CBOR
                body = cbor_request_body(origin, dirs)
                path = os.path.join(tmp, "req-%d.cbor" % n)
            else:
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
    print("(batches under %d rays are one chunk: in-process they run on one "
          "thread, while wrk's %d connections keep all %d HTTP threads busy, so "
          "their ratio can exceed 1)" % (SERVER_CHUNK_RAYS, 4, args.threads))
    _, p50 = wrk_rate(endpoint, one_ray_body[1], lua, args.seconds, 1, True)
    py = python_rtt(url, one_ray_body[0])
    print("1-ray round trip, median: wrk 1 connection %.1f us, Python "
          "http.client keep-alive %.1f us" % (p50 * 1e6, py * 1e6))


# ---- 1M-ray rows (issue 16) --------------------------------------------------

LARGE_SIDE = 1024           # frustum image LARGE_SIDE^2 pixels
LARGE_SHADOW_SAMPLES = 64   # cone-shadow: rays / 64 points, one light


def _json_f32(vals):
    """JSON numbers as a client holding float32 data prints them ("%.9g"
    round-trips every float32)."""
    return "[" + ",".join("%.9g" % v for v in vals) + "]"


def large_payloads(bounds, n):
    """(label, endpoint, kind, payload) for every query kind at n rays;
    float arrays as F32 (CBOR typed arrays, base64, or JSON numbers)."""
    lo, hi = bounds["min"], bounds["max"]
    size = max(b - a for a, b in zip(lo, hi)) or 1.0
    c = [(a + b) / 2 for a, b in zip(lo, hi)]
    origin, dirs = rays(bounds, n, seed=n)
    dirs = F32(struct.unpack("<%df" % len(dirs), struct.pack("<%df" % len(dirs), *dirs)))
    rng = random.Random(5)
    npts = n // LARGE_SHADOW_SAMPLES
    pts = F32(struct.unpack("<%df" % (3 * npts), struct.pack(
        "<%df" % (3 * npts), *(rng.uniform(lo[k % 3], hi[k % 3]) for k in range(3 * npts)))))
    light = {"center": [c[0], hi[1] + size, c[2]], "radius": 0.05 * size}
    side = int(round(n ** 0.5))
    cam = {"eye": origin, "target": c, "up": [0.0, 1.0, 0.0], "fov_y_deg": 60.0,
           "width": side, "height": side}
    bundle = {"origins": F32(origin), "directions": dirs}
    return [
        ("bundle closest", "bundle", "bundle", dict(bundle)),
        ("bundle any", "bundle", "bundle", dict(bundle, query="any")),
        ("cone-shadow", "cone-shadow", "cone-shadow",
         {"points": pts, "lights": [light], "samples": LARGE_SHADOW_SAMPLES}),
        ("frustum closest", "frustum", "frustum", {"camera": cam, "tile": 8}),
        ("frustum any", "frustum", "frustum", {"camera": cam, "tile": 8, "query": "any"}),
        ("transport only", "bundle", "bundle", dict(bundle, tmin=1.0, tmax=0.0)),
    ]


def encode_payload(payload, enc):
    """The body bytes and file suffix of a payload in one encoding."""
    if enc == "cbor":
        return cbor_body(payload), ".cbor"
    parts = []
    for k, v in payload.items():
        if isinstance(v, F32):
            v = json.dumps(f32_b64(v)) if enc == "base64" else _json_f32(v)
        else:
            v = json.dumps(v)
        parts.append("%s:%s" % (json.dumps(k), v))
    if enc == "base64":
        parts.append('"encoding":"base64"')
    return ("{" + ",".join(parts) + "}").encode(), ".json"


def timed_post(conn, path, body, ctype):
    """One POST on a keep-alive http.client connection, timed from the
    request's first byte to the answer's last: (status, seconds, answer
    bytes, kdrayd's Server-Timing as {step: ms}). http.client sends the body
    with one sendall and reads a Content-Length answer with one read: both
    memcpy-speed next to kdrayd's work."""
    t0 = time.perf_counter()
    conn.request("POST", path, body, {"Content-Type": ctype, "Accept": ctype})
    resp = conn.getresponse()
    data = resp.read()
    dt = time.perf_counter() - t0
    timing = dict((m.group(1), float(m.group(2))) for m in re.finditer(
        r"(\w+);dur=([\d.]+)", resp.getheader("Server-Timing") or ""))
    return resp.status, dt, len(data), timing


def trace_best_ms(args, kind, path, repeat):
    cmd = [args.trace, "--kind", kind, "--mode", "fast", "--threads", str(args.threads),
           "--repeat", str(repeat), path]
    if args.scene:
        cmd[1:1] = ["--scene", args.scene]
    out = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                         text=True, timeout=600)
    m = re.search(r"best ([\d.]+) ms", out.stderr)
    if not m:
        raise SystemExit("kdray-trace: " + out.stderr)
    return float(m.group(1))


def large_table(args, url, scene, tmp):
    """Each request: R curl POSTs and R in-process runs (kdray-trace, the same
    request file through the same executor, tracing time only); best of
    each. ratio = in-process ms / HTTP ms (the request's rate over HTTP
    against in-process). kdrayd's Server-Timing header of the best POST
    splits its time: body (arrival), parse (queue + parse), trace, encode;
    rest = the answer's transfer and what no step covers; "tr+codec" = 1 -
    trace / HTTP ms, the share of the request's time that is transport and
    codecs, measured within that one request (robust to the neighbours'
    load, unlike the ratio, whose two sides run at different moments)."""
    n, reps = args.large, args.large_repeat
    print("\n%d-ray requests, %d worker threads, best of %d (Python http.client, "
          "keep-alive, loopback, one request at a time; in-process: kdray-trace --repeat %d, tracing only)"
          % (n, args.threads, reps, max(reps, 3)))
    print("%-15s %-6s %8s %8s %8s %6s %6s %6s %6s %6s %6s %8s %6s %8s" % (
        "request", "enc", "body MiB", "ans MiB", "HTTP ms", "MiB/s", "body", "parse",
        "trace", "encode", "rest", "in-proc", "ratio", "tr+codec"))
    host, port = url.split("//")[1].split(":")
    conn = http.client.HTTPConnection(host, int(port), timeout=600)
    for label, ep, kind, payload in large_payloads(scene["bounds"], n):
        for enc in ("json", "base64", "cbor"):
            body, suffix = encode_payload(payload, enc)
            path = os.path.join(tmp, "large%s" % suffix)
            with open(path, "wb") as f:
                f.write(body)
            ctype = "application/cbor" if enc == "cbor" else "application/json"
            best = None
            for _ in range(reps):
                st, total, nbytes, timing = timed_post(conn, "/v1/scenes/default/" + ep,
                                                       body, ctype)
                if st != 200:
                    raise SystemExit("%s %s: HTTP %d" % (label, enc, st))
                if best is None or total < best[0]:
                    best = (total, nbytes, timing)
            core = trace_best_ms(args, kind, path, max(reps, 3))
            http_ms = best[0] * 1e3
            steps = [best[2].get(k, float("nan")) for k in
                     ("body", "queue", "parse", "trace", "encode")]
            print("%-15s %-6s %8.2f %8.2f %8.1f %6.0f %6.1f %6.1f %6.1f %6.1f %6.1f %8.1f "
                  "%6.3f %7.0f%%" % (
                      label, enc, len(body) / 2**20, best[1] / 2**20, http_ms,
                      (len(body) + best[1]) / 2**20 / best[0], steps[0],
                      steps[1] + steps[2], steps[3], steps[4], http_ms - sum(steps), core,
                      core / http_ms, 100 * (1 - steps[3] / http_ms)), flush=True)
            os.unlink(path)
    conn.close()


def _vm(pid, key):
    """A /proc/PID/status line's value in MiB (VmRSS, VmHWM)."""
    with open("/proc/%d/status" % pid) as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def _cpu_ms(pid):
    """CPU time of every thread of pid so far, ms (schedstat: ns)."""
    total = 0
    for tid in os.listdir("/proc/%d/task" % pid):
        try:
            with open("/proc/%d/task/%s/schedstat" % (pid, tid)) as f:
                total += int(f.read().split()[0])
        except OSError:
            pass  # a thread that just ended
    return total / 1e6


def _post_streamed(conn, path, body, cbor2):
    """One CBOR POST asking for a streamed answer (application/cbor-seq):
    (status, seconds to the first chunk item, total seconds, answer bytes,
    trace ms from the final item's timing). Items are decoded as they come
    (typed arrays stay bytes), as a client consuming them would."""
    t0 = time.perf_counter()
    conn.request("POST", path, body, {"Content-Type": "application/cbor",
                                      "Accept": "application/cbor-seq"})
    resp = conn.getresponse()
    if resp.status != 200:
        resp.read()
        return resp.status, 0, 0, 0, 0
    counted = _Counting(resp)
    dec = cbor2.CBORDecoder(counted)
    first, final = None, None
    head = dec.decode()
    for _ in range(head["items"]):
        dec.decode()
        if first is None:
            first = time.perf_counter() - t0
    final = dec.decode()
    total = time.perf_counter() - t0
    if resp.read(1):
        raise SystemExit("streamed answer: bytes after the final item")
    if final.get("status") != 200:
        raise SystemExit("streamed answer failed: %r" % final)
    return 200, first if first is not None else total, total, counted.n, \
        final["timing"]["trace_us"] / 1e3


class _Counting:
    """A file-like that counts the bytes read through it."""

    def __init__(self, fp):
        self.fp, self.n = fp, 0

    def read(self, k=-1):
        b = self.fp.read(k)
        self.n += len(b)
        return b


def stream_table(args, scene):
    """Each large request in CBOR, answered in one piece (application/cbor)
    and streamed (application/cbor-seq), each in a fresh kdrayd so that its
    peak RSS is its own: first = time to the answer's first data (one piece:
    its headers, sent with the finished answer; streamed: the first chunk
    item), total = to the last byte, trace from kdrayd (Server-Timing, or
    the final item's timing), tr+codec = 1 - trace / total, cpu = kdrayd's
    CPU time for that request, all threads (on a shared box wall times move
    with the neighbours' load; CPU time does not), peak = VmHWM - VmRSS
    before the requests (MiB)."""
    import cbor2  # Debian python3-cbor2; only this table needs it
    n, reps = args.large, args.large_repeat
    print("\n%d-ray requests in CBOR, one piece vs streamed (Accept: application/"
          "cbor-seq), %d worker threads, best of %d, fresh kdrayd per row"
          % (n, args.threads, reps))
    print("%-15s %-8s %8s %8s %8s %8s %8s %8s %8s" % (
        "request", "answer", "ans MiB", "first ms", "total ms", "trace ms", "tr+codec",
        "cpu ms", "peak MiB"))
    for label, ep, kind, payload in large_payloads(scene["bounds"], n):
        body = cbor_body(payload)
        for mode in ("one-piece", "streamed"):
            proc, url = start_daemon(args.kdrayd, args.scene, args.threads)
            try:
                base = _vm(proc.pid, "VmRSS")
                host, port = url.split("//")[1].split(":")
                conn = http.client.HTTPConnection(host, int(port), timeout=600)
                best = None
                path = "/v1/scenes/default/" + ep
                for _ in range(reps):
                    cpu0 = _cpu_ms(proc.pid)
                    if mode == "streamed":
                        st, first, total, nbytes, trace = _post_streamed(
                            conn, path, body, cbor2)
                    else:
                        t0 = time.perf_counter()
                        conn.request("POST", path, body,
                                     {"Content-Type": "application/cbor",
                                      "Accept": "application/cbor"})
                        resp = conn.getresponse()
                        first = time.perf_counter() - t0
                        data = resp.read()
                        total = time.perf_counter() - t0
                        st, nbytes = resp.status, len(data)
                        m = re.search(r"trace;dur=([\d.]+)",
                                      resp.getheader("Server-Timing") or "")
                        trace = float(m.group(1)) if m else float("nan")
                    if st != 200:
                        raise SystemExit("%s %s: HTTP %d" % (label, mode, st))
                    cpu = _cpu_ms(proc.pid) - cpu0
                    if best is None or total < best[1]:
                        best = (first, total, nbytes, trace, cpu)
                peak = _vm(proc.pid, "VmHWM") - base
                conn.close()
            finally:
                proc.terminate()
                proc.wait(60)
            first, total, nbytes, trace, cpu = best
            print("%-15s %-8s %8.2f %8.1f %8.1f %8.1f %7.0f%% %8.1f %8.1f" % (
                label, mode, nbytes / 2**20, first * 1e3, total * 1e3, trace,
                100 * (1 - trace / (total * 1e3)), cpu, peak), flush=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("kdrayd")
    ap.add_argument("trace")
    ap.add_argument("--scene", help="glTF file (default: the bundled scene)")
    ap.add_argument("--seconds", type=int, default=3, help="per wrk run")
    ap.add_argument("--threads", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--soak", type=int, default=0, metavar="S",
                    help="also run the S-second mixed-query soak (issue: 60)")
    ap.add_argument("--soak-only", action="store_true",
                    help="skip the throughput table, the round trip and the large rows")
    ap.add_argument("--large", type=int, default=1048576, metavar="N",
                    help="rays of the large-request rows (0: none; issue 16: 1M)")
    ap.add_argument("--large-only", action="store_true",
                    help="only the large-request rows")
    ap.add_argument("--large-repeat", type=int, default=3, metavar="R",
                    help="requests per large row, best kept")
    ap.add_argument("--stream-only", action="store_true",
                    help="only the large requests in CBOR, one piece vs streamed "
                    "(application/cbor-seq), with time to first data and peak RSS")
    args = ap.parse_args()
    if not shutil.which("wrk"):
        raise SystemExit("wrk is not installed")
    t_start = time.time()
    if args.stream_only:
        proc, url = start_daemon(args.kdrayd, args.scene, args.threads)
        try:
            scene = Client(url).scene("default")
        finally:
            proc.terminate()
            proc.wait(60)
        print("kdrayd: scene default, %d triangles, %d threads, loopback"
              % (scene["triangles"], args.threads))
        stream_table(args, scene)
        print("bench_service: %.1f s" % (time.time() - t_start))
        return
    proc, url = start_daemon(args.kdrayd, args.scene, args.threads)
    tmp = tempfile.mkdtemp(prefix="kdray-bench-")
    try:
        scene = Client(url).scene("default")
        print("kdrayd %s: scene default, %d triangles, %d threads, loopback"
              % (url, scene["triangles"], args.threads))
        ok = True
        if not args.soak_only and not args.large_only:
            throughput_table(args, url, scene, tmp)
        if args.large and not args.soak_only:
            large_table(args, url, scene, tmp)
        if args.soak:
            ok = soak(url, proc, scene["bounds"], args.soak, tmp)
    finally:
        proc.terminate()
        proc.wait(60)
        shutil.rmtree(tmp)
    print("bench_service: %.1f s" % (time.time() - t_start))
    if not ok:
        sys.exit(1)


if __name__ == "__main__":
    main()

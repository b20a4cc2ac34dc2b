#!/usr/bin/env python3
"""cluster_bench.py - kdrayd behind HAProxy (deploy/haproxy/kdray.cfg) on
this machine's loopback: a measurement, not a test (~1 min).

    bench/cluster_bench.py [KDRAYD] [SCENE.glb] [SECONDS] [PARTS]

PARTS: a comma list of throughput, overload, hangup (default: all).

Defaults: build/server/kdrayd, scenes/default.glb, 5 s per wrk run.
Prints, with 64K-ray bundles sent and answered in base64 (wrk, 1 thread,
4 connections, runs interleaved and repeated twice, the mean reported):
  direct   1 replica x 2 worker threads, no balancer
  lb 1x2   the same replica through HAProxy (balancer overhead = 1 -
           lb 1x2 / direct; the issue's target: <= 10%)
  lb 2x1   2 replicas x 1 worker thread through HAProxy (the same 2 cores)
Each line also gives the CPU (user + system, from /proc and wrk's rusage)
that kdrayd, HAProxy and wrk spent per 200 answer and the cores each used:
the client's cost is the same in both modes, so the difference in the
replicas' cores is what the balancer took. Throughput counts 200 answers
only.
then an overload run (2 replicas, --max-queue 0, 32 connections of
cone-shadow queries through HAProxy: the 503s that reach the client and
how many carry Retry-After; replica RSS sampled every 0.5 s, first and
last), and a client that hangs up through HAProxy mid-query (the replica's
busy workers and cancellation counter before and after, and how long the
worker took to come free).
"""

import json
import os
import random
import re
import resource
import socket
import sys
import tempfile
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, os.path.join(ROOT, "tests"))
sys.path.insert(0, os.path.join(ROOT, "clients"))
import cluster_lib as cl  # noqa: E402
from kdray_client import f32_b64  # noqa: E402

HAPROXY = "/usr/sbin/haproxy"


def bundle_64k(path):
    rng = random.Random(1)
    dirs = []
    for _ in range(65536):
        dirs += [rng.uniform(-0.6, 0.6), rng.uniform(-0.7, 0.1), -1.0]
    body = json.dumps({"origins": f32_b64([0.2, 4.0, 8.0]), "directions": f32_b64(dirs),
                       "encoding": "base64"}).encode()
    with open(path, "wb") as f:
        f.write(body)
    return len(body)


def shadow_body(path, points):
    rng = random.Random(5)
    pts = []
    for _ in range(points):
        pts += [rng.uniform(-5, 5), 0.02, rng.uniform(-5, 5)]
    body = {"points": pts, "samples": 4096,
            "lights": [{"center": [x, 9, z], "radius": 2.5}
                       for x, z in ((0, 0), (4, 4), (-4, 4), (4, -4))]}
    data = json.dumps(body).encode()
    if path:
        with open(path, "wb") as f:
            f.write(data)
    return data


def metric(url, name):
    _, _, body = cl.get(url + "/metrics")
    m = re.search(r"^%s(?:\{[^}]*\})? ([\d.e+-]+)$" % name, body.decode(), re.M)
    return float(m.group(1)) if m else 0.0


def throughput(kdrayd, scene, seconds, tmp):
    body = os.path.join(tmp, "b64k.json")
    size = bundle_64k(body)
    print("64K-ray base64 bundle: %d bytes per request" % size)
    wide = cl.Replica(kdrayd, [("default", scene)], threads=2)
    narrow = [cl.Replica(kdrayd, [("default", scene)], threads=1) for _ in range(2)]
    for r in [wide] + narrow:
        r.wait_ready()
    path = "/v1/scenes/default/bundle"
    runs = {"direct 1x2": [], "lb 1x2": [], "lb 2x1": []}
    # CPU seconds (user, system) of kdrayd, haproxy and wrk, the wall
    # seconds and the 200 answers, summed over the runs
    cpu = {k: {"kdrayd": [0.0, 0.0], "haproxy": [0.0, 0.0], "wrk": [0.0, 0.0],
               "wall": 0.0, "ok": 0} for k in runs}

    def measure(kind, url, reps, lb):
        before = [cl.cpu_split(r.proc.pid) for r in reps]
        lb_before = cl.cpu_split(lb.proc.pid) if lb else (0.0, 0.0)
        # wrk is this script's only child that ends during the run, so the
        # children's rusage grows by wrk's CPU alone
        ch = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.time()
        rps, codes, _, err, _ = cl.wrk(url + path, body, seconds, 4)
        wall = time.time() - t0
        ch1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        c = cpu[kind]
        for r, b in zip(reps, before):
            a = cl.cpu_split(r.proc.pid)
            c["kdrayd"][0] += a[0] - b[0]
            c["kdrayd"][1] += a[1] - b[1]
        if lb:
            a = cl.cpu_split(lb.proc.pid)
            c["haproxy"][0] += a[0] - lb_before[0]
            c["haproxy"][1] += a[1] - lb_before[1]
        c["wrk"][0] += ch1.ru_utime - ch.ru_utime
        c["wrk"][1] += ch1.ru_stime - ch.ru_stime
        c["wall"] += wall
        c["ok"] += codes.get(200, 0)
        # throughput counts answers to the query only: a 503 is not one
        ok_rps = rps * codes.get(200, 0) / max(sum(codes.values()), 1)
        runs[kind].append((ok_rps, codes, err))

    try:
        for _ in range(2):
            measure("direct 1x2", wide.url, [wide], None)
            lb = cl.Balancer(HAPROXY, [wide.addr], [])
            lb.wait_status({("kdray_main", "main1"): "UP", ("kdray_main", "main2"): "DOWN",
                            ("kdray_main", "main3"): "DOWN"})
            measure("lb 1x2", lb.url, [wide], lb)
            lb.stop()
            lb = cl.Balancer(HAPROXY, [r.addr for r in narrow], [])
            lb.wait_status({("kdray_main", "main1"): "UP", ("kdray_main", "main2"): "UP",
                            ("kdray_main", "main3"): "DOWN"})
            measure("lb 2x1", lb.url, narrow, lb)
            lb.stop()
    finally:
        for r in [wide] + narrow:
            r.stop()
    mean = {}
    for k, v in runs.items():
        mean[k] = sum(x[0] for x in v) / len(v)
        c = cpu[k]
        n = max(c["ok"], 1)
        print("%-11s %7.2f requests/s = %5.2f Mrays/s (runs: %s; statuses %s%s)" %
              (k, mean[k], mean[k] * 65536 / 1e6, ", ".join("%.2f" % x[0] for x in v),
               [x[1] for x in v], "; " + v[0][2] if v[0][2] else ""))
        print("            CPU per 200 answer (user + system ms) and cores used: " +
              ", ".join("%s %.2f + %.2f = %.2f ms, %.2f cores" %
                        (p, 1e3 * c[p][0] / n, 1e3 * c[p][1] / n,
                         1e3 * sum(c[p]) / n, sum(c[p]) / max(c["wall"], 1e-9))
                        for p in ("kdrayd", "haproxy", "wrk")))
    over = 1 - mean["lb 1x2"] / mean["direct 1x2"]
    share = sum(cpu["lb 1x2"]["haproxy"]) / max(sum(cpu["lb 1x2"]["kdrayd"]) +
                                                sum(cpu["lb 1x2"]["haproxy"]), 1e-9)
    print("balancer overhead (1 - lb 1x2 / direct 1x2): %.1f%% of throughput (target "
          "<= 10%%: %s); HAProxy's share of the CPU spent per request: %.1f%%" %
          (100 * over, "met" if over <= 0.10 else "NOT met", 100 * share))
    print("2 replicas x 1 thread / 1 replica x 2 threads, both through HAProxy: %.3f" %
          (mean["lb 2x1"] / mean["lb 1x2"]))


def overload(kdrayd, scene, seconds, tmp):
    body = os.path.join(tmp, "shadow.json")
    shadow_body(body, 200)
    reps = [cl.Replica(kdrayd, [("default", scene)], threads=1,
                       extra=["--max-queue", "0", "--max-rays", str(200 * 4 * 4096)])
            for _ in range(2)]
    for r in reps:
        r.wait_ready()
    lb = cl.Balancer(HAPROXY, [r.addr for r in reps], [])
    lb.wait_status({("kdray_main", "main1"): "UP", ("kdray_main", "main2"): "UP"})
    rss = [[] for _ in reps]
    stop = threading.Event()

    def sample():
        while not stop.is_set():
            for i, r in enumerate(reps):
                rss[i].append(r.rss_kib())
            time.sleep(0.5)
    th = threading.Thread(target=sample)
    th.start()
    try:
        rps, codes, ra, err, _ = cl.wrk(lb.url + "/v1/scenes/default/cone-shadow", body,
                                        seconds * 2, 32)
    finally:
        stop.set()
        th.join()
        lb.stop()
        for r in reps:
            r.stop()
    n503 = codes.get(503, 0)
    print("overload (2 replicas x 1 thread, --max-queue 0, 32 connections, %d s): "
          "statuses %s, %d of %d 503s carry Retry-After%s" %
          (seconds * 2, codes, ra, n503, "; " + err if err else ""))
    for i, s in enumerate(rss):
        q = len(s) // 4
        print("  replica %d RSS (KiB): idle %d; at 1/4 of the run %d, 1/2 %d, 3/4 %d, "
              "end %d (%d samples every 0.5 s)" %
              (i + 1, s[0], s[q], s[2 * q], s[3 * q], s[-1], len(s)))


def hangup(kdrayd, scene):
    rep = cl.Replica(kdrayd, [("default", scene)], threads=1,
                     extra=["--max-rays", str(4000 * 4 * 4096)])
    rep.wait_ready()
    lb = cl.Balancer(HAPROXY, [rep.addr], [])
    lb.wait_status({("kdray_main", "main1"): "UP"})
    try:
        data = shadow_body(None, 4000)  # several seconds of one core
        c0 = metric(rep.url, "kdray_cancellations_total")
        s = socket.create_connection(("127.0.0.1", lb.port))
        s.sendall(b"POST /v1/scenes/default/cone-shadow HTTP/1.1\r\nHost: x\r\n"
                  b"Content-Type: application/json\r\nContent-Length: %d\r\n\r\n"
                  % len(data) + data)
        t0 = time.time()
        while metric(rep.url, "kdray_workers_busy") < 1 and time.time() - t0 < 30:
            time.sleep(0.01)
        busy = metric(rep.url, "kdray_workers_busy")
        s.close()
        t1 = time.time()
        while metric(rep.url, "kdray_workers_busy") > 0 and time.time() - t1 < 30:
            time.sleep(0.005)
        freed = time.time() - t1
        print("hang-up through HAProxy: workers busy %d while the query ran; client "
              "closed; worker free again after %.3f s; kdray_cancellations_total %d -> %d" %
              (busy, freed, c0, metric(rep.url, "kdray_cancellations_total")))
    finally:
        lb.stop()
        rep.stop()


def main():
    kdrayd = sys.argv[1] if len(sys.argv) > 1 else os.path.join(ROOT, "build/server/kdrayd")
    scene = sys.argv[2] if len(sys.argv) > 2 else os.path.join(ROOT, "scenes/default.glb")
    seconds = int(sys.argv[3]) if len(sys.argv) > 3 else 5
    parts = sys.argv[4].split(",") if len(sys.argv) > 4 else ["throughput", "overload",
                                                              "hangup"]
    with tempfile.TemporaryDirectory(prefix="kdray-cluster-bench-") as tmp:
        if "throughput" in parts:
            throughput(kdrayd, scene, seconds, tmp)
        if "overload" in parts:
            overload(kdrayd, scene, seconds, tmp)
        if "hangup" in parts:
            hangup(kdrayd, scene)


if __name__ == "__main__":
    main()

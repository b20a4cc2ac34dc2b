#!/usr/bin/env python3
"""lb_variants.py - A/B of HAProxy set-ups in front of one kdrayd: what
each costs per 64K-ray base64 bundle. A measurement, not a test.

    bench/lb_variants.py [--seconds S] [--reps N] VARIANT...

VARIANT is CONFIG[|HAPROXY ARGS[|NAME=VALUE,...]]: a configuration file
(deploy/haproxy/kdray.cfg or an edited copy), extra HAProxy command-line
arguments (e.g. -dMglobal; the cluster library's own are left out here, so
a variant says all of its own) and environment variables for HAProxy.

One replica (2 worker threads) serves every run. The runs go direct, then
through each variant in turn, REPS times over (default 3, S seconds each,
default 3), wrk 1 thread x 4 connections as in bench/cluster_bench.py.
Printed per set-up: requests/s of each run and CPU per answer of kdrayd,
HAProxy and wrk (user and system ms, from /proc and wrk's rusage), with
HAProxy's total per run: on a machine other jobs share, the CPU per
request is the figure to compare, not requests/s.
"""

import argparse
import os
import resource
import statistics
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, os.path.join(ROOT, "tests"))
sys.path.insert(0, HERE)
import cluster_lib as cl  # noqa: E402
from cluster_bench import bundle_64k  # noqa: E402


def start_balancer(spec, addr):
    cfg, _, rest = spec.partition("|")
    args, _, envs = rest.partition("|")
    saved = (cl.CFG, cl.HAPROXY_OPTS, dict(os.environ))
    cl.CFG, cl.HAPROXY_OPTS = os.path.abspath(cfg), args.split()
    for kv in filter(None, envs.split(",")):
        k, v = kv.split("=", 1)
        os.environ[k] = v
    try:
        lb = cl.Balancer("/usr/sbin/haproxy", [addr], [])
    finally:
        cl.CFG, cl.HAPROXY_OPTS = saved[0], saved[1]
        os.environ.clear()
        os.environ.update(saved[2])
    down = {("kdray_main", "main2"): "DOWN", ("kdray_main", "main3"): "DOWN",
            ("kdray_main_alive", "main2"): "DOWN", ("kdray_main_alive", "main3"): "DOWN"}
    down[("kdray_main", "main1")] = "UP"
    if not lb.wait_status(down):
        raise RuntimeError("haproxy not ready: " + lb.log_text())
    return lb


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=int, default=3)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--kdrayd", default=os.path.join(ROOT, "build/server/kdrayd"))
    ap.add_argument("--scene", default=os.path.join(ROOT, "scenes/default.glb"))
    ap.add_argument("variants", nargs="+")
    a = ap.parse_args()
    body = "/tmp/kdray-lb-variants-%d.json" % os.getpid()
    bundle_64k(body)
    rep = cl.Replica(a.kdrayd, [("default", a.scene)], threads=2)
    rows = {}

    def measure(name, url, lb):
        k0 = cl.cpu_split(rep.proc.pid)
        h0 = cl.cpu_split(lb.proc.pid) if lb else (0.0, 0.0)
        c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        rps, codes, _, err, _ = cl.wrk(url + "/v1/scenes/default/bundle", body, a.seconds, 4)
        c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        k1 = cl.cpu_split(rep.proc.pid)
        h1 = cl.cpu_split(lb.proc.pid) if lb else (0.0, 0.0)
        n = max(codes.get(200, 0), 1)
        rows.setdefault(name, []).append(
            (rps * codes.get(200, 0) / max(sum(codes.values()), 1),
             (k1[0] - k0[0]) / n, (k1[1] - k0[1]) / n, (h1[0] - h0[0]) / n,
             (h1[1] - h0[1]) / n, (c1.ru_utime - c0.ru_utime) / n,
             (c1.ru_stime - c0.ru_stime) / n, codes, err))

    try:
        rep.wait_ready()
        for _ in range(a.reps):
            measure("direct", rep.url, None)
            for v in a.variants:
                lb = start_balancer(v, rep.addr)
                try:
                    measure(v, lb.url, lb)
                finally:
                    lb.stop()
    finally:
        rep.stop()
        os.unlink(body)
    for name, v in rows.items():
        med = [1e3 * statistics.median(x[i] for x in v) for i in range(1, 7)]
        print("%s\n  requests/s %s; median CPU per answer (ms): kdrayd %.2f user + %.2f "
              "system, haproxy %.2f + %.2f, wrk %.2f + %.2f; haproxy per run: %s; "
              "statuses %s%s" %
              (name, " ".join("%.1f" % x[0] for x in v), *med,
               " ".join("%.2f" % (1e3 * (x[3] + x[4])) for x in v),
               [x[7] for x in v], "; " + v[0][8] if v[0][8] else ""))


if __name__ == "__main__":
    main()

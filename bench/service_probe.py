#!/usr/bin/env python3
"""service_probe.py - where a 1M-ray request's time goes inside kdrayd, old
and new daemon alternated in one time window (issue 16, svc8 round). Not a
test.

    service_probe.py KDRAYD [KDRAYD_B ...] [--scene PATH] [--reps N]
                     [--rounds R] [--only NAME]... [--faults] [--floor BIN]
                     [--syscalls]

For each round, each daemon in turn is started on the scene (default
2CylinderEngine of the scene ladder, --threads 2, workers at nice 0) and
sent N times (default 4) each of three requests over one keep-alive
loopback connection:
  frustum      1024x1024 frustum, closest hits, CBOR answer (16.8 MB: t,
               prim, u, v);
  bundle24     1M rays with an origin each as a CBOR bundle (24 MiB body,
               float32 typed arrays aligned so kdrayd reads them in place);
  transport24  the same bundle with tmin 1 > tmax 0: nothing to trace.
The client is a raw socket that reads the answer with recv_into into one
buffer reused for every request, so that what is timed is kdrayd and the
loopback, not the client's copies. Each request prints its wall time, the
daemon's CPU time for it (all threads, /proc/PID/task/*/schedstat), the
system part of it and its minor page faults (/proc/PID/stat; sys is in
clock ticks, 10 ms here) and kdrayd's Server-Timing split (body arrival, queue, parse, trace, encode);
the summary gives the medians per daemon and request kind, and the
largest encode (cold memory shows there). With --faults each daemon's
minor page faults over its requests are counted with `perf stat -e
page-faults` (perf must be installed; a missing perf fails the run).
With --syscalls each daemon's reads, polls and sends over its requests are
counted with `strace -f -c -p PID` (strace must be installed; a missing
strace fails the run), and the bytes of request bodies per read call
printed: libmicrohttpd's read size. strace slows every system call, so
the times of such a run are not comparable with others.
With --floor BIN (build/bench/kdray-loopback-floor) the run ends with the
loopback floor on this machine for the bundle's body size: the same bytes
between two threads of one process, read as libmicrohttpd reads a body in
kdrayd and in larger pieces (bench/loopback_floor.c), so that the "body"
column above has its floor beside it, measured in the same minutes.
"""

import argparse
import json
import os
import re
import shutil
import socket
import statistics
import subprocess
import sys
import time
import urllib.request

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from bench_service import F32, _cpu_ms as cpu_ms, cbor_body, start_daemon  # noqa: E402

# the scene ladder of this checkout (scenes/fetch build/scene-ladder)
LADDER_ENGINE = os.path.join(os.path.dirname(HERE), "build", "scene-ladder", "engine",
                             "2CylinderEngine.glb")
KINDS = ("frustum", "bundle24", "transport24")
STEPS = ("body", "queue", "parse", "trace", "encode")


def proc_stat(pid):
    """(minor faults, system CPU ms) of pid so far: /proc/PID/stat fields 10
    and 15, after the command name (which may hold spaces)."""
    with open("/proc/%d/stat" % pid) as f:
        rest = f.read().rsplit(")", 1)[1].split()
    return int(rest[7]), int(rest[12]) * 1e3 / os.sysconf("SC_CLK_TCK")


def post(sock, path, body, ctype, buf):
    head = ("POST %s HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: %s\r\n"
            "Accept: application/cbor\r\nContent-Length: %d\r\n\r\n"
            % (path, ctype, len(body))).encode()
    mv = memoryview(buf)
    t0 = time.perf_counter()
    sock.sendall(head)
    sock.sendall(body)
    n = 0
    while True:
        k = sock.recv_into(mv[n:])
        if k == 0:
            raise SystemExit("kdrayd closed the connection")
        n += k
        end = bytes(mv[:min(n, 8192)]).find(b"\r\n\r\n")
        if end >= 0:
            break
    head = bytes(mv[:end]).decode("latin-1")
    clen = int(re.search(r"(?im)^content-length: *(\d+)", head).group(1))
    want = end + 4 + clen
    while n < want:
        k = sock.recv_into(mv[n:want])
        if k == 0:
            raise SystemExit("kdrayd closed the connection")
        n += k
    wall = (time.perf_counter() - t0) * 1e3
    status = int(head.split()[1])
    timing = dict((k, float(v)) for k, v in re.findall(r"(\w+);dur=([\d.]+)", head))
    return status, wall, timing, clen


def requests(url):
    with urllib.request.urlopen(url + "/v1/scenes/default") as r:
        info = json.load(r)
    lo, hi = info["bounds"]["min"], info["bounds"]["max"]
    c = [(a + b) / 2 for a, b in zip(lo, hi)]
    size = max(b - a for a, b in zip(lo, hi)) or 1.0
    eye = [c[0], c[1] + 0.25 * size, c[2] + 1.5 * size]
    frustum = json.dumps({"camera": {"eye": eye, "target": c, "up": [0, 1, 0],
                                     "fov_y_deg": 60, "width": 1024, "height": 1024},
                          "tile": 8}).encode()
    import random
    rng = random.Random(1)
    n = 1 << 20
    dirs, orgs = [], eye * n
    for _ in range(n):
        dirs += [rng.uniform(lo[k], hi[k]) - eye[k] for k in range(3)]
    bundle = cbor_body({"origins": F32(orgs), "directions": F32(dirs)})
    empty = cbor_body({"tmin": 1.0, "tmax": 0.0, "origins": F32(orgs),
                       "directions": F32(dirs)})
    return {"frustum": ("/v1/scenes/default/frustum", frustum, "application/json"),
            "bundle24": ("/v1/scenes/default/bundle", bundle, "application/cbor"),
            "transport24": ("/v1/scenes/default/bundle", empty, "application/cbor")}


SYSCALLS = ("recvfrom", "read", "poll", "sendto", "sendmsg", "writev")


def strace_counts(err):
    """{syscall: calls} from strace -c's summary table."""
    calls = {}
    for line in err.splitlines():
        f = line.split()
        if len(f) >= 5 and f[-1] in SYSCALLS and f[3].isdigit():
            calls[f[-1]] = int(f[3])
    return calls


def run_daemon(kdrayd, scene, kinds, reps, bodies, faults, rows, syscalls=False):
    proc, url = start_daemon(kdrayd, scene, 2)
    try:
        if bodies[0] is None:
            bodies[0] = requests(url)
        host, port = url.split("//")[1].split(":")
        sock = socket.create_connection((host, int(port)))
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        buf = bytearray(64 << 20)
        perf = None
        if faults:
            perf = subprocess.Popen(["perf", "stat", "-x", ",", "-e", "page-faults",
                                     "-p", str(proc.pid)], stderr=subprocess.PIPE,
                                    text=True)
            time.sleep(0.5)
        tracer = None
        if syscalls:
            tracer = subprocess.Popen(["strace", "-f", "-c", "-e", "trace=" + ",".join(SYSCALLS),
                                       "-p", str(proc.pid)], stderr=subprocess.PIPE, text=True)
            time.sleep(0.5)
        body_bytes = 0
        for kind in kinds:
            path, body, ctype = bodies[0][kind]
            for _ in range(reps):
                c0, (f0, s0) = cpu_ms(proc.pid), proc_stat(proc.pid)
                status, wall, timing, clen = post(sock, path, body, ctype, buf)
                cpu = cpu_ms(proc.pid) - c0
                f1, s1 = proc_stat(proc.pid)
                if status != 200:
                    raise SystemExit("%s: HTTP %d" % (kind, status))
                rows.append((kdrayd, kind, wall, cpu, timing))
                body_bytes += len(body)
                print("%-22s %-12s wall %7.1f ms cpu %6.1f ms (sys %5.0f) minflt %5d "
                      "answer %5.1f MB  %s" % (
                          os.path.basename(kdrayd)[-22:], kind, wall, cpu, s1 - s0,
                          f1 - f0, clen / 1e6,
                          " ".join("%s %.1f" % (k, timing.get(k, float("nan")))
                                   for k in STEPS)), flush=True)
        sock.close()
        if tracer:
            time.sleep(0.2)
            tracer.send_signal(2)
            calls = strace_counts(tracer.communicate()[1])
            reads = calls.get("recvfrom", 0) + calls.get("read", 0)
            if not reads:
                raise SystemExit("strace counted no reads")
            print("%s: %s; %.1f KiB of request bodies per read call" % (
                kdrayd, ", ".join("%s %d" % kv for kv in sorted(calls.items())),
                body_bytes / reads / 1024))
        if perf:
            time.sleep(0.2)
            perf.send_signal(2)
            err = perf.communicate()[1]
            m = re.search(r"^(\d+),,page-faults", err, re.M)
            if not m:
                raise SystemExit("perf stat gave no page-fault count:\n" + err)
            print("%s: %s page faults over these requests" % (kdrayd, m.group(1)))
    finally:
        proc.terminate()
        proc.wait()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("kdrayd", nargs="+")
    ap.add_argument("--scene", default=LADDER_ENGINE)
    ap.add_argument("--reps", type=int, default=4)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--only", action="append", choices=KINDS)
    ap.add_argument("--faults", action="store_true")
    ap.add_argument("--syscalls", action="store_true")
    ap.add_argument("--floor", metavar="BIN",
                    help="kdray-loopback-floor: print the loopback floor for the body size")
    a = ap.parse_args()
    if a.faults and not shutil.which("perf"):
        raise SystemExit("--faults needs perf (linux-perf)")
    if a.syscalls and not shutil.which("strace"):
        raise SystemExit("--syscalls needs strace")
    kinds = a.only or list(KINDS)
    bodies, rows = [None], []
    for r in range(a.rounds):
        for d in a.kdrayd:
            run_daemon(d, a.scene, kinds, a.reps, bodies, a.faults, rows, a.syscalls)
    print("\nmedians (ms) over %d round(s) x %d request(s); load average %s" % (
        a.rounds, a.reps, open("/proc/loadavg").read().split()[0]))
    print("%-12s %-22s %7s %7s %7s %7s %7s %7s %10s" % (
        "request", "daemon", "wall", "cpu", "body", "parse", "trace", "encode",
        "encode max"))
    for kind in kinds:
        for d in a.kdrayd:
            got = [r for r in rows if r[0] == d and r[1] == kind]
            med = lambda f: statistics.median(f(r) for r in got)  # noqa: E731
            print("%-12s %-22s %7.1f %7.1f %7.1f %7.1f %7.1f %7.1f %10.1f" % (
                kind, os.path.basename(d)[-22:], med(lambda r: r[2]), med(lambda r: r[3]),
                med(lambda r: r[4]["body"]), med(lambda r: r[4]["parse"]),
                med(lambda r: r[4]["trace"]), med(lambda r: r[4]["encode"]),
                max(r[4]["encode"] for r in got)))
    if a.floor:
        size = len(bodies[0]["bundle24"][1])
        print("\nthe loopback floor for the %d-byte bundle body (%s):" % (size, a.floor),
              flush=True)
        out = subprocess.run([a.floor, "--bytes", str(size)], capture_output=True, text=True)
        if out.returncode != 0:
            raise SystemExit("%s failed:\n%s" % (a.floor, out.stderr))
        print(out.stdout, end="")


if __name__ == "__main__":
    main()

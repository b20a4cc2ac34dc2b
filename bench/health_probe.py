#!/usr/bin/env python3
"""health_probe.py - GET /v1/health latency of kdrayd against a trivial
server, measured by the same client in the same run.

    health_probe.py KDRAYD [KDRAYD_B ...] [--probes N] [--rounds R]
                    [--gap-ms G] [--kdrayd-arg ARG ...] [--busy]

Starts kdrayd on the bundled scene (port 0) and a single-threaded Python
socket server that answers every request with a fixed 200 (the floor: what
a do-nothing server costs on this machine). Each round sends N sequential
probes to each, alternating, in two modes: a new TCP connection per probe
(as a balancer or kubelet probes) and one kept-alive connection. G ms of
sleep separate probes (the test's 5 ms: a probe then lands on an idle
machine, as a real probe does). Prints p50/p90/p99/max per server and mode
and the ratio kdrayd / trivial, so noise from other jobs shows in both.
More than one kdrayd binary (an A/B of two builds) are probed in the same
rounds, each against the same trivial server.
With --busy, two clients keep both workers tracing a long cone-shadow
query while kdrayd is probed (issue 13's case; the trivial server is
unaffected, so its numbers are then only the machine's).

The client uses raw sockets (no http.client parsing) so that its own cost
is small and identical for both servers.
"""

import argparse
import json
import os
import socket
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))
import test_server_lib as lib  # noqa: E402

REQ = b"GET /v1/health HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n"

TRIVIAL = r'''
import socket, sys
s = socket.socket()
s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
s.bind(("127.0.0.1", 0)); s.listen(64)
print(s.getsockname()[1], flush=True)
body = b'{"status":"ok","scenes":1}'
resp = (b"HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nContent-Length: %d\r\n\r\n"
        % len(body)) + body
while True:
    c, _ = s.accept()
    c.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    buf = b""
    while True:
        d = c.recv(4096)
        if not d:
            break
        buf += d
        while b"\r\n\r\n" in buf:
            _, buf = buf.split(b"\r\n\r\n", 1)
            c.sendall(resp)
    c.close()
'''


def read_response(s):
    """Reads one HTTP response with a Content-Length; returns the status."""
    buf = b""
    while b"\r\n\r\n" not in buf:
        d = s.recv(4096)
        if not d:
            raise RuntimeError("connection closed before the head")
        buf += d
    head, rest = buf.split(b"\r\n\r\n", 1)
    n = 0
    for line in head.split(b"\r\n")[1:]:
        k, _, v = line.partition(b":")
        if k.strip().lower() == b"content-length":
            n = int(v)
    while len(rest) < n:
        d = s.recv(4096)
        if not d:
            raise RuntimeError("connection closed in the body")
        rest += d
    return int(head.split(b" ", 2)[1])


def connect(port):
    s = socket.create_connection(("127.0.0.1", port))
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return s


def probe(port, n, gap, keep):
    lat = []
    s = connect(port) if keep else None
    for _ in range(n):
        t0 = time.perf_counter()
        c = s if keep else connect(port)
        c.sendall(REQ)
        st = read_response(c)
        if not keep:
            c.close()
        lat.append((time.perf_counter() - t0) * 1e3)
        if st != 200:
            raise RuntimeError("status %d" % st)
        if gap:
            time.sleep(gap)
    if s:
        s.close()
    return sorted(lat)


def summary(lat):
    return (lib.pct(lat, 50), lib.pct(lat, 90), lib.pct(lat, 99), lat[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("kdrayd", nargs="+")
    ap.add_argument("--probes", type=int, default=1000)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--gap-ms", type=float, default=5.0)
    ap.add_argument("--kdrayd-arg", action="append", default=[])
    ap.add_argument("--busy", action="store_true")
    a = ap.parse_args()
    lib.add_client_path(os.path.join(HERE, "..", "clients"))
    daemons = [lib.Daemon(k, ["--threads", "2", "--max-rays", str(10000 * 4 * 4096)]
                          + a.kdrayd_arg) for k in a.kdrayd]
    names = ["kdrayd" if len(daemons) == 1 else "kdrayd" + "AB"[i] if i < 2 else
             "kdrayd%d" % i for i in range(len(daemons))]
    servers = [(n, int(d.url.rsplit(":", 1)[1])) for n, d in zip(names, daemons)]
    triv = subprocess.Popen([sys.executable, "-c", TRIVIAL], stdout=subprocess.PIPE,
                            text=True)
    tport = int(triv.stdout.readline())
    loads, tmp = [], None
    try:
        if a.busy:
            import tempfile
            tmp = tempfile.NamedTemporaryFile("w", suffix=".json", delete=False)
            json.dump(lib.long_shadow_payload(10000), tmp)
            tmp.close()
            loads = [subprocess.Popen([sys.executable, "-c", lib.BUSY_CLIENT, "127.0.0.1",
                                       str(port), tmp.name])
                     for _, port in servers for _ in range(2)]
            time.sleep(2.0)
        gap = a.gap_ms / 1e3
        res = {}
        for _ in range(a.rounds):
            for keep in (False, True):
                for name, port in servers + [("trivial", tport)]:
                    res.setdefault((name, keep), []).extend(
                        probe(port, a.probes, gap, keep))
        print("%d rounds x %d probes, %.1f ms apart%s" % (
            a.rounds, a.probes, a.gap_ms, ", both workers busy" if a.busy else ""))
        print("%-8s %-10s %7s %7s %7s %7s" % ("server", "mode", "p50", "p90", "p99",
                                                "max"))
        for keep in (False, True):
            mode = "keepalive" if keep else "new-conn"
            t = summary(sorted(res[("trivial", keep)]))
            print("%-8s %-10s %7.3f %7.3f %7.3f %7.2f ms" % (("trivial", mode) + t))
            for name, _ in servers:
                k = summary(sorted(res[(name, keep)]))
                print("%-8s %-10s %7.3f %7.3f %7.3f %7.2f ms" % ((name, mode) + k))
                print("%-8s %-10s %7.2f %7.2f %7.2f %7.2f x trivial's" % (
                    "", "", k[0] / t[0], k[1] / t[1], k[2] / t[2], k[3] / t[3]))
    finally:
        for p in loads:
            p.kill()
            p.wait()
        if tmp:
            os.unlink(tmp.name)
        triv.kill()
        triv.wait()
        for d in daemons:
            d.stop()


if __name__ == "__main__":
    main()

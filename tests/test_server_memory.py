#!/usr/bin/env python3
"""test_server_memory.py - kdrayd's memory under hostile load, measured on the
process itself (VmRSS / VmHWM from /proc). Not run in the sanitizer build:
AddressSanitizer's shadow memory and quarantine make RSS meaningless, and it
cannot live under an address-space limit.

    test_server_memory.py KDRAYD CLIENTS_DIR

rss_bound: 100 clients each announce a maximum-size body (--max-body-mb 4)
and send all of it but the last byte, at once. Admission charges each
announced body (x3, for parsing) against --max-inflight-mb 16 before a byte
is stored, so one is admitted at a time and the others are read and thrown
away; the daemon's peak RSS must stay within the budget plus per-connection
buffers, far from the 400 MiB the bodies add up to. Then every client sends
its last byte: the admitted one is answered 200, the others 503 with
Retry-After.

parse_charged: a JSON body the fast path cannot read (a 2 MiB array of
single digits in a member the contract does not know goes to cJSON, some 40
bytes of nodes per body byte) is charged as its parse allocates: past the
whole budget it is refused with 413 before the nodes exist, and the peak
RSS stays within the budget. (Before parses were metered it was answered
200 after ~80 MiB of cJSON nodes on a 16 MiB budget.)

out_of_memory: the daemon's address space is capped (prlimit) a little above
what it uses; a query whose result arrays cannot be allocated is answered
503 with Retry-After (never 500), and so is a body whose cJSON parse runs
out of memory (never a 400 "malformed JSON"); the daemon goes on answering.
"""

import json
import os
import resource
import socket
import sys
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import test_server_lib as lib  # noqa: E402

KDRAYD, CLIENTS = sys.argv[1], sys.argv[2]
lib.add_client_path(CLIENTS)
from kdray_client import Client  # noqa: E402

CLIENTS_N = 100
BODY_MB = 4
INFLIGHT_MB = 16
CONN_BUFFER_MB = 0.03125  # libmicrohttpd's per-connection memory (http_daemon.c)
SLACK_MB = 24           # allocator arenas, thread stacks touched, the scrape


def proc_kib(pid, field):
    with open("/proc/%d/status" % pid) as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1])
    raise RuntimeError(field + " not found")


def test_rss_bound(t):
    d = lib.Daemon(KDRAYD, ["--threads", "1", "--max-body-mb", str(BODY_MB),
                            "--max-inflight-mb", str(INFLIGHT_MB), "--max-connections",
                            "512"])
    try:
        c = Client(d.url)
        pid = d.proc.pid
        base = proc_kib(pid, "VmRSS")
        size = BODY_MB << 20
        payload = json.dumps({"origins": [0, 3, 5], "directions": [0, -0.3, -1]}).encode()
        body = payload + b" " * (size - len(payload))
        host, port = d.url.split("//")[1].split(":")
        head = (b"POST /v1/scenes/default/bundle HTTP/1.1\r\nHost: x\r\n"
                b"Content-Type: application/json\r\nConnection: close\r\n"
                b"Content-Length: %d\r\n\r\n" % size)
        socks = [socket.create_connection((host, int(port)), timeout=120)
                 for _ in range(CLIENTS_N)]
        errors = []

        def send_all_but_last(s):
            try:
                s.sendall(head + body[:-1])
            except OSError as e:
                errors.append(repr(e))

        t0 = time.time()
        threads = [threading.Thread(target=send_all_but_last, args=(s,)) for s in socks]
        for th in threads:
            th.start()
        for th in threads:
            th.join(300)
        sent = time.time() - t0
        time.sleep(0.5)
        peak = proc_kib(pid, "VmHWM")
        now = proc_kib(pid, "VmRSS")
        m = c.metrics()
        bound = (INFLIGHT_MB + CLIENTS_N * CONN_BUFFER_MB + SLACK_MB) * 1024
        print("  %d clients x %d MiB (all but the last byte) sent in %.1f s; kdrayd RSS "
              "%.1f MiB at start, %.1f MiB now, peak %.1f MiB; bound %.1f MiB; in flight "
              "%.1f MiB of %d; %d refused for memory"
              % (CLIENTS_N, BODY_MB, sent, base / 1024, now / 1024, peak / 1024,
                 (base + bound) / 1024, lib.metric(m, "kdray_inflight_bytes") / 2**20,
                 INFLIGHT_MB, lib.metric(m, "kdray_rejections_total", reason="memory")))
        t.eq(errors, [], "every client could send its body")
        t.check(peak - base <= bound, "peak RSS grew %.1f MiB, over %.1f MiB"
                % ((peak - base) / 1024, bound / 1024))
        t.check(lib.metric(m, "kdray_inflight_bytes") <= INFLIGHT_MB << 20,
                "bytes in flight within the budget")
        for s in socks:
            s.sendall(body[-1:])
        codes = {}
        for s in socks:
            reply = b""
            while True:
                chunk = s.recv(65536)
                if not chunk:
                    break
                reply += chunk
            s.close()
            status = reply[9:12].decode() if reply.startswith(b"HTTP/1.1 ") else "none"
            codes[status] = codes.get(status, 0) + 1
            if status == "503":
                t.check(b"\r\nRetry-After: " in reply, "503 carries Retry-After")
        print("  answers: %r" % codes)
        t.check(codes.get("200", 0) >= 1, "the admitted body is answered")
        t.eq(codes.get("200", 0) + codes.get("503", 0), CLIENTS_N,
             "every other client gets 503")
        t.eq(c.health()["status"], "ok", "alive")
    finally:
        t.eq(d.stop(), 0, "exit 0")


def digits_body(mb):
    """A valid bundle body of about mb MiB, nearly all of it an array of
    single digits in an unknown member (parsed by cJSON, not the fast path)."""
    head = b'{"origins": [0, 3, 5], "directions": [0, -0.3, -1], "x": ['
    n = ((mb << 20) - len(head)) // 2
    return head + b"0," * (n - 1) + b"0]}"


def test_parse_charged(t):
    d = lib.Daemon(KDRAYD, ["--threads", "1", "--max-body-mb", str(BODY_MB),
                            "--max-inflight-mb", str(INFLIGHT_MB)])
    try:
        c = Client(d.url)
        pid = d.proc.pid
        t.eq(c.bundle("default", [0, 3, 5], [0, -0.3, -1])["count"], 1, "warm")
        base = proc_kib(pid, "VmHWM")
        code, headers, body = c.request("POST", "/v1/scenes/default/bundle",
                                        digits_body(2))
        peak = proc_kib(pid, "VmHWM")
        p = json.loads(body)
        print("  2 MiB of digits for cJSON on a %d MiB budget: %d %s; peak RSS %.1f -> "
              "%.1f MiB" % (INFLIGHT_MB, code, p.get("detail"), base / 1024, peak / 1024))
        t.eq(code, 413, "a parse larger than the whole budget is 413")
        t.check("in-flight memory limit" in p.get("detail", ""), "says why: %r" % p)
        t.check(peak - base <= (INFLIGHT_MB + SLACK_MB) * 1024,
                "peak RSS grew %.1f MiB" % ((peak - base) / 1024))
        # the claim is returned when libmicrohttpd reports the answer sent,
        # which can come just after the client has read it
        deadline = time.time() + 10
        while (lib.metric(c.metrics(), "kdray_inflight_bytes") != 0.0 and
               time.time() < deadline):
            time.sleep(0.01)
        t.eq(lib.metric(c.metrics(), "kdray_inflight_bytes"), 0.0, "the charge is returned")
        t.eq(c.bundle("default", [0, 3, 5], [0, -0.3, -1])["count"], 1, "goes on")
    finally:
        t.eq(d.stop(), 0, "exit 0")


def test_out_of_memory(t):
    d = lib.Daemon(KDRAYD, ["--threads", "1", "--max-rays", str(1 << 28),
                            "--max-inflight-mb", "65536"])
    try:
        c = Client(d.url)
        pid = d.proc.pid
        vm = proc_kib(pid, "VmSize") * 1024
        cap = vm + (384 << 20)
        resource.prlimit(pid, resource.RLIMIT_AS, (cap, cap))
        # 16384 x 8192 pixels: 2 GiB of result arrays, far above the cap
        cam = {"camera": {"eye": [0, 3, 9], "target": [0, 1, 0], "fov_y_deg": 50,
                          "width": 16384, "height": 8192}, "encoding": "base64"}
        code, headers, body = c.request("POST", "/v1/scenes/default/frustum",
                                        json.dumps(cam).encode())
        p = json.loads(body)
        print("  address space capped at %.0f MiB: %d %s" % (cap / 2**20, code,
                                                            p.get("detail")))
        t.eq(code, 503, "out of memory is 503, not 500")
        t.check("out of memory" in p.get("detail", ""), "says so: %r" % p)
        t.check(headers.get("Retry-After", "").isdigit(), "with Retry-After")
        t.eq(lib.metric(c.metrics(), "kdray_out_of_memory_total"), 1.0, "counted")
        t.eq(c.bundle("default", [0, 3, 5], [0, -0.3, -1])["count"], 1,
             "the daemon goes on answering")
        # 16 MiB of digits: ~640 MiB of cJSON nodes, more than the cap allows
        code, headers, body = c.request("POST", "/v1/scenes/default/bundle",
                                        digits_body(16))
        p = json.loads(body)
        print("  16 MiB of digits for cJSON under the cap: %d %s" % (code, p.get("detail")))
        t.eq(code, 503, "cJSON out of memory is 503, not a 400")
        t.check("out of memory" in p.get("detail", ""), "says so: %r" % p)
        t.check(headers.get("Retry-After", "").isdigit(), "with Retry-After")
        t.eq(lib.metric(c.metrics(), "kdray_out_of_memory_total"), 2.0, "counted")
        t.eq(c.bundle("default", [0, 3, 5], [0, -0.3, -1])["count"], 1,
             "the daemon goes on answering after it")
    finally:
        t.eq(d.stop(), 0, "exit 0")


def main():
    t = lib.Runner()
    t.run(test_rss_bound)
    t.run(test_parse_charged)
    t.run(test_out_of_memory)
    return t.finish()


if __name__ == "__main__":
    sys.exit(main())

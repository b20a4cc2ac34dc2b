#!/usr/bin/env python3
"""test_server_arrival.py - how a large request body reaches kdrayd.

    test_server_arrival.py KDRAYD CLIENTS_DIR

Needs Debian's python3-cbor2 (run with /usr/bin/python3): a missing module
is a failure, not a skip. The bodies are CBOR bundles of 100 000 rays
(2.4 MB: over the size answered on the HTTP thread, so they go through
admission and the executor, and into a huge-page block) sent on raw
sockets, so that the test decides how the bytes travel:

- pieces: the body in odd-sized pieces (1 byte to 128 KiB + 1, paced so
  that they arrive apart), announced by Content-Length and again chunked
  (Transfer-Encoding, the length unknown to the daemon), answers byte for
  byte the answer to the body sent in one call; the slow sender's pauses
  show in the answer's Server-Timing body step (it measures arrival);
- cut short: a client that announces the body and hangs up half way, or
  half-closes its side and waits, gets no 200, and the daemon lets go of
  the request (in-flight gauge, admitted bytes back to 0 in /v1/ready) and
  answers the next request;
- Content-Length lies: a length shorter than the bytes sent is answered
  for what the length covered (a 400 naming the body, the truncated CBOR),
  never with another request's answer; a length that never arrives ends at
  the connection timeout with the admitted bytes released; a body over
  --max-body-mb is a 413 naming the limit, the connection kept readable.
"""

import json
import os
import random
import re
import socket
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import test_server_lib as lib  # noqa: E402

KDRAYD, CLIENTS = sys.argv[1], sys.argv[2]
lib.add_client_path(CLIENTS)
import cbor2  # noqa: E402,F401  (python3-cbor2: required, see above)
from kdray_client import Client, _f32_array, cbor_body  # noqa: E402

SCENE = "default"
PATH = "/v1/scenes/%s/bundle" % SCENE
RAYS = 100000
TIMEOUT_S = 3  # --connection-timeout-s of the daemon under test
PIECES = (1, 3, 4093, 16385, 7, 131073, 65537, 2, 32769, 999)


def body_of(c, seed=11):
    bounds = c.scene(SCENE)["bounds"]
    o, d = lib.rays_into_box(bounds, RAYS, seed=seed)
    return cbor_body({"origins": _f32_array(o), "directions": _f32_array(d)})


def head(length=None, chunked=False, close=True):
    h = ("POST %s HTTP/1.1\r\nHost: x\r\nContent-Type: application/cbor\r\n"
         "Accept: application/cbor\r\n" % PATH)
    if length is not None:
        h += "Content-Length: %d\r\n" % length
    if chunked:
        h += "Transfer-Encoding: chunked\r\n"
    if close:
        h += "Connection: close\r\n"
    return (h + "\r\n").encode()


def connect(url):
    host, port = url.split("//")[1].split(":")
    s = socket.create_connection((host, int(port)), timeout=60)
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return s


def read_all(s):
    out = bytearray()
    while True:
        try:
            chunk = s.recv(1 << 20)
        except ConnectionResetError:
            return bytes(out)
        if not chunk:
            return bytes(out)
        out += chunk


def split_answer(raw):
    """(status, headers dict (lower-case names), body) of one answer with a
    Content-Length; status 0 when nothing came back."""
    if not raw:
        return 0, {}, b""
    end = raw.index(b"\r\n\r\n")
    lines = raw[:end].decode("latin-1").split("\r\n")
    hdrs = {}
    for line in lines[1:]:
        k, _, v = line.partition(":")
        hdrs[k.strip().lower()] = v.strip()
    n = int(hdrs.get("content-length", len(raw) - end - 4))
    return int(lines[0].split()[1]), hdrs, raw[end + 4:end + 4 + n]


def pieces(data, pause_every=4, pause_s=0.02):
    """data cut into PIECES' sizes in turn; after every pause_every pieces
    the sender sleeps, so that the daemon reads them apart."""
    at, k = 0, 0
    while at < len(data):
        n = PIECES[k % len(PIECES)]
        yield data[at:at + n], (k % pause_every == pause_every - 1) and pause_s
        at += n
        k += 1


def send_in_pieces(s, data):
    slept = 0.0
    for piece, pause in pieces(data):
        s.sendall(piece)
        if pause:
            time.sleep(pause)
            slept += pause
    return slept


def chunked(data):
    """data in HTTP/1.1 chunks of PIECES' sizes (then the last, empty one)."""
    out = bytearray()
    for piece, _ in pieces(data, pause_every=10 ** 9):
        out += b"%x\r\n" % len(piece) + piece + b"\r\n"
    return bytes(out + b"0\r\n\r\n")


def server_timing(hdrs):
    return dict((k, float(v)) for k, v in
                re.findall(r"(\w+);dur=([\d.]+)", hdrs.get("server-timing", "")))


def ready(c):
    code, _, data = c.request("GET", "/v1/ready")
    return json.loads(data)


def wait_idle(t, c, what, timeout=30):
    """Waits until nothing is in flight and no byte is admitted; fails the
    test naming what was left."""
    deadline = time.time() + timeout
    while True:
        r = ready(c)
        inflight = lib.metric(c.metrics(), "kdray_http_requests_in_flight")
        # the scrape itself is in flight while it is answered
        if (r["inflight_bytes"] == 0 and r["slots_used"] == 0 and inflight <= 1) or \
                time.time() > deadline:
            break
        time.sleep(0.02)
    t.eq((r["inflight_bytes"], r["slots_used"]), (0, 0), what + ": admission released")
    t.check(inflight <= 1, "%s: %s requests still in flight" % (what, inflight))


def test_pieces(t, c):
    body = body_of(c)
    with connect(c.url) as s:
        s.sendall(head(len(body)) + body)
        want = split_answer(read_all(s))
    t.eq(want[0], 200, "the body in one call: 200")
    t.check(len(want[2]) > RAYS * 16, "a full answer (%d bytes)" % len(want[2]))
    with connect(c.url) as s:
        s.sendall(head(len(body)))
        slept = send_in_pieces(s, body)
        got = split_answer(read_all(s))
    t.eq(got[0], 200, "odd-sized pieces: 200")
    t.check(got[2] == want[2], "odd-sized pieces: the same answer, byte for byte")
    body_ms = server_timing(got[1]).get("body", 0)
    t.check(body_ms >= 0.8 * slept * 1e3,
            "Server-Timing body %.1f ms covers the sender's %.0f ms of pauses"
            % (body_ms, slept * 1e3))
    with connect(c.url) as s:  # chunked: the daemon grows the buffer as it goes
        s.sendall(head(chunked=True))
        send_in_pieces(s, chunked(body))
        got = split_answer(read_all(s))
    t.eq(got[0], 200, "chunked odd-sized pieces: 200")
    t.check(got[2] == want[2], "chunked odd-sized pieces: the same answer")
    wait_idle(t, c, "after the pieces")


def test_cut_short(t, c):
    body = body_of(c, seed=12)
    base = lib.metric(c.metrics(), "kdray_http_requests_total")
    with connect(c.url) as s:  # hangs up half way
        s.sendall(head(len(body), close=False) + body[:len(body) // 2])
        time.sleep(0.1)
    wait_idle(t, c, "a client that hung up half way")
    with connect(c.url) as s:  # half-closes and waits for an answer
        s.sendall(head(len(body), close=False) + body[:len(body) // 3])
        s.shutdown(socket.SHUT_WR)
        code, _, _ = split_answer(read_all(s))
    t.check(code != 200, "a body cut short is never answered 200 (got %d)" % code)
    wait_idle(t, c, "a client that half-closed mid-body")
    with connect(c.url) as s:  # the chunked way: its last chunk never comes
        s.sendall(head(chunked=True, close=False) + chunked(body)[:len(body) // 2])
        s.shutdown(socket.SHUT_WR)
        code, _, _ = split_answer(read_all(s))
    t.check(code != 200, "a chunked body cut short: no 200 (got %d)" % code)
    wait_idle(t, c, "a chunked body cut short")
    t.eq(c.health()["status"], "ok", "alive after bodies cut short")
    t.check(lib.metric(c.metrics(), "kdray_http_requests_total") >= base,
            "metrics still answer")
    got = c.request("POST", PATH, body, "application/cbor", {"Accept": "application/cbor"})
    t.eq(got[0], 200, "the same body sent whole afterwards: 200")


def test_length_lies(t, c):
    body = body_of(c, seed=13)
    # shorter than what is sent: the length is what counts; the truncated
    # CBOR is a 400 naming the body, and the rest is not a request (the
    # client asks for Connection: close and keeps its side open: kdrayd
    # takes a query's client that half-closed for one that left)
    with connect(c.url) as s:
        s.sendall(head(len(body) - 10) + body)
        raw = read_all(s)
    code, hdrs, data = split_answer(raw)
    t.eq(code, 400, "Content-Length short of the body: 400 for the truncated body")
    t.eq(hdrs.get("content-type"), "application/problem+json", "a problem answer")
    t.check("body" in json.loads(data).get("detail", ""),
            "the problem names the body: %r" % data[:200])
    t.check(raw.count(b"HTTP/1.1 200") == 0, "no 200 for the left-over bytes")
    wait_idle(t, c, "a short Content-Length")
    # longer than what is sent, the sender then stalls: the connection
    # timeout ends it and the admitted bytes go back
    with connect(c.url) as s:
        s.sendall(head(len(body) + 1000, close=False) + body)
        t0 = time.time()
        code, _, _ = split_answer(read_all(s))
        waited = time.time() - t0
    t.check(code != 200, "a body that never completes: no 200 (got %d)" % code)
    t.check(waited < TIMEOUT_S + 20, "closed by the connection timeout (%.1f s)" % waited)
    wait_idle(t, c, "a Content-Length that never arrives")


def test_over_the_limit(t):
    """--max-body-mb 2: a 2.4 MB body is a 413 naming the limit, whether it
    is announced (answered after the body is drained) or chunked."""
    d = lib.Daemon(KDRAYD, ["--threads", "2", "--max-body-mb", "2",
                            "--connection-timeout-s", str(TIMEOUT_S)])
    try:
        c = Client(d.url)
        body = body_of(c, seed=14)
        for how in ("announced", "chunked"):
            with connect(c.url) as s:
                if how == "announced":
                    s.sendall(head(len(body)))
                    send_in_pieces(s, body)
                else:
                    s.sendall(head(chunked=True))
                    send_in_pieces(s, chunked(body))
                code, hdrs, data = split_answer(read_all(s))
            t.eq(code, 413, how + ": over --max-body-mb: 413")
            detail = json.loads(data).get("detail", "") if data else ""
            t.check("limit" in detail or "large" in detail,
                    "%s: the 413 says why: %r" % (how, detail))
            wait_idle(t, c, how + " over the limit")
        t.eq(c.health()["status"], "ok", "alive after bodies over the limit")
    finally:
        rc = d.stop()
    t.eq(rc, 0, "the daemon with --max-body-mb 2 stops cleanly")


def main():
    random.seed(1)
    t = lib.Runner()
    d = lib.Daemon(KDRAYD, ["--threads", "2", "--connection-timeout-s", str(TIMEOUT_S)])
    c = Client(d.url)
    try:
        for fn in (test_pieces, test_cut_short, test_length_lies):
            t.run(fn, c)
    finally:
        c.close()
        rc = d.stop()
    if rc != 0:
        print("FAIL kdrayd exited %s\n%s" % (rc, d.log_text()))
        t.failures.append("exit status")
    t.run(test_over_the_limit)
    return t.finish()


if __name__ == "__main__":
    sys.exit(main())

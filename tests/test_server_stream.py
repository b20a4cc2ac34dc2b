#!/usr/bin/env python3
"""test_server_stream.py - streamed answers (Accept: application/cbor-seq).

    test_server_stream.py KDRAYD CLIENTS_DIR [memory]

Needs Debian's python3-cbor2 (run with /usr/bin/python3): a missing module
is a failure, not a skip. Starts kdrayd on the bundled default scene and
checks that a streamed answer (head item, chunk items, final item over
chunked transfer encoding) holds the one-shot CBOR answer's arrays byte for
byte, for bundle closest/any (with fields), frustum closest/any and
cone-shadow (with stats); that a request error is still an ordinary 400
problem+json and a query that cannot stream a 406; that a deadline firing
mid-stream ends the sequence with a 503 problem item after chunk items were
sent (and the Python client raises); and that a client hanging up
mid-stream cancels its query (kdray_cancellations_total); that a bundle
stream reuses its window of result slots (answers unchanged) and that a
client that stops reading stalls its query with no worker inside, still
stopped by its deadline (a final 503 item once read) and by a SIGTERM
(exit 0), and, with no deadline, by the connection timeout
(--connection-timeout-s), which frees its slot and bytes. With
"memory" (ctest server_stream_memory, normal build only: the sanitizers
change RSS): a streamed 1M-ray bundle's peak RSS growth is at least 24 MiB
below the one-piece answer's.
"""

import http.client
import io
import os
import socket
import sys
import time
import urllib.parse

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import test_server_lib as lib  # noqa: E402

KDRAYD, CLIENTS = sys.argv[1], sys.argv[2]
lib.add_client_path(CLIENTS)
import cbor2  # noqa: E402  (python3-cbor2: required, see above)
from kdray_client import (CBOR, CBOR_SEQ, Client, KdrayError,  # noqa: E402
                          _f32_array, cbor_body, random_directions, read_cbor_seq)

SCENE = "default"
PATH = "/v1/scenes/%s/" % SCENE


def post(url, path, payload, accept):
    """(status, headers, body bytes) of one POST with a CBOR body."""
    u = urllib.parse.urlsplit(url)
    conn = http.client.HTTPConnection(u.hostname, u.port, timeout=300)
    try:
        conn.request("POST", path, cbor_body(payload),
                     {"Content-Type": CBOR, "Accept": accept})
        resp = conn.getresponse()
        return resp.status, {k.lower(): v for k, v in resp.getheaders()}, resp.read()
    finally:
        conn.close()


def raw_arrays(answer):
    """A CBOR answer's typed arrays as raw bytes (bit for bit), other
    members as they are."""
    return {k: (v.value if isinstance(v, cbor2.CBORTag) else v)
            for k, v in answer.items()}


def items_of(body):
    """A cbor-seq body's items, typed arrays kept as CBORTag."""
    out = []
    fp = io.BytesIO(body)
    dec = cbor2.CBORDecoder(fp)
    while fp.tell() < len(body):
        out.append(dec.decode())
    return out


def same_as_one_shot(t, d, path, payload, what, min_items=1):
    st1, h1, one = post(d.url, path, payload, CBOR)
    t.eq(st1, 200, what + ": one-shot status")
    st2, h2, seq = post(d.url, path, payload, CBOR_SEQ)
    t.eq(st2, 200, what + ": streamed status")
    t.eq(h2.get("content-type"), CBOR_SEQ, what + ": Content-Type")
    t.eq(h2.get("transfer-encoding"), "chunked", what + ": chunked")
    one = raw_arrays(cbor2.loads(one))
    items = items_of(seq)
    head, chunks, final = items[0], items[1:-1], items[-1]
    t.eq(head.get("count"), one["count"], what + ": head count")
    t.eq(head.get("items"), len(chunks), what + ": head items")
    t.check(len(chunks) >= min_items, "%s: %d chunk items" % (what, len(chunks)))
    t.eq(final.get("status"), 200, what + ": final status")
    t.eq(final.get("items"), len(chunks), what + ": final items")
    t.eq(sorted(final.get("timing", {})), ["parse_us", "queue_us", "trace_us"],
         what + ": timing in the final item")
    joined, at = {}, 0
    for c in chunks:
        t.eq(c["first"], at, what + ": items in order, contiguous")
        at += c["count"]
        for k, v in raw_arrays(c).items():
            if k not in ("first", "count"):
                joined[k] = joined.get(k, b"") + v
    t.eq(at, one["count"], what + ": items cover the answer")
    if "stats" in one:
        t.eq(final.get("stats"), one["stats"], what + ": stats in the final item")
    arrays = {k: v for k, v in one.items() if k not in ("count", "stats")}
    t.eq(sorted(joined), sorted(arrays), what + ": members")
    for k in arrays:
        t.check(joined[k] == arrays[k], "%s: %s differs from the one-shot answer" % (what, k))


def test_equal_to_one_shot(t, d):
    c = Client(d.url, binary=True)
    bounds = c.scene(SCENE)["bounds"]
    org, dirs = lib.rays_into_box(bounds, 9000, seed=3)
    for q in ("closest", "any"):
        same_as_one_shot(t, d, PATH + "bundle",
                         {"origins": org, "directions": dirs, "query": q},
                         "bundle " + q, min_items=3)
    same_as_one_shot(t, d, PATH + "bundle",
                     {"origins": org[:3], "directions": random_directions(5000, 7),
                      "fields": ["t", "normal", "mesh"]}, "bundle fields t,normal,mesh")
    same_as_one_shot(t, d, PATH + "bundle",
                     {"origins": org, "directions": dirs, "query": "any",
                      "fields": ["hit"]}, "bundle any fields hit")
    cam = {"eye": [3, 4, 9], "target": [0, 1, 0], "up": [0, 1, 0], "fov_y_deg": 60,
           "width": 333, "height": 201}
    for q in ("closest", "any"):
        same_as_one_shot(t, d, PATH + "frustum", {"camera": cam, "query": q},
                         "frustum " + q, min_items=20)
    same_as_one_shot(t, d, PATH + "frustum",
                     {"camera": cam, "tile": 16, "fields": ["t", "prim"]},
                     "frustum tile 16 fields t,prim", min_items=10)
    shadow = lib.long_shadow_payload(300)
    shadow["samples"] = 32
    shadow["stats"] = True
    same_as_one_shot(t, d, PATH + "cone-shadow", shadow, "cone-shadow", min_items=4)
    # the Python client's streamed answer is its one-shot answer
    s = Client(d.url, stream=True)
    t.eq(s.bundle(SCENE, org, dirs), c.bundle(SCENE, org, dirs), "client bundle")
    t.eq(s.frustum(SCENE, cam["eye"], cam["target"], 333, 201),
         c.frustum(SCENE, cam["eye"], cam["target"], 333, 201), "client frustum")


def test_window_wraps(t, d):
    """A bundle stream of more chunks than its window of result slots
    (exec: KDR_EXEC_STREAM_WINDOW = 16 chunks): slots are reused, answers
    unchanged."""
    c = Client(d.url, binary=True)
    org, dirs = lib.rays_into_box(c.scene(SCENE)["bounds"], 100000, seed=9)
    for q in ("closest", "any"):
        same_as_one_shot(t, d, PATH + "bundle",
                         {"origins": org, "directions": dirs, "query": q,
                          "tmax": [1e30 if i % 7 else 2.5 for i in range(100000)]},
                         "100K-ray bundle " + q, min_items=25)


def open_stalled_stream(t, url, payload, endpoint="bundle"):
    """A socket with a streamed query sent whose answer it does not read
    (a 32 KiB receive buffer): the stream stalls once the buffers fill."""
    body = cbor_body(payload)
    u = urllib.parse.urlsplit(url)
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 32768)
    sock.settimeout(300)
    sock.connect((u.hostname, u.port))
    sock.sendall(("POST %s%s HTTP/1.1\r\nHost: x\r\nContent-Type: %s\r\n"
                  "Accept: %s\r\nContent-Length: %d\r\n\r\n"
                  % (PATH, endpoint, CBOR, CBOR_SEQ, len(body))).encode() + body)
    got = sock.recv(4096)
    t.check(got.startswith(b"HTTP/1.1 200"), "streaming began: %r" % got[:80])
    return sock, got


def read_chunked(sock, got):
    """The rest of a chunked answer, de-chunked."""
    data = got
    while not data.endswith(b"0\r\n\r\n"):
        more = sock.recv(1 << 20)
        if not more:
            break
        data += more
    sock.close()
    _, _, rest = data.partition(b"\r\n\r\n")
    out = b""
    while rest:
        size, _, rest = rest.partition(b"\r\n")
        k = int(size, 16)
        if k == 0:
            break
        out += rest[:k]
        rest = rest[k + 2:]
    return out


def big_bundle(c, n=1 << 20, **extra):
    _, dirs = lib.rays_into_box(c.scene(SCENE)["bounds"], 4096, seed=11)
    return dict({"origins": [0.0, 3.0, 0.0],
                 "directions": _f32_array(dirs * (n // 4096))}, **extra)


def test_stalled_stream_deadline(t, d):
    """A stalled bundle stream (window full, no worker inside) still stops
    at its deadline: read on, the client gets the traced items and a final
    503 deadline item."""
    c = Client(d.url, binary=True)
    sock, got = open_stalled_stream(t, d.url, big_bundle(c, deadline_ms=1500))
    time.sleep(2.5)
    items = items_of(read_chunked(sock, got))
    t.check(len(items) >= 3, "head, items, final: %d items" % len(items))
    t.eq(items[-1].get("status"), 503, "final item: 503")
    t.check("deadline" in items[-1].get("detail", ""), "deadline: %r" % items[-1])
    t.check(sum(i.get("count", 0) for i in items[1:-1]) < 1 << 20,
            "stopped before the end")


def test_shutdown_with_stalled_stream(t):
    """SIGTERM while a stream stalls: the daemon stops its query and exits
    0 (the grace period, then the executor's shutdown)."""
    d = lib.Daemon(KDRAYD, ["--threads", "2", "--shutdown-grace-s", "1"])
    try:
        c = Client(d.url, binary=True)
        sock, _ = open_stalled_stream(t, d.url, big_bundle(c))
        time.sleep(0.5)
        t0 = time.time()
        d.signal()
        rc = d.wait(60)
        t.eq(rc, 0, "exit status")
        t.check(time.time() - t0 < 30, "exited in %.1f s" % (time.time() - t0))
        sock.close()
    finally:
        d.stop()


def test_slow_reader_holds_workers(t, d):
    """A client that stops reading a bundle stream stalls its query once the
    window of result slots is full: the query stays running with no worker
    inside (its memory is the window, not the batch); reading on finishes
    it."""
    c = Client(d.url, binary=True)
    sock, got = open_stalled_stream(t, d.url, big_bundle(c))
    stalled, deadline = False, time.time() + 120
    while time.time() < deadline and not stalled:
        m = c.metrics()
        stalled = (lib.metric(m, "kdray_queries", state="running") == 1 and
                   lib.metric(m, "kdray_workers_busy") == 0)
        time.sleep(0.1)
    t.check(stalled, "a stalled reader leaves its query running with no worker inside")
    items = items_of(read_chunked(sock, got))
    t.eq(items[-1].get("status"), 200, "the stalled stream ends whole")
    t.eq(sum(i.get("count", 0) for i in items[1:-1]), 1 << 20, "every ray answered")


def free_after_timeout(t, c, what, limit_s):
    """Polls /metrics until nothing is charged, admitted or in flight but
    this scrape; returns the seconds it took (t.check fails past limit_s)."""
    t0 = time.time()
    m = c.metrics()
    while time.time() - t0 < limit_s:
        m = c.metrics()
        if (lib.metric(m, "kdray_inflight_bytes") == 0 and
                lib.metric(m, "kdray_queries", state="running") == 0 and
                lib.metric(m, "kdray_queries", state="receiving") == 0 and
                lib.metric(m, "kdray_workers_busy") == 0 and
                lib.metric(m, "kdray_http_requests_in_flight") == 1):
            return time.time() - t0
        time.sleep(0.1)
    t.check(False, "%s: still held %.0f s later: inflight bytes %s, running %s, "
            "receiving %s, busy %s, requests in flight %s"
            % (what, limit_s, lib.metric(m, "kdray_inflight_bytes"),
               lib.metric(m, "kdray_queries", state="running"),
               lib.metric(m, "kdray_queries", state="receiving"),
               lib.metric(m, "kdray_workers_busy"),
               lib.metric(m, "kdray_http_requests_in_flight")))
    return None


def freed_and_cut(t, c, sock, kind, within_s):
    """A stalled <kind> stream's slot and bytes come back, and the daemon
    closes its connection mid-answer, both within within_s seconds."""
    what = "stalled %s stream" % kind
    took = free_after_timeout(t, c, what, within_s)
    print("%s: freed %.1f s after it stalled" % (what, took)
          if took is not None else "%s: not freed" % what)
    t.check(cut_by_daemon(sock, within_s),
            "the daemon closed the stalled %s stream mid-answer" % kind)


def cut_by_daemon(sock, limit_s):
    """Reads what the daemon had sent on a stalled stream's socket: True if
    it ends in EOF (or a reset) before the chunked body's last chunk, so the
    daemon closed the connection in the middle of the answer."""
    sock.settimeout(limit_s)
    data = b""
    try:
        while True:
            more = sock.recv(1 << 20)
            if not more:
                break
            data += more
    except ConnectionResetError:
        pass
    except socket.timeout:
        return False
    finally:
        sock.close()
    return not data.endswith(b"\r\n0\r\n\r\n")


def test_stalled_stream_timeout(t):
    """A client that reads a streamed answer's head and then stops reading,
    keeping its connection open, with no deadline: the connection timeout
    (--connection-timeout-s 2 here, 60 by default) closes it and frees
    everything it held: a stalled bundle stream (window full, no worker
    inside) is cancelled, its slot and in-flight bytes returned; a frustum
    stream whose query had finished (its answer too big for the socket
    buffers) returns its bytes. Workers stay free for other queries
    meanwhile, and a later query is answered."""
    timeout_s = 2
    d = lib.Daemon(KDRAYD, ["--threads", "2", "--max-rays", "67108864",
                            "--connection-timeout-s", str(timeout_s)])
    try:
        c = Client(d.url, binary=True)
        t.check("idle timeout 2 s" in d.log_text(), "the start-up line names the timeout")
        cancels = lib.metric(c.metrics(), "kdray_cancellations_total")
        # the bundle: stalls with its window full
        sock, _ = open_stalled_stream(t, d.url, big_bundle(c))
        stalled, t0 = False, time.time()
        while time.time() - t0 < 60 and not stalled:
            m = c.metrics()
            stalled = (lib.metric(m, "kdray_queries", state="running") == 1 and
                       lib.metric(m, "kdray_workers_busy") == 0 and
                       lib.metric(m, "kdray_inflight_bytes") > 0)
            time.sleep(0.05)
        t.check(stalled, "the bundle stream stalled: running, no worker, bytes held")
        # the workers are free while it stalls
        t.eq(len(Client(d.url).bundle(SCENE, [0, 3, 0], [0, -1, 0])["t"]), 1,
             "a query answered beside the stalled stream")
        freed_and_cut(t, c, sock, "bundle", 10 * timeout_s)
        t.eq(lib.metric(c.metrics(), "kdray_cancellations_total"), cancels + 1,
             "the stalled bundle query was cancelled")
        # the frustum: finished while its answer waits in the connection
        cam = {"eye": [3, 4, 9], "target": [0, 1, 0], "up": [0, 1, 0],
               "fov_y_deg": 60, "width": 1024, "height": 1024}
        sock, _ = open_stalled_stream(t, d.url, {"camera": cam, "fields": ["t", "normal"]},
                                      endpoint="frustum")
        time.sleep(0.5)
        t.check(lib.metric(c.metrics(), "kdray_inflight_bytes") > 0,
                "the stalled frustum stream holds its bytes")
        freed_and_cut(t, c, sock, "frustum", 10 * timeout_s)
        s = Client(d.url, stream=True)
        t.eq(len(s.bundle(SCENE, [0, 3, 0], random_directions(5000, 3))["t"]), 5000,
             "a streamed query after the timeouts")
    finally:
        rc = d.stop()
    t.eq(rc, 0, "kdrayd exit status")


def test_errors_before_streaming(t, d):
    st, h, body = post(d.url, PATH + "bundle", {"origins": [0, 0, 0],
                                                "directions": [1, 2]}, CBOR_SEQ)
    t.eq(st, 400, "bad directions: 400")
    t.eq(h.get("content-type"), "application/problem+json", "problem+json")
    t.check(b"directions" in body, "the problem names the field: %r" % body)
    st, h, body = post(d.url, PATH + "bundle", {"origins": [0, 0, 0],
                                                "directions": [1, 2, 3],
                                                "query": "count"}, CBOR_SEQ)
    t.eq(st, 406, "count cannot stream: 406")
    t.check(b"application/cbor" in body, "406 says what to ask: %r" % body)
    st, _, _ = post(d.url, PATH + "closest-point", {"points": [0, 0, 0]}, CBOR_SEQ)
    t.eq(st, 406, "closest-point cannot stream: 406")
    s = Client(d.url, stream=True)
    try:
        s.bundle(SCENE, [0, 0, 0], [1, 2])
        t.check(False, "the client raises on a 400")
    except KdrayError as err:
        t.eq(err.status, 400, "client: 400")


def test_deadline_mid_stream(t, d):
    """A deadline that fires after the head went out: chunk items, then a
    503 problem item; the client raises after yielding them."""
    s = Client(d.url, stream=True)
    seen = []
    for deadline in (300, 1000, 3000):
        payload = lib.long_shadow_payload(2000)
        payload["deadline_ms"] = deadline
        got, err = [], None
        try:
            for item in s.stream_query(PATH + "cone-shadow", payload):
                got.append(item)
        except KdrayError as e:
            err = e
        seen.append((deadline, len(got), err and err.status))
        if err is not None and err.status == 503 and len(got) >= 2:
            t.check("kind" in got[0], "the head came first")
            t.check("deadline" in err.problem.get("detail", ""),
                    "the final item says deadline: %r" % err.problem)
            t.eq(err.problem.get("type"), "about:blank", "problem details item")
            return
    t.check(False, "no deadline fired mid-stream: %r" % (seen,))


def test_hang_up_cancels(t, d):
    c = Client(d.url)
    before = lib.metric(c.metrics(), "kdray_cancellations_total")
    u = urllib.parse.urlsplit(d.url)
    body = cbor_body(lib.long_shadow_payload(4000))
    sock = socket.create_connection((u.hostname, u.port), timeout=60)
    sock.sendall(("POST %scone-shadow HTTP/1.1\r\nHost: x\r\nContent-Type: %s\r\n"
                  "Accept: %s\r\nContent-Length: %d\r\n\r\n"
                  % (PATH, CBOR, CBOR_SEQ, len(body))).encode() + body)
    got = b""
    while b"\r\n\r\n" not in got or len(got) < 200:
        more = sock.recv(4096)
        if not more:
            break
        got += more
    t.check(got.startswith(b"HTTP/1.1 200"), "streaming began: %r" % got[:80])
    sock.close()
    deadline = time.time() + 20
    now = before
    while time.time() < deadline and now < before + 1:
        time.sleep(0.05)
        now = lib.metric(c.metrics(), "kdray_cancellations_total")
    t.eq(now, before + 1, "the hang-up cancelled the query")
    # the daemon is fine afterwards
    t.eq(len(Client(d.url, stream=True).bundle(SCENE, [0, 3, 0], [0, -1, 0])["t"]), 1,
         "a query after the hang-up")


def test_reader_of_cut_sequence(t, d):
    """A sequence without its final item fails in the client."""
    from kdray_client import stream_items
    st, _, seq = post(d.url, PATH + "bundle",
                      {"origins": [0, 3, 0], "directions": random_directions(5000, 2)},
                      CBOR_SEQ)
    t.eq(st, 200, "status")
    full = list(read_cbor_seq(io.BytesIO(seq)))
    t.eq(len(full), 4, "head, two chunks, final")
    for cut in (len(seq) - 1, len(seq) // 2):
        try:
            list(stream_items(read_cbor_seq(io.BytesIO(seq[:cut]))))
            t.check(False, "a cut sequence (%d of %d bytes) must raise" % (cut, len(seq)))
        except (KdrayError, EOFError, ValueError):
            pass
    try:
        list(stream_items(full[:-1]))
        t.check(False, "a sequence without its final item must raise")
    except KdrayError as err:
        t.eq(err.status, 0, "incomplete: status 0")


def vm_mib(pid, field):
    with open("/proc/%d/status" % pid) as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024.0
    raise RuntimeError("no %s in /proc/%d/status" % (field, pid))


def test_peak_rss(t):
    """A 1M-ray closest bundle (CBOR, one origin: a 12 MiB body) raises
    kdrayd's peak RSS by its body and its result arrays (16 MiB) in one
    piece, whose answer is sent from the arrays where the core wrote them
    (exec/'s answer in pieces; until stop 26 it was copied into a 16 MiB
    buffer first: 48 MiB of growth); streamed, by its body and a window of
    16 chunks (1 MiB). Each in a fresh daemon (VmHWM over VmRSS)."""
    n = 1 << 20
    growth = {}
    for accept in (CBOR, CBOR_SEQ):
        d = lib.Daemon(KDRAYD, ["--threads", "2"])
        try:
            c = Client(d.url, binary=True)
            _, dirs = lib.rays_into_box(c.scene(SCENE)["bounds"], 4096, seed=4)
            payload = {"origins": [0.0, 3.0, 0.0],
                       "directions": _f32_array(dirs * (n // 4096))}
            base = vm_mib(d.proc.pid, "VmRSS")
            st, _, body = post(d.url, PATH + "bundle", payload, accept)
            t.eq(st, 200, accept + ": status")
            growth[accept] = vm_mib(d.proc.pid, "VmHWM") - base
        finally:
            d.stop()
    print("peak RSS growth, 1M-ray closest bundle: one piece %.1f MiB, streamed "
          "%.1f MiB" % (growth[CBOR], growth[CBOR_SEQ]))
    t.check(growth[CBOR] <= 12 + 16 + 8,
            "one piece holds the body and the result arrays, no copy of the "
            "answer (<= 36 MiB): %r" % growth)
    t.check(growth[CBOR_SEQ] + 12 <= growth[CBOR],
            "streamed saves the result arrays (>= 12 of 16 MiB): %r" % growth)


def main():
    if sys.argv[3:] == ["memory"]:
        t = lib.Runner()
        t.run(test_peak_rss)
        return t.finish()
    t = lib.Runner()
    d = lib.Daemon(KDRAYD, ["--threads", "2", "--max-rays", "67108864"])
    try:
        t.run(test_equal_to_one_shot, d)
        t.run(test_window_wraps, d)
        t.run(test_slow_reader_holds_workers, d)
        t.run(test_stalled_stream_deadline, d)
        t.run(test_errors_before_streaming, d)
        t.run(test_deadline_mid_stream, d)
        t.run(test_hang_up_cancels, d)
        t.run(test_reader_of_cut_sequence, d)
    finally:
        rc = d.stop()
    t.eq(rc, 0, "kdrayd exit status")
    t.run(test_shutdown_with_stalled_stream)
    t.run(test_stalled_stream_timeout)
    return t.finish()


if __name__ == "__main__":
    sys.exit(main())

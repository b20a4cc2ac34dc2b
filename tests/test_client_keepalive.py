#!/usr/bin/env python3
"""test_client_keepalive.py - clients/kdray_client.py keeps its connection.

    test_client_keepalive.py KDRAYD CLIENTS_DIR

Needs Debian's python3-cbor2 (run with /usr/bin/python3; a missing module
is a failure, not a skip). A Client talks to a real kdrayd through a small
TCP relay in this file that counts the connections it accepts and can
close them, cut an answer short or refuse new ones, so each check counts
connections instead of trusting the client's word. Checked: many requests
of every kind (JSON, CBOR, streamed, error answers) on one Client use one
connection, one per thread when threads share it, and close() closes
them; a kept connection the server closed while idle (the relay dropping
it, kdrayd's own --connection-timeout-s, a kdrayd restarted on the same
port) is replaced once, transparently; a failure after part of an answer
arrived, on a new connection, or of a request whose body was read from an
iterable (sent chunked, cannot be sent twice) is raised and not retried;
a streamed
answer abandoned mid-way closes its connection and the next request gets
a right answer on a new one, while one read to its end leaves its
connection for the next request.
"""

import os
import socket
import sys
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import test_server_lib as lib  # noqa: E402

KDRAYD, CLIENTS = sys.argv[1], sys.argv[2]
lib.add_client_path(CLIENTS)
import cbor2  # noqa: E402,F401  (python3-cbor2: required, see above)
from kdray_client import Client, KdrayError  # noqa: E402

SCENE = "default"
CAM = {"eye": [3, 4, 9], "target": [0, 1, 0], "up": [0, 1, 0], "fov_y_deg": 60,
       "width": 333, "height": 201}
FRUSTUM = "/v1/scenes/%s/frustum" % SCENE


class Relay:
    """127.0.0.1:port -> kdrayd, byte for byte, one thread per direction.
    accepted: connections accepted so far; live(): those still open."""

    def __init__(self, target_url):
        host, port = target_url.split("//")[1].rsplit(":", 1)
        self.target = (host, int(port))
        self.lsock = socket.create_server(("127.0.0.1", 0))
        self.url = "http://127.0.0.1:%d" % self.lsock.getsockname()[1]
        self.lock = threading.Lock()
        self.accepted = 0
        self.pairs = set()
        self.refuse = False   # close every new connection at once
        self.budget = None    # answer bytes still passed before a cut
        self.kill = False     # drop a connection when its next request comes
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self):
        while True:
            try:
                s, _ = self.lsock.accept()
            except OSError:
                return
            with self.lock:
                self.accepted += 1
            if self.refuse:
                s.close()
                continue
            u = socket.create_connection(self.target)
            pair = (s, u)
            with self.lock:
                self.pairs.add(pair)
            threading.Thread(target=self._pipe, args=(s, u, pair, False),
                             daemon=True).start()
            threading.Thread(target=self._pipe, args=(u, s, pair, True),
                             daemon=True).start()

    def _pipe(self, src, dst, pair, answer):
        try:
            while True:
                data = src.recv(65536)
                if not data:
                    break
                with self.lock:
                    kill = self.kill and not answer
                    self.kill = self.kill and not kill
                    budget = self.budget if answer else None
                if kill:
                    break  # nothing forwarded: kdrayd never saw the request
                with self.lock:
                    if budget is not None:
                        data = data[:budget]
                        self.budget = budget - len(data)
                dst.sendall(data)
                if budget is not None and self.budget == 0:
                    break
        except OSError:
            pass
        self._drop(pair)

    def _drop(self, pair):
        with self.lock:
            self.pairs.discard(pair)
        for sock in pair:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            sock.close()

    def drop_all(self):
        """Closes every open connection, as a server closing idle ones."""
        with self.lock:
            pairs = list(self.pairs)
        for pair in pairs:
            self._drop(pair)

    def live(self, want, timeout=5.0):
        """The number of open connections, once it equals want (or at the
        timeout: the two pipe threads notice a close asynchronously)."""
        deadline = time.time() + timeout
        while True:
            with self.lock:
                n = len(self.pairs)
            if n == want or time.time() > deadline:
                return n
            time.sleep(0.01)

    def close(self):
        self.lsock.close()
        self.drop_all()


def mixed_requests(c, b, s):
    """One of each kind of request, on JSON, binary and stream clients."""
    c.health()
    c.scenes()
    r = c.bundle(SCENE, [0, 3, 0], [0, -1, 0, 1, 0, 0])
    assert len(r["t"]) == 2, r
    c.frustum(SCENE, CAM["eye"], CAM["target"], 64, 48)
    try:
        c.call("POST", "/v1/scenes/%s/bundle" % SCENE, {"origins": [0, 0]})
        raise AssertionError("400 expected")
    except KdrayError as err:
        assert err.status == 400, err
    c.metrics()
    b.bundle(SCENE, [0, 3, 0], [0, -1, 0], fields=["t"])
    s.frustum(SCENE, CAM["eye"], CAM["target"], 333, 201)


def test_one_connection(t, d):
    relay = Relay(d.url)
    try:
        c = Client(relay.url)
        b = Client(relay.url, binary=True)
        s = Client(relay.url, stream=True)
        for _ in range(5):
            mixed_requests(c, b, s)
        t.eq(relay.accepted, 3, "40 requests on 3 Clients: connections accepted")
        t.eq(relay.live(3), 3, "kept connections open between requests")
        for x in (c, b, s):
            x.close()
        t.eq(relay.live(0), 0, "close() closed them")
        c.health()
        t.eq(relay.accepted, 4, "a request after close() opens a new one")
        with Client(relay.url) as w:
            for _ in range(10):
                w.health()
        t.eq(relay.accepted, 5, "10 requests in a with block: one connection")
        t.eq(relay.live(1), 1, "leaving the with block closed it (c's is left)")
        # an answer saying "Connection: close" (kdrayd's 404s do, through
        # libmicrohttpd) is read whole, then the next request reconnects
        before = relay.accepted
        status, hdrs, _ = c.request("GET", "/v1/scenes/no-such-scene")
        t.eq(status, 404, "no such scene")
        closes = {k.lower(): v for k, v in hdrs.items()}.get("connection") == "close"
        t.eq(c.health()["status"], "ok", "the request after a 404")
        t.eq(relay.accepted - before, 1 if closes else 0,
             "connections after a 404 (Connection: close: %s)" % closes)
        c.close()
        # threads sharing a Client: one connection each, answers right
        errors = []
        shared = Client(relay.url)

        def work(seed):
            try:
                for i in range(8):
                    r = shared.bundle(SCENE, [0, 3, 0], [0, -1, 0] * (seed + i + 1))
                    assert len(r["t"]) == seed + i + 1, r
            except Exception as err:  # reported by the main thread
                errors.append(repr(err))
        before = relay.accepted
        threads = [threading.Thread(target=work, args=(k,)) for k in range(3)]
        for th in threads:
            th.start()
        for th in threads:
            th.join()
        t.eq(errors, [], "shared Client: thread errors")
        t.eq(relay.accepted - before, 3, "3 threads x 8 requests: connections")
        shared.close()
        t.eq(relay.live(0), 0, "close() closed every thread's connection")
    finally:
        relay.close()


def test_idle_closed(t, d):
    relay = Relay(d.url)
    try:
        c = Client(relay.url)
        c.health()
        relay.drop_all()
        relay.live(0)
        t.eq(c.bundle(SCENE, [0, 3, 0], [0, -1, 0])["prim"] != [-1], True,
             "answer after the server closed the idle connection")
        t.eq(relay.accepted, 2, "reconnected once")
        # closed at the moment the request came (the client's idle check
        # saw nothing): sent again on a new connection
        relay.kill = True
        t.eq(c.health()["status"], "ok", "a request whose connection closed under it")
        t.eq(relay.accepted, 3, "its retry's connection")
        # the same with a big body: a 1M-ray bundle's send meets the close
        n = 1 << 20
        b = Client(relay.url, binary=True, lists=False)
        b.health()
        relay.kill = True
        r = b.bundle(SCENE, [0, 3, 0], [0, -1, 0] * n, fields=["t"])
        t.eq(len(r["t"]), n, "1M-ray CBOR bundle after its connection closed")
        t.check(r["t"][0] > 0 and r["t"][n - 1] == r["t"][0], "its answers")
        t.eq(relay.accepted, 5, "b's connection, then its retry's")
        # a body read from an iterable (sent chunked) cannot be sent twice:
        # its request is not retried
        def parts():
            return iter([b'{"origins": [0, 3, 0], ', b'"directions": [0, -1, 0]}'])
        bundle = "/v1/scenes/%s/bundle" % SCENE
        chunked = {"Transfer-Encoding": "chunked"}
        status, _, body = c.request("POST", bundle, parts(), headers=chunked)
        t.eq(status, 200, "chunked body: %r" % body[:200])
        before = relay.accepted
        relay.kill = True
        try:
            c.request("POST", bundle, parts(), headers=chunked)
            t.check(False, "an iterable body's request was retried")
        except OSError:
            pass
        t.eq(relay.accepted, before, "iterable body: no new connection")
        # a failure after part of an answer arrived: raised, not retried
        c.health()
        before = relay.accepted
        relay.budget = 40  # the status line and part of a header
        try:
            c.scenes()
            t.check(False, "an answer cut after 40 bytes raised nothing")
        except AssertionError:
            raise
        except Exception:  # noqa: BLE001 (http.client's or json's error)
            pass
        relay.budget = None
        t.eq(relay.accepted, before, "cut answer: no new connection (no retry)")
        t.eq(c.health()["status"], "ok", "next request after the cut")
        # a kept connection closed under its request and the server
        # refusing new ones: one retry, then the error
        relay.refuse = True
        relay.kill = True
        before = relay.accepted
        try:
            c.health()
            t.check(False, "no error while every connection is refused")
        except OSError:
            pass
        t.eq(relay.accepted - before, 1, "closed, then one new connection tried")
        before = relay.accepted
        try:
            c.health()
            t.check(False, "no error on a new connection closed at once")
        except OSError:
            pass
        t.eq(relay.accepted - before, 1, "a new connection's failure is not retried")
        relay.refuse = False
        t.eq(c.health()["status"], "ok", "after the server accepts again")
    finally:
        relay.close()


def test_server_idle_timeout(t, kdrayd):
    """kdrayd's own idle close (--connection-timeout-s 1), no relay."""
    d = lib.Daemon(kdrayd, ["--connection-timeout-s", "1"])
    try:
        c = Client(d.url)
        c.health()
        time.sleep(2.5)
        t.eq(c.health()["status"], "ok", "answer after kdrayd closed the idle connection")
        t.eq(len(c.bundle(SCENE, [0, 3, 0], [0, -1, 0] * 10)["t"]), 10,
             "a bundle on the same Client")
    finally:
        d.stop()


def test_restart(t, kdrayd):
    d = lib.Daemon(kdrayd)
    port = d.url.rsplit(":", 1)[1]
    c = Client(d.url)
    want = c.bundle(SCENE, [0, 3, 0], [0, -1, 0, 1, 0, 0])
    t.eq(d.stop(), 0, "first kdrayd exit status")
    d = lib.Daemon(kdrayd, ["--listen", "127.0.0.1:" + port])
    try:
        t.eq(d.url, c.url, "restarted on the same address")
        t.eq(c.bundle(SCENE, [0, 3, 0], [0, -1, 0, 1, 0, 0]), want,
             "the same Client's answer from the restarted kdrayd")
    finally:
        d.stop()


def test_stream_abandoned(t, d):
    relay = Relay(d.url)
    try:
        c = Client(relay.url, binary=True)
        whole = list(c.stream_query(FRUSTUM, {"camera": CAM}))
        t.check(len(whole) >= 5, "frustum stream items: %d" % len(whole))
        t.eq(relay.accepted, 1, "a stream read to its end")
        want = c.frustum(SCENE, CAM["eye"], CAM["target"], 333, 201)
        t.eq(relay.accepted, 1, "the request after it reused its connection")
        # closed early: the connection goes, the next request is right
        gen = c.stream_query(FRUSTUM, {"camera": CAM})
        next(gen)
        next(gen)
        gen.close()
        t.eq(relay.live(0), 0, "the abandoned stream's connection closed")
        t.eq(c.frustum(SCENE, CAM["eye"], CAM["target"], 333, 201), want,
             "the frustum after an abandoned stream")
        t.eq(relay.accepted, 2, "it opened one new connection")
        # dropped early while another request runs on the same thread
        gen = c.stream_query(FRUSTUM, {"camera": CAM})
        next(gen)
        t.eq(c.frustum(SCENE, CAM["eye"], CAM["target"], 333, 201), want,
             "a request while a stream is half read")
        del gen
        t.eq(c.frustum(SCENE, CAM["eye"], CAM["target"], 333, 201), want,
             "after the half-read stream was dropped")
        t.eq(relay.accepted, 3, "the half-read stream's connection was not reused")
        t.eq(relay.live(1), 1, "only the kept connection stays open")
    finally:
        relay.close()


def main():
    t = lib.Runner()
    d = lib.Daemon(KDRAYD)
    try:
        t.run(test_one_connection, d)
        t.run(test_idle_closed, d)
        t.run(test_stream_abandoned, d)
    finally:
        d.stop()
    t.run(test_server_idle_timeout, KDRAYD)
    t.run(test_restart, KDRAYD)
    return t.finish()


if __name__ == "__main__":
    sys.exit(main())

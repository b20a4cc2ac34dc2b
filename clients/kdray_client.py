#!/usr/bin/env python3
"""kdray_client.py - a client for the kdray HTTP API.

In its default JSON mode only the standard library (http.client, struct,
base64, json) is used, so the file can be copied anywhere next to a running kdrayd.
Its binary mode (Client(url, binary=True), --binary) sends and receives
application/cbor with float arrays as RFC 8746 typed arrays (raw
little-endian float32, no text conversion at all); it needs Debian's
python3-cbor2 (apt-get install python3-cbor2; run /usr/bin/python3 if
another Python comes first on PATH). As a module:

    from kdray_client import Client
    c = Client("http://127.0.0.1:8080")
    r = c.bundle("default", origins=[0, 0, 0], directions=[0, 0, -1, 1, 0, 0])
    print(r["t"], r["prim"])
    b = Client("http://127.0.0.1:8080", binary=True)
    r = b.bundle("default", [0, 0, 0], [0, 0, -1], fields=["t"])

Answers come back with every array decoded to a Python list, whatever the
wire encoding was, unless a binary client is made with lists=False: then
its typed arrays stay array.array objects (float32 "f", int32 "i", uint8
"B"), read at memory speed, where a list costs a Python object per value
(a 1M-ray closest answer, 16.8 MB: about 80 ms to decode into lists, a
few ms into arrays; numpy.frombuffer(a, numpy.float32) views one without
a copy). HTTP errors raise KdrayError carrying the status and the
problem+json body (errors are problem+json in binary mode too).

As a command (see --help):

    kdray_client.py --url http://127.0.0.1:8080 scenes
    kdray_client.py ready          # exit 1 and the problem while not ready
    kdray_client.py bundle --origin 0,0,5 --random 1000 --encoding base64
    kdray_client.py shadow --point 0,0,0 --light 10,10,10,1 --samples 64
    kdray_client.py frustum --eye 0,0,5 --target 0,0,0 --width 320 --height 240 \\
        --pgm depth.pgm
    kdray_client.py --binary bundle --random 100000 --fields t
    kdray_client.py --stream frustum --eye 0,0,5 --target 0,0,0 --width 1024 \\
        --height 1024   # the answer streamed while later chunks trace

A Client keeps its HTTP/1.1 connection open between requests (one per
thread that uses it) and closes it on close() or at the end of a with
block; see Client for when it reconnects.
"""

import argparse
import array
import base64
import http.client
import json
import math
import random
import struct
import select
import sys
import threading
import urllib.parse
import weakref

DEFAULT_URL = "http://127.0.0.1:8080"
DEFAULT_TIMEOUT_S = 120.0
CBOR = "application/cbor"
CBOR_SEQ = "application/cbor-seq"  # RFC 8742: a streamed answer's items
JSON = "application/json"
# RFC 8746 typed-array tags: element type and the array typecode holding it
TYPED_ARRAYS = {85: "f", 78: "i", 64: "B"}  # float32 LE, int32 LE, uint8


class KdrayError(Exception):
    """An HTTP error answer; .status is the code, .problem the parsed body,
    .retry_after the Retry-After seconds of a 503 that a retry may cure
    (None otherwise: a deadline, a shutdown, a bad request)."""

    def __init__(self, status, problem, retry_after=None):
        self.status = status
        self.problem = problem if isinstance(problem, dict) else {"detail": problem}
        self.retry_after = retry_after
        super().__init__("HTTP %d: %s" % (status, self.problem.get("detail", "")))


def f32_b64(values):
    """The {"f32": base64} form of a float array (little-endian float32)."""
    data = struct.pack("<%df" % len(values), *values)
    return {"f32": base64.b64encode(data).decode("ascii")}


def _decode(value, code):
    raw = base64.b64decode(value, validate=True)
    return list(struct.unpack("<%d%s" % (len(raw) // 4, code), raw))


def decode_array(value):
    """A response array in either encoding, as a list of numbers."""
    if isinstance(value, dict):
        if "f32" in value:
            return _decode(value["f32"], "f")
        if "i32" in value:
            return _decode(value["i32"], "i")
        raise ValueError("unknown array encoding: %r" % list(value))
    return list(value)


def decode_answer(answer):
    """Decodes every base64 array of a query answer in place."""
    for key, value in list(answer.items()):
        if isinstance(value, dict) and ("f32" in value or "i32" in value):
            answer[key] = decode_array(value)
    return answer


def _floats(values, send):
    if send == "cbor":
        return _f32_array(values)
    values = [float(x) for x in values]
    return f32_b64(values) if send == "base64" else values


# ---- binary mode (CBOR) --------------------------------------------------------

def _cbor2():
    try:
        import cbor2  # noqa: PLC0415 (only binary mode needs it)
    except ImportError as err:
        raise RuntimeError("binary mode needs python3-cbor2 (Debian: apt-get install "
                           "python3-cbor2; run /usr/bin/python3)") from err
    return cbor2


def _f32_array(values):
    """values as an array('f') of little-endian float32."""
    a = array.array("f", (float(x) for x in values))
    if sys.byteorder != "little":
        a.byteswap()
    return a


def _head(major, n):
    """A CBOR head: major type and argument n, in the shortest form."""
    if n < 24:
        return bytes([major << 5 | n])
    for extra, fmt in ((24, ">B"), (25, ">H"), (26, ">I"), (27, ">Q")):
        if n < 1 << (8 * struct.calcsize(fmt)):
            return bytes([major << 5 | extra]) + struct.pack(fmt, n)
    raise ValueError("CBOR argument too large: %d" % n)


def cbor_body(payload):
    """A request map as CBOR bytes. array('f') values become float32 typed
    arrays (tag 85 over their little-endian bytes, as _f32_array makes
    them) whose bytes start at a multiple of 4 from the body's start, so
    kdrayd reads them in place; that takes a padding member ("_pad0",
    "_pad1", ...: unknown members are ignored) before an array that would
    otherwise be misaligned. An array's bytes are copied once, into the
    body (a 1M-ray bundle's 12 MiB of directions; encoding it through
    cbor2 and concatenating copied them four times)."""
    cbor2 = _cbor2()
    parts = [b""]  # the map head, once the members are counted
    members = 0
    offset = 1     # the map head (fewer than 24 members)
    for key, value in payload.items():
        k = cbor2.dumps(key)
        if isinstance(value, array.array):
            data = memoryview(value).cast("B")
            head = b"\xd8\x55" + _head(2, len(data))  # tag 85, byte string
            start = offset + len(k) + len(head)
            if start % 4:
                pad_key = cbor2.dumps("_pad%d" % members)
                # pad member: key, then a text head (1 byte) and n characters
                n = (4 - (start + len(pad_key) + 1) % 4) % 4
                pad = pad_key + cbor2.dumps("x" * n)
                parts.append(pad)
                members += 1
                offset += len(pad)
            parts += [k, head, data]
            offset += len(k) + len(head) + len(data)
        else:
            v = cbor2.dumps(value)
            parts.append(k + v)
            offset += len(k) + len(v)
        members += 1
    if members >= 24:
        raise ValueError("cbor_body: too many members")
    parts[0] = bytes([0xA0 + members])
    return b"".join(parts)


def _typed_array(tag):
    """An RFC 8746 typed-array tag as an array.array (native byte order), or
    None for any other tag."""
    code = TYPED_ARRAYS.get(tag.tag)
    if code is None or not isinstance(tag.value, bytes):
        return None
    a = array.array(code)
    a.frombytes(tag.value)
    if sys.byteorder != "little" and code != "B":
        a.byteswap()
    return a


def _typed_hook(decoder, tag):
    """cbor2 tag hook: RFC 8746 typed arrays to lists of numbers."""
    a = _typed_array(tag)
    return tag if a is None else a.tolist()


def _typed_hook_arrays(decoder, tag):
    """cbor2 tag hook: RFC 8746 typed arrays to array.array objects."""
    a = _typed_array(tag)
    return tag if a is None else a


def _hook(lists):
    return _typed_hook if lists else _typed_hook_arrays


def decode_cbor(data, lists=True):
    """A CBOR answer as a dict with typed arrays decoded to lists (lists=False:
    to array.array objects, no Python object per value)."""
    return _cbor2().loads(data, tag_hook=_hook(lists))


def read_cbor_seq(fp, lists=True):
    """The items of an application/cbor-seq body read from the file-like fp,
    one at a time as they arrive (typed arrays decoded to lists, or with
    lists=False to array.array objects). Stops at the end of fp; a cut item
    raises the decoder's EOFError."""
    cbor2 = _cbor2()
    decoder = cbor2.CBORDecoder(fp, tag_hook=_hook(lists))
    while True:
        first = fp.read(1)
        if not first:
            return
        # the byte read to see the end is the item's first: decode from it
        decoder.fp = _Prefixed(first, fp)
        yield decoder.decode()


class _Prefixed:
    """fp with bytes put back in front of it (for read_cbor_seq)."""

    def __init__(self, prefix, fp):
        self.prefix, self.fp = prefix, fp

    def read(self, n=-1):
        if not self.prefix:
            return self.fp.read(n)
        head, self.prefix = self.prefix[:n], self.prefix[n:]
        if len(head) < n:
            head += self.fp.read(n - len(head))
        return head


def stream_items(items):
    """Checks a streamed answer's items (head, chunk items, final item) and
    yields them: the head first, then each chunk item ({"first", "count",
    arrays} of rays first..first+count-1), then the final {"status": 200,
    ...} item. A final problem item raises KdrayError with it, after the
    chunks before it were yielded; a sequence without its final item raises
    KdrayError(0, ...): the answer is incomplete."""
    items = iter(items)
    head = next(items, None)
    if not isinstance(head, dict) or "kind" not in head:
        raise KdrayError(0, "streamed answer: no head item")
    yield head
    for item in items:
        if isinstance(item, dict) and "status" in item:
            if item["status"] != 200:
                raise KdrayError(item["status"], item)
            yield item
            return
        yield item
    raise KdrayError(0, "streamed answer cut before its final item")


def assemble_stream(items):
    """The one-shot answer from a streamed answer's items: the chunk items'
    arrays appended in order (lists, or array.array objects when the items
    hold those), "count" from the head, the cone-shadow "stats" from the
    final item."""
    answer, final, count = {}, None, None
    for item in stream_items(items):
        if "kind" in item:
            count = item["count"]
        elif "status" in item:
            final = item
        else:
            for key, value in item.items():
                if key not in ("first", "count"):
                    empty = (array.array(value.typecode)
                             if isinstance(value, array.array) else [])
                    answer.setdefault(key, empty).extend(value)
    answer["count"] = count
    if final and "stats" in final:
        answer["stats"] = final["stats"]
    return answer


class _NoAnswer(Exception):
    """The connection failed before the first byte of an answer arrived (the
    server had closed it, or reset it): the request may be sent again."""


class _Response(http.client.HTTPResponse):
    """An answer that tells "nothing arrived" (_NoAnswer) apart from a failure
    after its first byte, which is never retried."""

    def begin(self):
        try:
            first = self.fp.peek(1)
        except ConnectionError as err:
            raise _NoAnswer(err) from err
        if not first:
            raise _NoAnswer("connection closed before an answer")
        super().begin()


class _Connection(http.client.HTTPConnection):
    response_class = _Response


class _TLSConnection(http.client.HTTPSConnection):
    response_class = _Response


def _stale(conn):
    """True when an idle kept-alive connection cannot carry a request: the
    server closed it (EOF readable) or sent something unasked. A readable
    idle socket is never good news, so the check costs no round trip. Not
    done over TLS, where a session ticket can arrive unasked (a request on
    a closed TLS connection is retried as below)."""
    sock = conn.sock
    if sock is None or isinstance(conn, _TLSConnection):
        return False  # http.client opens a new socket at the next request
    try:
        if hasattr(select, "poll"):
            poller = select.poll()
            poller.register(sock, select.POLLIN)
            return bool(poller.poll(0))
        return bool(select.select([sock], [], [], 0)[0])
    except (OSError, ValueError):
        return True


class Client:
    """One kdrayd; every method is one HTTP request. binary: query bodies and
    answers in CBOR instead of JSON. stream: bundle, cone-shadow and frustum
    answers streamed (application/cbor-seq, chunk by chunk while later chunks
    trace) and put together (implies binary). lists=False (binary or
    stream): answer arrays as array.array objects instead of lists (see the
    module's docstring for why).

    Connections: the Client keeps one HTTP/1.1 keep-alive connection per
    thread that uses it (a Client may be shared by threads: each gets its
    own connection, no request waits for another's). A request on a kept
    connection that the server had closed while it was idle (its
    --connection-timeout-s, a restart) is sent once more on a new
    connection, provided no byte of the answer had arrived; a failure after
    the first byte of an answer is never retried, and neither is a failure
    on a new connection. A request whose body was cut half sent is retried
    too: every kdray request is idempotent (GETs, and queries that only
    read the scene); only a body given as an iterable or a file (sent as
    it is read, chunked with a Transfer-Encoding header) is never sent
    twice. A streamed answer leaves its connection for the next
    request only when read to its end; one left half read (a generator
    closed or dropped early) closes its connection. close(), or leaving a
    with block, closes the kept connections; a later request opens a new
    one."""

    def __init__(self, url=DEFAULT_URL, timeout=DEFAULT_TIMEOUT_S, binary=False,
                 stream=False, lists=True):
        self.url = url.rstrip("/")
        self.timeout = timeout
        self.binary = binary or stream
        self.stream = stream
        self.lists = lists
        parts = urllib.parse.urlsplit(self.url)
        if parts.scheme not in ("http", "https") or not parts.hostname:
            raise ValueError("url: expected http://HOST[:PORT], got %r" % url)
        self._conn_class = _Connection if parts.scheme == "http" else _TLSConnection
        self._netloc = parts.netloc
        self._prefix = parts.path  # a path prefix (behind a proxy), may be ""
        self._local = threading.local()   # .conn: this thread's idle connection
        self._idle = weakref.WeakSet()    # every thread's, for close()
        self._lock = threading.Lock()
        if self.binary:
            _cbor2()  # fail now, not at the first query

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        """Closes the idle kept connections of every thread (one carrying a
        request closes when that request ends)."""
        with self._lock:
            conns = list(self._idle)
            self._idle.clear()
        for conn in conns:
            conn.close()

    def _take(self):
        """This thread's kept connection, or a new one (not yet connected)."""
        with self._lock:
            conn = getattr(self._local, "conn", None)
            self._local.conn = None
            if conn is not None:
                self._idle.discard(conn)
        if conn is not None and _stale(conn):
            conn.close()  # the next request on it opens a new socket
        return conn or self._conn_class(self._netloc, timeout=self.timeout)

    def _keep(self, conn, resp):
        """Puts conn back for the next request if resp was read to its end
        and the server keeps the connection open; closes it otherwise."""
        if resp.isclosed() and not resp.will_close and conn.sock is not None:
            with self._lock:
                if getattr(self._local, "conn", None) is None:
                    self._local.conn = conn
                    self._idle.add(conn)
                    return
        conn.close()

    def _open(self, method, path, body, headers):
        """Sends a request; returns (conn, response) with the response's head
        read. Retries once on a new connection when a kept connection turns
        out to be closed (see the class's docstring)."""
        # a body given as an iterable or a file is sent as it is read: it
        # cannot be sent twice, so its request is never retried; one with a
        # Transfer-Encoding header is sent chunked (as urllib did)
        resendable = body is None or isinstance(body, (bytes, bytearray, str))
        chunked = any(k.lower() == "transfer-encoding" for k in headers)
        while True:
            conn = self._take()
            # retried only on a kept connection (a new one failing is real)
            may_retry = conn.sock is not None and resendable
            try:
                try:
                    conn.request(method, self._prefix + path, body=body,
                                 headers=headers, encode_chunked=chunked)
                except ConnectionError:
                    # The server may have answered before it stopped reading
                    # (413: body too large): read that answer if there is one.
                    if conn.sock is None:
                        raise  # never connected: nothing to read
                return conn, conn.getresponse()
            except _NoAnswer as err:
                conn.close()
                if not may_retry:
                    raise ConnectionError("%s: no answer: %s" % (self.url, err)) from None
            except BaseException:
                conn.close()
                raise

    def request(self, method, path, body=None, content_type="application/json",
                headers=None):
        """Raw request: returns (status, headers dict, body bytes); never raises
        for HTTP error statuses."""
        hdrs = dict(headers or {})
        if body is not None and content_type is not None:
            hdrs["Content-Type"] = content_type
        conn, resp = self._open(method, path, body, hdrs)
        try:
            data = resp.read()
        except BaseException:
            conn.close()
            raise
        self._keep(conn, resp)
        return resp.status, dict(resp.headers.items()), data

    def call(self, method, path, payload=None):
        """JSON in, JSON out (CBOR both ways for queries in binary mode);
        raises KdrayError on an error status."""
        ctype, headers = JSON, None
        if payload is None:
            body = None
        elif self.binary:
            body, ctype, headers = cbor_body(payload), CBOR, {"Accept": CBOR}
        else:
            body = json.dumps(payload).encode("utf-8")
        status, hdrs, data = self.request(method, path, body, ctype, headers)
        hdrs = {k.lower(): v for k, v in hdrs.items()}
        answer_type = hdrs.get("content-type", "")
        try:
            if answer_type.startswith(CBOR):
                parsed = decode_cbor(data, self.lists)
            else:
                parsed = json.loads(data) if data else None
        except ValueError:
            parsed = data.decode("utf-8", "replace")
        if status >= 400:
            retry = hdrs.get("retry-after", "")
            raise KdrayError(status, parsed, int(retry) if retry.isdigit() else None)
        return parsed

    def stream_query(self, path, payload):
        """POSTs a query (CBOR) asking for a streamed answer and yields its
        items as they arrive (see stream_items: head, chunk items, final
        item). An error answer before streaming began raises KdrayError with
        its problem, as call() does; so does a final problem item. The
        connection is kept for the next request only when the answer was
        read to its end."""
        conn, resp = self._open("POST", path, cbor_body(payload),
                                {"Content-Type": CBOR, "Accept": CBOR_SEQ})
        settled = False  # conn kept or closed
        try:
            if resp.status >= 400:
                data = resp.read()
                self._keep(conn, resp)
                settled = True
                try:
                    problem = json.loads(data)
                except ValueError:
                    problem = data.decode("utf-8", "replace")
                retry = resp.headers.get("Retry-After", "")
                raise KdrayError(resp.status, problem,
                                 int(retry) if retry.isdigit() else None)
            ctype = resp.headers.get("Content-Type", "")
            if not ctype.startswith(CBOR_SEQ):
                raise KdrayError(resp.status, "not a streamed answer: " + ctype)
            try:
                for item in stream_items(read_cbor_seq(resp, self.lists)):
                    if "status" in item and "kind" not in item:
                        # The final item: its last byte ended the sequence.
                        # Reading the chunked body's terminator makes the
                        # connection reusable; it is settled before the
                        # caller sees the item, as a caller may stop asking
                        # for items once it has the final one.
                        if resp.read() == b"":
                            self._keep(conn, resp)
                        else:
                            conn.close()
                        settled = True
                    yield item
            except (EOFError, OSError, ValueError,
                    http.client.HTTPException) as err:
                if isinstance(err, KdrayError):
                    raise
                raise KdrayError(0, "streamed answer cut: %s" % err) from None
        finally:
            # A generator closed or dropped early (GeneratorExit at a yield)
            # or an error lands here unsettled: the rest of the answer is
            # unread, so the connection cannot carry another request.
            if not settled:
                conn.close()

    def _query(self, path, payload):
        if self.stream:
            return assemble_stream(self.stream_query(path, payload))
        return decode_answer(self.call("POST", path, payload))

    def _send(self, send):
        return "cbor" if self.binary else send

    def health(self):
        """GET /v1/health: is the daemon alive (200 once every scene is built,
        whatever the load)."""
        return self.call("GET", "/v1/health")

    def ready(self):
        """GET /v1/ready: should it get traffic now? The readiness document
        (status, scenes, workers, busy, queued, slots, slots_used,
        inflight_bytes, inflight_limit) when ready; KdrayError 503 while
        starting, shutting down or saturated (.retry_after set when
        saturated)."""
        return self.call("GET", "/v1/ready")

    def metrics(self):
        status, _, data = self.request("GET", "/metrics")
        if status != 200:
            raise KdrayError(status, data.decode("utf-8", "replace"))
        return data.decode("utf-8")

    def scenes(self):
        return self.call("GET", "/v1/scenes")["scenes"]

    def scene(self, name):
        return self.call("GET", "/v1/scenes/" + name)

    def bundle(self, scene, origins, directions, tmin=None, tmax=None,
               query="closest", encoding="json", send="json", fields=None,
               max_hits=None):
        """Traces rays; origins is 3 floats (shared) or 3*N; send picks the
        request's float encoding, encoding the answer's (JSON mode); fields
        lists the answer arrays wanted (t, prim, u, v, hit). query "all"
        (every hit, at most max_hits per ray: nhits, offset and flat arrays)
        and "count" (nhits per ray) are answered too."""
        send = self._send(send)
        payload = {"origins": _floats(origins, send),
                   "directions": _floats(directions, send),
                   "query": query, "encoding": encoding}
        for key, value in (("tmin", tmin), ("tmax", tmax)):
            if value is not None:
                payload[key] = (value if isinstance(value, (int, float))
                                else _floats(value, send))
        if fields is not None:
            payload["fields"] = list(fields)
        if max_hits is not None:
            payload["max_hits"] = max_hits
        path = "/v1/scenes/%s/bundle" % scene
        return self._query(path, payload)

    def shadow(self, scene, points, lights, normals=None, samples=None,
               seed=None, epsilon=None, stats=False, encoding="json", send="json"):
        """Cone-shadow visibility; lights are (x, y, z, radius) tuples or
        {"center": ..., "radius": ...} dicts."""
        send = self._send(send)
        payload = {"points": _floats(points, send), "encoding": encoding,
                   "lights": [l if isinstance(l, dict) else
                              {"center": list(l[:3]), "radius": l[3]}
                              for l in lights]}
        if normals is not None:
            payload["normals"] = _floats(normals, send)
        for key, value in (("samples", samples), ("seed", seed),
                           ("epsilon", epsilon)):
            if value is not None:
                payload[key] = value
        if stats:
            payload["stats"] = True
        path = "/v1/scenes/%s/cone-shadow" % scene
        return self._query(path, payload)

    def frustum(self, scene, eye, target, width, height, up=(0, 1, 0),
                fov_y_deg=60.0, tile=8, query="closest", encoding="base64",
                fields=None):
        camera = {"eye": list(eye), "target": list(target), "up": list(up),
                  "fov_y_deg": fov_y_deg, "width": width, "height": height}
        payload = {"camera": camera, "tile": tile, "query": query,
                   "encoding": encoding}
        if fields is not None:
            payload["fields"] = list(fields)
        path = "/v1/scenes/%s/frustum" % scene
        return self._query(path, payload)

    def render(self, scene, **params):
        """GET render.png: a picture (PNG bytes) and its stage times and
        statistics, as a (png, timing, stats) tuple of bytes and two dicts.
        params: eye, target, up (3 numbers), light (x, y, z, radius), fov,
        width, height, samples, mode; lists are sent comma-separated, and
        what is left out the daemon chooses (it frames the scene)."""
        query = urllib.parse.urlencode(
            {k: ",".join("%r" % float(x) for x in v) if isinstance(v, (list, tuple))
             else v for k, v in params.items() if v is not None})
        path = "/v1/scenes/%s/render.png" % urllib.parse.quote(scene)
        status, hdrs, data = self.request("GET", path + ("?" + query if query else ""))
        hdrs = {k.lower(): v for k, v in hdrs.items()}
        if status != 200:
            try:
                problem = json.loads(data)
            except ValueError:
                problem = data.decode("utf-8", "replace")
            retry = hdrs.get("retry-after", "")
            raise KdrayError(status, problem, int(retry) if retry.isdigit() else None)
        return data, parse_server_timing(hdrs.get("server-timing", "")), \
            parse_render_stats(hdrs.get("x-kdray-render", ""))


def parse_server_timing(value):
    """{"primary": ms, ...} from a Server-Timing header."""
    out = {}
    for part in value.split(","):
        name, _, rest = part.strip().partition(";")
        if name and rest.startswith("dur="):
            out[name] = float(rest[4:])
    return out


def parse_render_stats(value):
    """The X-Kdray-Render header as a dict (numbers where they are numbers)."""
    out = {}
    for part in value.split(";"):
        key, _, v = part.strip().partition("=")
        if key:
            try:
                out[key] = int(v)
            except ValueError:
                try:
                    out[key] = float(v)
                except ValueError:
                    out[key] = v
    return out


def random_directions(n, seed=1):
    """n directions uniform on the unit sphere (flat list of 3n floats)."""
    rng = random.Random(seed)
    out = []
    for _ in range(n):
        z = rng.uniform(-1.0, 1.0)
        phi = rng.uniform(0.0, 2.0 * math.pi)
        r = math.sqrt(max(0.0, 1.0 - z * z))
        out += [r * math.cos(phi), r * math.sin(phi), z]
    return out


def write_pgm(path, t, width, height):
    """A binary PGM depth image: near hits bright, far dark, misses black."""
    hits = [x for x in t if x >= 0]
    near, far = (min(hits), max(hits)) if hits else (0.0, 1.0)
    span = far - near if far > near else 1.0
    pixels = bytearray(0 if x < 0 else 255 - int(200 * (x - near) / span)
                       for x in t)
    with open(path, "wb") as f:
        f.write(b"P5\n%d %d\n255\n" % (width, height))
        f.write(bytes(pixels))


def _vec(text, n=3):
    parts = [float(x) for x in text.split(",")]
    if len(parts) != n:
        raise argparse.ArgumentTypeError("expected %d comma-separated numbers" % n)
    return parts


def _summary(answer):
    """The answer with long arrays cut to their first 8 entries."""
    return {key: value[:8] + ["..."] if isinstance(value, list) and len(value) > 8
            else value for key, value in answer.items()}


def _cmd_bundle(client, args):
    dirs = []
    for d in args.dir or []:
        dirs += d
    dirs += random_directions(args.random, args.seed) if args.random else []
    if not dirs:
        raise SystemExit("bundle: give --dir x,y,z and/or --random N")
    return client.bundle(args.scene, args.origin, dirs, tmin=args.tmin,
                         tmax=args.tmax, query="any" if args.any else "closest",
                         encoding=args.encoding, send=args.send,
                         fields=args.fields.split(",") if args.fields else None)


def _cmd_shadow(client, args):
    points = [x for p in args.point for x in p]
    return client.shadow(args.scene, points, args.light, samples=args.samples,
                         seed=args.seed, stats=True, encoding=args.encoding)


def _cmd_frustum(client, args):
    fields = args.fields.split(",") if args.fields else None
    if args.pgm and fields and "t" not in fields:
        fields.append("t")
    answer = client.frustum(args.scene, args.eye, args.target, args.width,
                            args.height, up=args.up, fov_y_deg=args.fov,
                            tile=args.tile, encoding=args.encoding, fields=fields)
    if args.pgm:
        write_pgm(args.pgm, answer["t"], args.width, args.height)
        print("wrote %s" % args.pgm, file=sys.stderr)
    return answer


def _cmd_render(client, args):
    png, timing, stats = client.render(
        args.scene, eye=args.eye, target=args.target, up=args.up, fov=args.fov,
        width=args.width, height=args.height, light=args.light,
        samples=args.samples, mode=args.mode)
    with open(args.out, "wb") as f:
        f.write(png)
    print("wrote %s (%d bytes)" % (args.out, len(png)), file=sys.stderr)
    return {"out": args.out, "bytes": len(png), "timing_ms": timing, "stats": stats}


def _parser():
    p = argparse.ArgumentParser(description="kdray HTTP client")
    p.add_argument("--url", default=DEFAULT_URL)
    p.add_argument("--full", action="store_true", help="print whole arrays")
    p.add_argument("--binary", action="store_true",
                   help="queries in CBOR (application/cbor; needs python3-cbor2)")
    p.add_argument("--stream", action="store_true",
                   help="bundle, shadow, frustum: the answer streamed chunk by "
                   "chunk (Accept: application/cbor-seq; implies --binary)")
    sub = p.add_subparsers(dest="cmd", required=True)
    for name in ("health", "ready", "metrics", "scenes"):
        sub.add_parser(name)
    b = sub.add_parser("bundle", help="trace rays from one origin")
    b.add_argument("--origin", type=_vec, default=[0.0, 0.0, 0.0])
    b.add_argument("--dir", type=_vec, action="append")
    b.add_argument("--random", type=int, default=0, help="N random directions")
    b.add_argument("--tmin", type=float)
    b.add_argument("--tmax", type=float)
    b.add_argument("--any", action="store_true", help="occlusion query")
    b.add_argument("--send", choices=("json", "base64"), default="json")
    s = sub.add_parser("shadow", help="cone-shadow visibility")
    s.add_argument("--point", type=_vec, action="append", required=True)
    s.add_argument("--light", type=lambda t: _vec(t, 4), action="append",
                   required=True, help="x,y,z,radius")
    s.add_argument("--samples", type=int, default=64)
    f = sub.add_parser("frustum", help="primary rays of a camera")
    f.add_argument("--eye", type=_vec, required=True)
    f.add_argument("--target", type=_vec, required=True)
    f.add_argument("--up", type=_vec, default=[0.0, 1.0, 0.0])
    f.add_argument("--fov", type=float, default=60.0)
    f.add_argument("--width", type=int, default=320)
    f.add_argument("--height", type=int, default=240)
    f.add_argument("--tile", type=int, default=8)
    f.add_argument("--pgm", help="write a PGM depth image")
    r = sub.add_parser("render", help="a picture (PNG) rendered by the daemon")
    r.add_argument("--out", required=True, help="the PNG file to write")
    r.add_argument("--eye", type=_vec)
    r.add_argument("--target", type=_vec)
    r.add_argument("--up", type=_vec)
    r.add_argument("--fov", type=float)
    r.add_argument("--width", type=int)
    r.add_argument("--height", type=int)
    r.add_argument("--light", type=lambda t: _vec(t, 4), help="x,y,z,radius")
    r.add_argument("--samples", type=int)
    r.add_argument("--mode", choices=("shade", "depth", "normal", "shadow", "ao"))
    r.add_argument("--scene", default="default")
    for q in (b, f):
        q.add_argument("--fields", help="answer arrays, e.g. t,prim (default: all)")
    for q in (b, s, f):
        q.add_argument("--scene", default="default")
        q.add_argument("--seed", type=int, default=1)
        q.add_argument("--encoding", choices=("json", "base64"), default="json")
    return p


def main(argv=None):
    args = _parser().parse_args(argv)
    try:
        client = Client(args.url, binary=args.binary, stream=args.stream)
    except RuntimeError as err:
        print("kdray_client: %s" % err, file=sys.stderr)
        return 2
    try:
        if args.cmd == "metrics":
            sys.stdout.write(client.metrics())
            return 0
        handlers = {"health": lambda c, a: c.health(),
                    "ready": lambda c, a: c.ready(),
                    "scenes": lambda c, a: {"scenes": c.scenes()},
                    "bundle": _cmd_bundle, "shadow": _cmd_shadow,
                    "frustum": _cmd_frustum, "render": _cmd_render}
        answer = handlers[args.cmd](client, args)
    except KdrayError as err:
        print(json.dumps(err.problem), file=sys.stderr)
        if err.retry_after is not None:
            print("kdray_client: retry after %d s" % err.retry_after, file=sys.stderr)
        return 1
    except (OSError, http.client.HTTPException) as err:
        print("kdray_client: %s: %s" % (args.url, err), file=sys.stderr)
        return 1
    if not args.full and isinstance(answer, dict):
        answer = _summary(answer)
    print(json.dumps(answer, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

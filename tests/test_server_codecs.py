#!/usr/bin/env python3
"""test_server_codecs.py - kdrayd's binary bodies over real HTTP.

    test_server_codecs.py KDRAYD CLIENTS_DIR

Needs Debian's python3-cbor2 (run with /usr/bin/python3): a missing module
is a failure, not a skip. Starts the daemon on the bundled default scene and
checks that every query kind answers the same values in JSON and in CBOR
(application/cbor, RFC 8746 typed arrays) whichever way each body travels;
that Content-Type and Accept pick the answer's media type; that "fields"
trims answers; that malformed CBOR bodies get 400 problem+json naming the
field (problem+json even when the client accepts only CBOR); that a
typed array at a misaligned offset (copied) answers as one read in place;
and that kdray-trace reads a .cbor request file (or --content-type) and
answers it byte for byte as kdrayd does, in the media type --accept picks;
and that query answers carry Server-Timing (body, queue, parse, trace,
encode).
"""

import array
import json
import os
import re
import struct
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import test_server_lib as lib  # noqa: E402

KDRAYD, CLIENTS = sys.argv[1], sys.argv[2]
TRACE = os.path.join(os.path.dirname(KDRAYD), "kdray-trace")
lib.add_client_path(CLIENTS)
import cbor2  # noqa: E402  (python3-cbor2: required, see above)
from kdray_client import (CBOR, Client, KdrayError, _f32_array, cbor_body,  # noqa: E402
                          decode_cbor)

SCENE = "default"
RAYS = 9000  # three 4096-ray chunks


def f32(xs):
    return [struct.unpack("<f", struct.pack("<f", x))[0] for x in xs]


def same_answer(t, js, cb, what):
    """A JSON answer (floats as text) and a CBOR one hold the same values."""
    t.eq(sorted(cb), sorted(js), what + ": members")
    for key, value in js.items():
        if isinstance(value, list) and key in ("t", "u", "v", "visibility"):
            t.eq(cb[key], f32(value), "%s: %s" % (what, key))
        else:
            t.eq(cb[key], value, "%s: %s" % (what, key))


def raw_post(c, path, body, ctype=CBOR, accept=None):
    headers = {"Accept": accept} if accept else None
    return c.request("POST", path, body, ctype, headers)


def content_type(headers):
    return {k.lower(): v for k, v in headers.items()}.get("content-type", "")


def test_every_kind_both_ways(t, c, b):
    bounds = c.scene(SCENE)["bounds"]
    for shared in (False, True):
        o, d = lib.rays_into_box(bounds, RAYS, seed=3, shared_origin=shared)
        tmax = [1e30 if i % 5 else 0.5 for i in range(RAYS)]
        for query in ("closest", "any"):
            what = "bundle %s shared=%s" % (query, shared)
            js = c.bundle(SCENE, o, d, tmax=tmax, query=query)
            cb = b.bundle(SCENE, o, d, tmax=tmax, query=query)
            same_answer(t, js, cb, what)
            if query == "closest":
                t.check(sum(p >= 0 for p in cb["prim"]) > RAYS // 10, what + " hits")
    cam = bounds["max"]
    for query in ("closest", "any"):
        js = c.frustum(SCENE, [2 * x for x in cam], [0, 0, 0], 83, 41, query=query,
                       encoding="json")
        cb = b.frustum(SCENE, [2 * x for x in cam], [0, 0, 0], 83, 41, query=query)
        same_answer(t, js, cb, "frustum " + query)
    pts, _ = lib.rays_into_box(bounds, 150, seed=4)
    lights = [(0, 50, 0, 3), (40, 10, 0, 1)]
    js = c.shadow(SCENE, pts, lights, samples=8, stats=True)
    cb = b.shadow(SCENE, pts, lights, samples=8, stats=True)
    same_answer(t, js, cb, "cone-shadow")


def test_negotiation(t, c, b):
    path = "/v1/scenes/%s/bundle" % SCENE
    payload = {"origins": [0, 3, 5], "directions": [0, 0, -1, 0.1, -0.2, -1]}
    as_cbor = cbor_body({"origins": _f32_array(payload["origins"]),
                         "directions": _f32_array(payload["directions"])})
    as_json = json.dumps(payload).encode()
    cases = [  # body type, Accept, answer type
        (CBOR, None, CBOR), (CBOR, "*/*", CBOR), (CBOR, "application/json", "json"),
        ("application/json", None, "json"), ("application/json", CBOR, CBOR),
        ("application/json", "application/json;q=0.5, application/cbor", CBOR),
        (CBOR, "application/cbor;q=0.1, application/json", "json"),
        (CBOR, "text/html", CBOR),
    ]
    answers = []
    for ctype, accept, want in cases:
        body = as_cbor if ctype == CBOR else as_json
        code, headers, data = raw_post(c, path, body, ctype, accept)
        what = "%s body, Accept %s" % (ctype, accept)
        t.eq(code, 200, what)
        got = content_type(headers)
        if want == CBOR:
            t.eq(got, CBOR, what + ": answer type")
            answers.append(decode_cbor(data))
        else:
            t.check(got.startswith("application/json"), what + ": JSON answer")
            a = json.loads(data)
            answers.append({k: f32(v) if k in "tuv" else v for k, v in a.items()})
    for a in answers[1:]:
        t.eq(a, answers[0], "every negotiation answers the same values")
    # a CBOR body answered in JSON keeps its "encoding" choice
    body = cbor_body({"origins": _f32_array([0, 3, 5]), "directions": _f32_array([0, 0, -1]),
                      "encoding": "base64"})
    code, headers, data = raw_post(c, path, body, CBOR, "application/json")
    t.eq(code, 200, "CBOR body, JSON answer, base64")
    t.check("f32" in json.loads(data)["t"], "base64 arrays in the JSON answer")
    # scenes and health stay JSON whatever Accept says
    code, headers, _ = c.request("GET", "/v1/health", headers={"Accept": CBOR})
    t.check(code == 200 and content_type(headers).startswith("application/json"),
            "health is JSON")


def test_fields(t, c, b):
    o, d = [0, 3, 5], [0, 0, -1, 0.1, -0.2, -1, 1, 0, 0]
    full = c.bundle(SCENE, o, d)
    for fields in (["t"], ["prim", "t"], ["hit"], ["u", "v", "hit"]):
        for client in (c, b):
            a = client.bundle(SCENE, o, d, fields=fields)
            t.eq(sorted(a), sorted(["count"] + fields), "fields %s" % fields)
            if "prim" in fields:
                t.eq(a["prim"], full["prim"], "prim")
            if "hit" in fields:
                t.eq(a["hit"], [1 if p >= 0 else 0 for p in full["prim"]], "closest hit")
    anyhit = b.bundle(SCENE, o, d, query="any", fields=["hit"])
    t.eq(sorted(anyhit), ["count", "hit"], "any with hit")
    try:
        b.bundle(SCENE, o, d, query="any", fields=["t"])
        t.check(False, "t of an any query is refused")
    except KdrayError as err:
        t.eq(err.status, 400, "fields status")
        t.eq(err.problem["detail"], 'fields[0]: "t" needs "query": "closest"', "detail")
    a = b.frustum(SCENE, [0, 3, 9], [0, 0, 0], 32, 16, fields=["t"])
    t.eq(sorted(a), ["count", "t"], "frustum fields")
    # a quarter of the bytes: t only, against t, prim, u, v
    body = cbor_body({"origins": _f32_array(o), "directions": _f32_array(d * 1000)})
    path = "/v1/scenes/%s/bundle" % SCENE
    whole = len(raw_post(c, path, body)[2])
    body_t = cbor_body({"origins": _f32_array(o), "directions": _f32_array(d * 1000),
                        "fields": ["t"]})
    only_t = len(raw_post(c, path, body_t)[2])
    t.check(only_t * 4 <= whole + 64, "t only: %d bytes of %d" % (only_t, whole))


def expect_problem(t, resp, status, what, detail_has):
    code, headers, data = resp
    t.eq(code, status, what + " status")
    t.eq(content_type(headers), "application/problem+json", what + " type")
    p = json.loads(data)
    t.check(detail_has in p.get("detail", ""), "%s: detail %r lacks %r"
            % (what, p.get("detail"), detail_has))


def test_bad_bodies(t, c, b):
    path = "/v1/scenes/%s/bundle" % SCENE
    good = cbor_body({"origins": _f32_array([0, 3, 5]),
                      "directions": _f32_array([0, 0, -1, 1, 0, 0])})
    for cut in (1, 5, len(good) // 2, len(good) - 1):
        expect_problem(t, raw_post(c, path, good[:cut], accept=CBOR), 400,
                       "truncated at %d" % cut, "truncated CBOR")
    tag = cbor2.CBORTag
    cases = [
        ({"origins": [0, 3, 5], "directions": "x"}, "directions: expected a float32"),
        ({"origins": [0, 3, 5], "directions": tag(85, b"\0" * 10)},
         "directions: typed array length is not a multiple of 4"),
        ({"origins": [0, 3, 5], "directions": tag(86, b"\0" * 24)},
         "directions: only float32 little-endian typed arrays"),
        ({"origins": [0, 3, 5], "directions": b"\0" * 12},
         "directions: a byte string needs a typed-array tag"),
        ({"origins": [0, 3, 5], "directions": [0, 0, -1], "query": 7},
         'query: must be "closest", "any", "all" or "count"'),
        ({"origins": [0, 3, 5], "directions": [0, 0, float("nan")]},
         "directions[2]: not a number"),
        ({"origins": [0, 3, 5], "directions": [0, 0, -1], "tmax": float("nan")},
         "tmax: not a number"),
        ({"origins": [0, 3, 5], "directions": [0, 0, -1], "zzz": [[[[[[[[[[[[[[[[[0]]]]]]]]]]]]]]]]]},
         "zzz[0][0][0][0][0][0][0][0][0][0][0][0][0][0][0]: nested too deeply"),
    ]
    for payload, detail in cases:
        expect_problem(t, raw_post(c, path, cbor2.dumps(payload), accept=CBOR), 400,
                       detail, detail)
    expect_problem(t, raw_post(c, path, b"\xbb" + b"\xff" * 8), 400, "huge map",
                   "body: truncated CBOR")
    expect_problem(t, raw_post(c, path, b"\xa1\x6adirections\x5b" + b"\xff" * 8), 400,
                   "huge byte string", "directions: truncated CBOR")
    expect_problem(t, raw_post(c, path, good, "application/msgpack"), 415, "msgpack",
                   "expected application/json or application/cbor")
    t.eq(c.health()["status"], "ok", "alive after the bad bodies")


def test_misaligned_typed_array(t, c, b):
    """The same rays with directions at every offset mod 4: equal answers."""
    path = "/v1/scenes/%s/bundle" % SCENE
    bounds = c.scene(SCENE)["bounds"]
    o, d = lib.rays_into_box(bounds, 500, seed=9, shared_origin=True)
    answers = []
    for pad in range(4):
        body = (b"\xa3" + cbor2.dumps("_") + cbor2.dumps("x" * pad) +
                cbor2.dumps("origins") + cbor2.dumps(cbor2.CBORTag(85, struct.pack("<3f", *o[:3]))) +
                cbor2.dumps("directions") +
                cbor2.dumps(cbor2.CBORTag(85, struct.pack("<%df" % len(d), *d))))
        code, _, data = raw_post(c, path, body)
        t.eq(code, 200, "pad %d" % pad)
        answers.append(decode_cbor(data))
    for a in answers[1:]:
        t.eq(a, answers[0], "aligned and misaligned typed arrays answer the same")


def trace(args, what):
    out = subprocess.run([TRACE] + args, capture_output=True, timeout=300)
    if out.returncode != 0:
        raise RuntimeError("kdray-trace %s: %s" % (what, out.stderr.decode()))
    return out.stdout


def test_trace_reads_cbor(t, c, b):
    """kdray-trace answers a CBOR file as kdrayd answers the same body."""
    bounds = c.scene(SCENE)["bounds"]
    o, d = lib.rays_into_box(bounds, RAYS, seed=5)
    pts, _ = lib.rays_into_box(bounds, 150, seed=6)
    bodies = {
        "bundle": cbor_body({"origins": _f32_array(o), "directions": _f32_array(d)}),
        "cone-shadow": cbor_body({
            "points": _f32_array(pts), "samples": 64, "stats": True,
            "lights": [{"center": [0, 50, 0], "radius": 3}]}),
    }
    tmp = tempfile.mkdtemp(prefix="kdray-cbor-")
    try:
        for kind, body in bodies.items():
            path = "/v1/scenes/%s/%s" % (SCENE, kind)
            file_cbor = os.path.join(tmp, kind + ".cbor")
            file_bin = os.path.join(tmp, kind + ".bin")
            for name in (file_cbor, file_bin):
                with open(name, "wb") as f:
                    f.write(body)
            code, headers, served = raw_post(c, path, body)
            t.eq(code, 200, kind + " over HTTP")
            base = ["--kind", kind, "--mode", "fast", "--threads", "2"]
            t.eq(trace(base + [file_cbor], kind), served,
                 kind + ": kdray-trace on a .cbor file == kdrayd, byte for byte")
            t.eq(trace(base + ["--content-type", CBOR, file_bin], kind), served,
                 kind + ": --content-type application/cbor")
            code, headers, served_json = raw_post(c, path, body, accept="application/json")
            t.eq(trace(base + ["--accept", "application/json", file_cbor], kind),
                 served_json, kind + ": --accept application/json == kdrayd's JSON")
    finally:
        for name in os.listdir(tmp):
            os.unlink(os.path.join(tmp, name))
        os.rmdir(tmp)


def test_server_timing(t, c, b):
    """A query answer says where its time went (Server-Timing: body, queue,
    parse, trace, encode in ms, each >= 0, together no more than the
    client's own wall time); an error answer does not."""
    bounds = c.scene(SCENE)["bounds"]
    o, d = lib.rays_into_box(bounds, RAYS, seed=5)
    path = "/v1/scenes/%s/bundle" % SCENE
    for enc, body in (("cbor", cbor_body({"origins": _f32_array(o),
                                          "directions": _f32_array(d)})),
                      ("json", json.dumps({"origins": o, "directions": d}).encode())):
        ctype = CBOR if enc == "cbor" else "application/json"
        t0 = time.perf_counter()
        code, headers, _ = raw_post(c, path, body, ctype)
        wall_ms = (time.perf_counter() - t0) * 1e3
        t.eq(code, 200, enc + ": status")
        st = {k.lower(): v for k, v in headers.items()}.get("server-timing", "")
        steps = dict((m.group(1), float(m.group(2)))
                     for m in re.finditer(r"(\w+);dur=([\d.]+)", st))
        t.eq(sorted(steps), ["body", "encode", "parse", "queue", "trace"],
             enc + ": Server-Timing steps in %r" % st)
        t.check(steps.get("trace", 0) > 0, enc + ": a traced query took time: %r" % st)
        t.check(sum(steps.values()) <= wall_ms + 1,
                "%s: steps %r within the client's %.2f ms" % (enc, steps, wall_ms))
    code, headers, _ = raw_post(c, path, b'{"origins": [0, 0]}', "application/json")
    t.eq(code, 400, "bad body: 400")
    t.check("server-timing" not in {k.lower() for k in headers},
            "no Server-Timing on an error answer")


def test_cbor_body_layout(t, c, b):
    """cbor_body writes what cbor2 reads back: every float array a tag-85
    typed array of its little-endian bytes starting at a multiple of 4
    (whatever came before it), other members as given, members counted
    with the padding ones (heads of 1, 2, 3 and 5 bytes for the lengths)."""
    for n in (0, 1, 5, 6, 64, 16384, 70000):
        for key_len in range(1, 5):
            payload = {"q" * key_len: "closest", "origins": _f32_array([1, 2, 3]),
                       "d" * key_len: _f32_array(1000.25 + i for i in range(n)),
                       "tmax": 2.5}
            body = cbor_body(payload)
            got = cbor2.loads(body)
            what = "n=%d key_len=%d" % (n, key_len)
            for key, value in payload.items():
                if isinstance(value, array.array):
                    raw = struct.pack("<%df" % len(value), *value)
                    item = got.get(key)
                    t.check(isinstance(item, cbor2.CBORTag) and item.tag == 85 and
                            item.value == raw, "%s: %s round trip" % (what, key))
                    at = body.find(raw) if raw else 0  # values found nowhere else
                    t.check(at % 4 == 0, "%s: %s at offset %d" % (what, key, at))
                else:
                    t.eq(got.get(key), value, "%s: %s" % (what, key))
            t.check(set(got) - set(payload) <= {"_pad%d" % i for i in range(8)},
                    what + ": only padding members added")


def test_arrays_not_lists(t, c, b):
    """A binary client with lists=False answers with array.array objects of
    the typed arrays' element types (float32 "f", int32 "i", uint8 "B"),
    holding what the list-decoding client gets; one-piece and streamed."""
    bounds = c.scene(SCENE)["bounds"]
    o, d = lib.rays_into_box(bounds, RAYS, seed=5)
    want_type = {"t": "f", "u": "f", "v": "f", "prim": "i", "hit": "B"}
    for stream in (False, True):
        a = Client(b.url, binary=True, stream=stream, lists=False)
        for query in ("closest", "any"):
            what = "bundle %s stream=%s" % (query, stream)
            ls = b.bundle(SCENE, o, d, query=query)
            ar = a.bundle(SCENE, o, d, query=query)
            t.eq(sorted(ar), sorted(ls), what + ": members")
            for key, value in ls.items():
                if isinstance(value, list):
                    got = ar[key]
                    t.check(isinstance(got, array.array) and
                            got.typecode == want_type[key],
                            "%s: %s is %r" % (what, key, type(got)))
                    t.eq(got.tolist(), value, "%s: %s" % (what, key))
                else:
                    t.eq(ar[key], value, "%s: %s" % (what, key))


def main():
    t = lib.Runner()
    d = lib.Daemon(KDRAYD, ["--threads", "2"])
    c, b = Client(d.url), Client(d.url, binary=True)
    try:
        for fn in (test_every_kind_both_ways, test_negotiation, test_fields,
                   test_bad_bodies, test_misaligned_typed_array, test_trace_reads_cbor,
                   test_server_timing, test_arrays_not_lists,
                   test_cbor_body_layout):
            t.run(fn, c, b)
    finally:
        rc = d.stop()
    if rc != 0:
        print("FAIL kdrayd exited %s\n%s" % (rc, d.log_text()))
        t.failures.append("exit status")
    return t.finish()


if __name__ == "__main__":
    sys.exit(main())

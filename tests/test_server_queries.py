#!/usr/bin/env python3
"""test_server_queries.py - bundle "query": "all" and "count", and
closest-point, over HTTP.

    test_server_queries.py KDRAYD KDRAY_TRACE CLIENTS_DIR

Starts kdrayd on the bundled default scene (--max-rays 6000000, so the
rays * max_hits limit can be reached) and checks: the answers equal the
executor's direct-core answers (kdray-trace) byte for byte; each ray's list
is in increasing t (ties by prim), holds no prim twice and at most max_hits
hits; its first hit is the closest query's hit bit for bit; nhits of
"count" equals the uncapped list's length; offsets are the prefix sums;
base64 and CBOR answers equal JSON ones; bad input gets a 400 or 413 that
names the field. closest-point: answers equal kdray-trace's bytes, each
point lies at the answered distance, max_distance keeps exactly the answers
within it, base64 and CBOR equal JSON, bad input is a 400 naming the field.
occupancy: answers equal kdray-trace's bytes, 0/1, CBOR uint8; signed
closest-point: |distance| equals the unsigned answer and is negative
exactly where occupancy says inside. Run by Debian's /usr/bin/python3
(python3-cbor2).
"""

import json
import os
import struct
import sys
import urllib.request

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import test_server_lib as lib  # noqa: E402

KDRAYD, TRACE, CLIENTS = sys.argv[1], sys.argv[2], sys.argv[3]
lib.add_client_path(CLIENTS)
from kdray_client import Client  # noqa: E402
import cbor2  # noqa: E402

SCENE = "default"
PATH = "/v1/scenes/%s/bundle" % SCENE
N = 5000  # two chunks


def f32(x):
    return struct.unpack("<f", struct.pack("<f", x))[0]


def post(c, body, accept=None):
    headers = {"Accept": accept} if accept else None
    return c.request("POST", PATH, json.dumps(body).encode(), "application/json",
                     headers=headers)


def problem(t, c, body, status, has):
    code, _, data = post(c, body)
    t.eq(code, status, "status for %s" % has)
    detail = json.loads(data).get("detail", "")
    t.check(has in detail, "detail %r names %r" % (detail, has))


def test_all_and_count(t, c):
    bounds = c.scene(SCENE)["bounds"]
    o, d = lib.rays_into_box(bounds, N, seed=15)
    payloads = [{"origins": o, "directions": d, "query": "all", "max_hits": k}
                for k in (1, 4, 1024)] + [{"origins": o, "directions": d,
                                            "query": "count"}]
    core = lib.core_answers(TRACE, [("bundle", p, "fast") for p in payloads])
    answers = []
    for p, want in zip(payloads, core):
        code, _, body = post(c, p)
        t.eq(code, 200, "status of %s" % p.get("max_hits", "count"))
        t.eq(body, want, "%s %s == kdray-trace bytes" % (p["query"], p.get("max_hits")))
        answers.append(json.loads(body))
    closest = c.bundle(SCENE, o, d, encoding="base64")
    counts = answers[3]["nhits"]
    t.eq(answers[3]["count"], N, "count answer's count")
    full = answers[2]
    multi = 0
    for k, a in zip((1, 4, 1024), answers[:3]):
        t.eq(len(a["nhits"]), N, "nhits length")
        t.eq(len(a["offset"]), N + 1, "offset length")
        t.eq(a["offset"][0], 0, "offset[0]")
        bad_order = bad_first = bad_prefix = bad_count = 0
        for i in range(N):
            lo, hi = a["offset"][i], a["offset"][i + 1]
            if hi - lo != a["nhits"][i] or a["nhits"][i] > k:
                bad_count += 1
            if k == 1024 and a["nhits"][i] != counts[i]:
                bad_count += 1
            if k < 1024 and a["nhits"][i] != min(k, counts[i]):
                bad_count += 1
            ts, ps = a["t"][lo:hi], a["prim"][lo:hi]
            if len(set(ps)) != len(ps) or any(
                    (ts[j], ps[j]) >= (ts[j + 1], ps[j + 1]) for j in range(len(ts) - 1)):
                bad_order += 1
            if hi > lo:
                multi += k == 1024 and hi - lo > 1
                if (ps[0] != closest["prim"][i] or f32(ts[0]) != closest["t"][i]
                        or f32(a["u"][lo]) != closest["u"][i]):
                    bad_first += 1
            elif closest["prim"][i] >= 0:
                bad_first += 1
            flo = full["offset"][i]
            if (ts != full["t"][flo:flo + hi - lo] or ps != full["prim"][flo:flo + hi - lo]):
                bad_prefix += 1
        t.eq(bad_count, 0, "max_hits %d: rays with a wrong nhits/offset" % k)
        t.eq(bad_order, 0, "max_hits %d: rays not in (t, prim) order or a prim twice" % k)
        t.eq(bad_first, 0, "max_hits %d: first hit != closest hit" % k)
        t.eq(bad_prefix, 0, "max_hits %d: list != prefix of the full list" % k)
    t.check(multi > N // 10, "many rays have several hits (%d)" % multi)
    # the same answers in base64 and CBOR
    b64 = c.bundle(SCENE, o, d, query="all", max_hits=4, encoding="base64")
    t.eq(b64["prim"], answers[1]["prim"], "base64 prim")
    t.eq(b64["nhits"], answers[1]["nhits"], "base64 nhits")
    t.eq(b64["t"], [f32(x) for x in answers[1]["t"]], "base64 t")
    code, hdr, body = post(c, payloads[1], accept="application/cbor")
    t.eq(code, 200, "CBOR status")
    cb = cbor2.loads(body)
    ints = lambda tag: list(struct.unpack("<%di" % (len(tag.value) // 4), tag.value))
    floats = lambda tag: list(struct.unpack("<%df" % (len(tag.value) // 4), tag.value))
    t.eq(ints(cb["offset"]), answers[1]["offset"], "CBOR offset")
    t.eq(ints(cb["prim"]), answers[1]["prim"], "CBOR prim")
    t.eq(floats(cb["v"]), [f32(x) for x in answers[1]["v"]], "CBOR v")
    cc = cbor2.loads(post(c, payloads[3], accept="application/cbor")[2])
    t.eq(ints(cc["nhits"]), counts, "CBOR count nhits")
    # a CBOR request (typed arrays, max_hits as a CBOR integer)
    cbin = Client(c.url, binary=True)
    got = cbin.bundle(SCENE, o, d, query="all", max_hits=4)
    t.eq(list(got["prim"]), answers[1]["prim"], "CBOR request: prim")
    t.eq(list(got["nhits"]), answers[1]["nhits"], "CBOR request: nhits")
    sel = c.bundle(SCENE, o[:3], d[:30], query="all", fields=["prim"])
    t.eq(sorted(sel), ["count", "nhits", "offset", "prim"], "fields select the arrays")


def test_bad(t, c):
    base = {"origins": [0, 0, 10], "directions": [0, 0, -1]}
    problem(t, c, dict(base, query="all", max_hits=0), 400, "max_hits")
    problem(t, c, dict(base, query="all", max_hits=1025), 400, "max_hits")
    problem(t, c, dict(base, query="all", max_hits=2.5), 400, "max_hits")
    problem(t, c, dict(base, query="closest", max_hits=3), 400, "max_hits")
    problem(t, c, dict(base, query="count", fields=["t"]), 400, "fields")
    problem(t, c, dict(base, query="all", fields=["hit"]), 400, "fields[0]")
    problem(t, c, dict(base, query="every"), 400, "query")
    many = {"origins": [0, 0, 10], "directions": [0, 0, -1] * 6000, "query": "all",
            "max_hits": 1001}
    problem(t, c, many, 413, "rays * max_hits")
    many["max_hits"] = 1000
    code, _, body = post(c, many)
    t.eq(code, 200, "6000 rays * 1000 hits within --max-rays 6000000")
    t.eq(json.loads(body)["nhits"], [3] * 6000, "three hits at a shared vertex")


CP_PATH = "/v1/scenes/%s/closest-point" % SCENE


def test_closest_point(t, c):
    import math
    import random
    rng = random.Random(7)
    bounds = c.scene(SCENE)["bounds"]
    lo, hi = bounds["min"], bounds["max"]
    pts = [rng.uniform(a - 2, b + 2) for _ in range(3000) for a, b in zip(lo, hi)]
    payloads = [{"points": pts}, {"points": pts, "max_distance": 0.5}]
    core = lib.core_answers(TRACE, [("closest-point", p, "fast") for p in payloads])
    answers = []
    for p, want in zip(payloads, core):
        code, _, body = c.request("POST", CP_PATH, json.dumps(p).encode(),
                                  "application/json")
        t.eq(code, 200, "closest-point status")
        t.eq(body, want, "closest-point == kdray-trace bytes")
        answers.append(json.loads(body))
    a, lim = answers
    t.eq(a["count"], 3000, "count")
    bad = found = 0
    for i in range(3000):
        q, p = a["point"][3 * i:3 * i + 3], pts[3 * i:3 * i + 3]
        d = math.dist(q, p)
        if a["prim"][i] < 0 or abs(d - a["distance"][i]) > 1e-5 * max(1.0, d):
            bad += 1
        # with a limit: the same answer where within it, none elsewhere
        if a["distance"][i] <= 0.5:
            found += 1
            bad += lim["prim"][i] != a["prim"][i] or lim["distance"][i] != a["distance"][i]
        else:
            bad += lim["prim"][i] != -1 or lim["distance"][i] != -1
    t.eq(bad, 0, "closest points at their distance, max_distance respected")
    t.check(0 < found < 3000, "some points within 0.5 (%d)" % found)
    code, _, body = c.request("POST", CP_PATH, json.dumps(dict(payloads[0], encoding="base64"))
                              .encode(), "application/json")
    from kdray_client import decode_answer
    b = decode_answer(json.loads(body))
    t.eq(b["prim"], a["prim"], "base64 prim")
    t.eq(b["distance"], [f32(x) for x in a["distance"]], "base64 distance")
    code, _, body = c.request("POST", CP_PATH, json.dumps(payloads[0]).encode(),
                              "application/json", headers={"Accept": "application/cbor"})
    cb = cbor2.loads(body)
    t.eq(list(struct.unpack("<%df" % (3 * 3000), cb["point"].value)),
         [f32(x) for x in a["point"]], "CBOR point")
    for body, has in (({"points": [0, 1]}, "points"), ({}, "points"),
                      ({"points": [0, 1, 2], "max_distance": -1}, "max_distance"),
                      ({"points": [0, 1, 2], "max_distance": "far"}, "max_distance"),
                      ({"points": [0, 1, float("inf")]}, "points[2]")):
        raw = json.dumps(body).replace("Infinity", "1e999").encode()
        code, _, data = c.request("POST", CP_PATH, raw, "application/json")
        t.eq(code, 400, "closest-point 400 for %s" % has)
        detail = json.loads(data).get("detail", "")
        t.check(has in detail, "detail %r names %r" % (detail, has))


OCC_PATH = "/v1/scenes/%s/occupancy" % SCENE


def test_occupancy_and_signed(t, c):
    import random
    rng = random.Random(9)
    bounds = c.scene(SCENE)["bounds"]
    lo, hi = bounds["min"], bounds["max"]
    n = 1500
    pts = [rng.uniform(a - 1, b + 1) for _ in range(n) for a, b in zip(lo, hi)]
    occ_body, cp_body = {"points": pts}, {"points": pts, "signed": True}
    core = lib.core_answers(TRACE, [("occupancy", occ_body, "fast"),
                                    ("closest-point", cp_body, "fast"),
                                    ("closest-point", {"points": pts}, "fast")])
    got = []
    for path, body, want in ((OCC_PATH, occ_body, core[0]), (CP_PATH, cp_body, core[1])):
        code, _, data = c.request("POST", path, json.dumps(body).encode(), "application/json")
        t.eq(code, 200, "%s status" % path)
        t.eq(data, want, "%s == kdray-trace bytes" % path)
        got.append(json.loads(data))
    occ, sgn = got
    plain = json.loads(core[2])
    t.eq(occ["count"], n, "occupancy count")
    t.check(set(occ["inside"]) <= {0, 1}, "inside is 0/1")
    t.check(0 < sum(occ["inside"]) < n, "some points inside (%d)" % sum(occ["inside"]))
    bad = sum(1 for i in range(n)
              if abs(sgn["distance"][i]) != plain["distance"][i]
              or (sgn["distance"][i] < 0) != (occ["inside"][i] == 1 and plain["distance"][i] > 0)
              or sgn["prim"][i] != plain["prim"][i])
    t.eq(bad, 0, "signed distance = unsigned, negative exactly where inside")
    code, _, data = c.request("POST", OCC_PATH, json.dumps(occ_body).encode(),
                              "application/json", headers={"Accept": "application/cbor"})
    cb = cbor2.loads(data)
    t.eq(cb["inside"].tag, 64, "CBOR inside is a uint8 typed array")
    t.eq(list(cb["inside"].value), occ["inside"], "CBOR inside")
    for path, body, has in ((OCC_PATH, {"points": [1, 2]}, "points"),
                            (OCC_PATH, {}, "points"),
                            (CP_PATH, {"points": [0, 1, 2], "signed": 1}, "signed"),
                            (CP_PATH, {"points": [0, 1, 2], "signed": True, "max_distance": 1},
                             "max_distance")):
        code, _, data = c.request("POST", path, json.dumps(body).encode(), "application/json")
        t.eq(code, 400, "400 for %s" % has)
        detail = json.loads(data).get("detail", "")
        t.check(has in detail, "detail %r names %r" % (detail, has))


def test_normal_and_mesh(t):
    """A scene whose normals and glTF indices are known: a quad at z = 0
    (counter-clockwise seen from +z: normal +z) as node 0 / mesh 0, and a
    tilted quad (normal (0, -0.6, 0.8)) as mesh 1, instanced by node 1 with a
    translation; node 2 is their parent. Bundle closest and all answers and
    a frustum answer carry the normals and (node, mesh, primitive) triples,
    which also match the scene's meshes table."""
    import math
    import tempfile
    sys.path.insert(0, os.path.join(HERE, "..", "scenes"))
    import glbutil
    g = glbutil.Glb("test_server_queries")
    flat = g.add_mesh("flat", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [0, 1, 2, 0, 2, 3])
    # tilted: spans x and the direction (0, 0.8, 0.6): normal x-axis cross that
    tilt = g.add_mesh("tilt", [(0, 0, 0), (1, 0, 0), (1, 0.8, 0.6), (0, 0.8, 0.6)],
                      [0, 1, 2, 0, 2, 3])
    n1 = g.add_node("flat", mesh=flat)
    n2 = g.add_node("tilt", mesh=tilt, translation=[3, 0, 0])
    g.add_node("root", children=[n1, n2], root=True)
    tmp = tempfile.mkdtemp(prefix="kdray-nm-")
    path = os.path.join(tmp, "nm.glb")
    g.write(path)
    d = lib.Daemon(KDRAYD, ["--threads", "1", "--scene", "nm=" + path], default_scene=False)
    try:
        c = Client(d.url)
        meshes = c.scene("nm")["meshes"]
        # the last ray meets the tilted quad on its diagonal (an edge shared
        # by its two triangles): two hits, as docs/API.md defines a hit
        o = [0.3, 0.6, 5, 3.5, 0.2, 5, 3.3, 5, 0.3, 9, 9, 9, 3.5, 5, 0.3]
        dirs = [0, 0, -1, 0, 0, -1, 0, -1, 0, 1, 0, 0, 0, -1, 0]
        for query in ("closest", "all"):
            a = c.bundle("nm", o, dirs, query=query, fields=["prim", "normal", "mesh"])
            t.eq(sorted(a), sorted(["count", "prim", "normal", "mesh"] +
                                   (["nhits", "offset"] if query == "all" else [])),
                 query + ": the arrays asked for")
            n, m = a["normal"], a["mesh"]
            if query == "all":  # one hit per ray for the first three: the same order
                t.eq(a["nhits"], [1, 1, 1, 0, 2], "all: hits per ray (2 on the shared edge)")
            want_n = [(0, 0, 1), (0, -0.6, 0.8), (0, -0.6, 0.8)]
            want_m = [(n1, flat, 0), (n2, tilt, 0), (n2, tilt, 0)]
            for i in range(3):
                got = n[3 * i:3 * i + 3]
                t.check(all(abs(x - y) < 1e-6 for x, y in zip(got, want_n[i])),
                        "%s ray %d: normal %r, want %r" % (query, i, got, want_n[i]))
                t.eq(tuple(m[3 * i:3 * i + 3]), want_m[i], "%s ray %d: node, mesh, primitive"
                     % (query, i))
                r = [x for x in meshes if x["first_prim"] <= a["prim"][i] <
                     x["first_prim"] + x["count"]][0]
                t.eq(tuple(m[3 * i:3 * i + 3]), (r["node"], r["mesh"], r["primitive"]),
                     "%s ray %d: mesh agrees with the scene's meshes table" % (query, i))
            if query == "closest":
                closest_mesh = m
                t.eq(n[9:12], [0, 0, 0], "a miss: normal 0,0,0")
                t.eq(m[9:12], [-1, -1, -1], "a miss: mesh -1,-1,-1")
                t.check(abs(math.hypot(*n[3:6]) - 1) < 1e-6, "unit normal")
        b64 = c.bundle("nm", o, dirs, fields=["normal", "mesh"], encoding="base64")
        t.eq(b64["mesh"], closest_mesh, "base64 mesh")
        code, _, body = c.request("POST", "/v1/scenes/nm/bundle", json.dumps(
            {"origins": o, "directions": dirs, "query": "any", "fields": ["normal"]}).encode(),
            "application/json")
        t.eq(code, 400, "normal of an any query")
        fr = c.call("POST", "/v1/scenes/nm/frustum",
                    {"camera": {"eye": [0.5, 0.5, 5], "target": [0.5, 0.5, 0], "fov_y_deg": 10,
                                "width": 4, "height": 4}, "fields": ["normal", "mesh"]})
        t.eq(fr["normal"], [0, 0, 1] * 16, "frustum normals")
        t.eq(fr["mesh"], [n1, flat, 0] * 16, "frustum meshes")
    finally:
        rc = d.stop()
        os.unlink(path)
        os.rmdir(tmp)
    t.eq(rc, 0, "kdrayd exit status")


def main():
    t = lib.Runner()
    d = lib.Daemon(KDRAYD, ["--threads", "2", "--max-rays", "6000000"])
    c = Client(d.url)
    try:
        t.run(test_all_and_count, c)
        t.run(test_bad, c)
        t.run(test_closest_point, c)
        t.run(test_occupancy_and_signed, c)
    finally:
        rc = d.stop()
    if rc != 0:
        print("FAIL kdrayd exited %s\n%s" % (rc, d.log_text()))
        t.failures.append("exit status")
    t.run(test_normal_and_mesh)
    return t.finish()


if __name__ == "__main__":
    sys.exit(main())

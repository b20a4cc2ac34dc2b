#!/usr/bin/env python3
"""test_server.py - integration tests of kdrayd over real HTTP.

    test_server.py KDRAYD KDRAY_TRACE CLIENTS_DIR

Starts the daemon on the bundled default scene (no --scene) on a free
loopback port and checks every endpoint with the Python client: answers
equal the core's own answers (kdray-trace, byte for byte for the modes the
daemon uses, value for value for the single-ray reference modes), bad input
of every kind gets the right problem+json status, concurrent clients get
the single-threaded answers, and SIGTERM lets a request in flight finish.
"""

import base64
import json
import os
import socket
import struct
import subprocess
import sys
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import test_server_lib as lib  # noqa: E402

KDRAYD, TRACE, CLIENTS = sys.argv[1], sys.argv[2], sys.argv[3]
lib.add_client_path(CLIENTS)
from kdray_client import Client, KdrayError, f32_b64  # noqa: E402

SCENE = "default"
BUNDLE_RAYS = 10000   # three 4096-ray chunks: the executor splits it
SHADOW_POINTS = 150   # three 64-point chunks
CONCURRENT_THREADS, CONCURRENT_REQUESTS = 8, 50


def bundle_path(scene=SCENE):
    return "/v1/scenes/%s/bundle" % scene


def post(c, path, body, content_type="application/json"):
    if isinstance(body, (dict, list)):
        body = json.dumps(body).encode()
    elif isinstance(body, str):
        body = body.encode()
    return c.request("POST", path, body, content_type)


def expect_problem(t, resp, status, what, detail_has=None):
    code, headers, body = resp
    t.eq(code, status, what + " status")
    ctype = {k.lower(): v for k, v in headers.items()}.get("content-type", "")
    t.eq(ctype, "application/problem+json", what + " content type")
    p = json.loads(body)
    t.eq(p.get("status"), status, what + " problem status")
    t.eq(p.get("type"), "about:blank", what + " problem type")
    t.check(isinstance(p.get("title"), str) and p["title"], what + " title")
    t.check(isinstance(p.get("detail"), str) and p["detail"], what + " detail")
    if detail_has:
        t.check(detail_has in p["detail"], "%s: detail %r lacks %r"
                % (what, p["detail"], detail_has))
    return p


# ---- read-only endpoints ----------------------------------------------------

def test_health_and_scenes(t, c, d):
    t.eq(c.health(), {"status": "ok", "scenes": 1}, "health")
    scenes = c.scenes()
    t.eq([s["name"] for s in scenes], [SCENE], "scene names")
    s = c.scene(SCENE)
    t.eq(s, scenes[0], "scene == scenes[0]")
    t.check(s["triangles"] > 0, "default scene has triangles")
    for key in ("nodes", "leaves", "empty_leaves", "max_depth", "refs_per_leaf",
                "sah_cost", "build_ms"):
        t.check(key in s["kdtree"], "kdtree." + key)
    t.check(s["kdtree"]["nodes"] >= s["kdtree"]["leaves"] >= 1, "node counts")
    first = 0
    for m in s["meshes"]:
        t.eq(m["first_prim"], first, "mesh ranges tile the triangles")
        first += m["count"]
    t.eq(first, s["triangles"], "mesh ranges cover every triangle")
    t.check(all(a <= b for a, b in zip(s["bounds"]["min"], s["bounds"]["max"])),
            "bounds")
    t.check(d.wait_log("ready:"), "ready is logged")
    log = d.log_text()
    t.check(log.index("listening on") < log.index("ready:"),
            "the port opens before the scenes are built")
    t.check("kd-tree built" in log, "scene statistics are logged")


metric = lib.metric


def test_metrics(t, c, d):
    before = c.metrics()
    o, dirs = lib.rays_into_box(c.scene(SCENE)["bounds"], 100, seed=7)
    for _ in range(3):
        c.bundle(SCENE, o, dirs)
    post(c, bundle_path(), "{")
    after = c.metrics()
    ok = dict(endpoint="bundle", status="200")
    bad = dict(endpoint="bundle", status="400")
    t.eq(metric(after, "kdray_http_requests_total", **ok)
         - metric(before, "kdray_http_requests_total", **ok), 3, "bundle 200 count")
    t.eq(metric(after, "kdray_http_errors_total", **bad)
         - metric(before, "kdray_http_errors_total", **bad), 1, "bundle 400 errors")
    t.eq(metric(after, "kdray_rays_traced_total", kind="bundle")
         - metric(before, "kdray_rays_traced_total", kind="bundle"), 300, "rays")
    t.check(metric(after, "kdray_http_request_duration_seconds_count",
                   endpoint="bundle") >= 4, "latency histogram counts")
    t.check(metric(after, "kdray_http_request_duration_seconds_bucket",
                   endpoint="bundle", le="+Inf") >= 4, "+Inf bucket")
    t.check(metric(after, "kdray_scene_build_seconds", scene=SCENE) > 0,
            "build time gauge")
    for line in after.splitlines():
        t.check(line.startswith("#") or len(line.split(" ")) == 2,
                "exposition line " + line)


# ---- queries against the core ------------------------------------------------

def bundle_payload(bounds, n, seed, query="closest", shared=False):
    o, dirs = lib.rays_into_box(bounds, n, seed, shared_origin=shared)
    return {"origins": o, "directions": dirs, "query": query}


def test_bundle_equals_core(t, c, d):
    bounds = c.scene(SCENE)["bounds"]
    cases = [(q, shared, bundle_payload(bounds, BUNDLE_RAYS, 11, q, shared))
             for q in ("closest", "any") for shared in (False, True)]
    specs = [("bundle", p, mode) for _, _, p in cases for mode in ("fast", "reference")]
    core = lib.core_answers(TRACE, specs)
    for k, (query, shared, p) in enumerate(cases):
        code, _, body = post(c, bundle_path(), p)
        t.eq(code, 200, "bundle status")
        what = "bundle %s shared=%s" % (query, shared)
        t.eq(body, core[2 * k], what + " == core bytes")
        t.eq(json.loads(body), json.loads(core[2 * k + 1]),
             what + " == single-ray reference")
        a = json.loads(body)
        t.eq(a["count"], BUNDLE_RAYS, "count")
        if query == "closest":
            hits = sum(1 for x in a["prim"] if x >= 0)
            t.check(hits > BUNDLE_RAYS // 10, "rays into the box hit (%d)" % hits)


def test_bundle_base64_and_any(t, c, d):
    bounds = c.scene(SCENE)["bounds"]
    o, dirs = lib.rays_into_box(bounds, 3000, seed=5)
    js = c.bundle(SCENE, o, dirs)
    b64 = c.bundle(SCENE, o, dirs, send="base64", encoding="base64")
    f32 = lambda xs: [struct.unpack("<f", struct.pack("<f", x))[0] for x in xs]
    for k in ("t", "u", "v"):
        t.eq(f32(js[k]), b64[k], "base64 answer %s equals JSON answer" % k)
    t.eq(js["prim"], b64["prim"], "base64 prim")
    anyhit = c.bundle(SCENE, o, dirs, query="any")
    t.eq(anyhit["hit"], [1 if p >= 0 else 0 for p in js["prim"]],
         "any-hit iff a closest hit")
    # A closest hit at t lies inside [0, t] (closed) and nothing is nearer.
    hit_idx = [i for i, p in enumerate(js["prim"]) if p >= 0][:500]
    oo = [x for i in hit_idx for x in o[3 * i:3 * i + 3]]
    dd = [x for i in hit_idx for x in dirs[3 * i:3 * i + 3]]
    at_t = c.bundle(SCENE, oo, dd, tmax=[js["t"][i] for i in hit_idx], query="any")
    t.eq(at_t["hit"], [1] * len(hit_idx), "any-hit with tmax = closest t")
    before = c.bundle(SCENE, oo, dd, tmax=[js["t"][i] * 0.5 for i in hit_idx])
    t.eq(before["prim"], [-1] * len(hit_idx), "nothing before half the closest t")
    past = c.bundle(SCENE, oo, dd, tmin=[js["t"][i] * 1.0001 + 1e-6 for i in hit_idx])
    t.check(all(p != js["prim"][i] or tt > js["t"][i]
                for i, p, tt in zip(hit_idx, past["prim"], past["t"])),
            "tmin past the hit skips it")


def shadow_payload(bounds, n, seed):
    o, _ = lib.rays_into_box(bounds, n, seed)
    lo, hi = bounds["min"], bounds["max"]
    size = max(b - a for a, b in zip(lo, hi)) or 1.0
    center = [(a + b) / 2 for a, b in zip(lo, hi)]
    pts = []
    rng = lib.random.Random(seed)
    for _ in range(n):
        pts += [rng.uniform(a, b) for a, b in zip(lo, hi)]
    lights = [{"center": [center[0], hi[1] + 2 * size, center[2]], "radius": size / 4},
              {"center": [hi[0] + size, center[1], center[2]], "radius": size / 10}]
    return {"points": pts, "lights": lights, "samples": 16, "seed": 3,
            "stats": True}


def test_shadow_equals_core(t, c, d):
    p = shadow_payload(c.scene(SCENE)["bounds"], SHADOW_POINTS, 21)
    plain = dict(p, stats=False)
    # 64 samples: the whole-light walk, its back-off and the last blockers,
    # state carried from point to point, so the stats depend on where the
    # point chunks start (core/kdray.h; exec/kdr_exec.h KDR_EXEC_CHUNK_POINTS,
    # KDR_EXEC_CHUNK_SHADOW_RAYS: kdrayd and kdray-trace run the same executor);
    # 16 samples take the stateless path below 32.
    walk = dict(p, samples=64)
    sp = "/v1/scenes/%s/cone-shadow" % SCENE
    core, core_stats, core_walk = lib.core_answers(
        TRACE, [("cone-shadow", plain, "fast"), ("cone-shadow", p, "fast"),
                ("cone-shadow", walk, "fast")])
    code, _, body = post(c, sp, plain)
    t.eq(code, 200, "cone-shadow status")
    t.eq(body, core, "cone-shadow == core bytes")
    # Same calls on the same scene: every stat is equal, nodes_visited too.
    got = {}
    for what, req, want_body in (("16 samples", p, core_stats),
                                 ("64 samples", walk, core_walk)):
        code, _, body = post(c, sp, req)
        t.eq(code, 200, "cone-shadow with stats, " + what)
        a, want = json.loads(body), json.loads(want_body)
        t.eq(a["visibility"], want["visibility"], "cone-shadow == core, " + what)
        for key in ("cones_decided", "rays_traced", "nodes_visited"):
            t.eq(a["stats"][key], want["stats"][key], "stats.%s, %s" % (key, what))
        t.check(a["stats"]["nodes_visited"] > 0, "nodes_visited counted, " + what)
        got[what] = a
    a = got["16 samples"]
    t.eq(a["count"], SHADOW_POINTS, "count")
    t.eq(len(a["visibility"]), 2 * SHADOW_POINTS, "N*L visibilities")
    t.check(all(0.0 <= v <= 1.0 for v in a["visibility"]), "visibility in [0,1]")
    t.check(0 < a["stats"]["cones_decided"] + a["stats"]["rays_traced"], "stats")
    b64 = c.shadow(SCENE, p["points"], p["lights"], samples=16, seed=3,
                   encoding="base64")
    f32 = [struct.unpack("<f", struct.pack("<f", x))[0] for x in a["visibility"]]
    t.eq(b64["visibility"], f32, "base64 visibility")
    inside = dict(p, points=p["lights"][0]["center"] + p["points"][3:])
    expect_problem(t, post(c, "/v1/scenes/%s/cone-shadow" % SCENE, inside), 400,
                   "point inside a light", "points[0]: inside lights[0]")
    # API v1.1: "auto" is the default offset; a numeric epsilon whose offset
    # (epsilon * diagonal) overflows float is a 400 naming epsilon, not a point
    auto = dict(plain, epsilon="auto")
    code, _, body = post(c, sp, auto)
    t.eq((code, body), (200, core), "epsilon \"auto\" is the default")
    huge = dict(plain, epsilon=3e38)
    expect_problem(t, post(c, sp, huge), 400, "overflowing epsilon offset",
                   "epsilon: ")


def camera_payload(bounds, w, h, tile, query="closest", encoding="base64"):
    lo, hi = bounds["min"], bounds["max"]
    center = [(a + b) / 2 for a, b in zip(lo, hi)]
    size = max(b - a for a, b in zip(lo, hi)) or 1.0
    eye = [center[0] + 0.3 * size, center[1] + 0.4 * size, center[2] + 1.5 * size]
    return {"camera": {"eye": eye, "target": center, "up": [0, 1, 0],
                       "fov_y_deg": 50, "width": w, "height": h},
            "tile": tile, "query": query, "encoding": encoding}


def test_frustum_equals_core(t, c, d):
    bounds = c.scene(SCENE)["bounds"]
    cases = [camera_payload(bounds, w, h, tile, q)
             for w, h, tile, q in ((97, 61, 8, "closest"), (64, 48, 4, "any"),
                                   (40, 30, 64, "closest"))]
    core = lib.core_answers(TRACE, [("frustum", p, mode) for p in cases
                                    for mode in ("fast", "reference")])
    for k, p in enumerate(cases):
        code, _, body = post(c, "/v1/scenes/%s/frustum" % SCENE, p)
        cam = p["camera"]
        what = "frustum %dx%d tile %d %s" % (cam["width"], cam["height"], p["tile"],
                                             p["query"])
        t.eq(code, 200, what)
        t.eq(body, core[2 * k], what + " == core bytes")
        t.eq(json.loads(body), json.loads(core[2 * k + 1]),
             what + " == per-pixel reference")
    a = c.frustum(SCENE, cam["eye"], cam["target"], 40, 30)
    t.check(sum(1 for x in a["prim"] if x >= 0) > 0, "the camera sees the scene")


# ---- bad input -----------------------------------------------------------------

def test_bad_requests(t, c, d):
    bp = bundle_path()
    good = {"origins": [0, 0, 0], "directions": [0, 0, 1]}
    expect_problem(t, post(c, bp, "{\"origins\": [0,0"), 400, "malformed JSON")
    body = json.dumps(bundle_payload(c.scene(SCENE)["bounds"], 50, 1))
    expect_problem(t, post(c, bp, body[:len(body) // 2]), 400, "truncated body")
    expect_problem(t, post(c, bp, ""), 400, "empty body")
    expect_problem(t, post(c, bp, "[]"), 400, "not an object")
    expect_problem(t, post(c, bp, good, "text/plain"), 415, "text/plain")
    expect_problem(t, post(c, bp, good, None), 415, "no content type")
    expect_problem(t, post(c, bp, good, "application/json; charset=latin1"), 415,
                   "latin1 charset")
    t.eq(post(c, bp, good, "Application/JSON; charset=UTF-8")[0], 200,
         "content type is case-insensitive, charset utf-8 allowed")
    expect_problem(t, post(c, bp, '{"origins":[0,0,0],"directions":[0,0,NaN]}'),
                   400, "NaN token")
    expect_problem(t, post(c, bp, '{"origins":[0,0,0],"directions":[0,0,1e39]}'),
                   400, "beyond float32")
    nan = struct.unpack("<f", b"\x00\x00\xc0\x7f")[0]
    for bad, name in ((nan, "NaN"), (float("inf"), "Inf")):
        p = {"origins": [0, 0, 0], "directions": f32_b64([0, 0, 1, 0, bad, 1])}
        expect_problem(t, post(c, bp, p), 400, "base64 " + name, "directions")
    expect_problem(t, post(c, bp, {"origins": [0, 0, 0], "directions": []}), 400,
                   "zero rays")
    expect_problem(t, post(c, bp, {"origins": [0, 0, 0], "directions": [0, 0, 0]}),
                   400, "all-zero direction")
    expect_problem(t, post(c, bp, {"origins": [0, 0, 0], "directions": [0, 1]}),
                   400, "directions not a multiple of 3")
    expect_problem(t, post(c, bp, {"origins": [0, 0, 0], "directions": {"f32": "@@"}}),
                   400, "bad base64")
    expect_problem(t, post(c, bp, dict(good, query="nearest")), 400, "bad query")
    fr = "/v1/scenes/%s/frustum" % SCENE
    cam = camera_payload(c.scene(SCENE)["bounds"], 8, 8, 4)
    expect_problem(t, post(c, fr, dict(cam, tile=3)), 400, "tile below 4")
    cam2 = json.loads(json.dumps(cam))
    cam2["camera"]["target"] = cam2["camera"]["eye"]
    expect_problem(t, post(c, fr, cam2), 400, "eye == target")
    sp = "/v1/scenes/%s/cone-shadow" % SCENE
    expect_problem(t, post(c, sp, {"points": [0, 0, 0], "lights": []}), 400,
                   "no lights")
    expect_problem(t, post(c, sp, {"points": [0, 0, 0], "samples": 0, "lights":
                                   [{"center": [9, 9, 9], "radius": 1}]}), 400,
                   "zero samples")


def mutations(body, n, seed):
    """n corrupted copies of body: flipped, deleted, duplicated and inserted
    bytes, cut tails, and JSON-ish tokens dropped into random places."""
    rng = lib.random.Random(seed)
    tokens = [b"NaN", b"-", b"1e999", b"null", b"{", b"]", b'"', b"\\u0000", b"\xff",
              b"-0", b"0x10", b"[[[[", b'{"f32": "AAAA"}', b",", b"1e-50"]
    for _ in range(n):
        b = bytearray(body)
        for _ in range(rng.randint(1, 4)):
            i = rng.randrange(len(b) + 1)
            op = rng.randrange(5)
            if op == 0 and i < len(b):
                b[i] = rng.randrange(256)
            elif op == 1:
                del b[i:i + rng.randint(1, 8)]
            elif op == 2:
                b[i:i] = b[i:i + rng.randint(1, 16)]
            elif op == 3:
                b[i:i] = rng.choice(tokens)
            else:
                del b[i:]
        yield bytes(b)


def test_mutated_bodies(t, c, d):
    bounds = c.scene(SCENE)["bounds"]
    seeds = [
        ("bundle", bundle_payload(bounds, 5, 9)),
        ("bundle", {"origins": f32_b64([0, 0, 9]), "directions": f32_b64([0, 0, -1] * 4),
                    "tmax": [5, 6, 7, 8], "query": "any", "encoding": "base64"}),
        ("cone-shadow", shadow_payload(bounds, 3, 2)),
        ("frustum", camera_payload(bounds, 9, 7, 4, encoding="json")),
    ]
    statuses = {}
    for k, (kind, payload) in enumerate(seeds):
        path = "/v1/scenes/%s/%s" % (SCENE, kind)
        for body in mutations(json.dumps(payload).encode(), 60, k):
            code, headers, data = post(c, path, body)
            statuses[code] = statuses.get(code, 0) + 1
            if code != 200:
                expect_problem(t, (code, headers, data), code, "mutated %s" % kind)
            t.check(code in (200, 400, 413), "mutated %s: status %d for %r: %r"
                    % (kind, code, body[:200], data[:200]))
    t.check(statuses.get(400, 0) > 0, "mutations do produce 400s: %r" % statuses)
    t.eq(c.health()["status"], "ok", "daemon alive after mutated bodies")


def test_routing_errors(t, c, d):
    expect_problem(t, post(c, bundle_path("nosuch"), {}), 404, "unknown scene")
    expect_problem(t, c.request("GET", "/v1/scenes/nosuch"), 404, "unknown scene GET")
    expect_problem(t, c.request("GET", "/v2/health"), 404, "unknown path")
    expect_problem(t, c.request("GET", "/v1/scenes/%s/raymarch" % SCENE), 404,
                   "unknown query")
    r = c.request("GET", bundle_path())
    expect_problem(t, r, 405, "GET on bundle")
    t.eq(r[1].get("Allow"), "POST", "Allow header on a query endpoint")
    r = c.request("DELETE", "/v1/scenes/%s" % SCENE)
    expect_problem(t, r, 405, "DELETE on a scene")
    t.eq(r[1].get("Allow"), "GET, HEAD", "Allow header on a GET endpoint")
    expect_problem(t, post(c, "/v1/health", {}), 405, "POST on health")
    t.eq(c.request("HEAD", "/v1/health")[0], 200, "HEAD on health")


def raw_http(url, data, read=True, half_close=True):
    """Sends data on a new connection and reads until the server closes it.
    half_close shuts our sending side first; kdrayd treats a query's client
    that did so as gone (it cannot send anything more), so a raw query that
    wants its answer sends Connection: close instead."""
    host, port = url.split("//")[1].split(":")
    with socket.create_connection((host, int(port)), timeout=20) as s:
        s.sendall(data)
        if not read:
            return b""
        if half_close:
            s.shutdown(socket.SHUT_WR)
        out = b""
        while True:
            chunk = s.recv(65536)
            if not chunk:
                return out
            out += chunk


def in_flight(c):
    return metric(c.metrics(), "kdray_http_requests_in_flight")


def test_broken_connections(t, c, d):
    path = bundle_path().encode()
    hdr = (b"POST " + path + b" HTTP/1.1\r\nHost: x\r\nContent-Type: "
           b"application/json\r\nContent-Length: 1000\r\n\r\n")
    base = in_flight(c)
    raw_http(c.url, hdr + b'{"origins": [0,0,0], "dir', read=False)  # hang up
    # Poll until it drops; the value checked is the one polled, because a
    # scrape that answered a moment ago can still count as in flight.
    deadline = time.time() + 30
    while (now := in_flight(c)) > base and time.time() < deadline:
        time.sleep(0.01)
    t.eq(now, base, "a client that hangs up mid-body is forgotten")
    reply = raw_http(c.url, b"GARBAGE\r\n\r\n")
    t.check(reply == b"" or reply.startswith(b"HTTP/1.1 4"), "garbage: %r" % reply[:40])
    reply = raw_http(c.url, b"POST " + path + b" HTTP/1.1\r\nHost: x\r\nContent-Type:"
                     b" application/json\r\nContent-Length: -5\r\n\r\n")
    t.check(reply == b"" or reply.startswith(b"HTTP/1.1 4"), "negative length")
    reply = raw_http(c.url, hdr.replace(b"1000", b"8").replace(
        b"\r\n\r\n", b"\r\nConnection: close\r\n\r\n") + b"[1,2,3]}", half_close=False)
    t.check(reply.startswith(b"HTTP/1.1 400"), "raw 400: %r" % reply[:40])
    t.eq(c.health()["status"], "ok", "daemon alive after broken connections")


# ---- concurrency ---------------------------------------------------------------

def test_concurrent_clients(t, c, d):
    bounds = c.scene(SCENE)["bounds"]
    sizes = [1, 7, 100, 5000, 300]
    payloads = [bundle_payload(bounds, n, 100 + i, "closest" if i % 2 else "any")
                for i, n in enumerate(sizes)]
    payloads.append(camera_payload(bounds, 33, 17, 4))
    payloads.append(shadow_payload(bounds, 70, 4))
    paths = [bundle_path()] * len(sizes) + ["/v1/scenes/%s/frustum" % SCENE,
                                            "/v1/scenes/%s/cone-shadow" % SCENE]
    want = [post(c, p, b) for p, b in zip(paths, payloads)]  # one at a time
    errors = []

    def worker(k):
        cl = Client(c.url)
        for i in range(CONCURRENT_REQUESTS):
            j = (k + i) % len(payloads)
            got = post(cl, paths[j], payloads[j])
            if got[0] != 200 or got[2] != want[j][2]:
                errors.append((k, i, j, got[0]))

    threads = [threading.Thread(target=worker, args=(k,))
               for k in range(CONCURRENT_THREADS)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    t.eq(errors, [], "concurrent answers equal single-threaded ones")


def test_client_cli(t, c, d):
    cli = os.path.join(CLIENTS, "kdray_client.py")
    pgm = os.path.join(os.environ.get("TMPDIR", "/tmp"), "kdray-test-%d.pgm" % os.getpid())
    run = lambda *a: subprocess.run([sys.executable, cli, "--url", c.url] + list(a),
                                    capture_output=True, text=True, timeout=120)
    r = run("scenes")
    t.eq(r.returncode, 0, "client scenes: " + r.stderr)
    t.eq(json.loads(r.stdout)["scenes"][0]["name"], SCENE, "client scenes output")
    r = run("bundle", "--origin", "0,0,0", "--random", "50", "--encoding", "base64")
    t.eq(r.returncode, 0, "client bundle: " + r.stderr)
    t.eq(json.loads(r.stdout)["count"], 50, "client bundle count")
    lo, hi = c.scene(SCENE)["bounds"]["min"], c.scene(SCENE)["bounds"]["max"]
    eye = ",".join(str(2 * b - a) for a, b in zip(lo, hi))
    target = ",".join(str((a + b) / 2) for a, b in zip(lo, hi))
    r = run("frustum", "--eye=" + eye, "--target=" + target, "--width", "32",
            "--height", "24", "--pgm", pgm)
    t.eq(r.returncode, 0, "client frustum: " + r.stderr)
    with open(pgm, "rb") as f:
        data = f.read()
    os.unlink(pgm)
    t.check(data.startswith(b"P5\n32 24\n255\n") and len(data) == 13 + 32 * 24, "PGM")
    r = run("shadow", "--point=" + target, "--light=" + eye + ",0.5")
    t.eq(r.returncode, 0, "client shadow: " + r.stderr)
    r = run("bundle", "--dir", "0,0,0")
    t.eq(r.returncode, 1, "client reports a 400 with exit 1")


# ---- other daemons: limits, shutdown, flags --------------------------------------

def test_limits(t):
    d = lib.Daemon(KDRAYD, ["--max-body-mb", "1", "--max-rays", "100", "--threads", "1"])
    try:
        c = Client(d.url)
        bp = bundle_path()
        big = b'{"origins": [0,0,0], "directions": [' + b"0," * 700000 + b"1]}"
        expect_problem(t, post(c, bp, big), 413, "body over --max-body-mb",
                       "limit")
        chunks = (big[i:i + 65536] for i in range(0, len(big), 65536))
        r = c.request("POST", bp, chunks, headers={"Transfer-Encoding": "chunked"})
        expect_problem(t, r, 413, "chunked body over the limit")
        o, dirs = lib.rays_into_box(c.scene(SCENE)["bounds"], 101, 1)
        expect_problem(t, post(c, bp, {"origins": o, "directions": dirs}), 413,
                       "101 rays over --max-rays 100")
        t.eq(len(c.bundle(SCENE, o[:300], dirs[:300])["t"]), 100, "100 rays pass")
        cam = camera_payload(c.scene(SCENE)["bounds"], 11, 10, 4)
        expect_problem(t, post(c, "/v1/scenes/%s/frustum" % SCENE, cam), 413,
                       "110 pixels over --max-rays 100")
        t.eq(c.health()["status"], "ok", "alive after limits")
    finally:
        d.signal(lib.signal.SIGINT)
        t.eq(d.wait(), 0, "exit status after SIGINT")
        t.check("received SIGINT" in d.log_text(), "SIGINT logged")


def test_sigterm_in_flight(t):
    d = lib.Daemon(KDRAYD, ["--threads", "2"])
    c = Client(d.url)
    o, dirs = lib.rays_into_box(c.scene(SCENE)["bounds"], 1, 1)
    big = {"origins": o, "directions": f32_b64(dirs * 400000), "encoding": "base64"}
    result = {}

    def slow():
        result["r"] = post(Client(d.url, timeout=600), bundle_path(), big)

    th = threading.Thread(target=slow)
    th.start()
    deadline = time.time() + 120
    while time.time() < deadline:  # in flight: the big one plus this scrape
        if metric(c.metrics(), "kdray_http_requests_in_flight") >= 2:
            break
        time.sleep(0.01)
    d.signal()
    th.join(600)
    rc = d.wait()
    t.eq(result["r"][0], 200, "the request in flight completed")
    t.eq(json.loads(result["r"][2])["count"], 400000, "with its whole answer")
    t.eq(rc, 0, "exit 0 after SIGTERM")
    t.check("received SIGTERM" in d.log_text(), "shutdown logged")


def test_startup_503_and_two_scenes(t, default_path):
    """The port answers 503 while a scene is still loading (its path is a
    FIFO we have not written yet); with two threads the other scene is built
    meanwhile (scenes build at once, not one after the other); then both
    scenes serve the same answers."""
    tmp = lib.tempfile.mkdtemp(prefix="kdray-fifo-")
    fifo = os.path.join(tmp, "scene.glb")
    os.mkfifo(fifo)
    d = lib.Daemon(KDRAYD, ["--scene", "a=" + fifo, "--scene", "b=" + default_path,
                            "--threads", "2"],
                   wait_ready=False, default_scene=False)
    try:
        c = Client(d.url)
        p = expect_problem(t, c.request("GET", "/v1/health"), 503, "health while loading")
        t.check(" of 2 scenes built" in p["detail"], "starting detail: " + p["detail"])
        try:
            c.ready()
            t.check(False, "client ready() raises while loading")
        except KdrayError as err:
            t.check(err.status == 503 and err.problem["detail"].startswith("starting"),
                    "client ready() while loading: %r" % err.problem)
        expect_problem(t, post(c, "/v1/scenes/b/bundle", {}), 503, "query while loading")
        expect_problem(t, c.request("GET", "/v1/scenes"), 503, "scenes while loading")
        t.eq(metric(c.metrics(), "kdray_ready"), 0.0, "metrics answer while loading")
        deadline = time.time() + 60
        while (metric(c.metrics(), "kdray_scene_build_seconds", scene="b") == 0
               and time.time() < deadline):
            time.sleep(0.05)
        t.check(metric(c.metrics(), "kdray_scene_build_seconds", scene="b") > 0,
                "b built while a still loads")
        t.eq(metric(c.metrics(), "kdray_scene_build_seconds", scene="a"), 0.0,
             "no gauge for a scene still loading")
        p = expect_problem(t, c.request("GET", "/v1/health"), 503, "health, a loading")
        t.check("1 of 2" in p["detail"], "starting detail: " + p["detail"])
        with open(default_path, "rb") as src, open(fifo, "wb") as dst:
            dst.write(src.read())
        d.wait_healthy()
        t.eq(c.health(), {"status": "ok", "scenes": 2}, "health with two scenes")
        t.eq((c.ready()["status"], c.ready()["scenes"]), ("ready", 2), "client ready()")
        t.eq([s["name"] for s in c.scenes()], ["a", "b"], "scenes in flag order")
        o, dirs = lib.rays_into_box(c.scene("a")["bounds"], 500, 3)
        t.eq(c.bundle("a", o, dirs), c.bundle("b", o, dirs), "same file, same answers")
    finally:
        t.eq(d.stop(), 0, "exit 0")
        os.unlink(fifo)
        os.rmdir(tmp)


def test_flags(t):
    def run(*args):
        return subprocess.run([KDRAYD] + list(args), capture_output=True, text=True,
                              timeout=300)
    r = run("--help")
    t.eq(r.returncode, 0, "--help")
    t.check("--max-rays" in r.stdout, "--help lists flags")
    r = run("--version")
    t.check(r.returncode == 0 and r.stdout.startswith("kdrayd "), "--version")
    for bad in (["--bogus"], ["--threads", "0"], ["--threads", "x"], ["--threads"],
                ["--max-body-mb", "0"], ["--max-rays", "-1"], ["--listen", "nope"],
                ["--scene", "noequals"], ["--scene", "a b=x.glb"],
                ["--scene", "a=x.glb", "--scene", "a=y.glb"]):
        r = run(*bad)
        t.eq(r.returncode, 2, "exit 2 for %s" % bad)
        t.check(r.stderr.strip() and r.stderr.count("\n") == 1,
                "one-line error for %s: %r" % (bad, r.stderr))
    r = run("--listen", "127.0.0.1:0", "--scene", "x=/nonexistent/scene.glb")
    t.eq(r.returncode, 1, "a scene that fails to load exits 1")
    t.check("error: scene x:" in r.stderr, "the load error is logged")


def main():
    t = lib.Runner()
    d = lib.Daemon(KDRAYD, ["--threads", "2"])
    c = Client(d.url)
    try:
        for fn in (test_health_and_scenes, test_metrics, test_bundle_equals_core,
                   test_bundle_base64_and_any, test_shadow_equals_core,
                   test_frustum_equals_core, test_bad_requests, test_mutated_bodies,
                   test_routing_errors,
                   test_broken_connections, test_concurrent_clients, test_client_cli):
            t.run(fn, c, d)
    finally:
        rc = d.stop()
    if rc != 0:
        print("FAIL kdrayd exited %s\n%s" % (rc, d.log_text()))
        t.failures.append("exit status")
    for fn in (test_limits, test_sigterm_in_flight, test_flags):
        t.run(fn)
    loaded = [l for l in d.log if "scene default: loading " in l]
    t.run(test_startup_503_and_two_scenes, loaded[0].split("loading ", 1)[1])
    return t.finish()


if __name__ == "__main__":
    sys.exit(main())

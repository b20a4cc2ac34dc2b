#!/usr/bin/env python3
"""test_render.py - GET /v1/scenes/{name}/render.png against the daemon's
own query answers (ctest render_png).

A small scene (one mesh, no node transforms, so its triangles here are the
core's floats) is served by a real kdrayd. For one camera and light the
test fetches the frustum query's hits and the cone-shadow query's
visibilities from that daemon, recomputes the picture from them in float32
arithmetic (every float operation rounded to float32, in the order
render/kdr_render.c documents), and requires render.png, decoded by Pillow
(Debian python3-pil), to equal it pixel for pixel. Nothing is a stored image.
Also: defaults frame the scene, bad parameters are 400s naming the
parameter, pixels count against --max-rays, deadlines stop a render,
Server-Timing and X-Kdray-Render are there and agree with the queries.

Usage: test_render.py KDRAYD CLIENTS_DIR
"""

import io
import math
import os
import struct
import sys
import tempfile
import urllib.parse

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, "..", "scenes"))
import test_server_lib as lib  # noqa: E402
from glbutil import Glb  # noqa: E402

try:
    from PIL import Image  # Debian python3-pil: the real decoder this test needs
except ImportError:  # fail, never skip
    print("FAIL: Pillow (Debian package python3-pil) is missing")
    sys.exit(1)

_F = struct.Struct("<f")


def F(x):
    """x rounded to float32 (a basic operation done in double and rounded
    once gives the float32 result exactly)."""
    return _F.unpack(_F.pack(x))[0]


AMBIENT, DIFFUSE = F(0.12), F(0.88)
ALBEDO = (F(0.84), F(0.80), F(0.74))
HALF_DEG_TO_RAD = 0.008726646259971647884618453842443


def scene_triangles():
    """A floor, a box standing on it and a slanted panel above: shadows,
    penumbrae and faces seen from both sides. One mesh, triangles in order."""
    pos, idx = [], []

    def quad(a, b, c, d):
        base = len(pos)
        pos.extend([a, b, c, d])
        idx.extend([base, base + 1, base + 2, base, base + 2, base + 3])

    quad((-4, 0, -4), (-4, 0, 4), (4, 0, 4), (4, 0, -4))  # floor, +y
    x0, x1, z0, z1, h = -1.0, 1.0, -1.0, 1.0, 1.5
    quad((x0, h, z0), (x0, h, z1), (x1, h, z1), (x1, h, z0))  # top
    quad((x0, 0.01, z1), (x1, 0.01, z1), (x1, h, z1), (x0, h, z1))  # front
    quad((x1, 0.01, z1), (x1, 0.01, z0), (x1, h, z0), (x1, h, z1))  # right
    quad((x0, 0.01, z0), (x0, h, z0), (x1, h, z0), (x1, 0.01, z0))  # back
    quad((x0, 0.01, z0), (x0, 0.01, z1), (x0, h, z1), (x0, h, z0))  # left
    quad((1.5, 2.5, -2.5), (3.0, 2.0, -2.5), (3.0, 2.5, -1.0), (1.5, 3.0, -1.0))  # panel
    tris = []
    for t in range(len(idx) // 3):
        tri = []
        for k in range(3):
            tri.extend(F(c) for c in pos[idx[3 * t + k]])
        tris.append(tri)
    return pos, idx, tris


def write_scene(path):
    pos, idx, tris = scene_triangles()
    g = Glb("test_render.py")
    g.add_node("all", g.add_mesh("all", pos, idx), root=True)
    g.write(path)
    return tris


# ---- float32 camera and shading, as render/kdr_render.c defines them ----

def norm3(v):
    ln = F(math.sqrt(F(F(F(v[0] * v[0]) + F(v[1] * v[1])) + F(v[2] * v[2]))))
    return [F(c / ln) for c in v], ln


def cross3(a, b):
    return [F(F(a[1] * b[2]) - F(a[2] * b[1])), F(F(a[2] * b[0]) - F(a[0] * b[2])),
            F(F(a[0] * b[1]) - F(a[1] * b[0]))]


def camera_dirs(eye, target, up, fov, w, h):
    f, _ = norm3([F(F(t) - F(e)) for t, e in zip(target, eye)])
    r, _ = norm3(cross3(f, [F(c) for c in up]))
    u = cross3(r, f)
    th = F(math.tan(F(fov) * HALF_DEG_TO_RAD))
    fw, fh = F(w), F(h)
    a = F(fw / fh)
    dirs = []
    for py in range(h):
        sy = F(F(1.0 - F(F(2.0 * F(py + 0.5)) / fh)) * th)
        for px in range(w):
            sx = F(F(F(F(F(2.0 * F(px + 0.5)) / fw) - 1.0) * th) * a)
            dirs.append([F(F(f[i] + F(sx * r[i])) + F(sy * u[i])) for i in range(3)])
    return dirs


def hit_geometry(eye, dirs, t, prim, tris):
    points, normals = [], []
    for i, d in enumerate(dirs):
        if prim[i] < 0:
            points.append(None)
            normals.append(None)
            continue
        p = [F(F(eye[c]) + F(F(t[i]) * d[c])) for c in range(3)]
        v = tris[prim[i]]
        e1 = [F(v[3 + c] - v[c]) for c in range(3)]
        e2 = [F(v[6 + c] - v[c]) for c in range(3)]
        n = cross3(e1, e2)
        ln = F(math.sqrt(F(F(F(n[0] * n[0]) + F(n[1] * n[1])) + F(n[2] * n[2]))))
        n = [F(c / ln) for c in n] if ln > 0 else [0.0, 0.0, 0.0]
        if F(F(F(d[0] * n[0]) + F(d[1] * n[1])) + F(d[2] * n[2])) > 0:
            n = [-c for c in n]
        points.append(p)
        normals.append(n)
    return points, normals


def to8(v):
    v = F(F(v * 255.0) + 0.5)
    return 255 if v >= 255.0 else int(v)


def expected_image(mode, w, h, prim, points, normals, vis, light):
    out = []
    for i in range(w * h):
        y = i // w
        if prim[i] < 0:
            k = (24 * y) // h
            out.append((58 - k, 66 - k, 82 - k))
            continue
        p, n = points[i], normals[i]
        if mode == "normal":
            out.append(tuple(to8(F(F(c * 0.5) + 0.5)) for c in n))
        elif mode == "shadow":
            g = to8(F(AMBIENT + F(DIFFUSE * F(vis[i]))))
            out.append((g, g, g))
        else:
            lv = [F(F(light[c]) - p[c]) for c in range(3)]
            ll = F(math.sqrt(F(F(F(lv[0] * lv[0]) + F(lv[1] * lv[1])) + F(lv[2] * lv[2]))))
            ndl = F(F(F(F(n[0] * lv[0]) + F(n[1] * lv[1])) + F(n[2] * lv[2])) / ll)
            if not ndl > 0:
                ndl = 0.0
            k = F(AMBIENT + F(F(DIFFUSE * ndl) * F(vis[i])))
            out.append(tuple(to8(F(k * a)) for a in ALBEDO))
    return out


# ---- the tests ----

EYE, TARGET, UP, FOV = (5.5, 4.0, 6.5), (0.0, 0.8, 0.0), (0.0, 1.0, 0.0), 50.0
W, H = 56, 40
LIGHT = (2.5, 6.0, 1.5, 0.9)
SAMPLES = 32


def render(client, scene, **params):
    q = urllib.parse.urlencode(params)
    return client.request("GET", "/v1/scenes/%s/render.png%s" % (scene, "?" + q if q else ""))


def camera_params(mode):
    return {"eye": "%g,%g,%g" % EYE, "target": "%g,%g,%g" % TARGET, "up": "0,1,0",
            "fov": FOV, "width": W, "height": H, "light": "%g,%g,%g,%g" % LIGHT,
            "samples": SAMPLES, "mode": mode}


def decode_png(data):
    img = Image.open(io.BytesIO(data))
    img.load()
    return img


def test_equals_queries(r, client, tris):
    fr = client.frustum("t", EYE, TARGET, W, H, up=UP, fov_y_deg=FOV, tile=8,
                        encoding="base64", fields=["t", "prim"])
    t, prim = fr["t"], fr["prim"]
    dirs = camera_dirs(EYE, TARGET, UP, FOV, W, H)
    points, normals = hit_geometry(EYE, dirs, t, prim, tris)
    hits = [i for i in range(W * H) if prim[i] >= 0]
    r.check(0 < len(hits) < W * H, "the view has hits and misses (%d)" % len(hits))
    # one cone-shadow point per pixel (point index = pixel index); a miss
    # repeats the first hit point, and its answer is not used
    fill_p, fill_n = points[hits[0]], normals[hits[0]]
    pts, nrm = [], []
    for i in range(W * H):
        pts += points[i] if prim[i] >= 0 else fill_p
        nrm += normals[i] if prim[i] >= 0 else fill_n
    sh = client.shadow("t", pts, [LIGHT], normals=nrm, samples=SAMPLES, seed=1,
                       epsilon=1e-4, stats=True, encoding="base64", send="base64")
    vis = sh["visibility"]
    partial = sum(1 for i in hits if 0 < vis[i] < 1)
    r.check(partial > 10, "the view has penumbra pixels (%d)" % partial)
    r.check(any(vis[i] == 0 for i in hits) and any(vis[i] == 1 for i in hits),
            "the view has umbra and lit pixels")
    for mode in ("shade", "shadow", "normal"):
        status, hdrs, data = render(client, "t", **camera_params(mode))
        r.eq(status, 200, "%s: status" % mode)
        hdrs = {k.lower(): v for k, v in hdrs.items()}
        r.eq(hdrs.get("content-type"), "image/png", "%s: content type" % mode)
        img = decode_png(data)
        r.eq((img.format, img.mode, img.size), ("PNG", "RGB", (W, H)), "%s: PNG" % mode)
        got = list(img.getdata())
        want = expected_image(mode, W, H, prim, points, normals, vis, LIGHT)
        bad = [i for i in range(W * H) if got[i] != want[i]]
        r.check(not bad, "%s: %d of %d pixels differ from the queries' image, first "
                "at pixel %s: got %s, want %s" % (mode, len(bad), W * H,
                                                  bad[:1], got[bad[0]] if bad else None,
                                                  want[bad[0]] if bad else None))
        stats = dict(kv.split("=") for kv in hdrs["x-kdray-render"].split("; "))
        r.eq(int(stats["hits"]), len(hits), "%s: X-Kdray-Render hits" % mode)
        r.eq(int(stats["pixels"]), W * H, "%s: pixels" % mode)
        if mode != "normal":
            r.eq(int(stats["cones"]), len(hits), "%s: one cone per hit" % mode)
        timing = hdrs.get("server-timing", "")
        for stage in ("primary", "shadow", "shade", "png", "total"):
            r.check(stage + ";dur=" in timing, "%s: Server-Timing has %s: %r" %
                    (mode, stage, timing))


def test_modes_differ(r, client, tris):
    seen = {}
    for mode in ("shade", "depth", "normal", "shadow", "ao"):
        p = camera_params(mode)
        p["samples"] = 8
        status, _, data = render(client, "t", **p)
        r.eq(status, 200, mode)
        seen[mode] = decode_png(data).tobytes()
    r.eq(len(set(seen.values())), 5, "five modes, five different pictures")
    # ao is deterministic: the same request twice gives the same bytes
    p = camera_params("ao")
    p["samples"] = 8
    r.eq(decode_png(render(client, "t", **p)[2]).tobytes(), seen["ao"], "ao repeatable")


def test_defaults_frame_the_scene(r, client, tris):
    status, hdrs, data = render(client, "t")
    r.eq(status, 200, "no parameters")
    img = decode_png(data)
    r.eq(img.size, (640, 480), "default size")
    hdrs = {k.lower(): v for k, v in hdrs.items()}
    stats = dict(kv.split("=") for kv in hdrs["x-kdray-render"].split("; "))
    r.check(int(stats["hits"]) > 640 * 480 // 4,
            "the default view is filled by the scene: %s hits" % stats["hits"])
    # a HEAD is answered like the GET, without the picture
    st, _, body = client.request("HEAD", "/v1/scenes/t/render.png?width=8&height=8")
    r.eq((st, body), (200, b""), "HEAD")


def test_bad_parameters(r, client, tris):
    cases = [("eye=1,2", "eye"), ("target=a,b,c", "target"), ("up=0,0,0", "up"),
             ("fov=180", "fov"), ("fov=nan", "fov"), ("width=0", "width"),
             ("height=16385", "height"), ("light=0,5,0,0", "light"),
             ("light=0,5,0", "light"), ("samples=0", "samples"),
             ("samples=4097", "samples"), ("mode=pretty", "mode"),
             ("colour=red", "colour"), ("eye=0,0.8,0&target=0,0.8,0", "eye"),
             ("eye=0,5,0&target=0,0,0", "up")]
    for query, name in cases:
        status, hdrs, data = client.request("GET", "/v1/scenes/t/render.png?" + query)
        hdrs = {k.lower(): v for k, v in hdrs.items()}
        r.eq(status, 400, query)
        r.eq(hdrs.get("content-type"), "application/problem+json", query + ": type")
        r.check(data.decode().find('"detail":"%s:' % name) >= 0,
                "%s: the problem names %s: %s" % (query, name, data.decode()))
    status, _, _ = client.request("GET", "/v1/scenes/nope/render.png")
    r.eq(status, 404, "unknown scene")
    status, hdrs, _ = client.request("POST", "/v1/scenes/t/render.png", b"{}")
    r.eq(status, 405, "POST")


def test_client(r, client, tris, url, clients):
    """clients/kdray_client.py render writes the picture the endpoint sends."""
    import subprocess
    out = os.path.join(tempfile.mkdtemp(prefix="kdray-client-"), "view.png")
    p = subprocess.run([sys.executable, os.path.join(clients, "kdray_client.py"),
                        "--url", url, "render", "--scene", "t", "--eye", "%g,%g,%g" % EYE,
                        "--target", "%g,%g,%g" % TARGET, "--fov", str(FOV), "--width", str(W), "--height",
                        str(H), "--light", "%g,%g,%g,%g" % LIGHT, "--samples",
                        str(SAMPLES), "--mode", "shade", "--out", out],
                       capture_output=True, text=True, timeout=120)
    r.eq(p.returncode, 0, "client exit status: " + p.stderr)
    with open(out, "rb") as f:
        got = f.read()
    want = render(client, "t", **{k: v for k, v in camera_params("shade").items()
                                  if k != "up"})[2]
    r.eq(decode_png(got).tobytes(), decode_png(want).tobytes(), "client picture")
    r.check('"total"' in p.stdout and '"hits"' in p.stdout, "timing and stats printed")
    png, timing, stats = client.render("t", width=16, height=12, mode="depth")
    r.eq((decode_png(png).size, stats["mode"]), ((16, 12), "depth"), "Client.render")
    r.check(set(timing) >= {"primary", "shadow", "shade", "png", "total"}, str(timing))
    p = subprocess.run([sys.executable, os.path.join(clients, "kdray_client.py"),
                        "--url", url, "render", "--scene", "t", "--samples", "0",
                        "--out", out], capture_output=True, text=True, timeout=120)
    r.check(p.returncode == 1 and "samples" in p.stderr, "client error: " + p.stderr)
    os.unlink(out)
    os.rmdir(os.path.dirname(out))


def test_limits_and_deadline(r, kdrayd, scene_path):
    d = lib.Daemon(kdrayd, ["--scene", "t=" + scene_path, "--max-rays", "10000"],
                   default_scene=False)
    try:
        from kdray_client import Client
        c = Client(d.url, timeout=60)
        status, _, data = render(c, "t", width=101, height=100)
        r.eq(status, 413, "10100 pixels over --max-rays 10000")
        r.check(b"width x height" in data, data.decode())
        status, _, _ = render(c, "t", width=100, height=100)
        r.eq(status, 200, "10000 pixels")
        metrics = c.metrics()
        r.check(lib.metric(metrics, "kdray_rays_traced_total", kind="render") >= 10000,
                "rays of renders are counted")
    finally:
        d.stop()
    d = lib.Daemon(kdrayd, ["--scene", "t=" + scene_path, "--deadline-ms", "30",
                            "--threads", "1"], default_scene=False)
    try:
        from kdray_client import Client
        c = Client(d.url, timeout=120)
        status, _, data = render(c, "t", width=1024, height=1024, samples=4096,
                                 mode="ao")
        r.eq(status, 503, "a long render stops at the deadline")
        r.check(b"deadline" in data, data.decode())
    finally:
        d.stop()


def main():
    kdrayd, clients = sys.argv[1], sys.argv[2]
    lib.add_client_path(clients)
    from kdray_client import Client
    tmp = tempfile.mkdtemp(prefix="kdray-render-")
    scene_path = os.path.join(tmp, "t.glb")
    tris = write_scene(scene_path)
    r = lib.Runner()
    d = lib.Daemon(kdrayd, ["--scene", "t=" + scene_path], default_scene=False)
    try:
        client = Client(d.url, timeout=120)
        for fn in (test_equals_queries, test_modes_differ, test_defaults_frame_the_scene,
                   test_bad_parameters):
            r.run(fn, client, tris)
        r.run(test_client, client, tris, d.url, clients)
    finally:
        d.stop()
    r.run(test_limits_and_deadline, kdrayd, scene_path)
    os.unlink(scene_path)
    os.rmdir(tmp)
    sys.exit(r.finish())


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""make_distinct_scene.py: a large scene of distinct geometry (Python 3
standard library only, deterministic, no downloads).

engine3 and engine9 repeat one mesh 3 and 9 times, so a tree's memory
layout gets the same few leaves' triangles over and over. This scene has no
repeated object: a procedural terrain (a heightfield of fractal value
noise), each real model given with --model placed on it once (the ladder's
converted assimp-testmodels files: their node trees and geometry are merged
in, only positions and indices), and procedurally deformed rocks, every one
its own mesh, until the scene holds at least --min-triangles (default
1,000,000). Objects sit on the terrain at different sizes and densities, so
rays see real occlusion and the tree is uneven.

Usage: make_distinct_scene.py OUT.glb [--model FILE.glb|FILE.gltf]...
                              [--min-triangles N] [--seed S]
"""

import argparse
import json
import math
import os
import random
import struct
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from count_triangles import count as count_triangles  # noqa: E402
from glbutil import Glb  # noqa: E402

WORLD = 200.0        # terrain side, scene units
RELIEF = 12.0        # terrain height range
TERRAIN_QUADS = 384  # per side: 2 * 384^2 = 294,912 triangles
MODEL_SIZE = (18.0, 40.0)  # a model's largest extent after scaling
ROCK_SIZE = (0.3, 3.5)
ROCK_SUBDIV = 3      # icosphere level: 1280 triangles per rock


# ---- terrain ----------------------------------------------------------------

class ValueNoise:
    """Fractal value noise on a random lattice per octave (smoothstep)."""

    def __init__(self, rng, octaves=6, cells=4):
        self.octaves = []
        for o in range(octaves):
            n = cells << o
            self.octaves.append((n, [rng.random() for _ in range((n + 1) * (n + 1))]))

    def __call__(self, u, v):  # u, v in [0, 1]
        total, amp, norm = 0.0, 1.0, 0.0
        for n, lat in self.octaves:
            x, y = u * n, v * n
            i, j = min(int(x), n - 1), min(int(y), n - 1)
            fx, fy = x - i, y - j
            fx, fy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)
            a = lat[j * (n + 1) + i]
            b = lat[j * (n + 1) + i + 1]
            c = lat[(j + 1) * (n + 1) + i]
            d = lat[(j + 1) * (n + 1) + i + 1]
            total += amp * ((a + (b - a) * fx) * (1 - fy) + (c + (d - c) * fx) * fy)
            norm += amp
            amp *= 0.5
        return total / norm


def terrain_height(noise, x, z):
    return RELIEF * noise(x / WORLD + 0.5, z / WORLD + 0.5)


def add_terrain(glb, noise):
    n = TERRAIN_QUADS
    pos = []
    for k in range(n + 1):
        for i in range(n + 1):
            x, z = (i / n - 0.5) * WORLD, (k / n - 0.5) * WORLD
            pos.append((x, terrain_height(noise, x, z), z))
    idx = []
    for k in range(n):
        for i in range(n):
            a = k * (n + 1) + i
            idx += [a, a + n + 1, a + 1, a + 1, a + n + 1, a + n + 2]
    glb.add_node("terrain", mesh=glb.add_mesh("terrain", pos, idx), root=True)
    return 2 * n * n


# ---- models from files ------------------------------------------------------

def read_gltf(path):
    data = open(path, "rb").read()
    if data[:4] == b"glTF":
        off, gltf, binary = 12, None, b""
        while off + 8 <= len(data):
            length, kind = struct.unpack_from("<I4s", data, off)
            chunk = data[off + 8: off + 8 + length]
            if kind == b"JSON":
                gltf = json.loads(chunk)
            elif kind == b"BIN\0":
                binary = chunk
            off += 8 + length + (-length % 4)
        return gltf, [binary]
    gltf = json.loads(data)
    buffers = []
    for b in gltf.get("buffers", []):
        uri = b.get("uri", "")
        if not uri or uri.startswith("data:"):
            raise ValueError("%s: only .glb or external .bin buffers" % path)
        buffers.append(open(os.path.join(os.path.dirname(path), uri), "rb").read())
    return gltf, buffers


def mat_mul(a, b):  # column-major 4x4
    return [sum(a[r + 4 * k] * b[k + 4 * c] for k in range(4)) for c in range(4)
            for r in range(4)]


def node_matrix(node):
    if "matrix" in node:
        return [float(v) for v in node["matrix"]]
    tx, ty, tz = node.get("translation", [0, 0, 0])
    qx, qy, qz, qw = node.get("rotation", [0, 0, 0, 1])
    sx, sy, sz = node.get("scale", [1, 1, 1])
    r = [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy + qz * qw), 2 * (qx * qz - qy * qw),
         2 * (qx * qy - qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz + qx * qw),
         2 * (qx * qz + qy * qw), 2 * (qy * qz - qx * qw), 1 - 2 * (qx * qx + qy * qy)]
    return [r[0] * sx, r[1] * sx, r[2] * sx, 0, r[3] * sy, r[4] * sy, r[5] * sy, 0,
            r[6] * sz, r[7] * sz, r[8] * sz, 0, tx, ty, tz, 1]


def model_bounds(gltf):
    """World bounds of the scene's triangle primitives, from the POSITION
    accessors' min/max boxes through the node transforms."""
    lo, hi = [math.inf] * 3, [-math.inf] * 3
    roots = gltf["scenes"][gltf.get("scene", 0)].get("nodes", [])
    stack = [(r, [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]) for r in roots]
    while stack:
        idx, parent = stack.pop()
        node = gltf["nodes"][idx]
        m = mat_mul(parent, node_matrix(node))
        for prim in gltf["meshes"][node["mesh"]]["primitives"] if "mesh" in node else []:
            acc = gltf["accessors"][prim["attributes"]["POSITION"]]
            if prim.get("mode", 4) not in (4, 5, 6) or "min" not in acc:
                continue
            for c in range(8):
                p = [acc["max"][k] if c >> k & 1 else acc["min"][k] for k in range(3)]
                for k in range(3):
                    w = m[k] * p[0] + m[4 + k] * p[1] + m[8 + k] * p[2] + m[12 + k]
                    lo[k], hi[k] = min(lo[k], w), max(hi[k], w)
        stack.extend((c, m) for c in node.get("children", []))
    return lo, hi


def merge_model(glb, path, name, place):
    """Copies the triangle geometry and node trees of path under one new root
    node; place(lo, hi) gives that node's transform. Returns its triangles."""
    gltf, buffers = read_gltf(path)
    if gltf.get("extensionsRequired"):
        raise ValueError("%s: required extensions %s" % (path, gltf["extensionsRequired"]))
    views, accessors, meshes = {}, {}, {}

    def view(i):
        if i not in views:
            v = gltf["bufferViews"][i]
            data = buffers[v.get("buffer", 0)]
            off = v.get("byteOffset", 0)
            new = glb.add_view(data[off: off + v["byteLength"]], v.get("target"))
            if "byteStride" in v:
                glb.gltf["bufferViews"][new]["byteStride"] = v["byteStride"]
            views[i] = new
        return views[i]

    def accessor(i):
        if i not in accessors:
            a = dict(gltf["accessors"][i])
            if "sparse" in a or "bufferView" not in a:
                raise ValueError("%s: sparse or view-less accessor" % path)
            a["bufferView"] = view(a["bufferView"])
            glb.gltf["accessors"].append(a)
            accessors[i] = len(glb.gltf["accessors"]) - 1
        return accessors[i]

    def mesh(i):
        if i not in meshes:
            prims = []
            for p in gltf["meshes"][i]["primitives"]:
                if p.get("mode", 4) not in (4, 5, 6):
                    continue
                q = {"attributes": {"POSITION": accessor(p["attributes"]["POSITION"])},
                     "mode": p.get("mode", 4)}
                if "indices" in p:
                    q["indices"] = accessor(p["indices"])
                prims.append(q)
            glb.gltf["meshes"].append({"name": "%s_%d" % (name, i), "primitives": prims})
            meshes[i] = len(glb.gltf["meshes"]) - 1
        return meshes[i]

    def node(i):
        src = gltf["nodes"][i]
        kids = [node(c) for c in src.get("children", [])]
        t = {k: src[k] for k in ("matrix", "translation", "rotation", "scale") if k in src}
        m = mesh(src["mesh"]) if "mesh" in src and mesh_has_prims(src["mesh"]) else None
        return glb.add_node("%s_node%d" % (name, i), mesh=m, children=kids, **t)

    def mesh_has_prims(i):
        return any(p.get("mode", 4) in (4, 5, 6) for p in gltf["meshes"][i]["primitives"])

    roots = [node(r) for r in gltf["scenes"][gltf.get("scene", 0)].get("nodes", [])]
    glb.add_node(name, children=roots, root=True, **place(*model_bounds(gltf)))
    return count_triangles(gltf)


# ---- rocks --------------------------------------------------------------------

def icosphere(level):
    t = (1 + 5 ** 0.5) / 2
    verts = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
             (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    verts = [tuple(c / math.sqrt(sum(x * x for x in v)) for c in v) for v in verts]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9),
             (5, 11, 4), (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2),
             (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10),
             (8, 6, 7), (9, 8, 1)]
    for _ in range(level):
        mid, out = {}, []

        def midpoint(a, b):
            key = (min(a, b), max(a, b))
            if key not in mid:
                p = [(verts[a][k] + verts[b][k]) / 2 for k in range(3)]
                n = math.sqrt(sum(c * c for c in p))
                verts.append(tuple(c / n for c in p))
                mid[key] = len(verts) - 1
            return mid[key]
        for a, b, c in faces:
            ab, bc, ca = midpoint(a, b), midpoint(b, c), midpoint(c, a)
            out += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = out
    return verts, [i for f in faces for i in f]


def add_rock(glb, rng, noise, sphere, k):
    verts, idx = sphere
    waves = []
    for _ in range(6):
        d = [rng.gauss(0, 1) for _ in range(3)]
        n = math.sqrt(sum(c * c for c in d)) or 1.0
        waves.append(([c / n for c in d], rng.uniform(1.5, 7.0), rng.uniform(0, 6.3),
                      rng.uniform(0.03, 0.16)))
    size = rng.uniform(*ROCK_SIZE)
    sx, sy, sz = (size * rng.uniform(0.6, 1.4) for _ in range(3))
    ang = rng.uniform(0, 2 * math.pi)
    ca, sa = math.cos(ang), math.sin(ang)
    x, z = (rng.uniform(-0.48, 0.48) * WORLD for _ in range(2))
    y = terrain_height(noise, x, z) + sy * rng.uniform(0.1, 0.6)
    pos = []
    for v in verts:
        r = 1.0 + sum(a * math.cos(f * (v[0] * d[0] + v[1] * d[1] + v[2] * d[2]) + p)
                      for d, f, p, a in waves)
        px, py, pz = v[0] * r * sx, v[1] * r * sy, v[2] * r * sz
        pos.append((x + ca * px + sa * pz, y + py, z - sa * px + ca * pz))
    glb.add_node("rock_%d" % k, mesh=glb.add_mesh("rock_%d" % k, pos, idx), root=True)
    return len(idx) // 3


# ---- the scene ----------------------------------------------------------------

def build(out, models, min_triangles, seed):
    rng = random.Random(seed)
    noise = ValueNoise(rng)
    glb = Glb("kdray scenes/make_distinct_scene.py")
    total = add_terrain(glb, noise)
    # models on a ring around the centre, one each, different sizes and turns
    for k, path in enumerate(models):
        ang = 2 * math.pi * k / max(len(models), 1)
        cx, cz = 0.3 * WORLD * math.cos(ang), 0.3 * WORLD * math.sin(ang)
        size, turn = rng.uniform(*MODEL_SIZE), rng.uniform(0, 2 * math.pi)

        def place(lo, hi, cx=cx, cz=cz, size=size, turn=turn):
            ext = max(h - l for l, h in zip(lo, hi)) or 1.0
            s = size / ext
            mid = [(l + h) / 2 for l, h in zip(lo, hi)]
            base = terrain_height(noise, cx, cz)
            # scale about the model's centre, rest its bottom on the ground
            c, sn = math.cos(turn / 2), math.sin(turn / 2)
            rot = [0.0, sn, 0.0, c]
            # R * S * (p - mid) + (cx, base + s*(mid_y - lo_y), cz); R keeps y
            cosr, sinr = math.cos(turn), math.sin(turn)
            mx, mz = s * mid[0], s * mid[2]
            t = [cx - (cosr * mx + sinr * mz), base - s * lo[1], cz - (-sinr * mx + cosr * mz)]
            return {"translation": t, "rotation": rot, "scale": [s, s, s]}
        total += merge_model(glb, path, "model_%d_%s" % (k, os.path.basename(path)), place)
    sphere = icosphere(ROCK_SUBDIV)
    k = 0
    while total < min_triangles:
        total += add_rock(glb, rng, noise, sphere, k)
        k += 1
    glb.write(out)
    return total


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out")
    ap.add_argument("--model", action="append", default=[])
    ap.add_argument("--min-triangles", type=int, default=1000000)
    ap.add_argument("--seed", type=int, default=20240611)
    args = ap.parse_args()
    total = build(args.out, args.model, args.min_triangles, args.seed)
    print("%s: %d triangles" % (args.out, total))


if __name__ == "__main__":
    main()

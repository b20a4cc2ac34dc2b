#!/usr/bin/env python3
"""make_big_scene.py: builds a large scene by instancing a real model
(Python 3 standard library only, deterministic, no downloads).

The input .glb's node trees are copied COPIES times under new root nodes
laid out on a grid, each turned by a different angle about y; the meshes
and the binary chunk are shared, so the file stays the size of the input
while the flattened triangle count grows COPIES times. With the default
input (assimp-testmodels' 2CylinderEngine, 121496 triangles) and 9 copies
the scene has 1,093,464 triangles. Copies overlap a little in depth, so
rays see real occlusion.

Usage: make_big_scene.py OUT.glb [--copies N] [--input IN.glb]
"""

import argparse
import copy
import json
import math
import struct

DEFAULT_INPUT = ("/usr/share/assimp/models/glTF2/2CylinderEngine-glTF-Binary/"
                 "2CylinderEngine.glb")


def read_glb(path):
    data = open(path, "rb").read()
    magic, version, total = struct.unpack_from("<4sII", data, 0)
    if magic != b"glTF" or version != 2 or total > len(data):
        raise SystemExit("%s: not a glTF 2.0 binary" % path)
    chunks, off = {}, 12
    while off + 8 <= total:
        length, kind = struct.unpack_from("<I4s", data, off)
        chunks[kind] = data[off + 8: off + 8 + length]
        off += 8 + length + (-length % 4)
    return json.loads(chunks[b"JSON"]), chunks.get(b"BIN\0", b"")


def scene_extent(gltf):
    """Rough size of the model from its POSITION accessors' min/max."""
    lo, hi = [math.inf] * 3, [-math.inf] * 3
    for acc in gltf.get("accessors", []):
        if acc.get("type") == "VEC3" and "min" in acc and "max" in acc:
            lo = [min(a, b) for a, b in zip(lo, acc["min"])]
            hi = [max(a, b) for a, b in zip(hi, acc["max"])]
    return [h - l for l, h in zip(lo, hi)] if lo[0] <= hi[0] else [1.0, 1.0, 1.0]


def instance(gltf, copies):
    nodes = gltf["nodes"]
    roots = gltf["scenes"][gltf.get("scene", 0)]["nodes"]
    ext = scene_extent(gltf)
    size = max(ext)
    side = math.ceil(math.sqrt(copies))
    out_nodes, wrappers = [], []
    for k in range(copies):
        base = len(out_nodes)
        for n in nodes:
            m = copy.deepcopy(n)
            if "children" in m:
                m["children"] = [c + base for c in m["children"]]
            out_nodes.append(m)
        ang = math.radians(37.0 * k)
        row, col = divmod(k, side)
        # 0.8 spacing: neighbouring copies interlock a little.
        wrappers.append({"name": "copy_%d" % k,
                         "children": [r + base for r in roots],
                         "translation": [(col - (side - 1) / 2) * 0.8 * size, 0.0,
                                         (row - (side - 1) / 2) * 0.8 * size],
                         "rotation": [0.0, math.sin(ang / 2), 0.0, math.cos(ang / 2)]})
    first = len(out_nodes)
    out_nodes += wrappers
    gltf["nodes"] = out_nodes
    gltf["scenes"] = [{"nodes": list(range(first, first + copies))}]
    gltf["scene"] = 0
    gltf.pop("animations", None)  # their channels name the original nodes only
    gltf.setdefault("asset", {})["generator"] = "kdray scenes/make_big_scene.py"
    return gltf


def write_glb(path, gltf, binary):
    js = json.dumps(gltf, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    binary = bytes(binary) + b"\0" * (-len(binary) % 4)
    total = 12 + 8 + len(js) + (8 + len(binary) if binary else 0)
    with open(path, "wb") as f:
        f.write(struct.pack("<4sII", b"glTF", 2, total))
        f.write(struct.pack("<I4s", len(js), b"JSON") + js)
        if binary:
            f.write(struct.pack("<I4s", len(binary), b"BIN\0") + binary)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out")
    ap.add_argument("--copies", type=int, default=9)
    ap.add_argument("--input", default=DEFAULT_INPUT)
    args = ap.parse_args()
    if args.copies < 1:
        raise SystemExit("--copies must be at least 1")
    gltf, binary = read_glb(args.input)
    write_glb(args.out, instance(gltf, args.copies), binary)


if __name__ == "__main__":
    main()

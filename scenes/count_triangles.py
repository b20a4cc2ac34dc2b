#!/usr/bin/env python3
"""count_triangles.py: prints the number of triangles kdray will flatten from
a .gltf/.glb, computed from the JSON alone (Python 3 standard library only).

It is deliberately independent of the C++ loader: scenes/fetch writes its
counts into ladder.txt, and tests compare them with kdr_gltf_load. It walks
the same scene (default `scene`, else 0) and the same node trees, and counts
TRIANGLES as count/3 and strips/fans as count-2.

Usage: count_triangles.py FILE...   (prints "FILE COUNT" per file)
"""

import json
import struct
import sys


def load_json(path):
    data = open(path, "rb").read()
    if data[:4] == b"glTF":
        length, = struct.unpack_from("<I", data, 12)
        return json.loads(data[20:20 + length])
    return json.loads(data)


def primitive_triangles(gltf, prim):
    mode = prim.get("mode", 4)
    if mode not in (4, 5, 6):
        return 0
    acc = prim["indices"] if "indices" in prim else prim["attributes"]["POSITION"]
    n = gltf["accessors"][acc]["count"]
    return n // 3 if mode == 4 else max(n - 2, 0)


def count(gltf):
    scenes = gltf.get("scenes", [])
    if not scenes:
        return 0
    total, stack = 0, list(reversed(scenes[gltf.get("scene", 0)].get("nodes", [])))
    while stack:
        node = gltf["nodes"][stack.pop()]
        if "mesh" in node:
            for prim in gltf["meshes"][node["mesh"]]["primitives"]:
                total += primitive_triangles(gltf, prim)
        stack.extend(reversed(node.get("children", [])))
    return total


if __name__ == "__main__":
    for path in sys.argv[1:]:
        print(path, count(load_json(path)))

"""glbutil.py: a minimal glTF 2.0 binary (.glb) writer shared by the scene
generators (Python 3 standard library only).

A Glb collects meshes (float32 positions + uint16/uint32 indices, one
TRIANGLES primitive each) and nodes, and writes one .glb with a single BIN
chunk. Positions get the min/max the spec requires. Nothing else (normals,
materials) is written: kdray only needs positions.
"""

import json
import struct


class Glb:
    def __init__(self, generator):
        self.gltf = {
            "asset": {"version": "2.0", "generator": generator},
            "scene": 0,
            "scenes": [{"nodes": []}],
            "nodes": [],
            "meshes": [],
            "accessors": [],
            "bufferViews": [],
            "buffers": [{"byteLength": 0}],
        }
        self.bin = bytearray()

    def _view(self, data, target):
        while len(self.bin) % 4:
            self.bin.append(0)
        v = {"buffer": 0, "byteOffset": len(self.bin), "byteLength": len(data)}
        if target is not None:
            v["target"] = target
        self.gltf["bufferViews"].append(v)
        self.bin += data
        return len(self.gltf["bufferViews"]) - 1

    def add_view(self, data, target=None):
        """Raw bytes as a new bufferView (4-byte aligned); returns its index."""
        return self._view(data, target)

    def add_mesh(self, name, positions, indices):
        """positions: list of (x, y, z); indices: flat list, 3 per triangle."""
        flat = [c for p in positions for c in p]
        view = self._view(struct.pack("<%df" % len(flat), *flat), 34962)
        acc = self.gltf["accessors"]
        # min/max of the float32-rounded values, as the spec asks.
        rounded = struct.unpack("<%df" % len(flat), struct.pack("<%df" % len(flat), *flat))
        acc.append({"bufferView": view, "componentType": 5126, "count": len(positions),
                    "type": "VEC3",
                    "min": [min(rounded[k::3]) for k in range(3)],
                    "max": [max(rounded[k::3]) for k in range(3)]})
        pos_acc = len(acc) - 1
        wide = len(positions) > 65535
        fmt, ctype = ("<%dI", 5125) if wide else ("<%dH", 5123)
        view = self._view(struct.pack(fmt % len(indices), *indices), 34963)
        acc.append({"bufferView": view, "componentType": ctype, "count": len(indices),
                    "type": "SCALAR"})
        self.gltf["meshes"].append(
            {"name": name, "primitives": [{"attributes": {"POSITION": pos_acc},
                                           "indices": len(acc) - 1, "mode": 4}]})
        return len(self.gltf["meshes"]) - 1

    def add_node(self, name, mesh=None, children=None, root=False, **transform):
        """transform: translation/rotation/scale lists or matrix (16, column-major)."""
        node = {"name": name}
        if mesh is not None:
            node["mesh"] = mesh
        if children:
            node["children"] = list(children)
        for key in ("matrix", "translation", "rotation", "scale"):
            if key in transform:
                node[key] = [float(v) for v in transform[key]]
        self.gltf["nodes"].append(node)
        index = len(self.gltf["nodes"]) - 1
        if root:
            self.gltf["scenes"][0]["nodes"].append(index)
        return index

    def write(self, path):
        while len(self.bin) % 4:
            self.bin.append(0)
        self.gltf["buffers"][0]["byteLength"] = len(self.bin)
        js = json.dumps(self.gltf, separators=(",", ":")).encode()
        js += b" " * (-len(js) % 4)
        total = 12 + 8 + len(js) + 8 + len(self.bin)
        with open(path, "wb") as f:
            f.write(struct.pack("<4sII", b"glTF", 2, total))
            f.write(struct.pack("<I4s", len(js), b"JSON") + js)
            f.write(struct.pack("<I4s", len(self.bin), b"BIN\0") + bytes(self.bin))

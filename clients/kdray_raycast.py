"""kdray_raycast.py - kdrayd as a RaycastingScene: numpy arrays in and out,
with the method names of Open3D's open3d.t.geometry.RaycastingScene.

    from kdray_raycast import RaycastingScene
    scene = RaycastingScene("http://127.0.0.1:8080", "default")
    ans = scene.cast_rays(rays)             # rays: (..., 6) float32 ox oy oz dx dy dz
    ans["t_hit"], ans["primitive_ids"], ans["primitive_uvs"]
    scene.compute_signed_distance(points)   # points: (..., 3)

Every method is one HTTP request to kdrayd (docs/API.md); arrays travel as
base64 of their little-endian bytes ({"f32": ...}), never as decimal text.
Conventions follow Open3D where kdray has the same notion: a miss has
t_hit = inf and primitive_ids = INVALID_ID (2**32 - 1); leading dimensions
of the input are kept; geometry_ids are 0 for every hit (a kdrayd scene is
one geometry: the glTF node/mesh/primitive of a hit is the bundle's "mesh"
field, or the scene's "meshes" table, GET /v1/scenes/NAME). Differences: list_intersections
returns at most max_hits hits per ray (kdray's "all" query; pass a larger
max_hits, up to 1024, or check count_intersections); compute_occupancy and
the sign of compute_signed_distance come from kdray's 9-ray parity vote.

Needs numpy (Debian: python3-numpy) and kdray_client.py (beside it).
Install both from the repository, offline (see clients/README.md):

    python3 -m pip install --no-index --no-build-isolation ./clients
"""

import base64

import numpy as np

from kdray_client import DEFAULT_URL, Client

INVALID_ID = 0xFFFFFFFF


def _b64(a):
    return {"f32": base64.b64encode(np.ascontiguousarray(a, dtype="<f4").tobytes())
            .decode("ascii")}


def _arr(value, dtype):
    """An answer array: base64 {"f32"/"i32": ...} or a JSON list."""
    if isinstance(value, dict):
        key = "f32" if "f32" in value else "i32"
        code = "<f4" if key == "f32" else "<i4"
        return np.frombuffer(base64.b64decode(value[key]), dtype=code).astype(dtype)
    return np.asarray(value, dtype=dtype)


class RaycastingScene:
    """One scene of one kdrayd. The constructor only records where; every
    method asks the daemon (KdrayError on a refused request)."""

    def __init__(self, url=DEFAULT_URL, scene="default", timeout=120.0):
        self.client = Client(url, timeout=timeout)
        self.scene = scene

    # ---- helpers ---------------------------------------------------------------

    def _post(self, op, payload):
        payload = dict(payload, encoding="base64")
        return self.client.call("POST", "/v1/scenes/%s/%s" % (self.scene, op), payload)

    @staticmethod
    def _rays(rays):
        r = np.asarray(rays, dtype=np.float32)
        if r.shape[-1] != 6:
            raise ValueError("rays: the last dimension must be 6 (origin, direction)")
        return r.reshape(-1, 6), r.shape[:-1]

    @staticmethod
    def _points(points):
        p = np.asarray(points, dtype=np.float32)
        if p.shape[-1] != 3:
            raise ValueError("points: the last dimension must be 3")
        return p.reshape(-1, 3), p.shape[:-1]

    def _bundle(self, flat, query, tnear=0.0, tfar=np.inf, **extra):
        payload = {"origins": _b64(flat[:, :3]), "directions": _b64(flat[:, 3:]),
                   "query": query, "tmin": float(tnear),
                   "tmax": 1e300 if np.isinf(tfar) else float(tfar)}
        payload.update(extra)
        return self._post("bundle", payload)

    # ---- rays ---------------------------------------------------------------------

    def cast_rays(self, rays):
        """Closest hits: t_hit (inf: miss), geometry_ids, primitive_ids
        (INVALID_ID: miss), primitive_uvs (..., 2), primitive_normals
        (..., 3: the triangle's unit geometric normal; 0 on a miss)."""
        flat, lead = self._rays(rays)
        a = self._bundle(flat, "closest", fields=["t", "prim", "u", "v", "normal"])
        prim = _arr(a["prim"], np.int64)
        hit = prim >= 0
        t = np.where(hit, _arr(a["t"], np.float32), np.float32(np.inf))
        uv = np.stack([_arr(a["u"], np.float32), _arr(a["v"], np.float32)], axis=-1)
        return {"t_hit": t.reshape(lead),
                "geometry_ids": np.where(hit, 0, INVALID_ID).astype(np.uint32).reshape(lead),
                "primitive_ids": np.where(hit, prim, INVALID_ID).astype(np.uint32)
                .reshape(lead),
                "primitive_uvs": uv.reshape(lead + (2,)),
                "primitive_normals": _arr(a["normal"], np.float32).reshape(lead + (3,))}

    def test_occlusions(self, rays, tnear=0.0, tfar=np.inf):
        """True where any hit lies in [tnear, tfar]."""
        flat, lead = self._rays(rays)
        a = self._bundle(flat, "any", tnear, tfar)
        return (_arr(a["hit"], np.int32) != 0).reshape(lead)

    def count_intersections(self, rays):
        """Hits along each ray, [0, inf), no cap (kdray's "count" query: a ray
        through an edge shared by two triangles counts both)."""
        flat, lead = self._rays(rays)
        a = self._bundle(flat, "count")
        return _arr(a["nhits"], np.int32).reshape(lead)

    def list_intersections(self, rays, max_hits=1024):
        """Every hit, at most max_hits per ray, in increasing t: ray_splits
        (N+1 offsets into the flat arrays), ray_ids, geometry_ids,
        primitive_ids, primitive_uvs (M, 2), t_hit."""
        flat, _ = self._rays(rays)
        a = self._bundle(flat, "all", max_hits=int(max_hits))
        splits = _arr(a["offset"], np.int64)
        nh = _arr(a["nhits"], np.int64)
        prim = _arr(a["prim"], np.int64)
        return {"ray_splits": splits.astype(np.uint32),
                "ray_ids": np.repeat(np.arange(len(nh), dtype=np.uint32), nh),
                "geometry_ids": np.zeros(len(prim), np.uint32),
                "primitive_ids": prim.astype(np.uint32),
                "primitive_uvs": np.stack([_arr(a["u"], np.float32),
                                           _arr(a["v"], np.float32)], axis=-1),
                "t_hit": _arr(a["t"], np.float32)}

    # ---- points ----------------------------------------------------------------------

    def _closest(self, points, signed=False):
        flat, lead = self._points(points)
        payload = {"points": _b64(flat)}
        if signed:
            payload["signed"] = True
        return self._post("closest-point", payload), lead

    def compute_closest_points(self, query_points):
        """points (..., 3), geometry_ids, primitive_ids, primitive_uvs."""
        a, lead = self._closest(query_points)
        prim = _arr(a["prim"], np.int64)
        return {"points": _arr(a["point"], np.float32).reshape(lead + (3,)),
                "geometry_ids": np.where(prim >= 0, 0, INVALID_ID).astype(np.uint32)
                .reshape(lead),
                "primitive_ids": np.where(prim >= 0, prim, INVALID_ID).astype(np.uint32)
                .reshape(lead),
                "primitive_uvs": np.stack([_arr(a["u"], np.float32),
                                           _arr(a["v"], np.float32)], axis=-1)
                .reshape(lead + (2,))}

    def compute_distance(self, query_points):
        """Distance to the closest point of the scene."""
        a, lead = self._closest(query_points)
        return _arr(a["distance"], np.float32).reshape(lead)

    def compute_signed_distance(self, query_points):
        """The distance, negative inside the closed meshes (occupancy vote)."""
        a, lead = self._closest(query_points, signed=True)
        return _arr(a["distance"], np.float32).reshape(lead)

    def compute_occupancy(self, query_points):
        """1.0 inside the closed meshes, 0.0 outside (float32, as Open3D)."""
        flat, lead = self._points(query_points)
        a = self._post("occupancy", {"points": _b64(flat)})
        return _arr(a["inside"], np.float32).reshape(lead)


__all__ = ["RaycastingScene", "INVALID_ID"]

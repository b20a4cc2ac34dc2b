#!/usr/bin/env python3
"""test_client_raycast.py - clients/kdray_raycast.py (Open3D RaycastingScene
names over kdrayd) installed the documented way, offline, then used.

    test_client_raycast.py KDRAYD CLIENTS_DIR

Copies clients/ to a temporary directory, makes a venv with
--system-site-packages (Debian's numpy, setuptools and wheel) and runs the
documented `python -m pip install --no-index --no-build-isolation ./clients`
there; then, with the venv's python (which must import the installed
modules, not the repository's), starts kdrayd on the default scene and
checks every method against the raw HTTP answers: shapes kept, misses as
inf / INVALID_ID, occlusion = closest hit exists, list_intersections'
splits = min(count, max_hits) and its first hit = cast_rays', distances at
the closest points, signed distance = +-distance with the sign of
occupancy. Run by Debian's /usr/bin/python3; fails (never skips) when numpy
or venv is missing.
"""

import os
import shutil
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))


def install(clients, tmp):
    src = os.path.join(tmp, "clients")
    shutil.copytree(clients, src, ignore=shutil.ignore_patterns("build", "*.egg-info",
                                                                 "__pycache__"))
    venv = os.path.join(tmp, "venv")
    subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", venv],
                   check=True)
    py = os.path.join(venv, "bin", "python")
    out = subprocess.run([py, "-m", "pip", "install", "--no-index", "--no-build-isolation",
                          src], capture_output=True, text=True)
    if out.returncode != 0:
        print(out.stdout, out.stderr)
        raise SystemExit("FAIL: pip install --no-index --no-build-isolation ./clients")
    return py


def checks(kdrayd):
    """Runs inside the venv: the installed modules."""
    import numpy as np
    sys.path.insert(0, HERE)
    import test_server_lib as lib
    import kdray_raycast
    from kdray_raycast import INVALID_ID, RaycastingScene
    t = lib.Runner()
    t.check("site-packages" in kdray_raycast.__file__,
            "kdray_raycast imported from the install (%s)" % kdray_raycast.__file__)
    d = lib.Daemon(kdrayd, ["--threads", "2"])
    try:
        scene = RaycastingScene(d.url, "default")
        bounds = scene.client.scene("default")["bounds"]
        o, dirs = lib.rays_into_box(bounds, 2000, seed=3)
        rays = np.concatenate([np.asarray(o, np.float32).reshape(-1, 3),
                               np.asarray(dirs, np.float32).reshape(-1, 3)], axis=1)
        rays[::7, 3:] = -rays[::7, 3:]  # some rays point away: misses
        raw = scene.client.bundle("default", rays[:, :3].ravel().tolist(),
                                  rays[:, 3:].ravel().tolist(), encoding="base64")

        def run_all(t):
            ans = scene.cast_rays(rays.reshape(40, 50, 6))
            t.eq(ans["t_hit"].shape, (40, 50), "cast_rays keeps leading dims")
            t.eq(ans["primitive_uvs"].shape, (40, 50, 2), "uv shape")
            prim = np.asarray(raw["prim"])
            hit = prim >= 0
            t.check(0 < hit.sum() < len(prim), "hits and misses (%d)" % hit.sum())
            th = ans["t_hit"].ravel()
            t.check(np.array_equal(th[hit], np.asarray(raw["t"], np.float32)[hit]),
                    "t_hit equals the bundle answer")
            t.check(np.all(np.isinf(th[~hit])), "misses are inf")
            ids = ans["primitive_ids"].ravel()
            t.check(np.array_equal(ids[hit], prim[hit].astype(np.uint32)) and
                    np.all(ids[~hit] == INVALID_ID), "primitive_ids, INVALID_ID on a miss")
            nrm = ans["primitive_normals"].reshape(-1, 3)
            t.check(np.allclose(np.linalg.norm(nrm[hit], axis=1), 1, atol=1e-6) and
                    not nrm[~hit].any(), "primitive_normals: unit on hits, 0 on misses")
            occl = scene.test_occlusions(rays)
            t.check(np.array_equal(occl, hit), "test_occlusions = a closest hit exists")
            cnt = scene.count_intersections(rays)
            lst = scene.list_intersections(rays, max_hits=4)
            splits = lst["ray_splits"].astype(np.int64)
            t.check(np.array_equal(np.diff(splits), np.minimum(cnt, 4)),
                    "list_intersections splits = min(count, max_hits)")
            first = splits[:-1][cnt > 0]
            t.check(np.array_equal(lst["t_hit"][first], th[cnt > 0]) and
                    np.array_equal(lst["primitive_ids"][first], ids[cnt > 0]),
                    "first listed hit = cast_rays'")
            t.check(np.array_equal(lst["ray_ids"], np.repeat(np.arange(len(cnt)),
                                                             np.diff(splits))), "ray_ids")
            t.check(np.array_equal(cnt > 0, hit), "count > 0 exactly where a hit exists")
            rng = np.random.default_rng(5)
            lo, hi = np.asarray(bounds["min"]), np.asarray(bounds["max"])
            pts = rng.uniform(lo - 1, hi + 1, size=(30, 20, 3)).astype(np.float32)
            cp = scene.compute_closest_points(pts)
            dist = scene.compute_distance(pts)
            t.eq(dist.shape, (30, 20), "compute_distance shape")
            err = np.abs(np.linalg.norm(cp["points"] - pts, axis=-1) - dist)
            t.check(float(err.max()) <= 1e-4 * max(1.0, float(dist.max())),
                    "distance = |point - closest point| (max error %g)" % err.max())
            occ = scene.compute_occupancy(pts)
            t.check(set(np.unique(occ)) <= {0.0, 1.0} and occ.dtype == np.float32,
                    "occupancy is 0.0/1.0 float32")
            sd = scene.compute_signed_distance(pts)
            t.check(np.array_equal(np.abs(sd), dist), "|signed distance| = distance")
            t.check(np.array_equal(sd < 0, (occ == 1) & (dist > 0)),
                    "negative exactly where occupied")
            try:
                scene.cast_rays(np.zeros((3, 5), np.float32))
                t.check(False, "rays of width 5 refused")
            except ValueError:
                pass
        t.run(run_all)
    finally:
        rc = d.stop()
    if rc != 0:
        t.failures.append("kdrayd exit status %s" % rc)
    return t.finish()


def main():
    if len(sys.argv) == 3 and sys.argv[1] == "--checks":
        return checks(sys.argv[2])
    kdrayd, clients = sys.argv[1], sys.argv[2]
    tmp = tempfile.mkdtemp(prefix="kdray-client-")
    try:
        py = install(clients, tmp)
        env = dict(os.environ, PYTHONPATH="")  # nothing from the repository
        return subprocess.run([py, os.path.abspath(__file__), "--checks", kdrayd],
                              env=env, cwd=tmp).returncode
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())

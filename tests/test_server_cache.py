#!/usr/bin/env python3
"""test_server_cache.py - kdrayd --cache-dir, over real HTTP on loopback.

    test_server_cache.py KDRAYD CLIENTS_DIR SCENE.glb

A first start builds the tree and stores it; a second start maps it (log
line, kdray_scene_from_cache metric) and answers bundle, cone-shadow and
frustum queries and the scene description byte for byte like the built
tree. A cache file truncated at many lengths or with a byte changed at
many offsets (head, mesh ranges, image head, statistics, triangles, nodes,
leaf lists) is refused with a logged reason, the tree is rebuilt, the
answers are unchanged and the file is replaced by a good one. A file under
another key's name (stale) is refused; a changed scene file gets a new
key, at a restart and at a SIGHUP reload (a reload back to bytes seen
before maps their tree). Two daemons started together on an empty directory both publish
whole files and leave no temporary file. A --cache-dir that is a file is
a clear start-up error.
"""

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile

import test_server_lib as lib

KDRAYD, CLIENTS, SCENE = sys.argv[1], sys.argv[2], sys.argv[3]
lib.add_client_path(CLIENTS)
from kdray_client import Client  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))

QUERIES = [
    ("bundle", {"origins": [0.1, 4.0, 6.0], "directions":
                [x for i in range(64)
                 for x in ((i % 7 - 3) * 0.1, -0.5 + (i % 5) * 0.05, -1.0)]}),
    ("cone-shadow", {"points": [0, 0.02, 0, 1, 0.02, 1, -2, 0.02, 0.5],
                     "lights": [{"center": [0, 9, 0], "radius": 2.0}], "samples": 64}),
    ("frustum", {"camera": {"eye": [3, 4, 9], "target": [0, 1, 0], "fov_y_deg": 50,
                            "width": 40, "height": 30}, "encoding": "base64"}),
    # the glTF mesh table travels beside the tree (a mapped tree must name
    # each hit's node, mesh and primitive as a built one does)
    ("bundle", {"origins": [0.1, 4.0, 6.0], "directions":
                [x for i in range(16) for x in ((i % 4 - 1.5) * 0.2, -0.4, -1.0)],
                "fields": ["t", "prim", "normal", "mesh"]}),
]


def answers(d, name="s"):
    c = Client(d.url, timeout=120)
    out = [c.request("GET", "/v1/scenes/" + name)]
    for kind, body in QUERIES:
        out.append(c.request("POST", "/v1/scenes/%s/%s" % (name, kind),
                             json.dumps(body).encode(), "application/json"))
    # build_ms is this process's time to get the tree (a build, or mapping
    # the cache file): the one field allowed to differ
    code, hdrs, body = out[0]
    desc = json.loads(body)
    desc.get("kdtree", {}).pop("build_ms", None)
    out[0] = (code, hdrs, json.dumps(desc, sort_keys=True).encode())
    return [(code, body) for code, _, body in out]


def start(cache, scene, wait_ready=True):
    return lib.Daemon(KDRAYD, ["--threads", "1", "--scene", "s=" + scene,
                               "--cache-dir", cache], default_scene=False,
                      wait_ready=wait_ready)


def cache_files(cache):
    return sorted(f for f in os.listdir(cache))


def from_cache(d):
    return lib.metric(Client(d.url).metrics(), "kdray_scene_from_cache", scene="s")


def test_round_trip(t, tmp):
    cache = os.path.join(tmp, "cache")  # created by kdrayd
    d = start(cache, SCENE)
    try:
        t.check(d.wait_log("tree stored in cache"), "first start stores the tree")
        t.eq(from_cache(d), 0.0, "first start built")
        built = answers(d)
    finally:
        d.stop()
    t.check(all(code == 200 for code, _ in built), "queries answered: %r" %
            [code for code, _ in built])
    files = cache_files(cache)
    t.eq(len(files), 1, "one cache file")
    t.check(files[0].endswith(".kdtree") and len(files[0]) == 32 + 7, files[0])
    d = start(cache, SCENE)
    try:
        t.check(d.wait_log("tree mapped from cache"), "second start maps the tree")
        t.check(not any("kd build" in line for line in d.log), "and does not build")
        t.eq(from_cache(d), 1.0, "kdray_scene_from_cache")
        t.check(answers(d) == built, "mapped tree answers byte for byte like the built")
    finally:
        d.stop()
    return cache, os.path.join(cache, files[0]), built


def damaged_start(t, cache, path, good, built, what):
    d = start(cache, SCENE)
    try:
        t.check(d.wait_log("tree cache file refused, rebuilding"), what + ": refused")
        print("  %s: %s" % (what, [x for x in d.log if "refused" in x][0].split(": ")[-1]))
        t.check(d.wait_log("tree stored in cache"), what + ": rebuilt and stored")
        t.eq(from_cache(d), 0.0, what + ": served from a build")
        t.check(answers(d) == built, what + ": same answers")
    finally:
        d.stop()
    # (not byte-equal to the first file: the statistics carry the build time)
    t.eq(os.path.getsize(path), len(good), what + ": a whole file replaced it")
    d = start(cache, SCENE)
    try:
        t.check(d.wait_log("tree mapped from cache"), what + ": the new file maps")
    finally:
        d.stop()


def test_damage(t, tmp):
    cache, path, built = test_round_trip(t, tmp)
    with open(path, "rb") as f:
        good = f.read()
    n = len(good)
    # head 64 B, mesh ranges, then the image: head, body, triangles, nodes, refs
    img = (64 + 20 * int.from_bytes(good[12:16], "little") + 63) // 64 * 64
    for length in (0, 10, 63, 64, img - 1, img, img + 100, img + 256, n // 2, n - 1):
        with open(path, "wb") as f:
            f.write(good[:length])
        damaged_start(t, cache, path, good, built, "truncated to %d" % length)
    for off in (3, 20, 70, img + 2, img + 30, img + 40, img + 100, img + 300, n // 2,
                n - 200, n - 1):
        bad = bytearray(good)
        bad[off] ^= 0x40
        with open(path, "wb") as f:
            f.write(bad)
        damaged_start(t, cache, path, good, built, "byte %d of %d changed" % (off, n))
    # a good file under another key's name is stale
    os.rename(path, os.path.join(cache, "0" * 32 + ".kdtree"))
    shutil.copy(os.path.join(cache, "0" * 32 + ".kdtree"), path)
    with open(path, "r+b") as f:  # its head names another key
        f.seek(16)
        f.write(b"\0" * 16)
    damaged_start(t, cache, path, good, built, "another key")
    t.check(not [f for f in cache_files(cache) if f.startswith(".tmp")], "no temp files")


def write_quad(path):
    sys.path.insert(0, os.path.join(HERE, "..", "scenes"))
    from glbutil import Glb
    g = Glb("test_server_cache")
    m = g.add_mesh("quad", [(-20, 0, -20), (20, 0, -20), (20, 0, 20), (-20, 0, 20)],
                   [0, 1, 2, 0, 2, 3])
    g.add_node("quad", mesh=m, root=True)
    g.write(path + ".tmp")
    os.replace(path + ".tmp", path)


def count(d, text):
    return sum(text in line for line in d.log)


def test_changed_scene(t, tmp):
    """A changed file has another key, at a restart and at a SIGHUP reload;
    a reload back to bytes seen before maps their tree."""
    cache = os.path.join(tmp, "cache")
    scene = os.path.join(tmp, "scene.glb")
    shutil.copy(SCENE, scene)
    d = start(cache, scene)
    try:
        t.check(d.wait_log("tree stored in cache"), "first tree stored")
        write_quad(scene)
        d.signal(signal.SIGHUP)
        t.check(d.wait_log("generation 2 serving"), "reloaded")
        t.eq(count(d, "tree cache: not cached"), 2, "the changed file has another key")
        t.eq(count(d, "tree stored in cache"), 2, "its tree is stored too")
        t.eq(Client(d.url).scene("s")["triangles"], 2, "the new scene is served")
        shutil.copy(SCENE, scene + ".tmp")
        os.replace(scene + ".tmp", scene)
        d.signal(signal.SIGHUP)
        t.check(d.wait_log("generation 3 serving"), "reloaded again")
        t.eq(count(d, "tree mapped from cache"), 1, "the first bytes' tree is mapped")
        t.eq(lib.metric(Client(d.url).metrics(), "kdray_scene_from_cache", scene="s"), 1.0,
             "served from the cache")
    finally:
        d.stop()
    t.eq(len(cache_files(cache)), 2, "one file per key")
    write_quad(scene)
    d = start(cache, scene)
    try:
        t.check(d.wait_log("tree mapped from cache"), "a restart maps the quad's tree")
        t.eq(Client(d.url).scene("s")["triangles"], 2, "and serves it")
    finally:
        d.stop()


def test_concurrent_writers(t, tmp):
    cache = os.path.join(tmp, "cache")
    a = start(cache, SCENE, wait_ready=False)
    b = start(cache, SCENE, wait_ready=False)
    try:
        for d in (a, b):
            d.wait_healthy()
            t.check(d.wait_log("tree stored in cache") or d.wait_log("mapped from cache"),
                    "each daemon stored or mapped a whole file")
    finally:
        a.stop()
        b.stop()
    files = cache_files(cache)
    t.eq(len(files), 1, "one file, no temporary left: %r" % files)
    d = start(cache, SCENE)
    try:
        t.check(d.wait_log("tree mapped from cache"), "the published file maps")
    finally:
        d.stop()


def test_bad_dir(t, tmp):
    not_dir = os.path.join(tmp, "file")
    open(not_dir, "w").close()
    p = subprocess.run([KDRAYD, "--cache-dir", not_dir], capture_output=True, text=True,
                       timeout=60)
    t.eq(p.returncode, 2, "exit status")
    t.check("--cache-dir" in p.stderr and "not a directory" in p.stderr, p.stderr)


def main():
    t = lib.Runner()
    for fn in (test_round_trip, test_damage, test_changed_scene, test_concurrent_writers,
               test_bad_dir):
        tmp = tempfile.mkdtemp(prefix="kdray-cache-")
        try:
            t.run(fn, tmp)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    return t.finish()


if __name__ == "__main__":
    sys.exit(main())

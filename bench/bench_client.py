#!/usr/bin/env python3
"""bench_client.py - clients/kdray_client.py's wall time per request, against
another version of the same file, alternated in one process.

    /usr/bin/python3 bench/bench_client.py KDRAYD SCENE.glb OLD_CLIENT.py \\
        [--rounds 7] [--rays 1048576] [--size 1024]

Starts KDRAYD on SCENE (2 worker threads), then per round sends, through
each client in turn (the old file's and this tree's clients/, alternated
request by request, the first of the two swapped every round), a GET
/v1/health (what a request costs when its answer is small), a SIZExSIZE
frustum, a RAYS-ray bundle of random directions from the
camera's eye and the same bundle with tmin > tmax (nothing traced: all
transport), all in CBOR (binary=True, lists=False: answers as array.array, so the decode
into Python lists does not hide the transport; bodies built once and sent
through Client.call), each request twice in a row on the same Client. Prints every client's median, min and max wall ms
per request kind (and the median CPU time this process spent in it) and
the new/old ratio of the wall medians. OLD_CLIENT.py is,
for example, `git show 21fc675:clients/kdray_client.py > /tmp/old.py`
(the client before its keep-alive connection). Needs python3-cbor2.
"""

import argparse
import importlib.util
import os
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, os.path.join(ROOT, "tests"))
import test_server_lib as lib  # noqa: E402
lib.add_client_path(os.path.join(ROOT, "clients"))


def load(path, name):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("kdrayd")
    p.add_argument("scene")
    p.add_argument("old")
    p.add_argument("--rounds", type=int, default=7)
    p.add_argument("--rays", type=int, default=1 << 20)
    p.add_argument("--size", type=int, default=1024)
    a = p.parse_args()
    new = load(os.path.join(ROOT, "clients", "kdray_client.py"), "client_new")
    old = load(a.old, "client_old")
    d = lib.Daemon(a.kdrayd, ["--scene", "s=" + a.scene, "--threads", "2"],
                   default_scene=False, stdout=subprocess.DEVNULL)
    try:
        c0 = new.Client(d.url)
        b = c0.scene("s")["bounds"]
        lo, hi = b["min"], b["max"]
        centre = [(x + y) / 2 for x, y in zip(lo, hi)]
        eye = [centre[0], centre[1], centre[2] + 2.0 * (hi[2] - lo[2])]
        dirs = new._f32_array(new.random_directions(a.rays, 3))
        clients = {"old": old.Client(d.url, binary=True, lists=False),
                   "new": new.Client(d.url, binary=True, lists=False)}
        path = "/v1/scenes/s/"
        # bodies built once (array('f') arrays: cbor_body copies them once),
        # so that the per-request client work is the transport and decode,
        # not the conversion of 3M floats that bundle() would do each time
        bundle = {"origins": new._f32_array(eye), "directions": dirs,
                  "fields": ["t", "prim"]}
        nothing = dict(bundle, tmin=1.0, tmax=0.0)
        frustum = {"camera": {"eye": eye, "target": centre, "up": [0, 1, 0],
                              "fov_y_deg": 60, "width": a.size, "height": a.size},
                   "fields": ["t", "prim"]}
        kinds = {
            "GET /v1/health": lambda c: c.health(),
            "frustum %dx%d" % (a.size, a.size):
                lambda c: c.call("POST", path + "frustum", frustum),
            "bundle %d rays" % a.rays:
                lambda c: c.call("POST", path + "bundle", bundle),
            # tmin > tmax: nothing to trace, the request is all transport
            "transport-only bundle":
                lambda c: c.call("POST", path + "bundle", nothing),
        }
        times = {(n, k): [] for n in clients for k in kinds}
        cpu = {(n, k): [] for n in clients for k in kinds}
        for kind, fn in kinds.items():  # warm-up: the daemon's memory
            for c in clients.values():
                fn(c)
        for rnd in range(a.rounds):
            order = list(clients.items())
            if rnd % 2:
                order.reverse()  # neither client always goes first
            for kind, fn in kinds.items():
                for _rep in range(2):
                    for name, c in order:
                        t0, c0 = time.perf_counter(), time.process_time()
                        r = fn(c)
                        times[(name, kind)].append((time.perf_counter() - t0) * 1e3)
                        cpu[(name, kind)].append((time.process_time() - c0) * 1e3)
                        assert r.get("count", 1) > 0
        load1 = os.getloadavg()[0]
        print("kdrayd %s, scene %s, %d rounds x 2 requests per client and kind, "
              "load %.1f" % (a.kdrayd, a.scene, a.rounds, load1))
        for kind in kinds:
            med = {}
            for name in clients:
                v = times[(name, kind)]
                med[name] = statistics.median(v)
                print("  %-22s %-4s median %7.1f ms  min %7.1f  max %7.1f  "
                      "(client CPU median %.1f ms)" %
                      (kind, name, med[name], min(v), max(v),
                       statistics.median(cpu[(name, kind)])))
            print("  %-22s new/old median %.3f" % (kind, med["new"] / med["old"]))
    finally:
        d.stop()


if __name__ == "__main__":
    main()

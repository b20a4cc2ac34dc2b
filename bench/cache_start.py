#!/usr/bin/env python3
"""cache_start.py - time from exec to /v1/ready for kdrayd with a cold and
a warm --cache-dir (a measurement, not a test).

    bench/cache_start.py [KDRAYD] [SCENE.glb] [WARM_RUNS]

Defaults: build/server/kdrayd, the ladder's 1.09M-triangle engine9 scene
(/work/main/build/scene-ladder/engine9.glb, or $KDRAY_SCENE_DIR/engine9.glb).
Prints the cold start (load + build + store), each warm start (map +
validate) and the daemon's own "mapped ... in N ms" figure. The issue's
target: a cached start of the 1.09M scene in < 0.3 s.
"""

import os
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def ready(url):
    try:
        with urllib.request.urlopen(url + "/v1/ready", timeout=1) as r:
            return r.status == 200
    except Exception:
        return False


def start(kdrayd, scene, cache):
    port = free_port()
    url = "http://127.0.0.1:%d" % port
    log = tempfile.TemporaryFile(mode="w+")
    t0 = time.monotonic()
    p = subprocess.Popen([kdrayd, "--listen", "127.0.0.1:%d" % port, "--threads", "1",
                          "--scene", "s=" + scene, "--cache-dir", cache],
                         stdout=subprocess.DEVNULL, stderr=log)
    while not ready(url):
        if p.poll() is not None:
            log.seek(0)
            sys.exit("kdrayd exited:\n" + log.read())
        time.sleep(0.005)
    dt = time.monotonic() - t0
    p.terminate()
    p.wait(60)
    log.seek(0)
    text = log.read()
    m = re.search(r"mapped from cache \S+ \(([\d.]+) MiB\) in ([\d.]+) ms", text)
    return dt, m


def main():
    kdrayd = sys.argv[1] if len(sys.argv) > 1 else os.path.join(ROOT, "build/server/kdrayd")
    ladder = os.environ.get("KDRAY_SCENE_DIR", "/work/main/build/scene-ladder")
    scene = sys.argv[2] if len(sys.argv) > 2 else os.path.join(ladder, "engine9.glb")
    runs = int(sys.argv[3]) if len(sys.argv) > 3 else 3
    cache = tempfile.mkdtemp(prefix="kdray-cache-bench-")
    try:
        cold, _ = start(kdrayd, scene, cache)
        print("%s: cold start (load, build, store) %.3f s to /v1/ready" %
              (os.path.basename(scene), cold))
        best = None
        for i in range(runs):
            warm, m = start(kdrayd, scene, cache)
            if not m:
                sys.exit("warm start did not map the cache file")
            print("warm start %d: %.3f s to /v1/ready (daemon: %s MiB mapped and "
                  "validated in %s ms)" % (i + 1, warm, m.group(1), m.group(2)))
            best = warm if best is None else min(best, warm)
        print("cached start: best %.3f s of %d (target < 0.3 s: %s)" %
              (best, runs, "met" if best < 0.3 else "NOT met"))
    finally:
        shutil.rmtree(cache, ignore_errors=True)


if __name__ == "__main__":
    main()

"""test_server_lib.py - shared helpers of the kdrayd integration tests:
starting a real daemon on a free loopback port, a tiny assertion runner, and
direct-core answers from kdray-trace to compare HTTP answers with.

The daemon is started with --listen 127.0.0.1:0 and the port is read from
its "listening on http://..." log line, so parallel ctest runs never fight
over a port.
"""

import json
import math
import os
import random
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
import traceback

# Optional: run the suite on another scene, served as "default".
SCENE_PATH = os.environ.get("KDRAY_TEST_SCENE")
HEALTH_TIMEOUT_S = 300.0  # scene build under ASan on a loaded 2-core box
LISTEN_RE = re.compile(r"listening on (http://[^ ]+)")


class Daemon:
    """A running kdrayd; its stderr is collected in .log (list of lines)."""

    def __init__(self, kdrayd, args=(), wait_ready=True, default_scene=True,
                 stdout=subprocess.DEVNULL, env=None):
        scene = ["--scene", "default=" + SCENE_PATH] if SCENE_PATH else []
        scene = scene if default_scene else []
        self.proc = subprocess.Popen(
            [kdrayd, "--listen", "127.0.0.1:0"] + scene + list(args),
            stdout=stdout, stderr=subprocess.PIPE, text=True, env=env)
        self.log = []
        self.url = None
        self._seen_url = threading.Event()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        if not self._seen_url.wait(HEALTH_TIMEOUT_S) or not self.url:
            self.stop()
            raise RuntimeError("kdrayd did not listen:\n" + self.log_text())
        if wait_ready:
            self.wait_healthy()

    def _read(self):
        for line in self.proc.stderr:
            self.log.append(line.rstrip("\n"))
            m = LISTEN_RE.search(line)
            if m and not self.url:
                self.url = m.group(1)
                self._seen_url.set()
        self._seen_url.set()

    def log_text(self):
        return "\n".join(self.log)

    def wait_log(self, text, timeout=30.0):
        """True once a log line contains text (the log is read by another
        thread, so a line may trail the HTTP state it describes)."""
        deadline = time.time() + timeout
        while time.time() < deadline:
            if any(text in line for line in self.log):
                return True
            time.sleep(0.01)
        return False

    def wait_healthy(self):
        from kdray_client import Client
        with Client(self.url, timeout=10) as client:  # closes its connection
            deadline = time.time() + HEALTH_TIMEOUT_S
            while time.time() < deadline:
                if self.proc.poll() is not None:
                    raise RuntimeError("kdrayd exited:\n" + self.log_text())
                status, _, _ = client.request("GET", "/v1/health")
                if status == 200:
                    return
                time.sleep(0.05)
        raise RuntimeError("kdrayd never became healthy:\n" + self.log_text())

    def signal(self, sig=signal.SIGTERM):
        self.proc.send_signal(sig)

    def wait(self, timeout=120):
        rc = self.proc.wait(timeout)
        self._reader.join(10)
        return rc

    def stop(self):
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(60)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._reader.join(10)
        return self.proc.returncode


class Runner:
    """Runs test functions, keeps going after a failure, reports at the end."""

    def __init__(self):
        self.failures = []
        self.checks = 0

    def check(self, cond, what):
        self.checks += 1
        if not cond:
            raise AssertionError(what)

    def eq(self, got, want, what):
        self.check(got == want, "%s: got %r, want %r" % (what, _short(got),
                                                        _short(want)))

    def run(self, fn, *args):
        t0 = time.time()
        try:
            fn(self, *args)
            print("ok   %-40s %.2f s" % (fn.__name__, time.time() - t0), flush=True)
        except Exception:  # every failure is reported, none stops the suite
            self.failures.append(fn.__name__)
            print("FAIL %s\n%s" % (fn.__name__, traceback.format_exc()), flush=True)

    def finish(self):
        print("%d checks, %d failed tests %s" % (self.checks, len(self.failures),
                                                 self.failures or ""))
        return 1 if self.failures else 0


def _short(x):
    s = repr(x)
    return s if len(s) < 300 else s[:300] + "..."


def core_answers(trace, specs):
    """Direct-core answers (response bodies, bytes) for a list of
    (kind, payload, mode) on the default scene, from one kdray-trace run so
    the scene is built once."""
    tmp = tempfile.mkdtemp(prefix="kdray-trace-")
    args, outs = [], []
    try:
        for i, (kind, payload, mode) in enumerate(specs):
            path = os.path.join(tmp, "req%d.json" % i)
            with open(path, "w") as f:
                json.dump(payload, f)
            args.append("%s:%s:%s" % (kind, mode, path))
            outs.append(path + ".out")
        scene = ["--scene", SCENE_PATH] if SCENE_PATH else []
        out = subprocess.run([trace] + scene + args, capture_output=True,
                             timeout=600)
        if out.returncode != 0:
            raise RuntimeError("kdray-trace failed: %s" % out.stderr.decode())
        result = []
        for path in outs:
            with open(path, "rb") as f:
                result.append(f.read())
        return result
    finally:
        for name in os.listdir(tmp):
            os.unlink(os.path.join(tmp, name))
        os.rmdir(tmp)


def rays_into_box(bounds, n, seed, shared_origin=False):
    """n rays from a sphere around the scene box toward random points in it
    (most of them hit), as flat origin and direction lists."""
    rng = random.Random(seed)
    lo, hi = bounds["min"], bounds["max"]
    center = [(a + b) / 2 for a, b in zip(lo, hi)]
    radius = max(1e-3, math.dist(lo, hi))
    origins, dirs = [], []
    for i in range(n):
        if i == 0 or not shared_origin:
            z = rng.uniform(-1, 1)
            phi = rng.uniform(0, 2 * math.pi)
            r = math.sqrt(1 - z * z)
            o = [center[0] + radius * r * math.cos(phi),
                 center[1] + radius * r * math.sin(phi), center[2] + radius * z]
            origins += o
        target = [rng.uniform(a, b) for a, b in zip(lo, hi)]
        d = [t - s for t, s in zip(target, o)]
        if not any(d):
            d = [0.0, 0.0, 1.0]
        dirs += d
    return origins, dirs


def metric(text, name, **labels):
    """The value of one Prometheus sample (0.0 if absent)."""
    want = ",".join('%s="%s"' % kv for kv in sorted(labels.items()))
    for line in text.splitlines():
        if line.startswith(name + "{") or line.startswith(name + " "):
            head, _, value = line.rpartition(" ")
            got = head[len(name):].strip("{}")
            if ",".join(sorted(got.split(","))) == want or (not labels and not got):
                return float(value)
    return 0.0


def long_shadow_payload(points, seed=5):
    """A cone-shadow query on the bundled scene that takes long: points on
    the ground, four big lights above, 4096 samples, so most (point, light)
    pairs are in penumbra and traced in full (about 2 ms of one core per
    point here; 10,000 points is ~20 s). Needs --max-rays >= points*16384."""
    rng = random.Random(seed)
    pts = []
    for _ in range(points):
        pts += [rng.uniform(-5, 5), 0.02, rng.uniform(-5, 5)]
    lights = [{"center": [x, 9, z], "radius": 2.5}
              for x, z in ((0, 0), (4, 4), (-4, 4), (4, -4))]
    return {"points": pts, "lights": lights, "samples": 4096}


# A client that posts one cone-shadow body (argv[3]) to kdrayd at
# argv[1]:argv[2] in a loop, run as its own process (`python3 -c
# BUSY_CLIENT host port body`): the health tests keep every worker busy
# with it without this process's GIL in the probes' way.
BUSY_CLIENT = r'''
import http.client, sys
c = http.client.HTTPConnection(sys.argv[1], int(sys.argv[2]), timeout=3600)
body = open(sys.argv[3], "rb").read()
while True:
    c.request("POST", "/v1/scenes/default/cone-shadow", body,
              {"Content-Type": "application/json"})
    c.getresponse().read()
'''


def pct(lat, p):
    """The p-th percentile of a sorted list (nearest rank, no interpolation)."""
    return lat[min(len(lat) - 1, int(p / 100.0 * len(lat)))]


def add_client_path(clients_dir):
    if clients_dir not in sys.path:
        sys.path.insert(0, clients_dir)

#!/usr/bin/env python3
"""test_install.py - `cmake --install` into a DESTDIR, then the installed
programs on their own.

    test_install.py BUILD_DIR SYSTEMD_ANALYZE CLIENTS_DIR

Checks that the daemon, kdray-trace, kdray-scene-info, the default scene and
the systemd unit land in standard places; that the installed kdrayd serves
the installed scene (not the source tree's) and answers queries; that the
installed kdray-trace gives the same answer; that the unit passes
`systemd-analyze verify` and scores at most 1.5 ("OK") in
`systemd-analyze security`; and that `--prefix /opt/kdray` moves everything,
the unit's ExecStart= included.
"""

import json
import os
import shutil
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import test_server_lib as lib  # noqa: E402

BUILD, ANALYZE, CLIENTS = sys.argv[1], sys.argv[2], sys.argv[3]
lib.add_client_path(CLIENTS)
from kdray_client import Client  # noqa: E402

SOURCE_SCENE = os.path.realpath(os.path.join(HERE, "..", "scenes", "default.glb"))
HARDENING = ("DynamicUser=yes", "ProtectSystem=strict", "NoNewPrivileges=yes",
             "ProtectHome=yes", "PrivateTmp=yes", "PrivateDevices=yes",
             "CapabilityBoundingSet=\n", "RestrictAddressFamilies=",
             "SystemCallFilter=@system-service", "MemoryDenyWriteExecute=yes",
             "ProtectKernelTunables=yes", "RestrictNamespaces=yes", "Type=notify")
MAX_EXPOSURE = 15  # systemd-analyze's 0..100 scale: 1.5


def install(dest, prefix):
    env = dict(os.environ, DESTDIR=dest)
    r = subprocess.run(["cmake", "--install", BUILD, "--prefix", prefix], env=env,
                       capture_output=True, text=True, timeout=300)
    if r.returncode != 0:
        raise RuntimeError("cmake --install failed:\n" + r.stdout + r.stderr)
    return os.path.join(dest, prefix.lstrip("/"))


def test_installed_daemon(t):
    dest = DEST
    root = install(dest, "/usr/local")
    for rel in ("bin/kdrayd", "bin/kdray-trace", "bin/kdray-scene-info",
                "share/kdray/default.glb", "lib/systemd/system/kdrayd.service",
                "share/doc/kdray/OPERATIONS.md", "share/doc/kdray/examples/kdrayd.default"):
        t.check(os.path.exists(os.path.join(root, rel)), "installed: " + rel)
    kdrayd = os.path.join(root, "bin", "kdrayd")
    d = lib.Daemon(kdrayd, ["--threads", "1"], default_scene=False)
    try:
        want = os.path.join(os.path.realpath(root), "share", "kdray", "default.glb")
        t.check(d.wait_log("scene default: loading " + want),
                "the installed daemon loads the installed scene:\n" + d.log_text())
        t.check(SOURCE_SCENE not in d.log_text(), "and not the source tree's")
        c = Client(d.url)
        t.eq(c.health()["status"], "ok", "installed daemon healthy")
        req = {"origins": [0, 3, 5], "directions": [0.1, -0.3, -1, -0.2, -0.3, -1]}
        code, _, answer = c.request("POST", "/v1/scenes/default/bundle",
                                    json.dumps(req).encode())
        t.eq(code, 200, "installed daemon answers")
        path = os.path.join(dest, "req.json")
        with open(path, "w") as f:
            json.dump(req, f)
        r = subprocess.run([os.path.join(root, "bin", "kdray-trace"), "--kind", "bundle",
                            "--mode", "fast", path], capture_output=True, timeout=120)
        t.eq(r.returncode, 0, "installed kdray-trace runs: %r" % r.stderr)
        t.eq(r.stdout, answer, "and answers as the daemon does (its default scene too)")
        r = subprocess.run([os.path.join(root, "bin", "kdray-scene-info"),
                            os.path.join(root, "share", "kdray", "default.glb")],
                           capture_output=True, text=True, timeout=120)
        t.eq(r.returncode, 0, "installed kdray-scene-info runs")
    finally:
        t.eq(d.stop(), 0, "installed daemon exits 0")


def test_unit(t):
    root = os.path.join(DEST, "usr", "local")
    unit_path = os.path.join(root, "lib", "systemd", "system", "kdrayd.service")
    with open(unit_path) as f:
        unit = f.read()
    t.check("ExecStart=/usr/local/bin/kdrayd " in unit, "ExecStart names the final path")
    for key in HARDENING:
        t.check(key in unit, "unit sets " + key.strip())
    if not os.path.isfile(ANALYZE):
        t.check(False, "systemd-analyze is required (Debian package systemd): %r" % ANALYZE)
        return
    # verify resolves ExecStart= on this machine: point it at the staged binary
    staged = os.path.join(os.path.dirname(root), "kdrayd.service")
    with open(staged, "w") as f:
        f.write(unit.replace("/usr/local/bin/kdrayd", os.path.join(root, "bin", "kdrayd")))
    r = subprocess.run([ANALYZE, "verify", staged], capture_output=True, text=True,
                       timeout=120)
    t.eq((r.returncode, r.stdout + r.stderr), (0, ""), "systemd-analyze verify is silent")
    r = subprocess.run([ANALYZE, "security", "--offline=true",
                        "--threshold=%d" % MAX_EXPOSURE, staged],
                       capture_output=True, text=True, timeout=120)
    score = [l for l in r.stdout.splitlines() if "Overall exposure level" in l]
    print("  " + (score[0] if score else r.stdout[-300:] + r.stderr))
    t.eq(r.returncode, 0, "exposure at most %.1f" % (MAX_EXPOSURE / 10))


def test_other_prefix(t):
    root = install(DEST2, "/opt/kdray")
    with open(os.path.join(root, "lib", "systemd", "system", "kdrayd.service")) as f:
        t.check("ExecStart=/opt/kdray/bin/kdrayd " in f.read(), "--prefix reaches the unit")
    d = lib.Daemon(os.path.join(root, "bin", "kdrayd"), ["--threads", "1"],
                   default_scene=False)
    try:
        t.check(d.wait_log("loading " + os.path.realpath(root) + "/share/kdray/default.glb"),
                "relocated daemon finds its scene")
    finally:
        t.eq(d.stop(), 0, "exit 0")


DEST = tempfile.mkdtemp(prefix="kdray-destdir-")
DEST2 = tempfile.mkdtemp(prefix="kdray-destdir-")


def main():
    t = lib.Runner()
    try:
        for fn in (test_installed_daemon, test_unit, test_other_prefix):
            t.run(fn)
    finally:
        shutil.rmtree(DEST)
        shutil.rmtree(DEST2)
    return t.finish()


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""test_page.py - the page at / in headless Debian Chromium (ctest page).

Drives Chromium through Debian's chromedriver with plain W3C WebDriver
requests (JSON over HTTP on loopback, Python's standard library only):
chromedriver comes from the same Debian source as chromium, so the two
always match, and WebDriver's pointer actions give a real drag (pointer
events on the picture) without writing a DevTools websocket client. The
test waits for the first picture, drags across it, waits for the full
picture after the release, and requires its pixels to differ from the
first one; it checks the scene picker, the stats, the /metrics link, that
drafts were shown while dragging and that never more than one picture
request was in flight. Screenshots go to OUT_DIR. It fails (never skips)
when chromium or chromedriver is missing.

Usage: test_page.py KDRAYD CLIENTS_DIR OUT_DIR
"""

import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
import base64

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import test_server_lib as lib  # noqa: E402

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
         "--no-first-run", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--window-size=1200,800"]
WAIT_S = 120.0  # a sanitizer build on a loaded 2-core box is slow

# The picture's pixels as a short digest, computed in the page.
DIGEST_JS = """
const img = document.getElementById('picture');
if (!img.complete || !img.naturalWidth) return null;
const c = document.createElement('canvas');
c.width = img.naturalWidth; c.height = img.naturalHeight;
const g = c.getContext('2d');
g.drawImage(img, 0, 0);
const d = g.getImageData(0, 0, c.width, c.height).data;
let h = 2166136261 >>> 0;
for (let i = 0; i < d.length; i += 1) { h ^= d[i]; h = Math.imul(h, 16777619) >>> 0; }
return [c.width, c.height, h];
"""


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


class WebDriver:
    def __init__(self, url):
        self.url = url
        self.session = None

    def call(self, method, path, body=None):
        data = json.dumps(body).encode() if body is not None else None
        req = urllib.request.Request(self.url + path, data=data, method=method,
                                     headers={"Content-Type": "application/json"})
        try:
            with urllib.request.urlopen(req, timeout=WAIT_S) as resp:
                return json.loads(resp.read())["value"]
        except urllib.error.HTTPError as err:
            raise RuntimeError("webdriver %s %s: %s" % (method, path, err.read()[:500]))

    def s(self, method, path, body=None):
        return self.call(method, "/session/%s%s" % (self.session, path), body)

    def js(self, script, *args):
        return self.s("POST", "/execute/sync", {"script": script, "args": list(args)})

    def wait(self, script, what, timeout=WAIT_S):
        deadline = time.time() + timeout
        while time.time() < deadline:
            v = self.js(script)
            if v:
                return v
            time.sleep(0.05)
        raise AssertionError("timed out waiting for " + what)

    def screenshot(self, path):
        with open(path, "wb") as f:
            f.write(base64.b64decode(self.s("GET", "/screenshot")))


def start_driver(profile):
    port = free_port()
    proc = subprocess.Popen([CHROMEDRIVER, "--port=%d" % port],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wd = WebDriver("http://127.0.0.1:%d" % port)
    deadline = time.time() + 30
    while True:
        try:
            if wd.call("GET", "/status").get("ready"):
                break
        except (OSError, RuntimeError):
            pass
        if time.time() > deadline:
            proc.kill()
            raise RuntimeError("chromedriver did not start")
        time.sleep(0.1)
    caps = {"capabilities": {"alwaysMatch": {
        "browserName": "chrome",
        "goog:chromeOptions": {"binary": CHROMIUM,
                               "args": FLAGS + ["--user-data-dir=" + profile]}}}}
    wd.session = wd.call("POST", "/session", caps)["sessionId"]
    return proc, wd


def test_page(r, wd, url, out_dir):
    t0 = time.time()
    wd.s("POST", "/url", {"url": url + "/"})
    wd.wait("return window.kdray && window.kdray.pictures >= 1", "the first picture")
    first_ms = wd.js("return window.kdray.firstPictureMs")
    print("first picture (a draft) %.0f ms after the page started (%.2f s after "
          "navigation began)" % (first_ms, time.time() - t0))
    # then the full picture follows by itself
    wd.wait("return window.kdray.pictures >= 2 && window.kdray.lastDraft === false && "
            "window.kdray.inFlight === 0", "the full first picture")
    before = wd.wait(DIGEST_JS, "the first picture's pixels")
    wd.screenshot(os.path.join(out_dir, "page-first.png"))
    r.eq(wd.js("return [...document.querySelectorAll('#scene option')].map(o => o.value)"),
         ["default"], "scene picker lists the scenes")
    r.check(wd.js("return document.querySelector('a[href=\"/metrics\"]') !== null"),
            "a link to /metrics")
    r.check(wd.js("return document.getElementById('s-cones').textContent.includes(' of ')"),
            "cones decided shown")
    r.check(wd.js("return /ms$/.test(document.getElementById('s-total').textContent)"),
            "query time shown")
    r.eq(wd.js("return document.getElementById('status').textContent"), "", "no error")
    n0 = wd.js("return window.kdray.pictures")
    # drag across the picture: pointer down, ten moves, pointer up
    cx, cy = wd.js("const b = document.getElementById('view').getBoundingClientRect();"
                   "return [Math.round(b.left + b.width / 3), Math.round(b.top + b.height / 2)]")
    moves = [{"type": "pointerMove", "duration": 40, "origin": "pointer", "x": 25, "y": 6}
             for _ in range(10)]
    actions = {"actions": [{"type": "pointer", "id": "mouse",
                            "parameters": {"pointerType": "mouse"},
                            "actions": [{"type": "pointerMove", "duration": 0,
                                         "origin": "viewport", "x": cx, "y": cy},
                                        {"type": "pointerDown", "button": 0}] + moves +
                            [{"type": "pointerUp", "button": 0}]}]}
    wd.s("POST", "/actions", actions)
    wd.wait("return window.kdray.inFlight === 0 && window.kdray.lastDraft === false && "
            "window.kdray.pictures > %d" % n0, "the full picture after the drag")
    after = wd.wait(DIGEST_JS, "the new picture's pixels")
    wd.screenshot(os.path.join(out_dir, "page-after-drag.png"))
    r.check(after != before, "the picture changed: %r -> %r" % (before, after))
    r.eq(after[:2], before[:2], "full resolution again after the release")
    k = wd.js("return window.kdray")
    print("page: %d requests, %d pictures, %d drafts cancelled, at most %d in flight"
          % (k["requests"], k["pictures"], k["aborted"], k["maxInFlight"]))
    r.eq(k["maxInFlight"], 1, "never more than one request in flight")
    r.check(k["requests"] >= 2, "a picture was asked for after the drag")
    # a narrow window: the layout stacks, the picture is still shown
    wd.s("POST", "/window/rect", {"width": 420, "height": 800})
    wd.wait("return window.kdray.inFlight === 0 && window.kdray.pictures > %d"
            % k["pictures"], "the picture for the narrow window")
    r.check(wd.js("const b = document.getElementById('picture').getBoundingClientRect();"
                  "return b.width > 100 && b.right <= window.innerWidth + 1"),
            "the picture fits a narrow window")
    wd.screenshot(os.path.join(out_dir, "page-narrow.png"))


def main():
    kdrayd, clients, out_dir = sys.argv[1], sys.argv[2], sys.argv[3]
    for tool, pkg in ((CHROMIUM, "chromium"), (CHROMEDRIVER, "chromium-driver")):
        if not os.path.exists(tool):
            print("FAIL: %s is missing (Debian package %s; scripts/dev installs it)"
                  % (tool, pkg))
            return 1
    lib.add_client_path(clients)
    os.makedirs(out_dir, exist_ok=True)
    r = lib.Runner()
    profile = tempfile.mkdtemp(prefix="kdray-chromium-")
    d = lib.Daemon(kdrayd)
    proc = wd = None
    try:
        proc, wd = start_driver(profile)
        r.run(test_page, wd, d.url, out_dir)
    finally:
        if wd and wd.session:
            try:
                wd.call("DELETE", "/session/" + wd.session)
            except (OSError, RuntimeError):
                pass
        if proc:
            proc.terminate()
            proc.wait(30)
        d.stop()
        shutil.rmtree(profile, ignore_errors=True)
    print("screenshots in %s" % out_dir)
    return r.finish()


if __name__ == "__main__":
    sys.exit(main())

"""cluster_lib.py - kdrayd replicas behind HAProxy on loopback, for the
cluster test (tests/test_cluster.py) and the cluster benchmark
(bench/cluster_bench.py): free ports, replicas that can be killed and
restarted on the same port, HAProxy started on deploy/haproxy/kdray.cfg
itself (addresses through its environment variables), its CSV status
page, wrk with a Lua script that counts statuses.
"""

import csv
import io
import os
import re
import signal
import socket
import subprocess
import tempfile
import threading
import time
import urllib.request

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
CFG = os.path.join(ROOT, "deploy", "haproxy", "kdray.cfg")
SCENE_MAP = os.path.join(ROOT, "deploy", "haproxy", "kdray-scenes.map")
# HAProxy's command line beyond -f: -dMglobal, its process-wide pool of
# freed buffers, as deploy/haproxy/kdray.cfg asks (see its header).
HAPROXY_OPTS = ["-dMglobal"]

# wrk: POSTs KDRAY_BODY to the URL; counts statuses and 503s that carry
# Retry-After; prints them as one "statuses ..." line at the end.
WRK_LUA = r"""
wrk.method = "POST"
wrk.headers["Content-Type"] = "application/json"
local f = assert(io.open(os.getenv("KDRAY_BODY"), "rb"))
wrk.body = f:read("*a")
f:close()
local threads = {}
function setup(thread)
  table.insert(threads, thread)
end
function init(args)
  codes = {}
  retry_after = 0
end
function response(status, headers, body)
  codes[status] = (codes[status] or 0) + 1
  -- header names are case-insensitive; HAProxy sends them lower-case
  if status == 503 and (headers["Retry-After"] or headers["retry-after"]) then
    retry_after = retry_after + 1
  end
end
function done(summary, latency, requests)
  local total, ra = {}, 0
  for _, t in ipairs(threads) do
    local c = t:get("codes")
    for k, v in pairs(c) do total[k] = (total[k] or 0) + v end
    ra = ra + t:get("retry_after")
  end
  local parts = {}
  for k, v in pairs(total) do table.insert(parts, k .. "=" .. v) end
  io.write("statuses " .. table.concat(parts, " ") .. " retry_after=" .. ra .. "\n")
end
"""


def free_port():
    s = socket.socket()
    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def get(url, timeout=5):
    """(status, headers, body) of a GET; status 0 if no connection."""
    try:
        with urllib.request.urlopen(url, timeout=timeout) as r:
            return r.status, dict(r.headers), r.read()
    except urllib.error.HTTPError as e:
        return e.code, dict(e.headers), e.read()
    except (OSError, urllib.error.URLError):
        return 0, {}, b""


def post(url, body, timeout=60):
    req = urllib.request.Request(url, data=body, method="POST",
                                 headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=timeout) as r:
            return r.status, dict(r.headers), r.read()
    except urllib.error.HTTPError as e:
        return e.code, dict(e.headers), e.read()


class Replica:
    """One kdrayd on a fixed loopback port (restartable on the same port)."""

    def __init__(self, kdrayd, scenes, threads=1, extra=()):
        self.kdrayd, self.scenes, self.threads = kdrayd, scenes, threads
        self.extra = list(extra)
        self.port = free_port()
        self.addr = "127.0.0.1:%d" % self.port
        self.url = "http://" + self.addr
        self.proc = None
        self.was_ready = False
        self.log = tempfile.TemporaryFile(mode="w+")
        self.start()

    def start(self):
        args = [self.kdrayd, "--listen", self.addr, "--threads", str(self.threads)]
        for name, path in self.scenes:
            args += ["--scene", "%s=%s" % (name, path)]
        self.proc = subprocess.Popen(args + self.extra, stdout=subprocess.DEVNULL,
                                     stderr=self.log)

    def wait_ready(self, timeout=300):
        deadline = time.time() + timeout
        moves = 0
        while time.time() < deadline:
            if self.proc.poll() is not None:
                # free_port() closes its probe socket before kdrayd binds, so
                # a test running beside this one (ctest -j) can take the port
                # in between. Before the replica was first ready nothing else
                # knows its address: take another port and start again.
                if (not self.was_ready and moves < 5 and
                        "Address already in use" in self.log_text()):
                    moves += 1
                    self.port = free_port()
                    self.addr = "127.0.0.1:%d" % self.port
                    self.url = "http://" + self.addr
                    self.log.seek(0)
                    self.log.truncate()
                    self.start()
                    continue
                raise RuntimeError("kdrayd exited: " + self.log_text())
            if get(self.url + "/v1/ready", 2)[0] == 200:
                self.was_ready = True
                return
            time.sleep(0.02)
        raise RuntimeError("kdrayd never ready: " + self.log_text())

    def kill(self):
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait()

    def stop(self):
        if self.proc and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(60)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()

    def rss_kib(self):
        with open("/proc/%d/status" % self.proc.pid) as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
        return 0

    def log_text(self):
        self.log.seek(0)
        return self.log.read()[-4000:]


class Balancer:
    """HAProxy on deploy/haproxy/kdray.cfg; main and big are address lists
    (the config has three main servers and one big one: missing ones point
    at a port nobody listens on and stay DOWN)."""

    def __init__(self, haproxy, main, big):
        dead = "127.0.0.1:%d" % free_port()
        main = list(main) + [dead] * (3 - len(main))
        big = list(big) or [dead]
        self.port, self.stats_port = free_port(), free_port()
        self.url = "http://127.0.0.1:%d" % self.port
        self.stats_url = "http://127.0.0.1:%d/stats;csv" % self.stats_port
        env = dict(os.environ, KDRAY_BIND="127.0.0.1:%d" % self.port,
                   KDRAY_STATS_BIND="127.0.0.1:%d" % self.stats_port,
                   KDRAY_MAIN_1=main[0], KDRAY_MAIN_2=main[1], KDRAY_MAIN_3=main[2],
                   KDRAY_BIG_1=big[0], KDRAY_SCENE_MAP=SCENE_MAP)
        self.log = tempfile.TemporaryFile(mode="w+")
        self.proc = subprocess.Popen([haproxy, "-db"] + HAPROXY_OPTS + ["-f", CFG], env=env,
                                     stdout=self.log, stderr=self.log)

    def servers(self):
        """{(backend, server): (status, retries, redispatches)}"""
        code, _, body = get(self.stats_url, 2)
        if code != 200:
            return {}
        rows = csv.DictReader(io.StringIO(body.decode().lstrip("# ")))
        return {(r["pxname"], r["svname"]): (r["status"], int(r["wretr"] or 0),
                                             int(r["wredis"] or 0))
                for r in rows if r["svname"] not in ("FRONTEND", "BACKEND")}

    def backend_retries(self, backend):
        code, _, body = get(self.stats_url, 2)
        rows = csv.DictReader(io.StringIO(body.decode().lstrip("# ")))
        for r in rows:
            if r["pxname"] == backend and r["svname"] == "BACKEND":
                return int(r["wretr"] or 0), int(r["wredis"] or 0)
        return 0, 0

    def wait_status(self, want, timeout=30):
        """Waits until every (backend, server) in want has its status."""
        deadline = time.time() + timeout
        while time.time() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError("haproxy exited: " + self.log_text())
            s = self.servers()
            if all(s.get(k, ("?",))[0].startswith(v) for k, v in want.items()):
                return True
            time.sleep(0.05)
        return False

    def stop(self):
        if self.proc.poll() is None:
            self.proc.terminate()
            self.proc.wait(30)

    def log_text(self):
        self.log.seek(0)
        return self.log.read()[-4000:]


class Dropper:
    """A fake replica on loopback: answers GET (the balancer's /v1/ready and
    /v1/health checks) with 200, but reads each POST's whole body and closes
    the connection without a byte of answer, as a replica killed mid-query
    would. posts counts the bodies it dropped (and their sizes)."""

    def __init__(self):
        self.sock = socket.socket()
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(64)
        self.port = self.sock.getsockname()[1]
        self.addr = "127.0.0.1:%d" % self.port
        self.posts = []
        self.stopped = False
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self):
        while not self.stopped:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            threading.Thread(target=self._serve, args=(conn,), daemon=True).start()

    def _serve(self, conn):
        with conn:
            data = b""
            while b"\r\n\r\n" not in data:
                chunk = conn.recv(65536)
                if not chunk:
                    return
                data += chunk
            head, _, rest = data.partition(b"\r\n\r\n")
            if head.startswith(b"GET "):
                conn.sendall(b"HTTP/1.1 200 OK\r\nContent-Length: 0\r\n"
                             b"Connection: close\r\n\r\n")
                return
            m = re.search(rb"(?im)^content-length:\s*(\d+)", head)
            want = int(m.group(1)) if m else 0
            while len(rest) < want:
                chunk = conn.recv(1 << 20)
                if not chunk:
                    break
                rest += chunk
            self.posts.append(len(rest))

    def stop(self):
        self.stopped = True
        self.sock.close()


def cpu_split(pid):
    """(user, system) CPU seconds of a process so far (from /proc)."""
    with open("/proc/%d/stat" % pid) as f:
        fields = f.read().rsplit(")", 1)[1].split()
    tick = os.sysconf("SC_CLK_TCK")
    return int(fields[11]) / tick, int(fields[12]) / tick


def wrk(url, body_path, seconds, conns, threads=1, timeout_s=30):
    """Runs wrk; returns (requests/s, {status: count}, retry_after_503s,
    socket errors text or "", full output)."""
    with tempfile.NamedTemporaryFile("w", suffix=".lua", delete=False) as f:
        f.write(WRK_LUA)
        lua = f.name
    try:
        out = subprocess.run(
            ["wrk", "-t%d" % threads, "-c%d" % conns, "-d%ds" % seconds,
             "--timeout", "%ds" % timeout_s, "-s", lua, url],
            env=dict(os.environ, KDRAY_BODY=body_path), capture_output=True,
            text=True, timeout=seconds + timeout_s + 30).stdout
    finally:
        os.unlink(lua)
    rps = float(re.search(r"Requests/sec:\s+([\d.]+)", out).group(1))
    m = re.search(r"^statuses (.*) retry_after=(\d+)$", out, re.M)
    codes = {}
    for part in m.group(1).split():
        k, v = part.split("=")
        codes[int(k)] = int(v)
    errors = re.search(r"Socket errors:.*", out)
    return rps, codes, int(m.group(2)), errors.group(0) if errors else "", out


def run_in_thread(fn, *args):
    box = {}
    th = threading.Thread(target=lambda: box.update(r=fn(*args)))
    th.start()
    return th, box

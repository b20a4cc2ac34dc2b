#!/usr/bin/env python3
"""test_cluster.py - three kdrayd replicas and a sharded fourth behind
HAProxy running deploy/haproxy/kdray.cfg, all on loopback.

    test_cluster.py KDRAYD HAPROXY SCENE.glb [SECONDS]

Asserts: HAProxy's active checks on /v1/ready put every replica in
rotation; /v1/scenes/big/... is routed by the scene map to the big group
(whose replica alone serves "big") and every other path to the main group;
under wrk load (SECONDS, default 12) through the balancer one main replica
is killed with SIGKILL and restarted on its port mid-run, and every client
request still gets a 200 (no other status, no socket error): requests that
were on the killed replica are retried once on another (HAProxy's retry
counters must show it). The restarted replica is back in rotation before
the load ends. A client that hangs up mid-query through the balancer has
its query cancelled (the replica's worker comes free, its cancellation
counter grows). A replica that takes a 64K-ray base64 query (about
1 MiB) and closes without answering has it retried on the other replica
(the whole body must fit HAProxy's buffer). With no replica of a group
alive, HAProxy's own answer is a 503 problem+json with Retry-After.
"""

import base64
import json
import os
import re
import socket
import struct
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import cluster_lib as cl  # noqa: E402

KDRAYD, HAPROXY, SCENE = sys.argv[1], sys.argv[2], sys.argv[3]
SECONDS = int(sys.argv[4]) if len(sys.argv) > 4 else 12
failures = []


def check(cond, what):
    print(("ok   " if cond else "FAIL ") + what, flush=True)
    if not cond:
        failures.append(what)


def bundle_body(n):
    dirs = []
    for i in range(n):
        dirs += [(i % 17 - 8) * 0.05, -0.4 + (i % 13) * 0.03, -1.0]
    return json.dumps({"origins": [0.2, 4.0, 8.0], "directions": dirs,
                       "encoding": "base64"}).encode()


def bundle_64k_b64():
    """The benchmark's request (bench/cluster_bench.py): 65536 directions
    from one origin, base64 float32, 1,048,665 bytes."""
    dirs = []
    for i in range(65536):
        dirs += [(i % 17 - 8) * 0.05, -0.4 + (i % 13) * 0.03, -1.0]
    def b64(v):
        return {"f32": base64.b64encode(struct.pack("<%df" % len(v), *v)).decode()}
    return json.dumps({"origins": b64([0.2, 4.0, 8.0]), "directions": b64(dirs),
                       "encoding": "base64"}).encode()


def metric(url, name):
    _, _, body = cl.get(url + "/metrics")
    m = re.search(r"^%s(?:\{[^}]*\})? ([\d.e+-]+)$" % name, body.decode(), re.M)
    return float(m.group(1)) if m else -1.0


def long_shadow(points):
    """A cone-shadow query of several seconds of one core."""
    pts = []
    for i in range(points):
        pts += [(i % 97) / 9.7 - 5, 0.02, (i % 89) / 8.9 - 5]
    return json.dumps({"points": pts, "samples": 4096,
                       "lights": [{"center": [x, 9, z], "radius": 2.5}
                                  for x, z in ((0, 0), (4, 4), (-4, 4), (4, -4))]}).encode()


def main():
    many = ["--max-rays", str(3000 * 4 * 4096)]
    main_reps = [cl.Replica(KDRAYD, [("default", SCENE)], extra=many) for _ in range(3)]
    big = cl.Replica(KDRAYD, [("big", SCENE)])
    lb = None
    body = tempfile.NamedTemporaryFile(suffix=".json", delete=False)
    body.write(bundle_body(1024))
    body.close()
    try:
        for r in main_reps + [big]:
            r.wait_ready()
        lb = cl.Balancer(HAPROXY, [r.addr for r in main_reps], [big.addr])
        up = {("kdray_main", "main%d" % i): "UP" for i in (1, 2, 3)}
        up[("kdray_big", "big1")] = "UP"
        check(lb.wait_status(up), "every replica UP by its /v1/ready check: %r" %
              lb.servers())

        # routing by scene name
        check(cl.get(lb.url + "/v1/scenes/big")[0] == 200, "big routed to the big group")
        check(cl.get(main_reps[0].url + "/v1/scenes/big")[0] == 404,
              "(the main group does not serve big)")
        check(cl.get(lb.url + "/v1/scenes/default")[0] == 200, "default to the main group")
        code, _, _ = cl.post(lb.url + "/v1/scenes/big/bundle", bundle_body(8))
        check(code == 200, "a query on big through the balancer: %d" % code)
        check(cl.get(lb.url + "/v1/ready")[0] == 200, "probes pass through")

        # load, one replica killed and restarted in the middle
        retr0 = lb.backend_retries("kdray_main")
        th, box = cl.run_in_thread(cl.wrk, lb.url + "/v1/scenes/default/bundle", body.name,
                                   SECONDS, 6)
        time.sleep(SECONDS * 0.25)
        victim = main_reps[1]
        victim.kill()
        print("     killed main2 (SIGKILL) at %.1f s" % (SECONDS * 0.25), flush=True)
        check(lb.wait_status({("kdray_main", "main2"): "DOWN"}, SECONDS * 0.25),
              "HAProxy saw main2 DOWN")
        victim.start()
        victim.wait_ready()
        back = lb.wait_status({("kdray_main", "main2"): "UP"}, SECONDS * 0.4)
        check(back, "main2 restarted and back UP while the load runs")
        th.join(SECONDS + 120)
        rps, codes, _, errors, out = box["r"]
        retr1 = lb.backend_retries("kdray_main")
        total = sum(codes.values())
        print("     wrk: %.0f requests/s, statuses %r, %s; HAProxy retries %d, "
              "redispatches %d" % (rps, codes, errors or "no socket errors",
                                   retr1[0] - retr0[0], retr1[1] - retr0[1]), flush=True)
        check(total > 0 and codes.get(200, 0) == total,
              "every request through the kill answered 200 (%d of %d)" %
              (codes.get(200, 0), total))
        check(not errors, "no socket errors")
        check(retr1[0] + retr1[1] > retr0[0] + retr0[1],
              "the kill was felt: HAProxy retried requests on another replica")
        check(lb.wait_status(up, 10), "all replicas UP at the end")

        # a client that hangs up through the balancer frees its worker
        # (HAProxy's abortonclose: without it the query ran to its end)
        rep = main_reps[0]
        # the load phase may still end queries on this replica (wrk's
        # connections closing cancel theirs): take the baseline only once
        # the replica is idle and its count has stood still for 0.5 s
        t0, c0, still = time.time(), -1, 0.0
        while time.time() - t0 < 30:
            c = metric(rep.url, "kdray_cancellations_total")
            idle = (metric(rep.url, "kdray_workers_busy") == 0
                    and metric(rep.url, "kdray_queue_depth") == 0)
            if c == c0 and idle:
                still += 0.05
                if still >= 0.5:
                    break
            else:
                c0, still = c, 0.0
            time.sleep(0.05)
        long = long_shadow(3000)
        lb2 = cl.Balancer(HAPROXY, [rep.addr], [])
        try:
            check(lb2.wait_status({("kdray_main", "main1"): "UP"}), "one-replica balancer")
            s = socket.create_connection(("127.0.0.1", lb2.port))
            s.sendall(b"POST /v1/scenes/default/cone-shadow HTTP/1.1\r\nHost: x\r\n"
                      b"Content-Type: application/json\r\nContent-Length: %d\r\n\r\n"
                      % len(long) + long)
            t0 = time.time()
            while metric(rep.url, "kdray_workers_busy") < 1 and time.time() - t0 < 60:
                time.sleep(0.01)
            check(metric(rep.url, "kdray_workers_busy") == 1, "the long query runs")
            s.close()
            t1 = time.time()
            while metric(rep.url, "kdray_workers_busy") > 0 and time.time() - t1 < 60:
                time.sleep(0.01)
            freed = time.time() - t1
            # the worker frees itself before the query's end is counted (the
            # executor's books are closed just after): give the count a moment
            while (metric(rep.url, "kdray_cancellations_total") < c0 + 1
                   and time.time() - t1 < 10):
                time.sleep(0.01)
            c1 = metric(rep.url, "kdray_cancellations_total")
            check(freed < 5.0 and c1 == c0 + 1,
                  "hang-up through HAProxy cancelled the query (worker free in %.3f s, "
                  "cancellations %d -> %d)" % (freed, c0, c1))
        finally:
            lb2.stop()

        # a 64K-ray base64 query (about 1 MiB) whose replica dies without
        # answering is retried on the other one: HAProxy still holds all of
        # it only if tune.bufsize (KDRAY_LB_BUFSIZE) fits it
        rep = main_reps[0]
        drop = cl.Dropper()
        lb3 = cl.Balancer(HAPROXY, [drop.addr, rep.addr], [])
        try:
            check(lb3.wait_status({("kdray_main", "main1"): "UP",
                                   ("kdray_main", "main2"): "UP",
                                   ("kdray_main", "main3"): "DOWN"}),
                  "dropping replica and real replica UP")
            big_body = bundle_64k_b64()
            codes = []
            for _ in range(8):  # leastconn alternates between the two idle ones
                codes.append(cl.post(lb3.url + "/v1/scenes/default/bundle", big_body)[0])
                if len(drop.posts) >= 2:
                    break
            retr = lb3.backend_retries("kdray_main")
            print("     %d-byte bodies: statuses %r; the dropper took %d; HAProxy "
                  "retries %d, redispatches %d" % (len(big_body), codes, len(drop.posts),
                                                  retr[0], retr[1]), flush=True)
            check(len(drop.posts) >= 1 and all(n == len(big_body) for n in drop.posts),
                  "the dropping replica received whole 64K-ray bodies")
            check(codes and all(c == 200 for c in codes),
                  "every 64K-ray query answered 200 though one replica dropped it: "
                  "retried on the other")
        finally:
            lb3.stop()
            drop.stop()

        # no replica of a group alive: HAProxy's own 503, problem+json with
        # Retry-After like the replicas'
        big.kill()
        check(lb.wait_status({("kdray_big_alive", "big1"): "DOWN"}, 10), "big1 DOWN")
        code, hdrs, answer = cl.post(lb.url + "/v1/scenes/big/bundle", bundle_body(8))
        hdrs = {k.lower(): v for k, v in hdrs.items()}
        check(code == 503 and hdrs.get("retry-after") == "1" and
              hdrs.get("content-type") == "application/problem+json" and
              json.loads(answer)["status"] == 503,
              "no replica: 503 problem+json with Retry-After (%d %r)" % (code, hdrs))
    finally:
        if lb:
            lb.stop()
        for r in main_reps + [big]:
            r.stop()
        os.unlink(body.name)
    if failures:
        if lb:
            print(lb.log_text())
        print("%d failed: %r" % (len(failures), failures))
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())

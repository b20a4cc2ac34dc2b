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
the load ends.
"""

import json
import os
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


def main():
    main_reps = [cl.Replica(KDRAYD, [("default", SCENE)]) for _ in range(3)]
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

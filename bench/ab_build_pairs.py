#!/usr/bin/env python3
"""bench/ab_build_pairs.py: the summary of `bench/ab_build --separate N`.

Reads the lines `side A|B SCENE TRIS T first CPU WALL IDLE best CPU WALL IDLE
NODES REFS` that kdray_ab_build --side printed, one process per line, A and
B alternated, and prints per scene and thread count the medians (and
ranges) of the per-pair ratios B/A: of the process's first build and of its
best build, for process CPU, wall and idle>= time. With --same it exits 1
when A's and B's tree digests differ.

    ab_build_pairs.py FILE [--same]
"""
import statistics
import sys


def main(argv):
    if len(argv) < 2 or argv[1] in ("-h", "--help"):
        print(__doc__.strip())
        return 0 if len(argv) >= 2 else 2
    same = "--same" in argv[2:]
    runs = {}  # (scene, tris, threads) -> {"A": [...], "B": [...]}
    with open(argv[1]) as f:
        for line in f:
            w = line.split()
            if len(w) != 15 or w[0] != "side" or w[5] != "first" or w[9] != "best":
                continue
            key = (w[2], int(w[3]), int(w[4]))
            vals = [float(x) for x in w[6:9] + w[10:13]]
            runs.setdefault(key, {"A": [], "B": []})[w[1]].append((vals, w[13], w[14]))
    if not runs:
        print("ab_build_pairs: no side lines in " + argv[1], file=sys.stderr)
        return 1
    names = ["cpu", "wall", "idle>="]
    print("separate processes, A and B alternated; B/A median (range) over the pairs; "
          "first = a process's first build, best = its fastest")
    print("%-10s %8s %2s %5s | %-26s %-26s %-26s | %-26s %-26s %-26s | %s" % (
        "scene", "tris", "T", "pairs", *("first " + n for n in names),
        *("best " + n for n in names), "trees"))
    bad = 0
    for key, sides in runs.items():
        pairs = list(zip(sides["A"], sides["B"]))
        if not pairs:
            continue
        cells = []
        for j in range(6):
            r = [b[0][j] / a[0][j] for a, b in pairs if a[0][j] > 0]
            cells.append("%.3f (%.3f-%.3f)" % (statistics.median(r), min(r), max(r))
                         if r else "-")
        digests = {(x[1], x[2]) for s in ("A", "B") for x in sides[s]}
        trees = "same" if len(digests) == 1 else "DIFFERENT"
        bad |= same and trees != "same"
        amed = [statistics.median(a[0][j] for a, _ in pairs) for j in range(6)]
        bmed = [statistics.median(b[0][j] for _, b in pairs) for j in range(6)]
        print("%-10s %8d %2d %5d | %s | %s | %s" % (
            key[0], key[1], key[2], len(pairs), " ".join("%-26s" % c for c in cells[:3]),
            " ".join("%-26s" % c for c in cells[3:]), trees))
        print("%-10s %8s %2s %5s   ms, median A -> B: first %s; best %s" % (
            "", "", "", "", ", ".join("%.1f -> %.1f" % (amed[j], bmed[j]) for j in range(3)),
            ", ".join("%.1f -> %.1f" % (amed[j], bmed[j]) for j in range(3, 6))))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))

#!/usr/bin/env python3
"""tables.py OUTDIR — the Markdown tables of docs/BENCHMARKS.md and the
numbers of README's target table, computed from the summary CSVs of one
bench/run-all (core.csv, bundle.csv, frustum.csv, cone.csv), so that no
figure is copied by hand. Ratios are speed ratios (> 1: kd faster); "best"
is the strongest Embree API of that row's workload, named.
"""
import csv
import math
import os
import sys
from collections import OrderedDict


def load(path):
    """{scene: {(workload, method): row}} in file order, plus triangles."""
    out = OrderedDict()
    if not os.path.exists(path):
        return out
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            out.setdefault(r["scene"], {})[(r["workload"], r["method"])] = r
    return out


def ms(rows, w, m):
    r = rows.get((w, m))
    return float(r["ms"]) if r else None


def over(rows, w, a, b):
    """Speed of method a over method b (b's time / a's time)."""
    ta, tb = ms(rows, w, a), ms(rows, w, b)
    return tb / ta if ta and tb else None


def best(rows, w):
    """(name without embree_, ms) of the strongest Embree API of workload w."""
    for (work, m), r in rows.items():
        if work == w and r["rival"]:
            return r["rival"][len("embree_"):], ms(rows, w, r["rival"])
    return None, None


def vs_best(rows, w, m):
    api, t = best(rows, w)
    tm = ms(rows, w, m)
    return (t / tm if t and tm else None), api


def fms(v):
    """A time in ms: two decimals below 10 ms (the small scenes build in
    microseconds), one above."""
    return "-" if v is None else ("%.2f" % v if v < 10 else "%.1f" % v)


def f2(v):
    return "-" if v is None else "%.2f" % v


def rng(vals):
    vals = [v for v in vals if v is not None]
    if not vals:
        return "-"
    lo, hi = min(vals), max(vals)
    return "%.2f" % lo if abs(hi - lo) < 0.005 else "%.2f–%.2f" % (lo, hi)


def gmean(vals):
    vals = [v for v in vals if v]
    return math.exp(sum(map(math.log, vals)) / len(vals)) if vals else None


def short(api):
    """rtcIntersect16_coherent -> I16c, rtcOccluded1M -> O1M."""
    if not api:
        return "-"
    s = api.replace("rtcIntersect", "I").replace("rtcOccluded", "O")
    return s.replace("_coherent", "c")


def tris(rows):
    return next(iter(rows.values()))["triangles"]


def bytes_per_tri(out):
    """{scene: (kd, embree)} bytes per triangle from core.txt's last table
    (the summary CSV holds times only)."""
    path, got, on = os.path.join(out, "core.txt"), {}, False
    if not os.path.exists(path):
        return got
    for line in open(path):
        if line.startswith("== kd build, single rays") or line.startswith("== kd build and single rays"):
            on = True
        elif on and "|" in line and not line.startswith("scene"):
            cells = [c.split() for c in line.split("|")]
            if len(cells) > 2 and len(cells[2]) == 2 and cells[0]:
                got[cells[0][0]] = (cells[2][0], cells[2][1])
    return got


def core_tables(core, bpt):
    print("#### kd build and memory\n")
    print("| scene | triangles | kd build ms | Embree HIGH ms | kd / HIGH (time) | "
          "Embree MEDIUM ms | kd / MEDIUM | bytes/triangle kd / Embree HIGH |")
    print("|---|---|---|---|---|---|---|---|")
    for s, rows in core.items():
        kd, hi, med = (ms(rows, "build", m) for m in
                       ("kd_build", "embree_build_high", "embree_build_medium"))
        print("| %s | %s | %s | %s | %s | %s | %s | %s |" % (
            s, tris(rows), fms(kd), fms(hi), f2(kd / hi), fms(med),
            f2(kd / med) if med else "-", " / ".join(bpt.get(s, ("-", "-")))))
    print("\n#### Single rays: kd_single against each Embree API (speed ratio; "
          "Mrays/s of kd and of the strongest API)\n")
    apis = {"camera": ["rtcIntersect1", "rtcIntersect1M_coherent",
                       "rtcIntersect8_coherent", "rtcIntersect16_coherent"],
            "random": ["rtcIntersect1", "rtcIntersect1M", "rtcIntersect8",
                       "rtcIntersect16"],
            "ao_any": ["rtcOccluded1", "rtcOccluded1M", "rtcOccluded8", "rtcOccluded16"],
            "shadow": ["rtcOccluded1", "rtcOccluded1M_coherent", "rtcOccluded8_coherent",
                       "rtcOccluded16_coherent"]}
    for w, names in apis.items():
        print("%s:\n" % w)
        print("| scene | kd Mrays/s | best Embree Mrays/s (API) | kd / best | " +
              " | ".join("vs %s" % short(n) for n in names) + " |")
        print("|---|---|---|---|" + "---|" * len(names))
        for s, rows in core.items():
            api, t = best(rows, w)
            r = rows.get((w, "kd_single"))
            if not r:
                continue
            n = int(r["rays"])
            print("| %s | %.2f | %.2f (%s) | **%s** | %s |" % (
                s, float(r["mrays"]), n / (t * 1e3), short(api),
                f2(t / float(r["ms"])),
                " | ".join(f2(over(rows, w, "kd_single", "embree_" + a)) for a in names)))
        print()


def bundle_table(bun):
    print("| scene | camera b8 Mrays/s | ×single | ×I8c | ×best (API) | "
          "AO any ×single | ×O1 | ×O8 | ×best (API) | AO closest ×single | ×best (API) | "
          "random ×single | ×best (API) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for s, rows in bun.items():
        b = "kd_bundle8"
        cam = rows.get(("camera", b))
        if not cam:
            continue
        cells = [s, "%.1f" % float(cam["mrays"])]
        for w, extra in (("camera", ["rtcIntersect8_coherent"]),
                         ("ao_any", ["rtcOccluded1", "rtcOccluded8"]),
                         ("ao_closest", []), ("random", [])):
            cells.append(f2(over(rows, w, b, "kd_single")))
            cells += [f2(over(rows, w, b, "embree_" + a)) for a in extra]
            v, api = vs_best(rows, w, b)
            cells.append("%s (%s)" % (f2(v), short(api)))
        print("| " + " | ".join(cells) + " |")


def frustum_table(fru):
    print("| scene | camera | kd 4-frustum Mrays/s | ×1-frustum | ×kd per ray | "
          "×I1 | ×best (API) | Embree raygen share |")
    print("|---|---|---|---|---|---|---|---|")
    g = {"f4_f1": [], "f4_best": [], "f4_i1": [], "f1_best": [], "rays_best": []}
    for s, rows in fru.items():
        for w in sorted({w for w, _ in rows if w.startswith("frustum_cam")}):
            f4 = rows.get((w, "kd_frustum4"))
            v, api = vs_best(rows, w, "kd_frustum4")
            gen = [ms(rows, w, m) for (ww, m) in rows if ww == w and m.startswith("raygen")]
            _, tb = best(rows, w)
            share = "%.0f%%" % (100 * gen[0] / tb) if gen and tb else "-"
            a = over(rows, w, "kd_frustum4", "kd_frustum1")
            c = over(rows, w, "kd_frustum4", "embree_rtcIntersect1")
            print("| %s | %s | %.1f | %s | %s | %s | %s (%s) | %s |" % (
                s, w[len("frustum_"):], float(f4["mrays"]), f2(a),
                f2(over(rows, w, "kd_frustum4", "kd_rays")), f2(c), f2(v), short(api), share))
            g["f4_f1"].append(a)
            g["f4_best"].append(v)
            g["f4_i1"].append(c)
            g["f1_best"].append(vs_best(rows, w, "kd_frustum1")[0])
            g["rays_best"].append(vs_best(rows, w, "kd_rays")[0])
    print("\nGeometric means over %d cameras: 4-frustum / 1-frustum %s, 4-frustum / "
          "strongest Embree %s, 4-frustum / rtcIntersect1 %s, 1-frustum / strongest %s, "
          "kd per ray / strongest %s." % (len(g["f4_f1"]), f2(gmean(g["f4_f1"])),
                                          f2(gmean(g["f4_best"])), f2(gmean(g["f4_i1"])),
                                          f2(gmean(g["f1_best"])),
                                          f2(gmean(g["rays_best"]))))
    sweep = {}
    for s, rows in fru.items():
        for (w, m) in rows:
            if w.startswith("sweep_") and m == "kd_frustum4":
                tile = int(w.rsplit("tile", 1)[1])
                sweep.setdefault(tile, []).append(over(rows, w, "kd_frustum4", "kd_frustum1"))
    if sweep:
        print("Tile sweep, 4-frustum / 1-frustum at the same tile (geometric mean): " +
              ", ".join("%d: %s" % (t, f2(gmean(v))) for t, v in sorted(sweep.items())) +
              ".")


def cone_table(cone):
    views = OrderedDict()
    for s, rows in cone.items():
        for (w, m) in rows:
            if w.startswith("shadow_") and m == "kd_cone":
                _, light, spp = w.split("_")
                views.setdefault((s, light), []).append(int(spp[:-3]))
    spps = sorted({n for v in views.values() for n in v})
    print("kd_cone speed over the strongest Embree API at equal samples (API below "
          "each ratio; the Embree side's sample generation is part of its time):\n")
    print("| view | " + " | ".join("%d spp" % n for n in spps) + " |")
    print("|---|" + "---|" * len(spps))
    for (s, light), ns in views.items():
        rows = cone[s]
        cells = []
        for n in spps:
            w = "shadow_%s_%dspp" % (light, n)
            v, api = vs_best(rows, w, "kd_cone")
            cells.append("%s %s" % (f2(v), short(api)) if v else "-")
        print("| %s, %s light | %s |" % (s, light, " | ".join(cells)))


def targets(core, bun, fru, cone):
    print("\n### Numbers for README's target table\n")
    L = list(core.items())
    print("- build kd/HIGH (time): %s; kd/MEDIUM: %s" % (
        rng([ms(r, "build", "kd_build") / ms(r, "build", "embree_build_high") for _, r in L]),
        rng([ms(r, "build", "kd_build") / ms(r, "build", "embree_build_medium")
             for _, r in L if ms(r, "build", "embree_build_medium")])))
    for w, one in (("random", "embree_rtcIntersect1"), ("camera", "embree_rtcIntersect1"),
                   ("ao_any", "embree_rtcOccluded1"), ("shadow", "embree_rtcOccluded1")):
        print("- single %s: vs strongest %s (APIs: %s); vs %s %s" % (
            w, rng([vs_best(r, w, "kd_single")[0] for _, r in L]),
            ", ".join(sorted({short(best(r, w)[0]) for _, r in L})), one[7:],
            rng([over(r, w, "kd_single", one) for _, r in L])))
        big = [(s, vs_best(r, w, "kd_single")[0]) for s, r in L
               if s in ("haus", "engine", "engine3", "engine9")]
        print("    haus/engine/engine3/engine9: " + ", ".join("%s %s" % (s, f2(v)) for s, v in big))
    B = list(bun.items())
    for w in ("camera", "ao_any", "ao_closest", "random"):
        print("- bundle8 %s: ×single %s; ×best %s (APIs %s)" % (
            w, rng([over(r, w, "kd_bundle8", "kd_single") for _, r in B]),
            rng([vs_best(r, w, "kd_bundle8")[0] for _, r in B]),
            ", ".join(sorted({short(best(r, w)[0]) for _, r in B}))))
    # AUTO's width on an AVX-512 CPU (absent from runs on other CPUs)
    for w in ("camera", "ao_any", "ao_closest", "random", "shadow"):
        B16 = [(s, r) for s, r in B if (w, "kd_bundle16") in r]
        if B16:
            print("- bundle16 %s: ×single %s; ×bundle8 %s; ×best %s" % (
                w, rng([over(r, w, "kd_bundle16", "kd_single") for _, r in B16]),
                rng([over(r, w, "kd_bundle16", "kd_bundle8") for _, r in B16]),
                rng([vs_best(r, w, "kd_bundle16")[0] for _, r in B16])))
    print("- bundle8 camera ×I8c %s ×I1 %s; bundle4 camera ×single %s" % (
        rng([over(r, "camera", "kd_bundle8", "embree_rtcIntersect8_coherent") for _, r in B]),
        rng([over(r, "camera", "kd_bundle8", "embree_rtcIntersect1") for _, r in B]),
        rng([over(r, "camera", "kd_bundle4", "kd_single") for _, r in B])))
    print("- bundle8 ao_any ×O1 %s ×O8 %s; engine family ×single %s" % (
        rng([over(r, "ao_any", "kd_bundle8", "embree_rtcOccluded1") for _, r in B]),
        rng([over(r, "ao_any", "kd_bundle8", "embree_rtcOccluded8") for _, r in B]),
        rng([over(r, "ao_any", "kd_bundle8", "kd_single") for s, r in B
             if s.startswith("engine")])))
    for light in ("small", "large"):
        for lo, hi in ((1, 8), (16, 256)):
            vals = []
            for s, rows in cone.items():
                for (w, m) in rows:
                    if m == "kd_cone" and w.startswith("shadow_%s_" % light):
                        n = int(w.split("_")[2][:-3])
                        if lo <= n <= hi:
                            vals.append(vs_best(rows, w, "kd_cone")[0])
            print("- cone %s light %d-%d spp: ×best %s" % (light, lo, hi, rng(vals)))


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else "build/bench-results"
    core, bun, fru, cone = (load(os.path.join(out, n + ".csv"))
                            for n in ("core", "bundle", "frustum", "cone"))
    if core:
        core_tables(core, bytes_per_tri(out))
    if bun:
        print("#### Bundles (kd_bundle8, the daemon's AUTO on this CPU)\n")
        bundle_table(bun)
        print()
    if fru:
        print("#### Frusta\n")
        frustum_table(fru)
        print()
    if cone:
        print("#### Cone shadows\n")
        cone_table(cone)
    targets(core, bun, fru, cone)


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""plot_all.py OUTDIR — PNG plots of the CSV files bench/run-all writes.

core.png:    kd / Embree per scene (build time against the HQ build,
             camera, random and AO ray throughput);
bundle.png:  8-wide bundles against single-ray kd and Embree rtcIntersect1,
             per scene and ray kind;
frustum.png: primary-ray throughput per scene (mean of its cameras) for
             each method.
The cone plot (cone.png) is written by kdray_bench_cone itself. Standard
library only; needs gnuplot (Debian gnuplot-nox).
"""
import csv
import os
import subprocess
import sys
from collections import OrderedDict


def load(path):
    """{scene: {metric: value}} in file order."""
    out = OrderedDict()
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            out.setdefault(row["scene"], {})[row["metric"]] = float(row["value"])
    return out


def write_dat(path, scenes, columns):
    """One row per scene: name, then each column's value (or NaN)."""
    with open(path, "w") as f:
        f.write("scene " + " ".join(c for c, _ in columns) + "\n")
        for name, m in scenes.items():
            vals = [fn(m) for _, fn in columns]
            f.write(name + " " + " ".join("%.6g" % v if v is not None else "NaN"
                                          for v in vals) + "\n")


def mean(m, keys):
    vals = [m[k] for k in keys if k in m]
    return sum(vals) / len(vals) if vals else None


def bars(png, dat, title, ylabel, ncols, logscale=False, hline=None):
    series = ", ".join(
        "'%s' using %d:xtic(1) title columnhead" % (dat, c + 2) for c in range(ncols))
    script = "\n".join([
        "set terminal pngcairo size 1200,520 font ',10' noenhanced",
        "set output '%s'" % png,
        "set title '%s'" % title,
        "set ylabel '%s'" % ylabel,
        "set style data histograms",
        "set style histogram clustered gap 1",
        "set style fill solid 0.8 border -1",
        "set key top left",
        "set grid ytics",
        "set xtics rotate by -30",
        "set logscale y" if logscale else "set yrange [0:*]",
        ("set arrow from graph 0, first %g to graph 1, first %g nohead dt 2"
         % (hline, hline)) if hline else "",
        "plot " + series,
    ])
    subprocess.run(["gnuplot"], input=script.encode(), check=True)


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else "build/bench-results"
    made = []
    if os.path.exists(os.path.join(out, "core.csv")):
        s = load(os.path.join(out, "core.csv"))
        dat = os.path.join(out, "core.dat")
        cols = [("build_(Embree_HQ/kd)", lambda m: m["build_ms_embree_hq"] / m["build_ms_kd"]
                 if m.get("build_ms_kd") else None),
                ("camera", lambda m: m.get("camera_ratio")),
                ("random", lambda m: m.get("random_ratio")),
                ("AO_any", lambda m: m.get("ao_any_ratio"))]
        write_dat(dat, s, cols)
        bars(os.path.join(out, "core.png"), dat,
             "single-ray kd against Embree (above 1: kd faster)", "kd / Embree",
             len(cols), logscale=True, hline=1)
        made.append("core.png")
    if os.path.exists(os.path.join(out, "bundle.csv")):
        s = load(os.path.join(out, "bundle.csv"))
        dat = os.path.join(out, "bundle.dat")
        cols = []
        for kind in ("camera", "ao_any", "ao_closest", "random"):
            cols.append(("%s_/single" % kind,
                         lambda m, k=kind: m.get("%s_auto_over_single" % k)))
        cols.append(("camera_/Embree1", lambda m: m.get("camera_auto_over_embree1")))
        write_dat(dat, s, cols)
        bars(os.path.join(out, "bundle.png"), dat,
             "8-wide omni-directional bundles against single-ray kd and Embree rtcIntersect1",
             "speed-up", len(cols), hline=1)
        made.append("bundle.png")
    if os.path.exists(os.path.join(out, "frustum.csv")):
        s = load(os.path.join(out, "frustum.csv"))
        dat = os.path.join(out, "frustum.dat")
        methods = [("kd_per_ray", "rays"), ("kd_bundle4", "bundle4"),
                   ("kd_1-frustum", "frustum1"), ("kd_4-frustum", "frustum4"),
                   ("Embree_1", "embree1"), ("Embree_8", "embree8")]
        cols = [(label, lambda m, k=key: mean(m, ["cam%d_%s_mrays" % (c, k)
                                                  for c in range(8)]))
                for label, key in methods]
        write_dat(dat, s, cols)
        bars(os.path.join(out, "frustum.png"), dat,
             "1000x1000 primary rays, tile 8 (mean over the cameras of each scene)",
             "Mrays/s", len(cols))
        made.append("frustum.png")
    print("plot_all: wrote " + ", ".join(made) if made else "plot_all: no CSV found")


if __name__ == "__main__":
    main()

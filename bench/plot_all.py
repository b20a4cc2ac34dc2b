#!/usr/bin/env python3
"""plot_all.py OUTDIR — PNG plots of the summary CSVs bench/run-all writes
(scene,triangles,workload,method,rays,ms,mrays,nodes_per_ray,rival,vs_rival).

core.png:    per scene, kdray's speed over Embree's: the kd build over the
             high-quality BVH build, and single rays over the strongest
             Embree API for camera, random and AO any-hit rays;
bundle.png:  8-wide bundles (the daemon's AUTO here) over single-ray kd and
             over the strongest Embree API, per scene and ray kind;
frustum.png: primary-ray throughput per scene (mean over its cameras) of
             kd's per-pixel walk, 1- and 4-frustum, Embree rtcIntersect1 and
             the strongest Embree API of each camera.
The cone plot (cone_rmse.png) is written by kdray_bench_cone itself.
Standard library only; needs gnuplot (Debian gnuplot-nox).
"""
import csv
import os
import subprocess
import sys
from collections import OrderedDict


def load(path):
    """{scene: {(workload, method): row}} in file order."""
    out = OrderedDict()
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            out.setdefault(row["scene"], {})[(row["workload"], row["method"])] = row
    return out


def value(rows, workload, method, field):
    r = rows.get((workload, method))
    return float(r[field]) if r and r[field] else None


def write_dat(path, scenes, columns):
    """One row per scene: name, then each column's value (or NaN)."""
    with open(path, "w") as f:
        f.write("scene " + " ".join(c for c, _ in columns) + "\n")
        for name, rows in scenes.items():
            vals = [fn(rows) for _, fn in columns]
            f.write(name + " " + " ".join("%.6g" % v if v is not None else "NaN"
                                          for v in vals) + "\n")


def mean(vals):
    vals = [v for v in vals if v is not None]
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


def core_plot(out, s):
    def build(rows):
        kd = value(rows, "build", "kd_build", "ms")
        hi = value(rows, "build", "embree_build_high", "ms")
        return hi / kd if kd and hi else None

    cols = [("build_(Embree_HIGH/kd)", build)]
    for w in ("camera", "random", "ao_any"):
        cols.append((w, lambda rows, w=w: value(rows, w, "kd_single", "vs_rival")))
    dat = os.path.join(out, "core.dat")
    write_dat(dat, s, cols)
    bars(os.path.join(out, "core.png"), dat,
         "kd against the strongest Embree API per workload (above 1: kd faster)",
         "kd speed / Embree speed", len(cols), logscale=True, hline=1)


def bundle_plot(out, s):
    cols = []
    for w in ("camera", "ao_any", "ao_closest", "random"):
        cols.append(("%s_/single" % w, lambda rows, w=w: (
            value(rows, w, "kd_single", "ms") / value(rows, w, "kd_bundle8", "ms")
            if value(rows, w, "kd_bundle8", "ms") else None)))
    for w in ("camera", "ao_any", "ao_closest", "random"):
        cols.append(("%s_/Embree" % w,
                     lambda rows, w=w: value(rows, w, "kd_bundle8", "vs_rival")))
    dat = os.path.join(out, "bundle.dat")
    write_dat(dat, s, cols)
    bars(os.path.join(out, "bundle.png"), dat,
         "8-wide bundles over single-ray kd and over the strongest Embree API",
         "speed-up", len(cols), logscale=True, hline=1)


def frustum_plot(out, s):
    def cams(rows):
        return sorted({w for w, _ in rows if w.startswith("frustum_cam")})

    def rate(method):
        return lambda rows: mean([value(rows, w, method, "mrays") for w in cams(rows)])

    def best(rows):
        return mean([value(rows, w, rows[(w, "kd_rays")]["rival"], "mrays")
                     for w in cams(rows) if (w, "kd_rays") in rows])

    cols = [("kd_per_ray", rate("kd_rays")), ("kd_1-frustum", rate("kd_frustum1")),
            ("kd_4-frustum", rate("kd_frustum4")),
            ("Embree_rtcIntersect1", rate("embree_rtcIntersect1")),
            ("Embree_strongest_API", best)]
    dat = os.path.join(out, "frustum.dat")
    write_dat(dat, s, cols)
    bars(os.path.join(out, "frustum.png"), dat,
         "primary rays, camera in, image out (mean over the cameras of each scene)",
         "Mrays/s", len(cols))


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else "build/bench-results"
    made = []
    for name, fn in (("core", core_plot), ("bundle", bundle_plot),
                     ("frustum", frustum_plot)):
        path = os.path.join(out, name + ".csv")
        if os.path.exists(path):
            fn(out, load(path))
            made.append(name + ".png")
    print("plot_all: wrote " + ", ".join(made) if made else "plot_all: no CSV found")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""make_default_scene.py: writes scenes/default.glb, the scene kdrayd serves
when started without --scene (Python 3 standard library only, deterministic).

A 12 m x 12 m room, y up: a tessellated floor, two walls, a row of columns
(one cylinder mesh instanced by six nodes), a torus knot on a plinth, a
sphere, a table (a node hierarchy: top and four instanced legs under one
transformed parent) and a stack of rotated boxes. The objects overlap in
depth from most viewpoints, so primary rays, shadows and frusta all see
real occlusion. Node transforms mix TRS and `matrix`.

Usage: make_default_scene.py [OUT.glb]   (default: default.glb beside this script)
"""

import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from glbutil import Glb  # noqa: E402


def grid(nx, nz, sx, sz):
    """A plane in y=0 centred at the origin, nx*nz quads, normal +y."""
    pos = [((i / nx - 0.5) * sx, 0.0, (k / nz - 0.5) * sz)
           for k in range(nz + 1) for i in range(nx + 1)]
    idx = []
    for k in range(nz):
        for i in range(nx):
            a = k * (nx + 1) + i
            b, c, d = a + 1, a + nx + 1, a + nx + 2
            idx += [a, c, b, b, c, d]
    return pos, idx


def box(hx, hy, hz):
    """An axis-aligned box centred at the origin, outward winding."""
    pos = [(x * hx, y * hy, z * hz) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    idx = []
    for a, b, c, d in faces:
        idx += [a, b, c, a, c, d]
    return pos, idx


def uv_sphere(r, slices, stacks):
    pos = [(0.0, r, 0.0)]
    for j in range(1, stacks):
        phi = math.pi * j / stacks
        for i in range(slices):
            th = 2 * math.pi * i / slices
            pos.append((r * math.sin(phi) * math.cos(th), r * math.cos(phi),
                        r * math.sin(phi) * math.sin(th)))
    pos.append((0.0, -r, 0.0))
    south = len(pos) - 1
    idx = []
    for i in range(slices):
        idx += [0, 1 + (i + 1) % slices, 1 + i]
    for j in range(stacks - 2):
        row, nxt = 1 + j * slices, 1 + (j + 1) * slices
        for i in range(slices):
            i1 = (i + 1) % slices
            idx += [row + i, row + i1, nxt + i, row + i1, nxt + i1, nxt + i]
    last = 1 + (stacks - 2) * slices
    for i in range(slices):
        idx += [south, last + i, last + (i + 1) % slices]
    return pos, idx


def cylinder(r, h, sides):
    """Closed cylinder from y=0 to y=h."""
    pos = []
    for y in (0.0, h):
        for i in range(sides):
            th = 2 * math.pi * i / sides
            pos.append((r * math.cos(th), y, r * math.sin(th)))
    pos += [(0.0, 0.0, 0.0), (0.0, h, 0.0)]
    bot, top = 2 * sides, 2 * sides + 1
    idx = []
    for i in range(sides):
        i1 = (i + 1) % sides
        idx += [i, sides + i, i1, i1, sides + i, sides + i1]
        idx += [bot, i, i1, top, sides + i1, sides + i]
    return pos, idx


def torus_knot(p, q, big_r, tube, segs, sides):
    """A (p, q) torus knot swept by a circle of radius tube."""
    def curve(t):
        r = big_r * (2 + math.cos(q * t)) / 3
        return (r * math.cos(p * t), big_r * math.sin(q * t) / 3, r * math.sin(p * t))

    pos = []
    for s in range(segs):
        t = 2 * math.pi * s / segs
        c, c2 = curve(t), curve(t + 1e-3)
        tan = [c2[k] - c[k] for k in range(3)]
        n = [c[k] + c2[k] for k in range(3)]  # roughly away from the centre
        b = [tan[1] * n[2] - tan[2] * n[1], tan[2] * n[0] - tan[0] * n[2],
             tan[0] * n[1] - tan[1] * n[0]]
        n = [b[1] * tan[2] - b[2] * tan[1], b[2] * tan[0] - b[0] * tan[2],
             b[0] * tan[1] - b[1] * tan[0]]
        ln, lb = math.sqrt(sum(v * v for v in n)), math.sqrt(sum(v * v for v in b))
        for i in range(sides):
            a = 2 * math.pi * i / sides
            ca, sa = math.cos(a) * tube, math.sin(a) * tube
            pos.append(tuple(c[k] + ca * n[k] / ln + sa * b[k] / lb for k in range(3)))
    idx = []
    for s in range(segs):
        s1 = (s + 1) % segs
        for i in range(sides):
            i1 = (i + 1) % sides
            a, b, c, d = s * sides + i, s * sides + i1, s1 * sides + i, s1 * sides + i1
            idx += [a, c, b, b, c, d]
    return pos, idx


def quat_y(deg):
    h = math.radians(deg) / 2
    return [0.0, math.sin(h), 0.0, math.cos(h)]


def build(path):
    g = Glb("kdray scenes/make_default_scene.py")
    floor = g.add_mesh("floor", *grid(24, 24, 12.0, 12.0))
    wall = g.add_mesh("wall", *grid(12, 6, 12.0, 6.0))
    column = g.add_mesh("column", *cylinder(0.25, 3.5, 20))
    knot = g.add_mesh("torus_knot", *torus_knot(2, 3, 1.1, 0.22, 160, 12))
    sphere = g.add_mesh("sphere", *uv_sphere(0.75, 32, 18))  # radius exact in float32
    cube = g.add_mesh("box", *box(0.5, 0.5, 0.5))
    top = g.add_mesh("table_top", *box(1.2, 0.05, 0.7))
    leg = g.add_mesh("table_leg", *box(0.05, 0.45, 0.05))

    g.add_node("floor", floor, root=True)
    # Walls: the grid stands up, one at the back, one on the left. Exact
    # matrices (not a 90-degree quaternion, whose rounding would lift the
    # wall's corners 1e-8 off the floor plane y = 0).
    g.add_node("back_wall", wall, root=True,
               matrix=[1, 0, 0, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 3, -6, 1])
    g.add_node("left_wall", wall, root=True,
               matrix=[0, 0, 1, 0, 1, 0, 0, 0, 0, 1, 0, 0, -6, 3, 0, 1])
    for i in range(6):
        g.add_node("column_%d" % i, column, root=True, translation=[-4.5 + 1.8 * i, 0, -4.2])
    plinth = g.add_node("plinth", cube, scale=[1.6, 0.8, 1.6], translation=[0, 0.4, 0])
    knot_node = g.add_node("knot", knot, translation=[0, 2.0, 0], rotation=quat_y(20))
    g.add_node("knot_group", None, [plinth, knot_node], root=True, translation=[-1.5, 0, -1.5])
    g.add_node("sphere", sphere, root=True, translation=[2.4, 0.75, 0.6])
    legs = [g.add_node("leg_%d" % i, leg, translation=[sx * 1.1, 0.45, sz * 0.6])
            for i, (sx, sz) in enumerate([(-1, -1), (1, -1), (-1, 1), (1, 1)])]
    table_top = g.add_node("top", top, translation=[0, 0.95, 0])
    cup = g.add_node("cube_on_table", cube, scale=[0.3, 0.3, 0.3], translation=[0.4, 1.15, 0.1],
                     rotation=quat_y(35))
    g.add_node("table", None, [table_top] + legs + [cup], root=True,
               translation=[2.0, 0, 3.2], rotation=quat_y(-15))
    base = 0.0
    for i in range(4):
        size = 1.0 - 0.15 * i
        g.add_node("stack_%d" % i, cube, root=True, translation=[-3.6, base + size / 2, 2.6],
                   rotation=quat_y(17 * i), scale=[size] * 3)
        base += size
    g.write(path)


if __name__ == "__main__":
    here = os.path.dirname(os.path.abspath(__file__))
    build(sys.argv[1] if len(sys.argv) > 1 else os.path.join(here, "default.glb"))

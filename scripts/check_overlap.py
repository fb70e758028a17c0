#!/usr/bin/python3
"""Overlap of deformable disks in a compact run's levels.h5, measured independently of the solver.

The contact law of deformable pairs is node-to-segment, one pass: the boundary
nodes of the slave disk (the higher particle number) cannot enter the master
disk, but nothing keeps the master's nodes out of the slave. This script checks
both ways from the written meshes alone: every boundary node of every
deformable disk against the boundary curve of every other deformable disk
(its quadratic finite-element edges, or with --curve spline the Catmull-Rom
curve through its boundary nodes that the contact law uses; sampled finely
enough to be exact to a few 1e-6 <d>). For each level it prints the number of boundary
nodes inside another disk and the deepest one (distance to that disk's
boundary, in units of <d> = 1), separately for the nodes that are the slave
of their pair (the solver keeps them out: a check of this script) and those
that are the master, and the packing fraction, which can exceed 1 only
through such overlaps.

Usage:
  /usr/bin/python3 scripts/check_overlap.py out/campaign/k1_mu0.2/levels.h5 [--csv out.csv]
"""
import argparse
import csv
from collections import Counter

import h5py
import numpy as np
from matplotlib.path import Path


def catmull_rom(nodes, samples):
    """compact's contact curve: the uniform Catmull-Rom spline through the boundary nodes (curve_kinematics.cpp)."""
    t = np.linspace(0.0, 1.0, samples, endpoint=False)[:, None]
    n0, n1 = -t / 2 + t**2 - t**3 / 2, 1 - 5 * t**2 / 2 + 3 * t**3 / 2
    n2, n3 = t / 2 + 2 * t**2 - 3 * t**3 / 2, -t**2 / 2 + t**3 / 2
    p0, p1, p2, p3 = (np.roll(nodes, -k, axis=0) for k in (-1, 0, 1, 2))
    return np.vstack([n0 * p0[i] + n1 * p1[i] + n2 * p2[i] + n3 * p3[i] for i in range(len(nodes))])


def boundary_curve(coords, cells, samples=16, spline=False):
    """Boundary nodes (vertices and edge mid-nodes, in order) and the sampled boundary curve:
    the finite elements' quadratic edges, or (spline) the contact law's Catmull-Rom curve."""
    count, mid = Counter(), {}
    edges = []
    for c in cells:
        for a, b, m in ((c[0], c[1], c[3]), (c[1], c[2], c[4]), (c[2], c[0], c[5])):
            key = (min(a, b), max(a, b))
            count[key] += 1
            mid[key] = m
            edges.append((a, b, m))
    following = {a: (b, m) for a, b, m in edges if count[(min(a, b), max(a, b))] == 1}
    start = next(iter(following))
    nodes, curve, v = [], [], start
    t = np.linspace(0.0, 1.0, samples, endpoint=False)[:, None]
    while True:
        w, m = following[v]
        nodes += [v, m]
        if not spline:  # quadratic edge through v (t = 0), m (t = 1/2), w (t = 1)
            curve.append(coords[v] * (1 - t) * (1 - 2 * t) + coords[m] * 4 * t * (1 - t) + coords[w] * t * (2 * t - 1))
        v = w
        if v == start:
            break
    if spline:
        return coords[nodes], catmull_rom(coords[nodes], samples // 2)
    return coords[nodes], np.vstack(curve)


def distance_to_polyline(p, poly):
    a, b = poly, np.roll(poly, -1, axis=0)
    d = b - a
    t = np.clip(((p - a) * d).sum(1) / (d * d).sum(1), 0.0, 1.0)
    return np.min(np.hypot(*(p - (a + t[:, None] * d)).T))


def check_level(level, tol, spline):
    """Boundary nodes deeper than tol inside another disk, split by who is the master of the pair
    (compact's rule: the lower particle number, i.e. the lower body number among deformable disks)."""
    names = sorted((k for k in level if k.startswith("body_")), key=lambda k: int(k.split("_")[1]))
    disks = [boundary_curve(level[k]["coordinates"][()], level[k]["cells"][()], spline=spline) for k in names]
    centre = [c.mean(axis=0) for _, c in disks]
    radius = [np.max(np.hypot(*(c - c.mean(axis=0)).T)) for _, c in disks]
    count = {"slave": 0, "master": 0}
    deepest = {"slave": 0.0, "master": 0.0}
    for i, (nodes_i, _) in enumerate(disks):
        for j, (_, curve_j) in enumerate(disks):
            if i == j or np.hypot(*(centre[i] - centre[j])) > radius[i] + radius[j]:
                continue
            role = "slave" if i > j else "master"  # the role of disk i in the pair (i, j)
            for p in nodes_i[Path(curve_j).contains_points(nodes_i)]:
                depth = distance_to_polyline(p, curve_j)
                if depth > tol:
                    count[role] += 1
                    deepest[role] = max(deepest[role], depth)
    return len(disks), count, deepest


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("levels_h5")
    ap.add_argument("--csv", help="also write the table here")
    ap.add_argument("--curve", choices=["quadratic", "spline"], default="quadratic",
                    help="the other disk's boundary: its quadratic finite-element edges, or the contact law's spline")
    ap.add_argument("--tol", type=float, default=1e-5, help="count nodes deeper than this (<d>); the sampled curve is exact to ~4e-6")
    a = ap.parse_args()
    rows = []
    with h5py.File(a.levels_h5, "r") as f:
        for name in sorted(f.keys()):
            g = f[name]
            n, count, deepest = check_level(g, a.tol, a.curve == "spline")
            rows.append([g.attrs["P_over_E"], g.attrs["packing_fraction"], n, count["slave"], deepest["slave"],
                         count["master"], deepest["master"]])
    print(f"nodes deeper than {a.tol:g} <d> inside another deformable disk ({a.curve} boundary), as slave / as master of the pair")
    print(f"{'P/E':>8} {'phi':>8} {'disks':>5} {'slave nodes':>11} {'deepest':>9} {'master nodes':>12} {'deepest':>9}")
    for r in rows:
        print(f"{r[0]:8.4g} {r[1]:8.5f} {r[2]:5d} {r[3]:11d} {r[4]:9.2e} {r[5]:12d} {r[6]:9.2e}")
    if a.csv:
        with open(a.csv, "w", newline="") as f:
            f.write(f"# scripts/check_overlap.py {a.levels_h5} --curve {a.curve} --tol {a.tol:g}\n")
            w = csv.writer(f)
            w.writerow(["P_over_E", "phi", "deformable_disks", "slave_nodes_inside", "slave_deepest_over_d",
                        "master_nodes_inside", "master_deepest_over_d"])
            w.writerows(rows)


if __name__ == "__main__":
    main()

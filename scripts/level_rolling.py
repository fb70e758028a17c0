#!/usr/bin/env python3
"""How far the deformable disks roll between levels, beside the Newton
iterations each level took.

For every pair of successive levels of a compact run (its levels.h5 and
curve.csv) and every deformable disk, the rotation of its nodes about their
centroid (least squares: theta = sum r x dr / sum |r|^2) times the disk's
radius, in units of the boundary node spacing h = 2 pi R / (boundary nodes).
A Newton step that rolls a deformable disk is accurate over about a
twentieth of h (docs/level-solver-measurements.md, "Measured: why a level takes tens of
Newton iterations"), so a level whose disks roll by about h takes tens of
iterations whatever the globalization.

Usage:
  /usr/bin/python3 scripts/level_rolling.py OUT.csv OUT.png [LABEL=]RUN_DIR ...
Prints one line per level and run; writes the table to OUT.csv and the
iterations against the largest roll to OUT.png (runs named by LABEL, or by
their directory).
"""
import csv
import os
import sys

import h5py
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from provenance import git_commit, machine  # noqa: E402


def boundary_nodes(cells):
    """Nodes on the boundary of a mesh of 6-node triangles (corner 0-2, mid-edge 3-5)."""
    edges = {}
    for c in cells:
        for a, b, m in ((c[0], c[1], c[3]), (c[1], c[2], c[4]), (c[2], c[0], c[5])):
            key = (min(a, b), max(a, b))
            edges.setdefault(key, []).append(m)
    nodes = set()
    for (a, b), mids in edges.items():
        if len(mids) == 1:
            nodes.update((a, b, mids[0]))
    return nodes


def rolls(run):
    with h5py.File(os.path.join(run, "levels.h5"), "r") as f:
        levels = sorted(k for k in f.keys() if k.startswith("level_"))
        out = []
        for a, b in zip(levels[:-1], levels[1:]):
            per_body = []
            for body in f[a].keys():
                if not body.startswith("body_") or "coordinates" not in f[a][body]:
                    continue
                x0 = f[a][body]["coordinates"][:]
                x1 = f[b][body]["coordinates"][:]
                n_boundary = len(boundary_nodes(f[a][body]["cells"][:]))
                c0, c1 = x0.mean(0), x1.mean(0)
                r = x0 - c0
                dr = (x1 - c1) - r
                theta = np.sum(r[:, 0] * dr[:, 1] - r[:, 1] * dr[:, 0]) / np.sum(r * r)
                radius = np.sqrt(np.max(np.sum(r * r, 1)))
                h = 2.0 * np.pi * radius / n_boundary
                per_body.append(abs(theta) * radius / h)
            per_body = np.array(per_body) if per_body else np.zeros(1)
            out.append((np.max(per_body), np.median(per_body)))
    return out


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    out_csv, out_png = sys.argv[1], sys.argv[2]
    runs, labels = [], {}
    for arg in sys.argv[3:]:
        label, _, run = arg.rpartition("=")
        runs.append(run)
        labels[run] = label or os.path.basename(os.path.normpath(run))
    rows = []
    for run in runs:
        with open(os.path.join(run, "curve.csv")) as f:
            curve = list(csv.DictReader(f))
        for (largest, median), level in zip(rolls(run), curve[1:]):
            rows.append({"run": labels[run], "P_over_E": level["P_over_E"], "newton_its": int(level["newton_its"]),
                         "largest_roll_over_h": largest, "median_roll_over_h": median})
            print(f"{labels[run]}  P/E {level['P_over_E']:>8}  {int(level['newton_its']):5d} Newton its  "
                  f"largest roll {largest:5.2f} h  median {median:5.3f} h")
    with open(out_csv, "w", newline="") as f:
        f.write(f"# analysed at commit {git_commit()}, machine {machine()}\n")
        f.write("# command: scripts/level_rolling.py " + " ".join(sys.argv[1:]) + "\n")
        w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
        w.writeheader()
        w.writerows(rows)
    fig, ax = plt.subplots(figsize=(5.5, 4))
    for run in runs:
        pts = [(r["largest_roll_over_h"], r["newton_its"]) for r in rows if r["run"] == labels[run]]
        ax.plot(*zip(*pts), "o", label=labels[run])
    ax.set_xlabel("largest roll of a deformable disk since the last level / node spacing h")
    ax.set_ylabel("Newton iterations of the level")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out_png, dpi=120)
    print(f"wrote {out_csv} and {out_png}")


if __name__ == "__main__":
    main()

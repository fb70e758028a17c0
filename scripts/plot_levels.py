#!/usr/bin/env python3
"""Draw the deformed disks of chosen levels of a deformix levels.h5 file.

Like the paper's Fig. Snap-shots: rigid disks grey, each cell of a deformable
disk drawn as its curved (for 6-node cells) outline and coloured by its
volumetric strain J - 1; the walls are drawn as the box. With --forces the
contact network is drawn over it (the force-chain figure of granular
physics): a red segment between the centres of every pair of particles in
contact (to the wall for wall contacts), its width proportional to the normal
force (the mean force drawn 1.5 points wide), from the level's /contacts
datasets; the deformable disks are then drawn pale.

usage: plot_levels.py levels.h5 out.png [--forces] [level ...]   (default: last level)
"""
import sys

import h5py
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection, PolyCollection


def cell_outline(x, cell):
    """Polygon through the cell boundary; quadratic edges sampled at 4 points."""
    if len(cell) == 3:
        return x[cell]
    v, m = cell[:3], cell[3:]
    pts = []
    for k in range(3):
        a, b, c = x[v[k]], x[v[(k + 1) % 3]], x[m[k]]
        for t in np.linspace(0.0, 1.0, 4, endpoint=False):
            # quadratic Lagrange interpolation along the edge a - c - b
            pts.append((1 - t) * (1 - 2 * t) * a + 4 * t * (1 - t) * c + t * (2 * t - 1) * b)
    return np.array(pts)


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    forces = "--forces" in sys.argv[3:]
    h = h5py.File(sys.argv[1], "r")
    names = sorted(k for k in h.keys() if k.startswith("level_"))
    chosen = [names[int(i)] for i in sys.argv[3:] if i != "--forces"] or [names[-1]]
    fig, axes = plt.subplots(1, len(chosen), figsize=(4 * len(chosen), 4), squeeze=False)
    for ax, name in zip(axes[0], chosen):
        g = h[name]
        polys, strain = [], []
        for body in (k for k in g.keys() if k.startswith("body_")):
            x = g[body]["coordinates"][:]
            cells = g[body]["cells"][:]
            polys += [cell_outline(x, c) for c in cells]
            strain += list(g[body]["cell_area_ratio"][:] - 1.0)
        pc = PolyCollection(polys, array=np.array(strain), cmap="viridis", edgecolors="k", linewidths=0.2,
                            alpha=0.35 if forces else 1.0)
        ax.add_collection(pc)
        if "rigid" in g:
            for x, y, r, _ in g["rigid"][:]:
                ax.add_patch(plt.Circle((x, y), r, facecolor="0.85" if forces else "0.6", edgecolor="k", linewidth=0.3))
        if forces and "contacts" in g:
            ends = g["contacts/points"][:].reshape(-1, 2, 2)
            fn = g["contacts/normal_force"][:]
            widths = 1.5 * fn / fn.mean()
            ax.add_collection(LineCollection(ends, linewidths=widths, colors="r", capstyle="round", zorder=3))
        w = g["walls"][:]
        ax.plot([w[0], w[1], w[1], w[0], w[0]], [w[2], w[2], w[3], w[3], w[2]], "k-", lw=1.5)
        ax.set_aspect("equal")
        ax.set_xlim(w[0] - 0.05, w[1] + 0.05)
        ax.set_ylim(w[2] - 0.05, w[3] + 0.05)
        ax.set_title("P/E = %g, phi = %.4f%s" % (g.attrs["P_over_E"], g.attrs["packing_fraction"],
                                                   ", force chains" if forces else ""))
        if strain and not forces:
            fig.colorbar(pc, ax=ax, shrink=0.7, label="J - 1")
    fig.tight_layout()
    fig.savefig(sys.argv[2], dpi=120)


if __name__ == "__main__":
    main()

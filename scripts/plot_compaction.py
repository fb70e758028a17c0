#!/usr/bin/env python3
"""Compaction plot of one or more deformix `compact` runs.

Four panels from each curve.csv: phi against P/E, Z (without rattlers)
against phi, the contact-stress check P_sigma / P against P/E (it must be 1 to
solver tolerance) and the Newton iterations per level.

usage: plot_compaction.py out.png run1/curve.csv [run2/curve.csv ...]
       (the legend uses each csv's directory name)
"""
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np


def read(path):
    data = np.genfromtxt(path, delimiter=",", names=True)
    return np.atleast_1d(data)


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    fig, ax = plt.subplots(2, 2, figsize=(10, 8))
    for path in sys.argv[2:]:
        d = read(path)
        label = os.path.basename(os.path.dirname(os.path.abspath(path)))
        P = d["P_over_E"]
        ax[0, 0].semilogx(P, d["phi"], "o-", ms=3, label=label)
        ax[0, 1].plot(d["phi"], d["Z_no_rattlers"], "o-", ms=3, label=label)
        ax[1, 0].semilogx(P, d["P_sigma_over_E"] / P, "o-", ms=3, label=label)
        ax[1, 1].loglog(P, np.maximum(d["newton_its"], 1), "o-", ms=3, label=label)
    ax[0, 0].set(xlabel="P / E", ylabel="packing fraction phi")
    ax[0, 1].set(xlabel="phi", ylabel="Z (without rattlers)")
    ax[1, 0].set(xlabel="P / E", ylabel="P_sigma / P (contact stress / imposed)")
    ax[1, 1].set(xlabel="P / E", ylabel="Newton iterations per level")
    for a in ax.flat:
        a.grid(True, which="both", alpha=0.3)
    ax[0, 0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(sys.argv[1], dpi=120)
    print("wrote", sys.argv[1])


if __name__ == "__main__":
    main()

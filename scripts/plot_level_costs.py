#!/usr/bin/env python3
"""Newton iterations and seconds per level of one or more curve.csv files.

Each file is a compact curve.csv, optionally with '#' comment lines first
(the benchmark files of benchmarks/ record machine, binary and command
there). Every file is drawn as its own series, labelled by the file name,
so the levels of a curve measured in pieces (restarts with other binaries)
show which binary solved which level. Prints the rows it draws and the
totals.

usage: plot_level_costs.py out.png file.csv [file.csv ...]
"""
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt


def read_levels(path):
    with open(path) as f:
        rows = [line for line in f if not line.startswith("#")]
    levels = list(csv.DictReader(rows))
    if not levels or "newton_its" not in levels[0]:
        sys.exit(f"{path}: not a curve.csv (no newton_its column)")
    return [(float(r["P_over_E"]), int(float(r["newton_its"])), float(r["seconds"])) for r in levels]


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    out, paths = sys.argv[1], sys.argv[2:]
    fig, (ax_its, ax_s) = plt.subplots(1, 2, figsize=(11, 4.2))
    total_its = total_s = 0
    seen = set()
    for path in paths:
        levels = [lv for lv in read_levels(path) if lv[0] not in seen]  # a level drawn once, from its first file
        seen.update(lv[0] for lv in levels)
        if not levels:
            continue
        p, its, s = zip(*levels)
        label = os.path.splitext(os.path.basename(path))[0]
        ax_its.plot(p, its, "o-", label=label)
        ax_s.plot(p, s, "o-", label=label)
        for row in levels:
            print(f"{label:28s} P/E {row[0]:<8g} {row[1]:6d} its {row[2]:9.1f} s")
        total_its += sum(its)
        total_s += sum(s)
    print(f"{len(seen)} levels, {total_its} Newton iterations, {total_s / 60:.1f} minutes")
    for ax, name in ((ax_its, "Newton iterations"), (ax_s, "seconds")):
        ax.set_xscale("log")
        ax.set_xlabel("P/E")
        ax.set_ylabel(name + " per level")
        ax.grid(True, which="both", alpha=0.3)
    ax_its.legend(fontsize=8)
    fig.suptitle(f"{len(seen)} levels, {total_its} Newton iterations, {total_s / 60:.0f} minutes")
    fig.tight_layout()
    fig.savefig(out, dpi=120)


if __name__ == "__main__":
    main()

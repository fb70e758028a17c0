#!/usr/bin/env python3
"""When does phi settle within a level? From compact runs with -level_monitor.

For every level of a run without friction (-level_solver auto solves them
by newton iterations only), the packing fraction of every
iterate is read from the -level_monitor lines of the run's log and compared
with the level's final phi (curve.csv): the first iterate from which phi stays
within 1e-4 (the paper's criterion) and within 1e-5 of its final value,
against the level's Newton iterations. A level whose phi settles only in its
last iterations spends them on moving the packing, not on polishing forces.

Usage:
  level_phi.py OUT.csv OUT.png LABEL=LOG:RUN_DIR [LABEL=LOG:RUN_DIR ...]
LOG is the saved standard output of
  build/bin/compact ... -level_monitor -output_dir RUN_DIR
"""
import csv
import re
import sys

NEWTON = re.compile(r"^\s+newton\s+(\d+)\s+phi\s+([0-9.eE+-]+)\s")
TABLE = re.compile(r"^\s+([0-9.eE+-]+)\s+0\.\d+\s+\d+\.\d+\s+\d+\.\d+\s+\d+\.\d+")


def levels_of(log):
    """Per level row of the table: the phi of each newton iterate before it."""
    out, current, last_it = [], [], None
    with open(log) as f:
        for line in f:
            m = NEWTON.match(line)
            if m:
                it = int(m.group(1))
                if it != last_it:  # rejected trials repeat the iterate's line
                    current.append(float(m.group(2)))
                    last_it = it
                continue
            if TABLE.match(line) and "unknowns" not in line:
                out.append(current)
                current, last_it = [], None
    return out


def settled_from(phis, final, tol):
    k = len(phis)
    while k > 0 and abs(phis[k - 1] - final) <= tol * final:
        k -= 1
    return k + 1  # 1-based iteration from which every iterate is within tol (len + 1: only the final state)


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    out_csv, out_png = sys.argv[1], sys.argv[2]
    rows = []
    for arg in sys.argv[3:]:
        label, spec = arg.split("=", 1)
        log, run_dir = spec.split(":", 1)
        with open(f"{run_dir}/curve.csv") as f:
            curve = list(csv.DictReader(f))
        if not re.search(r"friction = 0\.?,", open(log).read()):
            sys.exit(f"{log}: a run with friction (its anchored iterations are not in the monitor): use -friction 0")
        levels = levels_of(log)
        if len(levels) != len(curve):
            sys.exit(f"{log}: {len(levels)} levels in the log, {len(curve)} in {run_dir}/curve.csv")
        for phis, c in zip(levels, curve):
            if not phis:
                sys.exit(f"{log}: no -level_monitor lines for P/E {c['P_over_E']}")
            its = int(c["newton_its"])
            phis = phis[-its:]  # the level's own iterations (a settling before the first level is left out)
            final = float(c["phi"])
            rows.append({"run": label, "P_over_E": c["P_over_E"], "newton_its": int(c["newton_its"]),
                         "monitored_its": len(phis), "settled_1e-4_from": settled_from(phis, final, 1e-4),
                         "settled_1e-5_from": settled_from(phis, final, 1e-5), "phi": final})
    with open(out_csv, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print(f"{'run':>16} {'P/E':>7} {'its':>5} {'phi within 1e-4 from':>21} {'1e-5 from':>10}")
    for r in rows:
        print(f"{r['run']:>16} {r['P_over_E']:>7} {r['newton_its']:>5} {r['settled_1e-4_from']:>21} {r['settled_1e-5_from']:>10}")

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(5.5, 4.5))
    for label in dict.fromkeys(r["run"] for r in rows):
        sel = [r for r in rows if r["run"] == label]
        ax.plot([r["monitored_its"] for r in sel], [r["settled_1e-4_from"] for r in sel], "o", label=label)
    top = max(r["monitored_its"] for r in rows) * 1.05
    ax.plot([0, top], [0, top], "k:", lw=1, label="settled only at the end")
    ax.set_xlabel("Newton iterations of the level")
    ax.set_ylabel("iteration from which phi stays within 1e-4")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out_png, dpi=120)
    print(f"wrote {out_csv}, {out_png}")


if __name__ == "__main__":
    main()

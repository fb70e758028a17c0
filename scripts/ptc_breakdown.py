#!/usr/bin/env python3
"""Where the Newton iterations of each level go, from a compact run's output
with -ptc_monitor (for instance log.txt of a bench_solver.py run with
--extra "-ptc_monitor").

Per level (the rows of compact's table):
  its        Newton iterations of the level (the table's newton column)
  before     iterations not in anchored's pseudo-time steps: hybrid's newton
             attempt (and, on the first level, the frictionless settling)
  anchored   iterations in anchored's pseudo-time steps (failed ones included)
  failed     failed inner solves, and the iterations in them
  settled    iterations after the first pseudo-time step at which |F|_inf <=
             TOL P <d> and phi changed by less than TOL (the force and phi
             parts of the level criterion; what is left then is the per-body
             balance, the contact rows and the contact states)
  end_game   iterations after the step that began the end game (the
             "end game" line of -ptc_monitor; empty where it did not begin)
  jumps      pseudo-time steps whose |F|_inf exceeds JUMP times the larger of
             the step before's and P <d> (a step that unbalanced the packing,
             which later steps have to bring back)

usage: ptc_breakdown.py LOG [--tol 1e-4] [--jump 10] [--csv OUT.csv]
"""
import argparse
import csv
import re

ROW = re.compile(r"^ +(\d[\d.e+-]*) +(0\.\d+) +\S+ +\S+ +\S+ +\S+ +\S+ +(\d+) +\d+ +\S+\s*$")
STEP = re.compile(r"^  ptc +\d+  \|R\| .*\|F\|_inf (\S+)  phi (\S+)  move \S+  its (\d+)")
FAILED = re.compile(r"^  ptc +\d+  inner solve failed \(\S+ after (\d+) its")
END_GAME = re.compile(r"^  ptc +\d+  end game:")


def breakdown(lines, tol, jump=10.0):
    levels, steps, end_game_at = [], [], None
    for line in lines:
        m = ROW.match(line)
        if m:
            P, its = float(m[1]), int(m[3])
            anchored = sum(s[1] for s in steps)
            failed = [s for s in steps if s[0] == "failed"]
            done, phi_last, settled, force_last, jumps = 0, None, None, None, 0
            for kind, n, force, phi in steps:
                done += n
                if kind != "step":
                    continue
                if settled is None and phi_last is not None and force <= tol * P and abs(phi - phi_last) <= tol * phi:
                    settled = anchored - done
                if force_last is not None and force > jump * max(force_last, P):
                    jumps += 1
                phi_last, force_last = phi, force
            levels.append({"P_over_E": P, "its": its, "before": its - anchored, "anchored": anchored,
                           "failed": len(failed), "failed_its": sum(s[1] for s in failed),
                           "settled": "" if settled is None else settled,
                           "end_game": "" if end_game_at is None else anchored - end_game_at,
                           "jumps": jumps})
            steps, end_game_at = [], None
            continue
        m = STEP.match(line)
        if m:
            steps.append(("step", int(m[3]), float(m[1]), float(m[2])))
            continue
        m = FAILED.match(line)
        if m:
            steps.append(("failed", int(m[1]), 0.0, 0.0))
            continue
        if END_GAME.match(line) and end_game_at is None:
            end_game_at = sum(s[1] for s in steps)
    return levels


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("log")
    ap.add_argument("--tol", type=float, default=1e-4, help="the level criterion's -level_force_rtol and -level_phi_rtol")
    ap.add_argument("--jump", type=float, default=10.0, help="the factor of the jumps column")
    ap.add_argument("--csv", help="also write the table as CSV")
    a = ap.parse_args()
    with open(a.log) as f:
        # the rows of compact's table come after its header line
        lines = f.read().split(" P/E      phi", 1)[-1].splitlines()
    levels = breakdown(lines, a.tol, a.jump)
    keys = ["P_over_E", "its", "before", "anchored", "failed", "failed_its", "settled", "end_game", "jumps"]
    print("\t".join(keys))
    for lv in levels:
        print("\t".join(f"{lv[k]:g}" if isinstance(lv[k], float) else str(lv[k]) for k in keys))
    total = {k: sum(lv[k] for lv in levels if lv[k] != "") for k in keys[1:]}
    print("all\t" + "\t".join(str(total[k]) for k in keys[1:]))
    if a.csv:
        with open(a.csv, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=keys)
            w.writeheader()
            w.writerows(levels)


if __name__ == "__main__":
    main()

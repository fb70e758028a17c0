#!/usr/bin/python3
"""Skip-work and cost benchmark of the mixture driver.

For every (N_p, kappa, friction) of the grid, runs build/bin/compact on a few
pressure levels and records per level: Newton iterations, pseudo-time steps,
symbolic factorizations (new sparsity patterns), seconds, and the size of the
unknown layout (rigid / deformable / tangential unknowns, contact candidates,
Jacobian nonzeros), i.e. what the scene needs and nothing more:
  - no tangential unknowns without friction,
  - no finite-element unknowns at kappa = 0, no rigid unknowns at kappa = 1,
  - candidates only within the contact margin (linear in N_p),
  - a symbolic factorization only when the candidate set changes.
Runs that fail or exceed --timeout are recorded as such (status column).
Runs are sequential so that the timings mean something.

Outputs: benchmarks/mixture_cost.csv ('#' header lines: machine, commit,
options) and benchmarks/mixture_cost.png.

Usage:
  /usr/bin/python3 scripts/bench_mixture.py --sizes 20 64 --pressures 1e-4,1e-3
  /usr/bin/python3 scripts/bench_mixture.py --sizes 100 400 1500 --timeout 3600   # the issue's sizes
"""
import argparse
import csv
import os
import subprocess
import sys
import time

import numpy as np

from provenance import git_commit, machine

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[20, 64])
    ap.add_argument("--kappas", type=float, nargs="+", default=[0.0, 0.5, 1.0])
    ap.add_argument("--frictions", type=float, nargs="+", default=[0.0, 0.2])
    ap.add_argument("--pressures", default="1e-4,1e-3")
    ap.add_argument("--timeout", type=float, default=600.0, help="seconds per run")
    ap.add_argument("--runs-dir", default="/tmp/deformix_bench_mixture")
    ap.add_argument("--out", default=os.path.join(ROOT, "benchmarks", "mixture_cost"))
    ap.add_argument("--extra", default="", help="extra options for compact")
    args = ap.parse_args()
    exe = os.path.join(ROOT, "build", "bin", "compact")
    if not os.path.exists(exe):
        sys.exit(f"{exe} not found: build first (bash scripts/test.sh or cmake --build build)")
    cols = ["n_particles", "kappa", "friction", "status", "P_over_E", "phi", "newton_its", "pseudo_time_steps",
            "symbolic_factorizations", "seconds", "unknowns", "rigid_unknowns", "deformable_unknowns",
            "tangential_unknowns", "candidates", "jacobian_nonzeros", "force_residual_over_Pd"]
    rows = []
    for n in args.sizes:
        for kappa in args.kappas:
            for mu in args.frictions:
                d = os.path.join(args.runs_dir, f"n{n}_k{kappa}_mu{mu}")
                os.makedirs(d, exist_ok=True)
                cmd = [exe, "-n_particles", str(n), "-kappa", str(kappa), "-friction", str(mu), "-pressures",
                       args.pressures, "-output_dir", d, "-write_hdf5", "false"] + args.extra.split()
                t0 = time.time()
                try:
                    r = subprocess.run(cmd, capture_output=True, text=True, timeout=args.timeout)
                    status = "ok" if r.returncode == 0 else "failed"
                except subprocess.TimeoutExpired:
                    status = "timeout"
                wall = time.time() - t0
                got = []
                path = os.path.join(d, "curve.csv")
                if os.path.exists(path) and os.path.getmtime(path) >= t0:
                    with open(path, newline="") as f:
                        got = list(csv.DictReader(f))
                for g in got:
                    rows.append([n, kappa, mu, status] + [g[c] for c in cols[4:]])
                if not got:
                    rows.append([n, kappa, mu, status] + [""] * (len(cols) - 4))
                print(f"N_p {n:5d} kappa {kappa:.1f} mu {mu:.1f}: {status:7s} {len(got)} levels, {wall:7.1f} s wall")
                for g in got:
                    print(f"    P/E {float(g['P_over_E']):8.1e}  newton {g['newton_its']:>6s}  pseudo-time {g['pseudo_time_steps']:>5s}"
                          f"  symbolic {g['symbolic_factorizations']:>4s}  {float(g['seconds']):8.2f} s  unknowns {g['unknowns']:>7s}"
                          f" (rigid {g['rigid_unknowns']}, deformable {g['deformable_unknowns']}, tangential"
                          f" {g['tangential_unknowns']}, candidates {g['candidates']})")
                sys.stdout.flush()
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out + ".csv", "w", newline="") as f:
        f.write(f"# machine: {machine()}\n")
        f.write(f"# commit: {git_commit()}\n")
        f.write(f"# command: {' '.join(sys.argv)}\n# compact options: -pressures {args.pressures} {args.extra}\n")
        w = csv.writer(f)
        w.writerow(cols)
        w.writerows(rows)
    print("wrote", args.out + ".csv")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.5))
    for n in args.sizes:
        for kappa in args.kappas:
            for mu in args.frictions:
                sel = [r for r in rows if r[0] == n and r[1] == kappa and r[2] == mu and r[4] != ""]
                if not sel:
                    continue
                P = np.array([float(r[4]) for r in sel])
                lab = f"N={n} k={kappa:g} mu={mu:g}"
                ax[0].loglog(P, [max(float(r[6]), 1) for r in sel], "o-", ms=3, label=lab)
                ax[1].loglog(P, [max(float(r[9]), 1e-3) for r in sel], "o-", ms=3, label=lab)
    ax[0].set(xlabel="P / E", ylabel="Newton iterations per level")
    ax[1].set(xlabel="P / E", ylabel="seconds per level")
    ax[0].legend(fontsize=6)
    fig.suptitle(f"deformix compact, commit {git_commit()}, {machine()}", fontsize=9)
    fig.tight_layout()
    fig.savefig(args.out + ".png", dpi=120)
    print("wrote", args.out + ".png")


if __name__ == "__main__":
    main()

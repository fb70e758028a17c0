#!/usr/bin/python3
"""Validation campaign: compact for kappa in {0.2, 0.5, 0.8, 1}
and friction in {0, 0.2}, then the paper's fits per friction.

Runs build/bin/compact (two at a time by default: one per core), writes each
run to <runs>/k<kappa>_mu<mu>/, then calls scripts/fit_compaction.py on the
curves of each friction (with --kappa, so the phi_max(kappa) mixing rule is
fitted too) and scripts/plot_compaction.py on all of them. Writes
  <out>/runs.csv            per run: status, levels reached, seconds, phi and Z at the last level
  <out>/fit_mu<mu>.csv/.png the fits (fit_compaction.py)
  <out>/fit_mu<mu>.txt      its printed table
  <out>/compaction.png      phi(P), Z(phi), P_sigma/P, Newton iterations of every run
with the machine, commit and options in the '#' lines of runs.csv.

Usage:
  /usr/bin/python3 scripts/campaign.py                         # 50 disks (about 20 min on 2 cores)
  /usr/bin/python3 scripts/campaign.py --n-particles 100 --jobs 2 --timeout 7200
"""
import argparse
import concurrent.futures as cf
import csv
import os
import subprocess
import sys
import time

from provenance import git_commit, machine

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PY = "/usr/bin/python3" if os.path.exists("/usr/bin/python3") else sys.executable


def run_one(exe, n, kappa, mu, pressures, out, timeout, extra):
    os.makedirs(out, exist_ok=True)
    cmd = [exe, "-n_particles", str(n), "-kappa", str(kappa), "-friction", str(mu), "-pressures", pressures,
           "-output_dir", out] + extra
    t0 = time.time()
    try:
        p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=timeout)
        status = "ok" if p.returncode == 0 else "failed"
        log = p.stdout
    except subprocess.TimeoutExpired as e:
        status = "timeout"
        log = e.stdout.decode() if isinstance(e.stdout, bytes) else (e.stdout or "")
    with open(os.path.join(out, "log.txt"), "w") as f:
        f.write(" ".join(cmd) + "\n" + log)
    return status, time.time() - t0


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n-particles", type=int, default=50)
    ap.add_argument("--kappas", type=float, nargs="+", default=[0.2, 0.5, 0.8, 1.0])
    ap.add_argument("--frictions", type=float, nargs="+", default=[0.0, 0.2])
    ap.add_argument("--pressures", default="1e-4,3e-4,1e-3,3e-3,0.01,0.02,0.05,0.1,0.15,0.2,0.25,0.3,0.4,0.5")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--timeout", type=float, default=3600.0, help="seconds per run")
    ap.add_argument("--runs", default=os.path.join(ROOT, "out", "campaign"))
    ap.add_argument("--out", default=os.path.join(ROOT, "benchmarks", "campaign"))
    ap.add_argument("--extra", default="", help="extra compact options")
    ap.add_argument("--fit-only", action="store_true", help="reuse finished runs")
    ap.add_argument("--exe", default=os.path.join(ROOT, "build", "bin", "compact"),
                    help="compact executable (a copy lets the build directory change while the campaign runs)")
    a = ap.parse_args()
    exe = a.exe
    if not os.path.exists(exe):
        sys.exit(f"{exe} not found: build first")
    os.makedirs(a.out, exist_ok=True)
    grid = [(k, m) for m in a.frictions for k in a.kappas]
    status = {}
    if not a.fit_only:
        with cf.ThreadPoolExecutor(max_workers=a.jobs) as pool:
            futs = {pool.submit(run_one, exe, a.n_particles, k, m, a.pressures, os.path.join(a.runs, f"k{k:g}_mu{m:g}"),
                                a.timeout, a.extra.split()): (k, m) for k, m in grid}
            for f in cf.as_completed(futs):
                k, m = futs[f]
                status[(k, m)] = f.result()
                print(f"kappa {k:g} friction {m:g}: {status[(k, m)][0]} in {status[(k, m)][1]:.0f} s", flush=True)
    rows = []
    for k, m in grid:
        path = os.path.join(a.runs, f"k{k:g}_mu{m:g}", "curve.csv")
        levels = []
        if os.path.exists(path):
            with open(path, newline="") as f:
                levels = list(csv.DictReader(f))
        st, sec = status.get((k, m), ("reused", float("nan")))
        last = levels[-1] if levels else {}
        rows.append([k, m, st, len(levels), last.get("P_over_E", ""), f"{sec:.0f}", last.get("phi", ""),
                     last.get("Z_no_rattlers", ""), sum(float(l["newton_its"]) for l in levels)])
    # --fit-only keeps the runs.csv of the campaign that produced the curves.
    with open(os.path.join(a.out, "runs.csv" if not a.fit_only else os.devnull), "w", newline="") as f:
        f.write(f"# machine: {machine()}; commit {git_commit()}\n")
        f.write(f"# command: {' '.join(sys.argv)}\n# compact: -n_particles {a.n_particles} -pressures {a.pressures} {a.extra}\n")
        w = csv.writer(f)
        w.writerow(["kappa", "friction", "status", "levels", "last_P_over_E", "seconds", "phi_last", "Z_nr_last", "newton_its"])
        w.writerows(rows)
    curves_all = []
    for m in a.frictions:
        curves, kap = [], []
        for k in a.kappas:
            path = os.path.join(a.runs, f"k{k:g}_mu{m:g}", "curve.csv")
            if os.path.exists(path):
                with open(path) as f:
                    if sum(1 for _ in f) >= 5:  # header + at least 4 levels to fit
                        curves.append(path)
                        kap.append(k)
        curves_all += curves
        if not curves:
            continue
        cmd = [PY, os.path.join(ROOT, "scripts", "fit_compaction.py")] + curves + ["--labels"] + \
              [f"kappa={k:g},mu={m:g}" for k in kap] + ["--kappa"] + [str(k) for k in kap] + \
              ["--out", os.path.join(a.out, f"fit_mu{m:g}")]
        p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        with open(os.path.join(a.out, f"fit_mu{m:g}.txt"), "w") as f:
            f.write(p.stdout)
        print(p.stdout)
    if curves_all:
        subprocess.run([PY, os.path.join(ROOT, "scripts", "plot_compaction.py"), os.path.join(a.out, "compaction.png")]
                       + curves_all)
    if not a.fit_only:
        print("wrote", os.path.join(a.out, "runs.csv"))


if __name__ == "__main__":
    main()

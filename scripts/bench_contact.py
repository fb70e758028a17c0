#!/usr/bin/python3
"""Deformable-deformable contact laws compared: overlap, packing fraction and cost.

compact offers three laws for a pair of deformable disks (pair_kinematics.hpp):
  nts       one-pass node-to-segment (the slave's nodes against the master's curve),
  two_pass  node-to-segment both ways (-contact_deformable two_pass),
  mortar    the slave node's gap averaged over its dual cell (-contact_deformable mortar).
For each scene (N_p, kappa, friction) and law this runs build/bin/compact on the
same packing and pressure levels, then measures the overlap of the deformable
disks from levels.h5 alone (scripts/check_overlap.py: every boundary node of
every deformable disk against the quadratic finite-element boundary of every
other one, split by the node's role in its pair), and records per level:
phi, Newton iterations, seconds, the deepest slave and master node inside
another disk (in <d>). Runs go --jobs at a time (the default 2 fills this
2-core machine; the seconds are then those of a shared machine).

Outputs: <out>.csv ('#' header lines: machine, commit, options) and <out>.png
(deepest overlap and Newton iterations against P/E, one colour per law).

Usage:
  /usr/bin/python3 scripts/bench_contact.py                       # 20 disks, kappa 1 and 0.5
  /usr/bin/python3 scripts/bench_contact.py --laws nts mortar --scenes 20:1:0 --pressures 1e-4,0.01,0.1
"""
import argparse
import csv
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import h5py

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from check_overlap import check_level  # noqa: E402
from provenance import git_commit, machine  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LAW_OPTIONS = {law: ["-contact_deformable", law] for law in ("nts", "two_pass", "mortar")}


def read_curve(path):
    with open(path) as f:
        return list(csv.DictReader(line for line in f if not line.startswith("#")))


def run(scene, law, a):
    n, kappa, friction = scene
    out = os.path.join(a.workdir, f"n{n}_k{kappa:g}_mu{friction:g}_{law}")
    cmd = [os.path.join(ROOT, "build/bin/compact"), "-n_particles", str(n), "-kappa", f"{kappa:g}", "-friction",
           f"{friction:g}", "-seed", str(a.seed), "-pressures", a.pressures, "-output_dir", out] + LAW_OPTIONS[law]
    start = time.time()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=a.timeout)
        status = "ok" if proc.returncode == 0 else f"exit {proc.returncode}"
    except subprocess.TimeoutExpired:
        status = "timeout"
    rows = []
    curve_path = os.path.join(out, "curve.csv")
    if os.path.exists(curve_path) and os.path.exists(os.path.join(out, "levels.h5")):
        curve = read_curve(curve_path)
        with h5py.File(os.path.join(out, "levels.h5"), "r") as f:
            for level, c in zip(sorted(f.keys()), curve):
                _, count, deepest = check_level(f[level], 1e-5, False)
                rows.append([n, kappa, friction, law, status, float(c["P_over_E"]), float(c["phi"]), int(c["newton_its"]),
                             float(c["seconds"]), count["slave"], deepest["slave"], count["master"], deepest["master"]])
    print(f"  {law:>8} n {n} kappa {kappa:g} friction {friction:g}: {status}, {len(rows)} levels, "
          f"{time.time() - start:.0f} s", flush=True)
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", nargs="+", default=["20:1:0", "20:1:0.2", "20:0.5:0.2"],
                    help="N_p:kappa:friction")
    ap.add_argument("--laws", nargs="+", choices=sorted(LAW_OPTIONS), default=["nts", "mortar"])
    ap.add_argument("--pressures", default="1e-4,1e-3,0.01,0.05,0.1,0.2")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per run")
    ap.add_argument("--workdir", default=os.path.join(ROOT, "out/bench_contact"))
    ap.add_argument("--out", default=os.path.join(ROOT, "benchmarks/contact_laws"))
    a = ap.parse_args()
    scenes = []
    for s in a.scenes:
        n, kappa, friction = s.split(":")
        scenes.append((int(n), float(kappa), float(friction)))
    jobs = [(s, law) for s in scenes for law in a.laws]
    with ThreadPoolExecutor(max_workers=a.jobs) as pool:
        results = list(pool.map(lambda j: run(j[0], j[1], a), jobs))
    rows = [r for res in results for r in res]

    header = ["n_particles", "kappa", "friction", "law", "status", "P_over_E", "phi", "newton_its", "seconds",
              "slave_nodes_inside", "slave_deepest_over_d", "master_nodes_inside", "master_deepest_over_d"]
    with open(a.out + ".csv", "w", newline="") as f:
        f.write(f"# scripts/bench_contact.py {' '.join(sys.argv[1:])}\n")
        f.write(f"# machine: {machine()}; commit {git_commit()}; {a.jobs} runs at a time\n")
        f.write("# deepest: boundary node inside another deformable disk's quadratic boundary, in <d> (check_overlap.py)\n")
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)
    print(f"{'scene':>16} {'law':>8} {'P/E':>7} {'phi':>8} {'newton':>6} {'s':>6} {'slave':>8} {'master':>8}")
    for r in rows:
        print(f"{r[0]:>4}:{r[1]:<4g}:{r[2]:<5g} {r[3]:>8} {r[5]:7.4g} {r[6]:8.5f} {r[7]:6d} {r[8]:6.1f} "
              f"{r[10]:8.2e} {r[12]:8.2e}")

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(2, len(scenes), figsize=(4.2 * len(scenes), 7), squeeze=False)
    colours = {"nts": "C0", "two_pass": "C2", "mortar": "C3"}
    for k, s in enumerate(scenes):
        for law in a.laws:
            sel = [r for r in rows if (r[0], r[1], r[2]) == s and r[3] == law]
            if not sel:
                continue
            P = [r[5] for r in sel]
            ax[0, k].loglog(P, [max(r[10], 1e-6) for r in sel], "o--", color=colours[law], label=f"{law}: slave nodes")
            ax[0, k].loglog(P, [max(r[12], 1e-6) for r in sel], "s-", color=colours[law], label=f"{law}: master nodes")
            ax[1, k].semilogx(P, [r[7] for r in sel], "o-", color=colours[law], label=law)
        ax[0, k].set_title(f"N_p {s[0]}, kappa {s[1]:g}, friction {s[2]:g}")
        ax[0, k].set_ylabel("deepest node inside another disk / <d>")
        ax[1, k].set_ylabel("Newton iterations per level")
        ax[1, k].set_xlabel("P/E")
        ax[0, k].legend(fontsize=7)
        ax[1, k].legend(fontsize=7)
    fig.suptitle(f"deformable contact laws, commit {git_commit()}", fontsize=10)
    fig.tight_layout()
    fig.savefig(a.out + ".png", dpi=110)
    print(f"wrote {a.out}.csv and {a.out}.png")


if __name__ == "__main__":
    main()

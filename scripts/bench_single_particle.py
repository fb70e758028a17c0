#!/usr/bin/python3
"""Work-precision benchmark of the single-particle driver (paper Fig. Pp_vs_Phip).

Runs build/bin/single-particle for element orders 1 and 2 on a ladder of meshes,
reads phi_p at P/E = 0.01, 0.1, 0.5 from each curve.csv, and measures the error
|phi - phi_ref| against the finest order-2 mesh of the same nu (the "converged
reference").  Runs are sequential (timings are meaningless otherwise on a small
machine).  Raw run directories go under --runs-dir (default /tmp/...), never into
the repository.

Outputs (relative to the repository root):
  benchmarks/single_particle_work_precision.csv   (header '#' lines: machine, commit, options)
  benchmarks/single_particle_work_precision.png   (error vs run time, log-log)

Usage (Debian python with numpy/matplotlib):
  /usr/bin/python3 scripts/bench_single_particle.py            # full benchmark
  /usr/bin/python3 scripts/bench_single_particle.py --reuse    # re-use finished runs in --runs-dir
  /usr/bin/python3 scripts/bench_single_particle.py --no-fine  # skip the 15000-triangle order-2 run
"""
import argparse
import csv
import os
import platform
import re
import subprocess
import sys
import time

import numpy as np

from provenance import cpu_name, git_commit

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DRIVER = os.path.join(REPO, "build", "bin", "single-particle")
# the driver's default list, passed explicitly so the benchmark does not depend on defaults
PRESSURES = "0.0001,0.001,0.005,0.01,0.02,0.05,0.1,0.15,0.2,0.3,0.4,0.5"
LEVELS = (0.01, 0.1, 0.5)


def machine_info():
    uname = " ".join(platform.uname())
    try:
        uname = subprocess.run(["uname", "-a"], capture_output=True, text=True).stdout.strip()
    except OSError:
        pass
    import hashlib
    with open(DRIVER, "rb") as f:
        sha = hashlib.sha256(f.read()).hexdigest()[:16]
    mtime = time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(os.path.getmtime(DRIVER)))
    return {"uname": uname, "nproc": os.cpu_count(), "cpu": cpu_name(), "binary": f"sha256 {sha}, built {mtime} UTC",
            "commit": git_commit(dirty_mark=True)}


def run_case(runs_dir, order, mesh, nu, reuse, timeout):
    tag = f"o{order}_n{mesh}_nu{nu}"
    out = os.path.join(runs_dir, tag)
    log = os.path.join(runs_dir, tag + ".log")
    args = [DRIVER, "-mesh_triangles", str(mesh), "-element_order", str(order), "-nu", str(nu),
            "-pressures", PRESSURES, "-write_hdf5", "0", "-output_dir", out]
    wall_file = os.path.join(runs_dir, tag + ".wall")
    status_file = os.path.join(runs_dir, tag + ".status")
    if reuse and os.path.exists(status_file) and os.path.exists(wall_file):
        with open(wall_file) as f:
            wall = float(f.read())
        with open(status_file) as f:
            status = f.read().strip()
    else:
        os.makedirs(out, exist_ok=True)
        t0 = time.perf_counter()
        try:
            proc = subprocess.run(args, capture_output=True, text=True, timeout=timeout)
            text, rc = proc.stdout + proc.stderr, proc.returncode
            status = "ok" if rc == 0 else "failed"
        except subprocess.TimeoutExpired as e:
            text = (e.stdout or b"").decode() if isinstance(e.stdout, bytes) else (e.stdout or "")
            status = f"timeout>{timeout:.0f}s"
        wall = time.perf_counter() - t0
        with open(log, "w") as f:
            f.write(" ".join(args) + "\n" + text)
        with open(wall_file, "w") as f:
            f.write(repr(wall))
        with open(status_file, "w") as f:
            f.write(status)
    with open(log) as f:
        text = f.read()
    m = re.search(r"single-particle: (\d+) triangles .*?, (\d+) nodes", text)
    tri, nodes = (int(m.group(1)), int(m.group(2))) if m else (None, None)
    if status != "ok":
        err = re.search(r"PETSC ERROR: (pressure level .*?)\. Try", text)
        why = err.group(1) if err else status
        print(f"  !! {tag}: {why}; see {log}", file=sys.stderr)
        return {"order": order, "mesh": mesh, "nu": nu, "tri": tri, "nodes": nodes, "status": why,
                "P": np.array([]), "phi": np.array([]), "sec": np.array([np.nan]), "its": np.array([0]),
                "cuts": np.array([0]), "wall": wall}
    rows = list(csv.DictReader(open(os.path.join(out, "curve.csv"))))
    P = np.array([float(r["P_over_E"]) for r in rows])
    phi = np.array([float(r["phi"]) for r in rows])
    sec = np.array([float(r["seconds"]) for r in rows])
    its = np.array([int(r["newton_its"]) for r in rows])
    cuts = np.array([int(r["cuts"]) for r in rows])
    return {"order": order, "mesh": mesh, "nu": nu, "tri": tri, "nodes": nodes, "P": P, "phi": phi,
            "sec": sec, "its": its, "cuts": cuts, "wall": wall, "status": "ok"}


def phi_at(run, level):
    i = np.flatnonzero(np.isclose(run["P"], level, rtol=1e-9, atol=0))
    return float(run["phi"][i[0]]) if len(i) else float("nan")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs-dir", default="/tmp/deformix-bench-single-particle")
    ap.add_argument("--meshes", default="92,368,968,3872")
    ap.add_argument("--order1-extra", default="1100,4200",
                    help="extra order-1 meshes (968 and 3872 give 78/150 boundary vertices, not a multiple "
                         "of 4, and order 1 then fails at the first level)")
    ap.add_argument("--timeout", type=float, default=240, help="per-run time limit, s")
    ap.add_argument("--fine-mesh", type=int, default=15000,
                    help="extra order-2 reference mesh (nu = 0.495); 0 to skip")
    ap.add_argument("--no-fine", action="store_true")
    ap.add_argument("--nu-locking", default="0.4999", help="second nu for the locking study; '' to skip")
    ap.add_argument("--locking-meshes", default="92,368")
    ap.add_argument("--locking-ref-mesh", type=int, default=968,
                    help="order-2 mesh used as reference for the locking nu")
    ap.add_argument("--reuse", action="store_true", help="re-use finished runs found in --runs-dir")
    ap.add_argument("--csv", default=os.path.join(REPO, "benchmarks", "single_particle_work_precision.csv"))
    ap.add_argument("--png", default=os.path.join(REPO, "benchmarks", "single_particle_work_precision.png"))
    a = ap.parse_args()

    os.makedirs(a.runs_dir, exist_ok=True)
    os.makedirs(os.path.dirname(a.csv), exist_ok=True)
    meshes = [int(m) for m in a.meshes.split(",")]
    cases = [(o, m, 0.495) for o in (1, 2) for m in meshes]
    if a.order1_extra:
        cases[len(meshes):len(meshes)] = [(1, int(m), 0.495) for m in a.order1_extra.split(",")]
    if a.fine_mesh and not a.no_fine:
        cases.append((2, a.fine_mesh, 0.495))
    if a.nu_locking:
        nul = float(a.nu_locking)
        lm = [int(m) for m in a.locking_meshes.split(",")]
        cases += [(o, m, nul) for o in (1, 2) for m in lm]
        if a.locking_ref_mesh not in lm:
            cases.append((2, a.locking_ref_mesh, nul))

    runs = []
    for (o, m, nu) in cases:
        print(f"run order {o} mesh {m} nu {nu} ...", flush=True)
        r = run_case(a.runs_dir, o, m, nu, a.reuse, a.timeout)
        runs.append(r)
        if r["status"] == "ok":
            print(f"   {r['tri']} triangles, wall {r['wall']:.2f} s, solver {r['sec'].sum():.2f} s, "
                  f"newton {r['its'].sum()}, cuts {r['cuts'].sum()}", flush=True)

    # reference: finest order-2 mesh for each nu
    refs = {}
    for nu in sorted({r["nu"] for r in runs}):
        cand = [r for r in runs if r["nu"] == nu and r["order"] == 2 and r["status"] == "ok"]
        refs[nu] = max(cand, key=lambda r: r["tri"])

    info = machine_info()
    out_rows = []
    for r in runs:
        ref = refs[r["nu"]]
        for lev in LEVELS:
            phi = phi_at(r, lev)
            phr = phi_at(ref, lev)
            out_rows.append({
                "nu": r["nu"], "order": r["order"], "mesh_triangles": r["mesh"], "triangles": r["tri"],
                "nodes": r["nodes"], "P_over_E": lev, "phi": phi, "phi_ref": phr,
                "error": abs(phi - phr), "rel_error": abs(phi - phr) / phr,
                "is_reference": int(r is ref), "status": r["status"],
                "seconds": r["sec"].sum(), "wall_seconds": r["wall"],
                "newton_its": int(r["its"].sum()) if r["status"] == "ok" else "",
                "cuts": int(r["cuts"].sum()) if r["status"] == "ok" else ""})

    with open(a.csv, "w", newline="") as f:
        f.write(f"# deformix single-particle work-precision benchmark ({time.strftime('%Y-%m-%d %H:%M %Z')})\n")
        f.write(f"# commit: {info['commit']} (dirty = other engineers' uncommitted work in the tree); "
                f"driver binary: {info['binary']}\n# machine: {info['uname']}\n")
        f.write(f"# nproc: {info['nproc']}; cpu: {info['cpu']}; runs sequential, 1 MPI rank\n")
        f.write(f"# command: build/bin/single-particle -mesh_triangles N -element_order O -nu NU "
                f"-pressures {PRESSURES} -write_hdf5 0 -output_dir DIR\n")
        for nu, ref in refs.items():
            f.write(f"# reference for nu={nu}: order 2, {ref['tri']} triangles (-mesh_triangles {ref['mesh']})\n")
        f.write("# error = |phi - phi_ref| at that P/E; seconds = sum of curve.csv 'seconds' over all 12 levels; "
                "wall_seconds = wall clock of the whole process; newton_its, cuts = totals over all levels\n")
        w = csv.DictWriter(f, fieldnames=list(out_rows[0].keys()))
        w.writeheader()
        for row in out_rows:
            row = dict(row)
            for k in ("phi", "phi_ref"):
                row[k] = f"{row[k]:.8f}"
            for k in ("error", "rel_error"):
                row[k] = f"{row[k]:.3e}"
            for k in ("seconds", "wall_seconds"):
                row[k] = f"{row[k]:.3f}"
            w.writerow(row)
    print(f"wrote {a.csv}")

    # table
    print(f"\n{'nu':>7} {'ord':>3} {'tri':>6} {'wall s':>8} {'solve s':>8} {'newton':>6} {'cuts':>4} | "
          + " | ".join(f"phi@{l:<4}  err" for l in LEVELS))
    for r in runs:
        ref = refs[r["nu"]]
        cells = []
        for lev in LEVELS:
            phi = phi_at(r, lev)
            err = abs(phi - phi_at(ref, lev))
            cells.append(f"{phi:.6f} {err:8.1e}" if r is not ref else f"{phi:.6f}      ref")
        if r["status"] != "ok":
            cells = [r["status"][:60]]
        print(f"{r['nu']:>7} {r['order']:>3} {r['tri']:>6} {r['wall']:8.2f} {r['sec'].sum():8.2f} "
              f"{r['its'].sum():6d} {r['cuts'].sum():4d} | " + " | ".join(cells))

    # figure: error vs wall time, one line per (order, level); nu-locking variant dashed
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.4, 4.6), dpi=100)
    colors = {0.01: "tab:blue", 0.1: "tab:orange", 0.5: "tab:green"}
    markers = {1: "s", 2: "o"}
    for nu in refs:
        dashed = nu != 0.495
        for order in (1, 2):
            sel = sorted([r for r in runs if r["nu"] == nu and r["order"] == order and r is not refs[nu]
                          and r["status"] == "ok"],
                         key=lambda r: r["tri"])
            if not sel:
                continue
            for lev in LEVELS:
                t = [r["wall"] for r in sel]
                e = [max(abs(phi_at(r, lev) - phi_at(refs[nu], lev)), 1e-9) for r in sel]
                ax.loglog(t, e, ls="--" if dashed else ("-" if order == 2 else ":"),
                          marker=markers[order], mfc="none" if order == 1 else colors[lev],
                          color=colors[lev], alpha=0.6 if dashed else 1.0, lw=1.2, ms=5,
                          label=f"order {order}, P/E={lev}" + (f", nu={nu}" if dashed else ""))
    ax.axhline(1e-3, color="gray", lw=0.8, ls="-.")
    ax.text(ax.get_xlim()[0] * 1.1 if ax.get_xlim()[0] > 0 else 0.3, 1.1e-3, "1e-3", color="gray", fontsize=8)
    refs_txt = "; ".join(f"nu={nu}: order 2, {r['tri']} tri" for nu, r in refs.items())
    ax.set_xlabel("wall-clock time of the whole run (12 levels), s")
    ax.set_ylabel(r"$|\phi_p - \phi_{p,\mathrm{ref}}|$")
    ax.set_title(f"single particle work-precision (ref: {refs_txt})", fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=6, ncol=2, loc="best")
    fig.tight_layout()
    fig.savefig(a.png)
    print(f"wrote {a.png} ({os.path.getsize(a.png) // 1024} KB)")


if __name__ == "__main__":
    main()

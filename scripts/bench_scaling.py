#!/usr/bin/python3
"""Strong and weak scaling of distributed compact runs, and linear-solver comparison.

Runs `<mpiexec> -n r <compact> ...` for every rank count r of --ranks:
  - strong scaling: the scene --n-particles N on every r;
  - weak scaling (--weak-per-rank M): N = M * r particles on r ranks;
  - linear solvers (--options-files f1 f2 ...): every run above once per options file
    (`-options_file f`), so solvers are compared on the same scenes and rank counts.
Per run and per level (from <run dir>/curve.csv, also a partial one): seconds, Newton iterations,
seconds per Newton iteration, unknowns, contact candidates; per run: wall time of the whole mpiexec
(packing generation, settling and MPI start-up included) and resident memory (PETSc -memory_view:
maximum over the run of the process memory, max over ranks and total over ranks). A level row
"all" sums the finished levels of a run. Parallel efficiency against the smallest rank count r0 of
the same mode and options file: strong r0 t_r0 / (r t_r), weak t_r0 / t_r. Newton iteration
counts can differ between rank counts (round-off changes the nonsmooth path), so the efficiency of
the seconds per Newton iteration is reported too. A run that fails or exceeds --timeout keeps its
finished levels (status column). Runs are sequential so that the timings mean something.

Outputs: --csv (default benchmarks/scaling.csv; '#' header lines: machine, MPI, commit, date,
options) and --png (default benchmarks/scaling.png: seconds per level, efficiency, memory per rank).
Run directories go under --out-dir (default out/scaling).

With --merge it runs nothing and merges CSVs written by earlier invocations (for instance one rank
count per invocation when the runs take hours), recomputing the efficiencies.

Usage:
  /usr/bin/python3 scripts/bench_scaling.py --n-particles 64 --pressures 1e-4,1e-3 --ranks 1 2
  /usr/bin/python3 scripts/bench_scaling.py --n-particles 400 --ranks 1 2 4 --weak-per-rank 100 \\
      --options-files petsc-options/mumps.opts my-asm.opts --timeout 3600
(as root, Open MPI needs OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1; set if missing)
"""
import argparse
import csv
import hashlib
import os
import re
import shlex
import signal
import subprocess
import sys
import time

from provenance import machine

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MEM_RE = re.compile(r"Maximum \(over computational time\) process memory:\s+total\s+(\S+)\s+max\s+(\S+)\s+min\s+(\S+)")
COLS = ["mode", "options_file", "ranks", "n_particles", "status", "wall_seconds", "max_rss_MiB_per_rank",
        "total_rss_MiB", "level", "P_over_E", "phi", "Z", "newton_its", "substeps", "pseudo_time_steps",
        "unknowns", "candidates", "seconds", "seconds_per_newton", "efficiency", "efficiency_per_newton"]


def fmt(x, f):
    return "" if x is None else f % x


def run_text(cmd):
    try:
        return subprocess.run(cmd, capture_output=True, text=True).stdout.strip()
    except OSError:
        return "unknown"


def run_compact(cmd, run_dir, timeout, env):
    """Runs cmd (output to run_dir/log.txt); returns status, wall seconds, levels (dicts), memory (MiB)."""
    os.makedirs(run_dir, exist_ok=True)
    log, curve = os.path.join(run_dir, "log.txt"), os.path.join(run_dir, "curve.csv")
    t0 = time.time()
    with open(log, "w") as f:
        f.write(" ".join(shlex.quote(c) for c in cmd) + "\n")
        f.flush()
        # own process group, so that a timeout stops mpiexec and its ranks (and nothing else)
        p = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, env=env, start_new_session=True)
        try:
            status = "ok" if p.wait(timeout=timeout) == 0 else "failed"
        except subprocess.TimeoutExpired:
            status = "timeout"
            f.write(f"\nbench_scaling: timed out after {timeout:g} s, stopping the process group\n")
            f.flush()
            for sig, grace in ((signal.SIGTERM, 10), (signal.SIGKILL, None)):
                try:
                    os.killpg(p.pid, sig)
                    p.wait(timeout=grace)
                    break
                except (subprocess.TimeoutExpired, ProcessLookupError):
                    pass
    wall = time.time() - t0
    levels = []
    if os.path.exists(curve) and os.path.getmtime(curve) >= t0:  # not a curve.csv of an earlier run
        with open(curve, newline="") as f:
            levels = [r for r in csv.DictReader(f) if None not in r.values() and r.get("seconds")]
    mem = (None, None)
    with open(log, errors="replace") as f:
        m = MEM_RE.search(f.read())
    if m:
        mem = (float(m.group(2)) / 2**20, float(m.group(1)) / 2**20)
    return status, wall, levels, mem


def checkpoint_levels(path):
    """Number of levels done in a compact checkpoint (their rows are repeated in a restarted run's curve.csv)."""
    import h5py
    try:
        with h5py.File(path, "r") as f:
            return len(f["levels"])
    except (OSError, KeyError) as e:
        sys.exit(f"--restart {path}: not a readable compact checkpoint ({e})")


def level_rows(levels, first=0):
    """(level, P_over_E, phi, Z, newton_its, substeps, pseudo_time_steps, unknowns, candidates, seconds) per level, plus 'all'.
    Levels are numbered from `first` (the levels a restart continued from are not in `levels`)."""
    keys = ["P_over_E", "phi", "Z", "newton_its", "substeps", "pseudo_time_steps", "unknowns", "candidates", "seconds"]
    rows = [[str(first + i)] + [g[k] for k in keys] for i, g in enumerate(levels)]
    if levels:
        s = lambda k: sum(float(g[k]) for g in levels)
        rows.append(["all", "", "", "", f"{s('newton_its'):g}", f"{s('substeps'):g}", f"{s('pseudo_time_steps'):g}",
                     levels[-1]["unknowns"], levels[-1]["candidates"], f"{s('seconds'):.6g}"])
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n-particles", type=int, default=64, help="strong-scaling scene")
    ap.add_argument("--kappa", type=float, default=0.5)
    ap.add_argument("--friction", type=float, default=0.2)
    ap.add_argument("--pressures", nargs="+", default=["1e-4,1e-3"], help="P/E levels (spaces or commas)")
    ap.add_argument("--mesh-triangles", type=int, default=92)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--weak-per-rank", type=int, default=0, help="M > 0: also weak scaling, N = M * r")
    ap.add_argument("--options-files", nargs="+", default=[], help="one set of runs per PETSc options file")
    ap.add_argument("--timeout", type=float, default=3600.0, help="seconds per run")
    ap.add_argument("--out-dir", default=os.path.join(ROOT, "out", "scaling"))
    ap.add_argument("--csv", default=os.path.join(ROOT, "benchmarks", "scaling.csv"))
    ap.add_argument("--png", default=os.path.join(ROOT, "benchmarks", "scaling.png"))
    ap.add_argument("--compact", default=os.path.join(ROOT, "build", "bin", "compact"))
    ap.add_argument("--mpiexec", default="mpirun")
    ap.add_argument("--mpiexec-args", default="--oversubscribe", help="options of mpiexec before the executable")
    ap.add_argument("--extra", default="", help="extra options for compact")
    ap.add_argument("--restart", metavar="CHECKPOINT", help="continue every run from this compact checkpoint"
                    " (-restart): only the levels after the checkpoint's are run and reported, all rank counts"
                    " start from the same state")
    ap.add_argument("--merge", nargs="+", metavar="CSV", help="run nothing: merge CSVs of earlier runs of this script"
                    " (e.g. 1 rank and 2 ranks measured separately), recompute the efficiencies, write --csv and --png")
    args = ap.parse_args()
    if args.merge:
        return merge(args.merge, args.csv, args.png)
    if not os.path.exists(args.compact):
        sys.exit(f"{args.compact} not found: build first (bash scripts/test.sh or cmake --build build)")
    for f in args.options_files:
        if not os.path.exists(f):
            sys.exit(f"options file {f} not found")
    pressures = ",".join(p for s in args.pressures for p in s.split(",") if p)
    ranks = sorted(set(args.ranks))
    env = dict(os.environ)
    if os.geteuid() == 0:
        env.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1"), env.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    common = ["-kappa", str(args.kappa), "-friction", str(args.friction), "-pressures", pressures,
              "-mesh_triangles", str(args.mesh_triangles), "-seed", str(args.seed), "-write_hdf5", "false",
              "-memory_view"] + shlex.split(args.extra)
    restored = 0
    if args.restart:
        restored = checkpoint_levels(args.restart)
        common += ["-restart", os.path.abspath(args.restart)]
    modes = [("strong", lambda r: args.n_particles)] + ([("weak", lambda r: args.weak_per_rank * r)]
                                                        if args.weak_per_rank > 0 else [])
    rows = []
    print(f"{'mode':6s} {'options':12s} {'r':>2s} {'N':>5s} {'status':7s} {'level':>5s} {'P/E':>8s} {'newton':>6s}"
          f" {'unknowns':>8s} {'seconds':>8s} {'s/newton':>8s} {'eff':>5s} {'eff/nwt':>7s} {'wall':>7s} {'maxMiB':>7s}")
    for mode, n_of in modes:
        for opts in args.options_files or [None]:
            oname = os.path.splitext(os.path.basename(opts))[0] if opts else "none"
            ref = {}  # level -> (ranks, seconds, seconds per Newton) of the smallest rank count
            for r in ranks:
                n = n_of(r)
                run_dir = os.path.join(args.out_dir, f"{mode}_{oname}_n{n}_r{r}")
                cmd = ([*shlex.split(args.mpiexec), "-n", str(r), *shlex.split(args.mpiexec_args), args.compact,
                        "-n_particles", str(n)] + common + (["-options_file", opts] if opts else [])
                       + ["-output_dir", run_dir])
                status, wall, levels, (mem_max, mem_tot) = run_compact(cmd, run_dir, args.timeout, env)
                lrows = level_rows(levels[restored:], restored) or [[""] * 10]
                for lr in lrows:
                    sec = float(lr[9]) if lr[9] else None
                    its = float(lr[4]) if lr[4] else 0
                    spn = sec / its if sec is not None and its > 0 else None
                    eff = effn = None
                    # 'all' is comparable only between runs that finished the same levels
                    key = lr[0] if lr[0] != "all" else f"all{len(levels) - restored}"
                    if sec is not None and r == ranks[0]:
                        ref[key] = (r, sec, spn)
                    if sec and key in ref:
                        r0, s0, spn0 = ref[key]
                        scale = r0 / r if mode == "strong" else 1.0
                        eff = scale * s0 / sec
                        effn = scale * spn0 / spn if spn and spn0 else None
                    rows.append([mode, opts or "none", r, n, status, f"{wall:.3f}", fmt(mem_max, "%.1f"),
                                 fmt(mem_tot, "%.1f")] + lr[:9] + [lr[9], fmt(spn, "%.6g"), fmt(eff, "%.4f"),
                                                                   fmt(effn, "%.4f")])
                    print(f"{mode:6s} {oname[:12]:12s} {r:2d} {n:5d} {status:7s} {lr[0]:>5s} {lr[1]:>8s} {lr[4]:>6s}"
                          f" {lr[7]:>8s} {fmt(sec, '%8.2f'):>8s} {fmt(spn, '%8.4f'):>8s} {fmt(eff, '%5.2f'):>5s}"
                          f" {fmt(effn, '%7.2f'):>7s} {wall:7.1f} {fmt(mem_max, '%7.1f'):>7s}")
                if status != "ok":
                    print(f"    {status}: see {os.path.join(run_dir, 'log.txt')}")
                sys.stdout.flush()
    for path in (args.csv, args.png):
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    sha = hashlib.sha256(open(args.compact, "rb").read()).hexdigest()[:16]
    with open(args.csv, "w", newline="") as f:
        f.write(f"# machine: {machine()}\n# MPI: {(run_text([*shlex.split(args.mpiexec), '--version']).splitlines() or ['unknown'])[0]}\n")
        f.write(f"# commit: {run_text(['git', '-C', ROOT, 'describe', '--always', '--dirty'])}, compact {args.compact}"
                f" (sha256 {sha})\n# date: {time.strftime('%Y-%m-%d %H:%M:%S %z')}\n")
        f.write(f"# command: {' '.join(shlex.quote(a) for a in sys.argv)}\n")
        f.write(f"# runs: {args.mpiexec} -n <ranks> {args.mpiexec_args} compact -n_particles <n_particles> "
                f"{' '.join(common)} [-options_file <options_file>] -output_dir {args.out_dir}/<mode>_<options>_n<N>_r<ranks>\n")
        f.write("# seconds: per level (curve.csv); level 'all': sum over the finished levels; wall_seconds: the whole"
                " mpiexec; memory: PETSc -memory_view maximum process memory (max over ranks, total over ranks)\n")
        f.write("# efficiency vs the smallest rank count r0 of the same mode and options file: strong r0 t_r0/(r t_r),"
                " weak t_r0/t_r; Newton iteration counts can differ between rank counts (round-off changes the"
                " nonsmooth path): efficiency_per_newton uses seconds per Newton iteration\n")
        w = csv.writer(f)
        w.writerow(COLS)
        w.writerows(rows)
    print("wrote", args.csv)
    plot(rows, args.png, f"compact N={args.n_particles} kappa={args.kappa:g} mu={args.friction:g} P/E={pressures}"
                         f"{f', weak {args.weak_per_rank}/rank' if args.weak_per_rank > 0 else ''}"
                         f"{f', restarted after level {restored - 1}' if restored else ''}")


def merge(paths, out_csv, out_png):
    """--merge: the rows of several CSVs of this script in one, efficiencies against the smallest rank count."""
    header, rows = [f"# merged by scripts/bench_scaling.py --merge from: {' '.join(paths)}\n"], []
    for path in paths:
        with open(path) as f:
            lines = f.readlines()
        header += [f"# [{os.path.basename(path)}] {ln[2:]}" for ln in lines if ln.startswith("#")]
        body = list(csv.reader(ln for ln in lines if not ln.startswith("#")))
        if not body or body[0] != COLS:
            sys.exit(f"{path}: not a CSV of bench_scaling.py (its columns differ)")
        rows += [[r[0], r[1], int(r[2]), int(r[3])] + r[4:] for r in body[1:]]
    runs = {}
    for r in rows:
        runs.setdefault((r[0], r[1], r[2], r[3]), set()).add(r[5])  # wall seconds tell the runs apart
    for run, walls in runs.items():
        if len(walls) > 1:
            sys.exit(f"--merge: {len(walls)} runs of mode {run[0]}, options {run[1]}, {run[2]} ranks, N = {run[3]}:"
                     " merge one run per rank count")
    for mode, opts in sorted({(r[0], r[1]) for r in rows}):
        sel = [r for r in rows if (r[0], r[1]) == (mode, opts)]
        r0 = min(r[2] for r in sel)
        nlev = lambda rk: sum(1 for r in sel if r[2] == rk and r[8] not in ("all", ""))
        key = lambda r: r[8] if r[8] != "all" else f"all{nlev(r[2])}"
        ref = {key(r): (float(r[17]), float(r[18]) if r[18] else None) for r in sel if r[2] == r0 and r[17]}
        for r in sel:
            eff = effn = None
            if r[17] and key(r) in ref:
                s0, spn0 = ref[key(r)]
                scale = r0 / r[2] if mode == "strong" else 1.0
                eff = scale * s0 / float(r[17])
                effn = scale * spn0 / float(r[18]) if spn0 and r[18] else None
            r[19], r[20] = fmt(eff, "%.4f"), fmt(effn, "%.4f")
    rows.sort(key=lambda r: (r[0], r[1], r[2]))
    with open(out_csv, "w", newline="") as f:
        f.writelines(header)
        w = csv.writer(f)
        w.writerow(COLS)
        w.writerows(rows)
    print("wrote", out_csv)
    for r in rows:
        print(f"{r[0]:6s} r={r[2]} N={r[3]} {r[4]:7s} level {r[8]:>3s} newton {r[12]:>6s} seconds {r[17]:>9s}"
              f" s/newton {r[18]:>8s} eff {r[19]:>6s} eff/nwt {r[20]:>6s} maxMiB {r[6]}")
    plot(rows, out_png, f"merged: {', '.join(os.path.basename(p) for p in paths)}")


def plot(rows, png, title):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 3, figsize=(14, 4.5))
    groups = sorted({(r[0], r[1]) for r in rows})
    name = lambda g: g[0] + (f" {os.path.splitext(os.path.basename(g[1]))[0]}" if g[1] != "none" else "")
    for gi, g in enumerate(groups):
        color = f"C{gi}"
        sel = [r for r in rows if (r[0], r[1]) == g]
        ranks = sorted({r[2] for r in sel})
        for k, rk in enumerate(ranks):
            lv = [r for r in sel if r[2] == rk and r[8] not in ("", "all")]
            if lv:
                ax[0].loglog([float(r[9]) for r in lv], [float(r[17]) for r in lv], "os^vD<>"[k % 7] + "-",
                           color=color, alpha=1.0 - 0.6 * k / max(len(ranks), 2), label=f"{name(g)} r={rk}")
        tot = [r for r in sel if r[8] == "all"]
        for col, style, lab in ((19, "o-", "time"), (20, "s--", "time/Newton")):
            pts = [(r[2], float(r[col])) for r in tot if r[col]]
            if pts:
                ax[1].plot(*zip(*pts), style, color=color, label=f"{name(g)}, {lab}")
        for col, style, lab, div in ((6, "o-", "max", False), (7, "s--", "mean", True)):
            pts = [(r[2], float(r[col]) / (r[2] if div else 1)) for r in sel if r[8] in ("all", "") and r[col]]
            if pts:
                ax[2].plot(*zip(*pts), style, color=color, label=f"{name(g)}, {lab}")
    ax[0].set(xlabel="P / E (level)", ylabel="seconds per level")
    ax[1].set(xlabel="ranks", ylabel="parallel efficiency (all levels)", ylim=(0, 1.2))
    ax[1].axhline(1.0, color="gray", lw=0.5)
    ax[2].set(xlabel="ranks", ylabel="memory per rank [MiB]", ylim=(0, None))
    for a in ax:
        if a.get_legend_handles_labels()[0]:
            a.legend(fontsize=7)
        if a is not ax[0]:
            a.set_xticks(sorted({r[2] for r in rows}))
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    print("wrote", png)


if __name__ == "__main__":
    main()

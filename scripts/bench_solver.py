#!/usr/bin/python3
"""Level-solver benchmark: the strategies of -level_solver side by side.

Runs build/bin/compact once per (scene, strategy) and records per pressure
level: Newton iterations (linearizations), numeric factorizations, seconds,
phi, P_sigma/P, the largest net force on a body and the largest nodal force
(both / P <d>), and the deepest penetration. Every run of a scene uses the
same options except -level_solver (and -load_step_policy), so the rows
compare the strategies on the same packing and load path. A strategy is
SOLVER (compact's default sub-stepping) or SOLVER/POLICY, e.g.
anchored/adaptive = -level_solver anchored -load_step_policy adaptive,
optionally followed by ':' and more compact options, e.g.
'anchored:-level_body_criterion false'.

Scenes (--scenes):
  default     petsc-options/default.opts (20 disks, kappa 0.5, friction 0.2)
  campaign50  the eight 50-disk runs kappa {0.2, 0.5, 0.8, 1} x friction {0, 0.2}
  frictionless  the default scene with friction 0 and the four frictionless 50-disk runs
  frictional  the default scene and the four frictional (0.2) 50-disk runs
  large400    400 disks, kappa 0.5 friction 0.2 and kappa 1 friction 0
  paper200    petsc-options/paper.opts with 200 disks (kappa 0.5, friction 0.2): the paper's scene and load
              path at a size whose levels take seconds to a minute
  paper1500   petsc-options/paper.opts (1500 disks, kappa 0.5, friction 0.2, -constrain_rotation true) on --ranks ranks
--pressures replaces the pressure list of the 50-, 200-, 400- and 1500-disk runs.

Outputs: <out>.csv (one row per level and run; '#' lines: machine, commit,
command) and <out>.png (Newton iterations per level and seconds per run).
--jobs 2 runs two simulations at a time: Newton iterations and
factorizations are unaffected, seconds are then those of a shared machine.
--baseline EXE adds the strategy "baseline": another compact binary (an
earlier commit, built from a worktree) with its own default level solver;
--baseline-env VAR=VALUE ... sets its environment (for instance
LD_LIBRARY_PATH=/usr/lib/x86_64-linux-gnu/blas:/usr/lib/x86_64-linux-gnu/lapack:
the reference BLAS instead of OpenBLAS).
--restart FILE starts every run from the checkpoint FILE (compact's
-restart; the scenes' options must be the checkpoint's) and leaves the
checkpoint's levels out of the rows: every strategy then solves the same
levels from the same state, a paired comparison (bit for bit repeatable
on one rank; on two, MUMPS' parallel factorization differs in its last
digits from run to run, docs/parallel.md, and a whole curve from its
settling is one sample of its path).
--restart-levels DIR solves every level of a run on its own, from the
checkpoint of the level before it (checkpoint_level_<k>.h5 of a reference
run with compact -checkpoint_levels true; its curve.csv gives the
pressures): every strategy then starts every level from the same state, so
a difference on one level does not carry over to the path of the next
(the levels of the reference curve after its first checkpoint, one run
each). DIR is the reference run's output directory, or the --runs
directory of a bench_solver invocation with --extra "-checkpoint_levels
true" (the reference of run LABEL is then its subdirectory LABEL_*).
--reuse reads the runs that an earlier invocation with the same arguments
left in --runs (their curve.csv and log.txt) instead of running them.

Usage:
  /usr/bin/python3 scripts/bench_solver.py --scenes default
  /usr/bin/python3 scripts/bench_solver.py --scenes default campaign50 --pressures 1e-4,3e-4,1e-3,3e-3,0.01,0.02,0.05 --jobs 2
  /usr/bin/python3 scripts/bench_solver.py --strategies anchored/whole anchored/adaptive newton/whole newton/adaptive
  /usr/bin/python3 scripts/bench_solver.py --scenes paper1500 --ranks 1 --jobs 2 --strategies auto --baseline OLD/compact --restart CHECKPOINT
  /usr/bin/python3 scripts/bench_solver.py --scenes paper1500 --ranks 1 --jobs 2 --strategies auto --baseline OLD/compact --restart-levels REFDIR
"""
import argparse
import concurrent.futures as cf
import csv
import math
import os
import re
import subprocess
import sys
import textwrap
import time

from provenance import git_commit, machine

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CAMPAIGN_PRESSURES = "1e-4,3e-4,1e-3,3e-3,0.01,0.02,0.05,0.1,0.15,0.2,0.25,0.3,0.4,0.5"


def scene_runs(a):
    """(scene, label, ranks, options) of every run, without -level_solver."""
    runs = []
    p = a.pressures
    # The paper's scene (petsc-options/paper.opts, kappa 0.5, friction 0.2) and its pressures.
    paper = ["-options_file", os.path.join(ROOT, "petsc-options", "paper.opts"), "-kappa", "0.5", "-friction", "0.2"] \
        + (["-pressures", p] if p else [])
    for s in a.scenes:
        if s == "default":
            runs.append((s, "n20_k0.5_mu0.2", 1, ["-options_file", os.path.join(ROOT, "petsc-options", "default.opts")]))
        elif s == "campaign50":
            for mu in (0.0, 0.2):
                for k in (0.2, 0.5, 0.8, 1.0):
                    runs.append((s, f"n50_k{k:g}_mu{mu:g}", 1, ["-n_particles", "50", "-kappa", str(k), "-friction", str(mu),
                                                               "-pressures", p or CAMPAIGN_PRESSURES]))
        elif s == "frictionless":
            # The frictionless scenes: the default scene without friction and the
            # four frictionless 50-disk campaign runs.
            runs.append((s, "n20_k0.5_mu0", 1, ["-options_file", os.path.join(ROOT, "petsc-options", "default.opts"),
                                                "-friction", "0"]))
            for k in (0.2, 0.5, 0.8, 1.0):
                runs.append((s, f"n50_k{k:g}_mu0", 1, ["-n_particles", "50", "-kappa", str(k), "-friction", "0",
                                                       "-pressures", p or CAMPAIGN_PRESSURES]))
        elif s == "frictional":
            # The default scene and the four frictional 50-disk campaign runs.
            runs.append((s, "n20_k0.5_mu0.2", 1, ["-options_file", os.path.join(ROOT, "petsc-options", "default.opts")]))
            for k in (0.2, 0.5, 0.8, 1.0):
                runs.append((s, f"n50_k{k:g}_mu0.2", 1, ["-n_particles", "50", "-kappa", str(k), "-friction", "0.2",
                                                         "-pressures", p or CAMPAIGN_PRESSURES]))
        elif s == "large400":
            for k, mu in ((0.5, 0.2), (1.0, 0.0)):
                runs.append((s, f"n400_k{k:g}_mu{mu:g}", 1, ["-n_particles", "400", "-kappa", str(k), "-friction", str(mu),
                                                            "-pressures", p or CAMPAIGN_PRESSURES]))
        elif s == "paper200":
            runs.append((s, "n200_k0.5_mu0.2", 1, paper + ["-n_particles", "200"]))
        elif s == "paper1500":
            # The rotation gauges during the frictionless settling: without them that
            # level of this scene does not converge (docs/level-solver-measurements.md).
            runs.append((s, "n1500_k0.5_mu0.2", a.ranks, paper + ["-constrain_rotation", "true"]))
        else:
            sys.exit(f"unknown scene {s}: use default, campaign50, frictionless, frictional, large400, paper200 or paper1500")
    return runs


def level_starts(a, label):
    """[(tag, checkpoint, pressures)] of --restart-levels for run `label`: level
    k + 1 of the reference curve from its checkpoint_level_<k>.h5, with
    -pressures up to it. The reference run is DIR itself or the one
    subdirectory of DIR named <label>_* (the runs of an earlier bench_solver
    invocation with --runs DIR)."""
    ref = a.restart_levels
    subs = [d for d in sorted(os.listdir(ref)) if d.startswith(label + "_") and os.path.isdir(os.path.join(ref, d))] \
        if os.path.isdir(ref) else []
    if len(subs) > 1:
        sys.exit(f"--restart-levels {ref}: several reference runs of {label}: {' '.join(subs)}")
    if subs:
        ref = os.path.join(ref, subs[0])
    curve = os.path.join(ref, "curve.csv")
    if not os.path.exists(curve):
        sys.exit(f"--restart-levels {a.restart_levels}: no curve.csv of {label} (the directory of a compact run with "
                 "-checkpoint_levels true, or of bench_solver runs with --extra \"-checkpoint_levels true\")")
    with open(curve) as f:
        pressures = [float(r["P_over_E"]) for r in csv.DictReader(f)]
    starts = []
    for k in range(len(pressures) - 1):
        path = os.path.join(ref, f"checkpoint_level_{k:04d}.h5")
        if os.path.exists(path):
            starts.append((f"_L{k + 1:02d}", path, ",".join(repr(p) for p in pressures[:k + 2])))
    if not starts:
        sys.exit(f"--restart-levels {ref}: no checkpoint_level_<k>.h5 before its last level")
    return starts


def run_one(a, scene, label, ranks, opts, strategy, start=("", "", "")):
    tag, restart, pressures = start
    restart = restart or a.restart
    if pressures:
        opts = opts + ["-pressures", pressures]
    out = os.path.join(a.runs, f"{label}{tag}_" + "".join(c if c.isalnum() or c in "._" else "_" for c in strategy))
    os.makedirs(out, exist_ok=True)
    env = None
    if strategy == "baseline":
        exe, solver = a.baseline, []
        env = dict(os.environ, **dict(kv.split("=", 1) for kv in a.baseline_env))
    else:  # SOLVER[/POLICY][:OPTIONS]: -level_solver SOLVER [-load_step_policy POLICY] [OPTIONS]
        spec, _, options = strategy.partition(":")
        name, _, policy = spec.partition("/")
        exe, solver = a.exe, ["-level_solver", name] + (["-load_step_policy", policy] if policy else []) + options.split()
    mpi = [a.mpiexec, "--allow-run-as-root", "-n", str(ranks)] if ranks > 1 else []
    if env and mpi:
        mpi += [x for kv in a.baseline_env for x in ("-x", kv.split("=", 1)[0])]
    cmd = mpi + \
          [exe] + opts + solver + ["-output_dir", out, "-checkpoint", "false"] + a.extra.split() + \
          (["-restart", restart] if restart else [])
    log = os.path.join(out, "log.txt")
    t0 = time.time()
    if a.reuse:
        if not os.path.exists(log):
            sys.exit(f"--reuse: no run in {out} (run the benchmark without --reuse first)")
        with open(log) as f:
            text = f.read()
        status = "ok" if "wrote " in text else "failed"
    else:
        # The run's output goes to log.txt as it comes (a long run's progress
        # lines can be followed there), after the command line.
        with open(log, "w") as f:
            f.write(" ".join((["env"] + a.baseline_env if env else []) + cmd) + "\n")
            f.flush()
            try:
                p = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT, timeout=a.timeout, env=env)
                status = "ok" if p.returncode == 0 else "failed"
            except subprocess.TimeoutExpired:
                status = "timeout"
        with open(log) as f:
            text = f.read()
    wall = time.time() - t0
    # A restarted run's curve.csv begins with the checkpoint's levels.
    done = re.search(r"restart from .*: (\d+) level\(s\) done", text)
    skip = int(done.group(1)) if done else 0
    rows = []
    curve = os.path.join(out, "curve.csv")
    if os.path.exists(curve):
        with open(curve) as f:
            for i, r in enumerate(csv.DictReader(f)):
                if i < skip:
                    continue
                P = float(r["P_over_E"])
                rows.append({
                    "scene": scene, "run": label, "strategy": strategy, "ranks": ranks, "status": status,
                    "P_over_E": P, "newton_its": int(float(r["newton_its"])),
                    "factorizations": int(float(r.get("factorizations", r["newton_its"]))),
                    "seconds": float(r["seconds"]),
                    "phi": float(r["phi"]), "P_sigma_over_P": float(r["P_sigma_over_E"]) / P,
                    "body_force_over_Pd": float(r.get("body_force_over_Pd", "nan")),
                    "node_force_over_Pd": float(r["force_residual_over_Pd"]),
                    "max_penetration": float(r["max_penetration"]), "substeps": int(float(r["substeps"])),
                    "cuts": int(float(r["cuts"]))})
    return status, wall, rows


def summary(rows, runs, strategies):
    print(f"{'run':22s} {'strategy':9s} {'status':8s} {'levels':>6s} {'its':>6s} {'median':>6s} {'max':>5s} "
          f"{'LU':>6s} {'seconds':>8s} {'phi_last':>9s} {'|Ps/P-1|':>9s} {'body F':>8s}")
    for scene, label, ranks, _ in runs:
        for s in strategies:
            r = [x for x in rows if x["run"] == label and x["strategy"] == s]
            st = status_of.get((label, s), "?")
            if not r:
                print(f"{label:22s} {s:9s} {st:8s} {0:6d}")
                continue
            its = sorted(x["newton_its"] for x in r)
            med = its[len(its) // 2] if len(its) % 2 else 0.5 * (its[len(its) // 2 - 1] + its[len(its) // 2])
            print(f"{label:22s} {s:9s} {st:8s} {len(r):6d} {sum(its):6d} {med:6.1f} {its[-1]:5d} "
                  f"{sum(x['factorizations'] for x in r):6d} {sum(x['seconds'] for x in r):8.1f} {r[-1]['phi']:9.6f} "
                  f"{max(abs(x['P_sigma_over_P'] - 1) for x in r):9.2e} "
                  f"{max((x['body_force_over_Pd'] for x in r), key=lambda v: -1 if math.isnan(v) else v):8.1e}")


status_of = {}


def plot(rows, runs, strategies, path, title):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 2, figsize=(13, 5))
    markers = {"baseline": "^", "anchored": "o", "newton": "s"}
    labels = [label for _, label, _, _ in runs]
    for s in strategies:
        for i, label in enumerate(labels):
            r = [x for x in rows if x["run"] == label and x["strategy"] == s]
            ax[0].semilogx([x["P_over_E"] for x in r], [x["newton_its"] for x in r], marker=markers.get(s, "x"),
                           color=f"C{i}", ls={"newton": "-", "anchored": ":"}.get(s, "--"), ms=4,
                           label=f"{label} {s}" if len(labels) <= 10 else None)
    ax[0].set_xlabel("P/E")
    ax[0].set_ylabel("Newton iterations per level")
    ax[0].set_yscale("log")
    ax[0].legend(fontsize=6, ncol=2)
    width = 0.8 / len(strategies)
    for j, s in enumerate(strategies):
        secs = [sum(x["seconds"] for x in rows if x["run"] == label and x["strategy"] == s) for label in labels]
        bars = ax[1].bar([i + j * width for i in range(len(labels))], secs, width, label=s)
        for b, label in zip(bars, labels):
            if status_of.get((label, s)) != "ok":
                ax[1].annotate(status_of.get((label, s), "?"), (b.get_x(), b.get_height()), fontsize=6, rotation=90)
    ax[1].set_xticks([i + 0.4 - width / 2 for i in range(len(labels))])
    ax[1].set_xticklabels(labels, rotation=45, ha="right", fontsize=7)
    ax[1].set_ylabel("seconds (levels reached)")
    ax[1].legend()
    fig.suptitle("\n".join(textwrap.wrap(title, 160)), fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", nargs="+", default=["default"])
    ap.add_argument("--strategies", nargs="+", default=["hybrid", "auto"])
    ap.add_argument("--only", nargs="+", default=[], help="run labels to keep (e.g. n400_k0.5_mu0.2); default: all")
    ap.add_argument("--pressures", default="", help="P/E list of the 50-, 400- and 1500-disk runs")
    ap.add_argument("--ranks", type=int, default=2, help="MPI ranks of paper1500")
    ap.add_argument("--jobs", type=int, default=1, help="simulations at a time")
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per run")
    ap.add_argument("--exe", default=os.path.join(ROOT, "build", "bin", "compact"))
    ap.add_argument("--baseline", default="", help="compact binary of an earlier commit (strategy 'baseline')")
    ap.add_argument("--baseline-env", nargs="*", default=[], metavar="VAR=VALUE",
                    help="environment of the baseline runs (e.g. LD_LIBRARY_PATH of another BLAS)")
    ap.add_argument("--mpiexec", default="mpiexec")
    ap.add_argument("--extra", default="", help="extra compact options for every run")
    ap.add_argument("--restart", default="", help="checkpoint every run starts from (compact -restart)")
    ap.add_argument("--restart-levels", default="", metavar="DIR",
                    help="solve every level on its own from DIR/checkpoint_level_<k>.h5 (compact -checkpoint_levels true)")
    ap.add_argument("--reuse", action="store_true", help="read the runs left in --runs instead of running them")
    ap.add_argument("--runs", default=os.path.join(ROOT, "out", "bench_solver"))
    ap.add_argument("--out", default=os.path.join(ROOT, "benchmarks", "solver"))
    a = ap.parse_args()
    if a.baseline and "baseline" not in a.strategies:
        a.strategies.insert(0, "baseline")
    runs = scene_runs(a)
    if a.only:
        unknown = set(a.only) - {label for _, label, _, _ in runs}
        if unknown:
            sys.exit(f"--only {' '.join(sorted(unknown))}: not a run of --scenes {' '.join(a.scenes)}")
        runs = [r for r in runs if r[1] in a.only]
    rows = []
    if a.restart_levels and a.restart:
        sys.exit("--restart and --restart-levels exclude each other")
    jobs = [(scene, label, ranks, opts, s, st) for scene, label, ranks, opts in runs
            for st in (level_starts(a, label) if a.restart_levels else [("", "", "")]) for s in a.strategies]
    with cf.ThreadPoolExecutor(max_workers=a.jobs) as pool:
        futs = {pool.submit(run_one, a, *j): j for j in jobs}
        for f in cf.as_completed(futs):
            scene, label, ranks, opts, s, st = futs[f]
            status, wall, r = f.result()
            if status_of.get((label, s), "ok") == "ok":  # a run of several levels: its first failure
                status_of[(label, s)] = status
            rows += r
            print(f"  {label}{st[0]} {s}: {status}, {len(r)} levels, {sum(x['newton_its'] for x in r)} Newton its, "
                  f"{wall:.0f} s", flush=True)
    order = {label: i for i, (_, label, _, _) in enumerate(runs)}
    rows.sort(key=lambda x: (order[x["run"]], a.strategies.index(x["strategy"]), x["P_over_E"]))
    header = (f"# machine: {machine()}; commit {git_commit()}; "
              f"{a.jobs} simulation(s) at a time\n# command: {' '.join(sys.argv)}\n")
    os.makedirs(os.path.dirname(a.out) or ".", exist_ok=True)
    with open(a.out + ".csv", "w", newline="") as f:
        f.write(header)
        fields = ["scene", "run", "strategy", "ranks", "status", "P_over_E", "newton_its", "factorizations", "seconds",
                  "substeps", "cuts", "phi", "P_sigma_over_P", "body_force_over_Pd", "node_force_over_Pd",
                  "max_penetration"]
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.12g}" if isinstance(v, float) else v) for k, v in r.items()})
    summary(rows, runs, a.strategies)
    plot(rows, runs, a.strategies, a.out + ".png", header.replace("\n", "  ").replace("# ", ""))
    print(f"wrote {a.out}.csv and {a.out}.png")


if __name__ == "__main__":
    main()

#!/usr/bin/python3
"""Command-line tests of the single-particle driver (registered in CTest).

    driver_tests.py --driver BIN --workdir DIR CASE [-- extra arguments]

Cases
  stability-unit-load      92 triangles, nu = 0.495, levels up to P/E = 1
  stability-incompressible nu = 0.4999 up to P/E = 0.5
  jump                     0 -> 0.5 in one requested level vs the stepped run (the default level
                           solver, and anchored, whose jump at nu = 0.4999 needs cut sub-steps)
  forced-failure           -load_max_cuts 0 on a jump that needs cuts (anchored): clear error, non-zero exit
  beyond-limit-point       nu = -0.9 past its limit load: clear error, non-zero exit, no endless creep
  bad-input --expect RE -- ARGS
                           ARGS must be refused: non-zero exit, RE in the output,
                           a pre-existing results directory left byte-identical
  help                     -help exits 0, lists the driver options with defaults, writes nothing
  unused-option            a misspelt option is refused by name before anything is written
  mpi --mpiexec BIN        curve.csv and levels.h5 of -n 2 and -n 3 equal the serial run
  restart                  a run stopped after two levels and continued with -restart from its
                           checkpoint.h5 repeats the three-level run bit for bit (curve.csv but
                           its seconds, levels.h5); a checkpoint of another scene or driver is refused

Every run's curve.csv is checked row by row: no inverted element
(min_cell_area_ratio > 0), no penetration, wall balance, phi <= 1.
"""
import argparse
import csv
import filecmp
import math
import os
import re
import shutil
import subprocess
import sys

COLUMNS = ["P_over_E", "phi", "area_ratio", "newton_its", "seconds", "substeps", "cuts", "box_width",
           "box_height", "wall_force_error", "max_penetration", "min_cell_area_ratio", "active_contacts"]
DEFAULT_LEVELS = [1e-4, 1e-3, 5e-3, 0.01, 0.02, 0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5]

failures = []


def check(cond, message):
    print(("  ok    " if cond else "  FAIL  ") + message)
    if not cond:
        failures.append(message)
    return cond


def run(cmd, timeout=240):
    print("$ " + " ".join(cmd))
    p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=timeout)
    return p.returncode, p.stdout


def fresh_dir(path):
    shutil.rmtree(path, ignore_errors=True)
    return path


def read_curve(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    check(rows and rows[0] == COLUMNS, f"{path}: header is {rows[0] if rows else None}")
    return [dict(zip(rows[0], map(float, r))) for r in rows[1:]]


def check_rows(rows, levels, label, nu):
    """Per-row invariants of a converged curve (independent of the solver internals)."""
    check(len(rows) == len(levels), f"{label}: {len(rows)} rows for {len(levels)} levels")
    for r, P in zip(rows, levels):
        tag = f"{label} P/E={P:g}"
        check(abs(r["P_over_E"] - P) <= 1e-12 * max(P, 1e-300), f"{tag}: P_over_E column {r['P_over_E']}")
        check(r["min_cell_area_ratio"] > 0.0, f"{tag}: min_cell_area_ratio {r['min_cell_area_ratio']:.6g} > 0")
        check(r["max_penetration"] <= 1e-10, f"{tag}: max_penetration {r['max_penetration']:.3e} <= 1e-10")
        check(r["wall_force_error"] <= 1e-10, f"{tag}: wall_force_error {r['wall_force_error']:.3e} <= 1e-10")
        check(r["phi"] <= 1.0 + 1e-12, f"{tag}: phi {r['phi']:.12g} <= 1")
        check(r["substeps"] >= 1, f"{tag}: at least one accepted sub-step")
        # phi = particle area / box area, with particle area = area_ratio * pi/4 (the
        # order-2 disk of diameter 1 has area pi/4 to ~1e-5).
        phi_from_columns = r["area_ratio"] * math.pi / 4 / (r["box_width"] * r["box_height"])
        check(abs(phi_from_columns - r["phi"]) <= 5e-5,
              f"{tag}: phi {r['phi']:.9f} vs area_ratio * (pi/4) / box area {phi_from_columns:.9f}")
        # Linear-elastic area change from the exact mean stress -P/phi (virial):
        # 1 - A/A0 ~ 2 (1 + nu)(1 - 2 nu) P / (E phi); nonlinear terms stay below 10 %.
        predicted = 2 * (1 + nu) * (1 - 2 * nu) * P / r["phi"]
        if P > 0:
            ratio = (1 - r["area_ratio"]) / predicted
            check(0.9 < ratio < 1.1, f"{tag}: area change / linear prediction = {ratio:.4f}")
    for a, b in zip(rows, rows[1:]):
        # phi rises until the coarse disk fills the box (phi = 1: nodes in the corners).
        check(b["phi"] > a["phi"] or a["phi"] >= 1 - 1e-12,
              f"{label}: phi increases from P/E={a['P_over_E']:g} to {b['P_over_E']:g} (or stays at 1)")
        check(b["area_ratio"] < a["area_ratio"], f"{label}: area decreases from P/E={a['P_over_E']:g}")


def check_hdf5(path, levels, label):
    """Every cell of every stored level has a positive area ratio."""
    try:
        import h5py
    except ImportError:
        check(False, "h5py missing (apt-get install python3-h5py): cannot check the per-cell area ratios")
        return
    with h5py.File(path, "r") as f:
        groups = sorted(k for k in f.keys() if k.startswith("level_"))
        check(len(groups) == len(levels), f"{label}: {len(groups)} HDF5 levels for {len(levels)}")
        worst = min(float(f[g]["body_0"]["cell_area_ratio"][()].min()) for g in groups)
        check(worst > 0.0, f"{label}: smallest cell area ratio over all HDF5 levels {worst:.6g} > 0")


def driver_run(args, out, extra, label, levels, nu=0.495):
    rc, log = run([args.driver, "-output_dir", out, "-pressures", ",".join(f"{p:g}" for p in levels),
                   "-nu", f"{nu:g}", "-options_left", "0"] + extra)
    if not check(rc == 0, f"{label}: exit code {rc}"):
        print(log[-3000:])
        return None
    rows = read_curve(os.path.join(out, "curve.csv"))
    check_rows(rows, levels, label, nu)
    check_hdf5(os.path.join(out, "levels.h5"), levels, label)
    return rows


# ---------------------------------------------------------------------------
def case_stability_unit_load(args):
    levels = [1e-4, 1e-3, 0.01, 0.05, 0.1, 0.2, 0.3, 0.5, 0.7, 0.85, 1.0]
    driver_run(args, fresh_dir(os.path.join(args.workdir, "unit-load")), [], "nu=0.495", levels)


def case_stability_incompressible(args):
    driver_run(args, fresh_dir(os.path.join(args.workdir, "incompressible")), [], "nu=0.4999", DEFAULT_LEVELS,
               nu=0.4999)


def case_jump(args):
    # The default level solver jumps; anchored needs cut sub-steps at nu = 0.4999 (the load controller's halving).
    for nu, solver, must_cut in ((0.495, [], False), (0.4999, [], False), (0.4999, ["-level_solver", "anchored"], True)):
        name = f"{nu}" + ("-" + solver[-1] if solver else "")
        stepped = driver_run(args, fresh_dir(os.path.join(args.workdir, f"stepped-{name}")), solver,
                             f"stepped nu={nu} {' '.join(solver)}", DEFAULT_LEVELS, nu)
        jump = driver_run(args, fresh_dir(os.path.join(args.workdir, f"jump-{name}")), solver,
                          f"jump nu={nu} {' '.join(solver)}", [0.5], nu)
        if not stepped or not jump:
            continue
        j = jump[0]
        print(f"  info  nu={nu} {' '.join(solver)}: the single jump 0 -> 0.5 took {j['substeps']:.0f} sub-steps and"
              f" {j['cuts']:.0f} cuts ({j['newton_its']:.0f} Newton iterations)")
        if must_cut:
            check(j["substeps"] > 1 and j["cuts"] >= 1,
                  f"nu={nu} {' '.join(solver)}: the jump needs sub-stepping (substeps {j['substeps']:.0f} > 1,"
                  f" cuts {j['cuts']:.0f} >= 1)")
        check(abs(j["phi"] - stepped[-1]["phi"]) <= 1e-6,
              f"nu={nu} {' '.join(solver)}: phi after the jump {j['phi']:.12f} equals the stepped phi"
              f" {stepped[-1]['phi']:.12f} to 1e-6")


def case_forced_failure(args):
    out = fresh_dir(os.path.join(args.workdir, "forced-failure"))
    rc, log = run([args.driver, "-output_dir", out, "-pressures", "0.5", "-nu", "0.4999", "-load_max_cuts", "0",
                   "-level_solver", "anchored"])
    check(rc != 0, f"exit code {rc} != 0")
    check(re.search(r"pressure level P = 0\.5 not reached", log) is not None, "message names the level not reached")
    check("-load_max_cuts" in log, "message suggests -load_max_cuts")
    curve = os.path.join(out, "curve.csv")
    rows = read_curve(curve) if os.path.exists(curve) else []
    check(len(rows) == 0, f"no level reported as converged ({len(rows)} rows)")


def case_beyond_limit_point(args):
    """nu = -0.9 gives lambda < 0: the neo-Hookean law softens in compression and the
    disk has a limit load near P/E = 0.364. A level beyond it has no equilibrium on
    this branch: the load controller must give up with a clear message, not creep
    towards the limit point for ever (hang guard: a run that stops takes about a minute,
    15 halved sub-steps, each failing after up to -level_max_its linearizations)."""
    out = fresh_dir(os.path.join(args.workdir, "beyond-limit-point"))
    cmd = [args.driver, "-output_dir", out, "-pressures", "0.1,0.5", "-nu", "-0.9"]
    try:
        rc, log = run(cmd, timeout=180)
    except subprocess.TimeoutExpired:
        check(False, "the driver stops at a level beyond the limit point (still running after 180 s: hang guard)")
        return
    check(rc != 0, f"exit code {rc} != 0")
    check(re.search(r"pressure level P = 0\.5 not reached", log) is not None, "message names the level not reached")
    rows = read_curve(os.path.join(out, "curve.csv"))
    check(len(rows) == 1 and rows[0]["P_over_E"] == 0.1, "the level before the limit point is kept in curve.csv")
    check_rows(rows, [0.1], "nu=-0.9", -0.9)


def make_sentinel(out):
    """A results directory from an earlier run, to be left untouched."""
    fresh_dir(out)
    os.makedirs(out)
    with open(os.path.join(out, "curve.csv"), "w") as f:
        f.write(",".join(COLUMNS) + "\n" + ",".join(["0.25"] * len(COLUMNS)) + "\n")
    with open(os.path.join(out, "levels.h5"), "wb") as f:
        f.write(b"earlier results\n")
    ref = out + ".reference"
    fresh_dir(ref)
    shutil.copytree(out, ref)
    return ref


def check_untouched(out, ref):
    names = sorted(os.listdir(ref))
    check(sorted(os.listdir(out)) == names, f"{out}: no file added or removed")
    match, mismatch, errors = filecmp.cmpfiles(ref, out, names, shallow=False)
    check(not mismatch and not errors, f"{out}: existing results byte-identical (changed: {mismatch + errors})")


def case_bad_input(args):
    out = os.path.join(args.workdir, "bad-input")
    ref = make_sentinel(out)
    extra = ["" if a == "<empty>" else a for a in args.extra]
    if "-output_dir" not in extra:
        extra = ["-output_dir", out] + extra
    rc, log = run([args.driver] + extra)
    print("\n".join("  | " + l for l in log.splitlines()[:12]))
    check(rc != 0, f"exit code {rc} != 0")
    check(re.search(args.expect, log) is not None, f"output matches /{args.expect}/")
    check(re.search(r"P/E\s+phi_p", log) is None, "no pressure level was started")
    check_untouched(out, ref)


def case_help(args):
    out = os.path.join(args.workdir, "help")
    ref = make_sentinel(out)
    rc, log = run([args.driver, "-help", "-output_dir", out])
    check(rc == 0, f"exit code {rc} == 0")
    # Each option with its default value as PETSc prints it: "-name <default ...".
    for opt, default in (("-E", r"1\."), ("-nu", r"0\.495"), ("-mesh_triangles", r"(now )?92"),
                         ("-output_dir", r"(now )?" + re.escape(out)), ("-element_order", r"(now )?2"),
                         ("-load_max_cuts", r"(now )?16"), ("-contact_ncp", r"(now )?min")):
        check(re.search(r"^\s*" + re.escape(opt) + r" <" + default, log, re.M) is not None,
              f"-help lists {opt} with its default")
    check(re.search(r"^\s*-pressures\b.*0\.0001.*0\.5", log, re.M) is not None,
          "-help lists -pressures with its default levels")
    check(re.search(r"P/E\s+phi_p", log) is None, "-help does not run")
    check_untouched(out, ref)


def case_unused_option(args):
    out = fresh_dir(os.path.join(args.workdir, "unused-option"))
    rc, log = run([args.driver, "-output_dir", out, "-pressures", "0.01", "-nuu", "0.3"])
    check(rc != 0, f"a misspelt option is refused (exit code {rc})")
    check(re.search(r"unknown option\(s\) -nuu", log) is not None, "the message names the misspelt option -nuu")
    check(not os.path.exists(out), "nothing is written")


def case_mpi(args):
    levels = [1e-3, 0.02, 0.1, 0.3, 0.5]
    runs = {}
    for n in (1, 2, 3):
        out = fresh_dir(os.path.join(args.workdir, f"mpi-{n}"))
        cmd = [args.driver] if n == 1 else [args.mpiexec, "-n", str(n), "--oversubscribe", args.driver]
        rc, log = run(cmd + ["-output_dir", out, "-pressures", ",".join(map(str, levels)), "-options_left", "0"])
        if not check(rc == 0, f"{n} rank(s): exit code {rc}"):
            print(log[-3000:])
            continue
        rows = read_curve(os.path.join(out, "curve.csv"))
        check_rows(rows, levels, f"{n} rank(s)", 0.495)
        runs[n] = (out, rows)
    if 1 not in runs:
        return
    serial = runs[1][1]
    for n in (2, 3):
        if n not in runs:
            continue
        rows = runs[n][1]
        check(len(rows) == len(serial), f"{n} ranks: {len(rows)} rows, serial {len(serial)}")
        for col in ("phi", "area_ratio", "box_width", "box_height"):
            worst = max((abs(a[col] - b[col]) / abs(b[col]) for a, b in zip(rows, serial)), default=0.0)
            check(worst <= 1e-10, f"{n} ranks: {col} equals serial (max relative difference {worst:.2e} <= 1e-10)")
        its = [(a["newton_its"], b["newton_its"]) for a, b in zip(rows, serial)]
        print(f"  info  {n} ranks: Newton iterations (parallel, serial) per level: {its}")
        try:
            import h5py
            import numpy
        except ImportError:
            check(False, "h5py missing (apt-get install python3-h5py): cannot compare levels.h5")
            continue
        # The whole assembly (walls + disk) may translate freely: a gauge that
        # only the proximal term holds, so roundoff moves it differently on
        # different rank counts. Positions are compared relative to the box centre.
        with h5py.File(os.path.join(runs[1][0], "levels.h5"), "r") as fs, \
                h5py.File(os.path.join(runs[n][0], "levels.h5"), "r") as fp:
            check(sorted(fs.keys()) == sorted(fp.keys()), f"{n} ranks: same HDF5 levels as serial")
            worst = drift = worst_abs = 0.0
            for g in fs.keys():
                rel = []
                for f in (fs, fp):
                    w = f[g]["walls"][()]
                    centre = numpy.array([(w[0] + w[1]) / 2, (w[2] + w[3]) / 2])
                    drift = max(drift, float(numpy.abs(centre).max()))
                    rel.append(f[g]["body_0"]["coordinates"][()] - centre)
                worst = max(worst, float(numpy.abs(rel[0] - rel[1]).max()))
                worst_abs = max(worst_abs, float(numpy.abs(fs[g]["body_0"]["coordinates"][()] -
                                                           fp[g]["body_0"]["coordinates"][()]).max()))
            print(f"  info  {n} ranks: absolute node coordinates differ from serial by up to {worst_abs:.2e}"
                  f" (rigid drift of the box centre up to {drift:.2e})")
            check(worst <= 1e-10, f"{n} ranks: node coordinates relative to the box centre equal serial"
                                  f" (max difference {worst:.2e} <= 1e-10)")
            check(drift <= 1e-6, f"rigid drift of the box centre {drift:.2e} <= 1e-6 d")


def case_restart(args):
    levels = [0.01, 0.1, 0.3]
    full = fresh_dir(os.path.join(args.workdir, "restart-full"))
    part = fresh_dir(os.path.join(args.workdir, "restart-part"))
    lv = ",".join(map(str, levels))
    rc, _ = run([args.driver, "-output_dir", full, "-pressures", lv])
    check(rc == 0, f"three-level run: exit code {rc}")
    rc, _ = run([args.driver, "-output_dir", part, "-pressures", ",".join(map(str, levels[:2]))])
    check(rc == 0, f"two-level run: exit code {rc}")
    ckpt = os.path.join(part, "checkpoint.h5")
    saved = os.path.join(args.workdir, "two-levels.h5")
    shutil.copy(ckpt, saved)
    rc, log = run([args.driver, "-output_dir", part, "-pressures", lv, "-restart", ckpt])
    check(rc == 0 and "restart from" in log, f"restart for the third level: exit code {rc}")
    a, b = read_curve(os.path.join(full, "curve.csv")), read_curve(os.path.join(part, "curve.csv"))
    check(len(a) == len(b) == 3, f"restarted curve has {len(b)} rows (3)")
    for ra, rb in zip(a, b):
        diff = [k for k in ra if k != "seconds" and ra[k] != rb[k]]
        check(not diff, f"P/E = {ra['P_over_E']:g}: restarted row equals the uninterrupted one (differs in {diff})")
    import h5py
    import numpy
    with h5py.File(os.path.join(full, "levels.h5"), "r") as fa, h5py.File(os.path.join(part, "levels.h5"), "r") as fb:
        check(sorted(fa.keys()) == sorted(fb.keys()), "levels.h5: the same levels")
        same = all(numpy.array_equal(fa[g]["body_0"]["coordinates"][()], fb[g]["body_0"]["coordinates"][()])
                   for g in fa.keys() if g in fb)
        check(same, "levels.h5: node coordinates of every level equal bit for bit")
    other = os.path.join(args.workdir, "other-driver.h5")
    shutil.copy(saved, other)
    with h5py.File(other, "r+") as f:
        del f.attrs["driver"]
        f.attrs.create("driver", numpy.bytes_("compact"))
    for extra, expect in ((["-restart", saved, "-nu", "0.49"], r"another scene \(-nu: checkpoint 0\.495, this run 0\.49\)"),
                          (["-restart", saved, "-mesh_triangles", "54"], r"-mesh_triangles: checkpoint 92, this run 54"),
                          (["-restart", other], r"was written by compact, not by single-particle")):
        ref = make_sentinel(os.path.join(args.workdir, "restart-bad"))
        rc, log = run([args.driver, "-output_dir", os.path.join(args.workdir, "restart-bad"), "-pressures", lv] + extra)
        check(rc != 0 and re.search(expect, log) is not None, f"{' '.join(extra[2:]) or 'driver'}: refused, /{expect}/")
        check_untouched(os.path.join(args.workdir, "restart-bad"), ref)


CASES = {
    "stability-unit-load": case_stability_unit_load,
    "stability-incompressible": case_stability_incompressible,
    "jump": case_jump,
    "forced-failure": case_forced_failure,
    "beyond-limit-point": case_beyond_limit_point,
    "bad-input": case_bad_input,
    "help": case_help,
    "unused-option": case_unused_option,
    "mpi": case_mpi,
    "restart": case_restart,
}


def main():
    argv = sys.argv[1:]
    extra = []
    if "--" in argv:
        i = argv.index("--")
        argv, extra = argv[:i], argv[i + 1:]
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--driver", required=True)
    ap.add_argument("--workdir", required=True)
    ap.add_argument("--mpiexec", default="mpirun")
    ap.add_argument("--expect", default=".")
    ap.add_argument("case", choices=sorted(CASES))
    args = ap.parse_args(argv)
    args.extra = extra
    os.makedirs(args.workdir, exist_ok=True)
    CASES[args.case](args)
    if failures:
        print(f"{len(failures)} check(s) failed:\n  " + "\n  ".join(failures))
        return 1
    print("all checks passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())

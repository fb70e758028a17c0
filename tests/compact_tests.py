#!/usr/bin/python3
"""Stability runs of the mixture driver `compact` (registered in CTest).

    compact_tests.py --driver BIN --workdir DIR CASE

Cases
  friction-to-half  50 disks, kappa = 0.5, friction 0.8, P/E from 1e-4 up to 0.5
  mpi               30 disks, kappa = 0.5, friction 0.3, three levels on 1, 2 and 3
                    MPI ranks (METIS partition): the same curve (phi to the level
                    criterion's 1e-4, Z to one contact)
  jump              the same scene asked for P/E = 0.1 in a single level (load
                    stepping from the settled packing inside the level), against
                    the same scene taken there in 5 levels: the friction path
                    differs only by the sub-steps, so phi must agree to 5e-3
  restart           12 disks, kappa = 0.5, friction 0.3: a run stopped after two
                    levels and restarted from its checkpoint.h5 for the third
                    repeats the three-level run bit for bit (curve.csv but its
                    seconds, levels.h5); restarted on 2 ranks it agrees to solver
                    tolerance; a restart from an earlier checkpoint rewrites the
                    later levels of levels.h5; bad checkpoints and options that do
                    not fit the checkpoint are refused with a clear message and
                    leave the existing results byte-identical
  restart-settled   the restart scene with rotation gauges: its frictional solve of the
                    settled state made to fail (-level_attempt_its 1 -ptc_max_steps 1)
                    is tried again from the settled state with anchored alone, then
                    exits non-zero naming -restart and the checkpoint of the settled
                    state it wrote; restarted from that checkpoint with the default
                    solver, the run repeats the uninterrupted one bit for bit
                    (curve.csv but its seconds, levels.h5); a first level that settles
                    at another pressure and -settle_frictionless false are refused
                    with a clear message, leaving the results byte-identical
  packing           -packing FILE: a 3 x 3 square lattice of equal rigid disks read from
                    a CSV file keeps phi = pi/4 with P d at every contact; bad files
                    (empty, missing or unknown column, text, radius <= 0, overlaps)
                    are refused with a clear message before anything is written
  settle            the default scene with -level_max_its 1: auto's newton cannot do
                    the rigid or the frictionless settling in one load step, hybrid
                    does each from the state before it (the rigid settling's line
                    says so), and the run completes; the options of their LDL^T
                    solves (-ldlt_*, -settle_ldlt_*) are read
  progress          12 disks: with -progress_interval 0 a progress line follows every
                    pseudo-time step, on 1 and on 2 ranks (printed once); the last
                    line of each sub-step counts its Newton iterations, and per
                    level they add up to curve.csv's newton_its; with
                    -progress_interval -1 there are none
  end-game          50 disks, kappa 0.2, friction 0.2 to P/E 0.03 with -ptc_monitor: the
                    end game of anchored (all of the level criterion but the contact rows
                    passes) begins on some level, and no inner solve fails after it has
                    begun (rho_a held at least at its value then)

Every row of curve.csv must satisfy: all requested levels present, phi rising
with P, no penetration beyond max(1e-9, 1e-6 P/E) <d> (the contact rows of the level
criterion over c_n), the unbalanced force within the level
criterion (force_residual_over_Pd <= 1e-4), the contact stress equal to the
imposed pressure to 1e-4 (the level criterion's bound on the virial defect),
Z > 0 and rising with compaction, no negative bulk modulus.
"""
import argparse
import csv
import filecmp
import os
import re
import shutil
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from driver_tests import check, failures  # noqa: E402  (the same check/report helpers)


SCENE = ["-n_particles", "50", "-kappa", "0.5", "-friction", "0.8", "-seed", "1"]


def run_compact(driver, out, pressures, timeout, scene=SCENE, launcher=(), extra=(), log=None):
    shutil.rmtree(out, ignore_errors=True)
    cmd = list(launcher) + [driver] + scene + ["-pressures", ",".join(str(p) for p in pressures), "-output_dir", out,
                                               "-write_hdf5", "false"] + list(extra)
    print("$ " + " ".join(cmd))
    p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=timeout)
    print(p.stdout)
    if log is not None:
        log.append(p.stdout)
    check(p.returncode == 0, f"exit code 0 (got {p.returncode})")
    path = os.path.join(out, "curve.csv")
    if not check(os.path.exists(path), "curve.csv written"):
        return []
    with open(path, newline="") as f:
        rows = [{k: float(v) for k, v in r.items()} for r in csv.DictReader(f)]
    check([r["P_over_E"] for r in rows] == pressures, f"levels {[r['P_over_E'] for r in rows]} == {pressures}")
    for i, r in enumerate(rows):
        P = r["P_over_E"]
        tag = f"P/E = {P:g}"
        if i > 0:
            check(r["phi"] > rows[i - 1]["phi"], f"{tag}: phi rises ({r['phi']:.5f})")
        # The level criterion holds the contact rows to 1e-4 of its force tolerance (1e-8 P <d>), and to
        # at least 1e-11 E <d>: a closed gap to that over c_n = 0.01 E.
        gap_tol = max(1e-11, 1e-8 * P) / 0.01
        check(r["max_penetration"] <= gap_tol, f"{tag}: max penetration {r['max_penetration']:.2e} <= {gap_tol:.0e}")
        check(r["force_residual_over_Pd"] <= 1e-4, f"{tag}: unbalanced force {r['force_residual_over_Pd']:.2e} P<d> <= 1e-4")
        # The level criterion bounds the virial defect by its force tolerance (-level_force_rtol 1e-4).
        check(abs(r["P_sigma_over_E"] / P - 1.0) <= 1e-4, f"{tag}: P_sigma / P = {r['P_sigma_over_E'] / P:.7f}")
        check(r["Z"] > 0.0 and r["Z_no_rattlers"] > 0.0, f"{tag}: Z = {r['Z']:.3f}, Z_nr = {r['Z_no_rattlers']:.3f} > 0")
        check(r["K_over_E"] > 0.0, f"{tag}: K/E = {r['K_over_E']:.3g} > 0")
    return rows


RESTART_SCENE = ["-n_particles", "12", "-kappa", "0.5", "-friction", "0.3", "-seed", "2", "-mesh_triangles", "40"]


def compact(driver, out, pressures, launcher=(), extra=()):
    """Runs compact into `out` (kept as it is); returns (exit code, output)."""
    cmd = list(launcher) + [driver] + RESTART_SCENE + ["-pressures", ",".join(str(p) for p in pressures),
                                                       "-output_dir", out] + list(extra)
    print("$ " + " ".join(cmd))
    p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=300)
    print(p.stdout)
    return p.returncode, p.stdout


def read_curve(out):
    with open(os.path.join(out, "curve.csv"), newline="") as f:
        return list(csv.DictReader(f))


def h5_levels(path):
    """{level name: {dataset path: array}} and the P_over_E attribute of each level."""
    import h5py
    import numpy as np
    levels = {}
    with h5py.File(path, "r") as f:
        for name, g in f.items():
            data = {"P_over_E": float(g.attrs["P_over_E"])}
            g.visititems(lambda k, v: data.__setitem__(k, np.array(v)) if isinstance(v, h5py.Dataset) else None)
            levels[name] = data
    return levels


def restart_case(driver, workdir, mpiexec):
    levels = [1e-4, 1e-3, 3e-3]
    full, part = os.path.join(workdir, "full"), os.path.join(workdir, "part")
    for d in (full, part):
        shutil.rmtree(d, ignore_errors=True)
    rc, _ = compact(driver, full, levels, extra=["-checkpoint_levels", "true"])
    check(rc == 0, f"three-level run: exit code {rc}")
    kept = sorted(f for f in os.listdir(full) if f.startswith("checkpoint_level_"))
    check(kept == [f"checkpoint_level_{k:04d}.h5" for k in range(3)], f"-checkpoint_levels keeps one per level: {kept}")
    rc, _ = compact(driver, part, levels[:2])
    check(rc == 0 and os.path.exists(os.path.join(part, "checkpoint.h5")), "two-level run writes checkpoint.h5")
    two_levels = os.path.join(workdir, "two-levels.h5")
    shutil.copy(os.path.join(part, "checkpoint.h5"), two_levels)
    rc, text = compact(driver, part, levels, extra=["-restart", os.path.join(part, "checkpoint.h5")])
    check(rc == 0 and "restart from" in text, f"restart for the third level: exit code {rc}")
    a = read_curve(full)
    check(len(a) == 3, f"uninterrupted curve has {len(a)} rows (3)")
    compare_runs(full, part)

    # The third level again from the second level's own checkpoint, in a copy of
    # the run's directory: the same level bit for bit, and the level checkpoints
    # of the earlier run beyond the restart are replaced (a stale fourth one goes).
    again = os.path.join(workdir, "again")
    shutil.rmtree(again, ignore_errors=True)
    shutil.copytree(full, again)
    stale = os.path.join(again, "checkpoint_level_0003.h5")
    shutil.copy(os.path.join(again, "checkpoint_level_0002.h5"), stale)
    rc, _ = compact(driver, again, levels,
                    extra=["-checkpoint_levels", "true", "-restart", os.path.join(full, "checkpoint_level_0001.h5")])
    check(rc == 0, f"restart from checkpoint_level_0001.h5: exit code {rc}")
    compare_runs(full, again)
    check(not os.path.exists(stale) and os.path.exists(os.path.join(again, "checkpoint_level_0002.h5")),
          "the restarted run rewrites checkpoint_level_0002.h5 and removes the earlier run's checkpoint_level_0003.h5")

    # On two ranks (METIS partition, distributed MUMPS): the same curve to solver tolerance.
    two = os.path.join(workdir, "two-ranks")
    shutil.rmtree(two, ignore_errors=True)
    rc, _ = compact(driver, two, levels, [mpiexec, "-n", "2", "--oversubscribe"], ["-restart", two_levels])
    check(rc == 0, f"restart on 2 ranks: exit code {rc}")
    if rc == 0:
        r1, r2 = a[-1], read_curve(two)[-1]
        check(abs(float(r2["phi"]) - float(r1["phi"])) <= 1e-4 * float(r1["phi"]),
              f"2 ranks: phi {r2['phi']} vs serial {r1['phi']} (within 1e-4 relative)")
        check(read_curve(two)[:2] == read_curve(part)[:2], "2 ranks: the checkpoint's rows are written back unchanged")

    # From an earlier checkpoint (one level) into the three-level directory, with a
    # different second level: levels.h5 loses the old levels 1 and 2.
    one = os.path.join(workdir, "one-level")
    shutil.rmtree(one, ignore_errors=True)
    compact(driver, one, levels[:1])
    early = os.path.join(workdir, "one-level.h5")
    shutil.copy(os.path.join(one, "checkpoint.h5"), early)
    redo = os.path.join(workdir, "redo")
    shutil.rmtree(redo, ignore_errors=True)
    shutil.copytree(full, redo)
    rc, _ = compact(driver, redo, [1e-4, 2e-3], extra=["-restart", early])
    check(rc == 0, f"restart from the first level into a three-level directory: exit code {rc}")
    if rc == 0:
        h = h5_levels(os.path.join(redo, "levels.h5"))
        check(sorted(h) == ["level_0000", "level_0001"] and h["level_0001"]["P_over_E"] == 2e-3,
              f"levels.h5 holds the two levels of the restarted run ({ {k: v['P_over_E'] for k, v in h.items()} })")
        check([r["P_over_E"] for r in read_curve(redo)] == ["0.0001", "0.002"], "curve.csv holds its two levels")

    # Bad restarts: refused with a message naming the problem, results untouched.
    broken = os.path.join(workdir, "broken.h5")
    with open(two_levels, "rb") as f:
        head = f.read(4096)
    with open(broken, "wb") as f:
        f.write(head)  # a checkpoint cut short (a full disk, a killed copy)
    incomplete = os.path.join(workdir, "incomplete.h5")
    shutil.copy(two_levels, incomplete)
    import h5py
    with h5py.File(incomplete, "r+") as f:
        del f["current/lambda_n"]
    cases = [
        (["-restart", os.path.join(workdir, "missing.h5")], levels, "cannot open it"),
        (["-restart", os.path.join(full, "curve.csv")], levels, "it is not an HDF5 file"),
        (["-restart", os.path.join(full, "levels.h5")], levels, "it is not a deformix checkpoint"),
        (["-restart", broken], levels, "-restart " + broken),
        (["-restart", incomplete], levels, "dataset lambda_n is missing"),
        (["-restart", two_levels, "-kappa", "0.6"], levels, "was written for another scene (-kappa: checkpoint 0.5, this run 0.6)"),
        (["-restart", two_levels, "-n_particles", "13"], levels, "(-n_particles: checkpoint 12, this run 13)"),
        (["-restart", two_levels], [1e-4, 2e-3, 3e-3], "its level 1 is P/E = 0.001, but -pressures has 0.002 there"),
        (["-restart", two_levels], levels[:2], "already holds all 2 levels of -pressures"),
        (["-restart", two_levels, "-checkpoint", "maybe"], levels, "maybe"),
    ]
    for extra, pressures, expect in cases:
        # The scene options come first; a later repeat of an option wins.
        check_refused(driver, workdir, part, pressures, extra, expect, f"{' '.join(extra[2:]) or extra[1]}")


def check_refused(driver, workdir, part, pressures, extra, expect, what):
    """Runs compact into `part` and checks it is refused with `expect` in its message, the results untouched."""
    before = sorted(os.listdir(part))
    snapshot = os.path.join(workdir, "snapshot")
    shutil.rmtree(snapshot, ignore_errors=True)
    shutil.copytree(part, snapshot)
    rc, text = compact(driver, part, pressures, extra=extra)
    check(rc != 0, f"{what}: refused (exit code {rc})")
    check(expect in text, f"message contains '{expect}'")
    match, mismatch, errors = filecmp.cmpfiles(snapshot, part, before, shallow=False)
    check(sorted(os.listdir(part)) == before and not mismatch and not errors,
          f"existing results byte-identical (changed: {mismatch + errors})")


def compare_runs(a_dir, b_dir):
    """Checks that the run in b_dir repeats the one in a_dir: curve.csv but its seconds, and levels.h5."""
    import numpy as np
    a, b = read_curve(a_dir), read_curve(b_dir)
    check(len(a) == len(b) and len(a) > 0, f"restarted curve has {len(b)} rows ({len(a)})")
    for ra, rb in zip(a, b):
        ra = {k: v for k, v in ra.items() if k != "seconds"}
        rb = {k: v for k, v in rb.items() if k != "seconds"}
        diff = [k for k in ra if ra[k] != rb.get(k)]
        check(not diff, f"P/E = {ra['P_over_E']}: restarted row equals the uninterrupted one to all digits (differs in {diff})")
    ha, hb = h5_levels(os.path.join(a_dir, "levels.h5")), h5_levels(os.path.join(b_dir, "levels.h5"))
    check(sorted(ha) == sorted(hb), f"levels.h5 groups {sorted(hb)} == {sorted(ha)}")
    same = all(k in hb[g] and np.array_equal(ha[g][k], hb[g][k]) for g in ha if g in hb for k in ha[g])
    check(same, "levels.h5 of the restarted run equals the uninterrupted one's, every dataset bit for bit")


def restart_settled_case(driver, workdir):
    levels = [1e-4, 1e-3, 3e-3]
    gauged = ["-constrain_rotation", "true"]
    full, part = os.path.join(workdir, "full"), os.path.join(workdir, "part")
    for d in (full, part):
        shutil.rmtree(d, ignore_errors=True)
    rc, _ = compact(driver, full, levels, extra=gauged)
    check(rc == 0, f"uninterrupted run: exit code {rc}")
    # One linearization for the attempt and one pseudo-time step: the frictional
    # solve of the settled state (its gauges released) cannot converge.
    rc, text = compact(driver, part, levels, extra=gauged + ["-level_attempt_its", "1", "-ptc_max_steps", "1"])
    checkpoint = os.path.join(part, "checkpoint.h5")
    check(rc != 0, f"the frictional solve of the settled state fails (exit code {rc})")
    check("again from the settled state with -level_solver anchored" in text,
          "the failed frictional solve is tried again from the settled state with anchored")
    check("-restart " + checkpoint in text, "the error message names -restart and the checkpoint of the settled state")
    check(os.path.exists(checkpoint), "checkpoint.h5 written after the frictionless settling")
    check(len(read_curve(part)) == 0, "curve.csv holds no level")
    settled = os.path.join(workdir, "settled.h5")
    shutil.copy(checkpoint, settled)
    rc, text = compact(driver, part, levels, extra=gauged + ["-restart", checkpoint])
    check(rc == 0 and "the frictionless settling of the first level done" in text,
          f"restart from the settled state: exit code {rc}")
    if rc == 0:
        compare_runs(full, part)
    cases = [
        (gauged + ["-restart", settled], [5e-5] + levels[1:], "holds the frictionless settling at P/E = 0.0001, "
         "but the first level of -pressures (5e-05) settles at P/E = 5e-05"),
        (gauged + ["-restart", settled, "-settle_frictionless", "false"], levels, "-settle_frictionless false"),
    ]
    for extra, pressures, expect in cases:
        check_refused(driver, workdir, part, pressures, extra, expect, f"{' '.join(extra[4:])}, -pressures {pressures}")


def packing_case(driver, workdir):
    """-packing FILE: a 3 x 3 square lattice of equal rigid disks (d = 1) read
    from a CSV file keeps phi = pi/4 and carries P d at every contact (pairs
    and walls), with friction; bad files are refused before anything is written."""
    import h5py
    import math
    lattice = os.path.join(workdir, "lattice.csv")
    with open(lattice, "w") as f:
        f.write("radius,x,y,deformable\n")  # any column order
        for i in range(3):
            for j in range(3):
                f.write(f"0.5,{i + 0.5},{j + 0.5},0\n")
    out = os.path.join(workdir, "lattice")
    shutil.rmtree(out, ignore_errors=True)
    levels = [1e-3, 1e-2]
    cmd = [driver, "-packing", lattice, "-friction", "0.3", "-pressures", ",".join(map(str, levels)), "-output_dir", out]
    print("$ " + " ".join(cmd))
    p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=300)
    print(p.stdout)
    if check(p.returncode == 0, f"lattice run: exit code {p.returncode}"):
        rows = read_curve(out)
        check(len(rows) == 2, "two levels")
        for r in rows:
            check(abs(float(r["phi"]) - math.pi / 4) <= 1e-10, f"phi {r['phi']} = pi/4")
        with h5py.File(os.path.join(out, "levels.h5"), "r") as h5:
            for name, P in zip(sorted(h5), levels):
                fn = h5[name]["contacts/normal_force"][()]
                pairs = h5[name]["contacts/particles"][()]
                check(len(fn) == 24 and (pairs[:, 1] >= 0).sum() == 12,
                      f"P/E {P}: 12 pair and 12 wall contacts carry force ({len(fn)} segments)")
                check(abs(fn - P).max() <= 1e-6 * P, f"P/E {P}: every contact carries P d (worst {abs(fn - P).max() / P:.1e} P)")
        with open(os.path.join(out, "packing.csv")) as f:
            check(len(f.readlines()) == 10, "packing.csv repeats the nine disks")
    bad = {
        "empty.csv": ("", "is empty"),
        "header_only.csv": ("x,y,radius,deformable\n", "has a header but no disk"),
        "missing.csv": ("x,y,radius\n0.5,0.5,0.5\n", "no column 'deformable'"),
        "unknown.csv": ("x,y,radius,deformable,z\n0.5,0.5,0.5,0,1\n", "unknown column 'z'"),
        "text.csv": ("x,y,radius,deformable\n0.5,abc,0.5,0\n", "y 'abc' is not a finite number"),
        "radius.csv": ("x,y,radius,deformable\n0.5,0.5,0,0\n", "radius 0 must be positive"),
        "flag.csv": ("x,y,radius,deformable\n0.5,0.5,0.5,2\n", "must be 0 (rigid) or 1 (deformable)"),
        "fields.csv": ("x,y,radius,deformable\n0.5,0.5,0.5\n", "3 fields for 4 columns"),
        "overlap.csv": ("x,y,radius,deformable\n0.5,0.5,0.5,0\n1.4,0.5,0.5,1\n", "disks 0 and 1 (rows 2 and 3) overlap by 0.1"),
    }
    target = os.path.join(workdir, "refused")
    for name, (text, expect) in bad.items():
        path = os.path.join(workdir, name)
        with open(path, "w") as f:
            f.write(text)
        shutil.rmtree(target, ignore_errors=True)
        p = subprocess.run([driver, "-packing", path, "-output_dir", target], stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True, timeout=60)
        check(p.returncode != 0, f"{name}: refused (exit code {p.returncode})")
        check(expect in p.stdout, f"{name}: message contains '{expect}'")
        check(not os.path.exists(target), f"{name}: nothing written")
    p = subprocess.run([driver, "-packing", os.path.join(workdir, "nowhere.csv"), "-output_dir", target],
                       stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=60)
    check(p.returncode != 0 and "cannot read the packing file" in p.stdout, "a missing file is refused")
    p = subprocess.run([driver, "-packing", lattice, "-kappa", "0.5", "-output_dir", target],
                       stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=60)
    check(p.returncode != 0 and "-kappa cannot be combined with -packing" in p.stdout, "-kappa with -packing is refused")


PROGRESS_RE = re.compile(r"^    \.\.\. P/E (\S+): pseudo-time step (\d+), (\d+) Newton its, \|F\|_inf (\S+) P<d>")


def progress_case(driver, workdir, mpiexec):
    levels = [1e-4, 1e-3, 3e-3]
    for ranks in (1, 2):
        out = os.path.join(workdir, f"ranks-{ranks}")
        shutil.rmtree(out, ignore_errors=True)
        launcher = [] if ranks == 1 else [mpiexec, "-n", "2", "--oversubscribe"]
        rc, text = compact(driver, out, levels, launcher, ["-progress_interval", "0", "-write_hdf5", "false"])
        if not check(rc == 0, f"{ranks} rank(s): exit code {rc}"):
            continue
        rows = read_curve(out)
        # Progress lines of the levels (the rigid settling's come before the table header).
        body = text.split(" P/E      phi", 1)[-1].splitlines()
        lines = [(float(m[1]), int(m[2]), int(m[3])) for m in map(PROGRESS_RE.match, body) if m]
        check(len(lines) >= len(levels), f"{ranks} rank(s): {len(lines)} progress lines")
        # Sub-steps: a line whose pressure differs from, or whose pseudo-time step does not follow, the last one's.
        substeps = []
        for p, step, its in lines:
            if substeps and substeps[-1][0] == p and step > substeps[-1][1]:
                substeps[-1] = (p, step, its)
            else:
                substeps.append((p, step, its))
        for r in rows:
            target, its = float(r["P_over_E"]), 0
            while substeps and substeps[0][0] <= target * (1 + 1e-3):  # this level's sub-steps (and re-solves at P)
                its += substeps.pop(0)[2]
            if float(r["cuts"]) == 0:
                check(its == int(float(r["newton_its"])),
                      f"{ranks} rank(s), P/E = {target:g}: progress lines count {its} Newton iterations, curve.csv"
                      f" {r['newton_its']}")
        check(not substeps, f"{ranks} rank(s): no progress lines beyond the last level ({substeps})")
    out = os.path.join(workdir, "quiet")
    shutil.rmtree(out, ignore_errors=True)
    rc, text = compact(driver, out, levels[:1], extra=["-progress_interval", "-1", "-write_hdf5", "false"])
    check(rc == 0 and not any(map(PROGRESS_RE.match, text.splitlines())), "-progress_interval -1: no progress lines")


def settle_case(driver, workdir):
    """auto's newton limited to one linearization per load step
    (-level_max_its 1) cannot settle the default scene, neither its rigid
    pre-settling nor the frictionless settling of the mixture: each
    settling must then be solved by hybrid from the state before it (without
    that, every step cut of the settling fails and compact stops). The levels
    that follow are frictional (hybrid), so the run completes; every level
    must pass the acceptance checks of run_compact. Both settlings factor
    newton's symmetric Newton matrix by LDL^T, whose solver options carry the
    prefixes ldlt_ and settle_ldlt_: they must be accepted and read."""
    default_opts = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "petsc-options", "default.opts")
    log = []
    rows = run_compact(driver, os.path.join(workdir, "max-its-1"), [1e-4, 1e-3], timeout=600,
                       scene=["-options_file", default_opts],
                       extra=["-level_max_its", "1", "-checkpoint", "false", "-ldlt_ksp_converged_reason",
                              "-settle_ldlt_ksp_converged_reason"], log=log)
    for prefix in ("ldlt_", "settle_ldlt_"):
        check(f"Linear {prefix} solve converged" in log[0], f"-{prefix}ksp_converged_reason is read by the LDL^T solves")
    # The rigid settling's line splits its iterations between newton's failed load step and hybrid.
    m = re.search(r"rigid settling at P/E = \S+: phi = \S+, (\d+) Newton iterations \((\d+) in newton's load step, "
                  r"which failed, then (\d+) by hybrid\)", log[0])
    if check(m is not None, "the rigid settling's line names newton's failed load step and hybrid's iterations"):
        check(int(m[2]) == 1 and int(m[1]) == int(m[2]) + int(m[3]),
              f"newton's load step took its one linearization ({m[2]}), and the parts add up to {m[1]}")
    if rows:
        check(rows[0]["newton_its"] > 1, f"the settling level took {rows[0]['newton_its']:.0f} > 1 Newton iterations"
                                         " (hybrid after newton's single linearization)")


LEVEL_ROW_RE = re.compile(r"^ +(\d[\d.e+-]*) +0\.\d+ +\d")


def end_game_case(driver, workdir):
    """50 disks, kappa 0.2, friction 0.2 (a frictional 50-disk campaign run)
    to P/E 0.03 with -ptc_monitor: anchored's end game
    (everything of the level criterion passes but the contact rows) must begin
    on some level, and once it has begun no inner solve of its sub-step may
    fail: rho_a stays at least at the value of the pseudo-time step that began
    it, so that the bodies stay anchored while the dual term, lowered there,
    lets the indeterminate contact forces of hyperstatic clusters move (with
    rho_a at its floor the first Newton step of such a solve moves those forces
    with the bodies held by nothing, and the solve fails). Every level must pass
    run_compact's acceptance checks."""
    levels, log = [1e-4, 3e-4, 1e-3, 3e-3, 0.01, 0.03], []
    rows = run_compact(driver, os.path.join(workdir, "n50_k0.2_mu0.2"), levels, timeout=600,
                       scene=["-n_particles", "50", "-kappa", "0.2", "-friction", "0.2"], extra=["-ptc_monitor"], log=log)
    if not rows:
        return
    end_games, failed, in_end_game, level_failed = [], 0, False, []
    for line in log[0].split(" P/E      phi", 1)[-1].splitlines():
        m = LEVEL_ROW_RE.match(line)
        if m or re.match(r"^  ptc +0  ", line):  # a level ends, or a sub-step's first pseudo-time step
            in_end_game = False
        if m and failed:
            level_failed.append((m[1], failed))
            failed = 0
        if re.match(r"^  ptc +\d+  end game:", line):
            in_end_game = True
            end_games.append(line.strip())
        elif in_end_game and "inner solve failed" in line:
            failed += 1
            print("  end game: " + line.strip())
    print(f"  info  {len(end_games)} end game(s): " + "; ".join(end_games))
    check(len(end_games) >= 1, "the end game begins on some level (else this scene no longer tests it)")
    check(not level_failed, f"no inner solve fails once the end game has begun (failures per level: {level_failed})")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--driver", required=True)
    ap.add_argument("--workdir", required=True)
    ap.add_argument("--mpiexec", default="mpirun")
    ap.add_argument("case", choices=["friction-to-half", "jump", "mpi", "restart", "restart-settled", "progress", "packing", "settle",
                                         "end-game"])
    a = ap.parse_args()
    os.makedirs(a.workdir, exist_ok=True)
    if a.case == "friction-to-half":
        rows = run_compact(a.driver, os.path.join(a.workdir, "stepped"),
                           [1e-4, 1e-3, 0.01, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5], timeout=900)
        if rows:
            check(rows[-1]["phi"] > 0.9, f"phi at P/E = 0.5 is {rows[-1]['phi']:.4f} > 0.9 (deformable half compacts)")
            check(any(r["sliding_contacts"] > 0 for r in rows), "friction: some contacts slide")
            check(rows[-1]["Z_no_rattlers"] > rows[0]["Z_no_rattlers"], "compaction raises the coordination")
    elif a.case == "mpi":
        scene = ["-n_particles", "30", "-kappa", "0.5", "-friction", "0.3", "-seed", "3", "-mesh_triangles", "40"]
        levels = [1e-4, 1e-3, 5e-3]
        runs = {}
        for n in (1, 2, 3):
            launcher = [] if n == 1 else [a.mpiexec, "-n", str(n), "--oversubscribe"]
            runs[n] = run_compact(a.driver, os.path.join(a.workdir, f"ranks-{n}"), levels, 900, scene, launcher,
                                  ["-partition_view"])
        for n in (2, 3):
            for r1, rn in zip(runs[1], runs[n]):
                tag = f"{n} ranks, P/E = {r1['P_over_E']:g}"
                check(abs(rn["phi"] - r1["phi"]) <= 1e-4 * r1["phi"],
                      f"{tag}: phi {rn['phi']:.6f} vs serial {r1['phi']:.6f} (within 1e-4 relative)")
                nonrattlers = 30 - r1["rattlers"]
                check(abs(rn["Z_no_rattlers"] - r1["Z_no_rattlers"]) <= 2.0 / nonrattlers + 1e-12,
                      f"{tag}: Z_nr {rn['Z_no_rattlers']:.4f} vs serial {r1['Z_no_rattlers']:.4f} (within one contact)")
    elif a.case == "restart":
        restart_case(a.driver, a.workdir, a.mpiexec)
    elif a.case == "restart-settled":
        restart_settled_case(a.driver, a.workdir)
    elif a.case == "progress":
        progress_case(a.driver, a.workdir, a.mpiexec)
    elif a.case == "packing":
        packing_case(a.driver, a.workdir)
    elif a.case == "settle":
        settle_case(a.driver, a.workdir)
    elif a.case == "end-game":
        end_game_case(a.driver, a.workdir)
    else:
        rows = run_compact(a.driver, os.path.join(a.workdir, "jump"), [0.1], timeout=900)
        ref = run_compact(a.driver, os.path.join(a.workdir, "stepped"), [1e-4, 1e-3, 0.01, 0.05, 0.1], timeout=900)
        if rows and ref:
            j, r = rows[0], ref[-1]
            check(j["substeps"] > 1, f"the jump was sub-stepped ({j['substeps']:.0f} sub-steps, {j['cuts']:.0f} cuts)")
            check(j["sliding_contacts"] > 0, f"friction is on in the jump ({j['sliding_contacts']:.0f} sliding contacts)")
            check(abs(j["phi"] - r["phi"]) <= 5e-3,
                  f"phi after the jump {j['phi']:.5f} vs stepped {r['phi']:.5f} (within 5e-3)")
    print("FAILED: %d check(s)" % len(failures) if failures else "all checks passed")
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()

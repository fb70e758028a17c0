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

Every row of curve.csv must satisfy: all requested levels present, phi rising
with P, no penetration beyond 1e-9 <d>, the unbalanced force within the level
criterion (force_residual_over_Pd <= 1e-4), the contact stress equal to the
imposed pressure to 2e-3 (the virial check at that force tolerance),
Z > 0 and rising with compaction, no negative bulk modulus.
"""
import argparse
import csv
import os
import shutil
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from driver_tests import check, failures  # noqa: E402  (the same check/report helpers)


SCENE = ["-n_particles", "50", "-kappa", "0.5", "-friction", "0.8", "-seed", "1"]


def run_compact(driver, out, pressures, timeout, scene=SCENE, launcher=(), extra=()):
    shutil.rmtree(out, ignore_errors=True)
    cmd = list(launcher) + [driver] + scene + ["-pressures", ",".join(str(p) for p in pressures), "-output_dir", out,
                                               "-write_hdf5", "false"] + list(extra)
    print("$ " + " ".join(cmd))
    p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=timeout)
    print(p.stdout)
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
        check(r["max_penetration"] <= 1e-9, f"{tag}: max penetration {r['max_penetration']:.2e} <= 1e-9")
        check(r["force_residual_over_Pd"] <= 1e-4, f"{tag}: unbalanced force {r['force_residual_over_Pd']:.2e} P<d> <= 1e-4")
        check(abs(r["P_sigma_over_E"] / P - 1.0) <= 2e-3, f"{tag}: P_sigma / P = {r['P_sigma_over_E'] / P:.6f}")
        check(r["Z"] > 0.0 and r["Z_no_rattlers"] > 0.0, f"{tag}: Z = {r['Z']:.3f}, Z_nr = {r['Z_no_rattlers']:.3f} > 0")
        check(r["K_over_E"] > 0.0, f"{tag}: K/E = {r['K_over_E']:.3g} > 0")
    return rows


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--driver", required=True)
    ap.add_argument("--workdir", required=True)
    ap.add_argument("--mpiexec", default="mpirun")
    ap.add_argument("case", choices=["friction-to-half", "jump", "mpi"])
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

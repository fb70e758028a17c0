#!/usr/bin/env python3
"""How far the bodies move in each level, and how much of it is not affine.

Reads the level checkpoints of a compact run made with -checkpoint_levels
true (RUN_DIR/checkpoint_level_<k>.h5 and RUN_DIR/curve.csv). For every
level after the first and every body: its displacement over the level (a
deformable disk's mean nodal displacement, a rigid disk's centre), and the
affine part of it, the displacement the walls' strain alone would give the
body's centre; the difference is the non-affine motion. Prints per level
the Newton iterations, the mean affine displacement and quantiles of the
non-affine one (in <d>), the fraction of bodies moving non-affinely by more
than 1e-3 <d>, and the share of the total non-affine motion carried by the
10 % of bodies that move most (0.1 if every body moved alike, near 1 if a
few did all of it); writes the table to OUT.csv and a plot to OUT.png.

Usage:
  /usr/bin/python3 scripts/level_motion.py RUN_DIR OUT.csv OUT.png
"""
import csv
import glob
import os
import sys

import h5py
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from provenance import git_commit, machine  # noqa: E402


def load(path):
    with h5py.File(path, "r") as f:
        return f["packing"][:], f["current/u"][:], f["current/walls"][:]


def body_positions(packing, u, dofs_deformable, dofs_rigid):
    """Centre displacement of every body (rows of packing: x, y, radius, deformable)."""
    n = len(packing)
    disp = np.zeros((n, 2))
    off = 0
    for i in range(n):
        if packing[i, 3] > 0.5:
            disp[i] = u[off:off + dofs_deformable].reshape(-1, 2).mean(axis=0)
            off += dofs_deformable
        else:
            disp[i] = u[off:off + 2]
            off += dofs_rigid
    if off != len(u):
        sys.exit(f"level_motion.py: {off} body unknowns from the packing and curve.csv, {len(u)} in the checkpoint")
    return packing[:, :2] + disp


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    run, out_csv, out_png = sys.argv[1:]
    with open(os.path.join(run, "curve.csv")) as f:
        curve = list(csv.DictReader(f))
    paths = sorted(glob.glob(os.path.join(run, "checkpoint_level_*.h5")))
    if len(paths) < 2:
        sys.exit(f"level_motion.py: {run} holds fewer than two checkpoint_level_*.h5 (run compact with -checkpoint_levels true)")
    rows = []
    packing, u1, w1 = load(paths[0])
    for k in range(1, len(paths)):
        u0, w0 = u1, w1  # each checkpoint is read once: the end of one level is the start of the next
        _, u1, w1 = load(paths[k])
        level = int(os.path.basename(paths[k])[len("checkpoint_level_"):-3])
        c = curve[level]
        n_def = int(round(packing[:, 3].sum()))
        n_rig = len(packing) - n_def
        dofs_def = int(float(c["deformable_unknowns"])) // n_def if n_def else 0
        dofs_rig = int(float(c["rigid_unknowns"])) // n_rig if n_rig else 0
        x0 = body_positions(packing, u0, dofs_def, dofs_rig)
        x1 = body_positions(packing, u1, dofs_def, dofs_rig)
        sx = (w1[1] - w1[0]) / (w0[1] - w0[0])
        sy = (w1[3] - w1[2]) / (w0[3] - w0[2])
        affine = np.stack([w1[0] + (x0[:, 0] - w0[0]) * sx, w1[2] + (x0[:, 1] - w0[2]) * sy], axis=1) - x0
        nonaffine = np.linalg.norm(x1 - x0 - affine, axis=1)
        q = np.quantile(nonaffine, [0.5, 0.9, 0.99, 1.0])
        top = np.sort(nonaffine)[-max(1, len(nonaffine) // 10):].sum() / max(nonaffine.sum(), 1e-300)
        rows.append({"P_over_E": c["P_over_E"], "newton_its": c["newton_its"],
                     "affine_mean": np.linalg.norm(affine, axis=1).mean(), "nonaffine_median": q[0],
                     "nonaffine_p90": q[1], "nonaffine_p99": q[2], "nonaffine_max": q[3],
                     "fraction_above_1e-3": float(np.mean(nonaffine > 1e-3)), "top10_share": top})
    print(f"{'P/E':>8} {'its':>5} {'affine':>9} {'median':>9} {'p90':>9} {'p99':>9} {'max':>9} {'>1e-3':>6} {'top10%':>6}")
    for r in rows:
        print(f"{float(r['P_over_E']):8.3g} {r['newton_its']:>5} {r['affine_mean']:9.2e} {r['nonaffine_median']:9.2e} "
              f"{r['nonaffine_p90']:9.2e} {r['nonaffine_p99']:9.2e} {r['nonaffine_max']:9.2e} "
              f"{r['fraction_above_1e-3']:6.2f} {r['top10_share']:6.2f}")
    with open(out_csv, "w", newline="") as f:
        f.write(f"# machine: {machine()}; commit {git_commit()}; run {run}\n")
        f.write(f"# command: {' '.join(sys.argv)}\n")
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    p = [float(r["P_over_E"]) for r in rows]
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    ax[0].loglog(p, [r["affine_mean"] for r in rows], "o-", label="affine, mean")
    for key, label in (("nonaffine_median", "non-affine, median"), ("nonaffine_p99", "non-affine, 99 %")):
        ax[0].loglog(p, [r[key] for r in rows], "s-", label=label)
    ax[0].set_xlabel("P/E")
    ax[0].set_ylabel("displacement over the level / <d>")
    ax[0].legend()
    ax[1].semilogx(p, [int(float(r["newton_its"])) for r in rows], "o-")
    ax[1].set_xlabel("P/E")
    ax[1].set_ylabel("Newton iterations of the level")
    fig.suptitle(f"{run} (commit {git_commit()})")
    fig.tight_layout()
    fig.savefig(out_png, dpi=120)
    print(f"wrote {out_csv} and {out_png}")


if __name__ == "__main__":
    main()

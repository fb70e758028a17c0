#!/usr/bin/python3
"""The ParaView view of a run: levels.xdmf beside levels.h5 (registered in CTest).

    xdmf_tests.py --driver BIN --workdir DIR [--mpiexec MPIEXEC --ranks N]

Runs `compact` on 12 disks (kappa 0.5, friction 0.3) for two levels, then
continues it from its checkpoint for a third, and checks levels.xdmf:
- every dataset it names exists in levels.h5 with the declared dimensions
  and number type, and the times are curve.csv's P/E, one step per level in
  each series (box, rigid disks, contacts, deformable disks);
- an independent XDMF reader (meshio, Debian's python3-meshio) opens it: the
  time series of the deformable disks has one step per level, as many points
  and 6-node triangles as the per-body datasets, and each step of every
  series, read as a grid of its own, has the expected points and cells;
- the data are what they claim: coordinates - displacement is the same
  reference configuration at every level, volumetric_strain is the per-body
  cell_area_ratio - 1, the rigid disks' centres and radii are /rigid's, the
  ends of a contact segment between two rigid disks are their centres, and
  the normal forces on each wall add up to P times its length (the wall's
  equilibrium, within the level criterion).
"""
import argparse
import copy
import csv
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

import h5py
import meshio
import numpy as np

failures = []


def check(cond, msg):
    if not cond:
        failures.append(msg)
        print("FAIL:", msg)


def run(cmd):
    p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if p.returncode != 0:
        print(p.stdout)
        sys.exit(f"command failed: {' '.join(cmd)}")


def verify(out):
    xdmf, h5path = os.path.join(out, "levels.xdmf"), os.path.join(out, "levels.h5")
    rows = list(csv.DictReader(open(os.path.join(out, "curve.csv"))))
    times = [float(r["P_over_E"]) for r in rows]
    root = ET.parse(xdmf).getroot()
    check(root.tag == "Xdmf" and root.get("Version") == "3.0", "root element Xdmf 3.0")
    domain = root[0]
    series = {g.get("Name"): g for g in domain}
    check(list(series) == ["box", "rigid disks", "contacts", "deformable disks"], f"series {list(series)}")
    with h5py.File(h5path, "r") as h5:
        levels = sorted(k for k in h5 if k.startswith("level_"))
        check(len(levels) == len(rows), f"{len(levels)} levels in levels.h5, {len(rows)} rows in curve.csv")
        # Every DataItem: the dataset, its dimensions and its number type.
        items = 0
        for item in root.iter("DataItem"):
            check(item.get("Format") == "HDF", "HDF data items")
            fname, path = item.text.strip().split(":")
            check(fname == "levels.h5", f"relative file name {fname}")
            check(path in h5, f"{path} named by the XDMF is not in levels.h5")
            if path not in h5:
                continue
            dims = tuple(int(d) for d in item.get("Dimensions").split())
            check(h5[path].shape == dims, f"{path}: shape {h5[path].shape}, XDMF says {dims}")
            integer = np.issubdtype(h5[path].dtype, np.integer)
            check(integer == (item.get("NumberType") == "Int"), f"{path}: dtype {h5[path].dtype} vs {item.get('NumberType')}")
            items += 1
        check(items > 0, "no data items")
        for name, coll in series.items():
            check(coll.get("GridType") == "Collection" and coll.get("CollectionType") == "Temporal", f"{name} temporal")
            t = [float(g.find("Time").get("Value")) for g in coll]
            check(np.allclose(t, times, rtol=1e-12), f"{name}: times {t}, curve.csv {times}")
        # An independent reader: meshio's time series (the last series, the deformable disks).
        nodes = sum(h5[f"{levels[0]}/{b}/coordinates"].shape[0] for b in h5[levels[0]] if b.startswith("body_"))
        cells = sum(h5[f"{levels[0]}/{b}/cells"].shape[0] for b in h5[levels[0]] if b.startswith("body_"))
        with meshio.xdmf.TimeSeriesReader(xdmf) as r:
            check(r.num_steps == len(rows), f"meshio: {r.num_steps} steps, {len(rows)} levels")
            points, blocks = r.read_points_cells()
            check(points.shape == (nodes, 2), f"meshio: points {points.shape}, {nodes} nodes")
            check([b.type for b in blocks] == ["triangle6"] and blocks[0].data.shape == (cells, 6),
                  f"meshio: cells {[(b.type, b.data.shape) for b in blocks]}, {cells} triangles")
            reference = None
            for k in range(r.num_steps):
                t, pd, cd = r.read_data(k)
                check(abs(t - times[k]) <= 1e-12 * times[k], f"meshio: time {t} at step {k}")
                lvl = h5[levels[k]]
                ref = lvl["mesh/coordinates"][()] - pd["displacement"]
                if reference is None:
                    reference = ref
                check(np.allclose(ref, reference, atol=1e-12), f"step {k}: coordinates - displacement is not the reference")
                strain = np.concatenate([lvl[f"body_{b}/cell_area_ratio"][()] - 1.0 for b in range(
                    sum(1 for x in lvl if x.startswith("body_")))])
                check(np.allclose(cd["volumetric_strain"][0], strain, atol=1e-14), f"step {k}: volumetric_strain")
        # Every step of every series, read by meshio as a grid of its own.
        for name, coll in series.items():
            for k, step in enumerate(coll):
                g = copy.deepcopy(step)
                for t in g.findall("Time"):
                    g.remove(t)  # meshio's single-grid reader knows no Time
                one = ET.Element("Xdmf", Version="3.0")
                ET.SubElement(one, "Domain").append(g)
                path = os.path.join(out, "one.xdmf")
                ET.ElementTree(one).write(path)
                m = meshio.xdmf.read(path)
                lvl = h5[levels[k]]
                P = times[k]
                if name == "box":
                    check(m.points.shape == (4, 2) and m.cells[0].type == "line" and len(m.cells[0].data) == 4, "box")
                    w = lvl["walls"][()]
                    check(np.allclose(sorted(set(m.points[:, 0])), sorted(w[:2])), "box corners are the walls")
                elif name == "rigid disks":
                    rig = lvl["rigid"][()]
                    check(m.points.shape == (len(rig), 2) and m.cells[0].type == "vertex", f"rigid disks at step {k}")
                    check(np.allclose(m.points, rig[:, :2]) and np.allclose(m.point_data["radius"], rig[:, 2]),
                          "rigid disk centres and radii are /rigid's")
                elif name == "contacts":
                    n = len(lvl["contacts/normal_force"])
                    check(m.points.shape == (2 * n, 2) and m.cells[0].type == "line" and len(m.cells[0].data) == n,
                          f"contacts at step {k}: {m.points.shape}, {n} segments")
                    fn = m.cell_data["normal_force"][0]
                    check(np.all(fn > -1e-12 * P), "compressive normal forces")
                    pairs = lvl["contacts/particles"][()]
                    rig = lvl["rigid"][()]
                    rigid_particle = {p: i for i, p in enumerate(lvl["disks/particle"][()])}
                    for i, (s, mst) in enumerate(pairs):
                        if s in rigid_particle and mst in rigid_particle:
                            check(np.allclose(m.points[2 * i], rig[rigid_particle[s], :2]) and
                                  np.allclose(m.points[2 * i + 1], rig[rigid_particle[mst], :2]),
                                  "a rigid-rigid segment joins the two centres")
                    # Wall equilibrium: the normal forces on each wall add up to P times its length.
                    w = lvl["walls"][()]
                    length = [w[3] - w[2], w[3] - w[2], w[1] - w[0], w[1] - w[0]]
                    for wall in range(4):
                        total = fn[pairs[:, 1] == -1 - wall].sum()
                        check(abs(total - P * length[wall]) <= 2e-3 * P * length[wall],
                              f"step {k}, wall {wall}: normal forces {total} against P L {P * length[wall]}")
                else:
                    check(m.points.shape == (nodes, 2) and m.cells[0].data.shape == (cells, 6), "deformable mesh")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--driver", required=True)
    ap.add_argument("--workdir", required=True)
    a = ap.parse_args()
    shutil.rmtree(a.workdir, ignore_errors=True)
    os.makedirs(a.workdir)
    out = os.path.join(a.workdir, "run")
    scene = [a.driver, "-n_particles", "12", "-kappa", "0.5", "-friction", "0.3", "-mesh_triangles", "40",
             "-output_dir", out]
    run(scene + ["-pressures", "1e-4,1e-3"])
    verify(out)
    # Continued for a third level: the XDMF follows what levels.h5 holds.
    run(scene + ["-pressures", "1e-4,1e-3,3e-3", "-restart", os.path.join(out, "checkpoint.h5")])
    verify(out)
    if failures:
        sys.exit(f"{len(failures)} check(s) failed")
    print("levels.xdmf: every dataset present with its shape; meshio reads every series")


if __name__ == "__main__":
    main()

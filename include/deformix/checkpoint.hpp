// Checkpoints of the drivers: after every pressure level, everything
// needed to continue the run as if it had never stopped (-restart FILE).
// compact also writes one inside its first level, after the frictionless
// settling: it holds no level yet, and its values say so (settled_P_over_E).
//
// A checkpoint holds
//   - the driver's name and its scene options (compact: N_p, kappa, seed,
//     mesh, E, nu, friction, contact law, rotation gauges), which a restart
//     must repeat: they define the bodies and the unknowns the state refers to;
//   - compact: the packing the bodies were built from (after the rigid
//     settling), so a restart neither regenerates nor re-settles it;
//   - the levels done and their curve.csv rows (a restarted run writes the
//     whole curve again, then continues it);
//   - the load controller's suggested step and driver-specific numbers
//     (compact: the last level's phi and P, for the finite-difference bulk
//     modulus of the next level);
//   - the solver state (CompactionProblem::Snapshot): displacements, walls,
//     gauges, candidates and their multipliers, and whether a load step has
//     converged before it (have_previous).
// On one rank a restarted run repeats the uninterrupted one bit for bit; on
// another number of ranks it agrees to solver tolerance, as any run does.
//
// File layout (HDF5):
//   /                     attributes: format, driver, load_step, have_previous
//   /scene, /values       one attribute per scene option / driver number
//   /levels               P/E of the levels done
//   /curve                their curve.csv rows (attribute "columns": the header)
//   /packing              x, y, radius, deformable (N_p x 4);  /walls (4)
//   /current              u, walls, torque, lambda_n, lambda_t, candidates
//                         (n x 6: type, body, point, wall, master, segment);
//                         attribute pressure
// Rank 0 writes FILE.tmp and renames it to FILE: an interrupted write never
// replaces a good checkpoint. Every rank reads the file.
#pragma once
#include <petscsys.h>

#include <string>
#include <vector>

#include "deformix/packing.hpp"
#include "deformix/problem.hpp"

namespace deformix {

// The options that define the bodies and unknowns of a run, by name
// ("kappa", "mesh_triangles", ...): a restart must repeat them.
struct SceneValue {
  std::string option;
  double value;
};
using Scene = std::vector<SceneValue>;

// "" when `run` repeats `saved`, otherwise the first difference as
// "-kappa: checkpoint 0.5, this run 0.8".
std::string SceneDifference(const Scene &saved, const Scene &run);

struct Checkpoint {
  std::string driver;                 // the executable that wrote it
  Scene scene;
  DiskPacking packing;                // compact: the packing the bodies were built from (empty otherwise)
  std::vector<SceneValue> values;     // driver-specific numbers (phi_0, the last level's phi, ...)
  std::vector<double> levels;         // P/E of the levels done, in order (none: a checkpoint inside the first level)
  std::vector<std::string> columns;   // curve.csv header
  std::vector<std::vector<double>> rows;  // one curve.csv row per level done
  double load_step = -1.0;            // the load controller's suggested increment
  CompactionProblem::Snapshot state;
  double Value(const std::string &name) const;  // an entry of `values` (0 if absent)
};

// Collective; rank 0 writes.
PetscErrorCode WriteCheckpoint(MPI_Comm comm, const std::string &path, const Checkpoint &c);
// After level `level` of `pressures`: completes `c` (whose driver, scene,
// columns, packing and values the driver has set) with the levels done, the
// curve rows, the load step and the problem's state, and writes it.
PetscErrorCode WriteLevelCheckpoint(MPI_Comm comm, const std::string &path, const std::vector<double> &pressures,
                                    size_t level, const std::vector<std::vector<double>> &rows, double load_step,
                                    const CompactionProblem &problem, Checkpoint *c);
// Collective; fails with a message naming the file and what is wrong with it
// (missing, not HDF5, not a deformix checkpoint, incomplete).
PetscErrorCode ReadCheckpoint(MPI_Comm comm, const std::string &path, Checkpoint *c);
// Reads `path` and checks that this run can continue it: written by `driver`
// for the same scene and curve columns, and `pressures` beginning with its
// levels with at least one left to do. Collective; nothing is written.
PetscErrorCode LoadRestart(MPI_Comm comm, const std::string &path, const std::string &driver, const Scene &scene,
                           const std::vector<std::string> &columns, const std::vector<double> &pressures,
                           Checkpoint *c);

}  // namespace deformix

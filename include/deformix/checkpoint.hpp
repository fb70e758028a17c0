// Checkpoints of the mixture driver: after every pressure level, everything
// needed to continue the run as if it had never stopped (compact -restart).
//
// A checkpoint holds
//   - the scene options (N_p, kappa, seed, mesh, E, nu, friction, contact
//     law, rotation gauges), which a restart must repeat: they define the
//     bodies and the unknowns the state refers to;
//   - the packing the bodies were built from (after the rigid settling), so a
//     restart neither regenerates nor re-settles it;
//   - the levels done and their curve.csv rows (a restarted run writes the
//     whole curve again, then continues it);
//   - the load controller's suggested step, the last level's phi and P (the
//     finite-difference bulk modulus of the next level);
//   - the solver state and the one before it (CompactionProblem::Snapshot):
//     displacements, walls, gauges, candidates and their multipliers.
// On one rank a restarted run repeats the uninterrupted one bit for bit; on
// another number of ranks it agrees to solver tolerance, as any run does.
//
// File layout (HDF5):
//   /                     attributes: format, the scene, load_step,
//                         previous_phi, previous_pressure, phi_0, Z_0 values
//   /levels               P/E of the levels done
//   /curve                their curve.csv rows (attribute "columns": the header)
//   /packing              x, y, radius, deformable (N_p x 4);  /walls (4)
//   /current, /previous   u, walls, torque, lambda_n, lambda_t, candidates
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

// The options that define the bodies and unknowns of a compaction run.
struct CompactionScene {
  PetscInt n_particles = 0;
  double kappa = 0.0;
  PetscInt seed = 0;
  PetscInt mesh_triangles = 0;
  double young = 0.0, poisson = 0.0, friction = 0.0;
  int deformable_contact = 0;  // DeformableContact
  int constrain_rotation = 0;
};

// "" when `run` repeats `saved`, otherwise the first difference as
// "-kappa: checkpoint 0.5, this run 0.8".
std::string SceneDifference(const CompactionScene &saved, const CompactionScene &run);

struct Checkpoint {
  CompactionScene scene;
  DiskPacking packing;
  double phi_0 = 0.0;                 // the jammed rigid packing (printed again on restart)
  double z0_no_rattlers = 0.0, z0_mirror = 0.0, rattler_fraction = 0.0;
  std::vector<double> levels;         // P/E of the levels done, in order
  std::vector<std::string> columns;   // curve.csv header
  std::vector<std::vector<double>> rows;  // one curve.csv row per level done
  double load_step = -1.0;            // the load controller's suggested increment
  double previous_phi = 0.0, previous_P = 0.0;  // phi and pressure P (not P/E) of the last level
  CompactionProblem::Snapshot state;
};

// Collective; rank 0 writes.
PetscErrorCode WriteCheckpoint(MPI_Comm comm, const std::string &path, const Checkpoint &c);
// Collective; fails with a message naming the file and what is wrong with it
// (missing, not HDF5, not a deformix checkpoint, incomplete).
PetscErrorCode ReadCheckpoint(MPI_Comm comm, const std::string &path, Checkpoint *c);

}  // namespace deformix

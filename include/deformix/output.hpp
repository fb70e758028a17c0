// Results: the per-level curve (CSV) and the deformed meshes (HDF5).
//
// curve.csv has a header row and one row per converged pressure level, in
// the order applied; rows are flushed as they are written so a long run can
// be followed. The HDF5 file holds one group per level:
//   /level_NNNN            attributes P_over_E, packing_fraction
//     /walls               (x_left, x_right, y_bottom, y_top)
//     /body_K/coordinates  current node coordinates (n_nodes x 2)
//     /body_K/cells        connectivity (n_cells x nodes per cell)
//     /body_K/cell_area_ratio   current / reference area per cell (J)
//     /rigid               rigid disks (n_rigid x 4): x, y, radius, rotation
//   and, for viewers (xdmf.hpp: levels.xdmf beside the file),
//     /box/points, segments          the walls as four segments
//     /mesh/coordinates, displacement, cells, volumetric_strain, particle
//                          every deformable disk in one mesh (node numbers
//                          offset body by body, in body order)
//     /disks/centers, vertices, radius, rotation, particle   rigid disks
//     /contacts/points, segments, particles, normal_force, tangential_force
//                          the contact network (observables.hpp,
//                          ComputeForceNetwork), absent without contact force
// The CSV is written by rank 0. The HDF5 file is written in parallel (MPI-IO):
// each body's datasets by the rank owning it, the rest by rank 0; the file
// layout does not depend on the number of ranks.
#pragma once
#include <petscsys.h>

#include <cstdio>
#include <string>
#include <vector>

#include "deformix/problem.hpp"

namespace deformix {

class CsvWriter {
 public:
  CsvWriter() = default;
  ~CsvWriter();
  CsvWriter(const CsvWriter &) = delete;
  CsvWriter &operator=(const CsvWriter &) = delete;
  PetscErrorCode Open(MPI_Comm comm, const std::string &path, const std::vector<std::string> &columns);
  PetscErrorCode Row(const std::vector<double> &values);

 private:
  FILE *file_ = nullptr;
  size_t ncols_ = 0;
  MPI_Comm comm_ = MPI_COMM_NULL;
};

// Removes a file if it exists (rank 0).
PetscErrorCode RemoveFile(MPI_Comm comm, const std::string &path);

// Appends level `level` to the HDF5 file `path` (created at level 0, or
// when it does not exist) and rewrites the XDMF file beside it. Collective on comm.
PetscErrorCode WriteLevelHDF5(MPI_Comm comm, const std::string &path, int level, double P_over_E,
                              const CompactionProblem &problem);
// Removes the groups of levels `first`, first + 1, ... from `path`, if it
// exists (and rewrites its XDMF file): a run restarted from an earlier
// checkpoint rewrites them.
PetscErrorCode TruncateLevelsHDF5(MPI_Comm comm, const std::string &path, int first);

}  // namespace deformix

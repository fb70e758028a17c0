// ParaView / VisIt view of levels.h5: an XDMF 3 file beside it (levels.xdmf)
// that names the datasets of every level as a time series (time = P/E).
//
// Four temporal collections, one per kind of object, each level a uniform
// grid that points into levels.h5:
//   box              the walls as four segments (Polyline)
//   rigid disks      points (Polyvertex) with radius, rotation, particle
//   contacts         the contact network: a segment per force-carrying
//                    pair between the centres (observables.hpp,
//                    ComputeForceNetwork) with normal_force and
//                    tangential_force on the segment; absent at a level
//                    without contact force
//   deformable disks every deformable disk in one mesh of 6-node triangles
//                    (Triangle_6) with the displacement (node vectors),
//                    volumetric_strain J - 1 and the particle per cell
// The file is generated from what levels.h5 holds (so it follows restarts
// and truncations), by rank 0, written to a temporary file and renamed.
#pragma once
#include <petscsys.h>

#include <string>

namespace deformix {

// Path of the XDMF file of an HDF5 file: the same name with .xdmf.
std::string XdmfPathOf(const std::string &h5_path);

// Writes XdmfPathOf(h5_path) for the levels in h5_path (rank 0; collective
// only for the error check).
PetscErrorCode WriteLevelsXdmf(MPI_Comm comm, const std::string &h5_path);

}  // namespace deformix

// Driver options shared by every executable: pressure list and output
// directory, validated before anything is written.
#pragma once
#include <petscsys.h>

#include <string>
#include <vector>

namespace deformix {

// Reads -pressures (comma-separated P/E values). Refuses an empty list,
// negative or non-finite values.
PetscErrorCode GetPressureList(MPI_Comm comm, const std::vector<double> &defaults, std::vector<double> *pressures);

// Reads -output_dir.
PetscErrorCode GetOutputDirectory(MPI_Comm comm, const std::string &fallback, std::string *dir);

// Reads -restart FILE (a checkpoint to continue from; "" when not given),
// -checkpoint (write <output_dir>/checkpoint.h5 after every level) and
// -checkpoint_levels (keep a checkpoint of every level besides).
PetscErrorCode GetRestartOptions(MPI_Comm comm, std::string *restart, PetscBool *checkpoint,
                                 PetscBool *checkpoint_levels);

// Creates the directory (and parents) and checks that a file can be written
// in it, without touching any existing file. Collective; errors on every rank.
PetscErrorCode PrepareOutputDirectory(MPI_Comm comm, const std::string &dir);

// Refuses options that nothing in deformix or PETSc's solver stack will read
// (a misspelt -nuu must not silently run the default nu). Call it after
// every component has read its options; solver options (-snes_*, -ksp_*,
// -pc_*, -mat_*, ...) are read later and pass by their prefix.
PetscErrorCode CheckUnknownOptions(MPI_Comm comm);

// Refuses, before anything is allocated, a scene whose Jacobian and LU
// factors would not fit in the physical memory of the nodes the run has
// (a rough estimate: about 14 kB per triangle of every deformable disk).
PetscErrorCode CheckSceneMemory(MPI_Comm comm, double deformable_disks, double triangles_per_disk, double rigid_disks);

// The common main() of the drivers: PetscInitialize, run, PetscFinalize; any
// error becomes exit code 1. Errors in the user's input (options, files:
// PETSC_ERR_USER_INPUT, _FILE_OPEN, _FILE_READ, _FILE_UNEXPECTED, and while
// the options are read, PETSc's own _USER and _ARG_UNKNOWN_TYPE for a bad
// list entry or type name) print one line, "<program>: error: <message>";
// others PETSc's traceback.
int RunDriver(int argc, char **argv, const char *help, PetscErrorCode (*run)(MPI_Comm));

// True when -help was given: drivers print their options and stop before running.
bool HelpRequested();

}  // namespace deformix

#include "deformix/output.hpp"

#include <hdf5.h>

#include <cstring>

namespace deformix {

CsvWriter::~CsvWriter() {
  if (file_) std::fclose(file_);
}

PetscErrorCode CsvWriter::Open(MPI_Comm comm, const std::string &path, const std::vector<std::string> &columns) {
  PetscMPIInt rank;
  int ok = 1;
  PetscFunctionBeginUser;
  comm_ = comm;
  ncols_ = columns.size();
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  if (rank == 0) {
    file_ = std::fopen(path.c_str(), "w");
    ok = file_ != nullptr;
    for (size_t i = 0; ok && i < columns.size(); ++i) std::fprintf(file_, "%s%s", i ? "," : "", columns[i].c_str());
    if (ok) std::fprintf(file_, "\n"), std::fflush(file_);
  }
  PetscCallMPI(MPI_Bcast(&ok, 1, MPI_INT, 0, comm));
  PetscCheck(ok, comm, PETSC_ERR_FILE_OPEN, "cannot open %s for writing", path.c_str());
  PetscFunctionReturn(0);
}

PetscErrorCode CsvWriter::Row(const std::vector<double> &values) {
  PetscFunctionBeginUser;
  PetscCheck(values.size() == ncols_, comm_, PETSC_ERR_PLIB, "CSV row has %zu values for %zu columns", values.size(),
             ncols_);
  if (file_) {
    for (size_t i = 0; i < values.size(); ++i) std::fprintf(file_, "%s%.12g", i ? "," : "", values[i]);
    std::fprintf(file_, "\n");
    std::fflush(file_);
  }
  PetscFunctionReturn(0);
}

PetscErrorCode RemoveFile(MPI_Comm comm, const std::string &path) {
  PetscMPIInt rank;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  if (rank == 0) std::remove(path.c_str());
  PetscFunctionReturn(0);
}

namespace {

herr_t WriteDataset(hid_t group, const char *name, hid_t type, int rows, int cols, const void *data) {
  hsize_t dims[2] = {static_cast<hsize_t>(rows), static_cast<hsize_t>(cols)};
  hid_t space = H5Screate_simple(cols > 1 ? 2 : 1, dims, nullptr);
  hid_t set = H5Dcreate2(group, name, type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  herr_t st = (set < 0) ? -1 : H5Dwrite(set, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data);
  if (set >= 0) H5Dclose(set);
  H5Sclose(space);
  return st;
}

herr_t WriteAttribute(hid_t obj, const char *name, double v) {
  hid_t space = H5Screate(H5S_SCALAR);
  hid_t attr = H5Acreate2(obj, name, H5T_NATIVE_DOUBLE, space, H5P_DEFAULT, H5P_DEFAULT);
  herr_t st = (attr < 0) ? -1 : H5Awrite(attr, H5T_NATIVE_DOUBLE, &v);
  if (attr >= 0) H5Aclose(attr);
  H5Sclose(space);
  return st;
}

}  // namespace

PetscErrorCode WriteLevelHDF5(MPI_Comm comm, const std::string &path, int level, double P_over_E,
                              const CompactionProblem &problem) {
  PetscMPIInt rank;
  int ok = 1;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  if (rank == 0) {
    hid_t file = level == 0 ? H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT)
                            : H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    ok = file >= 0;
    if (ok) {
      char name[64];
      std::snprintf(name, sizeof(name), "level_%04d", level);
      hid_t g = H5Gcreate2(file, name, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
      const StateSummary s = problem.Summary();
      ok = g >= 0 && WriteAttribute(g, "P_over_E", P_over_E) >= 0 &&
           WriteAttribute(g, "packing_fraction", s.packing_fraction) >= 0 &&
           WriteDataset(g, "walls", H5T_NATIVE_DOUBLE, 4, 1, problem.Walls()) >= 0;
      for (int b = 0; ok && b < static_cast<int>(problem.Bodies().size()); ++b) {
        const DeformableBody &body = problem.Bodies()[b];
        const int nn = body.mesh.num_nodes(), nc = body.mesh.num_cells(), nen = body.mesh.nodes_per_cell();
        std::vector<double> x(2 * nn);
        for (int a = 0; a < nn; ++a) problem.NodePosition(b, a, &x[2 * a]);
        const std::vector<double> J = problem.CellAreaRatio(b);
        std::snprintf(name, sizeof(name), "body_%d", b);
        hid_t gb = H5Gcreate2(g, name, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
        ok = gb >= 0 && WriteDataset(gb, "coordinates", H5T_NATIVE_DOUBLE, nn, 2, x.data()) >= 0 &&
             WriteDataset(gb, "cells", H5T_NATIVE_INT, nc, nen, body.mesh.cells.data()) >= 0 &&
             WriteDataset(gb, "cell_area_ratio", H5T_NATIVE_DOUBLE, nc, 1, J.data()) >= 0;
        if (gb >= 0) H5Gclose(gb);
      }
      const std::vector<RigidBody> &rigid = problem.RigidBodies();
      if (ok && !rigid.empty()) {
        std::vector<double> xr(4 * rigid.size());
        for (size_t r = 0; r < rigid.size(); ++r) {
          problem.RigidPosition(static_cast<int>(r), &xr[4 * r], &xr[4 * r + 3]);
          xr[4 * r + 2] = rigid[r].radius;
        }
        ok = WriteDataset(g, "rigid", H5T_NATIVE_DOUBLE, static_cast<int>(rigid.size()), 4, xr.data()) >= 0;
      }
      if (g >= 0) H5Gclose(g);
      H5Fclose(file);
    }
  }
  PetscCallMPI(MPI_Bcast(&ok, 1, MPI_INT, 0, comm));
  PetscCheck(ok, comm, PETSC_ERR_FILE_WRITE, "writing level %d to %s failed", level, path.c_str());
  PetscFunctionReturn(0);
}

}  // namespace deformix

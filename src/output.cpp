#include "deformix/output.hpp"

#include <hdf5.h>

#include <cstring>
#include <unistd.h>

#include "deformix/observables.hpp"
#include "deformix/xdmf.hpp"

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

// Creates dataset `name` (rows x cols; 1-D if cols == 1) in `group`, which is
// collective, and writes `data` into it on the ranks that pass it (nullptr:
// create only). The data is written with the default, independent transfer.
herr_t WriteDataset(hid_t group, const char *name, hid_t type, int rows, int cols, const void *data) {
  hsize_t dims[2] = {static_cast<hsize_t>(rows), static_cast<hsize_t>(cols)};
  hid_t space = H5Screate_simple(cols > 1 ? 2 : 1, dims, nullptr);
  // One rank writes every element, so skip the fill with default values.
  hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE);
  H5Pset_fill_time(dcpl, H5D_FILL_TIME_NEVER);
  hid_t set = H5Dcreate2(group, name, type, space, H5P_DEFAULT, dcpl, H5P_DEFAULT);
  herr_t st = (set < 0) ? -1 : data ? H5Dwrite(set, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data) : 0;
  if (set >= 0) H5Dclose(set);
  H5Pclose(dcpl);
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


// The datasets the XDMF file (WriteLevelsXdmf) shows, in one piece per kind
// (every deformable disk in one mesh), from the replicated state; rank 0
// writes the data, every rank takes part in the creation (collective).
herr_t WriteViewerDatasets(hid_t level, const CompactionProblem &problem, bool writer) {
  herr_t st = 0;
  const std::vector<DeformableBody> &bodies = problem.Bodies();
  // Box outline: corners (left, bottom), (right, bottom), (right, top), (left, top).
  {
    const double *w = problem.Walls();
    const double corners[8] = {w[kLeft], w[kBottom], w[kRight], w[kBottom], w[kRight], w[kTop], w[kLeft], w[kTop]};
    const int sides[8] = {0, 1, 1, 2, 2, 3, 3, 0};
    hid_t g = H5Gcreate2(level, "box", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    if (g < 0 || WriteDataset(g, "points", H5T_NATIVE_DOUBLE, 4, 2, writer ? corners : nullptr) < 0 ||
        WriteDataset(g, "segments", H5T_NATIVE_INT, 4, 2, writer ? sides : nullptr) < 0)
      st = -1;
    if (g >= 0) H5Gclose(g);
  }
  if (!bodies.empty()) {
    int nn = 0, nc = 0;
    for (const DeformableBody &b : bodies) nn += b.mesh.num_nodes(), nc += b.mesh.num_cells();
    const int nen = bodies[0].mesh.nodes_per_cell();
    std::vector<double> x, u, strain;
    std::vector<int> cells, particle;
    if (writer) {
      const std::vector<double> &disp = problem.Displacements();
      int first = 0;
      for (int b = 0; b < static_cast<int>(bodies.size()); ++b) {
        const DeformableBody &body = bodies[b];
        for (int a = 0; a < body.mesh.num_nodes(); ++a) {
          double p[2];
          problem.NodePosition(b, a, p);
          x.insert(x.end(), {p[0], p[1]});
          u.insert(u.end(), {disp[body.dof_offset + 2 * a], disp[body.dof_offset + 2 * a + 1]});
        }
        for (int n : body.mesh.cells) cells.push_back(first + n);
        for (double J : problem.CellAreaRatio(b)) strain.push_back(J - 1.0), particle.push_back(body.particle);
        first += body.mesh.num_nodes();
      }
    }
    hid_t g = H5Gcreate2(level, "mesh", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    if (g < 0 || WriteDataset(g, "coordinates", H5T_NATIVE_DOUBLE, nn, 2, writer ? x.data() : nullptr) < 0 ||
        WriteDataset(g, "displacement", H5T_NATIVE_DOUBLE, nn, 2, writer ? u.data() : nullptr) < 0 ||
        WriteDataset(g, "cells", H5T_NATIVE_INT, nc, nen, writer ? cells.data() : nullptr) < 0 ||
        WriteDataset(g, "volumetric_strain", H5T_NATIVE_DOUBLE, nc, 1, writer ? strain.data() : nullptr) < 0 ||
        WriteDataset(g, "particle", H5T_NATIVE_INT, nc, 1, writer ? particle.data() : nullptr) < 0)
      st = -1;
    if (g >= 0) H5Gclose(g);
  }
  const std::vector<RigidBody> &rigid = problem.RigidBodies();
  if (!rigid.empty()) {
    const int n = static_cast<int>(rigid.size());
    std::vector<double> c(2 * n), radius(n), rotation(n);
    std::vector<int> index(n), particle(n);
    for (int r = 0; r < n; ++r) {
      problem.RigidPosition(r, &c[2 * r], &rotation[r]);
      radius[r] = rigid[r].radius, index[r] = r, particle[r] = rigid[r].particle;
    }
    hid_t g = H5Gcreate2(level, "disks", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    if (g < 0 || WriteDataset(g, "centers", H5T_NATIVE_DOUBLE, n, 2, writer ? c.data() : nullptr) < 0 ||
        WriteDataset(g, "vertices", H5T_NATIVE_INT, n, 1, writer ? index.data() : nullptr) < 0 ||
        WriteDataset(g, "radius", H5T_NATIVE_DOUBLE, n, 1, writer ? radius.data() : nullptr) < 0 ||
        WriteDataset(g, "rotation", H5T_NATIVE_DOUBLE, n, 1, writer ? rotation.data() : nullptr) < 0 ||
        WriteDataset(g, "particle", H5T_NATIVE_INT, n, 1, writer ? particle.data() : nullptr) < 0)
      st = -1;
    if (g >= 0) H5Gclose(g);
  }
  // Contact network. Every rank computes it from the replicated state (the
  // sizes must agree for the collective creation).
  const ForceNetwork net = ComputeForceNetwork(problem);
  const int m = net.segments();
  if (m > 0) {
    std::vector<int> seg(2 * m);
    for (int i = 0; i < 2 * m; ++i) seg[i] = i;
    hid_t g = H5Gcreate2(level, "contacts", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    if (g < 0 || WriteDataset(g, "points", H5T_NATIVE_DOUBLE, 2 * m, 2, writer ? net.points.data() : nullptr) < 0 ||
        WriteDataset(g, "segments", H5T_NATIVE_INT, m, 2, writer ? seg.data() : nullptr) < 0 ||
        WriteDataset(g, "particles", H5T_NATIVE_INT, m, 2, writer ? net.particles.data() : nullptr) < 0 ||
        WriteDataset(g, "normal_force", H5T_NATIVE_DOUBLE, m, 1, writer ? net.normal_force.data() : nullptr) < 0 ||
        WriteDataset(g, "tangential_force", H5T_NATIVE_DOUBLE, m, 1, writer ? net.tangential_force.data() : nullptr) < 0)
      st = -1;
    if (g >= 0) H5Gclose(g);
  }
  return st;
}

}  // namespace

// With parallel HDF5 all ranks open the file through MPI-IO. Everything that
// touches the file's metadata is collective: opening and closing the file,
// creating groups and datasets, and writing attributes. All ranks make these
// calls with the same arguments in the same order, which they can because
// the state is replicated (every rank knows every shape). The raw data of a
// dataset is written independently by a single rank: a deformable body's
// datasets by the owner of its particle, /walls and /rigid by rank 0. A
// failed write only clears the rank's `ok` flag and never makes it skip the
// collective calls that follow; the flags are reduced at the end. Without
// parallel HDF5, rank 0 writes everything alone.
PetscErrorCode WriteLevelHDF5(MPI_Comm comm, const std::string &path, int level, double P_over_E,
                              const CompactionProblem &problem) {
  PetscMPIInt rank;
  int ok = 1;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  // Attribute values must be identical on all ranks: take rank 0's.
  double attr[2] = {P_over_E, problem.Summary().packing_fraction};
  PetscCallMPI(MPI_Bcast(attr, 2, MPI_DOUBLE, 0, comm));
  // A restarted run appends to the file of the run it continues, if it is there.
  int exists = 0;
  if (rank == 0) exists = access(path.c_str(), F_OK) == 0;
  PetscCallMPI(MPI_Bcast(&exists, 1, MPI_INT, 0, comm));
  hid_t fapl = H5Pcreate(H5P_FILE_ACCESS);
#ifdef H5_HAVE_PARALLEL
  H5Pset_fapl_mpio(fapl, comm, MPI_INFO_NULL);
  const bool opens = true;
  const std::vector<int> &owner = problem.ParticleOwners();  // empty on one rank: all rank 0's
#else
  const bool opens = rank == 0;
  const std::vector<int> owner;  // rank 0 writes everything
#endif
  if (opens) {
    hid_t file = (level == 0 || !exists) ? H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, fapl)
                                         : H5Fopen(path.c_str(), H5F_ACC_RDWR, fapl);
    ok = file >= 0;
    if (ok) {
      char name[64];
      std::snprintf(name, sizeof(name), "level_%04d", level);
      hid_t g = H5Gcreate2(file, name, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
      ok = g >= 0 && WriteAttribute(g, "P_over_E", attr[0]) >= 0 &&
           WriteAttribute(g, "packing_fraction", attr[1]) >= 0;
      if (g >= 0) {
        if (WriteDataset(g, "walls", H5T_NATIVE_DOUBLE, 4, 1, rank == 0 ? problem.Walls() : nullptr) < 0) ok = 0;
        for (int b = 0; b < static_cast<int>(problem.Bodies().size()); ++b) {
          const DeformableBody &body = problem.Bodies()[b];
          const bool mine = (owner.empty() ? 0 : owner[body.particle]) == rank;
          const int nn = body.mesh.num_nodes(), nc = body.mesh.num_cells(), nen = body.mesh.nodes_per_cell();
          std::vector<double> x, J;
          if (mine) {
            x.resize(2 * nn);
            for (int a = 0; a < nn; ++a) problem.NodePosition(b, a, &x[2 * a]);
            J = problem.CellAreaRatio(b);
          }
          std::snprintf(name, sizeof(name), "body_%d", b);
          hid_t gb = H5Gcreate2(g, name, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
          if (gb < 0 ||
              WriteDataset(gb, "coordinates", H5T_NATIVE_DOUBLE, nn, 2, mine ? x.data() : nullptr) < 0 ||
              WriteDataset(gb, "cells", H5T_NATIVE_INT, nc, nen, mine ? body.mesh.cells.data() : nullptr) < 0 ||
              WriteDataset(gb, "cell_area_ratio", H5T_NATIVE_DOUBLE, nc, 1, mine ? J.data() : nullptr) < 0)
            ok = 0;
          if (gb >= 0) H5Gclose(gb);
        }
        const std::vector<RigidBody> &rigid = problem.RigidBodies();
        if (!rigid.empty()) {
          std::vector<double> xr(4 * rigid.size());
          for (size_t r = 0; r < rigid.size(); ++r) {
            problem.RigidPosition(static_cast<int>(r), &xr[4 * r], &xr[4 * r + 3]);
            xr[4 * r + 2] = rigid[r].radius;
          }
          if (WriteDataset(g, "rigid", H5T_NATIVE_DOUBLE, static_cast<int>(rigid.size()), 4,
                           rank == 0 ? xr.data() : nullptr) < 0)
            ok = 0;
        }
        if (WriteViewerDatasets(g, problem, rank == 0) < 0) ok = 0;
        H5Gclose(g);
      }
      if (H5Fclose(file) < 0) ok = 0;
    }
  }
  H5Pclose(fapl);
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &ok, 1, MPI_INT, MPI_MIN, comm));
  PetscCheck(ok, comm, PETSC_ERR_FILE_WRITE, "writing level %d to %s failed", level, path.c_str());
  PetscCall(WriteLevelsXdmf(comm, path));
  PetscFunctionReturn(0);
}

PetscErrorCode TruncateLevelsHDF5(MPI_Comm comm, const std::string &path, int first) {
  PetscMPIInt rank;
  int ok = 1;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  if (rank == 0 && access(path.c_str(), F_OK) == 0) {
    H5E_auto2_t func;
    void *data;
    H5Eget_auto2(H5E_DEFAULT, &func, &data);
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
    hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    ok = file >= 0;
    for (int level = first; ok; ++level) {
      char name[64];
      std::snprintf(name, sizeof(name), "level_%04d", level);
      if (H5Lexists(file, name, H5P_DEFAULT) <= 0) break;
      ok = H5Ldelete(file, name, H5P_DEFAULT) >= 0;
    }
    if (file >= 0 && H5Fclose(file) < 0) ok = 0;
    H5Eset_auto2(H5E_DEFAULT, func, data);
  }
  PetscCallMPI(MPI_Bcast(&ok, 1, MPI_INT, 0, comm));
  PetscCheck(ok, comm, PETSC_ERR_FILE_WRITE, "%s: cannot remove the levels from %d on (restart); move the file away",
             path.c_str(), first);
  int exists = 0;
  if (rank == 0) exists = access(path.c_str(), F_OK) == 0;
  PetscCallMPI(MPI_Bcast(&exists, 1, MPI_INT, 0, comm));
  if (exists) PetscCall(WriteLevelsXdmf(comm, path));
  PetscFunctionReturn(0);
}

}  // namespace deformix

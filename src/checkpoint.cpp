#include "deformix/checkpoint.hpp"

#include <hdf5.h>

#include <algorithm>
#include <cstdio>
#include <sstream>
#include <stdexcept>

namespace deformix {

namespace {

constexpr int kFormat = 1;  // bump when the layout changes; older files are refused

// A failed HDF5 call inside this file: caught at the entry points and turned
// into a PETSc error, so no exception leaves them.
struct H5Failure : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Owns one HDF5 identifier and closes it with the matching H5*close.
class H5Id {
 public:
  H5Id(hid_t id, herr_t (*close)(hid_t), const std::string &what) : id_(id), close_(close) {
    if (id_ < 0) throw H5Failure(what);
  }
  ~H5Id() { close_(id_); }
  H5Id(const H5Id &) = delete;
  H5Id &operator=(const H5Id &) = delete;
  operator hid_t() const { return id_; }

 private:
  hid_t id_;
  herr_t (*close_)(hid_t);
};

// HDF5 prints its own error stack by default; the messages here are ours.
class QuietHDF5 {
 public:
  QuietHDF5() {
    H5Eget_auto2(H5E_DEFAULT, &func_, &data_);
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  }
  ~QuietHDF5() { H5Eset_auto2(H5E_DEFAULT, func_, data_); }

 private:
  H5E_auto2_t func_ = nullptr;
  void *data_ = nullptr;
};

void check(herr_t status, const std::string &what) {
  if (status < 0) throw H5Failure(what);
}

template <class T>
hid_t native_type();
template <>
hid_t native_type<double>() { return H5T_NATIVE_DOUBLE; }
template <>
hid_t native_type<int>() { return H5T_NATIVE_INT; }

// rows x cols dataset (1-D when cols == 0); empty ones are created but not written.
template <class T>
void write_array(hid_t loc, const char *name, const std::vector<T> &data, size_t cols = 0) {
  const size_t rows = cols ? data.size() / cols : data.size();
  const hsize_t dims[2] = {rows, cols};
  H5Id space(H5Screate_simple(cols ? 2 : 1, dims, nullptr), H5Sclose, "dataspace");
  H5Id set(H5Dcreate2(loc, name, native_type<T>(), space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Dclose,
           std::string("creating ") + name);
  if (!data.empty()) check(H5Dwrite(set, native_type<T>(), H5S_ALL, H5S_ALL, H5P_DEFAULT, data.data()), name);
}

// Reads a dataset whose trailing dimension must be `cols` (0: 1-D).
template <class T>
std::vector<T> read_array(hid_t loc, const char *name, size_t cols = 0) {
  H5Id set(H5Dopen2(loc, name, H5P_DEFAULT), H5Dclose, std::string("dataset ") + name + " is missing");
  H5Id space(H5Dget_space(set), H5Sclose, name);
  hsize_t dims[2] = {0, 0};
  const int rank = H5Sget_simple_extent_ndims(space);
  if (rank != (cols ? 2 : 1) || H5Sget_simple_extent_dims(space, dims, nullptr) < 0 || (cols && dims[1] != cols))
    throw H5Failure(std::string("dataset ") + name + " has the wrong shape");
  std::vector<T> data(dims[0] * (cols ? cols : 1));
  if (!data.empty()) check(H5Dread(set, native_type<T>(), H5S_ALL, H5S_ALL, H5P_DEFAULT, data.data()), name);
  return data;
}

void write_attribute(hid_t obj, const char *name, double v) {
  H5Id space(H5Screate(H5S_SCALAR), H5Sclose, "dataspace");
  H5Id attr(H5Acreate2(obj, name, H5T_NATIVE_DOUBLE, space, H5P_DEFAULT, H5P_DEFAULT), H5Aclose, name);
  check(H5Awrite(attr, H5T_NATIVE_DOUBLE, &v), name);
}

double read_attribute(hid_t obj, const char *name) {
  H5Id attr(H5Aopen(obj, name, H5P_DEFAULT), H5Aclose, std::string("attribute ") + name + " is missing");
  double v = 0.0;
  check(H5Aread(attr, H5T_NATIVE_DOUBLE, &v), name);
  return v;
}

void write_string_attribute(hid_t obj, const char *name, const std::string &text) {
  H5Id type(H5Tcopy(H5T_C_S1), H5Tclose, "string type");
  check(H5Tset_size(type, text.size() + 1), name);
  H5Id space(H5Screate(H5S_SCALAR), H5Sclose, "dataspace");
  H5Id attr(H5Acreate2(obj, name, type, space, H5P_DEFAULT, H5P_DEFAULT), H5Aclose, name);
  check(H5Awrite(attr, type, text.c_str()), name);
}

std::string read_string_attribute(hid_t obj, const char *name) {
  H5Id attr(H5Aopen(obj, name, H5P_DEFAULT), H5Aclose, std::string("attribute ") + name + " is missing");
  H5Id type(H5Aget_type(attr), H5Tclose, name);
  if (H5Tget_class(type) != H5T_STRING) throw H5Failure(std::string("attribute ") + name + " is not a string");
  std::vector<char> buf(H5Tget_size(type) + 1, '\0');
  check(H5Aread(attr, type, buf.data()), name);
  return std::string(buf.data());
}

void write_state(hid_t file, const char *name, const CompactionProblem::State &s, double pressure) {
  H5Id g(H5Gcreate2(file, name, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose, name);
  write_attribute(g, "pressure", pressure);
  write_array(g, "u", s.u);
  write_array(g, "walls", std::vector<double>(s.w, s.w + 4));
  write_array(g, "torque", s.torque);
  write_array(g, "lambda_n", s.lambda);
  write_array(g, "lambda_t", s.lambda_t);
  std::vector<int> cand;
  for (const ContactCandidate &c : s.candidates)
    cand.insert(cand.end(), {static_cast<int>(c.type), c.body, c.point, static_cast<int>(c.wall), c.master, c.segment});
  write_array(g, "candidates", cand, 6);
}

CompactionProblem::State read_state(hid_t file, const char *name, double *pressure) {
  H5Id g(H5Gopen2(file, name, H5P_DEFAULT), H5Gclose, std::string("group ") + name + " is missing");
  CompactionProblem::State s;
  *pressure = read_attribute(g, "pressure");
  s.u = read_array<double>(g, "u");
  const std::vector<double> w = read_array<double>(g, "walls");
  if (w.size() != 4) throw H5Failure(std::string(name) + "/walls does not have 4 entries");
  std::copy(w.begin(), w.end(), s.w);
  s.torque = read_array<double>(g, "torque");
  s.lambda = read_array<double>(g, "lambda_n");
  s.lambda_t = read_array<double>(g, "lambda_t");
  const std::vector<int> cand = read_array<int>(g, "candidates", 6);
  for (size_t i = 0; i < cand.size(); i += 6) {
    ContactCandidate c;
    c.type = static_cast<ContactType>(cand[i]);
    c.body = cand[i + 1];
    c.point = cand[i + 2];
    c.wall = static_cast<Wall>(cand[i + 3]);
    c.master = cand[i + 4];
    c.segment = cand[i + 5];
    s.candidates.push_back(c);
  }
  return s;
}

void write_values(hid_t file, const char *name, const std::vector<SceneValue> &values) {
  H5Id g(H5Gcreate2(file, name, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose, name);
  for (const SceneValue &v : values) write_attribute(g, v.option.c_str(), v.value);
}

herr_t collect_name(hid_t, const char *name, const H5A_info_t *, void *names) {
  static_cast<std::vector<std::string> *>(names)->push_back(name);
  return 0;
}

std::vector<SceneValue> read_values(hid_t file, const char *name) {
  H5Id g(H5Gopen2(file, name, H5P_DEFAULT), H5Gclose, std::string("group ") + name + " is missing");
  std::vector<std::string> names;
  check(H5Aiterate2(g, H5_INDEX_NAME, H5_ITER_INC, nullptr, collect_name, &names), name);
  std::vector<SceneValue> values;
  for (const std::string &n : names) values.push_back({n, read_attribute(g, n.c_str())});
  return values;
}

std::string format_difference(const std::string &option, const std::string &saved, const std::string &run) {
  return "-" + option + ": checkpoint " + saved + ", this run " + run;
}

std::string number(double v) {
  std::ostringstream os;
  os << v;
  return os.str();
}

}  // namespace

std::string SceneDifference(const Scene &saved, const Scene &run) {
  for (const SceneValue &r : run) {
    auto it = std::find_if(saved.begin(), saved.end(), [&](const SceneValue &s) { return s.option == r.option; });
    if (it == saved.end()) return format_difference(r.option, "none", number(r.value));
    if (it->value != r.value) return format_difference(r.option, number(it->value), number(r.value));
  }
  for (const SceneValue &s : saved)
    if (std::none_of(run.begin(), run.end(), [&](const SceneValue &r) { return s.option == r.option; }))
      return format_difference(s.option, number(s.value), "none");
  return "";
}

double Checkpoint::Value(const std::string &name) const {
  for (const SceneValue &v : values)
    if (v.option == name) return v.value;
  return 0.0;
}

PetscErrorCode WriteCheckpoint(MPI_Comm comm, const std::string &path, const Checkpoint &c) {
  PetscMPIInt rank;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  std::string error;
  if (rank == 0) {
    const std::string tmp = path + ".tmp";
    try {
      QuietHDF5 quiet;
      {
        H5Id file(H5Fcreate(tmp.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose, "cannot create " + tmp);
        write_attribute(file, "format", kFormat);
        write_string_attribute(file, "driver", c.driver);
        write_attribute(file, "load_step", c.load_step);
        write_attribute(file, "have_previous", c.state.have_previous ? 1.0 : 0.0);
        write_values(file, "scene", c.scene);
        write_values(file, "values", c.values);
        write_array(file, "levels", c.levels);
        std::vector<double> rows;
        for (const std::vector<double> &r : c.rows) rows.insert(rows.end(), r.begin(), r.end());
        std::string header;
        for (const std::string &col : c.columns) header += (header.empty() ? "" : ",") + col;
        write_array(file, "curve", rows, c.columns.size());
        {
          H5Id curve(H5Dopen2(file, "curve", H5P_DEFAULT), H5Dclose, "curve");
          write_string_attribute(curve, "columns", header);
        }
        const DiskPacking &p = c.packing;
        std::vector<double> disks;
        for (int i = 0; i < p.size(); ++i) disks.insert(disks.end(), {p.x[i], p.y[i], p.radius[i], double(p.deformable[i])});
        write_array(file, "packing", disks, 4);
        write_array(file, "walls", std::vector<double>(p.walls, p.walls + 4));
        write_state(file, "current", c.state.current, c.state.pressure);
        check(H5Fflush(file, H5F_SCOPE_GLOBAL), "flush");
      }
      if (std::rename(tmp.c_str(), path.c_str()) != 0) throw H5Failure("cannot rename " + tmp + " to " + path);
    } catch (const H5Failure &e) {
      error = e.what();
      std::remove(tmp.c_str());
    }
  }
  int failed = !error.empty();
  PetscCallMPI(MPI_Bcast(&failed, 1, MPI_INT, 0, comm));
  PetscCheck(!failed, comm, PETSC_ERR_FILE_WRITE, "writing the checkpoint %s failed: %s", path.c_str(), error.c_str());
  PetscFunctionReturn(0);
}

PetscErrorCode WriteLevelCheckpoint(MPI_Comm comm, const std::string &path, const std::vector<double> &pressures,
                                    size_t level, const std::vector<std::vector<double>> &rows, double load_step,
                                    const CompactionProblem &problem, Checkpoint *c) {
  PetscFunctionBeginUser;
  c->levels.assign(pressures.begin(), pressures.begin() + level + 1);
  c->rows = rows;
  c->load_step = load_step;
  c->state = problem.TakeSnapshot();
  PetscCall(WriteCheckpoint(comm, path, *c));
  PetscFunctionReturn(0);
}

PetscErrorCode ReadCheckpoint(MPI_Comm comm, const std::string &path, Checkpoint *c) {
  PetscFunctionBeginUser;
  std::string error;
  *c = Checkpoint();
  try {
    QuietHDF5 quiet;
    if (H5Fis_hdf5(path.c_str()) <= 0) {
      FILE *f = std::fopen(path.c_str(), "rb");
      if (!f) throw H5Failure("cannot open it (no such file, or not readable)");
      std::fclose(f);
      throw H5Failure("it is not an HDF5 file");
    }
    H5Id file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose, "cannot open it as HDF5");
    if (H5Aexists(file, "format") <= 0) throw H5Failure("it is not a deformix checkpoint (no format attribute)");
    const double format = read_attribute(file, "format");
    if (format != kFormat) {
      std::ostringstream os;
      os << "its format is " << format << ", this build reads format " << kFormat;
      throw H5Failure(os.str());
    }
    c->driver = read_string_attribute(file, "driver");
    c->scene = read_values(file, "scene");
    c->values = read_values(file, "values");
    c->load_step = read_attribute(file, "load_step");
    c->state.have_previous = read_attribute(file, "have_previous") != 0.0;
    c->levels = read_array<double>(file, "levels");
    {
      H5Id curve(H5Dopen2(file, "curve", H5P_DEFAULT), H5Dclose, "dataset curve is missing");
      std::istringstream header(read_string_attribute(curve, "columns"));
      for (std::string col; std::getline(header, col, ',');) c->columns.push_back(col);
    }
    if (c->columns.empty()) throw H5Failure("the curve has no columns");
    const std::vector<double> rows = read_array<double>(file, "curve", c->columns.size());
    for (size_t i = 0; i < rows.size(); i += c->columns.size())
      c->rows.emplace_back(rows.begin() + i, rows.begin() + i + c->columns.size());
    if (c->rows.size() != c->levels.size()) throw H5Failure("its curve rows do not match its levels");
    const std::vector<double> disks = read_array<double>(file, "packing", 4);
    for (size_t i = 0; i < disks.size(); i += 4) {
      c->packing.x.push_back(disks[i]);
      c->packing.y.push_back(disks[i + 1]);
      c->packing.radius.push_back(disks[i + 2]);
      c->packing.deformable.push_back(disks[i + 3] != 0.0);
    }
    const std::vector<double> walls = read_array<double>(file, "walls");
    if (walls.size() != 4) throw H5Failure("walls does not have 4 entries");
    std::copy(walls.begin(), walls.end(), c->packing.walls);
    c->state.current = read_state(file, "current", &c->state.pressure);
  } catch (const H5Failure &e) {
    error = e.what();
  }
  int failed = !error.empty();
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &failed, 1, MPI_INT, MPI_MAX, comm));
  PetscCheck(!failed, comm, PETSC_ERR_FILE_READ, "-restart %s: %s", path.c_str(),
             error.empty() ? "another rank could not read it" : error.c_str());
  PetscFunctionReturn(0);
}

PetscErrorCode LoadRestart(MPI_Comm comm, const std::string &path, const std::string &driver, const Scene &scene,
                           const std::vector<std::string> &columns, const std::vector<double> &pressures,
                           Checkpoint *c) {
  PetscFunctionBeginUser;
  PetscCall(ReadCheckpoint(comm, path, c));
  PetscCheck(c->driver == driver, comm, PETSC_ERR_USER_INPUT, "-restart %s was written by %s, not by %s", path.c_str(),
             c->driver.c_str(), driver.c_str());
  const std::string diff = SceneDifference(c->scene, scene);
  PetscCheck(diff.empty(), comm, PETSC_ERR_USER_INPUT,
             "-restart %s was written for another scene (%s): give the scene options of the run it continues",
             path.c_str(), diff.c_str());
  PetscCheck(c->columns == columns, comm, PETSC_ERR_FILE_UNEXPECTED,
             "-restart %s was written by another version of %s (its curve.csv columns differ)", path.c_str(),
             driver.c_str());
  const size_t done = c->levels.size();
  for (size_t i = 0; i < done; ++i) {
    char given[32] = "nothing";
    if (i < pressures.size()) std::snprintf(given, sizeof(given), "%g", pressures[i]);
    PetscCheck(i < pressures.size() && pressures[i] == c->levels[i], comm, PETSC_ERR_USER_INPUT,
               "-restart %s: its level %zu is P/E = %g, but -pressures has %s there; -pressures must begin with "
               "the %zu levels of the checkpoint", path.c_str(), i, c->levels[i], given, done);
  }
  PetscCheck(pressures.size() > done, comm, PETSC_ERR_USER_INPUT,
             "-restart %s: the checkpoint already holds all %zu levels of -pressures; add levels to continue",
             path.c_str(), done);
  PetscFunctionReturn(0);
}

}  // namespace deformix

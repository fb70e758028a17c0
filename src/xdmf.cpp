#include "deformix/xdmf.hpp"

#include <hdf5.h>

#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <vector>

namespace deformix {

std::string XdmfPathOf(const std::string &h5_path) {
  const size_t dot = h5_path.rfind('.'), slash = h5_path.rfind('/');
  const bool has_ext = dot != std::string::npos && (slash == std::string::npos || dot > slash);
  return (has_ext ? h5_path.substr(0, dot) : h5_path) + ".xdmf";
}

namespace {

// Dimensions of dataset `path` (1-D datasets: cols = 1); false if absent.
bool Shape(hid_t file, const std::string &path, hsize_t *rows, hsize_t *cols) {
  if (H5Lexists(file, path.c_str(), H5P_DEFAULT) <= 0) return false;
  hid_t set = H5Dopen2(file, path.c_str(), H5P_DEFAULT);
  if (set < 0) return false;
  hid_t space = H5Dget_space(set);
  hsize_t dims[2] = {0, 1};
  const int rank = H5Sget_simple_extent_ndims(space);
  H5Sget_simple_extent_dims(space, dims, nullptr);
  if (rank == 1) dims[1] = 1;
  H5Sclose(space);
  H5Dclose(set);
  *rows = dims[0], *cols = dims[1];
  return true;
}

bool GroupExists(hid_t file, const std::string &path) { return H5Lexists(file, path.c_str(), H5P_DEFAULT) > 0; }

herr_t CollectLevel(hid_t, const char *name, const H5L_info_t *, void *data) {
  if (std::strncmp(name, "level_", 6) == 0) static_cast<std::vector<std::string> *>(data)->push_back(name);
  return 0;
}

struct Writer {
  std::ostringstream xml;
  std::string h5_name;  // the HDF5 file's name, relative to the XDMF file
  hid_t file;

  void Item(const std::string &path, hsize_t rows, hsize_t cols, bool integer) {
    xml << "          <DataItem Dimensions=\"" << rows;
    if (cols > 1) xml << " " << cols;
    xml << "\" NumberType=\"" << (integer ? "Int" : "Float") << "\" Precision=\"" << (integer ? 4 : 8)
        << "\" Format=\"HDF\">" << h5_name << ":" << path << "</DataItem>\n";
  }
  // An attribute from dataset path (present: checked by the caller).
  void Attribute(const std::string &name, const std::string &path, const char *center, bool integer = false) {
    hsize_t rows, cols;
    if (!Shape(file, path, &rows, &cols)) return;
    xml << "        <Attribute Name=\"" << name << "\" AttributeType=\"" << (cols > 1 ? "Vector" : "Scalar")
        << "\" Center=\"" << center << "\">\n";
    Item(path, rows, cols, integer);
    xml << "        </Attribute>\n";
  }
  // One uniform grid: topology from `cells` (rows x nodes per element), geometry from `points`.
  bool Grid(const std::string &name, double time, const char *topology, const std::string &cells,
            const std::string &points) {
    hsize_t nc, npe, np, dim;
    if (!Shape(file, cells, &nc, &npe) || !Shape(file, points, &np, &dim) || nc == 0) return false;
    xml << "      <Grid Name=\"" << name << "\" GridType=\"Uniform\">\n";
    xml << "        <Time Value=\"" << time << "\"/>\n";
    xml << "        <Topology TopologyType=\"" << topology << "\" NumberOfElements=\"" << nc << "\"";
    if (std::string(topology) == "Polyline" || std::string(topology) == "Polyvertex")
      xml << " NodesPerElement=\"" << npe << "\"";
    xml << ">\n";
    Item(cells, nc, npe, true);
    xml << "        </Topology>\n        <Geometry GeometryType=\"XY\">\n";
    Item(points, np, dim, false);
    xml << "        </Geometry>\n";
    return true;
  }
};

}  // namespace

PetscErrorCode WriteLevelsXdmf(MPI_Comm comm, const std::string &h5_path) {
  PetscMPIInt rank;
  int ok = 1;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  if (rank == 0) {
    H5E_auto2_t func;
    void *data;
    H5Eget_auto2(H5E_DEFAULT, &func, &data);
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
    hid_t file = H5Fopen(h5_path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    ok = file >= 0;
    if (ok) {
      std::vector<std::string> levels;
      H5Literate(file, H5_INDEX_NAME, H5_ITER_INC, nullptr, CollectLevel, &levels);
      std::vector<double> times(levels.size(), 0.0);
      for (size_t k = 0; k < levels.size(); ++k) {
        hid_t g = H5Gopen2(file, levels[k].c_str(), H5P_DEFAULT);
        if (g >= 0 && H5Aexists(g, "P_over_E") > 0) {
          hid_t a = H5Aopen(g, "P_over_E", H5P_DEFAULT);
          H5Aread(a, H5T_NATIVE_DOUBLE, &times[k]);
          H5Aclose(a);
        }
        if (g >= 0) H5Gclose(g);
      }
      Writer w;
      w.file = file;
      const size_t slash = h5_path.rfind('/');
      w.h5_name = slash == std::string::npos ? h5_path : h5_path.substr(slash + 1);
      w.xml.precision(17);
      w.xml << "<?xml version=\"1.0\"?>\n<Xdmf Version=\"3.0\">\n  <Domain>\n";
      // The deformable disks last: readers that take one series (meshio) take the last.
      for (const char *kind : {"box", "rigid disks", "contacts", "deformable disks"}) {
        std::ostringstream steps;
        steps.precision(17);
        std::swap(w.xml, steps);
        int n = 0;
        for (size_t k = 0; k < levels.size(); ++k) {
          const std::string l = "/" + levels[k];
          const std::string what = kind;
          bool open = false;
          if (what == "box") {
            open = w.Grid("box", times[k], "Polyline", l + "/box/segments", l + "/box/points");
          } else if (what == "rigid disks" && GroupExists(file, l + "/disks")) {
            open = w.Grid("rigid disks", times[k], "Polyvertex", l + "/disks/vertices", l + "/disks/centers");
            if (open) {
              w.Attribute("radius", l + "/disks/radius", "Node");
              w.Attribute("rotation", l + "/disks/rotation", "Node");
              w.Attribute("particle", l + "/disks/particle", "Node", true);
            }
          } else if (what == "contacts" && GroupExists(file, l + "/contacts")) {
            open = w.Grid("contacts", times[k], "Polyline", l + "/contacts/segments", l + "/contacts/points");
            if (open) {
              w.Attribute("normal_force", l + "/contacts/normal_force", "Cell");
              w.Attribute("tangential_force", l + "/contacts/tangential_force", "Cell");
            }
          } else if (what == "deformable disks" && GroupExists(file, l + "/mesh")) {
            hsize_t nc, npe;
            Shape(file, l + "/mesh/cells", &nc, &npe);
            open = w.Grid("deformable disks", times[k], npe == 6 ? "Triangle_6" : "Triangle", l + "/mesh/cells",
                          l + "/mesh/coordinates");
            if (open) {
              w.Attribute("displacement", l + "/mesh/displacement", "Node");
              w.Attribute("volumetric_strain", l + "/mesh/volumetric_strain", "Cell");
              w.Attribute("particle", l + "/mesh/particle", "Cell", true);
            }
          }
          if (open) w.xml << "      </Grid>\n", ++n;
        }
        std::swap(w.xml, steps);
        if (n == 0) continue;
        w.xml << "    <Grid Name=\"" << kind << "\" GridType=\"Collection\" CollectionType=\"Temporal\">\n"
              << steps.str() << "    </Grid>\n";
      }
      w.xml << "  </Domain>\n</Xdmf>\n";
      H5Fclose(file);
      const std::string path = XdmfPathOf(h5_path), tmp = path + ".tmp";
      std::ofstream out(tmp);
      out << w.xml.str();
      out.close();
      ok = out.good() && std::rename(tmp.c_str(), path.c_str()) == 0;
    }
    H5Eset_auto2(H5E_DEFAULT, func, data);
  }
  PetscCallMPI(MPI_Bcast(&ok, 1, MPI_INT, 0, comm));
  PetscCheck(ok, comm, PETSC_ERR_FILE_WRITE, "cannot write %s from %s", XdmfPathOf(h5_path).c_str(), h5_path.c_str());
  PetscFunctionReturn(0);
}

}  // namespace deformix

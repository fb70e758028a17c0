#include "deformix/options.hpp"

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <sys/stat.h>
#include <unistd.h>

namespace deformix {

PetscErrorCode GetPressureList(MPI_Comm comm, const std::vector<double> &defaults, std::vector<double> *pressures) {
  PetscInt n = 256;
  std::vector<PetscReal> values(n);
  PetscBool set = PETSC_FALSE;
  std::string def;
  for (double p : defaults) {
    char buf[32];
    std::snprintf(buf, sizeof(buf), "%g", p);
    def += (def.empty() ? "" : ",") + std::string(buf);
  }
  PetscFunctionBeginUser;
  PetscOptionsBegin(comm, nullptr, "Loading", "deformix");
  const std::string text = "comma-separated list of target P/E levels, applied in order (default " + def + ")";
  PetscCall(PetscOptionsRealArray("-pressures", text.c_str(), "", values.data(), &n, &set));
  PetscOptionsEnd();
  // "-pressures" given without a value (or as '') comes back as not set.
  PetscBool given = PETSC_FALSE;
  PetscCall(PetscOptionsHasName(nullptr, nullptr, "-pressures", &given));
  PetscCheck(!given || (set && n > 0), comm, PETSC_ERR_USER_INPUT,
             "-pressures is empty: give at least one P/E value, e.g. -pressures 0.01,0.1,0.5");
  if (!set) {
    *pressures = defaults;
    PetscFunctionReturn(0);
  }
  PetscCheck(n > 0, comm, PETSC_ERR_USER_INPUT,
             "-pressures is empty: give at least one P/E value, e.g. -pressures 0.01,0.1,0.5");
  pressures->assign(values.begin(), values.begin() + n);
  for (PetscInt i = 0; i < n; ++i)
    PetscCheck(std::isfinite(values[i]) && values[i] >= 0.0, comm, PETSC_ERR_USER_INPUT,
               "-pressures entry %" PetscInt_FMT " is %g: pressure levels P/E must be finite and >= 0", i,
               (double)values[i]);
  PetscFunctionReturn(0);
}

PetscErrorCode GetOutputDirectory(MPI_Comm comm, const std::string &fallback, std::string *dir) {
  char buf[PETSC_MAX_PATH_LEN];
  PetscFunctionBeginUser;
  PetscCall(PetscStrncpy(buf, fallback.c_str(), sizeof(buf)));
  PetscOptionsBegin(comm, nullptr, "Output", "deformix");
  PetscCall(PetscOptionsString("-output_dir", "directory for curve.csv and the HDF5 results", "", buf, buf,
                               sizeof(buf), nullptr));
  PetscOptionsEnd();
  *dir = buf;
  PetscCheck(!dir->empty(), comm, PETSC_ERR_USER_INPUT, "-output_dir is empty");
  PetscFunctionReturn(0);
}

PetscErrorCode GetRestartOptions(MPI_Comm comm, std::string *restart, PetscBool *checkpoint,
                                 PetscBool *checkpoint_levels) {
  char buf[PETSC_MAX_PATH_LEN] = "";
  PetscBool set = PETSC_FALSE;
  PetscFunctionBeginUser;
  PetscOptionsBegin(comm, nullptr, "Checkpoints", "deformix");
  PetscCall(PetscOptionsBool("-checkpoint", "write <output_dir>/checkpoint.h5 after every level (for -restart)", "",
                             *checkpoint, checkpoint, nullptr));
  PetscCall(PetscOptionsBool("-checkpoint_levels",
                             "also keep <output_dir>/checkpoint_level_<k>.h5 after every level k = 0, 1, ... (-restart "
                             "from any level of the run, e.g. to solve one level again with other solver options)",
                             "", *checkpoint_levels, checkpoint_levels, nullptr));
  PetscCall(PetscOptionsString("-restart",
                               "continue the run saved in this checkpoint.h5: the scene options must be the same and its "
                               "levels the first ones of -pressures",
                               "", buf, buf, sizeof(buf), &set));
  PetscOptionsEnd();
  PetscCheck(!set || buf[0], comm, PETSC_ERR_USER_INPUT,
             "-restart needs the path of a checkpoint.h5, e.g. -restart out/compact/checkpoint.h5");
  *restart = buf;
  PetscFunctionReturn(0);
}

static int MakeDirectories(const std::string &dir) {
  std::string partial;
  size_t pos = 0;
  while (pos != std::string::npos) {
    pos = dir.find('/', pos + 1);
    partial = dir.substr(0, pos);
    if (partial.empty()) continue;
    if (mkdir(partial.c_str(), 0755) != 0 && errno != EEXIST) return errno;
  }
  struct stat st;
  if (stat(dir.c_str(), &st) != 0) return errno;
  return S_ISDIR(st.st_mode) ? 0 : ENOTDIR;
}

PetscErrorCode PrepareOutputDirectory(MPI_Comm comm, const std::string &dir) {
  PetscMPIInt rank;
  int err = 0;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  if (rank == 0) {
    err = MakeDirectories(dir);
    if (!err) {
      const std::string probe = dir + "/.deformix-write-test-" + std::to_string(getpid());
      FILE *f = std::fopen(probe.c_str(), "w");
      if (!f) err = errno;
      else std::fclose(f), std::remove(probe.c_str());
    }
  }
  PetscCallMPI(MPI_Bcast(&err, 1, MPI_INT, 0, comm));
  PetscCheck(err == 0, comm, PETSC_ERR_FILE_OPEN, "-output_dir '%s' cannot be written: %s", dir.c_str(),
             std::strerror(err));
  PetscFunctionReturn(0);
}

namespace {
// True until CheckUnknownOptions has run: PETSc's own option parsing reports
// a bad value with PETSC_ERR_USER (an unknown list entry) or
// PETSC_ERR_ARG_UNKNOWN_TYPE (an unknown type name); later the same codes
// mean a programming error and keep their traceback.
bool reading_options = true;
}  // namespace

PetscErrorCode CheckUnknownOptions(MPI_Comm comm) {
  // Prefixes of options read after start-up: by the SNES / KSP / PC / Mat of
  // each solve (settle_*: compact's rigid pre-settling), the Jacobian (jac_), the
  // LDL^T factorization of the symmetric Newton matrix (ldlt_),
  // the ASM subdomain solvers (sub_), logging, viewers and PETSc's own run-time.
  static const char *const later[] = {"snes_", "ksp_", "pc_", "mat_", "jac_", "log", "info", "options_", "malloc",
                                      "help", "version", "on_error", "no_signal_handler", "fp_trap", "memory_view",
                                      "viewer", "draw", "vec_", "petsc", "check_pointer", "device_", "root_device",
                                      "mpi", "start_in_debugger", "debugger", "stop_for_debugger",
                                      "history", "tmp", "shared_tmp", "not_shared_tmp", "skip_petscrc",
                                      "objects_dump", "checkstack", "get_total_flops", "use_gpu_aware_mpi", "saws",
                                      "display", "nox", "x_virtual", "python", "dm_", "is_", "sf_", "options_file", "sub_",
                                      "settle_snes_", "settle_ksp_", "settle_pc_", "settle_mat_", "settle_sub_", "ldlt_",
                                      "settle_ldlt_"};
  PetscInt n;
  char **names, **values;
  std::string unknown;
  PetscFunctionBeginUser;
  PetscCall(PetscOptionsLeftGet(nullptr, &n, &names, &values));
  for (PetscInt i = 0; i < n; ++i) {
    bool known = false;
    for (const char *p : later) known = known || std::strncmp(names[i], p, std::strlen(p)) == 0;
    if (!known) unknown += std::string(unknown.empty() ? "" : ", ") + "-" + names[i];
  }
  PetscCall(PetscOptionsLeftRestore(nullptr, &n, &names, &values));
  PetscCheck(unknown.empty(), comm, PETSC_ERR_USER_INPUT,
             "unknown option(s) %s: check the spelling against -help", unknown.c_str());
  // PETSc takes one value per option and skips any further word, so
  // "-pressures 1e-5 3e-5" would run the first level alone: a word that is
  // neither an option nor the value right after one is refused. An option
  // starts with '-' and a letter; "-1" and "-.5" are values.
  int argc = 0;
  char **argv = nullptr;
  PetscCall(PetscGetArgs(&argc, &argv));
  const auto is_option = [](const char *a) { return a[0] == '-' && std::isalpha(static_cast<unsigned char>(a[1])); };
  for (int i = 1; i < argc; ++i) {
    if (is_option(argv[i])) {
      if (i + 1 < argc && !is_option(argv[i + 1])) ++i;  // its value
      continue;
    }
    const std::string after = i >= 2 ? std::string(" after ") + argv[i - 2] + " " + argv[i - 1] : "";
    SETERRQ(comm, PETSC_ERR_USER_INPUT,
            "stray argument '%s'%s: an option takes one value, and lists are comma-separated "
            "(for instance -pressures 1e-5,3e-5,1e-4)",
            argv[i], after.c_str());
  }
  reading_options = false;
  PetscFunctionReturn(0);
}

PetscErrorCode CheckSceneMemory(MPI_Comm comm, double deformable_disks, double triangles_per_disk, double rigid_disks) {
  PetscFunctionBeginUser;
  // Measured at 92-triangle disks (1500-disk scene, 750 deformable: about
  // 1.08 GiB on one rank, most of it MUMPS' LU factors): about 14 kB per
  // triangle, growing a little faster than linearly with the mesh.
  const double need = 14e3 * deformable_disks * triangles_per_disk + 2e3 * rigid_disks + 64.0 * (1 << 20);
  // Physical memory of the nodes the run has: each rank counts its node's
  // memory divided by the ranks sharing the node.
  MPI_Comm node;
  PetscMPIInt on_node;
  PetscCallMPI(MPI_Comm_split_type(comm, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &node));
  PetscCallMPI(MPI_Comm_size(node, &on_node));
  PetscCallMPI(MPI_Comm_free(&node));
  const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
  double have = pages > 0 && page > 0 ? double(pages) * double(page) / on_node : INFINITY;
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &have, 1, MPI_DOUBLE, MPI_SUM, comm));
  PetscCheck(need <= have, comm, PETSC_ERR_USER_INPUT,
             "this scene would need about %.3g GiB (%.0f deformable disks of %.0f triangles, about 14 kB per "
             "triangle for the Jacobian and its factors), more than the %.3g GiB of memory of the machine(s) running "
             "it: use fewer -mesh_triangles or particles, or more nodes",
             need / (1 << 30), deformable_disks, triangles_per_disk, have / (1 << 30));
  PetscFunctionReturn(0);
}

namespace {

// Errors in what the user gave (options, files) are reported as their one
// message, "<program>: error: <message>", by the first rank that raises
// them (rank 0 for collective checks); everything else gets PETSc's traceback.
const char *program_name = "deformix";

PetscErrorCode InputErrorHandler(MPI_Comm comm, int line, const char *fun, const char *file, PetscErrorCode n,
                                 PetscErrorType p, const char *mess, void *ctx) {
  const bool input = n == PETSC_ERR_USER_INPUT || n == PETSC_ERR_FILE_OPEN || n == PETSC_ERR_FILE_READ ||
                     n == PETSC_ERR_FILE_UNEXPECTED ||
                     (reading_options && (n == PETSC_ERR_USER || n == PETSC_ERR_ARG_UNKNOWN_TYPE));
  if (!input) return PetscTraceBackErrorHandler(comm, line, fun, file, n, p, mess, ctx);
  if (p == PETSC_ERROR_INITIAL) {
    PetscMPIInt rank = 0;
    if (comm != MPI_COMM_NULL) MPI_Comm_rank(comm, &rank);
    if (rank == 0) std::fprintf(stderr, "%s: error: %s\n", program_name, mess ? mess : "(no message)");
  }
  return n;
}

}  // namespace

int RunDriver(int argc, char **argv, const char *help, PetscErrorCode (*run)(MPI_Comm)) {
  // A run that no process manager started (none of the variables that
  // mpiexec, srun or another PMI launcher sets) is an Open MPI singleton. By
  // default it forks a runtime daemon (orted) that the drivers never use
  // (they spawn no processes), and it opens Open MPI's cm messaging layer,
  // probing the PSM/PSM2 network libraries, before it settles on ob1: a
  // singleton only talks to itself. Each costs about 0.2 s of start-up on the
  // development machine, so a singleton is made isolated and asks for ob1
  // directly (`compact -help` 0.12 s). Values already in the environment are
  // kept; runs under mpiexec keep Open MPI's own choice, which on a cluster is
  // the network's.
  if (!std::getenv("OMPI_COMM_WORLD_SIZE") && !std::getenv("PMIX_RANK") && !std::getenv("PMI_RANK")) {
    setenv("OMPI_MCA_ess_singleton_isolated", "1", 0);
    setenv("OMPI_MCA_pml", "ob1", 0);
  }
  if (PetscInitialize(&argc, &argv, nullptr, help)) return 1;
  if (argc > 0 && argv[0]) {
    const char *slash = std::strrchr(argv[0], '/');
    program_name = slash ? slash + 1 : argv[0];
  }
  PetscPushErrorHandler(InputErrorHandler, nullptr);
  const PetscErrorCode ierr = run(PETSC_COMM_WORLD);
  PetscPopErrorHandler();
  const PetscErrorCode fin = PetscFinalize();
  return (ierr || fin) ? 1 : 0;
}

bool HelpRequested() {
  PetscBool help = PETSC_FALSE;
  PetscOptionsHasHelp(nullptr, &help);
  return help;
}

}  // namespace deformix

static const char help[] =
    "single-particle: one neo-Hookean disk compressed by four frictionless, pressure-driven walls\n"
    "(the paper's single-particle test, Fig. Pp_vs_Phip).\n\n"
    "The disk (diameter 1) starts touching the four walls of a square box (phi_p = pi/4). Each level\n"
    "of -pressures (P/E) is reached quasistatically with automatic sub-stepping; at every level the\n"
    "packing fraction phi_p = particle area / box area is exact equilibrium of\n"
    "    min  sum_e W(F) + P * box_area   subject to   gap(node, wall) >= 0,\n"
    "solved by semismooth Newton on the KKT system (MUMPS LU), each step accepted by that energy\n"
    "(-level_solver auto, compact's level solver; docs/level-solver.md).\n\n"
    "Writes <output_dir>/curve.csv (one row per level), <output_dir>/levels.h5 (deformed meshes; levels.xdmf\n"
    "beside it opens in ParaView) and\n"
    "<output_dir>/checkpoint.h5 (after every level: what -restart needs to continue the run).\n\n"
    "Examples:\n"
    "  build/bin/single-particle -mesh_triangles 92 -output_dir out/sp\n"
    "  build/bin/single-particle -pressures 0.5 -nu 0.4999 -level_monitor\n"
    "  mpirun -n 2 build/bin/single-particle -options_file petsc-options/single-particle.opts\n"
    "  build/bin/single-particle -pressures 1e-4,1e-3,0.01,0.1 -restart out/single-particle/checkpoint.h5\n\n"
    "PETSc solver options apply as usual (-ksp_*, -pc_*, -log_view); -level_monitor prints\n"
    "each trial step with its merit and the number of closed contacts.\n\n";

#include <petscsnes.h>

#include <algorithm>
#include <cmath>
#include <exception>
#include <string>
#include <map>
#include <vector>

#include "deformix/checkpoint.hpp"
#include "deformix/disk_mesh.hpp"
#include "deformix/level_outputs.hpp"
#include "deformix/load_controller.hpp"
#include "deformix/options.hpp"
#include "deformix/output.hpp"
#include "deformix/problem.hpp"

using namespace deformix;

namespace {

struct SingleParticleOptions {
  PetscInt mesh_triangles = 92;
  PetscInt element_order = 2;
  std::vector<double> pressures;
  std::string output_dir;
  PetscBool write_hdf5 = PETSC_TRUE;
  PetscBool checkpoint = PETSC_TRUE;
  PetscBool checkpoint_levels = PETSC_FALSE;
  std::string restart;  // checkpoint to continue from ("": a new run)
};

const std::vector<std::string> kCurveColumns = {
    "P_over_E", "phi", "area_ratio", "newton_its", "seconds", "substeps", "cuts", "box_width", "box_height",
    "wall_force_error", "max_penetration", "min_cell_area_ratio", "active_contacts"};

PetscErrorCode ProcessOptions(MPI_Comm comm, SingleParticleOptions *o) {
  PetscFunctionBeginUser;
  PetscOptionsBegin(comm, nullptr, "Single-particle test", "deformix");
  PetscCall(PetscOptionsInt("-mesh_triangles", "approximate number of triangles of the disk mesh (>= 24)", "",
                            o->mesh_triangles, &o->mesh_triangles, nullptr));
  PetscCall(PetscOptionsInt("-element_order", "1: linear triangles (lock), 2: quadratic isoparametric", "",
                            o->element_order, &o->element_order, nullptr));
  PetscCall(PetscOptionsBool("-write_hdf5", "write the deformed mesh of every level to levels.h5", "", o->write_hdf5,
                             &o->write_hdf5, nullptr));
  PetscOptionsEnd();
  PetscCheck(o->mesh_triangles >= 24, comm, PETSC_ERR_USER_INPUT,
             "-mesh_triangles %" PetscInt_FMT " is too few: the disk needs at least 24 triangles (2 rings)",
             o->mesh_triangles);
  PetscCheck(o->mesh_triangles <= 2000000, comm, PETSC_ERR_USER_INPUT,
             "-mesh_triangles %" PetscInt_FMT " is too many for one disk", o->mesh_triangles);
  PetscCheck(o->element_order == 1 || o->element_order == 2, comm, PETSC_ERR_USER_INPUT,
             "-element_order %" PetscInt_FMT ": choose 1 or 2", o->element_order);
  const std::vector<double> defaults = {1e-4, 1e-3, 5e-3, 0.01, 0.02, 0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5};
  PetscCall(GetPressureList(comm, defaults, &o->pressures));
  PetscCall(GetOutputDirectory(comm, "out/single-particle", &o->output_dir));
  PetscCall(GetRestartOptions(comm, &o->restart, &o->checkpoint, &o->checkpoint_levels));
  PetscFunctionReturn(0);
}

PetscErrorCode Run(MPI_Comm comm) {
  SingleParticleOptions opts;
  ProblemParameters params;
  LoadControlParameters load;
  PetscLogStage stage_solve, stage_output;
  PetscFunctionBeginUser;
  // 1. Options: everything is validated before anything is written.
  PetscCall(ProcessOptions(comm, &opts));
  PetscCall(params.SetFromOptions(comm));
  PetscCall(load.SetFromOptions(comm));
  if (HelpRequested()) PetscFunctionReturn(0);
  PetscCall(CheckUnknownOptions(comm));
  PetscCall(CheckSceneMemory(comm, 1.0, opts.mesh_triangles, 0.0));
  // The options that define the body and its unknowns: a restart must repeat them.
  const Scene scene = {{"mesh_triangles", double(opts.mesh_triangles)},
                       {"element_order", double(opts.element_order)},
                       {"E", params.young},
                       {"nu", params.poisson},
                       {"constrain_rotation", params.constrain_rotation ? 1.0 : 0.0}};
  const bool restarting = !opts.restart.empty();
  Checkpoint restart;
  if (restarting)
    PetscCall(LoadRestart(comm, opts.restart, "single-particle", scene, kCurveColumns, opts.pressures, &restart));
  PetscCheck(!restarting || !restart.levels.empty(), comm, PETSC_ERR_FILE_UNEXPECTED,
             "-restart %s holds no level: single-particle writes its checkpoint after every level", opts.restart.c_str());
  PetscCall(PrepareOutputDirectory(comm, opts.output_dir));
  PetscCall(PetscLogStageRegister("Solve", &stage_solve));
  PetscCall(PetscLogStageRegister("Output", &stage_output));

  // 2. Scene: a disk of diameter 1 touching the four walls.
  const double radius = 0.5;
  DiskMesh mesh;
  try {
    mesh = make_disk_mesh(radius, static_cast<int>(opts.mesh_triangles), static_cast<int>(opts.element_order));
  } catch (const std::exception &e) {
    SETERRQ(comm, PETSC_ERR_USER_INPUT, "disk mesh: %s", e.what());
  }
  CompactionProblem problem(comm);
  PetscCall(problem.SetParameters(params));
  problem.AddDeformableBody(mesh, 0.0, 0.0);
  // The walls touch the discrete disk: the bounding box of its boundary contact
  // points (nodes, and the control points of curved edges), which is the
  // disk's diameter whenever a vertex sits at 0, 90, 180 and 270 degrees.
  double walls[4] = {INFINITY, -INFINITY, INFINITY, -INFINITY};
  for (int i = 0; i < static_cast<int>(mesh.boundary.size()); ++i) {
    double x[2];
    problem.BoundaryPointPosition(0, i, x);
    walls[kLeft] = std::min(walls[kLeft], x[0]), walls[kRight] = std::max(walls[kRight], x[0]);
    walls[kBottom] = std::min(walls[kBottom], x[1]), walls[kTop] = std::max(walls[kTop], x[1]);
  }
  problem.SetWalls(walls);
  const StateSummary s0 = problem.Summary();
  if (restarting) PetscCall(problem.RestoreSnapshot(restart.state));
  PetscCall(PetscPrintf(comm,
                        "single-particle: %d triangles (order %d, min angle %.1f deg), %d nodes, E = %g, nu = %g\n"
                        "  phi_p at P = 0: %.6f (pi/4 = %.6f)\n",
                        mesh.num_cells(), mesh.order, min_angle_degrees(mesh), mesh.num_nodes(), params.young,
                        params.poisson, s0.packing_fraction, M_PI / 4));
  if (restarting)
    PetscCall(PetscPrintf(comm, "  restart from %s: %zu level(s) done (last P/E = %g), continuing with P/E = %g\n",
                          opts.restart.c_str(), restart.levels.size(), restart.levels.back(),
                          opts.pressures[restart.levels.size()]));

  // 3. Levels: solve, measure, write.
  LevelOutputs outputs;
  PetscCall(outputs.Open(comm,
                         {opts.output_dir, bool(opts.write_hdf5), bool(opts.checkpoint), bool(opts.checkpoint_levels)},
                         kCurveColumns,
                         restarting ? &restart : nullptr));
  PetscCall(PetscPrintf(comm, "  %10s %10s %10s %6s %6s %9s\n", "P/E", "phi_p", "area_ratio", "newton", "steps",
                        "seconds"));
  double step = restarting ? restart.load_step : -1.0;
  for (size_t level = outputs.LevelsDone(); level < opts.pressures.size(); ++level) {
    const double P_over_E = opts.pressures[level];
    LevelReport rep;
    PetscCall(PetscLogStagePush(stage_solve));
    PetscCall(AdvanceToPressure(problem, load, P_over_E * params.young, &step, &rep));
    PetscCall(PetscLogStagePop());
    const StateSummary s = problem.Summary();
    // Wall equilibrium check: each wall's contact forces against P x (its length).
    const double P = P_over_E * params.young;
    double wall_err = 0.0;
    const double lengths[4] = {s.box_height, s.box_height, s.box_width, s.box_width};
    for (int k = 0; k < 4; ++k) wall_err = std::max(wall_err, std::abs(s.wall_force[k] - P * lengths[k]));
    if (P > 0.0) wall_err /= P * s.box_width;
    PetscCall(PetscPrintf(comm, "  %10.4g %10.6f %10.6f %6" PetscInt_FMT " %6d %9.3f\n", P_over_E,
                          s.packing_fraction, s.area_ratio, rep.newton_its, rep.substeps, rep.seconds));
    PetscCall(PetscLogStagePush(stage_output));
    const std::map<std::string, double> row = {
        {"P_over_E", P_over_E}, {"phi", s.packing_fraction}, {"area_ratio", s.area_ratio},
        {"newton_its", double(rep.newton_its)}, {"seconds", rep.seconds}, {"substeps", double(rep.substeps)},
        {"cuts", double(rep.cuts)}, {"box_width", s.box_width}, {"box_height", s.box_height},
        {"wall_force_error", wall_err}, {"max_penetration", s.max_penetration},
        {"min_cell_area_ratio", s.min_cell_area_ratio}, {"active_contacts", double(s.active_contacts)}};
    Checkpoint c;
    c.driver = "single-particle";
    c.scene = scene;
    PetscCall(outputs.Level(level, opts.pressures, row, step, problem, c));
    PetscCall(PetscLogStagePop());
  }
  PetscCall(PetscPrintf(comm, "  wrote %s: %s\n", opts.output_dir.c_str(), outputs.Written().c_str()));
  PetscFunctionReturn(0);
}

}  // namespace

int main(int argc, char **argv) { return RunDriver(argc, argv, help, Run); }

static const char help[] =
    "compact: isotropic compaction of a mixture of rigid and deformable (neo-Hookean) disks\n"
    "with frictional contact, in a box of four frictionless, pressure-driven walls (the paper's\n"
    "sections II-IV).\n\n"
    "Protocol: n_particles rigid disks (diameters in [0.8, 1.2], uniform area fraction per diameter)\n"
    "are packed to the frictionless jammed state phi_0 (soft-disk FIRE compression to vanishing\n"
    "overlap); a fraction kappa of the particle area is turned deformable, homogeneously in space\n"
    "(or -packing FILE: the disks of a CSV file with the columns of packing.csv);\n"
    "it is settled into exact contact without friction at min(P_1, 1e-4 E) (with -constrain_rotation\n"
    "the deformable disks' mean rotation held by gauges), then friction is switched on (gauges\n"
    "released; -settle_frictionless); each level of -pressures (P/E) is reached quasistatically in one\n"
    "sub-step, halved while its solve fails (-load_step_policy), each level being equilibrium of\n"
    "    elasticity + rigid bodies + walls (P x length) + Signorini + Coulomb (Alart-Curnier)\n"
    "solved by semismooth Newton (MUMPS LU) inside pseudo-transient continuation: -level_solver newton\n"
    "takes one Newton step per pseudo-time step, accepted by the residual of its proximal subproblem,\n"
    "-level_solver anchored solves every pseudo-time step (to a 100-fold drop of its residual), -level_solver hybrid\n"
    "tries newton for -level_attempt_its linearizations and goes on with anchored from there, and\n"
    "-level_solver auto (default) takes newton with the energy merit (enthalpy + exact penalty,\n"
    "-level_merit energy) on levels without friction and hybrid on frictional levels.\n"
    "Levels are accepted per body (net force and torque of every body).\n"
    "Deformable pairs meet through a mortar (cell-averaged) gap of the slave's boundary nodes against\n"
    "the master's contact curve (-contact_deformable mortar; nts and two_pass are node-to-segment).\n"
    "A level is accepted at exact equilibrium or by the paper's criterion: unbalanced forces of every\n"
    "node and body <= -level_force_rtol x P <d>, P_sigma/P within -level_force_rtol of 1, phi settled\n"
    "to -level_phi_rtol, contact conditions exact.\n\n"
    "Writes <output_dir>/curve.csv (one row per level), <output_dir>/levels.h5 (the state of every\n"
    "level, with the contact network) and levels.xdmf beside it (open it in ParaView: a time series\n"
    "over the levels), <output_dir>/packing.csv (the initial packing) and <output_dir>/checkpoint.h5 (after\n"
    "every level, and after the frictionless settling of the first: what -restart needs to continue the run\n"
    "exactly where it stopped; -checkpoint_levels true keeps checkpoint_level_<k>.h5 of every level k besides).\n\n"
    "Examples:\n"
    "  build/bin/compact -options_file petsc-options/default.opts     (20 disks, a few seconds)\n"
    "  build/bin/compact -n_particles 64 -kappa 0.5 -friction 0.2 -pressures 1e-4,1e-3 -output_dir out/c64\n"
    "  build/bin/compact -options_file petsc-options/paper.opts -kappa 0.8 -friction 0.2 -constrain_rotation true\n"
    "      (1500 disks: about 40 minutes per curve on 2 ranks)\n"
    "  build/bin/compact -options_file petsc-options/default.opts -pressures 1e-4,1e-3,3e-3,0.01,0.02,0.03,0.05 \\\n"
    "      -restart out/compact/checkpoint.h5      (continue the default scene by one more level)\n\n"
    "PETSc solver options apply as usual (-snes_*, -ksp_*, -pc_*, -log_view; -settle_snes_*, -settle_ksp_*,\n"
    "-settle_pc_* for the rigid pre-settling); -newton_monitor prints\n"
    "each Newton iteration with the numbers of closed and sliding contacts, -newton_monitor_contacts\n"
    "the contacts whose state changed (to see an active-set cycle), -ptc_monitor each\n"
    "pseudo-time step (residual by block, largest unbalanced force and where it acts), -level_monitor each\n"
    "trial step of -level_solver newton (and of hybrid's attempt); without them,\n"
    "a sub-step that runs long prints a progress line every -progress_interval seconds (default 60).\n\n";

#include <petscsnes.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>
#include <map>
#include <string>
#include <vector>

#include "deformix/checkpoint.hpp"
#include "deformix/disk_mesh.hpp"
#include "deformix/level_outputs.hpp"
#include "deformix/load_controller.hpp"
#include "deformix/observables.hpp"
#include "deformix/options.hpp"
#include "deformix/output.hpp"
#include "deformix/packing.hpp"
#include "deformix/problem.hpp"

using namespace deformix;

namespace {

struct CompactOptions {
  PetscInt n_particles = 64;
  PetscReal kappa = 0.5;  // mixture ratio: deformable area / particle area
  PetscInt seed = 1;
  PetscInt mesh_triangles = 92;
  std::vector<double> pressures;
  std::string output_dir;
  PetscBool write_hdf5 = PETSC_TRUE;
  PetscBool settle_frictionless = PETSC_TRUE;
  PetscBool settle_rigid = PETSC_TRUE;
  PetscBool checkpoint = PETSC_TRUE;
  PetscBool checkpoint_levels = PETSC_FALSE;
  std::string restart;  // checkpoint to continue from ("" : a new run)
  std::string packing;  // user packing (CSV) instead of the generated one ("" : generate)
};

PetscErrorCode ProcessOptions(MPI_Comm comm, CompactOptions *o) {
  PetscFunctionBeginUser;
  char file[PETSC_MAX_PATH_LEN] = "";
  PetscBool has_packing = PETSC_FALSE;
  PetscOptionsBegin(comm, nullptr, "Mixture compaction", "deformix");
  PetscCall(PetscOptionsInt("-n_particles", "number of disks N_p", "", o->n_particles, &o->n_particles, nullptr));
  PetscCall(PetscOptionsReal("-kappa", "mixture ratio: deformable area / total particle area, in [0, 1]", "", o->kappa,
                             &o->kappa, nullptr));
  PetscCall(PetscOptionsInt("-seed", "random seed of the packing (the scene reproduces exactly)", "", o->seed, &o->seed,
                            nullptr));
  PetscCall(PetscOptionsInt("-mesh_triangles", "approximate number of triangles per deformable disk (>= 24)", "",
                            o->mesh_triangles, &o->mesh_triangles, nullptr));
  PetscCall(PetscOptionsBool("-write_hdf5", "write the state of every level to levels.h5", "", o->write_hdf5,
                             &o->write_hdf5, nullptr));
  PetscCall(PetscOptionsBool("-settle_rigid",
                             "start from the exact frictionless equilibrium of the all-rigid packing at the first pressure "
                             "(then the deformable disks only deform, instead of rearranging the soft-jammed state)",
                             "", o->settle_rigid, &o->settle_rigid, nullptr));
  PetscCall(PetscOptionsBool("-settle_frictionless",
                             "settle the packing without friction at min(first level, 1e-4 E), then switch friction on, solve again and step to the first level", "",
                             o->settle_frictionless, &o->settle_frictionless, nullptr));
  PetscCall(PetscOptionsString("-packing",
                               "run on the disks of a CSV file (columns x, y, radius, deformable as in packing.csv; "
                               "walls on their bounding box) instead of generating a packing",
                               "", file, file, sizeof(file), &has_packing));
  PetscOptionsEnd();
  if (has_packing) {
    PetscCheck(file[0] != '\0', comm, PETSC_ERR_USER_INPUT, "-packing needs a file name");
    for (const char *other : {"-n_particles", "-kappa", "-seed"}) {
      PetscBool set = PETSC_FALSE;
      PetscCall(PetscOptionsHasName(nullptr, nullptr, other, &set));
      PetscCheck(!set, comm, PETSC_ERR_USER_INPUT,
                 "%s cannot be combined with -packing: the file gives the disks and which of them are deformable", other);
    }
    o->packing = file;
  }
  PetscCheck(o->n_particles >= 1 && o->n_particles <= 200000, comm, PETSC_ERR_USER_INPUT,
             "-n_particles %" PetscInt_FMT ": give between 1 and 200000 particles", o->n_particles);
  PetscCheck(o->kappa >= 0.0 && o->kappa <= 1.0, comm, PETSC_ERR_USER_INPUT,
             "-kappa %g: the mixture ratio is a fraction of the particle area, in [0, 1]", (double)o->kappa);
  PetscCheck(o->seed >= 0, comm, PETSC_ERR_USER_INPUT, "-seed %" PetscInt_FMT " must be >= 0", o->seed);
  PetscCheck(o->mesh_triangles >= 24, comm, PETSC_ERR_USER_INPUT,
             "-mesh_triangles %" PetscInt_FMT " is too few: a disk needs at least 24 triangles (2 rings)",
             o->mesh_triangles);
  const std::vector<double> defaults = {1e-4, 1e-3, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.3, 0.5};
  PetscCall(GetPressureList(comm, defaults, &o->pressures));
  PetscCall(GetOutputDirectory(comm, "out/compact", &o->output_dir));
  PetscCall(GetRestartOptions(comm, &o->restart, &o->checkpoint, &o->checkpoint_levels));
  PetscFunctionReturn(0);
}

PetscErrorCode WritePackingCsv(MPI_Comm comm, const std::string &path, const DiskPacking &p) {
  CsvWriter csv;
  PetscFunctionBeginUser;
  PetscCall(csv.Open(comm, path, {"x", "y", "radius", "deformable"}));
  for (int i = 0; i < p.size(); ++i) PetscCall(csv.Row({p.x[i], p.y[i], p.radius[i], double(p.deformable[i])}));
  PetscFunctionReturn(0);
}

const std::vector<std::string> kCurveColumns = {
    "P_over_E", "phi", "Z", "Z_no_rattlers", "rattlers", "sigma_xx_over_E", "sigma_xy_over_E", "sigma_yy_over_E",
    "P_sigma_over_E", "K_over_E", "mean_volumetric_strain", "contacts", "sliding_contacts", "newton_its", "substeps",
    "cuts", "seconds", "max_penetration", "pseudo_time_steps", "symbolic_factorizations", "unknowns",
    "rigid_unknowns", "deformable_unknowns", "tangential_unknowns", "candidates", "jacobian_nonzeros",
    "force_residual_over_Pd", "relaxed_substeps", "gauge_torque_over_Pd2", "factorizations",
    "body_force_over_Pd", "body_torque_over_Pd2"};

// The counts of a solve added to those of its level.
void AddCounts(const SolveReport &s, LevelReport *rep) {
  rep->newton_its += s.newton_its;
  rep->factorizations += s.factorizations;
  rep->inner_solves += s.inner_solves;
  rep->layouts += s.layouts;
}

void AddCounts(const LevelReport &r, LevelReport *rep) {
  rep->newton_its += r.newton_its;
  rep->factorizations += r.factorizations;
  rep->inner_solves += r.inner_solves;
  rep->layouts += r.layouts;
  rep->substeps += r.substeps;
  rep->cuts += r.cuts;
  rep->relaxed_substeps += r.relaxed_substeps;
}

// The frictionless settling of the first level in a checkpoint (compact
// writes one after it, so that -restart takes up the frictional solve): its
// pressure and the counts that the first level's curve row includes.
std::vector<SceneValue> SettlingValues(double P_settle_over_E, const LevelReport &r) {
  return {{"settled_P_over_E", P_settle_over_E},
          {"settled_newton_its", double(r.newton_its)},
          {"settled_factorizations", double(r.factorizations)},
          {"settled_inner_solves", double(r.inner_solves)},
          {"settled_layouts", double(r.layouts)},
          {"settled_substeps", double(r.substeps)},
          {"settled_cuts", double(r.cuts)},
          {"settled_relaxed_substeps", double(r.relaxed_substeps)},
          {"settled_seconds", r.seconds}};
}

LevelReport SettlingReport(const Checkpoint &c) {
  LevelReport r;
  r.newton_its = static_cast<PetscInt>(c.Value("settled_newton_its"));
  r.factorizations = static_cast<PetscInt>(c.Value("settled_factorizations"));
  r.inner_solves = static_cast<int>(c.Value("settled_inner_solves"));
  r.layouts = static_cast<int>(c.Value("settled_layouts"));
  r.substeps = static_cast<int>(c.Value("settled_substeps"));
  r.cuts = static_cast<int>(c.Value("settled_cuts"));
  r.relaxed_substeps = static_cast<int>(c.Value("settled_relaxed_substeps"));
  r.seconds = c.Value("settled_seconds");
  return r;
}

// The pressure of the frictionless settling for a first level P_1 (P/E).
double SettlingPressure(double P1_over_E) { return std::min(P1_over_E, 1e-4); }

// A settling load step (the rigid pre-settling, the frictionless settling
// of the mixture): with -level_solver auto it is tried in one load step,
// and where that fails, solved by hybrid from the state before it. auto's
// newton (energy merit) can fail on a packing that still has to settle:
// on the 1500-disk paper scene the rigid settling failed at every one of
// 17 step cuts (its trial steps' multipliers blow up the contact rows),
// where hybrid settles in 213 iterations (11 s on 2 ranks), and the
// frictionless settling of the mixture at P/E 1e-5 failed at every cut
// down to 3e-7 P (halving the pressure does not make the geometry easier).
// A settling step is not halved, so its newton gets budget times
// -level_max_its linearizations before hybrid takes over. The frictionless
// settling of the mixture gets kSettleBudget: on the 1500-disk paper scene
// (-constrain_rotation true, 2 ranks) it converges after about 450, while
// with 400 hybrid started again from the settled rigid packing and crept
// for over an hour without passing the level criterion
// (docs/level-solver-measurements.md, "Measured: the 1500-disk paper
// scene"). The rigid settling gets 1: its newton converges in a few
// iterations or not at all (the paper's scene at 200 disks: 2; at 400 it
// fails after 1663, at 1500 after the 2000 of kSettleBudget, and hybrid
// settles it in 11 and 250: 19 and 68 s in all on one rank), and hybrid starts
// from the state before it whatever the budget. Other strategies step as
// usual. rep->seconds counts the whole settling (newton's failed load step
// included). *newton_its (if given): the Newton iterations of auto's load
// step where hybrid had to take over (they are counted in rep too), else 0.
constexpr PetscInt kSettleBudget = 5;
PetscErrorCode Settle(CompactionProblem &problem, const LoadControlParameters &load, double pressure, double *step,
                      LevelReport *rep, PetscInt budget, PetscInt *newton_its = nullptr) {
  PetscFunctionBeginUser;
  if (newton_its) *newton_its = 0;
  if (load.level.strategy != LevelStrategy::Auto) {
    PetscCall(AdvanceToPressure(problem, load, pressure, step, rep));
    PetscFunctionReturn(0);
  }
  PetscLogDouble t_start;
  PetscCall(PetscTime(&t_start));
  LoadControlParameters once = load;
  once.max_cuts = 0;
  once.level.max_its = budget * load.level.max_its;
  once.level.settling = true;
  const double step_before = *step;
  PetscCall(PetscPushErrorHandler(PetscReturnErrorHandler, nullptr));
  const PetscErrorCode ierr = AdvanceToPressure(problem, once, pressure, step, rep);
  PetscCall(PetscPopErrorHandler());
  if (ierr != PETSC_ERR_NOT_CONVERGED) {
    PetscCall(ierr);
    PetscFunctionReturn(0);
  }
  const LevelReport first = *rep;
  if (newton_its) *newton_its = first.newton_its;
  LoadControlParameters hybrid = load;
  hybrid.level.strategy = LevelStrategy::Hybrid;
  *step = step_before;
  PetscCall(AdvanceToPressure(problem, hybrid, pressure, step, rep));
  PetscLogDouble t_end;
  PetscCall(PetscTime(&t_end));
  AddCounts(first, rep);
  rep->seconds = t_end - t_start;  // newton's failed load step included
  PetscFunctionReturn(0);
}

PetscErrorCode Run(MPI_Comm comm) {
  CompactOptions opts;
  ProblemParameters params;
  LoadControlParameters load;
  PetscLogStage stage_pack, stage_solve, stage_output;
  PetscFunctionBeginUser;
  // 1. Options: everything is validated before anything is written.
  // Deformable disks rotate freely in a packing. A rotation gauge
  // (-constrain_rotation) cuts the Newton iterations of frictionless kappa =
  // 0.8 (50 disks) by 4x, but the contacts of the discrete disk (its boundary
  // nodes against neighbours) do exert torques: the gauges then carry up to
  // 0.19 P <d>^2 (20 disks, P/E = 1e-4), as much as friction would. Not the
  // default. With friction, -constrain_rotation true holds the disks' mean
  // rotation only during the frictionless settling of the first level and
  // releases it when friction is switched on, so every level is solved
  // without gauges. Measured, first two levels (P/E 1e-4, 1e-3), kappa 0.5,
  // friction 0.2: 400 disks 780 Newton iterations and 258 s instead of 1338
  // and 489 s; 100 disks 25 s instead of 34 s; 1500 disks pass their first
  // level (which does not settle in 16 minutes without). But small scenes
  // are slower (20 disks 12 s instead of 11 s), and the gauged settling is
  // another preparation, not the same state reached faster: with the mean
  // rotations held the deformable disks cannot roll into place, as if their
  // contacts were rough, and the packing jams looser. 30 disks (kappa 0.5,
  // 54 triangles, seed 3), frictionless settling at P/E = 1e-4: phi = 0.77086
  // with gauges, 0.77203 without, phi_0 = 0.7710 (friction 0.3 then keeps
  // either value). So it stays an option for the scenes that do not settle
  // without it (1500 disks).
  params.constrain_rotation = PETSC_FALSE;
  // Packings have floppy modes (rattlers, free rotations, sliding before the
  // network closes): pseudo-transient continuation with full Newton steps.
  params.ptc_move = 0.02;
  // The paper's level criterion (unbalanced forces below 1e-4 P <d>, phi
  // settled to 1e-4) besides exact equilibrium: see -level_force_rtol.
  params.level_force_rtol = 1e-4;
  // c_n = c_t = 0.01 E in the NCP functions (the Newton path only, not the
  // solution). In a packing at P << E the relevant stiffnesses (sliding,
  // rolling, rearranging) are far below E, and with c = E the stick/slip
  // decision lambda_t - c s is dominated by the slip accumulated over the
  // step: Newton then cycles between stick, slip and open on a few contacts.
  // Measured (50 disks to P/E = 0.5, friction 0.2): kappa 0.5 in 109 s
  // instead of 243 s, kappa 1 in 183 s instead of 392 s; 100 disks, first two
  // levels: 588 Newton iterations instead of 1108.
  params.ncp_scale = 0.01;
  // Deformable pairs: the mortar (cell-averaged) gap, so that no point of the
  // slave boundary is left unchecked (node-to-segment one way lets the
  // master's nodes in by 2-4e-2 <d> at P/E = 0.5, phi 1.003 at kappa 1).
  params.deformable_contact = DeformableContact::Mortar;
  // Full Newton steps inside each pseudo-time step (anchored);
  // -snes_linesearch_type overrides it.
  load.level.line_search = SNESLINESEARCHBASIC;
  PetscCall(ProcessOptions(comm, &opts));
  PetscCall(params.SetFromOptions(comm));
  PetscCall(load.SetFromOptions(comm));
  if (HelpRequested()) PetscFunctionReturn(0);
  PetscCall(CheckUnknownOptions(comm));
  // A user packing is read (and refused if bad) before anything is written;
  // its size and deformable area fraction stand for -n_particles and -kappa.
  DiskPacking user_packing;
  if (!opts.packing.empty()) {
    try {
      user_packing = read_packing_csv(opts.packing);
    } catch (const std::exception &e) {
      SETERRQ(comm, PETSC_ERR_USER_INPUT, "-packing: %s", e.what());
    }
    double area = 0.0, deformable_area = 0.0;
    for (int i = 0; i < user_packing.size(); ++i) {
      const double a = M_PI * user_packing.radius[i] * user_packing.radius[i];
      area += a, deformable_area += user_packing.deformable[i] ? a : 0.0;
    }
    opts.n_particles = user_packing.size();
    opts.kappa = deformable_area / area;
    opts.seed = 0;
  }
  {
    const double n_def = std::ceil(opts.kappa * opts.n_particles);
    PetscCall(CheckSceneMemory(comm, n_def, opts.mesh_triangles, opts.n_particles - n_def));
  }
  // At P = 0 the walls carry no load: the packing has no equilibrium that
  // the level criterion (forces relative to P <d>) could measure.
  for (size_t i = 0; i < opts.pressures.size(); ++i)
    PetscCheck(opts.pressures[i] > 0.0, comm, PETSC_ERR_USER_INPUT,
               "-pressures entry %zu is 0: compact's levels need P/E > 0 (the walls are held by the pressure alone); "
               "start from a small value such as 1e-5",
               i);
  // The options that define the bodies and unknowns: a restart must repeat them.
  const Scene scene = {{"n_particles", double(opts.n_particles)},
                       {"kappa", opts.kappa},
                       {"seed", double(opts.seed)},
                       {"mesh_triangles", double(opts.mesh_triangles)},
                       {"E", params.young},
                       {"nu", params.poisson},
                       {"friction", params.friction},
                       {"contact_deformable", double(params.deformable_contact)},
                       {"constrain_rotation", params.constrain_rotation ? 1.0 : 0.0}};
  const bool restarting = !opts.restart.empty();
  const bool settle_frictionless = opts.settle_frictionless && params.friction > 0.0;
  Checkpoint restart;
  if (restarting) {
    PetscCall(LoadRestart(comm, opts.restart, "compact", scene, kCurveColumns, opts.pressures, &restart));
    PetscCheck(restart.packing.size() == opts.n_particles, comm, PETSC_ERR_FILE_UNEXPECTED,
               "-restart %s holds %d disks for -n_particles %" PetscInt_FMT, opts.restart.c_str(),
               restart.packing.size(), opts.n_particles);
  }
  // A checkpoint without a level holds the frictionless settling of the first level.
  const bool restart_settled = restarting && restart.levels.empty();
  if (restart_settled) {
    const double settled = restart.Value("settled_P_over_E");
    PetscCheck(settled > 0.0, comm, PETSC_ERR_FILE_UNEXPECTED,
               "-restart %s holds neither a level nor the frictionless settling of the first one", opts.restart.c_str());
    PetscCheck(settle_frictionless, comm, PETSC_ERR_USER_INPUT,
               "-restart %s holds the frictionless settling of the first level, which -settle_frictionless false "
               "skips: continue it with -settle_frictionless true",
               opts.restart.c_str());
    PetscCheck(SettlingPressure(opts.pressures[0]) == settled, comm, PETSC_ERR_USER_INPUT,
               "-restart %s holds the frictionless settling at P/E = %g, but the first level of -pressures (%g) "
               "settles at P/E = %g: give the first level of the run it continues",
               opts.restart.c_str(), settled, opts.pressures[0], SettlingPressure(opts.pressures[0]));
  }
  PetscCall(PrepareOutputDirectory(comm, opts.output_dir));
  PetscCall(PetscLogStageRegister("Packing", &stage_pack));
  PetscCall(PetscLogStageRegister("Solve", &stage_solve));
  PetscCall(PetscLogStageRegister("Output", &stage_output));

  // 2. Scene: jammed frictionless rigid packing, then a fraction kappa made
  // deformable; a restart takes the packing of its checkpoint instead.
  PetscCall(PetscLogStagePush(stage_pack));
  DiskPacking packing = restart.packing;
  DiskMesh unit_mesh;
  try {
    if (!restarting && !opts.packing.empty()) {
      packing = user_packing;
    } else if (!restarting) {
      packing = make_jammed_packing(static_cast<int>(opts.n_particles), static_cast<unsigned>(opts.seed), PackingOptions());
      assign_deformable(packing, opts.kappa, static_cast<unsigned>(opts.seed));
    }
    unit_mesh = make_disk_mesh(1.0, static_cast<int>(opts.mesh_triangles), 2);
  } catch (const std::exception &e) {
    SETERRQ(comm, PETSC_ERR_USER_INPUT, "scene set-up: %s", e.what());
  }
  PetscCall(PetscLogStagePop());
  double phi0 = restart.Value("phi_0"), z0_no_rattlers = restart.Value("Z_0_no_rattlers");
  double z0_mirror = restart.Value("Z_0_mirror"), rattlers0 = restart.Value("rattler_fraction_0");
  if (!restarting) {
    const Coordination z0 = coordination(packing, contact_network(packing, 0.0), 3);
    phi0 = packing_fraction(packing);
    z0_no_rattlers = z0.non_rattlers ? 2.0 * z0.pair_contacts / z0.non_rattlers : 0.0;
    z0_mirror = z0.z_mirror;
    rattlers0 = z0.rattler_fraction;
  }
  // The soft-jammed packing has tiny overlaps and gaps; settling it with
  // deformable disks is a slow, nonsmooth rearrangement, while the all-rigid
  // frictionless packing settles in a few Newton iterations (forces only).
  // Its equilibrium at the first pressure (at most 1e-4 E) is the starting geometry.
  if (!restarting && opts.settle_rigid && opts.kappa > 0.0) {
    ProblemParameters rigid_params = params;
    rigid_params.friction = 0.0;
    // Rigid frictionless contacts: c_n = E decides the active set by the gaps,
    // which suits infinitely stiff contacts (1500 disks: 184 Newton
    // iterations at c_n = E, 459 with four failed sub-steps at 0.01 E).
    rigid_params.ncp_scale = 1.0;
    CompactionProblem rigid(comm);
    PetscCall(rigid.SetParameters(rigid_params));
    rigid.SetOptionsPrefix("settle_");  // its solver options: -settle_snes_*, -settle_ksp_*, -settle_pc_*, -settle_ldlt_*
    DiskPacking all_rigid = packing;
    std::fill(all_rigid.deformable.begin(), all_rigid.deformable.end(), 0);
    rigid.AddPacking(all_rigid, unit_mesh);
    double step = -1.0;
    LevelReport rep;
    // At most P/E = 1e-4: contacts exact, deformations negligible; larger
    // first levels are then reached by load stepping.
    const double P_settle = std::min(opts.pressures[0], 1e-4) * params.young;
    PetscInt failed_its = 0;
    PetscCall(Settle(rigid, load, P_settle, &step, &rep, 1, &failed_its));
    for (int i = 0; i < packing.size(); ++i) {
      double x[2];
      rigid.RigidPosition(i, x, nullptr);
      packing.x[i] = x[0], packing.y[i] = x[1];
    }
    std::copy(rigid.Walls(), rigid.Walls() + 4, packing.walls);
    char split[96] = "";
    if (failed_its > 0)
      PetscCall(PetscSNPrintf(split, sizeof split, " (%" PetscInt_FMT " in newton's load step, which failed, then %" PetscInt_FMT " by hybrid)",
                              failed_its, rep.newton_its - failed_its));
    PetscCall(PetscPrintf(comm, "  rigid settling at P/E = %g: phi = %.5f, %" PetscInt_FMT " Newton iterations%s, %.2f s\n",
                          P_settle / params.young, rigid.Summary().packing_fraction, rep.newton_its, split, rep.seconds));
  }
  CompactionProblem problem(comm);
  PetscCall(problem.SetParameters(params));
  const int n_deformable = problem.AddPacking(packing, unit_mesh);
  if (restarting) PetscCall(problem.RestoreSnapshot(restart.state));
  PetscCall(WritePackingCsv(comm, opts.output_dir + "/packing.csv", packing));
  PetscCall(PetscPrintf(comm,
                        "compact: %d particles (%d deformable, %d triangles each; %d rigid), kappa = %g, friction = %g,"
                        " E = %g, nu = %g, %s%s\n"
                        "  initial packing (rigid disks): phi_0 = %.4f, Z_0 without rattlers = %.3f between particles"
                        " (%.3f with wall contacts counted twice), rattlers %.1f %%\n",
                        packing.size(), n_deformable, unit_mesh.num_cells(), packing.size() - n_deformable,
                        (double)opts.kappa, params.friction, params.young, params.poisson,
                        opts.packing.empty() ? "seed " : "packing ",
                        opts.packing.empty() ? std::to_string(opts.seed).c_str() : opts.packing.c_str(),
                        phi0, z0_no_rattlers, z0_mirror, 100.0 * rattlers0));
  if (restart_settled)
    PetscCall(PetscPrintf(comm,
                          "  restart from %s: the frictionless settling of the first level done (P/E = %g), "
                          "continuing with its frictional solve\n",
                          opts.restart.c_str(), restart.Value("settled_P_over_E")));
  else if (restarting)
    PetscCall(PetscPrintf(comm, "  restart from %s: %zu level(s) done (last P/E = %g), continuing with P/E = %g\n",
                          opts.restart.c_str(), restart.levels.size(), restart.levels.back(),
                          opts.pressures[restart.levels.size()]));

  // 3. Levels: solve, measure, write.
  LevelOutputs outputs;
  PetscCall(outputs.Open(comm,
                         {opts.output_dir, bool(opts.write_hdf5), bool(opts.checkpoint), bool(opts.checkpoint_levels)},
                         kCurveColumns,
                         restarting ? &restart : nullptr));
  PetscCall(PetscPrintf(comm, "  %9s %8s %6s %6s %10s %8s %7s %6s %6s %8s\n", "P/E", "phi", "Z", "Z_nr", "P_sig/P",
                        "K/E", "slide", "newton", "steps", "seconds"));
  double step = restarting ? restart.load_step : -1.0;
  double prev_phi = restarting ? restart.Value("previous_phi") : phi0;
  double prev_P = restarting ? restart.Value("previous_pressure") : 0.0;
  // A checkpoint of this run, which the outputs complete with the levels done
  // and the state: the last level's phi and P for the next bulk modulus.
  const auto RunCheckpoint = [&](double last_phi, double last_P) {
    Checkpoint c;
    c.driver = "compact";
    c.scene = scene;
    c.packing = packing;
    c.values = {{"phi_0", phi0},
                {"Z_0_no_rattlers", z0_no_rattlers},
                {"Z_0_mirror", z0_mirror},
                {"rattler_fraction_0", rattlers0},
                {"previous_phi", last_phi},
                {"previous_pressure", last_P}};
    return c;
  };
  for (size_t level = outputs.LevelsDone(); level < opts.pressures.size(); ++level) {
    const double P_over_E = opts.pressures[level], P = P_over_E * params.young;
    LevelReport rep;
    PetscCall(PetscLogStagePush(stage_solve));
    // Protocol: the packing is first settled into exact contact without
    // friction (as it was assembled) at min(P_1, 1e-4 E), then friction is
    // switched on, that state solved again, and the load stepped to P_1 with
    // friction: a large first level is not compacted frictionless.
    PetscLogDouble t_start, t_end;
    PetscCall(PetscTime(&t_start));
    if (level == 0 && settle_frictionless) {
      const double P_settle = SettlingPressure(P_over_E) * params.young;
      if (restart_settled) {
        rep = SettlingReport(restart);
      } else {
        problem.SetFrictionActive(false);
        PetscCall(Settle(problem, load, P_settle, &step, &rep, kSettleBudget));  // rep.seconds: the whole settling
      }
      const CompactionProblem::Snapshot settled = problem.TakeSnapshot();
      if (!restart_settled) {
        // On large packings the settling is most of the first level (about
        // 800 to 1300 of its Newton iterations at 1500 disks): -restart takes
        // up the frictional solve from here.
        Checkpoint c = RunCheckpoint(phi0, 0.0);
        const std::vector<SceneValue> settling = SettlingValues(P_settle / params.young, rep);
        c.values.insert(c.values.end(), settling.begin(), settling.end());
        PetscCall(outputs.MidLevelCheckpoint(opts.pressures, step, settled, c));
      }
      problem.SetFrictionActive(true);
      SolveReport again;
      PetscCall(SolveLevel(problem, load.level, P_settle, &again));
      LevelReport friction;  // the frictional solve of the settled state
      AddCounts(again, &friction);
      // The most fragile solve of a curve: on the 1500-disk paper scene its
      // inner solves fail up to five times in a row, and on one packing
      // hybrid gave up where anchored alone, from the settled state, passed
      // (docs/level-solver-measurements.md, "Measured: the best iterate of
      // a stalled inner solve"). No load step can be cut here, so a failed
      // solve is tried once more that way.
      if (!again.converged && load.level.strategy != LevelStrategy::Anchored) {
        PetscCall(PetscPrintf(comm,
                              "  P/E = %g: the frictional solve of the settled state failed (%s after %" PetscInt_FMT
                              " Newton iterations); again from the settled state with -level_solver anchored\n",
                              P_settle / params.young, SNESConvergedReasons[again.reason], again.newton_its));
        PetscCall(problem.RestoreSnapshot(settled));
        LevelSolverParameters anchored = load.level;
        anchored.strategy = LevelStrategy::Anchored;
        PetscCall(SolveLevel(problem, anchored, P_settle, &again));
        AddCounts(again, &friction);
      }
      PetscCheck(again.converged, comm, PETSC_ERR_NOT_CONVERGED,
                 "P/E = %g: the frictionless settled state did not converge once friction was switched on (%s); "
                 "%s%s%s, or try -settle_frictionless false (much slower on large packings)",
                 P_settle / params.young, SNESConvergedReasons[again.reason],
                 opts.checkpoint ? "take it up from the settled state with other solver options by -restart " : "",
                 outputs.CheckpointPath().c_str(),
                 opts.checkpoint ? ", or run it on another number of ranks (another path)"
                                 : "on several ranks run it again (the settling takes another path each time)");
      LevelReport rest;
      PetscCall(AdvanceToPressure(problem, load, P, &step, &rest));
      AddCounts(friction, &rep);
      AddCounts(rest, &rep);
      rep.force_residual = rest.substeps > 0 ? rest.force_residual : again.force_residual;
      if (rest.substeps == 0 && again.relaxed) ++rep.relaxed_substeps;
    } else {
      problem.SetFrictionActive(true);
      PetscCall(AdvanceToPressure(problem, load, P, &step, &rep));
    }
    PetscCall(PetscTime(&t_end));
    rep.seconds = t_end - t_start + (level == 0 && restart_settled ? restart.Value("settled_seconds") : 0.0);
    PetscCall(PetscLogStagePop());
    const PackingObservables o = ComputeObservables(problem);
    const LayoutSizes sizes = problem.Sizes();
    CompactionProblem::Balance balance;  // of the accepted state: the largest net force and torque on a body
    PetscCall(problem.StateBalance(&balance));
    if (level == 0)
      PetscCall(PetscPrintf(comm,
                            "  unknowns: %" PetscInt_FMT " (deformable %" PetscInt_FMT ", rigid %" PetscInt_FMT
                            ", walls 4, gauges %" PetscInt_FMT ", contact candidates %" PetscInt_FMT ", tangential %" PetscInt_FMT
                            "), Jacobian nonzeros %" PetscInt_FMT "\n",
                            sizes.total, sizes.deformable, sizes.rigid, sizes.gauges, sizes.normal, sizes.tangential,
                            sizes.jacobian_nonzeros));
    // Bulk modulus K = dP/dphi * dphi/deps_v = phi dP/dphi (eps_v = -ln(phi_0/phi)), by
    // finite differences between successive levels.
    const double dphi = o.packing_fraction - prev_phi;
    // A rigid packing does not compress: K is infinite (phi changes at roundoff level only).
    const double K = std::abs(dphi) > 1e-10 * o.packing_fraction ? 0.5 * (o.packing_fraction + prev_phi) * (P - prev_P) / dphi : INFINITY;
    prev_phi = o.packing_fraction, prev_P = P;
    PetscCall(PetscPrintf(comm, "  %9.3g %8.5f %6.3f %6.3f %10.7f %8.3g %7d %6" PetscInt_FMT " %6d %8.2f\n", P_over_E,
                          o.packing_fraction, o.coordination, o.coordination_no_rattlers,
                          P > 0 ? o.mean_stress / P : 0.0, K / params.young, o.sliding_contacts, rep.newton_its,
                          rep.substeps, rep.seconds));
    PetscCall(PetscLogStagePush(stage_output));
    const double E = params.young, d = problem.MeanDiameter();
    const std::map<std::string, double> row = {
        {"P_over_E", P_over_E}, {"phi", o.packing_fraction}, {"Z", o.coordination},
        {"Z_no_rattlers", o.coordination_no_rattlers}, {"rattlers", double(o.rattlers)},
        {"sigma_xx_over_E", o.stress[0] / E}, {"sigma_xy_over_E", o.stress[1] / E},
        {"sigma_yy_over_E", o.stress[3] / E}, {"P_sigma_over_E", o.mean_stress / E}, {"K_over_E", K / E},
        {"mean_volumetric_strain", o.mean_volumetric_strain}, {"contacts", double(o.contacts)},
        {"sliding_contacts", double(o.sliding_contacts)}, {"newton_its", double(rep.newton_its)},
        {"substeps", double(rep.substeps)}, {"cuts", double(rep.cuts)}, {"seconds", rep.seconds},
        {"max_penetration", o.max_penetration}, {"pseudo_time_steps", double(rep.inner_solves)},
        {"symbolic_factorizations", double(rep.layouts)}, {"unknowns", double(sizes.total)},
        {"rigid_unknowns", double(sizes.rigid)}, {"deformable_unknowns", double(sizes.deformable)},
        {"tangential_unknowns", double(sizes.tangential)}, {"candidates", double(sizes.normal)},
        {"jacobian_nonzeros", double(sizes.jacobian_nonzeros)},
        {"force_residual_over_Pd", rep.force_residual / (P * d)}, {"relaxed_substeps", double(rep.relaxed_substeps)},
        {"gauge_torque_over_Pd2", problem.Summary().max_gauge_torque / (P * d * d)},
        {"factorizations", double(rep.factorizations)}, {"body_force_over_Pd", balance.body_force / (P * d)},
        {"body_torque_over_Pd2", balance.body_torque / (P * d * d)}};
    PetscCall(outputs.Level(level, opts.pressures, row, step, problem, RunCheckpoint(prev_phi, prev_P)));
    PetscCall(PetscLogStagePop());
  }
  PetscCall(PetscPrintf(comm, "  wrote %s: %s\n", opts.output_dir.c_str(), outputs.Written().c_str()));
  PetscFunctionReturn(0);
}

}  // namespace

int main(int argc, char **argv) { return RunDriver(argc, argv, help, Run); }

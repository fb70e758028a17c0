// Quasistatic load control with automatic sub-stepping.
//
// A pressure level P_target is reached from the current pressure through
// sub-steps: each sub-step solves equilibrium at an intermediate pressure.
// A sub-step whose solve fails (divergence, iteration limit, an inverted
// element reported as a domain error) is discarded, the state restored and
// the step halved. How long the next sub-step is (-load_step_policy):
//   whole     (default) every sub-step goes for the whole rest of the level:
//             a level is one sub-step unless a solve fails;
//   adaptive  the step is carried from sub-step to sub-step and from level
//             to level, and grows by -load_growth after a sub-step that took
//             at most -load_easy_its Newton iterations per inner solve.
// Which one wins is measured in docs/level-solver.md: whole for
// -level_solver anchored on every scene measured, adaptive for newton.
#pragma once
#include "deformix/level_solver.hpp"
#include "deformix/problem.hpp"

namespace deformix {

enum class LoadStepPolicy : int { Whole = 0, Adaptive = 1 };

struct LoadControlParameters {
  LoadStepPolicy policy = LoadStepPolicy::Whole;
  PetscInt max_cuts = 16;    // give up after this many halvings in a row (smallest step: jump / 2^max_cuts)
  PetscInt easy_its = 8;     // adaptive: grow the step after a sub-step that took at most this many Newton iterations (per inner solve)
  double growth = 2.0;       // adaptive: step growth factor
  PetscBool monitor = PETSC_FALSE;  // one line per sub-step (-load_monitor)
  LevelSolverParameters level;      // how each sub-step is solved (-level_*)
  PetscErrorCode SetFromOptions(MPI_Comm comm);
};

struct LevelReport {
  double pressure = 0.0;
  PetscInt newton_its = 0;   // all Newton iterations of the level, failed sub-steps included
  int substeps = 0;          // accepted sub-steps
  int cuts = 0;              // rejected sub-steps
  int inner_solves = 0;      // SNES solves (pseudo-time steps, candidate refreshes)
  double force_residual = 0.0;  // largest unbalanced force at the level's final state
  int relaxed_substeps = 0;     // sub-steps accepted by the relative criterion (-level_force_rtol)
  int layouts = 0;           // new sparsity patterns (symbolic factorizations) in accepted sub-steps
  PetscInt factorizations = 0;  // numeric factorizations, failed sub-steps included
  double seconds = 0.0;
  bool converged = false;
};

// Brings `problem` from its current pressure to `target`. `step` is the
// suggested pressure increment (<= 0: try the whole jump); it is updated
// (the adaptive policy reads it, the whole policy only records it).
PetscErrorCode AdvanceToPressure(CompactionProblem &problem, const LoadControlParameters &params, double target,
                                 double *step, LevelReport *report);

}  // namespace deformix

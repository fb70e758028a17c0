#include "deformix/load_controller.hpp"

#include <algorithm>
#include <cmath>

namespace deformix {

PetscErrorCode LoadControlParameters::SetFromOptions(MPI_Comm comm) {
  PetscFunctionBeginUser;
  PetscInt choice = static_cast<PetscInt>(policy);
  const char *const names[] = {"whole", "adaptive"};  // LoadStepPolicy order
  PetscOptionsBegin(comm, nullptr, "Quasistatic load control", "deformix");
  PetscCall(PetscOptionsEList("-load_step_policy",
                              "length of a sub-step: whole (the rest of the level; halved after a failed solve) or "
                              "adaptive (carried between sub-steps and levels, grown after easy sub-steps: "
                              "-load_easy_its, -load_growth)",
                              "", names, 2, names[choice], &choice, nullptr));
  PetscCall(PetscOptionsInt("-load_max_cuts", "consecutive step halvings allowed before a level is declared failed", "", max_cuts, &max_cuts,
                            nullptr));
  PetscCall(PetscOptionsInt("-load_easy_its", "adaptive: grow the step after sub-steps with at most this many Newton iterations",
                            "", easy_its, &easy_its, nullptr));
  PetscCall(PetscOptionsReal("-load_growth", "adaptive: step growth factor after an easy sub-step", "", growth, &growth, nullptr));
  PetscCall(PetscOptionsBool("-load_monitor", "print one line per sub-step (pressure, Newton iterations, pseudo-time steps)",
                             "", monitor, &monitor, nullptr));
  PetscOptionsEnd();
  policy = static_cast<LoadStepPolicy>(choice);
  PetscCall(level.SetFromOptions(comm));
  PetscCheck(max_cuts >= 0, comm, PETSC_ERR_USER_INPUT, "-load_max_cuts must be >= 0");
  PetscCheck(growth >= 1.0, comm, PETSC_ERR_USER_INPUT, "-load_growth %g must be >= 1", growth);
  PetscFunctionReturn(0);
}

PetscErrorCode AdvanceToPressure(CompactionProblem &problem, const LoadControlParameters &params, double target,
                                 double *step, LevelReport *report) {
  PetscLogDouble t0, t1;
  PetscFunctionBeginUser;
  PetscCall(PetscTime(&t0));
  *report = LevelReport();
  report->pressure = target;
  double P = problem.Pressure();
  const double jump = std::abs(target - P);
  const bool whole = params.policy == LoadStepPolicy::Whole;
  double dP = (*step > 0.0 && !whole) ? std::min(*step, jump) : jump;
  // Pressures closer than this to the target count as the target.
  const double snap = 1e-12 * std::max(std::abs(target), 1e-300);
  int cuts_in_a_row = 0;
  const double min_step = std::ldexp(jump, -static_cast<int>(params.max_cuts));
  while (std::abs(target - P) > snap) {
    const double remaining = std::abs(target - P);
    const double inc = (remaining - dP <= snap) ? remaining : dP;
    const double Pnext = P + std::copysign(inc, target - P);
    SolveReport solve;
    PetscCall(SolveLevel(problem, params.level, Pnext, &solve));
    report->newton_its += solve.newton_its;
    report->factorizations += solve.factorizations;
    report->inner_solves += solve.inner_solves;
    report->layouts += solve.layouts;
    if (params.monitor)
      PetscCall(PetscPrintf(PETSC_COMM_WORLD, "    sub-step to P = %-10.4g %s: %4" PetscInt_FMT " Newton iterations, %3d pseudo-time steps%s\n",
                            Pnext, solve.converged ? "converged" : "failed   ", solve.newton_its, solve.inner_solves,
                            solve.converged ? (solve.relaxed ? " (level criterion)" : "") : ", step halved"));
    if (solve.converged) {
      P = Pnext;
      report->force_residual = solve.force_residual;
      report->relaxed_substeps += solve.relaxed;
      ++report->substeps;
      cuts_in_a_row = 0;
      if (whole) dP = std::abs(target - P);
      // Easy: few Newton iterations per inner solve (pseudo-transient steps count separately).
      else if (solve.newton_its <= params.easy_its * std::max(1, solve.inner_solves)) dP = inc * params.growth;
      else dP = inc;
    } else {
      ++report->cuts;
      ++cuts_in_a_row;
      PetscCall(PetscInfo(nullptr, "sub-step to P = %g failed (%s): halving\n", Pnext, SNESConvergedReasons[solve.reason]));
      // A level fails when the step has been halved max_cuts times in a row, or
      // has become smaller than jump / 2^max_cuts (creeping towards a limit load).
      PetscCheck(cuts_in_a_row <= params.max_cuts && 0.5 * inc >= min_step, PETSC_COMM_WORLD, PETSC_ERR_NOT_CONVERGED,
                 "pressure level P = %g not reached: %d step cuts in a row, last step %g from P = %g (reason %s). "
                 "Try more -load_max_cuts, smaller pressure increments or -newton_monitor to see the Newton history",
                 target, cuts_in_a_row, inc, P, SNESConvergedReasons[solve.reason]);
      dP = 0.5 * inc;
    }
  }
  problem.SetPressure(target);
  *step = dP;
  report->converged = true;
  PetscCall(PetscTime(&t1));
  report->seconds = t1 - t0;
  PetscFunctionReturn(0);
}

}  // namespace deformix

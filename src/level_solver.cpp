#include "deformix/level_solver.hpp"

#include <algorithm>
#include <cmath>
#include <deque>

namespace deformix {

PetscErrorCode LevelSolverParameters::SetFromOptions(MPI_Comm comm) {
  PetscInt choice = static_cast<PetscInt>(strategy);
  const char *const names[] = {"newton", "anchored"};  // LevelStrategy order
  PetscFunctionBeginUser;
  PetscOptionsBegin(comm, nullptr, "Level solver", "deformix");
  PetscCall(PetscOptionsEList("-level_solver",
                              "equilibrium of a load step: newton (semismooth Newton, one linearization per iteration, "
                              "steps accepted by a merit function with a Levenberg-Marquardt shift on the body rows) or "
                              "anchored (pseudo-transient continuation, each pseudo-time step solved to convergence: -ptc_*)",
                              "", names, 2, names[choice], &choice, nullptr));
  PetscCall(PetscOptionsInt("-level_max_its", "newton: linearizations per load step before the step is cut", "", max_its,
                            &max_its, nullptr));
  PetscCall(PetscOptionsReal("-level_initial_move",
                             "newton: trust radius at the start of a load step (largest move of a body under the "
                             "largest unbalanced force, in mean diameters)",
                             "", initial_move, &initial_move, nullptr));
  PetscCall(PetscOptionsBool("-level_monitor",
                             "newton: one line per iteration (|F|, largest force, trust radius, step fraction, merit "
                             "ratio, accepted or rejected, closed and sliding contacts)",
                             "", monitor, &monitor, nullptr));
  PetscOptionsEnd();
  strategy = static_cast<LevelStrategy>(choice);
  PetscCheck(max_its >= 1, comm, PETSC_ERR_USER_INPUT, "-level_max_its %" PetscInt_FMT " must be >= 1", max_its);
  PetscCheck(initial_move > 0.0 && std::isfinite(initial_move), comm, PETSC_ERR_USER_INPUT,
             "-level_initial_move %g must be positive", initial_move);
  PetscFunctionReturn(0);
}

namespace {

constexpr double kWeakContact = 1e3;    // a state flip within 1e3 atol of its switch is degenerate (contact_law.hpp)
constexpr double kMaxMove = 1e6;        // trust radius cap (rho is then at its floor)
constexpr int kMaxRejections = 12;      // rejected trial steps in a row before the load step fails
constexpr size_t kMemory = 4;           // accepted iterates the nonmonotone residual test compares with

// The merit-globalized semismooth Newton iteration of one load step.
class MeritNewton {
 public:
  MeritNewton(CompactionProblem &problem, const LevelSolverParameters &params) : p_(problem), prm_(params) {}
  ~MeritNewton() { Destroy(); }
  PetscErrorCode Solve(double pressure, SolveReport *report);

 private:
  PetscErrorCode Attach();            // the problem's layout objects, and our work vectors for them
  PetscErrorCode Destroy();
  PetscErrorCode Evaluate(Vec z, Vec F, double *norm, double *force, bool *inverted);
  PetscErrorCode Factor(double rho, bool *ok);   // (J + floor + rho D), numeric factorization in the KSP

  CompactionProblem &p_;
  const LevelSolverParameters &prm_;
  Vec z_ = nullptr, F_ = nullptr;     // the problem's (layout) vectors
  Mat J_ = nullptr;
  KSP ksp_ = nullptr;
  Vec d_ = nullptr, zt_ = nullptr, Ft_ = nullptr, floor_ = nullptr, weight_ = nullptr, work_ = nullptr;
  double rho_in_matrix_ = 0.0;
  int layouts_ = -1;
  MPI_Comm comm_ = MPI_COMM_NULL;
};

PetscErrorCode MeritNewton::Destroy() {
  PetscFunctionBeginUser;
  PetscCall(VecDestroy(&d_));
  PetscCall(VecDestroy(&zt_));
  PetscCall(VecDestroy(&Ft_));
  PetscCall(VecDestroy(&floor_));
  PetscCall(VecDestroy(&weight_));
  PetscCall(VecDestroy(&work_));
  PetscFunctionReturn(0);
}

PetscErrorCode MeritNewton::Attach() {
  PetscFunctionBeginUser;
  PetscCall(p_.Layout(&z_, &F_, &J_, &ksp_));  // packs the state into z_
  if (layouts_ == p_.LayoutsCreated() && d_) PetscFunctionReturn(0);
  layouts_ = p_.LayoutsCreated();
  PetscCall(Destroy());
  PetscCall(PetscObjectGetComm((PetscObject)z_, &comm_));
  PetscCall(VecDuplicate(z_, &d_));
  PetscCall(VecDuplicate(z_, &zt_));
  PetscCall(VecDuplicate(z_, &Ft_));
  PetscCall(VecDuplicate(z_, &floor_));
  PetscCall(VecDuplicate(z_, &weight_));
  PetscCall(VecDuplicate(z_, &work_));
  PetscCall(p_.ShiftDiagonals(floor_, weight_));
  PetscFunctionReturn(0);
}

PetscErrorCode MeritNewton::Evaluate(Vec z, Vec F, double *norm, double *force, bool *inverted) {
  PetscFunctionBeginUser;
  PetscCall(p_.Residual(z, F));
  *inverted = p_.Inverted();
  PetscCall(VecNorm(F, NORM_2, norm));
  PetscCall(p_.ForceResidual(F, force));
  if (*inverted || !std::isfinite(*norm)) *norm = INFINITY;
  PetscFunctionReturn(0);
}

PetscErrorCode MeritNewton::Factor(double rho, bool *ok) {
  PC pc;
  PCFailedReason reason;
  PetscFunctionBeginUser;
  // The matrix holds J + floor + rho_in_matrix_ D: add the difference.
  if (rho != rho_in_matrix_) {
    PetscCall(VecAXPBY(work_, rho - rho_in_matrix_, 0.0, weight_));
    PetscCall(MatDiagonalSet(J_, work_, ADD_VALUES));
    rho_in_matrix_ = rho;
  }
  PetscCall(KSPSetOperators(ksp_, J_, J_));
  PetscCall(KSPSetUp(ksp_));
  PetscCall(KSPGetPC(ksp_, &pc));
  PetscCall(PCGetFailedReason(pc, &reason));
  int failed = reason != PC_NOERROR;
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &failed, 1, MPI_INT, MPI_MAX, comm_));
  *ok = !failed;
  PetscFunctionReturn(0);
}

// Penalty weight of the merit's gap term: an exact penalty needs more than the
// largest contact force; the scale P <d> covers contacts not yet loaded.
double PenaltyWeight(const CompactionProblem &p) {
  double lam = p.Pressure() * p.MeanDiameter();
  for (double l : p.Multipliers()) lam = std::max(lam, l);
  return 10.0 * lam;
}

PetscErrorCode MeritNewton::Solve(double pressure, SolveReport *report) {
  PetscFunctionBeginUser;
  *report = SolveReport();
  PetscCall(p_.BeginLoadStep(pressure));
  PetscCall(Attach());
  const double dmean = p_.MeanDiameter();
  const double atol = 1e-11 * p_.Parameters().young * dmean;
  const double detect_every = 0.4 * p_.Parameters().contact_margin * dmean;
  double fnorm, force, merit = 0.0;
  bool inverted;
  // The merit's weights are frozen for the load step (re-frozen when the
  // candidates change), so that it is one function and the filter below can
  // compare iterates: the penalty on gaps, and the normal forces that weight
  // the frictional dissipation.
  double penalty = 0.0;
  std::vector<double> lagged;
  // The filter (Fletcher and Leyffer): the (|F|, merit) pairs of the accepted
  // iterates. A trial point is acceptable when, against every pair, it
  // lowers |F| or the merit by a margin. So a rearrangement may raise |F|
  // for some steps while the packing moves downhill, the last iterations are
  // driven by |F| (where merit differences drown in round-off), and no
  // cycle can return to a point the filter has seen.
  std::vector<std::pair<double, double>> filter;
  std::vector<double> history;  // |F| of the accepted iterates
  const bool exact_merit = !p_.FrictionActive();
  const auto freeze = [&]() {
    penalty = PenaltyWeight(p_);
    lagged = p_.Multipliers();
    filter.clear();
    history.clear();
  };
  const auto at_iterate = [&]() -> PetscErrorCode {
    PetscFunctionBeginUser;
    PetscCall(p_.AdoptState(z_));
    if (exact_merit) PetscCall(p_.Merit(z_, penalty, lagged, &merit));
    PetscCall(Evaluate(z_, F_, &fnorm, &force, &inverted));
    filter.emplace_back(fnorm, merit);
    history.push_back(fnorm);
    PetscFunctionReturn(0);
  };
  freeze();
  PetscCall(at_iterate());
  std::vector<char> active_before = p_.ActiveSet();
  double move = prm_.initial_move;     // trust radius m, in <d>
  double moved = 0.0;                  // largest body move since the last candidate check
  double changed_margin = INFINITY;    // largest switch margin of the contacts that changed in the last step
  double last_step = INFINITY;         // largest move of the last accepted step
  int rejections = 0;
  bool converged = false;
  for (;;) {
    // Converged: small residual with a stable contact state, and every
    // contact that can touch is a candidate.
    const bool small = std::isfinite(fnorm) && fnorm <= atol;
    const bool stable = report->newton_its == 0 || changed_margin <= kWeakContact * atol || last_step <= 1e-12 * dmean;
    if (moved > detect_every || small) {
      bool stale = false;
      PetscCall(p_.CandidatesStale(&stale));  // reads the state of the iterate (at_iterate adopted it)
      moved = 0.0;
      if (stale) {
        PetscCall(p_.RefreshCandidates());
        ++report->candidate_refreshes;
        PetscCall(Attach());
        PetscCall(at_iterate());
        active_before = p_.ActiveSet();
        changed_margin = INFINITY;
        continue;
      }
      if (small && stable) {
        converged = true;
        break;
      }
    }
    if (report->newton_its >= prm_.max_its) {
      report->reason = SNES_DIVERGED_MAX_IT;
      break;
    }
    // One linearization per iteration.
    PetscCall(p_.NewtonMatrix(z_, J_));
    rho_in_matrix_ = 0.0;
    ++report->newton_its;
    bool accepted = false;
    while (!accepted) {
      const double rho = force / (move * dmean);
      bool ok = false;
      PetscCall(Factor(rho, &ok));
      ++report->factorizations;
      double alpha = 1.0, ratio = 0.0, trial_norm = INFINITY, trial_force = 0.0, trial_merit = INFINITY, step = 0.0;
      bool trial_inverted = false, by_energy = false;
      if (ok) {
        KSPConvergedReason kreason;
        PetscCall(KSPSolve(ksp_, F_, d_));
        PetscCall(KSPGetConvergedReason(ksp_, &kreason));
        ok = kreason > 0;
      }
      if (!ok) {
        // A singular or failed factorization: MUMPS out of workspace gets a
        // larger one (new layout); anything else a larger shift.
        PC pc;
        PCFailedReason pc_reason;
        PetscCall(KSPGetPC(ksp_, &pc));
        PetscCall(PCGetFailedReason(pc, &pc_reason));
        int out_of_memory = pc_reason == PC_FACTOR_OUTMEMORY;
        PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &out_of_memory, 1, MPI_INT, MPI_MAX, comm_));
        if (out_of_memory && p_.GrowFactorWorkspace()) {
          PetscCall(PetscInfo(nullptr, "MUMPS workspace too small (INFOG(1) = -9): enlarged\n"));
          PetscCall(Attach());
          PetscCall(at_iterate());
          PetscCall(p_.NewtonMatrix(z_, J_));
          rho_in_matrix_ = 0.0;
          continue;
        }
      } else {
        PetscCall(VecScale(d_, -1.0));  // (J + rho D) d = -F
        PetscCall(p_.ContactStepFraction(d_, &alpha));
        if (alpha < 1.0) PetscCall(VecScale(d_, alpha));
        double dmin;
        PetscCall(VecMax(d_, nullptr, &step));
        PetscCall(VecMin(d_, nullptr, &dmin));
        step = std::max(step, -dmin);
        PetscCall(p_.RotatedUpdate(z_, d_, zt_));
        PetscCall(Evaluate(zt_, Ft_, &trial_norm, &trial_force, &trial_inverted));
        if (exact_merit && std::isfinite(trial_norm)) PetscCall(p_.Merit(zt_, penalty, lagged, &trial_merit));
        // Model quality, for the trust radius: the proximal residual
        // G(z') = F(z') + (floor + rho D)(z' - z), whose Newton direction at z
        // is d (G(z) = F(z), G' = the factored matrix), against its linear
        // model at s = alpha d, (1 - alpha) F.
        PetscCall(VecWAXPY(work_, rho, weight_, floor_));
        PetscCall(VecPointwiseMult(work_, work_, d_));
        PetscCall(VecAXPY(work_, 1.0, Ft_));
        double proximal_norm;
        PetscCall(VecNorm(work_, NORM_2, &proximal_norm));
        const double predicted = 1.0 - (1.0 - alpha) * (1.0 - alpha);
        ratio = std::isfinite(trial_norm) ? (1.0 - (proximal_norm / fnorm) * (proximal_norm / fnorm)) / predicted : -INFINITY;
        // Nonmonotone residual test: against the largest |F| of the last
        // kMemory accepted iterates (a change of the active set may raise |F|
        // for a step on the way to the solution).
        double reference = 0.0;
        for (size_t k = history.size() > kMemory ? history.size() - kMemory : 0; k < history.size(); ++k)
          reference = std::max(reference, history[k]);
        bool acceptable = std::isfinite(trial_norm) && trial_norm <= (1.0 - 1e-4) * reference;
        if (!acceptable && exact_merit && std::isfinite(trial_merit)) {
          // Frictionless: the merit is the exact penalty function of the
          // problem, and the filter decides.
          const double length = 1e-3 * dmean;  // converts a force margin into an energy margin
          acceptable = true;
          for (const auto &[theta, phi] : filter)
            if (!(trial_norm <= (1.0 - 1e-4) * theta || trial_merit <= phi - 1e-4 * length * theta)) acceptable = false;
        }
        by_energy = acceptable && trial_norm > fnorm;
        accepted = acceptable;
      }
      if (prm_.monitor && getenv("DFX_BLOCKS")) {
        double b[5], c[5];
        PetscCall(p_.ResidualBlocks(Ft_, b));
        PetscCall(p_.ResidualBlocks(F_, c));
        PetscCall(PetscPrintf(comm_, "      blocks now: body %.1e wall %.1e gauge %.1e normal %.1e tangential %.1e | trial: body %.1e wall %.1e gauge %.1e normal %.1e tangential %.1e\n",
                              c[0], c[1], c[2], c[3], c[4], b[0], b[1], b[2], b[3], b[4]));
      }
      if (prm_.monitor) {
        int closed = 0, sliding = 0;
        for (char a : p_.ActiveSet()) closed += a == kClosed, sliding += a == kSliding;
        PetscCall(PetscPrintf(comm_,
                              "    newton %3" PetscInt_FMT "  |F| %.3e -> %.3e  |F|_inf %.2e  merit %+.3e  move %.1e rho %.1e  "
                              "alpha %.2f |s| %.1e  ratio %6.3f  %s  closed %d sliding %d\n",
                              report->newton_its, fnorm, trial_norm, force, trial_merit - merit, move, rho, alpha, step,
                              ratio, !ok ? "failed factorization" : accepted ? (by_energy ? "accepted (merit)" : "accepted")
                                                                             : "rejected",
                              closed, sliding));
      }
      if (accepted) {
        rejections = 0;
        if (ratio > 0.75) move = std::min(4.0 * move, kMaxMove);
        else if (ratio < 0.25 && !by_energy) move *= 0.5;
        PetscCall(VecCopy(zt_, z_));
        PetscCall(p_.ChangedStateMargin(active_before, &changed_margin));
        active_before = p_.ActiveSet();
        PetscCall(at_iterate());
        last_step = step;
        moved += step;
        break;
      }
      move *= 0.25;
      if (++rejections > kMaxRejections) break;
      // Back to the iterate: the step limiter reads the residual's contact data there.
      PetscCall(Evaluate(z_, F_, &fnorm, &force, &inverted));
    }
    if (!accepted) {
      report->reason = SNES_DIVERGED_LINE_SEARCH;
      break;
    }
  }
  report->residual = fnorm;
  report->force_residual = force;
  report->inner_solves = 1;
  if (converged) report->reason = SNES_CONVERGED_FNORM_ABS;
  PetscCall(p_.EndLoadStep(converged, report));
  PetscFunctionReturn(0);
}

}  // namespace

PetscErrorCode SolveLevel(CompactionProblem &problem, const LevelSolverParameters &params, double pressure,
                          SolveReport *report) {
  PetscFunctionBeginUser;
  if (params.strategy == LevelStrategy::Anchored) {
    PetscCall(problem.Solve(pressure, report));
    report->factorizations = static_cast<int>(report->newton_its);  // one LU per Newton iteration
    PetscFunctionReturn(0);
  }
  MeritNewton solver(problem, params);
  PetscCall(solver.Solve(pressure, report));
  PetscFunctionReturn(0);
}

}  // namespace deformix

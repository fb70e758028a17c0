#include "deformix/level_solver.hpp"

#include <algorithm>
#include <cmath>

namespace deformix {

PetscErrorCode LevelSolverParameters::SetFromOptions(MPI_Comm comm) {
  PetscInt choice = static_cast<PetscInt>(strategy);
  const char *const names[] = {"newton", "anchored"};  // LevelStrategy order
  PetscFunctionBeginUser;
  PetscOptionsBegin(comm, nullptr, "Level solver", "deformix");
  PetscCall(PetscOptionsEList("-level_solver",
                              "equilibrium of a load step: newton (pseudo-transient continuation with one semismooth "
                              "Newton step per pseudo-time step, each step accepted by the residual of its proximal "
                              "subproblem) or anchored (pseudo-transient continuation, each pseudo-time step solved to "
                              "convergence: -ptc_*)",
                              "", names, 2, names[choice], &choice, nullptr));
  PetscCall(PetscOptionsInt("-level_max_its", "newton: linearizations per load step before the step is cut", "", max_its,
                            &max_its, nullptr));
  PetscCall(PetscOptionsReal("-level_initial_move",
                             "newton: trust radius at the start of a load step (largest move of a body under the "
                             "largest unbalanced force, in mean diameters)",
                             "", initial_move, &initial_move, nullptr));
  PetscCall(PetscOptionsBool("-level_monitor",
                             "newton: one line per trial step (|F|, merit |G| before and after, largest force, trust "
                             "radius, shift, step fraction and length, accepted or rejected, closed and sliding contacts, "
                             "residual by block) and the level criterion's balances",
                             "", monitor, &monitor, nullptr));
  PetscOptionsEnd();
  strategy = static_cast<LevelStrategy>(choice);
  PetscCheck(max_its >= 1, comm, PETSC_ERR_USER_INPUT, "-level_max_its %" PetscInt_FMT " must be >= 1", max_its);
  PetscCheck(initial_move > 0.0 && std::isfinite(initial_move), comm, PETSC_ERR_USER_INPUT,
             "-level_initial_move %g must be positive", initial_move);
  PetscFunctionReturn(0);
}

namespace {

constexpr double kMaxMove = 0.5;        // trust radius cap, in <d>
constexpr int kMaxRejections = 12;      // rejected trial steps in a row before the load step fails
constexpr int kBacktracks = 4;          // step fractions 1, 1/2, 1/4, 1/8 tried before a larger shift

// The iteration of one load step (level_solver.hpp, "newton").
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
  Vec za_ = nullptr, G_ = nullptr, Gt_ = nullptr;  // anchor, proximal residual at the iterate and at a trial point
  Vec d_ = nullptr, s_ = nullptr, zt_ = nullptr, Ft_ = nullptr, floor_ = nullptr, weight_ = nullptr, sqrt_weight_ = nullptr,
      work_ = nullptr;
  double rho_in_matrix_ = 0.0;
  int layouts_ = -1;
  MPI_Comm comm_ = MPI_COMM_NULL;
};

PetscErrorCode MeritNewton::Destroy() {
  PetscFunctionBeginUser;
  PetscCall(VecDestroy(&d_));
  PetscCall(VecDestroy(&za_));
  PetscCall(VecDestroy(&G_));
  PetscCall(VecDestroy(&Gt_));
  PetscCall(VecDestroy(&s_));
  PetscCall(VecDestroy(&sqrt_weight_));
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
  PetscCall(VecDuplicate(z_, &za_));
  PetscCall(VecDuplicate(z_, &G_));
  PetscCall(VecDuplicate(z_, &Gt_));
  PetscCall(VecDuplicate(z_, &s_));
  PetscCall(VecDuplicate(z_, &sqrt_weight_));
  PetscCall(VecDuplicate(z_, &zt_));
  PetscCall(VecDuplicate(z_, &Ft_));
  PetscCall(VecDuplicate(z_, &floor_));
  PetscCall(VecDuplicate(z_, &weight_));
  PetscCall(VecDuplicate(z_, &work_));
  PetscCall(p_.ShiftDiagonals(floor_, weight_));
  PetscCall(VecCopy(weight_, sqrt_weight_));
  PetscCall(VecSqrtAbs(sqrt_weight_));
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

PetscErrorCode MeritNewton::Solve(double pressure, SolveReport *report) {
  PetscFunctionBeginUser;
  *report = SolveReport();
  PetscCall(p_.BeginLoadStep(pressure));
  PetscCall(Attach());
  const double dmean = p_.MeanDiameter();
  const double atol = 1e-11 * p_.Parameters().young * dmean;
  const double detect_every = 0.4 * p_.Parameters().contact_margin * dmean;
  const double relaxed_tol = p_.Parameters().level_force_rtol, phi_tol = p_.Parameters().level_phi_rtol;
  const double progress_interval = p_.Parameters().progress_interval;
  PetscLogDouble t_start, t_progress;
  PetscCall(PetscTime(&t_start));
  t_progress = t_start;
  double fnorm, force, phi = 0.0, phi_before = 0.0;
  bool inverted;
  // The iterate z: its residual F(z), and phi for the level criterion.
  const auto at_iterate = [&]() -> PetscErrorCode {
    PetscFunctionBeginUser;
    PetscCall(p_.AdoptState(z_));
    PetscCall(Evaluate(z_, F_, &fnorm, &force, &inverted));
    phi_before = phi;
    if (relaxed_tol > 0.0) phi = p_.PackingFraction();
    PetscFunctionReturn(0);
  };
  double move = prm_.initial_move;  // trust radius m, in <d>
  double rho = 0.0;
  // A new anchor at the iterate: G = F there, rho from its largest force.
  const auto anchor = [&]() -> PetscErrorCode {
    PetscFunctionBeginUser;
    PetscCall(VecCopy(z_, za_));
    PetscCall(VecCopy(F_, G_));
    rho = force / (move * dmean);
    PetscFunctionReturn(0);
  };
  // G(z') = F(z') + rho D (z' - z_a) at a point with residual F.
  const auto proximal = [&](Vec zp, Vec Fp, Vec Gp, double *norm) -> PetscErrorCode {
    PetscFunctionBeginUser;
    PetscCall(VecWAXPY(work_, -1.0, za_, zp));
    PetscCall(VecPointwiseMult(work_, work_, weight_));
    PetscCall(VecWAXPY(Gp, rho, work_, Fp));
    PetscCall(VecNorm(Gp, NORM_2, norm));
    PetscFunctionReturn(0);
  };
  PetscCall(at_iterate());
  PetscCall(anchor());
  double gnorm = fnorm;
  std::vector<char> active_before = p_.ActiveSet();
  double moved = 0.0;                // largest body move since the last candidate check
  double changed_margin = INFINITY;  // largest switch margin of the contacts that changed in the last step
  double last_step = INFINITY;       // largest body move of the last accepted step
  int rejections = 0;
  bool converged = false;
  for (;;) {
    // Converged: small residual with a stable contact state, and every
    // contact that can touch is a candidate (checked whenever a body may
    // have crossed the candidate margin since the last check).
    const bool small = std::isfinite(fnorm) && fnorm <= atol;
    const bool stable = report->newton_its == 0 || changed_margin <= kDegenerateSwitch * atol || last_step <= 1e-12 * dmean;
    if (moved > detect_every || small) {
      bool stale = false;
      PetscCall(p_.CandidatesStale(&stale));  // the state of the iterate (adopted by at_iterate)
      moved = 0.0;
      if (stale) {
        PetscCall(p_.RefreshCandidates());
        ++report->candidate_refreshes;
        PetscCall(Attach());
        PetscCall(at_iterate());
        PetscCall(anchor());
        gnorm = fnorm;
        active_before = p_.ActiveSet();
        changed_margin = INFINITY;
        continue;
      }
      if (small && stable) {
        converged = true;
        break;
      }
    }
    // The paper's level criterion (-level_force_rtol > 0), per body: every
    // body's net force and torque below tol P <d> and tol P <d>^2, every
    // nodal force and contact row below tol P <d>, the contact states
    // stable and phi settled over the last step.
    if (relaxed_tol > 0.0 && report->newton_its > 0 && stable && std::abs(phi - phi_before) <= phi_tol * phi) {
      CompactionProblem::Balance b;
      PetscCall(p_.BodyBalance(F_, &b));
      const double f_tol = relaxed_tol * pressure * dmean;
      if (prm_.monitor)
        PetscCall(PetscPrintf(comm_, "    level criterion: body force %.2e torque %.2e node %.2e contact rows %.2e (tolerance %.2e), phi change %.1e\n",
                              b.body_force, b.body_torque / dmean, b.node_force, b.contact_row, f_tol, std::abs(phi - phi_before) / phi));
      if (b.body_force <= f_tol && b.body_torque <= f_tol * dmean && b.node_force <= f_tol && b.contact_row <= f_tol) {
        bool stale = false;
        PetscCall(p_.CandidatesStale(&stale));
        if (!stale) {
          converged = true;
          report->relaxed = true;
          break;
        }
        moved = INFINITY;  // refresh at the next pass
        continue;
      }
    }
    if (report->newton_its >= prm_.max_its) {
      report->reason = SNES_DIVERGED_MAX_IT;
      break;
    }
    if (progress_interval >= 0.0 && !prm_.monitor) {
      // A heartbeat for long load steps; rank 0's clock decides, so the ranks agree on whether to print.
      PetscLogDouble now;
      PetscCall(PetscTime(&now));
      int due = now - t_progress >= progress_interval;
      PetscCallMPI(MPI_Bcast(&due, 1, MPI_INT, 0, comm_));
      if (due) {
        t_progress = now;
        PetscCall(PetscPrintf(comm_,
                              "    ... P/E %.4g: %" PetscInt_FMT " Newton its, |F| %.2e, largest force %.2e P<d>, "
                              "trust radius %.1e <d>, %.0f s in this load step\n",
                              pressure / p_.Parameters().young, report->newton_its, fnorm,
                              force / (std::max(pressure, 1e-300) * dmean), move, now - t_start));
      }
    }
    // One linearization per iteration.
    PetscCall(p_.NewtonMatrix(z_, J_));
    rho_in_matrix_ = 0.0;
    ++report->newton_its;
    bool accepted = false;
    while (!accepted) {
      bool ok = false;
      PetscCall(Factor(rho, &ok));
      ++report->factorizations;
      if (ok) {
        KSPConvergedReason kreason;
        PetscCall(KSPSolve(ksp_, G_, d_));
        PetscCall(KSPGetConvergedReason(ksp_, &kreason));
        ok = kreason > 0;
      }
      if (!ok) {
        // A failed factorization: MUMPS out of workspace gets a larger one
        // (a new layout); anything else (a singular matrix) a larger shift.
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
          PetscCall(anchor());
          gnorm = fnorm;
          PetscCall(p_.NewtonMatrix(z_, J_));
          rho_in_matrix_ = 0.0;
          continue;
        }
        if (prm_.monitor)
          PetscCall(PetscPrintf(comm_, "    newton %3" PetscInt_FMT "  factorization failed (%s) at rho %.1e\n",
                                report->newton_its, PCFailedReasons[pc_reason], rho));
      } else {
        PetscCall(VecScale(d_, -1.0));  // (J + rho D) d = -G
        // Step fraction: open contacts not driven deep into penetration, and
        // no body moving (or turning, times its radius) more than m <d> in
        // one step: the shift alone does not bound a mode whose force is far
        // below |F|_inf.
        double alpha0, full_move;
        PetscCall(p_.ContactStepFraction(d_, &alpha0));
        PetscCall(VecPointwiseMult(work_, d_, sqrt_weight_));
        PetscCall(VecNorm(work_, NORM_INFINITY, &full_move));
        if (full_move > move * dmean) alpha0 = std::min(alpha0, move * dmean / full_move);
        // Backtracking (Armijo on |G| along its Newton direction d) before a
        // larger shift, which costs a factorization.
        for (int bt = 0; bt < kBacktracks && !accepted; ++bt) {
          const double alpha = alpha0 * std::ldexp(1.0, -bt);
          double trial_norm, trial_force, trial_gnorm;
          bool trial_inverted;
          PetscCall(VecAXPBY(s_, alpha, 0.0, d_));
          PetscCall(p_.RotatedUpdate(z_, s_, zt_));
          PetscCall(Evaluate(zt_, Ft_, &trial_norm, &trial_force, &trial_inverted));
          PetscCall(proximal(zt_, Ft_, Gt_, &trial_gnorm));
          if (!std::isfinite(trial_norm)) trial_gnorm = INFINITY;
          accepted = trial_gnorm <= (1.0 - 1e-4 * alpha) * gnorm;
          double step;
          PetscCall(VecPointwiseMult(work_, s_, sqrt_weight_));
          PetscCall(VecNorm(work_, NORM_INFINITY, &step));
          if (prm_.monitor) {
            double blocks[5];
            PetscCall(p_.ResidualBlocks(Ft_, blocks));
            int closed = 0, sliding = 0;
            for (char a : p_.ActiveSet()) closed += a == kClosed, sliding += a == kSliding;
            PetscCall(PetscPrintf(comm_,
                                  "    newton %3" PetscInt_FMT "  |F| %.3e  |G| %.3e -> %.3e (trial |F| %.3e)  |F|_inf %.2e  "
                                  "m %.1e rho %.1e  alpha %.3f |s| %.1e  %s  closed %d sliding %d  "
                                  "(trial rows: body %.1e wall %.1e gauge %.1e normal %.1e tangential %.1e)\n",
                                  report->newton_its, fnorm, gnorm, trial_gnorm, trial_norm, force, move, rho, alpha, step,
                                  accepted ? "accepted" : "rejected", closed, sliding, blocks[0], blocks[1], blocks[2],
                                  blocks[3], blocks[4]));
          }
          if (accepted) {
            last_step = step;
            moved += step;
            gnorm = trial_gnorm;
          }
        }
      }
      if (accepted) {
        rejections = 0;
        PetscCall(VecCopy(zt_, z_));
        PetscCall(p_.ChangedStateMargin(active_before, &changed_margin));
        active_before = p_.ActiveSet();
        PetscCall(at_iterate());
        // Pseudo-transient continuation with one Newton step per pseudo-time
        // step: the anchor moves to every accepted iterate, and the trust
        // radius grows after every accepted step.
        move = std::min(4.0 * move, kMaxMove);
        PetscCall(anchor());
        gnorm = fnorm;
        break;
      }
      // No acceptable step: a shorter radius, anchored at the iterate.
      move *= 0.25;
      if (++rejections > kMaxRejections) break;
      // Back to the iterate (the step limiter reads the residual's contact data there).
      PetscCall(Evaluate(z_, F_, &fnorm, &force, &inverted));
      PetscCall(anchor());
      gnorm = fnorm;
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

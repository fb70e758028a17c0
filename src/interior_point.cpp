#include "deformix/interior_point.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

namespace deformix {
namespace {

// Constants of the method (interior_point.hpp), IPOPT's where it has one.
constexpr double kMuInit = 1e-3;         // first barrier parameter, in P <d>^2
constexpr double kMuEnd = 1e-10;        // last one before the polish, in P <d>^2
constexpr double kKappaEps = 10.0;       // a barrier problem is solved when its error <= kKappaEps mu
constexpr double kKappaMu = 0.2, kThetaMu = 1.5;  // mu <- min(kKappaMu mu, mu^kThetaMu)
constexpr double kTau = 0.99;            // fraction to the boundary
constexpr double kRelax = 1e-9;          // eps, in <d>
constexpr double kReach = 0.2;           // shat of the clamped barrier, in candidate margins
constexpr double kLambdaCap = 1.0;       // lambda raised to at most this x P <d> when entering the interior
constexpr double kDeltaInit = 1e-4;      // first shift, in E
constexpr double kDeltaMax = 1e6;        // in E: beyond, the load step fails
constexpr double kSigma = 1e10;          // lambda within a factor kSigma of mu psi
constexpr int kMeritMemory = 3;          // iterates in the nonmonotone Armijo reference
constexpr int kHalvings = 10;            // Armijo halvings before a larger shift
constexpr int kPolishHalvings = 6;       // polish: halvings of a step on |F|

class InteriorPoint {
 public:
  InteriorPoint(CompactionProblem &problem, const LevelSolverParameters &params) : p_(problem), prm_(params) {}
  ~InteriorPoint() { Destroy(); }
  PetscErrorCode Solve(double pressure, SolveReport *report);

 private:
  PetscErrorCode Attach();
  PetscErrorCode Destroy();
  PetscErrorCode Factor(double delta, bool *ok, bool *out_of_memory);
  PetscErrorCode Evaluate(Vec z, Vec F);       // residual, merit, gaps at z
  PetscErrorCode EnterInterior();              // eps and lambda so that the iterate is interior
  PetscErrorCode Errors(double *stationarity, double *complementarity);

  CompactionProblem &p_;
  const LevelSolverParameters &prm_;
  Vec z_ = nullptr, F_ = nullptr;
  Mat J_ = nullptr;
  KSP ksp_ = nullptr;
  Vec d_ = nullptr, dx_ = nullptr, y_ = nullptr, s_ = nullptr, zt_ = nullptr, Ft_ = nullptr;
  Vec gaps_ = nullptr, stiff_ = nullptr, target_ = nullptr, weight_ = nullptr, floor_ = nullptr, body_ = nullptr,
      contact_ = nullptr, work_ = nullptr;
  double delta_in_matrix_ = 0.0;
  int layouts_ = -1;
  MPI_Comm comm_ = MPI_COMM_NULL;
  PetscMPIInt size_ = 1;
  double mu_ = 0.0, eps_ = 0.0, reach_ = 0.0, scale_f_ = 1.0, scale_mu_ = 1.0;
};

PetscErrorCode InteriorPoint::Destroy() {
  PetscFunctionBeginUser;
  for (Vec *v : {&d_, &dx_, &y_, &s_, &zt_, &Ft_, &gaps_, &stiff_, &target_, &weight_, &floor_, &body_, &contact_, &work_})
    PetscCall(VecDestroy(v));
  PetscFunctionReturn(0);
}

PetscErrorCode InteriorPoint::Attach() {
  PetscFunctionBeginUser;
  PetscCall(p_.Layout(&z_, &F_, &J_, &ksp_));
  if (layouts_ == p_.LayoutsCreated() && d_) PetscFunctionReturn(0);
  layouts_ = p_.LayoutsCreated();
  PetscCall(Destroy());
  PetscCall(PetscObjectGetComm((PetscObject)z_, &comm_));
  PetscCallMPI(MPI_Comm_size(comm_, &size_));
  for (Vec *v : {&d_, &dx_, &y_, &s_, &zt_, &Ft_, &gaps_, &stiff_, &target_, &weight_, &floor_, &body_, &contact_, &work_})
    PetscCall(VecDuplicate(z_, v));
  PetscCall(p_.ShiftDiagonals(floor_, weight_));
  // Masks: body and wall rows (the primal unknowns x), normal-multiplier rows.
  PetscCall(VecCopy(weight_, body_));
  PetscCall(VecPointwiseMult(body_, body_, body_));
  PetscCall(VecSqrtAbs(body_));
  {
    PetscScalar *b;
    PetscInt n;
    PetscCall(VecGetLocalSize(body_, &n));
    PetscCall(VecGetArray(body_, &b));
    for (PetscInt i = 0; i < n; ++i) b[i] = b[i] > 0.0 ? 1.0 : 0.0;
    PetscCall(VecRestoreArray(body_, &b));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode InteriorPoint::Factor(double delta, bool *ok, bool *out_of_memory) {
  PetscFunctionBeginUser;
  PetscCall(FactorShifted(J_, ksp_, weight_, work_, delta, &delta_in_matrix_, ok, out_of_memory));
  PetscFunctionReturn(0);
}

PetscErrorCode InteriorPoint::Evaluate(Vec z, Vec F) {
  PetscFunctionBeginUser;
  PetscCall(p_.Residual(z, F));
  PetscCall(p_.BarrierRows(gaps_, stiff_, target_, contact_));
  PetscFunctionReturn(0);
}

// The contact rows of the layout (the candidates' normal multipliers) from
// the gaps of the last evaluation; then eps so that every candidate is
// interior, and lambda_c >= mu / (g_c + eps).
PetscErrorCode InteriorPoint::EnterInterior() {
  PetscScalar *za;
  const PetscScalar *ga, *ca;
  PetscInt n;
  PetscFunctionBeginUser;
  p_.SetBarrier(mu_, eps_, reach_);
  PetscCall(Evaluate(z_, F_));
  PetscCall(VecGetLocalSize(z_, &n));
  PetscCall(VecGetArrayRead(gaps_, &ga));
  PetscCall(VecGetArrayRead(contact_, &ca));
  double lowest = INFINITY;  // smallest g + eps
  for (PetscInt i = 0; i < n; ++i)
    if (ca[i] != 0.0) lowest = std::min(lowest, ga[i]);
  PetscCall(VecRestoreArrayRead(contact_, &ca));
  PetscCall(VecRestoreArrayRead(gaps_, &ga));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &lowest, 1, MPI_DOUBLE, MPI_MIN, comm_));
  if (lowest <= 0.0) {
    eps_ = -2.0 * (lowest - eps_);
    p_.SetBarrier(mu_, eps_, reach_);
    PetscCall(Evaluate(z_, F_));
  }
  PetscCall(VecGetArray(z_, &za));
  PetscCall(VecGetArrayRead(target_, &ga));
  PetscCall(VecGetArrayRead(contact_, &ca));
  for (PetscInt i = 0; i < n; ++i)
    if (ca[i] != 0.0) za[i] = std::max(za[i], std::min(ga[i], kLambdaCap * scale_f_));
  PetscCall(VecRestoreArrayRead(contact_, &ca));
  PetscCall(VecRestoreArrayRead(target_, &ga));
  PetscCall(VecRestoreArray(z_, &za));
  PetscCall(p_.AdoptState(z_));
  PetscCall(Evaluate(z_, F_));
  PetscFunctionReturn(0);
}

// Error of the barrier problem: the largest unbalanced force / (P <d>) and
// the largest |lambda (g + eps) - mu| / (P <d>^2).
PetscErrorCode InteriorPoint::Errors(double *stationarity, double *complementarity) {
  PetscFunctionBeginUser;
  PetscCall(p_.ForceResidual(F_, stationarity));
  *stationarity /= scale_f_;
  PetscCall(VecPointwiseMult(work_, F_, gaps_));
  PetscCall(VecNorm(work_, NORM_INFINITY, complementarity));
  *complementarity /= scale_mu_;
  PetscFunctionReturn(0);
}

PetscErrorCode InteriorPoint::Solve(double pressure, SolveReport *report) {
  PetscFunctionBeginUser;
  *report = SolveReport();
  PetscCheck(!p_.Frictional(), PETSC_COMM_WORLD, PETSC_ERR_USER_INPUT,
             "-level_solver interior solves frictionless levels only (-friction 0); frictional scenes need "
             "-level_solver anchored or newton");
  PetscCall(p_.BeginLoadStep(pressure));
  PetscCall(Attach());
  const double dmean = p_.MeanDiameter(), young = p_.Parameters().young;
  const double atol = 1e-11 * young * dmean;
  const double detect_every = 0.4 * p_.Parameters().contact_margin * dmean;
  const double max_move = 0.5 * p_.Parameters().contact_margin * dmean;
  scale_f_ = pressure * dmean;
  scale_mu_ = pressure * dmean * dmean;
  // Errors below the Newton tolerance (in P <d>) count as zero: at small P a
  // nearly free mode (the rotation of a frictionless deformable disk) would
  // otherwise keep the last barrier problem iterating on round-off.
  const double error_floor = atol / scale_f_;
  mu_ = kMuInit * scale_mu_;
  eps_ = kRelax * dmean;
  reach_ = kReach * p_.Parameters().contact_margin * dmean;
  PetscCall(EnterInterior());
  bool barrier = true, converged = false;
  double delta_last = 0.0, moved = 0.0, fnorm = INFINITY;
  double changed_margin = INFINITY, last_step = INFINITY;
  std::vector<char> active_before = p_.ActiveSet();
  int mu_updates = 0;
  std::vector<double> history;  // merits of the last iterates (nonmonotone line search)
  double merit_mu = -1.0;
  int merit_layout = -1;
  for (;;) {
    // Candidates: refreshed once bodies may have crossed the margin.
    if (moved > detect_every) {
      bool stale = false;
      PetscCall(p_.CandidatesStale(&stale));
      moved = 0.0;
      if (stale) {
        PetscCall(p_.RefreshCandidates());
        ++report->candidate_refreshes;
        PetscCall(Attach());
        if (barrier) {
          PetscCall(EnterInterior());
        } else {
          PetscCall(Evaluate(z_, F_));
        }
        active_before = p_.ActiveSet();
        changed_margin = INFINITY;
        continue;
      }
    }
    double stationarity = 0.0, complementarity = 0.0;
    if (barrier) {
      // Lower mu while the barrier problem is solved (several times in a row if need be).
      PetscCall(Errors(&stationarity, &complementarity));
      while (std::max(stationarity, complementarity) <= std::max(kKappaEps * mu_ / scale_mu_, error_floor) && mu_ > kMuEnd * scale_mu_) {
        const double m = mu_ / scale_mu_;
        mu_ = std::max(kMuEnd, std::min(kKappaMu * m, std::pow(m, kThetaMu))) * scale_mu_;
        ++mu_updates;
        p_.SetBarrier(mu_, eps_, reach_);
        PetscCall(Evaluate(z_, F_));
        PetscCall(Errors(&stationarity, &complementarity));
      }
      if (mu_ <= kMuEnd * scale_mu_ && std::max(stationarity, complementarity) <= std::max(kKappaEps * kMuEnd, error_floor)) {
        // The active-set polish: exact NCP rows from here.
        barrier = false;
        p_.SetBarrier(0.0, 0.0, 0.0);
        PetscCall(Evaluate(z_, F_));
        active_before = p_.ActiveSet();
        changed_margin = INFINITY;
        if (prm_.monitor) PetscCall(PetscPrintf(comm_, "    interior: polish after %" PetscInt_FMT " iterations\n", report->newton_its));
      }
    }
    if (!barrier) {
      PetscCall(VecNorm(F_, NORM_2, &fnorm));
      const bool stable = changed_margin <= kDegenerateSwitch * atol || last_step <= 1e-12 * dmean;
      if (std::isfinite(fnorm) && fnorm <= atol && stable) {
        bool stale = false;
        PetscCall(p_.CandidatesStale(&stale));
        if (!stale) {
          converged = true;
          break;
        }
        moved = INFINITY;
        continue;
      }
    }
    if (report->newton_its >= prm_.max_its) {
      report->reason = SNES_DIVERGED_MAX_IT;
      break;
    }
    // One linearization per iteration; the shift grows until the step has
    // positive curvature and the merit decreases along it.
    PetscCall(p_.NewtonMatrix(z_, J_));
    delta_in_matrix_ = 0.0;
    ++report->newton_its;
    // Nonmonotone Armijo reference (Grippo, Lampariello and Lucidi 1986): the
    // largest merit of the last kMeritMemory iterates of this barrier problem.
    const double merit_now = p_.Merit();  // of the last residual evaluation, at z_
    if (merit_mu != mu_ || merit_layout != layouts_) history.clear(), merit_mu = mu_, merit_layout = layouts_;
    history.push_back(merit_now);
    if (static_cast<int>(history.size()) > kMeritMemory) history.erase(history.begin());
    const double merit0 = *std::max_element(history.begin(), history.end());
    double delta = 0.0;
    bool accepted = false;
    for (;;) {
      bool ok = false, out_of_memory = false;
      PetscCall(Factor(delta, &ok, &out_of_memory));
      ++report->factorizations;
      if (out_of_memory && p_.GrowFactorWorkspace()) {
        // MUMPS out of workspace (INFOG(1) = -9): a new layout with a larger
        // one, the same linearization, the same shift.
        PetscCall(PetscInfo(nullptr, "MUMPS workspace too small (INFOG(1) = -9): enlarged\n"));
        PetscCall(Attach());
        PetscCall(Evaluate(z_, F_));
        PetscCall(p_.NewtonMatrix(z_, J_));
        delta_in_matrix_ = 0.0;
        continue;
      }
      if (ok) {
        KSPConvergedReason kreason;
        PetscCall(KSPSolve(ksp_, F_, d_));
        PetscCall(KSPGetConvergedReason(ksp_, &kreason));
        ok = kreason > 0;
      }
      double curvature = 0.0, alpha_p = 1.0, full_move = 0.0;
      struct {
        int where = -1;
        double gap = 0, lambda = 0, dgap = 0, k = 0;
      } limit;
      if (ok) {
        PetscCall(VecScale(d_, -1.0));
        PetscCall(VecPointwiseMult(dx_, d_, body_));
        PetscCall(VecNorm(dx_, NORM_INFINITY, &full_move));
        if (barrier) {
          // Curvature d^T (W + delta D) d + sum_c k_c (A_c d)^2 with y = J dx:
          // its contact rows are k_c A_c d.
          PetscCall(MatMult(J_, dx_, y_));
          PetscCall(VecDot(dx_, y_, &curvature));
          const PetscScalar *ya, *za, *ga, *ka;
          PetscInt n;
          PetscCall(VecGetLocalSize(y_, &n));
          PetscCall(VecGetArrayRead(y_, &ya));
          PetscCall(VecGetArrayRead(z_, &za));
          PetscCall(VecGetArrayRead(gaps_, &ga));
          PetscCall(VecGetArrayRead(stiff_, &ka));
          double local[2] = {0.0, 1.0};  // contact curvature, fraction to the boundary of the gaps
          PetscInt lo;
          PetscCall(VecGetOwnershipRange(y_, &lo, nullptr));
          for (PetscInt i = 0; i < n; ++i) {
            if (ka[i] > 0.0) {
              const double dg = ya[i] / ka[i];  // A_c d
              local[0] += ya[i] * dg;
              if (dg < 0.0 && kTau * ga[i] / -dg < local[1]) {
                local[1] = kTau * ga[i] / -dg;
                limit.where = static_cast<int>(lo + i);
                limit.gap = ga[i], limit.lambda = za[i], limit.dgap = dg, limit.k = ka[i];
              }
            }
          }
          PetscCall(VecRestoreArrayRead(stiff_, &ka));
          PetscCall(VecRestoreArrayRead(gaps_, &ga));
          PetscCall(VecRestoreArrayRead(z_, &za));
          PetscCall(VecRestoreArrayRead(y_, &ya));
          local[1] = -local[1];
          PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &local[0], 1, MPI_DOUBLE, MPI_SUM, comm_));
          PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &local[1], 1, MPI_DOUBLE, MPI_MAX, comm_));
          curvature += local[0];
          if (prm_.monitor && size_ == 1 && limit.where >= 0 && -local[1] < 1.0)
            PetscCall(PetscPrintf(comm_, "      gap fraction %.2e from %s (row %d): s %.2e lambda %.2e k %.2e A d %.2e\n", -local[1],
                                  p_.DescribeUnknown(p_.NaturalIndex(limit.where)).c_str(), limit.where, limit.gap,
                                  limit.lambda, limit.k, limit.dgap));
          alpha_p = -local[1];
          ok = curvature > 0.0;
        } else {
          PetscCall(p_.ContactStepFraction(d_, &alpha_p));
        }
        // A step that moves a body further than the barrier's candidates can
        // guard is a Levenberg-Marquardt step too short in shift (rattlers
        // and floppy modes have tiny curvature): a larger shift, not a shorter step.
        if (barrier && full_move > max_move) ok = false;
        if (!barrier && full_move > max_move) alpha_p = std::min(alpha_p, max_move / full_move);
      }
      if (ok) {
        // Backtracking: Armijo on phi_mu (barrier; slope = -curvature) or on |F| (polish).
        const double slope = -curvature;
        const int halvings = barrier ? kHalvings : kPolishHalvings;
        for (int bt = 0; bt <= halvings && !accepted; ++bt) {
          const double a = alpha_p * std::ldexp(1.0, -bt), al = a;
          // s = a d on the primal rows, al d on the contact rows.
          PetscCall(VecPointwiseMult(work_, d_, contact_));
          PetscCall(VecAXPBY(s_, a, 0.0, d_));
          PetscCall(VecAXPY(s_, al - a, work_));
          PetscCall(p_.RotatedUpdate(z_, s_, zt_));
          PetscCall(p_.Residual(zt_, Ft_));
          double trial_norm = 0.0;
          if (barrier) {
            const double merit = p_.Merit();
            accepted = std::isfinite(merit) && !p_.Inverted() && merit <= merit0 + 1e-4 * a * slope;
            if (prm_.monitor)
              PetscCall(PetscPrintf(comm_,
                                    "    interior %3" PetscInt_FMT "  mu %.1e  error %.1e %.1e  merit %+.10e -> %+.10e  slope %.1e  "
                                    "delta %.1e  alpha %.2e %.2e  move %.1e  %s\n",
                                    report->newton_its, mu_ / scale_mu_, stationarity, complementarity, merit0 / scale_mu_,
                                    merit / scale_mu_, slope / scale_mu_, delta / young, a, al, a * full_move / dmean,
                                    accepted ? "accepted" : "rejected"));
          } else {
            PetscCall(VecNorm(Ft_, NORM_2, &trial_norm));
            accepted = std::isfinite(trial_norm) && !p_.Inverted() && trial_norm <= (1.0 - 1e-4 * a) * fnorm;
            if (prm_.monitor)
              PetscCall(PetscPrintf(comm_, "    polish   %3" PetscInt_FMT "  |F| %.3e -> %.3e  alpha %.2e  %s\n",
                                    report->newton_its, fnorm, trial_norm, a, accepted ? "accepted" : "rejected"));
          }
          if (accepted) last_step = a * full_move, moved += a * full_move;
        }
      }
      if (accepted) break;
      // A larger shift (IPOPT: from a third of the last one, x100 the first time, then x8).
      if (delta == 0.0)
        delta = delta_last > 0.0 ? std::max(kDeltaInit * young * 1e-6, delta_last / 3.0) : kDeltaInit * young;
      else
        delta *= delta_last > 0.0 ? 8.0 : 100.0;
      if (delta > kDeltaMax * young) break;
    }
    if (!accepted) {
      report->reason = SNES_DIVERGED_LINE_SEARCH;
      break;
    }
    delta_last = delta;
    PetscCall(VecCopy(zt_, z_));
    PetscCall(VecCopy(Ft_, F_));
    PetscCall(p_.BarrierRows(gaps_, stiff_, target_, contact_));
    PetscCall(p_.AdoptState(z_));
    PetscCall(p_.ChangedStateMargin(active_before, &changed_margin));
    active_before = p_.ActiveSet();
    if (barrier) {
      // IPOPT's safeguard: lambda within a factor kSigma of the barrier force mu psi.
      PetscScalar *za;
      const PetscScalar *ta, *ca;
      PetscInt n;
      int clipped = 0;
      PetscCall(VecGetLocalSize(z_, &n));
      PetscCall(VecGetArray(z_, &za));
      PetscCall(VecGetArrayRead(target_, &ta));
      PetscCall(VecGetArrayRead(contact_, &ca));
      for (PetscInt i = 0; i < n; ++i) {
        if (ca[i] == 0.0) continue;
        if (za[i] <= 0.0) za[i] = ta[i], clipped = 1;  // a multiplier the step turned negative: its barrier force
        const double lo = ta[i] / kSigma, hi = kSigma * ta[i];
        if (za[i] < lo || za[i] > hi) za[i] = std::clamp(za[i], lo, hi), clipped = 1;
      }
      PetscCall(VecRestoreArrayRead(contact_, &ca));
      PetscCall(VecRestoreArrayRead(target_, &ta));
      PetscCall(VecRestoreArray(z_, &za));
      PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &clipped, 1, MPI_INT, MPI_MAX, comm_));
      if (clipped) {
        PetscCall(p_.AdoptState(z_));
        PetscCall(Evaluate(z_, F_));
      }
    }
  }
  report->residual = fnorm;
  PetscCall(p_.ForceResidual(F_, &report->force_residual));
  report->inner_solves = 1 + mu_updates;
  if (converged) report->reason = SNES_CONVERGED_FNORM_ABS;
  PetscCall(p_.EndLoadStep(converged, report));
  PetscFunctionReturn(0);
}

}  // namespace

PetscErrorCode SolveLevelInterior(CompactionProblem &problem, const LevelSolverParameters &params, double pressure,
                                  SolveReport *report) {
  PetscFunctionBeginUser;
  InteriorPoint solver(problem, params);
  PetscCall(solver.Solve(pressure, report));
  PetscFunctionReturn(0);
}

}  // namespace deformix

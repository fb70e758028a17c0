#include "deformix/level_solver.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdint>
#include <deque>
#include <initializer_list>
#include <vector>

#include "deformix/observables.hpp"

namespace deformix {

PetscErrorCode LevelSolverParameters::SetFromOptions(MPI_Comm comm) {
  PetscInt choice = static_cast<PetscInt>(strategy);
  const char *const names[] = {"newton", "anchored", "hybrid", "auto"};  // LevelStrategy order
  PetscInt merit_choice = static_cast<PetscInt>(merit);
  const char *const merits[] = {"residual", "energy"};  // LevelMerit order
  PetscFunctionBeginUser;
  PetscOptionsBegin(comm, nullptr, "Level solver", "deformix");
  PetscCall(PetscOptionsEList("-level_solver",
                              "equilibrium of a load step: newton (pseudo-transient continuation with one semismooth "
                              "Newton step per pseudo-time step, each step accepted by the residual of its proximal "
                              "subproblem) or anchored (pseudo-transient continuation, each pseudo-time step solved "
                              "until its residual has dropped 100-fold: -ptc_*) or hybrid (a newton attempt of -level_attempt_its linearizations "
                              "from the tangent predictor, then anchored from where it stopped) or auto (newton with the "
                              "energy merit on levels without friction, hybrid on frictional levels)",
                              "", names, 4, names[choice], &choice, nullptr));
  PetscCall(PetscOptionsEList("-level_merit",
                              "newton and hybrid's attempt (auto: its frictional levels): what accepts a step: residual (|G| of the proximal "
                              "subproblem decreases) or energy (|G| decreases, or the energy decreases: the enthalpy "
                              "plus an exact l1 penalty on penetration beyond 1e-3 <d> and Tresca friction with the normal forces "
                              "lagged at the iterate; the shift then grows until the step has positive curvature)",
                              "", merits, 2, merits[merit_choice], &merit_choice, nullptr));
  PetscCall(PetscOptionsInt("-level_attempt_its", "hybrid: most linearizations of the newton attempt before anchored takes over (sooner once |F|_inf has not halved over 10)", "",
                            attempt_its, &attempt_its, nullptr));
  PetscCall(PetscOptionsInt("-level_max_its", "newton (and auto's frictionless levels): linearizations per load step before the step is halved (compact's settling steps, which are not halved: 5 times as many before hybrid takes over)", "", max_its,
                            &max_its, nullptr));
  PetscCall(PetscOptionsReal("-level_initial_move",
                             "newton: trust radius at the start of a load step (largest move of a body under the "
                             "largest unbalanced force, in mean diameters)",
                             "", initial_move, &initial_move, nullptr));
  PetscCall(PetscOptionsBool("-level_ldlt",
                             "newton (auto's levels without friction): factor the Newton matrix, made symmetric by row "
                             "operations that keep its solution, by MUMPS LDL^T (false: LU)",
                             "", ldlt, &ldlt, nullptr));
  PetscCall(PetscOptionsBool("-level_monitor",
                             "newton: one line per trial step (phi of the iterate, |F|, merit |G| before and after, largest force, trust "
                             "radius, shift, step fraction and length, accepted or rejected, closed and sliding contacts, "
                             "residual by block) and the level criterion's balances",
                             "", monitor, &monitor, nullptr));
  PetscCall(PetscOptionsBool("-level_body_criterion",
                             "anchored: the paper's level criterion also per body (net force and torque of every body "
                             "below -level_force_rtol P <d> and P <d>^2, P_sigma/P within -level_force_rtol of 1); false: per node only, which accepts bodies "
                             "with net forces up to 1e-2 P <d> (P_sigma/P off by up to 2e-3)",
                             "", body_criterion, &body_criterion, nullptr));
  PetscCall(PetscOptionsBool("-ptc_monitor",
                             "anchored: one line per pseudo-time step (residual by block, largest unbalanced force "
                             "and where it acts, phi, move), once the largest force passes the parts of the level criterion that do not, "
                             "every failed inner solve, and the step that begins the end game",
                             "", ptc_monitor, &ptc_monitor, nullptr));
  PetscCall(PetscOptionsBool("-newton_monitor",
                             "anchored: one line per Newton iteration (|R|, closed and sliding contacts, rho_a, "
                             "largest update and its unknown)",
                             "", newton_monitor, &newton_monitor, nullptr));
  PetscCall(PetscOptionsBool("-newton_monitor_contacts",
                             "anchored: every contact whose state changed in the last Newton iteration (to see an "
                             "active-set cycle)",
                             "", newton_monitor_contacts, &newton_monitor_contacts, nullptr));
  PetscOptionsEnd();
  strategy = static_cast<LevelStrategy>(choice);
  merit = static_cast<LevelMerit>(merit_choice);
  PetscCheck(attempt_its >= 1, comm, PETSC_ERR_USER_INPUT, "-level_attempt_its %" PetscInt_FMT " must be >= 1",
             attempt_its);
  PetscCheck(max_its >= 1, comm, PETSC_ERR_USER_INPUT, "-level_max_its %" PetscInt_FMT " must be >= 1", max_its);
  PetscCheck(initial_move > 0.0 && std::isfinite(initial_move), comm, PETSC_ERR_USER_INPUT,
             "-level_initial_move %g must be positive", initial_move);
  PetscFunctionReturn(0);
}

namespace {

// Work vectors of a strategy, duplicated from the layout's z (a new set with
// every new candidate layout) and destroyed together.
PetscErrorCode DuplicateAll(Vec z, std::initializer_list<Vec *> vecs) {
  PetscFunctionBeginUser;
  for (Vec *v : vecs) PetscCall(VecDuplicate(z, v));
  PetscFunctionReturn(0);
}
PetscErrorCode DestroyAll(std::initializer_list<Vec *> vecs) {
  PetscFunctionBeginUser;
  for (Vec *v : vecs) PetscCall(VecDestroy(v));
  PetscFunctionReturn(0);
}

// A heartbeat for long load steps, one line per -progress_interval seconds
// after a pseudo-time step (a newton iteration, or an inner solve of
// anchored): rank 0's clock decides, so the ranks agree on whether to print.
class Progress {
 public:
  explicit Progress(CompactionProblem &problem) : p_(problem) { PetscTime(&t_start_), t_last_ = t_start_; }
  // Whether a line is due now (collective); a caller that adds parts to the
  // line computes them only then.
  PetscErrorCode Due(MPI_Comm comm, bool *due) {
    PetscFunctionBeginUser;
    *due = false;
    if (p_.Parameters().progress_interval < 0.0) PetscFunctionReturn(0);
    PetscLogDouble now;
    PetscCall(PetscTime(&now));
    int is_due = now - t_last_ >= p_.Parameters().progress_interval;
    PetscCallMPI(MPI_Bcast(&is_due, 1, MPI_INT, 0, comm));
    if (is_due) t_last_ = now;
    *due = is_due != 0;
    PetscFunctionReturn(0);
  }
  // The line (after Due said so).
  PetscErrorCode Print(MPI_Comm comm, double pressure, int step, PetscInt its, double force, const char *extra = "") {
    const ProblemParameters &pp = p_.Parameters();
    PetscFunctionBeginUser;
    PetscCall(PetscPrintf(comm,
                          "    ... P/E %.4g: pseudo-time step %d, %" PetscInt_FMT " Newton its, |F|_inf %.2e P<d>"
                          " (level criterion %.0e), phi %.6f%s, %.0f s in this sub-step\n",
                          pressure / pp.young, step, its, force / (std::max(pressure, 1e-300) * p_.MeanDiameter()),
                          pp.level_force_rtol, p_.PackingFraction(), extra, t_last_ - t_start_));
    PetscFunctionReturn(0);
  }
  PetscErrorCode Step(MPI_Comm comm, double pressure, int step, PetscInt its, double force, const char *extra = "") {
    bool due;
    PetscFunctionBeginUser;
    PetscCall(Due(comm, &due));
    if (due) PetscCall(Print(comm, pressure, step, its, force, extra));
    PetscFunctionReturn(0);
  }

 private:
  CompactionProblem &p_;
  PetscLogDouble t_start_, t_last_;
};

constexpr double kMaxMove = 0.5;        // trust radius cap, in <d>
constexpr int kMaxRejections = 12;      // rejected trial steps in a row before the load step fails
constexpr int kBacktracks = 4;          // step fractions 1, 1/2, 1/4, 1/8 tried before a larger shift
constexpr double kAttemptOverlap = 0.1; // hybrid: deepest overlap of the newton attempt's predicted state, in <d>
// hybrid: deepest overlap (by the contact laws' gaps) of the attempt's last
// iterate that anchored goes on from, in <d>. Ten times the predictors'
// limit: the attempt can end near balance with a contact a few 1e-3 <d>
// deep (1500 disks at P/E 0.02: |F|_inf 8e-5 P <d>, 2.1e-3 <d>), which
// anchored's first pseudo-time steps (0.02 <d> each) close, where starting
// again from the undone load step repeats the level's whole compaction in
// damped steps (docs/level-solver-measurements.md, "Measured: the overlap
// limit of the attempt's hand-over").
constexpr double kHandoverOverlap = 1e-2;
// hybrid: the attempt hands over to anchored once its largest force |F|_inf
// has not halved over its last kAttemptWindow linearizations. Levels that
// deform the packing converge in the attempt or leave it far down; levels
// that rearrange it stall there at |F|_inf of 1e-2 to 1e-1 P <d>, and
// anchored does better from the sooner hand-over (docs/level-solver-
// measurements.md, "Measured: the attempt's length level by level").
constexpr size_t kAttemptWindow = 10;
// The energy merit accepts a trial below the largest merit of this many
// iterates (the iterate's and its predecessors'). Newton steps that roll
// deformable disks along their contacts lose their accuracy within a
// twentieth of the boundary node spacing (a step of 3e-3 <d> can raise the
// residual tenfold with an exact Jacobian), so a monotone test halves the
// step again and again where a full step raises the energy slightly and the
// next one lowers it for good (docs/level-solver-measurements.md, "Measured: the
// nonmonotone energy test").
constexpr size_t kNonmonotoneWindow = 4;

// anchored's inexact pseudo-time steps: an inner solve ends once it has
// reduced |G| by this factor (or at the exact tolerance). Measured on the
// frictional scenes against exact inner solves (docs/level-solver-measurements.md,
// "Measured: inexact pseudo-time steps"): 0.01 and 0.1 both take fewer
// iterations, 0.01 the fewest.
constexpr double kInnerForcing = 1e-2;
// anchored's move m grows by this factor after an easy pseudo-time step and
// is divided by 4 after a failed one; the fraction of failed steps settles
// near ln g / (ln g + ln 4), each failure costing ptc_stall_its iterations
// and a retry. Measured on the same scenes (docs/level-solver-measurements.md): 1.25 and
// 1.5 took 3396 and 3414 iterations against 3631 with 2.
constexpr double kMoveGrowth = 1.25;
// Once the largest force of a pseudo-time step passes the level's force
// tolerance, m grows by this factor after every step. What keeps such a
// level going is then the net force of bodies whose nodal forces all pass,
// the virial and the contact rows, and the anchor term itself holds them:
// an inner solve brings |G| = |F + rho_a D (z - z_a)| down a
// hundredfold while |F| only halves, since rho_a = |F|_inf / (m <d>)
// falls no faster than |F|_inf (1500 disks, P/E 1e-3: the largest body
// force from 1e-2 to 4e-4 P <d> over five steps of four iterations, with
// |F|_inf below 1e-4 P <d> and m at 1e-3 to 2e-3 <d>). Growing m faster than
// the residual falls lets rho_a fall faster than |F|, as in the switched
// evolution relaxation of Psi-tc. It grows no further than half the least
// m at which an inner solve has failed since the force passed: grown into
// a step that switches many contacts, the step fails, m is quartered and
// would grow into the same failure again (1500 disks, P/E 0.05: 82
// iterations with five such failures against 74 with the limit;
// docs/level-solver-measurements.md, "Measured: the move grown once the
// largest force passes").
constexpr double kSettledGrowth = 4.0;
// anchored gives a sub-step up (the load controller cuts it) once its force
// residual exceeds this multiple of the larger of its value at the start of
// the sub-step and P <d>. Each pseudo-time step only has to reduce the
// residual of its own subproblem, G = F + rho_a D (z - z_a), so under a
// large rho_a (move m of 1e-7 <d>) a run of accepted steps can let F grow
// by a few per cent per step: measured on n50_k0.2_mu0.2 at P/E 0.5, one
// sub-step went on for 900 pseudo-time steps (5400 Newton iterations) with
// |F|_inf growing from 2 to 5e6 E <d> until -ptc_max_steps
// (docs/level-solver-measurements.md, "Measured: the 50-disk campaign with auto").
constexpr double kDivergedForce = 100.0;

// |P_sigma / P - 1| of the problem's state (the same on every rank: the
// state is replicated). The virial identity P_sigma = P holds exactly at
// equilibrium; off it the contact stress misses P by about
// |Sum_b x_b . F_b| / (2 V P) (observables.hpp), a sum over all bodies, so
// every body's net force below tol P <d> still left it 1.5e-4 off on the
// 1500-disk paper scene (P/E 0.01; docs/level-solver-measurements.md, "Measured:
// the 1500-disk paper scene"). The per-body level criterion asks it below tol too.
double VirialDefect(const CompactionProblem &p, double pressure) {
  return std::abs(MeanContactStress(p) / pressure - 1.0);
}

// Numeric factorization of J + shift D in ksp (newton shifts the body and
// wall rows): J holds J + in_matrix D on entry (D = weight, the problem's
// ShiftDiagonals), the difference is added (work: scratch); *ok,
// *out_of_memory and *reason as FactorOnEveryRank's.
PetscErrorCode FactorShifted(Mat J, KSP ksp, Vec weight, Vec work, double shift, double *in_matrix, bool *ok,
                             bool *out_of_memory, PCFailedReason *reason) {
  PetscFunctionBeginUser;
  if (shift != *in_matrix) {
    PetscCall(VecAXPBY(work, shift - *in_matrix, 0.0, weight));
    PetscCall(MatDiagonalSet(J, work, ADD_VALUES));
    *in_matrix = shift;
  }
  PetscCall(KSPSetOperators(ksp, J, J));
  PetscCall(FactorOnEveryRank(ksp, ok, out_of_memory, reason));
  PetscFunctionReturn(0);
}

// The iteration of one load step (level_solver.hpp, "newton").
class MeritNewton {
 public:
  MeritNewton(CompactionProblem &problem, const LevelSolverParameters &params, Progress &progress)
      : p_(problem), prm_(params), progress_(progress) {}
  ~MeritNewton() { Destroy(); }
  // With left_open, the attempt of hybrid: the tangent predictor with
  // overlaps up to kAttemptOverlap, at most prm_.attempt_its linearizations;
  // on failure the load step is left open at the last accepted iterate
  // (*left_open) when anchored can start from it (no overlap deeper than
  // kHandoverOverlap), else undone.
  PetscErrorCode Solve(double pressure, SolveReport *report, bool *left_open = nullptr);

 private:
  PetscErrorCode Attach();            // the problem's layout objects, and our work vectors for them
  PetscErrorCode Destroy();
  PetscErrorCode Evaluate(Vec z, Vec F, double *norm, double *force, bool *inverted);
  // (J + floor + rho D) in ksp
  PetscErrorCode Factor(KSP ksp, double rho, bool *ok, bool *out_of_memory, PCFailedReason *reason);

  CompactionProblem &p_;
  const LevelSolverParameters &prm_;
  Progress &progress_;
  Vec z_ = nullptr, F_ = nullptr;     // the problem's (layout) vectors
  Mat J_ = nullptr;
  KSP ksp_ = nullptr;
  Vec za_ = nullptr, G_ = nullptr, Gt_ = nullptr;  // anchor, proximal residual at the iterate and at a trial point
  Vec d_ = nullptr, s_ = nullptr, zt_ = nullptr, Ft_ = nullptr, floor_ = nullptr, weight_ = nullptr, sqrt_weight_ = nullptr,
      work_ = nullptr;
  Vec body_mask_ = nullptr;  // 1 on the body and wall rows (the shifted ones), 0 elsewhere
  KSP ksp_ldlt_ = nullptr;   // the problem's LDL^T of the symmetric form (prm_.ldlt)
  Vec rhs_ = nullptr;        // the symmetric form's right-hand side
  double rho_in_matrix_ = 0.0;
  int layouts_ = -1;
  MPI_Comm comm_ = MPI_COMM_NULL;
};

PetscErrorCode MeritNewton::Destroy() {
  PetscFunctionBeginUser;
  PetscCall(DestroyAll({&d_, &za_, &G_, &Gt_, &s_, &sqrt_weight_, &zt_, &Ft_, &floor_, &weight_, &work_, &body_mask_, &rhs_}));
  PetscFunctionReturn(0);
}

PetscErrorCode MeritNewton::Attach() {
  PetscFunctionBeginUser;
  PetscCall(p_.Layout(&z_, &F_, &J_, &ksp_));  // packs the state into z_
  if (layouts_ == p_.LayoutsCreated() && d_) PetscFunctionReturn(0);
  layouts_ = p_.LayoutsCreated();
  PetscCall(Destroy());
  PetscCall(PetscObjectGetComm((PetscObject)z_, &comm_));
  PetscCall(DuplicateAll(z_, {&d_, &za_, &G_, &Gt_, &s_, &sqrt_weight_, &zt_, &Ft_, &floor_, &weight_, &work_, &body_mask_, &rhs_}));
  ksp_ldlt_ = nullptr;
  if (prm_.ldlt) PetscCall(p_.SymmetricKsp(&ksp_ldlt_));
  PetscCall(p_.ShiftDiagonals(floor_, weight_));
  {
    PetscScalar *m;
    const PetscScalar *w;
    PetscInt n;
    PetscCall(VecGetLocalSize(weight_, &n));
    PetscCall(VecGetArrayRead(weight_, &w));
    PetscCall(VecGetArray(body_mask_, &m));
    for (PetscInt i = 0; i < n; ++i) m[i] = w[i] > 0.0 ? 1.0 : 0.0;
    PetscCall(VecRestoreArray(body_mask_, &m));
    PetscCall(VecRestoreArrayRead(weight_, &w));
  }
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

PetscErrorCode MeritNewton::Factor(KSP ksp, double rho, bool *ok, bool *out_of_memory, PCFailedReason *reason) {
  PetscFunctionBeginUser;
  PetscCall(FactorShifted(J_, ksp, weight_, work_, rho, &rho_in_matrix_, ok, out_of_memory, reason));
  PetscFunctionReturn(0);
}

PetscErrorCode MeritNewton::Solve(double pressure, SolveReport *report, bool *left_open) {
  PetscFunctionBeginUser;
  const bool attempt = left_open != nullptr;
  if (attempt) *left_open = false;
  *report = SolveReport();
  if (attempt) PetscCall(p_.BeginLoadStep(pressure, LoadPredictor::Tangent, kAttemptOverlap));
  else PetscCall(p_.BeginLoadStep(pressure));
  const PetscInt max_its = attempt ? prm_.attempt_its : prm_.max_its;
  PetscCall(Attach());
  const double dmean = p_.MeanDiameter();
  const double atol = 1e-11 * p_.Parameters().young * dmean, row_tol = ContactRowTolerance(p_, pressure);
  const double detect_every = 0.4 * p_.Parameters().contact_margin * dmean;
  const double relaxed_tol = p_.Parameters().level_force_rtol, phi_tol = p_.Parameters().level_phi_rtol;
  double fnorm, force, phi = 0.0, phi_before = 0.0;
  bool inverted;
  // The iterate z: its residual F(z), and phi for the level criterion.
  const auto adopt = [&]() -> PetscErrorCode {
    PetscFunctionBeginUser;
    PetscCall(p_.AdoptState(z_));
    phi_before = phi;
    if (relaxed_tol > 0.0 || prm_.monitor) phi = p_.PackingFraction();
    PetscFunctionReturn(0);
  };
  const auto at_iterate = [&]() -> PetscErrorCode {
    PetscFunctionBeginUser;
    PetscCall(adopt());
    PetscCall(Evaluate(z_, F_, &fnorm, &force, &inverted));
    PetscFunctionReturn(0);
  };
  // An accepted trial point becomes the iterate: its residual is the last
  // one evaluated (the problem's contact data are those of the trial), so
  // at_iterate's evaluation is taken over instead of repeated.
  double trial_norm = INFINITY, trial_force = INFINITY;
  bool trial_inverted = false;
  const auto trial_to_iterate = [&]() -> PetscErrorCode {
    PetscFunctionBeginUser;
    PetscCall(VecCopy(zt_, z_));
    PetscCall(VecCopy(Ft_, F_));
    PetscCall(adopt());
    fnorm = trial_norm, force = trial_force, inverted = trial_inverted;
    PetscFunctionReturn(0);
  };
  double move = prm_.initial_move;  // trust radius m, in <d>
  double rho = 0.0;
  const bool energy = prm_.merit == LevelMerit::Energy;
  // Energy merit psi = H + nu x penetration + dissipation (CompactionProblem::
  // ContactPenalty): its parts at the last residual evaluation, and at the
  // iterate (with the Tresca bounds lagged there); nu is chosen per step.
  struct EnergyParts {
    double enthalpy = 0.0, penetration = 0.0, dissipation = 0.0;
  } at_z, trial_parts;
  double nu = 0.0;
  const auto energy_parts = [&](EnergyParts *e) -> PetscErrorCode {
    PetscFunctionBeginUser;
    PetscCall(p_.ContactPenalty(&e->penetration, &e->dissipation));
    e->enthalpy = p_.Merit();
    PetscFunctionReturn(0);
  };
  const auto psi_of = [&](const EnergyParts &e) { return e.enthalpy + nu * e.penetration + e.dissipation; };
  std::deque<EnergyParts> recent;  // the energy merit's parts at the last accepted iterates
  // A new anchor at the iterate (the last residual evaluation): G = F there,
  // rho from its largest force, the energy merit's Tresca bounds lagged there.
  const auto anchor = [&]() -> PetscErrorCode {
    PetscFunctionBeginUser;
    PetscCall(VecCopy(z_, za_));
    PetscCall(VecCopy(F_, G_));
    rho = force / (move * dmean);
    if (energy) {
      PetscCall(p_.LagContactWeights());
      PetscCall(energy_parts(&at_z));
    }
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
  std::vector<double> attempt_forces;  // hybrid's attempt: |F|_inf at each linearization
  for (;;) {
    // Converged: small residual with a stable contact state, and every
    // contact that can touch is a candidate (checked whenever a body may
    // have moved 0.4 x the candidate margin since the last check; a pair
    // that overlaps or approaches, CandidatesStale, makes a refresh).
    const bool small = std::isfinite(fnorm) && fnorm <= atol;
    const bool stable = report->newton_its == 0 || changed_margin <= kDegenerateSwitch * atol || last_step <= 1e-12 * dmean;
    if (moved > detect_every || small) {
      bool stale = false, approaching = false;
      PetscCall(p_.CandidatesStale(&stale, &approaching));  // the state of the iterate (adopted by at_iterate)
      moved = 0.0;
      if (stale || approaching) {
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
    // nodal force below tol P <d>, every contact row exact (below the
    // Newton tolerance, as anchored's criterion has it), P_sigma within tol
    // of P, the contact states stable and phi settled over the last step.
    if (relaxed_tol > 0.0 && report->newton_its > 0 && stable && std::abs(phi - phi_before) <= phi_tol * phi) {
      CompactionProblem::Balance b;
      PetscCall(p_.BodyBalance(F_, &b));
      const double f_tol = relaxed_tol * pressure * dmean;
      const bool balanced = b.body_force <= f_tol && b.body_torque <= f_tol * dmean && b.node_force <= f_tol && b.contact_row <= row_tol;
      const double virial = balanced || prm_.monitor ? VirialDefect(p_, pressure) : INFINITY;  // it walks every contact
      if (prm_.monitor)
        PetscCall(PetscPrintf(comm_, "    level criterion: body force %.2e torque %.2e node %.2e contact rows %.2e (tolerance %.2e, contact rows %.2e), |P_sigma/P - 1| %.1e, phi change %.1e\n",
                              b.body_force, b.body_torque / dmean, b.node_force, b.contact_row, f_tol, row_tol, virial, std::abs(phi - phi_before) / phi));
      if (balanced && virial <= relaxed_tol) {
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
    if (report->newton_its >= max_its) {
      report->reason = SNES_DIVERGED_MAX_IT;
      break;
    }
    if (attempt) {  // one entry per linearization (a candidate refresh passes here again)
      if (attempt_forces.size() <= static_cast<size_t>(report->newton_its)) attempt_forces.push_back(force);
      const size_t n = attempt_forces.size();
      if (n > kAttemptWindow && force > 0.5 * attempt_forces[n - 1 - kAttemptWindow]) {
        report->reason = SNES_DIVERGED_MAX_IT;
        break;
      }
    }
    // One linearization per iteration. The energy is not defined where an
    // element is inverted (a start state handed over folded): there the
    // step is tested on |G| alone, which does not need descent of the energy.
    const bool energy_step = energy && !inverted;
    // The symmetric form (LDL^T) where it applies, else LU.
    bool symmetric = false;
    const auto linearize = [&]() -> PetscErrorCode {
      PetscFunctionBeginUser;
      PetscCall(p_.NewtonMatrix(z_, J_));
      rho_in_matrix_ = 0.0;
      symmetric = false;
      if (ksp_ldlt_) PetscCall(p_.SymmetrizeNewtonMatrix(J_, &symmetric));
      PetscFunctionReturn(0);
    };
    PetscCall(linearize());
    ++report->newton_its;
    bool accepted = false;
    while (!accepted) {
      bool ok = false, out_of_memory = false;
      PCFailedReason pc_reason = PC_NOERROR;
      KSP ksp = symmetric ? ksp_ldlt_ : ksp_;
      PetscCall(Factor(ksp, rho, &ok, &out_of_memory, &pc_reason));
      ++report->factorizations;
      if (ok) {
        KSPConvergedReason kreason;
        if (symmetric) PetscCall(p_.SymmetricRhs(G_, rhs_));
        PetscCall(KSPSolve(ksp, symmetric ? rhs_ : G_, d_));
        PetscCall(KSPGetConvergedReason(ksp, &kreason));
        ok = kreason > 0;
      }
      bool negative_curvature = false;
      if (ok && energy_step) {
        // The energy merit needs a descent direction: with the contact rows
        // of d holding, the energy's slope along d is -d_x^T (K + rho D) d_x
        // (d_x its body and wall part, K the Hessian of the Lagrangian), so
        // the shift has to make that curvature positive: on rolling and
        // rearranging configurations K is indefinite. Tested on the step
        // itself (one product with the assembled matrix, which MUMPS's LU
        // cannot give as an inertia).
        PetscCall(VecPointwiseMult(work_, d_, body_mask_));
        PetscCall(MatMult(J_, work_, Ft_));
        double curvature;
        PetscCall(VecDot(work_, Ft_, &curvature));
        negative_curvature = !(curvature > 0.0);
        ok = !negative_curvature;
        if (negative_curvature && prm_.monitor)
          PetscCall(PetscPrintf(comm_, "    newton %3" PetscInt_FMT "  curvature %.2e <= 0 at rho %.1e: a larger shift\n",
                                report->newton_its, curvature, rho));
      }
      if (!ok && !negative_curvature) {
        // A failed factorization: MUMPS out of workspace gets a larger one
        // (a new layout); anything else (a singular matrix) a larger shift.
        if (out_of_memory && p_.GrowFactorWorkspace()) {
          PetscCall(PetscInfo(nullptr, "MUMPS workspace too small (INFOG(1) = -9): enlarged\n"));
          PetscCall(Attach());
          PetscCall(at_iterate());
          PetscCall(anchor());
          gnorm = fnorm;
          PetscCall(linearize());
          continue;
        }
        if (prm_.monitor)
          PetscCall(PetscPrintf(comm_, "    newton %3" PetscInt_FMT "  factorization failed (%s) at rho %.1e\n",
                                report->newton_its, PCFailedReasons[pc_reason], rho));
      }
      if (ok) {
        PetscCall(VecScale(d_, -1.0));  // (J + rho D) d = -G
        // Step fraction: open and touching contacts not driven deep into penetration, and
        // no body moving (or turning, times its radius) more than m <d> in
        // one step: the shift alone does not bound a mode whose force is far
        // below |F|_inf. Hybrid's attempt takes no contact cut: it starts
        // from the tangent predictor with overlaps up to kAttemptOverlap,
        // and with the cut some contact of a 1500-disk packing asks for its
        // floor of a tenth at every iteration, so that |F| falls by a tenth
        // per iteration and the attempt ends overlapping
        // (docs/level-solver-measurements.md, "Measured: the attempt handed
        // over"). Its end state is checked for overlap anyway.
        double alpha0 = 1.0, full_move;
        if (!attempt) PetscCall(p_.ContactStepFraction(d_, &alpha0));
        PetscCall(VecPointwiseMult(work_, d_, sqrt_weight_));
        PetscCall(VecNorm(work_, NORM_INFINITY, &full_move));
        if (full_move > move * dmean) alpha0 = std::min(alpha0, move * dmean / full_move);
        if (energy_step) {
          // The exact penalty needs nu above every normal force, those of
          // the step's end point included (the l1 merit of SQP).
          double largest_now, largest_next;
          PetscCall(p_.LargestNormalMultiplier(z_, &largest_now));
          PetscCall(VecWAXPY(work_, 1.0, z_, d_));
          PetscCall(p_.LargestNormalMultiplier(work_, &largest_next));
          nu = 2.0 * std::max(largest_now, largest_next) + pressure * dmean;
        }
        // Backtracking (Armijo on |G| along its Newton direction d) before a
        // larger shift, which costs a factorization.
        for (int bt = 0; bt < kBacktracks && !accepted; ++bt) {
          const double alpha = alpha0 * std::ldexp(1.0, -bt);
          double trial_gnorm;
          PetscCall(VecAXPBY(s_, alpha, 0.0, d_));
          PetscCall(p_.RotatedUpdate(z_, s_, zt_));
          PetscCall(Evaluate(zt_, Ft_, &trial_norm, &trial_force, &trial_inverted));
          PetscCall(proximal(zt_, Ft_, Gt_, &trial_gnorm));
          if (!std::isfinite(trial_norm)) trial_gnorm = INFINITY;
          const bool residual_decreased = trial_gnorm <= (1.0 - 1e-4 * alpha) * gnorm;
          double trial_psi = 0.0, psi = 0.0;
          if (energy_step) {
            // Either merit may accept: the energy where it decreases beyond
            // round-off (its sum over elements carries about 1e-16 of each
            // term), or |G|. The energy accepts the steps of a rearrangement
            // that switch contacts (|G| jumps there), |G| those that cross a
            // kink of the energy (an open contact closing, a contact slipping
            // against its lagged Tresca bound), which Newton's next
            // linearization resolves.
            PetscCall(energy_parts(&trial_parts));
            psi = psi_of(at_z), trial_psi = psi_of(trial_parts);
            // Nonmonotone (Grippo, Lampariello and Lucidi): the trial is
            // compared with the largest merit of the last kNonmonotoneWindow
            // iterates (the iterate's included), each with this step's nu.
            // With friction their dissipations were lagged at different
            // iterates, so the comparison is looser there (auto takes the
            // energy merit on frictionless levels only).
            double reference = psi;
            for (const EnergyParts &e : recent) reference = std::max(reference, psi_of(e));
            const double change = trial_psi - reference, band = 1e-13 * std::abs(psi);
            accepted = std::isfinite(trial_gnorm) && std::isfinite(trial_psi) && (change < -band || residual_decreased);
          } else {
            accepted = residual_decreased;
          }
          double step;
          PetscCall(VecPointwiseMult(work_, s_, sqrt_weight_));
          PetscCall(VecNorm(work_, NORM_INFINITY, &step));
          if (prm_.monitor) {
            double blocks[5];
            PetscCall(p_.ResidualBlocks(Ft_, blocks));
            int closed = 0, sliding = 0, closing = 0, opening = 0;
            const std::vector<char> &now = p_.ActiveSet();
            for (char a : now) closed += a == kClosed, sliding += a == kSliding;
            if (now.size() == active_before.size())
              for (size_t c = 0; c < now.size(); ++c)
                closing += active_before[c] == kOpen && now[c] != kOpen, opening += active_before[c] != kOpen && now[c] == kOpen;
            double moves[3];
            PetscCall(p_.StepMoves(z_, s_, moves));
            PetscCall(PetscPrintf(comm_,
                                  "    newton %3" PetscInt_FMT "  phi %.8f  |F| %.3e  |G| %.3e -> %.3e (trial |F| %.3e)  |F|_inf %.2e  "
                                  "m %.1e rho %.1e  alpha %.3f |s| %.1e (translation %.1e rotation %.1e deformation %.1e)  %s  "
                                  "closed %d (+%d -%d) sliding %d  "
                                  "(trial rows: body %.1e wall %.1e gauge %.1e normal %.1e tangential %.1e)",
                                  report->newton_its, phi, fnorm, gnorm, trial_gnorm, trial_norm, force, move, rho, alpha, step,
                                  moves[0], moves[1], moves[2], accepted ? "accepted" : "rejected", closed, closing, opening,
                                  sliding, blocks[0], blocks[1], blocks[2], blocks[3], blocks[4]));
            if (energy_step)
              PetscCall(PetscPrintf(comm_, "  energy change %+.3e of %.6e (enthalpy %+.3e, nu %.2e x penetration %+.3e, dissipation %+.3e)",
                                    trial_psi - psi, psi, trial_parts.enthalpy - at_z.enthalpy, nu,
                                    trial_parts.penetration - at_z.penetration, trial_parts.dissipation - at_z.dissipation));
            PetscCall(PetscPrintf(comm_, "\n"));
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
        PetscCall(p_.ChangedStateMargin(active_before, &changed_margin));
        active_before = p_.ActiveSet();
        PetscCall(trial_to_iterate());
        // Pseudo-transient continuation with one Newton step per pseudo-time
        // step: the anchor moves to every accepted iterate, and the trust
        // radius grows after every accepted step, fourfold, except in
        // compact's settlings with the energy merit: there no further than
        // four times the largest body move of the step just taken (a trust
        // region's rule: the radius grows where the steps reach it). In a
        // packing near jamming the Newton step at a large radius moves
        // nearly floppy bodies by 0.1-1 <d> while the line search accepts a
        // few 1e-3 <d>; grown fourfold, the radius made almost every
        // iteration begin with rejected trials and a refactorization. On the
        // levels the rule is not taken (mixed on frictionless levels, more
        // iterations in hybrid's attempts, some levels ending at the level
        // criterion instead of exact balance). Measurements:
        // docs/level-solver-measurements.md, "Measured: the trust radius
        // grown by the step taken".
        move = prm_.settling && energy ? std::min({4.0 * move, kMaxMove, std::max(move, 4.0 * last_step / dmean)})
                                       : std::min(4.0 * move, kMaxMove);
        PetscCall(anchor());
        if (energy) {
          recent.push_back(at_z);
          if (recent.size() > kNonmonotoneWindow) recent.pop_front();
        }
        gnorm = fnorm;
        if (!prm_.monitor) {
          char radius[64];
          PetscCall(PetscSNPrintf(radius, sizeof radius, ", trust radius %.1e <d>", move));
          PetscCall(progress_.Step(comm_, pressure, static_cast<int>(report->newton_its), report->newton_its, force, radius));
        }
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
  if (attempt && !converged) {
    PetscCall(p_.AdoptState(z_));
    if (p_.PredictionAdmissible(kHandoverOverlap)) {
      *left_open = true;
      PetscFunctionReturn(0);
    }
  }
  PetscCall(p_.EndLoadStep(converged, report));
  PetscFunctionReturn(0);
}

// ---------------------------------------------------------------------------
// anchored: pseudo-transient continuation, each pseudo-time step solved by
// SNESNEWTONLS (inexactly, kInnerForcing; level_solver.hpp). The SNES callbacks below
// work on this small context; the problem provides the residual (with the
// anchor term of SetAnchor), the Newton matrix and the contact states.
class AnchoredContinuation {
 public:
  AnchoredContinuation(CompactionProblem &problem, const LevelSolverParameters &params, Progress &progress)
      : p_(problem), prm_(params), progress_(progress) {}
  ~AnchoredContinuation() { Destroy(); }
  // After hybrid's newton attempt (its report): the counts go on from it,
  // and with begun the load step is still open at its last iterate.
  PetscErrorCode Solve(double pressure, SolveReport *report, const SolveReport *attempt = nullptr, bool begun = false);

 private:
  PetscErrorCode Attach();  // the problem's layout, and an SNES for it
  PetscErrorCode Destroy();
  static PetscErrorCode Function(SNES snes, Vec z, Vec F, void *ctx);
  static PetscErrorCode Jacobian(SNES, Vec z, Mat J, Mat, void *ctx);
  static PetscErrorCode Converged(SNES snes, PetscInt it, PetscReal, PetscReal snorm, PetscReal fnorm,
                                  SNESConvergedReason *reason, void *ctx);
  static PetscErrorCode Monitor(SNES snes, PetscInt it, PetscReal fnorm, void *ctx);
  static PetscErrorCode DetectCycle(SNESLineSearch, Vec, Vec, PetscBool *changed, void *ctx);
  // Contacts back in their state of two iterates ago while |R| (fnorm now)
  // has not halved over those two iterations: a local active-set cycle.
  int ContactsBack(const std::vector<char> &now, double fnorm) const;
  static PetscErrorCode Backtrack(SNESLineSearch ls, Vec X, Vec Y, Vec W, PetscBool *changed_Y, PetscBool *changed_W,
                                  void *ctx);

  CompactionProblem &p_;
  const LevelSolverParameters &prm_;
  Progress &progress_;
  SNES snes_ = nullptr;
  Vec z_ = nullptr, F_ = nullptr;  // the problem's (layout) vectors
  Mat J_ = nullptr;
  KSP ksp_ = nullptr;
  Vec work_ = nullptr, step_ = nullptr;
  int layouts_ = -1;
  MPI_Comm comm_ = MPI_COMM_NULL;
  std::vector<char> checked_;               // contact states at the last convergence test
  std::vector<char> monitor_states_;        // contact states at the last monitored iterate
  std::vector<std::uint64_t> history_;      // hashes of the contact states of the last Newton iterates (DetectCycle)
  bool backtrack_ = false;                  // DetectCycle found an active-set cycle: Backtrack this step
  std::deque<std::pair<std::vector<char>, double>> recent_;  // contact states and |R| of the last two Newton iterates (DetectCycle)
  double fnorm0_ = 0.0;
  double row_tol_ = 0.0;  // ContactRowTolerance of the sub-step (Solve), for Converged
  bool stalled_ = false;  // the last inner solve ended at ptc_stall_its with |G| decreased (Converged)
  Vec best_ = nullptr;      // the inner solve's iterate of least |G| so far (Converged)
  double best_norm_ = 0.0;
  bool take_best_ = false;  // the inner solve ends at best_ rather than at its last iterate
};

PetscErrorCode AnchoredContinuation::Destroy() {
  PetscFunctionBeginUser;
  PetscCall(SNESDestroy(&snes_));
  PetscCall(DestroyAll({&work_, &step_, &best_}));
  PetscFunctionReturn(0);
}

PetscErrorCode AnchoredContinuation::Attach() {
  PetscFunctionBeginUser;
  PetscCall(p_.Layout(&z_, &F_, &J_, &ksp_));  // packs the state into z_
  if (layouts_ == p_.LayoutsCreated() && snes_) PetscFunctionReturn(0);
  layouts_ = p_.LayoutsCreated();
  PetscCall(Destroy());
  PetscCall(PetscObjectGetComm((PetscObject)z_, &comm_));
  PetscCall(DuplicateAll(z_, {&work_, &step_}));
  const ProblemParameters &pp = p_.Parameters();
  PetscCall(SNESCreate(comm_, &snes_));
  PetscCall(SNESSetType(snes_, SNESNEWTONLS));
  PetscCall(SNESSetKSP(snes_, ksp_));
  if (!p_.OptionsPrefix().empty()) PetscCall(SNESSetOptionsPrefix(snes_, p_.OptionsPrefix().c_str()));
  PetscCall(SNESSetFunction(snes_, F_, Function, this));
  PetscCall(SNESSetJacobian(snes_, J_, J_, Jacobian, this));
  PetscCall(SNESSetConvergenceTest(snes_, Converged, this, nullptr));
  // Forces are per unit thickness, in units of E * d; the tolerance is absolute in those units.
  // With pseudo-transient continuation a stalled inner solve (active-set or
  // slip-direction cycling) is better cut short: the outer loop then retries
  // with more damping.
  const PetscInt max_it = pp.ptc_move > 0.0 ? 15 : 50;
  PetscCall(SNESSetTolerances(snes_, 1e-11 * pp.young * p_.MeanDiameter(), 1e-30, 0.0, max_it, -1));
  SNESLineSearch ls;
  PetscCall(SNESGetLineSearch(snes_, &ls));
  PetscCall(SNESLineSearchSetType(ls, prm_.line_search));
  PetscCall(SNESSetFromOptions(snes_));
  if (prm_.newton_monitor || prm_.newton_monitor_contacts) PetscCall(SNESMonitorSet(snes_, Monitor, this, nullptr));
  PetscCall(SNESGetLineSearch(snes_, &ls));
  PetscCall(SNESLineSearchSetPreCheck(ls, DetectCycle, this));
  PetscCall(SNESLineSearchSetPostCheck(ls, Backtrack, this));
  PetscFunctionReturn(0);
}

PetscErrorCode AnchoredContinuation::Function(SNES snes, Vec z, Vec F, void *ctx) {
  auto *a = static_cast<AnchoredContinuation *>(ctx);
  PetscFunctionBeginUser;
  PetscCall(a->p_.Residual(z, F));
  if (a->p_.Inverted() && snes) PetscCall(SNESSetFunctionDomainError(snes));
  PetscFunctionReturn(0);
}

PetscErrorCode AnchoredContinuation::Jacobian(SNES, Vec z, Mat J, Mat, void *ctx) {
  auto *a = static_cast<AnchoredContinuation *>(ctx);
  PetscFunctionBeginUser;
  PetscCall(a->p_.NewtonMatrix(z, J));
  PetscFunctionReturn(0);
}

// Converged only when the residual is small and the contact states are stable.
PetscErrorCode AnchoredContinuation::Converged(SNES snes, PetscInt it, PetscReal, PetscReal snorm, PetscReal fnorm,
                                               SNESConvergedReason *reason, void *ctx) {
  auto *a = static_cast<AnchoredContinuation *>(ctx);
  PetscReal atol, rtol, stol;
  PetscInt maxit, maxf;
  PetscFunctionBeginUser;
  PetscCall(SNESGetTolerances(snes, &atol, &rtol, &stol, &maxit, &maxf));
  // How far from its switch is the most decided of the contacts that changed
  // state since the last test (0: none changed). The contact states are
  // reduced over the ranks by the residual, so every rank agrees.
  const std::vector<char> &now = a->p_.ActiveSet();
  const bool changed_any = now != a->checked_;
  // Only plain Newton's stop (no anchor, below) reads the margin; inside
  // pseudo-time steps the walk over the contacts and its reduction are
  // skipped (AnchorWeight is the same on every rank).
  double changed_margin = 0.0;
  if (!(a->p_.AnchorWeight() > 0.0)) PetscCall(a->p_.ChangedStateMargin(a->checked_, &changed_margin));
  a->checked_ = now;
  *reason = SNES_CONVERGED_ITERATING;
  if (it == 0) a->fnorm0_ = fnorm, a->best_norm_ = fnorm, a->take_best_ = false;
  if (it > 0 && fnorm < a->best_norm_ && a->p_.AnchorWeight() > 0.0) {  // for the stall rule below
    Vec x;
    PetscCall(SNESGetSolution(snes, &x));
    if (!a->best_) PetscCall(VecDuplicate(x, &a->best_));
    PetscCall(VecCopy(x, a->best_));
    a->best_norm_ = fnorm;
  }
  // Inexact pseudo-time steps: the path in pseudo-time is not the answer,
  // only its end point is, so inside pseudo-transient continuation an inner
  // solve ends once it has reduced |G| by kInnerForcing (inexact Newton on
  // each pseudo-time step; Kelley and Keyes's Psi-tc takes a single Newton
  // step). The level is still accepted only with exact contact rows and the
  // level criterion (Solve); a state short of them is the anchor of the
  // next pseudo-time step. SNES's -snes_rtol, if larger, applies instead.
  const PetscReal forcing = a->p_.AnchorWeight() > 0.0 ? kInnerForcing : 0.0;
  // A local active-set cycle (DetectCycle) at an iterate that is a static
  // equilibrium of its contacts: contacts whose force sits on the Coulomb
  // cone flip stick <-> slip at every iteration; the sliding iterate has the
  // force on the cone and a slip since the anchor that points along the
  // force (not a Coulomb increment, so this pseudo-time step has no solution
  // near it), and the sticking one the slip back at 0 with the force beyond
  // the cone. Measured from the sliding iterate itself, its contact rows are
  // exact: the inner solve ends there and the next pseudo-time step starts
  // from it. Backtracked instead, each pseudo-time step halves the slip and
  // the level creeps to the same state (docs/level-solver-measurements.md,
  // "Measured: a pseudo-time step ended at a static state of a cycle").
  bool end_here = false;
  if (it > 0 && a->p_.AnchorWeight() > 0.0 && a->ContactsBack(now, fnorm) > 0) {
    Vec x;
    PetscCall(SNESGetSolution(snes, &x));
    PetscCall(a->p_.ResidualFromHere(x, a->work_));
    PetscReal here;
    PetscCall(VecNorm(a->work_, NORM_2, &here));
    CompactionProblem::Balance b;
    PetscCall(a->p_.BodyBalance(a->work_, &b));
    end_here = b.contact_row <= a->row_tol_ && here < fnorm;
    if (end_here && a->prm_.ptc_monitor)
      PetscCall(PetscPrintf(a->comm_, "    local cycle at newton %" PetscInt_FMT ": contact rows exact with the slip from here (|R| %.3e), the pseudo-time step ends here\n",
                            it, (double)here));
    if (!end_here) PetscCall(a->p_.Residual(x, a->work_));  // the contact states of this iterate, for DetectCycle
  }
  if (PetscIsInfOrNanReal(fnorm)) {
    *reason = SNES_DIVERGED_FNORM_NAN;
  } else if (fnorm <= std::max<PetscReal>(atol, std::max<PetscReal>(rtol, forcing) * a->fnorm0_) &&
             (forcing > 0.0 || it == 0 || !changed_any || snorm <= 1e-12 * a->p_.MeanDiameter() ||
              changed_margin <= kDegenerateSwitch * atol)) {
    // Inside pseudo-transient continuation (forcing > 0) an inner solve that
    // meets its forcing ends there even while some contacts still switch:
    // the contact states at the end of a pseudo-time step are not the
    // level's (the level criterion tests the exact contact rows of the
    // anchor). Held to stable states as well, such solves ran into the
    // stall limit with |G| 1e-3 to 1e-8 of its start and counted as
    // stalled, which does not grow m: on a 1500-disk level m stayed at
    // 0.02 <d> for nine pseudo-time steps, |F|_inf falling 0.5-0.8 per step
    // (docs/level-solver-measurements.md, "Measured: pseudo-time steps
    // ended at their forcing while contacts switch").
    // Outside it (plain semismooth Newton, deal.II step-42's rule):
    // A contact state may still flip at a converged point when the contact
    // is degenerate (lambda_n = g = 0 to round-off, e.g. a rattler resting
    // on a neighbour, or |lambda_t| = mu lambda_n with no slip): both
    // linearizations hold there, and the residual, which uses the exact NCP
    // functions, is already zero. Such flips are accepted when every contact
    // that changed is within kDegenerateSwitch atol of its switch. Two-pass
    // deformable contact makes them common: the two passes of a conforming
    // contact share its force in an indeterminate way, and each Newton step
    // moves the share, flipping weakly loaded nodes (lambda_n ~ 1e-10 E<d>)
    // between open, stick and slip forever.
    *reason = SNES_CONVERGED_FNORM_ABS;
  } else if (end_here) {
    a->stalled_ = true;
    a->take_best_ = false;
    *reason = SNES_CONVERGED_ITS;
  } else if (it >= maxit) {
    *reason = SNES_DIVERGED_MAX_IT;
  } else if (a->p_.AnchorWeight() > 0.0 && it >= a->p_.Parameters().ptc_stall_its) {
    // Inside pseudo-transient continuation an inner solve still short of its
    // forcing after ptc_stall_its (4) iterations (they converge in 2-7 at
    // 20-100 disks) is cycling somewhere (contact states or slip directions
    // of a few contacts; at 1500 disks among 21 000 of them) and is cut
    // short. If |G| has decreased, its iterate is an inexact pseudo-time
    // step, which does not grow the move; only one that has not decreased
    // |G| at all has failed, and the outer loop retries with more damping.
    // Failing every solve that had not halved |G| cost 300 against 213
    // Newton iterations on a 1500-disk level (docs/level-solver-measurements.md,
    // "Measured: a stalled inner solve kept as a pseudo-time step"). With
    // the cut at 4 iterations rather than 6, six 1500-disk levels restarted
    // from the same states took 11 % fewer iterations and the small scenes
    // as many; a whole curve, one sample of a path that differs from run to
    // run on 2 ranks, does not show it ("Measured: the stall limit at 1500
    // disks").
    // Semismooth Newton is not monotone: an inner solve whose last iterate
    // is above |G| at the anchor may have passed below it on the way (a
    // switch of many contact states raising |G| for a step). Then its best
    // iterate is the inexact pseudo-time step, as for a solve that ended
    // below the anchor's |G|, instead of a retry with rho_a four times
    // larger (docs/level-solver-measurements.md, "Measured: the best
    // iterate of a stalled inner solve").
    a->stalled_ = a->best_norm_ < a->fnorm0_;
    a->take_best_ = a->stalled_ && fnorm >= a->fnorm0_;
    *reason = a->stalled_ ? SNES_CONVERGED_ITS : SNES_DIVERGED_DTOL;
  }
  PetscFunctionReturn(0);
}

// -newton_monitor: one line per Newton iteration; -newton_monitor_contacts:
// every contact whose state changed in the last iteration (the contacts of
// an active-set cycle), with its multipliers, gap and slip at the new iterate.
PetscErrorCode AnchoredContinuation::Monitor(SNES snes, PetscInt it, PetscReal fnorm, void *ctx) {
  auto *a = static_cast<AnchoredContinuation *>(ctx);
  int closed = 0, sliding = 0;
  PetscFunctionBeginUser;
  for (char s : a->p_.ActiveSet()) closed += s == kClosed, sliding += s == kSliding;
  // Largest entry of the last Newton update and the kind of unknown it belongs to.
  char where[96] = "";
  if (it > 0) {
    Vec dz;
    PetscInt imax, imin;
    PetscReal dmax, dmin;
    PetscCall(SNESGetSolutionUpdate(snes, &dz));
    PetscCall(VecMax(dz, &imax, &dmax));
    PetscCall(VecMin(dz, &imin, &dmin));
    if (-dmin > dmax) dmax = -dmin, imax = imin;
    const PetscInt natural = a->p_.NaturalIndex(imax);
    PetscCall(PetscSNPrintf(where, sizeof(where), "  max|dz| %.2e (%s)", (double)dmax,
                            a->p_.DescribeUnknown(natural).c_str()));
  }
  PetscCall(PetscPrintf(a->comm_, "    newton %2" PetscInt_FMT "  |R| %.3e  closed contacts %d  sliding %d  rho_a %.1e%s\n",
                        it, (double)fnorm, closed, sliding, a->p_.AnchorWeight(), where));
  if (a->prm_.newton_monitor_contacts) {
    PetscCall(a->p_.PrintChangedContacts(a->monitor_states_));
    a->monitor_states_ = a->p_.ActiveSet();
  }
  PetscFunctionReturn(0);
}

int AnchoredContinuation::ContactsBack(const std::vector<char> &now, double fnorm) const {
  if (recent_.size() != 2 || !(fnorm > 0.5 * recent_[0].second) || recent_[0].first.size() != now.size() ||
      recent_[1].first.size() != now.size())
    return 0;
  int n = 0;
  for (size_t c = 0; c < now.size(); ++c) n += now[c] == recent_[0].first[c] && now[c] != recent_[1].first[c];
  return n;
}

// Line-search pre-check, which leaves the Newton step as it is (full steps
// inside a pseudo-time step: a cap on the move of a body per step and the
// contact step fraction, measured together, took as many iterations as
// neither; docs/level-solver-measurements.md, "Measured: the knobs of
// anchored"). Active-set cycles: semismooth Newton can alternate between
// contact states (typically stick <-> slip of a contact on the edge of its
// cone), each linearization sending the iterate into the other's region.
// When the state at the current iterate repeats one of two or three
// iterations ago (and is not the last one), the post-check (Backtrack)
// shortens the step, which lands between the two regions and breaks the
// cycle. States are compared on all ranks, as one hash of every contact's
// state, and contact by contact: in a large packing other contacts switch
// at the same time, so the hash never repeats in a local cycle, in which
// some contacts return to their state of two iterates ago while |R| does
// not fall (1500 disks: 15-30 contacts around a rigid disk turning back
// and forth by 4e-3 rad at every iteration, |R| alternating between two
// values for 60 pseudo-time steps; docs/level-solver-measurements.md,
// "Measured: local active-set cycles in anchored"). The norm guard keeps
// healthy iterations, which halve |R| in two, out of the backtracking.
PetscErrorCode AnchoredContinuation::DetectCycle(SNESLineSearch ls, Vec, Vec, PetscBool *changed, void *ctx) {
  auto *a = static_cast<AnchoredContinuation *>(ctx);
  PetscFunctionBeginUser;
  *changed = PETSC_FALSE;
  std::uint64_t h = 1469598103934665603ull;  // FNV-1a of the contact states
  for (char s : a->p_.ActiveSet()) h = (h ^ static_cast<unsigned char>(s)) * 1099511628211ull;
  std::vector<std::uint64_t> &hist = a->history_;
  bool cycle = false;
  for (size_t k = 2; k <= 3 && k <= hist.size(); ++k)
    if (hist[hist.size() - k] == h && hist.back() != h) cycle = true;
  hist.push_back(h);
  if (hist.size() > 4) hist.erase(hist.begin());
  // A local cycle: some contacts back in the state they had two iterates
  // ago while |R| has not halved over those two iterations.
  PetscReal xnorm, fnorm, ynorm;
  PetscCall(SNESLineSearchGetNorms(ls, &xnorm, &fnorm, &ynorm));
  const std::vector<char> &now = a->p_.ActiveSet();
  std::deque<std::pair<std::vector<char>, double>> &recent = a->recent_;
  if (!cycle) {
    const int n = a->ContactsBack(now, fnorm);
    cycle = n > 0;
    if (cycle && a->prm_.ptc_monitor)
      PetscCall(PetscPrintf(a->comm_, "    local cycle: %d contacts back in their state of two iterates ago, |R| %.3e against %.3e then\n",
                            n, (double)fnorm, recent[0].second));
  }
  recent.emplace_back(now, fnorm);
  if (recent.size() > 2) recent.pop_front();
  a->backtrack_ = cycle;  // the post-check (Backtrack) makes this step decrease |R|
  PetscFunctionReturn(0);
}

// Line-search post-check. The trial point W = X - lambda Y becomes
// RotatedUpdate(X, -lambda Y): each deformable body's mean rotation is applied
// as a finite rotation (a linearized rotation of a nearly incompressible disk
// changes its area, see RotatedUpdate). After an active-set cycle was
// detected (DetectCycle), the step is backtracked, alpha = 1, 1/2, ..., 1/64,
// until |R| decreases (Armijo with the Newton slope -|R|^2, sigma = 1e-4); if
// no fraction decreases it, the one with the smallest |R| is taken. Plain
// semismooth Newton is non-monotone (a change of the active set may raise
// |R| for one step), so this monotone safeguard is only used on cycles,
// which it breaks: a cycle returns |R| to a value it had before.
PetscErrorCode AnchoredContinuation::Backtrack(SNESLineSearch ls, Vec X, Vec Y, Vec W, PetscBool *changed_Y,
                                               PetscBool *changed_W, void *ctx) {
  auto *a = static_cast<AnchoredContinuation *>(ctx);
  PetscReal xnorm, fnorm, ynorm, lambda;
  PetscFunctionBeginUser;
  *changed_Y = PETSC_FALSE;
  PetscCall(SNESLineSearchGetLambda(ls, &lambda));  // W = X - lambda Y (1 for the basic line search)
  const auto trial = [&](double alpha) -> PetscErrorCode {
    PetscFunctionBeginUser;
    PetscCall(VecAXPBY(a->step_, -alpha * lambda, 0.0, Y));
    PetscCall(a->p_.RotatedUpdate(X, a->step_, W));
    PetscFunctionReturn(0);
  };
  PetscCall(trial(1.0));
  *changed_W = PETSC_TRUE;
  if (!a->backtrack_) PetscFunctionReturn(0);
  a->backtrack_ = false;
  PetscCall(SNESLineSearchGetNorms(ls, &xnorm, &fnorm, &ynorm));
  double best_alpha = 1.0, best_norm = INFINITY;
  for (double alpha = 1.0; alpha >= 1.0 / 64; alpha *= 0.5) {
    PetscCall(trial(alpha));
    PetscCall(a->p_.Residual(W, a->work_));
    PetscReal norm;
    PetscCall(VecNorm(a->work_, NORM_2, &norm));
    if (a->p_.Inverted()) norm = INFINITY;
    if (norm < best_norm) best_norm = norm, best_alpha = alpha;
    if (norm <= (1.0 - 1e-4 * alpha) * fnorm) break;
  }
  PetscCall(trial(best_alpha));
  if (best_alpha < 1.0) {
    PetscCall(VecScale(Y, best_alpha));
    *changed_Y = PETSC_TRUE;
  }
  PetscFunctionReturn(0);
}

PetscErrorCode AnchoredContinuation::Solve(double pressure, SolveReport *report, const SolveReport *attempt, bool begun) {
  PetscFunctionBeginUser;
  *report = SolveReport();
  if (attempt) {  // its counts go on from the attempt's (one pseudo-time step per newton iteration)
    report->newton_its = attempt->newton_its;
    report->inner_solves = attempt->inner_solves;
    report->candidate_refreshes = attempt->candidate_refreshes;
  }
  const int steps_before = static_cast<int>(report->newton_its);
  if (!begun) PetscCall(p_.BeginLoadStep(pressure));
  // Pseudo-transient continuation (-ptc_move > 0). The equations get the term
  // rho_a D (z - z_a), z_a the state at the start of the inner solve: each
  // SNES solve is an implicit step of an overdamped dynamics in which
  // rattlers, free rotations and sliding particles move a bounded distance.
  // rho_a = max(|F|_inf, |F_b|) / (m <d>), F the force residual without the
  // term and |F_b| the largest net force on a body at the last test: the
  // anchor holds a deformable disk's rigid motion as a rigid disk's
  // (CompactionProblem::Assemble), so an unbalanced force, on one unknown
  // or on a body as a whole, moves a body by at most about m <d> per step (so the
  // linearized contact geometry stays valid), and rho_a vanishes with the
  // residual, so the steps grow to plain Newton steps near equilibrium
  // (switched evolution relaxation). m grows by kMoveGrowth after an easy inner solve
  // (by kSettledGrowth after every step once the largest force passes) and
  // is divided by 4 after a failed one. The level is converged when the
  // residual WITHOUT the term is below tolerance with a stable contact state,
  // so the regularization has vanished at the accepted equilibrium.
  // Without -ptc_move the sub-step is one SNES solve (plain semismooth
  // Newton), repeated after a candidate refresh.
  const ProblemParameters &pp = p_.Parameters();
  const double dmean = p_.MeanDiameter(), row_tol = ContactRowTolerance(p_, pressure);
  row_tol_ = row_tol;
  const double rho_floor = pp.prox_eta * pp.young;
  const bool ptc = pp.ptc_move > 0.0;
  double move = pp.ptc_move;
  const int max_outer = static_cast<int>(pp.ptc_max_steps);
  int failures = 0;  // failed inner solves in a row
  double rho_retry = 0.0;  // the least rho_a of a retry from the same anchor
  double rho_end_game = 0.0;  // the least rho_a once the end game has begun
  double phi_last = -1.0;
  double force_residual = 0.0;
  double body_force = 0.0;  // the largest net force on a body at the last equilibrium test
  bool force_passed = false;                // the largest force has passed at some step of this sub-step
  double settled_failed_move = INFINITY;  // the least m of an inner solve that failed after that
  if (ptc) {
    PetscCall(Attach());
    p_.SetAnchor(0.0);
    PetscCall(p_.Residual(z_, F_));
    PetscCall(p_.ForceResidual(F_, &force_residual));
  }
  const double diverged_force = kDivergedForce * std::max(force_residual, pressure * dmean);
  for (int outer = 0, refresh = 0;; ++outer) {
    PetscCall(Attach());  // packs the state into z_
    // Friction is incremental per pseudo-time step: the slip is measured from
    // the anchor, so a contact that slid in one step can stick in the next
    // (Coulomb along the pseudo-time path, as the paper's contact dynamics
    // has it per time step). Measured from the start of the level, a
    // contact that has slid must stay on its cone until it slides back, and
    // a body whose contacts all slid has no stiffness but rho's against
    // turning or sliding on ("Measured: friction per pseudo-time step").
    if (ptc) p_.MarkStepStart();
    // -ptc_anchor_forces: the contact forces too (SetAnchor; docs/level-solver-
    // measurements.md, "Measured: the contact forces in the anchor").
    p_.SetAnchor(ptc ? std::max({rho_floor, rho_retry, rho_end_game, std::max(force_residual, body_force) / (move * dmean)}) : 0.0,
                pp.ptc_anchor_forces);
    checked_.clear();
    history_.clear();
    recent_.clear();
    stalled_ = false;
    PetscCall(SNESSolve(snes_, nullptr, z_));
    if (take_best_) {  // and the problem's contact data those of the best iterate
      PetscCall(VecCopy(best_, z_));
      PetscCall(p_.Residual(z_, F_));
    }
    const double rho_solved = p_.AnchorWeight();
    ++report->inner_solves;
    PetscInt its;
    PetscReal atol, rtol, stol;
    PetscInt maxit, maxf;
    PetscCall(SNESGetTolerances(snes_, &atol, &rtol, &stol, &maxit, &maxf));
    PetscCall(SNESGetIterationNumber(snes_, &its));
    PetscCall(SNESGetConvergedReason(snes_, &report->reason));
    report->newton_its += its;
    PetscCall(SNESGetFunctionNorm(snes_, &report->residual));
    if (report->reason == SNES_DIVERGED_LINEAR_SOLVE) {
      // MUMPS ran out of its workspace: enlarge it and redo the same step.
      PC pc;
      PCFailedReason pc_reason;
      PetscCall(KSPGetPC(ksp_, &pc));
      PetscCall(PCGetFailedReason(pc, &pc_reason));
      int out_of_memory = pc_reason == PC_FACTOR_OUTMEMORY;
      PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &out_of_memory, 1, MPI_INT, MPI_MAX, comm_));
      if (out_of_memory && p_.GrowFactorWorkspace()) {
        PetscCall(PetscInfo(snes_, "MUMPS workspace too small (INFOG(1) = -9): enlarged\n"));
        --outer;
        continue;
      }
    }
    if (report->reason <= 0) {
      if (prm_.ptc_monitor)
        PetscCall(PetscPrintf(comm_, "  ptc %3d  inner solve failed (%s after %" PetscInt_FMT " its, rho_a %.2e)\n", outer,
                              SNESConvergedReasons[report->reason], its, p_.AnchorWeight()));
      // Retry from the anchor with shorter pseudo-time steps, or give up.
      // (A retry with the Fischer-Burmeister function, smooth where the min
      // function cycles on weakly active contacts, took more iterations with
      // both deformable contact laws: docs/level-solver-measurements.md,
      // "Measured: the knobs of anchored".)
      // The retry's rho_a is at least 4 times the failed one's: with rho_a at
      // its floor prox_eta E (a small |F|_inf near the end of a level) a
      // quarter of the move alone would repeat the same inner solve.
      if (ptc && outer < max_outer && ++failures <= 8) {
        if (force_passed) settled_failed_move = std::min(settled_failed_move, move);
        move *= 0.25;
        rho_retry = 4.0 * p_.AnchorWeight();
        continue;
      }
      PetscCall(p_.EndLoadStep(false, report));
      PetscFunctionReturn(0);
    }
    PetscCall(p_.AdoptState(z_));
    // The level is tested with the slip measured from here (so are the next
    // pseudo-time step's rows): its contact rows are then the static
    // conditions, the tangential force within the Coulomb cone and on it
    // where the contact slides, which every state the test accepted with the
    // slip from the anchor meets too (ResidualFromHere below, whose rows
    // also accept a force inside the cone by less than the slip tie).
    if (ptc) p_.MarkStepStart();
    // A pair that is approaching is made a candidate now, while it is open
    // (the contact states stay, so the step still counts as settled): with
    // a refresh only once a pair overlaps, a pseudo-time step can close it
    // unseen, and near the end of a level the refresh that then follows
    // unbalances the packing again (docs/level-solver-measurements.md,
    // "Measured: candidates refreshed before pairs close").
    bool stale = false, approaching = false;
    PetscCall(p_.CandidatesStale(&stale, &approaching));
    if ((stale || approaching) && (ptc || refresh < 5)) {
      PetscCall(p_.RefreshCandidates());
      ++report->candidate_refreshes;
      ++refresh;
      if (prm_.ptc_monitor && approaching) PetscCall(PetscPrintf(comm_, "  ptc %3d  candidates refreshed before a pair closed\n", outer));
      if (!ptc && stale) continue;
    }
    if (!ptc) break;
    // Equilibrium test without the pseudo-transient term, with the static
    // contact rows.
    p_.SetAnchor(0.0);
    PetscCall(Attach());
    PetscReal true_norm;
    PetscCall(p_.ResidualFromHere(z_, F_));
    PetscCall(VecNorm(F_, NORM_2, &true_norm));
    PetscInt where;
    PetscCall(p_.ForceResidual(F_, &force_residual, &where));
    report->residual = true_norm;
    const double phi = p_.PackingFraction();
    // The balance of every body and the largest contact row (exact below the
    // Newton tolerance, per row as in newton's criterion: a norm over all
    // rows would ask more of every row the larger the packing).
    CompactionProblem::Balance b;
    PetscCall(p_.BodyBalance(F_, &b));
    body_force = b.body_force;
    if (prm_.ptc_monitor) {
      // Where the residual is: body, wall, gauge, normal-contact, tangential rows.
      double part[5];
      PetscCall(p_.ResidualBlocks(F_, part));
      PetscCall(PetscPrintf(comm_, "    largest force %.3e on %s\n", force_residual, p_.DescribeUnknown(where).c_str()));
      PetscCall(PetscPrintf(comm_,
                            "  ptc %3d  |R| %.3e (body %.1e wall %.1e gauge %.1e normal %.1e tangential %.1e; largest contact row %.1e)  |F|_inf %.3e  phi %.7f  move %.2e  its %" PetscInt_FMT "%s\n",
                            outer, (double)true_norm, part[0], part[1], part[2], part[3], part[4], b.contact_row, force_residual, phi, move, its,
                            stale ? "  (candidates refreshed)" : ""));
    }
    report->force_residual = force_residual;
    // The contact states of the test are those of this state (the anchor
    // term changes residual values only): they change between pseudo-time
    // steps only with the candidate list.
    const bool settled = !stale;
    // The parts of the level criterion other than |F|_inf, on the heartbeat
    // line, so that a long sub-step says what keeps it from being accepted.
    bool due = false;
    if (!prm_.ptc_monitor) PetscCall(progress_.Due(comm_, &due));
    if (due) {
      const double pd = std::max(pressure, 1e-300) * dmean;
      char parts[280], change[32] = "-";
      if (phi_last > 0.0) std::snprintf(change, sizeof change, "%.1e", std::abs(phi - phi_last) / phi);
      std::snprintf(parts, sizeof parts,
                    ", largest body force %.1e (particle %d, %s) and torque %.1e P<d>(^2), |P_sigma/P - 1| %.1e, largest "
                    "contact row %.1e (exact below %.0e), contact candidates %s, phi change %s",
                    b.body_force / pd, b.body_force_particle, b.body_force_deformable ? "deformable" : "rigid",
                    b.body_torque / (pd * dmean), VirialDefect(p_, pressure), b.contact_row, row_tol,
                    settled ? "kept" : "refreshed", change);
      PetscCall(progress_.Print(comm_, pressure, steps_before + outer + 1, report->newton_its, force_residual, parts));
    }
    if (settled && true_norm <= atol) break;  // exact equilibrium
    // The paper's level criterion: unbalanced forces small compared with the
    // contact forces (P <d>), the packing fraction no longer changing, and
    // the contact conditions (Signorini, Coulomb) still satisfied exactly.
    const double f_tol = pp.level_force_rtol * pressure * dmean, pd = pressure * dmean;
    const bool force_passes = pp.level_force_rtol > 0.0 && force_residual <= f_tol;
    const bool phi_passes = std::abs(phi - phi_last) <= pp.level_phi_rtol * phi;
    // and, with -level_body_criterion, the net force and torque of every
    // body and the virial identity (evaluated last, and once: it walks every contact)
    const bool body_passes = !prm_.body_criterion || (b.body_force <= f_tol && b.body_torque <= f_tol * dmean);
    double virial = -1.0;
    const auto virial_passes = [&]() {
      if (virial < 0.0) virial = VirialDefect(p_, pressure);
      return virial <= pp.level_force_rtol;
    };
    if (prm_.ptc_monitor && force_passes) {
      // The largest force passes: which other parts of the level criterion
      // keep the level from being accepted.
      std::string failing;
      char part[96];
      if (!settled) failing += " contact candidates refreshed;";
      if (!phi_passes) failing += " phi changing;";
      if (prm_.body_criterion) {
        if (b.body_force > f_tol) std::snprintf(part, sizeof part, " body force %.1e P<d>;", b.body_force / pd), failing += part;
        if (b.body_torque > f_tol * dmean) std::snprintf(part, sizeof part, " body torque %.1e P<d>^2;", b.body_torque / (pd * dmean)), failing += part;
        if (!virial_passes()) std::snprintf(part, sizeof part, " |P_sigma/P - 1| %.1e;", virial), failing += part;
      }
      if (b.contact_row > row_tol) std::snprintf(part, sizeof part, " contact rows %.1e;", b.contact_row), failing += part;
      PetscCall(PetscPrintf(comm_, "  ptc %3d  largest force passes; failing:%s\n", outer, failing.empty() ? " none" : failing.c_str()));
    }
    if (settled && force_passes && phi_passes && body_passes && (!prm_.body_criterion || virial_passes())) {
      if (b.contact_row <= row_tol) {
        report->relaxed = true;
        break;
      }
      // The end game: all but the contact rows pass. What is left there is
      // mostly the indeterminate forces of hyperstatic clusters (rigid disks
      // with more closed and sticking contacts than motions): their kinematic
      // rows can be made exact only by unloading a redundant contact, and
      // each Newton step moves those forces by (row residual) / delta: with
      // delta = prox_eta by about 1e-3 P <d> at P/E 0.6 on 1500 disks, for
      // tens of steps. The dual term is lowered so that they move by
      // about P <d> per step, as rho lets a body move by about m <d>
      // (docs/level-solver-measurements.md, "Measured: the end game of a
      // frictional level").
      p_.SetDualRegularization(b.contact_row / (pressure * dmean));
      // rho_a stays at least that of the pseudo-time step that began the end
      // game. Without it rho_a falls with |F|_inf (1e-13 E <d>) to its floor,
      // and the first Newton step from such an anchor moves the indeterminate
      // forces by about P <d> with the bodies held by nothing: thousands of
      // contacts switch and the inner solve fails (8 of the 15 pseudo-time
      // steps of a 1500-disk end game; docs/level-solver-measurements.md,
      // "Measured: rho_a held in the end game"). rho never enters the
      // residual, so the equilibrium is the same.
      if (rho_end_game == 0.0) {
        rho_end_game = rho_solved;
        if (prm_.ptc_monitor)
          PetscCall(PetscPrintf(comm_, "  ptc %3d  end game: largest contact row %.1e, rho_a held at %.2e or more\n", outer,
                                b.contact_row, rho_end_game));
      }
    }
    phi_last = phi;
    // Did not settle, or diverging: a failed solve, the load controller cuts the step.
    const bool diverged = ptc && force_residual > diverged_force;
    if (outer >= max_outer || diverged) {
      if (diverged && prm_.ptc_monitor)
        PetscCall(PetscPrintf(comm_, "  ptc %3d  diverged: |F|_inf %.3e above %.3e\n", outer, force_residual, diverged_force));
      report->reason = outer >= max_outer ? SNES_DIVERGED_MAX_IT : SNES_DIVERGED_DTOL;
      PetscCall(p_.EndLoadStep(false, report));
      PetscFunctionReturn(0);
    }
    failures = 0;
    rho_retry = 0.0;
    if (force_passes) {
      force_passed = true;
      move = std::min({kSettledGrowth * move, 1.0, std::max(move, 0.5 * settled_failed_move)});
    } else if (its <= pp.ptc_easy_its && !stalled_) move = std::min(kMoveGrowth * move, 1.0);
  }
  PetscCall(p_.EndLoadStep(true, report));
  PetscFunctionReturn(0);
}

PetscErrorCode SolveLevelBy(CompactionProblem &problem, const LevelSolverParameters &params, double pressure,
                            SolveReport *report) {
  PetscFunctionBeginUser;
  if (params.strategy == LevelStrategy::Auto) {
    LevelSolverParameters chosen = params;
    if (problem.FrictionActive()) {
      chosen.strategy = LevelStrategy::Hybrid;
    } else {
      chosen.strategy = LevelStrategy::Newton;
      chosen.merit = LevelMerit::Energy;
    }
    PetscCall(SolveLevelBy(problem, chosen, pressure, report));
    PetscFunctionReturn(0);
  }
  Progress progress(problem);
  if (params.strategy == LevelStrategy::Anchored) {
    AnchoredContinuation solver(problem, params, progress);
    PetscCall(solver.Solve(pressure, report));
    report->factorizations = static_cast<int>(report->newton_its);  // one LU per Newton iteration
    PetscFunctionReturn(0);
  }
  if (params.strategy == LevelStrategy::Hybrid) {
    SolveReport first;
    bool left_open = false;
    {
      MeritNewton attempt(problem, params, progress);
      PetscCall(attempt.Solve(pressure, &first, &left_open));
    }
    if (first.converged) {
      *report = first;
      PetscFunctionReturn(0);
    }
    AnchoredContinuation solver(problem, params, progress);
    PetscCall(solver.Solve(pressure, report, &first, left_open));
    report->factorizations = static_cast<int>(report->newton_its - first.newton_its) + first.factorizations;
    PetscFunctionReturn(0);
  }
  MeritNewton solver(problem, params, progress);
  PetscCall(solver.Solve(pressure, report));
  PetscFunctionReturn(0);
}

}  // namespace

// Contact rows (level_solver.hpp): 1e-4 of the level's force tolerance tol P <d>, and not
// below the Newton tolerance 1e-11 E <d> (which holds at P/E up to 1e-3 with
// tol 1e-4, and with tol 0). A row r is a force r on an open contact, 1e-4 of
// what a body may carry unbalanced, or a closed contact's penetration
// r / c_n = 1e-6 P / E <d> with c_n = 0.01 E: a millionth of the elastic
// indentation at that pressure (the slip of a sticking contact alike). Held
// to 1e-11 E <d> at every pressure instead, the end games of the 1500-disk
// levels above P/E 1e-3 spent up to 19 Newton iterations each on rows
// between 1e-8 P <d> and 1e-11 E <d>, 10 % of the curve's iterations
// (docs/level-solver-measurements.md, "Measured: the contact rows'
// tolerance relative to the pressure").
double ContactRowTolerance(const CompactionProblem &p, double pressure) {
  const double dmean = p.MeanDiameter();
  return std::max(1e-11 * p.Parameters().young * dmean, 1e-4 * p.Parameters().level_force_rtol * pressure * dmean);
}

PetscErrorCode SolveLevel(CompactionProblem &problem, const LevelSolverParameters &params, double pressure,
                          SolveReport *report) {
  PetscFunctionBeginUser;
  const int predictor_before = problem.PredictorFactorizations();
  PetscCall(SolveLevelBy(problem, params, pressure, report));
  report->factorizations += problem.PredictorFactorizations() - predictor_before;  // the tangent's
  PetscFunctionReturn(0);
}

}  // namespace deformix

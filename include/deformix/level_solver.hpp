// Equilibrium at one load step: the strategy that drives the operator of
// CompactionProblem (residual F, Newton matrix, state) to F = 0.
//
// newton: pseudo-transient continuation with ONE semismooth Newton step per
//   pseudo-time step (Kelley and Keyes' Psi-tc; the idea of PETSc's
//   TSPSEUDO), each step tested against a merit function. Iteration k
//   linearizes once, at z_k, and solves
//       (J(z_k) + rho_k D) d = -F(z_k),
//   J the generalized Jacobian (exact NCP rows for Signorini and Coulomb,
//   contact_law.hpp), D the identity on body and wall unknowns (r^2 on rigid
//   rotations), rho_k = |F(z_k)|_inf / (m_k <d>): a body under the largest
//   unbalanced force moves by about m_k <d>, so rattlers, free rotations and
//   rearranging particles (zero or negative curvature) take bounded steps,
//   and rho_k vanishes with F, so the last iterations are plain semismooth
//   Newton steps. Without friction acting, J + rho_k D is factored by MUMPS
//   LDL^T of its symmetric form (CompactionProblem::SymmetrizeNewtonMatrix,
//   -level_ldlt), else by LU. The step is d shortened so that no open or touching contact
//   is driven deeper than 1e-3 <d> into penetration (a cut continuous in the
//   gap, so round-off of either sign at a touching contact takes the same
//   step) and no body moves more than m_k <d>, applied with
//   the finite rotation of each deformable body (RotatedUpdate).
//   The merit is the residual of the proximal subproblem anchored at z_k,
//       G_k(z) = F(z) + rho_k D (z - z_k),
//   whose Newton direction at z_k is exactly d (G_k(z_k) = F(z_k), G_k' the
//   factored matrix), so d is a descent direction of |G_k| even where J is
//   indefinite (saddle-point contact rows, unstable rearrangements), which
//   |F| itself does not guarantee for a shifted step. A step is accepted when
//   |G_k| decreases by the Armijo fraction 1e-4 alpha along d; alpha = 1,
//   1/2, 1/4, 1/8 are tried (one residual each), then m_k / 4 (one more
//   factorization of the same linearization). After an accepted step m grows
//   x4 (to at most <d> / 2) and the next pseudo-time step is anchored at the
//   new iterate.
//   A load step is converged when |F|_2 <= 1e-11 E <d> and no contact
//   changed state in the last step (deal.II step-42's rule; degenerate flips
//   within 1e3 atol of their switch excepted, contact_law.hpp), or, with
//   -level_force_rtol tol > 0, by the paper's criterion per body: the net
//   force and torque of every body below tol P <d> and tol P <d>^2, every
//   nodal force below tol P <d>, every contact row exact (below 1e-4 tol
//   P <d>, at least 1e-11 E <d>), the contact states stable and phi settled to -level_phi_rtol over the
//   last step.
//   With -level_merit energy a step is also accepted when it brings the
//   energy merit below its largest value at the last four iterates (a
//   nonmonotone test; the iterate's value alone is the monotone one), the merit
//       psi(z) = H(z) + nu sum_c max(0, -g_c - e) + sum_c mu lambda_n,c |s_c|,
//   H the enthalpy (strain energy + P x box area), nu above every normal
//   force of the iterate and of the step's end point (an exact l1 penalty),
//   e = 1e-3 <d> the overshoot a step may leave to the next linearization
//   (CompactionProblem::kOpenOvershoot),
//   the friction a Tresca dissipation with the normal forces lagged at the
//   iterate (s_c the incremental slip). For it the step must descend, so the
//   shift grows (a factorization each) until d_x^T (K + rho D) d_x > 0 on
//   the step's body and wall part (one product with the assembled matrix;
//   MUMPS's LU gives no inertia). The energy alone is not
//   enough: steps that close an open contact or slip against a lagged bound
//   cross a kink of psi, and are the ones |G| accepts.
//   PETSc's SNESNEWTONTR does not fit: its trust region is a dogleg in the
//   2-norm of all unknowns (multipliers included), which neither bounds the
//   move of each body nor regularizes floppy modes, and its line searches
//   cannot re-solve with a larger shift. Hence this loop on PETSc's KSP and
//   the problem's residual and Jacobian.
// anchored: pseudo-transient continuation with each pseudo-time step solved
//   by SNESNEWTONLS until its residual has dropped 100-fold (or to the
//   exact tolerance), whether or not contacts still switch there. Each inner solve adds rho D (z - z_a)
//   to the body and wall rows (the problem's SetAnchor), rho = |F|_inf /
//   (m <d>) from the unbalanced force F of the previous pseudo-time step, m
//   = -ptc_move at first, grown by 1.25 after an inner solve of at most
//   -ptc_easy_its iterations (by 4 after every step once |F|_inf passes the
//   level's tolerance, up to half the least m that failed since), divided
//   by 4 after a failed one; the anchor
//   moves to each solution and rho vanishes with F. A sub-step is accepted at
//   exact equilibrium (|R| <= 1e-11 E <d>) or, with -level_force_rtol tol >
//   0, by the paper's criterion per node and per body (|F|_inf <= tol P <d>,
//   the net force and torque of every body below tol P <d> and tol P <d>^2,
//   phi settled to -level_phi_rtol, contact rows exact as for newton; -level_body_criterion
//   false drops the per-body part). Without -ptc_move it is plain
//   semismooth Newton.
//   Without the anchor (rho = 0) Newton stops only when |R| is below tolerance AND the set of open /
//   sticking / sliding contacts did not change in the last iteration
//   (deal.II step-42's rule), or the last step was at round-off, or every
//   contact that changed is within 1e3 atol of its switch: a degenerate
//   contact (lambda_n = c_n g = 0, or |lambda_t| = mu lambda_n without slip)
//   may flip state forever at a converged point, where both of its states'
//   equations hold (contact_law.hpp, changed_state_margin). Newton steps are
//   full, except that a step taken from contact states equal to those of
//   two or three iterations ago (an active-set cycle, typically stick <->
//   slip on the edge of the cone) is backtracked
//   until |R| decreases; an inner solve short of its 100-fold drop after
//   -ptc_stall_its (4) iterations is cut short: its last iterate is an
//   inexact pseudo-time step if its residual decreased, else its iterate of
//   least residual if that one is below the anchor's, else it is retried
//   with more damping. In the end game rho_a is held at least at its value when
//   the end game began. A sub-step whose force residual grows beyond 100
//   times the larger of its start value and P <d> has failed
//   (kDivergedForce): the controller cuts it.
//   The SNES and its callbacks live in level_solver.cpp over a small context.
// hybrid: a newton attempt of at most -level_attempt_its linearizations,
//   ended earlier once its largest force has not halved over its last 10,
//   started from the tangent predictor with overlaps up to 0.1 <d> admitted
//   (newton's first steps move bodies by 0.1 <d> and more, so it closes such
//   overlaps in a step or two, where anchored's damped first steps would
//   creep); its steps are not cut at contacts (newton's contact step
//   fraction). A level that only deforms the packing converges there. When
//   it does not, anchored goes on from the attempt's last iterate if no body
//   overlaps there by more than 1e-2 <d> by the contact laws' gaps (else
//   from the undone load step), and the level counts the iterations of both.
// auto (the default): newton with the energy merit on levels without
//   friction (a frictionless packing, and the frictionless settling level of
//   a frictional one), where the enthalpy is the exact potential; hybrid
//   (with -level_merit) on frictional levels, where steps accepted by the
//   energy with lagged normal forces can undo each other (docs/level-solver-measurements.md).
#pragma once
#include "deformix/problem.hpp"

namespace deformix {

enum class LevelStrategy : int { Newton = 0, Anchored = 1, Hybrid = 2, Auto = 3 };
// What tests a step of newton (and of hybrid's attempt): the residual of the
// proximal subproblem, or the energy (level_solver.hpp, newton).
enum class LevelMerit : int { Residual = 0, Energy = 1 };

struct LevelSolverParameters {
  LevelStrategy strategy = LevelStrategy::Auto;
  PetscInt max_its = 400;     // newton: linearizations per load step before it counts as failed
  PetscInt attempt_its = 30;  // hybrid: linearizations of the newton attempt
  LevelMerit merit = LevelMerit::Residual;  // newton (and hybrid's attempt): -level_merit
  double initial_move = 0.1;  // trust radius m at the start of a load step, in <d>
  PetscBool ldlt = PETSC_TRUE;  // newton on levels without friction: MUMPS LDL^T of the symmetric form (-level_ldlt)
  PetscBool monitor = PETSC_FALSE;  // -level_monitor: one line per Newton iteration
  SNESLineSearchType line_search = SNESLINESEARCHBT;  // anchored: the SNES line search (-snes_linesearch_type overrides)
  PetscBool body_criterion = PETSC_TRUE;   // anchored: the level criterion per body too (-level_body_criterion)
  PetscBool ptc_monitor = PETSC_FALSE;              // anchored: -ptc_monitor, one line per pseudo-time step
  PetscBool newton_monitor = PETSC_FALSE;           // anchored: -newton_monitor, one line per Newton iteration
  PetscBool newton_monitor_contacts = PETSC_FALSE;  // anchored: -newton_monitor_contacts
  // newton with the energy merit in compact's settlings (set by the driver, not
  // an option): the trust radius grows by at most four times the step taken.
  bool settling = false;
  PetscErrorCode SetFromOptions(MPI_Comm comm);
};

// The largest contact row the level criteria accept as exact at pressure P:
// 1e-4 -level_force_rtol P <d>, and at least the Newton tolerance 1e-11 E <d>.
double ContactRowTolerance(const CompactionProblem &problem, double pressure);

// Solves equilibrium at pressure P from the problem's current state. On
// success the state is updated; on failure it is left unchanged.
PetscErrorCode SolveLevel(CompactionProblem &problem, const LevelSolverParameters &params, double pressure,
                          SolveReport *report);

}  // namespace deformix

// Equilibrium at one load step: the strategy that drives the operator of
// CompactionProblem (residual F, Newton matrix, state) to F = 0.
//
// newton (default): semismooth Newton globalized by a merit function.
//   Every iteration linearizes once, at the iterate z_k, and solves
//       (J(z_k) + rho_k D) d = -F(z_k),
//   J the generalized Jacobian (exact NCP rows for Signorini and Coulomb,
//   contact_law.hpp), D the identity on body and wall unknowns (r^2 on rigid
//   rotations). rho_k = |F(z_k)|_inf / (m_k <d>) is a Levenberg-Marquardt
//   shift: a body under an unbalanced force f moves by at most about m_k <d>,
//   so rattlers, free rotations and rearranging particles (zero or negative
//   curvature) take bounded steps, and rho_k -> 0 with F, so the last
//   iterations are plain semismooth Newton steps. The trial step (shortened
//   so that no open contact is driven deep into penetration) is tested
//   against the merit M(z) = |F(z)|^2 / 2 with the ratio of actual to
//   predicted decrease,
//       ratio = (M(z_k) - M(z_k + s)) / (M(z_k) - |F + J s|^2 / 2),
//   and the trust radius m_k is updated as in a trust-region method: x4
//   after a very good step (ratio > 0.75), /2 after a poor one (< 0.25).
//   A step is accepted when M decreases by at least 1e-4 of the prediction
//   compared with the largest M of the last three accepted iterates (a
//   non-monotone test: a change of the active set may raise M for one step
//   on the way to a solution); a rejected step is re-solved from the same
//   linearization with m_k / 4 (one more factorization, no new assembly).
//   Converged when |F|_2 <= atol and no contact changed state in the last
//   step (deal.II step-42's rule; degenerate flips within 1e3 atol of their
//   switch excepted, contact_law.hpp).
//   PETSc's SNESNEWTONTR does not fit: its trust region is a dogleg on the
//   Newton direction with the radius in the 2-norm of all unknowns
//   (multipliers included), which neither bounds the move of each body nor
//   keeps the Newton matrix nonsingular on floppy modes; its line searches
//   cannot re-solve with a different shift. Hence this loop, on PETSc's KSP
//   and the problem's residual and Jacobian.
// anchored: pseudo-transient continuation with each pseudo-time step solved
//   to convergence (CompactionProblem::Solve, the -ptc_* options).
#pragma once
#include "deformix/problem.hpp"

namespace deformix {

enum class LevelStrategy : int { Newton = 0, Anchored = 1 };

struct LevelSolverParameters {
  LevelStrategy strategy = LevelStrategy::Anchored;
  PetscInt max_its = 200;     // linearizations per load step before it counts as failed
  double initial_move = 0.1;  // trust radius m at the start of a load step, in <d>
  PetscBool monitor = PETSC_FALSE;  // -level_monitor: one line per Newton iteration
  PetscErrorCode SetFromOptions(MPI_Comm comm);
};

// Solves equilibrium at pressure P from the problem's current state. On
// success the state is updated; on failure it is left unchanged.
PetscErrorCode SolveLevel(CompactionProblem &problem, const LevelSolverParameters &params, double pressure,
                          SolveReport *report);

}  // namespace deformix

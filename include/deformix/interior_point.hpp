// interior: the level solver for frictionless load steps as a constrained
// minimization (level_solver.hpp lists the strategies).
//
// A frictionless equilibrium at pressure P is a constrained stationary point
// of the enthalpy H(z) = sum_b W_b(u) + P A(w) (strain energy of the
// deformable disks plus pressure times box area) under g_c(z) >= 0 for every
// contact candidate. The interior strategy follows the central path of the
// barrier problems
//     min  phi_mu(z) = H(z) - mu sum_c log(g_c + eps)
// by primal-dual Newton steps (Waechter and Biegler's IPOPT, 2006): the
// contact rows are lambda_c - mu / (g_c + eps) with their primal-dual Newton
// row (CompactionProblem::SetBarrier), one linearization per iteration, and
//   - inertia-free curvature test (Chiang and Zavala 2016): the step d
//     must have positive curvature d^T (W + A^T diag(lambda / (g + eps)) A
//     + delta D) d, W the Hessian of the Lagrangian, or the shift delta D on
//     the body and wall rows grows (IPOPT's rule: 1e-4 E, x100, then x8;
//     the next iteration starts from delta / 3). The curvature of the step
//     is one matrix-vector product with the factored matrix, so MUMPS LU
//     serves (no LDL^T inertia needed), and on a rattler, a free rotation or
//     an unstable rearrangement the step descends on phi_mu;
//   - fraction to the boundary: lambda and g + eps (linearized) keep 1 %
//     of their value, and no body moves more than half the candidate margin
//     per step (the barrier only knows the candidates; the candidates are
//     refreshed as bodies move);
//   - Armijo backtracking on phi_mu (1e-4, halving), whose slope along d is
//     minus that curvature; a step without sufficient decrease after 10
//     halvings raises the shift;
//   - mu from 1e-3 P <d>^2, lowered to min(0.2 mu, mu^1.5) (in P <d>^2)
//     whenever the barrier problem's error (largest force and |lambda (g +
//     eps) - mu|, in P <d> and P <d>^2) is below 10 mu, down to 1e-10 P
//     <d>^2.
// Then an active-set polish: the exact NCP rows (contact_law.hpp) and
// semismooth Newton steps from the interior point, whose multipliers
// identify the active set, to |F| <= 1e-11 E <d> with stable contact
// states: every level ends at exact complementarity, as with the other
// strategies. eps = 1e-9 <d>, or twice the deepest penetration of a
// candidate when a predicted state or a refreshed candidate overlaps.
// Frictional levels need the other strategies (the Coulomb law is not a
// potential); the strategy refuses them.
#pragma once
#include "deformix/level_solver.hpp"

namespace deformix {

PetscErrorCode SolveLevelInterior(CompactionProblem &problem, const LevelSolverParameters &params, double pressure,
                                  SolveReport *report);

}  // namespace deformix

// interior: the level solver for frictionless load steps as a constrained
// minimization (level_solver.hpp lists the strategies).
//
// A frictionless equilibrium at pressure P is a constrained stationary point
// of the enthalpy H(z) = sum_b W_b(u) + P A(w) (strain energy of the
// deformable disks plus pressure times box area) under g_c(z) >= 0 for every
// contact candidate. The interior strategy follows the central path of the
// barrier problems
//     min  phi_mu(z) = H(z) + mu sum_c b(g_c + eps),
// b the clamped log barrier of reach shat = 0.2 x the candidate margin
// (contact_law.hpp: -log near 0, zero beyond shat, so candidates that enter
// or leave the list do not change phi_mu), by primal-dual Newton steps in
// the manner of IPOPT (Waechter and Biegler 2006): the contact rows are
// lambda_c - mu psi(g_c + eps) with their primal-dual Newton row
// (CompactionProblem::SetBarrier), one linearization per iteration, and
//   - an inertia-free curvature test (Chiang and Zavala 2016): the step d
//     must have positive curvature d^T (W + A^T diag(k) A + delta D) d, W the
//     Hessian of the Lagrangian, k_c the rows' stiffness; the curvature is
//     one product with the assembled matrix, so MUMPS LU serves (no LDL^T
//     inertia needed). A step that fails it, or that moves a body further
//     than half the candidate margin (rattlers and floppy modes have nearly
//     zero curvature), is recomputed with the shift delta D on the body and
//     wall rows grown by IPOPT's rule (1e-4 E, x100, then x8; the next
//     iteration starts from delta / 3): a Levenberg-Marquardt step, so that
//     on a rattler, a free rotation or an unstable rearrangement the step
//     descends on phi_mu and stays within what the candidates guard;
//   - fraction to the boundary on the linearized gaps (tau = 0.99); the
//     multipliers take the primal step length, and one that would turn
//     negative is set to its barrier force mu psi(g + eps) at the new point
//     (then all are kept within 1e10 of it, IPOPT's safeguard);
//   - a nonmonotone Armijo test on phi_mu (Grippo, Lampariello and Lucidi
//     1986; 1e-4, against the largest merit of the last 3 iterates of the
//     same barrier problem), halving up to 10 times before a larger shift;
//     the slope along d is minus its curvature;
//   - mu from 1e-3 P <d>^2, lowered to min(0.2 mu, mu^1.5) (in P <d>^2)
//     whenever the barrier problem's error (largest force, and largest
//     |lambda - mu psi| (g + eps), in P <d> and P <d>^2) is below 10 mu (or
//     below the Newton tolerance), down to 1e-10 P <d>^2.
// Then an active-set polish: the exact NCP rows (contact_law.hpp) and
// semismooth Newton steps from the interior point, whose multipliers
// identify the active set, to |F| <= 1e-11 E <d> with stable contact
// states: every level ends at exact complementarity, as with the other
// strategies. eps = 1e-9 <d>, or twice the deepest penetration of a
// candidate when a predicted state or a refreshed candidate overlaps.
// Frictional levels need the other strategies (the Coulomb law is not a
// potential); compact refuses -level_solver interior with friction.
#pragma once
#include "deformix/level_solver.hpp"

namespace deformix {

PetscErrorCode SolveLevelInterior(CompactionProblem &problem, const LevelSolverParameters &params, double pressure,
                                  SolveReport *report);

}  // namespace deformix

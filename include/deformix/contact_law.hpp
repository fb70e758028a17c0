// Contact as complementarity, solved by semismooth Newton.
//
// Every contact c has a gap g_c(x) (>= 0 when the bodies are apart) and a
// normal multiplier lambda_c (the compressive contact force, per unit
// thickness). Signorini's conditions
//     g >= 0,   lambda >= 0,   g lambda = 0
// are replaced by one semismooth equation, the min (Alart-Curnier /
// projection) NCP function
//     C(lambda, g) = lambda - max(0, lambda - c_n g) = min(lambda, c_n g) = 0,
// or the Fischer-Burmeister function
//     C(lambda, g) = lambda + c_n g - sqrt(lambda^2 + (c_n g)^2) = 0.
// c_n ~ E scales the gap to force units; it changes the Newton path, never
// the solution. The generalized Jacobian of the min function is
//     active   (lambda - c_n g >= 0):  dC = c_n dg
//     inactive (lambda - c_n g <  0):  dC = d lambda,
// and the contact adds -lambda dg/dx to the equilibrium residual of every
// unknown the gap depends on (bodies and walls), with -lambda d2g/dx2 to the
// stiffness when the gap is curved. No penalty: a converged solution has
// g >= 0 and lambda >= 0 exactly up to the Newton tolerance.
//
// Coulomb friction (2D, incremental). With s the tangential slip over the
// increment (the load step, or one pseudo-time step of the anchored level
// solver) and lambda_t the tangential force on the slave along t, the
// Alart-Curnier projection
//     C_t = lambda_t - proj_[-mu a, mu a](lambda_t - c_t s),
//     a   = max(0, lambda_n - c_n g)   (the augmented normal force)
// is zero exactly when |lambda_t| <= mu lambda_n with s = 0 (stick) or
// lambda_t = -mu lambda_n sign(s) (slip), and lambda_t = 0 when the contact is
// open. Generalized Jacobian by cases:
//     open  (a = 0):                  dC_t = d lambda_t
//     stick (|lambda_t - c_t s| <= mu a): dC_t = c_t ds
//     slip  (sigma = sign(lambda_t - c_t s)):
//                                     dC_t = d lambda_t - sigma mu (d lambda_n - c_n dg)
//
// References: Alart & Curnier, CMAME 92 (1991); Fischer, Optimization 24
// (1992); Hueber & Wohlmuth, CMAME 194 (2005) (primal-dual active set =
// semismooth Newton).
#pragma once

#include <array>
#include <vector>

namespace deformix {

enum class NcpFunction { Min, FischerBurmeister };

// Value and generalized derivatives of the normal NCP function.
struct NormalNcp {
  double value = 0.0;
  double d_lambda = 0.0;  // dC / dlambda
  double d_gap = 0.0;     // dC / dg
  bool active = false;    // the constraint is treated as closed (g = 0) by this Newton step
  double switch_margin = 0.0;  // |lambda - c_n g|: how far the state is from switching
};

// tie (>= 0, force units): the min function's rows count as active down to
// lambda - c_n g = -tie, so that a touching contact without force (lambda =
// 0, g at round-off of 0, as the rigid settling leaves the contacts of
// disks that become deformable) takes the same row whatever the sign of its
// round-off (which depends on the number of ranks and the factorization).
NormalNcp normal_ncp(NcpFunction f, double lambda, double gap, double c_n, double tie = 0.0);

enum ContactState { kOpen = 0, kClosed = 1, kSliding = 2 };

// Value and generalized derivatives of the Coulomb NCP function.
struct TangentialNcp {
  double value = 0.0;
  double d_lambda_t = 0.0, d_lambda_n = 0.0, d_gap = 0.0, d_slip = 0.0;
  ContactState state = kOpen;
  double switch_margin = 0.0;  // | |lambda_t - c_t s| - mu a |: how far stick is from slip (0 when open)
};

// tie (>= 0, force units): a contact whose trial force is within tie of the
// cone, |lambda_t - c_t s| >= mu a - tie, takes the slip row. A contact that
// slid up to the start of an increment has s = 0 and |lambda_t| = mu a to
// the tolerance of the last solve: both rows hold there, and the stick row
// (0 slip) would make the first Newton step of the increment hold it, the
// next one let it slide again (and a rigid disk whose contacts all slid
// then turns back and forth). With the slip row it goes on sliding unless
// its slip reverses. A converged state is exact Coulomb either way: stick
// strictly inside the cone, or a force on the cone.
TangentialNcp coulomb_ncp(double lambda_t, double lambda_n, double gap, double slip, double mu, double c_n,
                          double c_t, double tie = 0.0);

// Degenerate state changes. At a converged point a weakly active contact
// (lambda_n = c_n g = 0, or |lambda_t| = mu lambda_n without slip) may
// switch state at every Newton step: both linearizations hold there. Given
// the states of n contacts at two iterates and, per contact, the margins
// {normal, tangential} (2n values) at the second one, returns the largest
// margin of a switch that happened: the normal margin for open <-> closed
// or sliding, the tangential one for stick <-> slip (0 if nothing changed).
// A state change whose margin is within this many Newton tolerances of the
// switch is degenerate: both states' equations hold at the converged point.
constexpr double kDegenerateSwitch = 1e3;
double changed_state_margin(const std::vector<char> &was, const std::vector<char> &now,
                            const std::vector<double> &margins);

// Kinematics of one contact: the gap and its first derivatives with respect
// to the global unknowns it depends on (at most kMaxDofs of them). A
// node-against-wall gap is linear in the unknowns; node-to-segment gaps of
// the mixture add second derivatives.
struct ContactKinematics {
  static constexpr int kMaxDofs = 8;
  double gap = 0.0;
  int ndof = 0;
  std::array<int, kMaxDofs> dofs{};     // global unknown indices
  std::array<double, kMaxDofs> dgap{};  // dg / d(unknown)
};

}  // namespace deformix

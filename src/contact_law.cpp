#include "deformix/contact_law.hpp"

#include <algorithm>
#include <cmath>

namespace deformix {

NormalNcp normal_ncp(NcpFunction f, double lambda, double gap, double c_n, double tie) {
  NormalNcp r;
  const double cg = c_n * gap;
  r.switch_margin = std::abs(lambda - cg);
  if (f == NcpFunction::Min) {
    // A tie (lambda = c_n g, e.g. a closed contact carrying no force yet) is
    // treated as active so that a touching wall is coupled to the body in the
    // first Newton step of a load increment.
    r.active = lambda - cg >= -tie;
    if (r.active) {
      r.value = cg;
      r.d_gap = c_n;
    } else {
      r.value = lambda;
      r.d_lambda = 1.0;
    }
    return r;
  }
  // Fischer-Burmeister. At the kink (0, 0) any element of the generalized
  // Jacobian will do; (1 - 1/sqrt2, 1 - 1/sqrt2) is the limit along the diagonal.
  const double norm = std::hypot(lambda, cg);
  r.value = lambda + cg - norm;
  if (norm > 0.0) {
    r.d_lambda = 1.0 - lambda / norm;
    r.d_gap = c_n * (1.0 - cg / norm);
  } else {
    r.d_lambda = 1.0 - M_SQRT1_2;
    r.d_gap = c_n * (1.0 - M_SQRT1_2);
  }
  r.active = cg <= lambda;
  return r;
}

TangentialNcp coulomb_ncp(double lambda_t, double lambda_n, double gap, double slip, double mu, double c_n,
                          double c_t, double tie) {
  TangentialNcp r;
  const double a = lambda_n - c_n * gap;
  if (!(a > 0.0)) {
    r.value = lambda_t;
    r.d_lambda_t = 1.0;
    return r;
  }
  const double bound = mu * a, trial = lambda_t - c_t * slip;
  r.switch_margin = std::abs(std::abs(trial) - bound);
  // Stick needs a cone to stick in: with mu = 0 (friction switched off) a
  // zero trial (no slip, no tangential force, e.g. at the start of a step)
  // must not lock the tangential motion. Within tie of the cone the slip row
  // is taken (contact_law.hpp); a contact whose bound is below tie (mu a <
  // 1e-8 c_t <d> with kSlipTie: a force that the level criterion cannot see)
  // always takes it, with its tangential force on the cone.
  if (bound > 0.0 && std::abs(trial) <= bound - tie) {
    r.state = kClosed;
    r.value = c_t * slip;
    r.d_slip = c_t;
    return r;
  }
  const double sigma = trial > 0.0 ? 1.0 : -1.0;
  r.state = kSliding;
  r.value = lambda_t - sigma * bound;
  r.d_lambda_t = 1.0;
  r.d_lambda_n = -sigma * mu;
  r.d_gap = sigma * mu * c_n;
  return r;
}

double changed_state_margin(const std::vector<char> &was, const std::vector<char> &now,
                            const std::vector<double> &margins) {
  double m = 0.0;
  for (size_t c = 0; c < now.size(); ++c) {
    if (was[c] == now[c]) continue;
    const bool normal_switch = (was[c] == kOpen) != (now[c] == kOpen);
    m = std::max(m, margins[2 * c + (normal_switch ? 0 : 1)]);
  }
  return m;
}

}  // namespace deformix

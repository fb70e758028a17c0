// Node against a smooth (C1) master curve: curve_node (see pair_kinematics.hpp).
//
// The master curve is the uniform Catmull-Rom spline through the master's
// boundary nodes: on the segment from P1 to P2 (neighbours P0, P3)
//   x(t) = N0(t) P0 + N1(t) P1 + N2(t) P2 + N3(t) P3,  t in [0, 1],
//   N0 = -t/2 + t^2 - t^3/2,   N1 = 1 - 5t^2/2 + 3t^3/2,
//   N2 = t/2 + 2t^2 - 3t^3/2,  N3 = -t^2/2 + t^3/2,
// which interpolates the nodes, has the tangent (P2 - P0)/2 at P1 (so the
// curve is C1 across nodes) and reproduces straight lines through equally
// spaced nodes. The curve is linear in the node positions.
//
// The closest point t* solves f(t, q) = (p - x(t)) . x'(t) = 0. Gap and slip
// are then explicit functions of (q, t*(q)):
//   g = (p - x) . n,  n = right normal of x' / |x'|  (outward, as for segments),
//   s = tau . [(p - p0) - sum_i N_i(t*) (P_i - P0_i)],  tau = x' / |x'|.
// Their first derivatives are closed-form (first_derivatives: the gap's by
// the envelope theorem, the slip's with dt*/dq from the implicit function
// theorem); the residual needs nothing more, and most candidates carry no
// force. The second derivatives (the Newton matrix of a loaded contact) come
// from the implicit function theorem with t as one more variable: the gap
// phi(q, t), the slip sigma(q, t) and the stationarity condition f(q, t) are
// closed-form in (q, t), and x(t) = sum_i N_i(t) P_i is linear in the nodes
// and a cubic in t, so their values, gradients and Hessians in (q, t) are
// written down directly for x, x' and u and carried through the few
// remaining products by forward-mode automatic differentiation. Then
//   t*_q  = -f_q / f_t,
//   t*_qq = -(f_qq + f_qt t*_q^T + t*_q f_tq + f_tt t*_q t*_q^T) / f_t,
//   psi*_qq = psi_qq + psi_qt t*_q^T + t*_q psi_tq + psi_tt t*_q t*_q^T + psi_t t*_qq
// for psi = phi, sigma (psi* = psi(q, t*(q))).
#include <algorithm>
#include <cmath>
#include <limits>

#include "deformix/pair_kinematics.hpp"

namespace deformix {

namespace {

constexpr int kN = 12;                   // unknowns of the pair
// Gap and slip on segment k depend on its four nodes and the slave node (q
// variables 0..9 below) and on t (variable 10).
constexpr int kV = 11, kT = 10;
constexpr int kH = kV * (kV + 1) / 2;    // packed symmetric Hessian

inline int packed(int i, int j) { return i <= j ? i * kV - i * (i - 1) / 2 + (j - i) : packed(j, i); }

// Second-order forward-mode number: value, gradient and packed symmetric
// Hessian with respect to the kV variables.
struct Ad {
  double v = 0.0;
  double g[kV] = {};
  double h[kH] = {};
  Ad() = default;
  explicit Ad(double value) : v(value) {}
};

Ad operator-(const Ad &a, const Ad &b) {
  Ad r(a.v - b.v);
  for (int i = 0; i < kV; ++i) r.g[i] = a.g[i] - b.g[i];
  for (int i = 0; i < kH; ++i) r.h[i] = a.h[i] - b.h[i];
  return r;
}

Ad operator+(const Ad &a, const Ad &b) {
  Ad r(a.v + b.v);
  for (int i = 0; i < kV; ++i) r.g[i] = a.g[i] + b.g[i];
  for (int i = 0; i < kH; ++i) r.h[i] = a.h[i] + b.h[i];
  return r;
}

Ad operator*(const Ad &a, const Ad &b) {
  Ad r(a.v * b.v);
  for (int i = 0; i < kV; ++i) r.g[i] = a.v * b.g[i] + b.v * a.g[i];
  int k = 0;
  for (int i = 0; i < kV; ++i)
    for (int j = i; j < kV; ++j, ++k) r.h[k] = a.v * b.h[k] + b.v * a.h[k] + a.g[i] * b.g[j] + a.g[j] * b.g[i];
  return r;
}

// f(a) for a scalar function with derivatives f1 = f'(a.v), f2 = f''(a.v).
Ad chain(const Ad &a, double f, double f1, double f2) {
  Ad r(f);
  for (int i = 0; i < kV; ++i) r.g[i] = f1 * a.g[i];
  int k = 0;
  for (int i = 0; i < kV; ++i)
    for (int j = i; j < kV; ++j, ++k) r.h[k] = f1 * a.h[k] + f2 * a.g[i] * a.g[j];
  return r;
}

// 1 / sqrt(a).
Ad inv_sqrt(const Ad &a) {
  const double s = 1.0 / std::sqrt(a.v);
  return chain(a, s, -0.5 * s / a.v, 0.75 * s / (a.v * a.v));
}

// Catmull-Rom basis and its first two derivatives at t.
void basis(double t, double N[4], double dN[4], double d2N[4]) {
  const double t2 = t * t, t3 = t2 * t;
  N[0] = (-0.5) * t + t2 - 0.5 * t3;
  N[1] = 1.0 - 2.5 * t2 + 1.5 * t3;
  N[2] = 0.5 * t + 2.0 * t2 - 1.5 * t3;
  N[3] = (-0.5) * t2 + 0.5 * t3;
  dN[0] = -0.5 + 2.0 * t - 1.5 * t2;
  dN[1] = (-5.0) * t + 4.5 * t2;
  dN[2] = 0.5 + 4.0 * t - 4.5 * t2;
  dN[3] = (-1.0) * t + 1.5 * t2;
  d2N[0] = 2.0 - 3.0 * t;
  d2N[1] = -5.0 + 9.0 * t;
  d2N[2] = 4.0 - 9.0 * t;
  d2N[3] = -1.0 + 3.0 * t;
}

// Point, tangent and second derivative of segment k (nodes k .. k+3 of the
// five patch nodes P) at t.
void curve_point(const double P[5][2], int k, double t, double x[2], double a[2], double b[2]) {
  double N[4], dN[4], d2N[4];
  basis(t, N, dN, d2N);
  for (int c = 0; c < 2; ++c) {
    x[c] = N[0] * P[k][c] + N[1] * P[k + 1][c] + N[2] * P[k + 2][c] + N[3] * P[k + 3][c];
    a[c] = dN[0] * P[k][c] + dN[1] * P[k + 1][c] + dN[2] * P[k + 2][c] + dN[3] * P[k + 3][c];
    b[c] = d2N[0] * P[k][c] + d2N[1] * P[k + 1][c] + d2N[2] * P[k + 2][c] + d2N[3] * P[k + 3][c];
  }
}

// Stationary point of |p - x(t)|^2 on segment k by Newton from the chord
// projection; t may leave [0, 1] (extrapolated cubic). Returns false if the
// iteration does not settle (the caller then takes the other segment).
bool project(const double P[5][2], int k, const double p[2], double *t_out, double *dist) {
  const double ex = P[k + 2][0] - P[k + 1][0], ey = P[k + 2][1] - P[k + 1][1];
  const double l2 = ex * ex + ey * ey;
  if (!(l2 > 0.0)) return false;
  double t = std::clamp(((p[0] - P[k + 1][0]) * ex + (p[1] - P[k + 1][1]) * ey) / l2, -0.5, 1.5);
  for (int it = 0; it < 30; ++it) {
    double x[2], a[2], b[2];
    curve_point(P, k, t, x, a, b);
    const double rx = p[0] - x[0], ry = p[1] - x[1];
    const double f = rx * a[0] + ry * a[1];
    const double df = -(a[0] * a[0] + a[1] * a[1]) + rx * b[0] + ry * b[1];
    if (!(df < 0.0)) return false;  // not a minimum of the distance: the node is far on the concave side
    const double dt = -f / df;
    const double next = std::clamp(t + dt, -1.0, 2.0);
    if (next == t) break;  // held at a bound of the extrapolated range
    t = next;
    // Newton converges quadratically: after a step below 1e-9 t is exact to
    // round-off, which the absolute coordinates (up to tens of <d>) put near 1e-14;
    // a test at the last bit would go on iterating on that noise.
    if (std::fabs(dt) < 1e-9) break;
  }
  double x[2], a[2], b[2];
  curve_point(P, k, t, x, a, b);
  *t_out = t;
  *dist = std::hypot(p[0] - x[0], p[1] - x[1]);
  return true;
}

// Gap, slip and their first and second derivatives on segment k at the
// converged t (see the top of the file); the entries of the patch node off
// the segment are left as they are (zero in a new PairKinematics).
void second_derivatives(const double q[12], const double q0[12], int k, double t, PairKinematics *out) {
  double Nb[4], dNb[4], d2Nb[4];
  basis(t, Nb, dNb, d2Nb);
  const double d3N[4] = {-3.0, 9.0, -9.0, 3.0};
  // x, x' = a and u = (p - p0) - sum_i N_i (P_i - P0_i) in (q, t): linear in
  // the nodes, so their only second derivatives are d/dt d/dP_i and d2/dt2.
  Ad x[2], a[2], u[2], p[2];
  for (int c = 0; c < 2; ++c) {
    for (int i = 0; i < 4; ++i) {
      const double P = q[2 * (k + i) + c], dP = P - q0[2 * (k + i) + c];
      const double N = Nb[i], dN = dNb[i], d2N = d2Nb[i];
      const int v = 2 * i + c;  // variable of node k + i, coordinate c
      x[c].v += N * P, x[c].g[v] = N, x[c].g[kT] += dN * P, x[c].h[packed(kT, kT)] += d2N * P;
      a[c].v += dN * P, a[c].g[v] = dN, a[c].g[kT] += d2N * P, a[c].h[packed(kT, kT)] += d3N[i] * P;
      u[c].v -= N * dP, u[c].g[v] = -N, u[c].g[kT] -= dN * dP, u[c].h[packed(kT, kT)] -= d2N * dP;
      x[c].h[packed(v, kT)] = dN, a[c].h[packed(v, kT)] = d2N, u[c].h[packed(v, kT)] = -dN;
    }
    p[c] = Ad(q[10 + c]), p[c].g[8 + c] = 1.0;
    u[c].v += q[10 + c] - q0[10 + c], u[c].g[8 + c] = 1.0;
  }
  const Ad r0 = p[0] - x[0], r1 = p[1] - x[1];
  const Ad f = r0 * a[0] + r1 * a[1];
  const Ad inv_len = inv_sqrt(a[0] * a[0] + a[1] * a[1]);
  // n = (a_y, -a_x) / |a|,  tau = a / |a|.
  const Ad gap = (r0 * a[1] - r1 * a[0]) * inv_len;
  const Ad slip = (u[0] * a[0] + u[1] * a[1]) * inv_len;
  // t*(q) by the implicit function theorem.
  constexpr int nq = kV - 1;
  const double f_t = f.g[kT];
  double tq[nq], tqq[nq][nq];
  for (int v = 0; v < nq; ++v) tq[v] = -f.g[v] / f_t;
  const auto second = [&](const Ad &psi, int v, int w) {  // d2/dq_v dq_w of psi(q, t) along t*(q), without psi_t t*_qq
    return psi.h[packed(v, w)] + psi.h[packed(v, kT)] * tq[w] + tq[v] * psi.h[packed(w, kT)] +
           psi.h[packed(kT, kT)] * tq[v] * tq[w];
  };
  for (int v = 0; v < nq; ++v)
    for (int w = v; w < nq; ++w) tqq[v][w] = tqq[w][v] = -second(f, v, w) / f_t;
  const auto unknown = [k](int v) { return v < 8 ? 2 * k + v : 2 + v; };  // pair unknown of variable v
  out->ndof = kN;
  out->gap = gap.v;
  out->slip = slip.v;
  out->normal[0] = a[1].v * inv_len.v;
  out->normal[1] = -a[0].v * inv_len.v;
  for (int v = 0; v < nq; ++v) {
    out->dgap[unknown(v)] = gap.g[v] + gap.g[kT] * tq[v];
    out->dslip[unknown(v)] = slip.g[v] + slip.g[kT] * tq[v];
    for (int w = v; w < nq; ++w) {
      const double hg = second(gap, v, w) + gap.g[kT] * tqq[v][w], hs = second(slip, v, w) + slip.g[kT] * tqq[v][w];
      out->d2gap[unknown(v) * kN + unknown(w)] = out->d2gap[unknown(w) * kN + unknown(v)] = hg;
      out->d2slip[unknown(v) * kN + unknown(w)] = out->d2slip[unknown(w) * kN + unknown(v)] = hs;
    }
  }
}

// Gap, slip and their first derivatives on segment k at the converged t, in
// closed form. With r = p - x(t), a = x'(t), b = x''(t), n and tau = a / |a|:
//   dg = n . (dp - sum_i N_i dP_i)           (r is parallel to n, n . dn = 0,
//                                             a . n = 0: t* drops out)
//   dt = -[(dp - sum_i N_i dP_i) . a + r . sum_i N_i' dP_i] / f_t,
//        f_t = r . b - a . a                 (implicit function theorem)
//   ds = (u . n)(n . da) / |a| + tau . du,   da = sum_i N_i' dP_i + b dt,
//        du = dp - sum_i N_i dP_i - [sum_i N_i' (P_i - P0_i)] dt.
void first_derivatives(const double q[12], const double q0[12], int k, double t, PairKinematics *out) {
  double N[4], dN[4], d2N[4];
  basis(t, N, dN, d2N);
  double x[2] = {0, 0}, a[2] = {0, 0}, b[2] = {0, 0}, u[2], w[2] = {0, 0};
  for (int c = 0; c < 2; ++c) {
    u[c] = q[10 + c] - q0[10 + c];
    for (int i = 0; i < 4; ++i) {
      const double P = q[2 * (k + i) + c], dP = P - q0[2 * (k + i) + c];
      x[c] += N[i] * P, a[c] += dN[i] * P, b[c] += d2N[i] * P;
      u[c] -= N[i] * dP, w[c] += dN[i] * dP;
    }
  }
  const double r[2] = {q[10] - x[0], q[11] - x[1]};
  const double la = std::hypot(a[0], a[1]);
  const double n[2] = {a[1] / la, -a[0] / la}, tau[2] = {a[0] / la, a[1] / la};
  const double f_t = r[0] * b[0] + r[1] * b[1] - (a[0] * a[0] + a[1] * a[1]);
  const double un = u[0] * n[0] + u[1] * n[1];
  out->ndof = kN;
  out->gap = r[0] * n[0] + r[1] * n[1];
  out->slip = u[0] * tau[0] + u[1] * tau[1];
  out->normal[0] = n[0], out->normal[1] = n[1];
  for (int j = 0; j < kN; ++j) {
    const int node = j / 2, c = j % 2, i = node - k;  // i: index in the segment's four nodes
    double Nj = 0.0, dNj = 0.0;                        // x = Nj P (+ p for the slave)
    if (node == 5) Nj = -1.0;                          // the slave node: dp enters as -(-1) dp
    else if (i >= 0 && i < 4) Nj = N[i], dNj = dN[i];
    else {
      out->dgap[j] = out->dslip[j] = 0.0;
      continue;
    }
    // Unit perturbation of coordinate c: dp - sum N_i dP_i = -Nj e_c, sum N_i' dP_i = dNj e_c.
    const double dt = -(-Nj * a[c] + r[c] * dNj) / f_t;
    const double da[2] = {(c == 0 ? dNj : 0.0) + b[0] * dt, (c == 1 ? dNj : 0.0) + b[1] * dt};
    const double du[2] = {(c == 0 ? -Nj : 0.0) - w[0] * dt, (c == 1 ? -Nj : 0.0) - w[1] * dt};
    out->dgap[j] = -Nj * n[c];
    out->dslip[j] = un * (n[0] * da[0] + n[1] * da[1]) / la + tau[0] * du[0] + tau[1] * du[1];
  }
}

}  // namespace

PairKinematics curve_node(const double q[12], const double q0[12], bool hessians, int *beyond) {
  if (beyond) *beyond = 0;
  PairKinematics k;
  k.ndof = kN;
  double P[5][2];
  for (int j = 0; j < 5; ++j)
    for (int c = 0; c < 2; ++c) P[j][c] = q[2 * j + c];
  const double p[2] = {q[10], q[11]};
  // Closest point on the two segments m1 -> m2 (k = 0) and m2 -> m3 (k = 1).
  double t[2] = {0.0, 0.0}, dist[2] = {0.0, 0.0};
  bool ok[2];
  for (int s = 0; s < 2; ++s) ok[s] = project(P, s, p, &t[s], &dist[s]);
  const bool in0 = ok[0] && t[0] >= 0.0 && t[0] <= 1.0, in1 = ok[1] && t[1] >= 0.0 && t[1] <= 1.0;
  int seg;
  if (in0 && in1) {
    seg = dist[0] <= dist[1] ? 0 : 1;
  } else if (in0 || in1) {
    seg = in0 ? 0 : 1;
  } else if (ok[0] && t[0] < 0.0) {
    seg = 0;  // before m1: the extrapolated first segment, re-centre the patch
    if (beyond) *beyond = -1;
  } else if (ok[1] && t[1] > 1.0) {
    seg = 1;
    if (beyond) *beyond = 1;
  } else if (ok[0] || ok[1]) {
    seg = ok[0] ? 0 : 1;  // both stationary points just past the shared node m2 (round-off)
    t[seg] = seg == 0 ? 1.0 : 0.0;
  } else {
    // No projection (degenerate patch or a node far on the concave side):
    // report the distance to m2 as an open gap, without a normal.
    k.gap = std::hypot(p[0] - q[4], p[1] - q[5]);
    return k;
  }
  // Degenerate tangent (collapsed segments): no normal.
  {
    double x[2], a[2], b[2];
    curve_point(P, seg, t[seg], x, a, b);
    const double scale = std::hypot(q[6] - q[2], q[7] - q[3]);
    if (!(std::hypot(a[0], a[1]) > 1e-12 * scale)) {
      k.gap = std::hypot(p[0] - x[0], p[1] - x[1]);
      return k;
    }
  }
  if (hessians)
    second_derivatives(q, q0, seg, t[seg], &k);
  else
    first_derivatives(q, q0, seg, t[seg], &k);
  return k;
}

}  // namespace deformix

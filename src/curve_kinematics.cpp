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

// A rigid disk against the smooth curve of a deformable boundary, over the
// cell of boundary node m2 (the parameters t in [1/2, 1] of segment m1 -> m2
// (s = 0) and [0, 1/2] of m2 -> m3 (s = 1); t_s = 1 or 0 is the node):
//   g = min over the cell of  psi(t) = |c - x(t)| - rA + (w / 2) (t - t_s)^2,
//   w = beta h^2 / rA  (h the reference node spacing).
// With w = 0 this is the distance from the disk to the curve, without the
// node-to-node bumps of rigid_node; but where the boundary wraps around the
// disk (a conforming contact) |c - x(t)| is nearly constant over the cell,
// the closest point is undetermined and the gap's Hessian (through
// dt*/dq = -psi_tq / psi_tt) unbounded. The pull towards the node keeps
// psi_tt >= w (1 / h^2 in t) there; on a straight boundary it leaves bumps
// of beta / (1 + beta) of rigid_node's (beta -> infinity is rigid_node;
// beta = kRigidCurvePull).
// Where the minimum lies inside the cell: psi at t*(q) (psi_t = 0), with
// the derivatives of the implicit function theorem as in curve_node; at
// the cell's end: the fixed material point x(1/2), i.e. rigid_node against
// it, plus w / 8. At the hand-over the two agree in value and gradient.
namespace {

// psi and its first two t-derivatives on segment s (see rigid_curve).
void cell_objective(const double P[5][2], int s, double t, const double c[2], double w, double *psi, double *dpsi,
                    double *d2psi) {
  double x[2], a[2], b[2];
  curve_point(P, s, t, x, a, b);
  const double r[2] = {c[0] - x[0], c[1] - x[1]};
  const double L = std::hypot(r[0], r[1]), ra = r[0] * a[0] + r[1] * a[1];
  const double dt = t - (s == 0 ? 1.0 : 0.0);
  *psi = L + 0.5 * w * dt * dt;
  *dpsi = -ra / L + w * dt;
  *d2psi = (a[0] * a[0] + a[1] * a[1] - r[0] * b[0] - r[1] * b[1]) / L - ra * ra / (L * L * L) + w;
}

// The minimum of psi over the cell's half on segment s: at an end of the
// half where psi rises into it, else the root of psi_t bracketed by the
// half (safeguarded Newton).
void half_minimum(const double P[5][2], int s, const double c[2], double w, double *t_out, double *psi_out) {
  double lo = s == 0 ? 0.5 : 0.0, hi = s == 0 ? 1.0 : 0.5, psi, dpsi, d2psi;
  cell_objective(P, s, lo, c, w, &psi, &dpsi, &d2psi);
  if (dpsi >= 0.0) {
    *t_out = lo, *psi_out = psi;
    return;
  }
  cell_objective(P, s, hi, c, w, &psi, &dpsi, &d2psi);
  if (dpsi <= 0.0) {
    *t_out = hi, *psi_out = psi;
    return;
  }
  double t = 0.5 * (lo + hi);
  for (int it = 0; it < 100 && hi - lo > 1e-15; ++it) {
    cell_objective(P, s, t, c, w, &psi, &dpsi, &d2psi);
    (dpsi < 0.0 ? lo : hi) = t;
    const double newton = d2psi > 0.0 ? t - dpsi / d2psi : lo - 1.0;
    const double next = newton > lo && newton < hi ? newton : 0.5 * (lo + hi);
    if (std::fabs(next - t) < 1e-15) break;
    t = next;
  }
  cell_objective(P, s, t, c, w, &psi, &dpsi, &d2psi);
  *t_out = t, *psi_out = psi;
}

}  // namespace

PairKinematics rigid_curve(const double q[13], const double q0[13], double rA, double spacing, bool hessians) {
  PairKinematics k;
  k.ndof = 13;
  double P[5][2];
  for (int j = 0; j < 5; ++j)
    for (int c = 0; c < 2; ++c) P[j][c] = q[3 + 2 * j + c];
  const double centre[2] = {q[0], q[1]};
  const double w = kRigidCurvePull * spacing * spacing / rA;
  int seg = 0;
  double t = 0.0, psi = std::numeric_limits<double>::infinity();
  for (int s = 0; s < 2; ++s) {
    double ts, ps;
    half_minimum(P, s, centre, w, &ts, &ps);
    if (ps < psi) seg = s, t = ts, psi = ps;
  }
  if (t != 0.5 && !hessians) {
    // Inside the cell, first derivatives in closed form (the residual's; most
    // candidates carry no force). With r = c - x(t), L = |r|, e = r / L,
    // a = x', b = x'', u = (c - c0) - sum_i N_i (m_i - m0_i):
    //   dg = e . (dc - sum_i N_i dm_i)                        (envelope: psi_t = 0)
    //   f = psi_t = -(r . a) / L + w (t - t_s),  f_t = (a . a - r . b) / L - (r . a)^2 / L^3 + w,
    //   f_c = -a_perp / L,  f_m_i = N_i a_perp / L - N_i' e   (a_perp = a - (e . a) e),
    //   ds = sigma_q dq + sigma_t dt*,  dt* = -f_q dq / f_t,  sigma = tau . u.
    double N[4], dN[4], d2N[4], x[2] = {0, 0}, a[2] = {0, 0}, b[2] = {0, 0}, u[2], du_t[2] = {0, 0};
    basis(t, N, dN, d2N);
    for (int c = 0; c < 2; ++c) {
      u[c] = q[c] - q0[c];
      for (int i = 0; i < 4; ++i) {
        const double Pc = q[3 + 2 * (seg + i) + c], dP = Pc - q0[3 + 2 * (seg + i) + c];
        x[c] += N[i] * Pc, a[c] += dN[i] * Pc, b[c] += d2N[i] * Pc;
        u[c] -= N[i] * dP, du_t[c] -= dN[i] * dP;
      }
    }
    const double r[2] = {q[0] - x[0], q[1] - x[1]}, L = std::hypot(r[0], r[1]);
    const double e[2] = {r[0] / L, r[1] / L}, ea = e[0] * a[0] + e[1] * a[1], ra = L * ea;
    const double a_perp[2] = {a[0] - ea * e[0], a[1] - ea * e[1]};
    const double la = std::hypot(a[0], a[1]), tau[2] = {a[0] / la, a[1] / la};
    const double ut = u[0] * tau[0] + u[1] * tau[1], u_perp[2] = {u[0] - ut * tau[0], u[1] - ut * tau[1]};
    const double dt = t - (seg == 0 ? 1.0 : 0.0);
    const double f_t = (a[0] * a[0] + a[1] * a[1] - r[0] * b[0] - r[1] * b[1]) / L - ra * ra / (L * L * L) + w;
    const double sigma_t = (du_t[0] * a[0] + du_t[1] * a[1] + u[0] * b[0] + u[1] * b[1]) / la -
                           ut * (a[0] * b[0] + a[1] * b[1]) / (la * la);
    k.gap = L + 0.5 * w * dt * dt - rA;
    k.slip = ut - rA * (q[2] - q0[2]);
    k.normal[0] = -e[0], k.normal[1] = -e[1];
    for (int c = 0; c < 2; ++c) {
      k.dgap[c] = e[c];
      k.dslip[c] = tau[c] + sigma_t * (a_perp[c] / L) / f_t;
      for (int i = 0; i < 4; ++i) {
        const int j = 3 + 2 * (seg + i) + c;
        const double f_m = N[i] * a_perp[c] / L - dN[i] * e[c];
        k.dgap[j] = -N[i] * e[c];
        k.dslip[j] = -N[i] * tau[c] + dN[i] * u_perp[c] / la - sigma_t * f_m / f_t;
      }
    }
    k.dslip[2] = -rA;
    return k;
  }
  if (t != 0.5) {
    // Inside the cell with second derivatives: psi(q, t) in forward mode
    // over the segment's four nodes (variables 0..7), the centre (8, 9) and
    // t (10).
    double Nb[4], dNb[4], d2Nb[4];
    basis(t, Nb, dNb, d2Nb);
    const double d3N[4] = {-3.0, 9.0, -9.0, 3.0};
    Ad x[2], a[2], u[2], r[2];
    for (int c = 0; c < 2; ++c) {
      for (int i = 0; i < 4; ++i) {
        const double Pc = q[3 + 2 * (seg + i) + c], dP = Pc - q0[3 + 2 * (seg + i) + c];
        const int v = 2 * i + c;
        x[c].v += Nb[i] * Pc, x[c].g[v] = Nb[i], x[c].g[kT] += dNb[i] * Pc, x[c].h[packed(kT, kT)] += d2Nb[i] * Pc;
        a[c].v += dNb[i] * Pc, a[c].g[v] = dNb[i], a[c].g[kT] += d2Nb[i] * Pc, a[c].h[packed(kT, kT)] += d3N[i] * Pc;
        u[c].v -= Nb[i] * dP, u[c].g[v] = -Nb[i], u[c].g[kT] -= dNb[i] * dP, u[c].h[packed(kT, kT)] -= d2Nb[i] * dP;
        x[c].h[packed(v, kT)] = dNb[i], a[c].h[packed(v, kT)] = d2Nb[i], u[c].h[packed(v, kT)] = -dNb[i];
      }
      Ad p(q[c]);
      p.g[8 + c] = 1.0;
      r[c] = p - x[c];
      u[c].v += q[c] - q0[c], u[c].g[8 + c] = 1.0;
    }
    Ad dt(t - (seg == 0 ? 1.0 : 0.0));
    dt.g[kT] = 1.0;
    const Ad rr = r[0] * r[0] + r[1] * r[1], inv_L = inv_sqrt(rr);
    const Ad half_w(0.5 * w), w_ad(w);
    const Ad gap = rr * inv_L + half_w * dt * dt;                                // psi + rA
    const Ad f = w_ad * dt - (r[0] * a[0] + r[1] * a[1]) * inv_L;                 // psi_t
    const Ad slip = (u[0] * a[0] + u[1] * a[1]) * inv_sqrt(a[0] * a[0] + a[1] * a[1]);
    constexpr int nq = kV - 1;
    const double f_t = f.g[kT];
    double tq[nq], tqq[nq][nq];
    for (int v = 0; v < nq; ++v) tq[v] = -f.g[v] / f_t;
    const auto second = [&](const Ad &g, int v, int w2) {
      return g.h[packed(v, w2)] + g.h[packed(v, kT)] * tq[w2] + tq[v] * g.h[packed(w2, kT)] + g.h[packed(kT, kT)] * tq[v] * tq[w2];
    };
    for (int v = 0; v < nq; ++v)
      for (int w2 = v; w2 < nq; ++w2) tqq[v][w2] = tqq[w2][v] = -second(f, v, w2) / f_t;
    const auto unknown = [seg](int v) { return v < 8 ? 3 + 2 * seg + v : v - 8; };
    k.gap = gap.v - rA;
    k.slip = slip.v - rA * (q[2] - q0[2]);  // the disk's contact point turns with it
    k.normal[0] = -r[0].v * inv_L.v, k.normal[1] = -r[1].v * inv_L.v;  // from the disk towards the curve
    for (int v = 0; v < nq; ++v) {
      k.dgap[unknown(v)] = gap.g[v] + gap.g[kT] * tq[v];
      k.dslip[unknown(v)] = slip.g[v] + slip.g[kT] * tq[v];
      if (!hessians) continue;
      for (int w2 = v; w2 < nq; ++w2) {
        const double hg = second(gap, v, w2) + gap.g[kT] * tqq[v][w2], hs = second(slip, v, w2) + slip.g[kT] * tqq[v][w2];
        k.d2gap[unknown(v) * 13 + unknown(w2)] = k.d2gap[unknown(w2) * 13 + unknown(v)] = hg;
        k.d2slip[unknown(v) * 13 + unknown(w2)] = k.d2slip[unknown(w2) * 13 + unknown(v)] = hs;
      }
    }
    k.dslip[2] = -rA;
    return k;
  }
  // The cell's end x(1/2) of segment seg: a fixed combination of four nodes.
  double N[4], dN[4], d2N[4], xe[2] = {0, 0}, xe0[2] = {0, 0};
  basis(0.5, N, dN, d2N);
  for (int c = 0; c < 2; ++c)
    for (int i = 0; i < 4; ++i) xe[c] += N[i] * q[3 + 2 * (seg + i) + c], xe0[c] += N[i] * q0[3 + 2 * (seg + i) + c];
  const double ql[5] = {q[0], q[1], q[2], xe[0], xe[1]}, ql0[5] = {q0[0], q0[1], q0[2], xe0[0], xe0[1]};
  const PairKinematics pk = rigid_node(ql, ql0, rA);
  k.gap = pk.gap + 0.125 * w, k.slip = pk.slip, k.normal[0] = pk.normal[0], k.normal[1] = pk.normal[1];
  // Local unknown l of rigid_node -> (unknowns of q, coefficients).
  int map_n[5], map_i[5][4];
  double map_c[5][4];
  for (int l = 0; l < 3; ++l) map_n[l] = 1, map_i[l][0] = l, map_c[l][0] = 1.0;
  for (int c = 0; c < 2; ++c) {
    map_n[3 + c] = 4;
    for (int i = 0; i < 4; ++i) map_i[3 + c][i] = 3 + 2 * (seg + i) + c, map_c[3 + c][i] = N[i];
  }
  for (int l = 0; l < 5; ++l)
    for (int a = 0; a < map_n[l]; ++a) {
      k.dgap[map_i[l][a]] += map_c[l][a] * pk.dgap[l];
      k.dslip[map_i[l][a]] += map_c[l][a] * pk.dslip[l];
      if (!hessians) continue;
      for (int m = 0; m < 5; ++m)
        for (int b = 0; b < map_n[m]; ++b) {
          k.d2gap[map_i[l][a] * 13 + map_i[m][b]] += map_c[l][a] * map_c[m][b] * pk.d2gap[l * 5 + m];
          k.d2slip[map_i[l][a] * 13 + map_i[m][b]] += map_c[l][a] * map_c[m][b] * pk.d2slip[l * 5 + m];
        }
    }
  return k;
}

}  // namespace deformix

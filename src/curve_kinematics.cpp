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
// from forward-mode automatic differentiation (value, gradient, Hessian),
// with t*(q) differentiated through the implicit function theorem in the
// Newton form: t*(q) is found in double precision, then two Newton steps
// t <- t - f / f_t are taken in AD arithmetic starting from the constant t*.
// Each step doubles the order of the derivatives that are exact (the value
// is already converged): one step gives exact first derivatives, two give
// exact second derivatives.
#include <algorithm>
#include <cmath>
#include <limits>

#include "deformix/pair_kinematics.hpp"

namespace deformix {

namespace {

constexpr int kN = 12;                   // unknowns of the pair
constexpr int kH = kN * (kN + 1) / 2;    // packed symmetric Hessian

inline int packed(int i, int j) { return i <= j ? i * kN - i * (i - 1) / 2 + (j - i) : packed(j, i); }

// Second-order forward-mode number: value, gradient and (if Hess) the
// packed symmetric Hessian with respect to the kN unknowns.
template <bool Hess>
struct Ad {
  double v = 0.0;
  double g[kN] = {};
  double h[Hess ? kH : 1] = {};
  Ad() = default;
  explicit Ad(double value) : v(value) {}
  static Ad variable(double value, int i) {
    Ad a(value);
    a.g[i] = 1.0;
    return a;
  }
};

template <bool H>
Ad<H> operator+(const Ad<H> &a, const Ad<H> &b) {
  Ad<H> r(a.v + b.v);
  for (int i = 0; i < kN; ++i) r.g[i] = a.g[i] + b.g[i];
  if constexpr (H)
    for (int i = 0; i < kH; ++i) r.h[i] = a.h[i] + b.h[i];
  return r;
}

template <bool H>
Ad<H> operator-(const Ad<H> &a, const Ad<H> &b) {
  Ad<H> r(a.v - b.v);
  for (int i = 0; i < kN; ++i) r.g[i] = a.g[i] - b.g[i];
  if constexpr (H)
    for (int i = 0; i < kH; ++i) r.h[i] = a.h[i] - b.h[i];
  return r;
}

template <bool H>
Ad<H> operator*(double s, const Ad<H> &a) {
  Ad<H> r(s * a.v);
  for (int i = 0; i < kN; ++i) r.g[i] = s * a.g[i];
  if constexpr (H)
    for (int i = 0; i < kH; ++i) r.h[i] = s * a.h[i];
  return r;
}

template <bool H>
Ad<H> operator*(const Ad<H> &a, const Ad<H> &b) {
  Ad<H> r(a.v * b.v);
  for (int i = 0; i < kN; ++i) r.g[i] = a.v * b.g[i] + b.v * a.g[i];
  if constexpr (H) {
    int k = 0;
    for (int i = 0; i < kN; ++i)
      for (int j = i; j < kN; ++j, ++k) r.h[k] = a.v * b.h[k] + b.v * a.h[k] + a.g[i] * b.g[j] + a.g[j] * b.g[i];
  }
  return r;
}

// f(a) for a scalar function with derivatives f1 = f'(a.v), f2 = f''(a.v).
template <bool H>
Ad<H> chain(const Ad<H> &a, double f, double f1, double f2) {
  Ad<H> r(f);
  for (int i = 0; i < kN; ++i) r.g[i] = f1 * a.g[i];
  if constexpr (H) {
    int k = 0;
    for (int i = 0; i < kN; ++i)
      for (int j = i; j < kN; ++j, ++k) r.h[k] = f1 * a.h[k] + f2 * a.g[i] * a.g[j];
  }
  return r;
}

template <bool H>
Ad<H> inv(const Ad<H> &a) {
  const double r = 1.0 / a.v;
  return chain(a, r, -r * r, 2.0 * r * r * r);
}

template <bool H>
Ad<H> sqrt(const Ad<H> &a) {
  const double s = std::sqrt(a.v);
  return chain(a, s, 0.5 / s, -0.25 / (s * a.v));
}

// Catmull-Rom basis and its first two derivatives at t (any scalar type).
template <class T>
void basis(const T &t, T N[4], T dN[4], T d2N[4]) {
  const T one(1.0);
  const T t2 = t * t, t3 = t2 * t;
  N[0] = (-0.5) * t + t2 - 0.5 * t3;
  N[1] = one - 2.5 * t2 + 1.5 * t3;
  N[2] = 0.5 * t + 2.0 * t2 - 1.5 * t3;
  N[3] = (-0.5) * t2 + 0.5 * t3;
  dN[0] = T(-0.5) + 2.0 * t - 1.5 * t2;
  dN[1] = (-5.0) * t + 4.5 * t2;
  dN[2] = T(0.5) + 4.0 * t - 4.5 * t2;
  dN[3] = (-1.0) * t + 1.5 * t2;
  d2N[0] = T(2.0) - 3.0 * t;
  d2N[1] = T(-5.0) + 9.0 * t;
  d2N[2] = T(4.0) - 9.0 * t;
  d2N[3] = T(-1.0) + 3.0 * t;
}

// Plain doubles with the same interface as Ad (for the projection).
struct Real {
  double v;
  Real(double x = 0.0) : v(x) {}
};
inline Real operator+(Real a, Real b) { return a.v + b.v; }
inline Real operator-(Real a, Real b) { return a.v - b.v; }
inline Real operator*(Real a, Real b) { return a.v * b.v; }
inline Real operator*(double s, Real a) { return s * a.v; }

// Point, tangent and second derivative of segment k (nodes k .. k+3 of the
// five patch nodes P) at t.
template <class T>
void curve_point(const T P[5][2], int k, const T &t, T x[2], T a[2], T b[2]) {
  T N[4], dN[4], d2N[4];
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
bool project(const Real P[5][2], int k, const double p[2], double *t_out, double *dist) {
  const double ex = P[k + 2][0].v - P[k + 1][0].v, ey = P[k + 2][1].v - P[k + 1][1].v;
  const double l2 = ex * ex + ey * ey;
  if (!(l2 > 0.0)) return false;
  double t = std::clamp(((p[0] - P[k + 1][0].v) * ex + (p[1] - P[k + 1][1].v) * ey) / l2, -0.5, 1.5);
  for (int it = 0; it < 30; ++it) {
    Real x[2], a[2], b[2];
    curve_point(P, k, Real(t), x, a, b);
    const double rx = p[0] - x[0].v, ry = p[1] - x[1].v;
    const double f = rx * a[0].v + ry * a[1].v;
    const double df = -(a[0].v * a[0].v + a[1].v * a[1].v) + rx * b[0].v + ry * b[1].v;
    if (!(df < 0.0)) return false;  // not a minimum of the distance: the node is far on the concave side
    const double dt = -f / df;
    t = std::clamp(t + dt, -1.0, 2.0);
    if (std::fabs(dt) < 1e-15) break;
  }
  Real x[2], a[2], b[2];
  curve_point(P, k, Real(t), x, a, b);
  *t_out = t;
  *dist = std::hypot(p[0] - x[0].v, p[1] - x[1].v);
  return true;
}

// Gap, slip and their derivatives on segment k around the converged t.
template <bool H>
void evaluate(const double q[12], const double q0[12], int k, double t_star, PairKinematics *out) {
  using T = Ad<H>;
  T P[5][2], p[2];
  for (int j = 0; j < 5; ++j)
    for (int c = 0; c < 2; ++c) P[j][c] = T::variable(q[2 * j + c], 2 * j + c);
  for (int c = 0; c < 2; ++c) p[c] = T::variable(q[10 + c], 10 + c);
  // t*(q): two Newton steps in AD from the converged value.
  T t(t_star);
  T x[2], a[2], b[2];
  for (int step = 0; step < (H ? 2 : 1); ++step) {
    curve_point(P, k, t, x, a, b);
    const T r0 = p[0] - x[0], r1 = p[1] - x[1];
    const T f = r0 * a[0] + r1 * a[1];
    const T df = r0 * b[0] + r1 * b[1] - (a[0] * a[0] + a[1] * a[1]);
    t = t - f * inv(df);
  }
  curve_point(P, k, t, x, a, b);
  const T inv_len = inv(sqrt(a[0] * a[0] + a[1] * a[1]));
  // n = (a_y, -a_x) / |a|,  tau = a / |a|.
  const T gap = ((p[0] - x[0]) * a[1] - (p[1] - x[1]) * a[0]) * inv_len;
  T N[4], dN[4], d2N[4];
  basis(t, N, dN, d2N);
  T u[2];
  for (int c = 0; c < 2; ++c) {
    u[c] = p[c] - T(q0[10 + c]);
    for (int i = 0; i < 4; ++i) u[c] = u[c] - N[i] * (P[k + i][c] - T(q0[2 * (k + i) + c]));
  }
  const T slip = (u[0] * a[0] + u[1] * a[1]) * inv_len;

  out->ndof = kN;
  out->gap = gap.v;
  out->slip = slip.v;
  out->normal[0] = a[1].v * inv_len.v;
  out->normal[1] = -a[0].v * inv_len.v;
  for (int i = 0; i < kN; ++i) out->dgap[i] = gap.g[i], out->dslip[i] = slip.g[i];
  if constexpr (H)
    for (int i = 0; i < kN; ++i)
      for (int j = 0; j < kN; ++j) {
        out->d2gap[i * kN + j] = gap.h[packed(i, j)];
        out->d2slip[i * kN + j] = slip.h[packed(i, j)];
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
  {
    Real Nr[4], dNr[4], d2Nr[4];
    basis(Real(t), Nr, dNr, d2Nr);
    for (int i = 0; i < 4; ++i) N[i] = Nr[i].v, dN[i] = dNr[i].v, d2N[i] = d2Nr[i].v;
  }
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
  Real P[5][2];
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
    Real x[2], a[2], b[2];
    curve_point(P, seg, Real(t[seg]), x, a, b);
    const double scale = std::hypot(q[6] - q[2], q[7] - q[3]);
    if (!(std::hypot(a[0].v, a[1].v) > 1e-12 * scale)) {
      k.gap = std::hypot(p[0] - x[0].v, p[1] - x[1].v);
      return k;
    }
  }
  if (hessians)
    evaluate<true>(q, q0, seg, t[seg], &k);
  else
    first_derivatives(q, q0, seg, t[seg], &k);
  return k;
}

}  // namespace deformix

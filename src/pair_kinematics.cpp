// Contact kinematics of the mixture's pair types (see pair_kinematics.hpp):
// gap, incremental slip and their exact first and second derivatives.
//
// Every pair is written in terms of at most two 2-vectors that are linear in
// the local unknowns q, so that the chain rule to q is a block map with
// coefficients in {-1, 0, +1}:
//   rigid-rigid / rigid-node:  d = c_B - c_A           (c_B = p for a node)
//   segment-node:              r = p - a,  e = b - a
// and (rigid pairs only) a part linear in the rotation angles. Gradients and
// Hessians are first formed with respect to these vectors, then scattered.
//
// Useful identities (L = |d|, n = d/L, t = J n, J = rotation by +90 deg;
// l = |e|, tau = e/l):
//   d n / d d = t t^T / L,  d t / d d = -n t^T / L,
//   for a constant c:  Hess_d (n . c) = -[(c.t)(n t^T + t n^T) + (c.n) t t^T] / L^2,
//   and the same with (d, n, t) -> (e, tau, n) for tau(e) . c.
//
// Rigid pairs. Delta c_B - Delta c_A = d - d0 and t . d = 0, so
//   s = -t(d) . d0 - r_A Delta theta_A - r_B Delta theta_B,
//   dg/dd = n,                      d2g/dd2 = t t^T / L,
//   ds/dd = (n . d0) t / L,         d2s/dd2 = [(t.d0) t t^T - (n.d0)(n t^T + t n^T)] / L^2,
//   ds/dtheta_A = -r_A, ds/dtheta_B = -r_B (no second derivatives in theta).
//
// Segment-node. n = right normal of tau = (tau_y, -tau_x) (the outward normal
// of a counter-clockwise boundary), t = J n = tau, xi = r.e / l^2,
// r = xi l tau + g n. With r0 = p0 - a0, e0 = b0 - a0 and
// Delta p - (1 - xi) Delta a - xi Delta b = (r - r0) - xi (e - e0):
//   s = tau . (r - r0) - xi tau . (e - e0) = xi gamma - rho,
//   gamma(e) = tau . e0,   rho(e) = tau . r0   (tau . r = xi l cancels).
// Derivatives of xi:
//   dxi/dr = tau / l,                dxi/de = (g / l^2) n - (xi / l) tau,
//   d2xi/dr de = (n n^T - tau tau^T) / l^2,
//   d2xi/de2 = (2 xi / l^2)(tau tau^T - n n^T) - (2 g / l^3)(n tau^T + tau n^T).
// Gap g = r . n(e), with dn/de = -tau n^T / l:
//   dg/dr = n,   dg/de = -xi n,
//   d2g/dr de = -tau n^T / l,   d2g/de2 = -(g / l^2) n n^T + (xi / l)(n tau^T + tau n^T).
// Slip:
//   ds/dr = gamma tau / l,   ds/de = gamma dxi/de + xi dgamma/de - drho/de,
//   d2s/dr2 = 0,
//   d2s/dr de = gamma d2xi/dr de + (tau / l) dgamma/de^T,
//   d2s/de2 = gamma d2xi/de2 + dxi/de dgamma/de^T + dgamma/de dxi/de^T
//             + xi d2gamma/de2 - d2rho/de2,
//   dgamma/de = (n . e0) n / l,  d2gamma/de2 = -[(e0.n)(tau n^T + n tau^T) + (e0.tau) n n^T] / l^2,
//   and rho likewise with r0.

#include "deformix/pair_kinematics.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace deformix {

namespace {

// A length below kDegenerateRel times the configuration's length scale is
// treated as zero (coincident centres, collapsed segment).
constexpr double kDegenerateRel = 1e-12;

struct V2 {
  double x, y;
};

inline double dot(V2 a, V2 b) { return a.x * b.x + a.y * b.y; }
inline V2 operator*(double s, V2 a) { return {s * a.x, s * a.y}; }
inline V2 operator+(V2 a, V2 b) { return {a.x + b.x, a.y + b.y}; }
inline V2 operator-(V2 a, V2 b) { return {a.x - b.x, a.y - b.y}; }

// Symmetric or general 2x2 matrix, row-major.
struct M2 {
  double a[2][2];
};

inline M2 outer(V2 u, V2 v) { return {{{u.x * v.x, u.x * v.y}, {u.y * v.x, u.y * v.y}}}; }
inline M2 sym_outer(V2 u, V2 v) {  // u v^T + v u^T
  const double xy = u.x * v.y + u.y * v.x;
  return {{{2.0 * u.x * v.x, xy}, {xy, 2.0 * u.y * v.y}}};
}
inline M2 operator*(double s, M2 m) { return {{{s * m.a[0][0], s * m.a[0][1]}, {s * m.a[1][0], s * m.a[1][1]}}}; }
inline M2 operator+(M2 p, M2 q) {
  return {{{p.a[0][0] + q.a[0][0], p.a[0][1] + q.a[0][1]}, {p.a[1][0] + q.a[1][0], p.a[1][1] + q.a[1][1]}}};
}
inline M2 operator-(M2 p, M2 q) { return p + (-1.0) * q; }
inline M2 transpose(M2 m) { return {{{m.a[0][0], m.a[1][0]}, {m.a[0][1], m.a[1][1]}}}; }

// Hessian of f(v) = u(v) . c for a unit vector u = v/|v|, w its perpendicular
// unit vector and len = |v|: -[(c.w)(u w^T + w u^T) + (c.u) w w^T] / len^2.
inline M2 hess_unit_dot(V2 u, V2 w, double len, V2 c) {
  return (-1.0 / (len * len)) * (dot(c, w) * sym_outer(u, w) + dot(c, u) * outer(w, w));
}

// Scatter of the derivatives with respect to up to two 2-vectors z_k (k = 0, 1)
// that depend linearly on 2-dof blocks X of q: z_k = sum_X coef[k][X] q_X.
// grad[k] = df/dz_k, hess[k][m] = d2f/dz_k dz_m (hess[1][0] = hess[0][1]^T).
struct Scatter {
  int nz;                 // number of vectors z_k (1 or 2)
  int nblocks;            // number of 2-dof blocks of q that they depend on
  int offset[3];          // first dof of each block in q
  double coef[2][3];      // coef[k][X]
};

void scatter(const Scatter &map, int ndof, const V2 grad[2], const M2 hess[2][2], double *dq, double *d2q) {
  for (int X = 0; X < map.nblocks; ++X) {
    V2 gX{0.0, 0.0};
    for (int k = 0; k < map.nz; ++k) gX = gX + map.coef[k][X] * grad[k];
    dq[map.offset[X]] += gX.x;
    dq[map.offset[X] + 1] += gX.y;
    for (int Y = 0; Y < map.nblocks; ++Y) {
      M2 HXY{{{0.0, 0.0}, {0.0, 0.0}}};
      for (int k = 0; k < map.nz; ++k)
        for (int m = 0; m < map.nz; ++m) {
          const double c = map.coef[k][X] * map.coef[m][Y];
          if (c != 0.0) HXY = HXY + c * hess[k][m];
        }
      for (int i = 0; i < 2; ++i)
        for (int j = 0; j < 2; ++j) d2q[(map.offset[X] + i) * ndof + map.offset[Y] + j] += HXY.a[i][j];
    }
  }
}

// Shared by rigid_rigid (node_B = false) and rigid_node (node_B = true: B is a
// point with r_B = 0 and no rotation). Layout: A = (x, y, theta) at 0..2,
// B centre at 3..4, theta_B at 5 for a rigid B.
PairKinematics rigid_pair(const double q[], const double q0[], double rA, double rB, bool node_B) {
  PairKinematics k;
  k.ndof = node_B ? 5 : 6;
  const V2 d{q[3] - q[0], q[4] - q[1]};
  const V2 d0{q0[3] - q0[0], q0[4] - q0[1]};
  const double L = std::hypot(d.x, d.y);
  const double scale = std::fabs(rA) + std::fabs(rB) + std::hypot(d0.x, d0.y);
  k.gap = L - rA - rB;
  if (!(L > kDegenerateRel * scale)) return k;  // coincident centres: no normal, zero derivatives

  const V2 n = (1.0 / L) * d;
  const V2 t{-n.y, n.x};
  k.normal[0] = n.x;
  k.normal[1] = n.y;
  const double dthA = q[2] - q0[2];
  const double dthB = node_B ? 0.0 : q[5] - q0[5];
  const double nd0 = dot(n, d0), td0 = dot(t, d0);
  k.slip = -td0 - rA * dthA - rB * dthB;

  // z_0 = d = c_B - c_A; blocks: c_A at 0, c_B at 3.
  const Scatter map{1, 2, {0, 3, 0}, {{-1.0, 1.0, 0.0}, {0.0, 0.0, 0.0}}};
  const M2 zero{{{0.0, 0.0}, {0.0, 0.0}}};

  const V2 gg[2] = {n, {0.0, 0.0}};
  const M2 hg[2][2] = {{(1.0 / L) * outer(t, t), zero}, {zero, zero}};
  scatter(map, k.ndof, gg, hg, k.dgap, k.d2gap);

  const V2 gs[2] = {(nd0 / L) * t, {0.0, 0.0}};
  const M2 hs[2][2] = {{(1.0 / (L * L)) * (td0 * outer(t, t) - nd0 * sym_outer(n, t)), zero}, {zero, zero}};
  scatter(map, k.ndof, gs, hs, k.dslip, k.d2slip);
  k.dslip[2] = -rA;
  if (!node_B) k.dslip[5] = -rB;
  return k;
}

}  // namespace

PairKinematics rigid_rigid(const double q[6], const double q0[6], double rA, double rB) {
  return rigid_pair(q, q0, rA, rB, false);
}

PairKinematics rigid_node(const double q[5], const double q0[5], double rA) {
  return rigid_pair(q, q0, rA, 0.0, true);
}

PairKinematics segment_node(const double q[6], const double q0[6]) {
  PairKinematics k;
  k.ndof = 6;
  const V2 a{q[0], q[1]}, b{q[2], q[3]}, p{q[4], q[5]};
  const V2 a0{q0[0], q0[1]}, b0{q0[2], q0[3]}, p0{q0[4], q0[5]};
  const V2 e = b - a, r = p - a;
  const V2 e0 = b0 - a0, r0 = p0 - a0;
  const double l = std::hypot(e.x, e.y);
  const double rlen = std::hypot(r.x, r.y);
  const double scale = std::hypot(e0.x, e0.y) + rlen;
  if (!(l > kDegenerateRel * scale)) {
    // Collapsed segment: no normal; report the distance to its point a as an
    // (open, g >= 0) gap with zero derivatives.
    k.gap = rlen;
    return k;
  }

  const V2 tau = (1.0 / l) * e;
  const V2 n{tau.y, -tau.x};  // right normal of a -> b: outward for a counter-clockwise boundary
  // t = (-n_y, n_x) = tau.
  const double il = 1.0 / l, il2 = il * il;
  const double xi = dot(r, e) * il2;
  const double g = dot(r, n);
  k.gap = g;
  k.normal[0] = n.x;
  k.normal[1] = n.y;

  const double gamma = dot(tau, e0), rho = dot(tau, r0);
  k.slip = xi * gamma - rho;

  // z_0 = r = p - a, z_1 = e = b - a; blocks a at 0, b at 2, p at 4.
  const Scatter map{2, 3, {0, 2, 4}, {{-1.0, 0.0, 1.0}, {-1.0, 1.0, 0.0}}};
  const M2 zero{{{0.0, 0.0}, {0.0, 0.0}}};
  const M2 nn = outer(n, n), tt = outer(tau, tau), snt = sym_outer(n, tau);

  // Gap.
  {
    const V2 grad[2] = {n, (-xi) * n};
    const M2 Hre = (-il) * outer(tau, n);
    const M2 Hee = (-g * il2) * nn + (xi * il) * snt;
    const M2 hess[2][2] = {{zero, Hre}, {transpose(Hre), Hee}};
    scatter(map, k.ndof, grad, hess, k.dgap, k.d2gap);
  }

  // Slip.
  {
    const V2 dxi_dr = il * tau;
    const V2 dxi_de = (g * il2) * n - (xi * il) * tau;
    const M2 d2xi_dre = il2 * (nn - tt);
    const M2 d2xi_dee = (2.0 * xi * il2) * (tt - nn) - (2.0 * g * il2 * il) * snt;
    const V2 dgamma = (dot(n, e0) * il) * n;
    const V2 drho = (dot(n, r0) * il) * n;
    const M2 d2gamma = hess_unit_dot(tau, n, l, e0);
    const M2 d2rho = hess_unit_dot(tau, n, l, r0);

    const V2 grad[2] = {gamma * dxi_dr, gamma * dxi_de + xi * dgamma - drho};
    const M2 Hre = gamma * d2xi_dre + outer(dxi_dr, dgamma);
    const M2 Hee = gamma * d2xi_dee + sym_outer(dxi_de, dgamma) + xi * d2gamma - d2rho;
    const M2 hess[2][2] = {{zero, Hre}, {transpose(Hre), Hee}};
    scatter(map, k.ndof, grad, hess, k.dslip, k.d2slip);
  }
  return k;
}

}  // namespace deformix

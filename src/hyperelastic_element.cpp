// Plane-strain compressible neo-Hookean triangles (see
// include/deformix/hyperelastic_element.hpp).
//
// Material (F 2x2, F33 = 1, J = det F, F^-T = (F^-1)^T):
//   W = mu/2 (F:F + 1 - 3) - mu ln J + lambda/2 (ln J)^2
//   P = dW/dF = mu F + (lambda ln J - mu) F^-T
//   A_iJkL = dP_iJ/dF_kL
//          = mu d_ik d_JL + lambda F^-1_Lk F^-1_Ji - (lambda ln J - mu) F^-1_Jk F^-1_Li
// using d(ln J)/dF_kL = F^-1_Lk and d(F^-1_Ji)/dF_kL = -F^-1_Jk F^-1_Li.
// Lame parameters from (E, nu) in plane strain: mu = E / (2(1+nu)),
// lambda = E nu / ((1+nu)(1-2nu)).
//
// Element: Lagrange triangle on the unit reference triangle (xi, eta) with
// barycentrics L0 = 1-xi-eta, L1 = xi, L2 = eta; order 2 shape functions
// L_a(2L_a-1) at the vertices and 4 L_a L_b at the mid-edge nodes. The
// reference map X(xi) = sum_a X_a N_a(xi) is isoparametric, so at each
// quadrature point
//   J0 = dX/dxi,  grad_X N_a = J0^-T grad_xi N_a,  F = sum_a x_a (x) grad_X N_a,
//   f_ai  = sum_q w_q det J0 P_iJ dN_a/dX_J
//   K_aibk = sum_q w_q det J0 dN_a/dX_J A_iJkL dN_b/dX_L.
// Quadrature: order 1 has constant F on the affine map, so the centroid rule
// is exact; order 2 uses the 6-point degree-4 Dunavant rule, which integrates
// det J0 (degree 2) and cof(J0) grad_xi N_a (degree 2) exactly, so the
// reference area and the patch test hold to round-off on curved elements.
#include "deformix/hyperelastic_element.hpp"

#include <cmath>

namespace deformix {

NeoHookean NeoHookean::from_young_poisson(double E, double nu) {
  NeoHookean m;
  m.mu = E / (2.0 * (1.0 + nu));
  m.lambda = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
  return m;
}

namespace {

inline void inverse2(const double F[4], double J, double Finv[4]) {
  const double s = 1.0 / J;
  Finv[0] = F[3] * s;
  Finv[1] = -F[1] * s;
  Finv[2] = -F[2] * s;
  Finv[3] = F[0] * s;
}

// Energy, stress and (if A != nullptr) tangent at one point, sharing ln J and F^-1.
inline double evaluate(const NeoHookean &m, const double F[4], double P[4], double *A) {
  const double J = F[0] * F[3] - F[1] * F[2];
  const double lnJ = std::log(J);
  double Finv[4];
  inverse2(F, J, Finv);
  const double c = m.lambda * lnJ - m.mu;
  // P = mu F + c F^-T, with (F^-T)_iJ = F^-1_Ji.
  for (int i = 0; i < 2; ++i)
    for (int Jc = 0; Jc < 2; ++Jc) P[2 * i + Jc] = m.mu * F[2 * i + Jc] + c * Finv[2 * Jc + i];
  if (A) {
    for (int i = 0; i < 2; ++i)
      for (int Jc = 0; Jc < 2; ++Jc)
        for (int k = 0; k < 2; ++k)
          for (int L = 0; L < 2; ++L)
            A[(2 * i + Jc) * 4 + 2 * k + L] = (i == k && Jc == L ? m.mu : 0.0) +
                                               m.lambda * Finv[2 * L + k] * Finv[2 * Jc + i] -
                                               c * Finv[2 * Jc + k] * Finv[2 * L + i];
  }
  const double FF = F[0] * F[0] + F[1] * F[1] + F[2] * F[2] + F[3] * F[3];
  return 0.5 * m.mu * (FF - 2.0) - m.mu * lnJ + 0.5 * m.lambda * lnJ * lnJ;
}

// Quadrature points with the shape-function gradients tabulated once.
template <int NN, int NQ>
struct Rule {
  double weight[NQ];            // includes the reference-triangle area 1/2
  double dN[NQ][NN][2];         // dN_a/dxi, dN_a/deta
};

Rule<3, 1> make_rule_p1() {
  Rule<3, 1> r{};
  r.weight[0] = 0.5;
  const double d[3][2] = {{-1.0, -1.0}, {1.0, 0.0}, {0.0, 1.0}};
  for (int a = 0; a < 3; ++a)
    for (int k = 0; k < 2; ++k) r.dN[0][a][k] = d[a][k];
  return r;
}

Rule<6, 6> make_rule_p2() {
  // Dunavant (1985) degree 4: two orbits of three points (a, a, 1-2a).
  const double a1 = 0.44594849091596488632, w1 = 0.22338158967801146570;
  const double a2 = 0.09157621350977074346, w2 = 0.10995174365532186764;
  const double L[6][3] = {{1 - 2 * a1, a1, a1}, {a1, 1 - 2 * a1, a1}, {a1, a1, 1 - 2 * a1},
                          {1 - 2 * a2, a2, a2}, {a2, 1 - 2 * a2, a2}, {a2, a2, 1 - 2 * a2}};
  const double w[6] = {w1, w1, w1, w2, w2, w2};
  Rule<6, 6> r{};
  for (int q = 0; q < 6; ++q) {
    const double L0 = L[q][0], L1 = L[q][1], L2 = L[q][2];
    r.weight[q] = 0.5 * w[q];
    const double d[6][2] = {{1 - 4 * L0, 1 - 4 * L0}, {4 * L1 - 1, 0.0},       {0.0, 4 * L2 - 1},
                            {4 * (L0 - L1), -4 * L1}, {4 * L2, 4 * L1},       {-4 * L2, 4 * (L0 - L2)}};
    for (int a = 0; a < 6; ++a)
      for (int k = 0; k < 2; ++k) r.dN[q][a][k] = d[a][k];
  }
  return r;
}

const Rule<3, 1> rule_p1 = make_rule_p1();
const Rule<6, 6> rule_p2 = make_rule_p2();

template <int NN, int NQ>
ElementResult integrate(const NeoHookean &m, const Rule<NN, NQ> &rule, const double *X, const double *x, double *f,
                        double *K) {
  constexpr int ND = 2 * NN;
  ElementResult result;
  if (f)
    for (int r = 0; r < ND; ++r) f[r] = 0.0;
  if (K)
    for (int r = 0; r < ND * ND; ++r) K[r] = 0.0;

  for (int q = 0; q < NQ; ++q) {
    const double(*dN)[2] = rule.dN[q];
    double J0[4] = {0.0, 0.0, 0.0, 0.0};  // dX_i/dxi_alpha, row-major
    for (int a = 0; a < NN; ++a) {
      J0[0] += X[2 * a] * dN[a][0];
      J0[1] += X[2 * a] * dN[a][1];
      J0[2] += X[2 * a + 1] * dN[a][0];
      J0[3] += X[2 * a + 1] * dN[a][1];
    }
    const double det0 = J0[0] * J0[3] - J0[1] * J0[2];
    if (!(det0 > 0.0)) {
      result.inverted = true;
      return result;
    }
    double J0inv[4];
    inverse2(J0, det0, J0inv);
    double G[NN][2];  // dN_a/dX_J = dN_a/dxi_alpha (J0^-1)_alpha J
    double F[4] = {0.0, 0.0, 0.0, 0.0};
    for (int a = 0; a < NN; ++a) {
      G[a][0] = dN[a][0] * J0inv[0] + dN[a][1] * J0inv[2];
      G[a][1] = dN[a][0] * J0inv[1] + dN[a][1] * J0inv[3];
      F[0] += x[2 * a] * G[a][0];
      F[1] += x[2 * a] * G[a][1];
      F[2] += x[2 * a + 1] * G[a][0];
      F[3] += x[2 * a + 1] * G[a][1];
    }
    const double J = F[0] * F[3] - F[1] * F[2];
    if (!(J > 0.0)) {
      result.inverted = true;
      return result;
    }
    const double dA = rule.weight[q] * det0;
    double P[4], A[16];
    result.energy += dA * evaluate(m, F, P, K ? A : nullptr);
    result.area += dA * J;
    result.ref_area += dA;

    if (f)
      for (int a = 0; a < NN; ++a) {
        f[2 * a] += dA * (P[0] * G[a][0] + P[1] * G[a][1]);
        f[2 * a + 1] += dA * (P[2] * G[a][0] + P[3] * G[a][1]);
      }
    if (K) {
      // B_a,i,kL = dA sum_J G_aJ A_iJkL, then K_ai,bk += sum_L B_a,i,kL G_bL.
      // A has the major symmetry A_iJkL = A_kLiJ, so only the upper block
      // triangle b >= a is formed here and mirrored below.
      for (int a = 0; a < NN; ++a) {
        double B[2][4];
        for (int i = 0; i < 2; ++i)
          for (int kL = 0; kL < 4; ++kL)
            B[i][kL] = dA * (G[a][0] * A[(2 * i) * 4 + kL] + G[a][1] * A[(2 * i + 1) * 4 + kL]);
        for (int b = a; b < NN; ++b)
          for (int i = 0; i < 2; ++i)
            for (int k = 0; k < 2; ++k)
              K[(2 * a + i) * ND + 2 * b + k] += B[i][2 * k] * G[b][0] + B[i][2 * k + 1] * G[b][1];
      }
    }
  }
  if (K)
    for (int a = 0; a < NN; ++a)
      for (int b = a + 1; b < NN; ++b)
        for (int i = 0; i < 2; ++i)
          for (int k = 0; k < 2; ++k) K[(2 * b + k) * ND + 2 * a + i] = K[(2 * a + i) * ND + 2 * b + k];
  return result;
}

}  // namespace

double NeoHookean::energy_density(const double F[4]) const {
  double P[4];
  return evaluate(*this, F, P, nullptr);
}

void NeoHookean::first_piola(const double F[4], double P[4]) const { evaluate(*this, F, P, nullptr); }

void NeoHookean::tangent(const double F[4], double A[16]) const {
  double P[4];
  evaluate(*this, F, P, A);
}

int triangle_nodes(int order) { return order == 1 ? 3 : 6; }

ElementResult triangle_element(const NeoHookean &material, int order, const double *X, const double *x, double *f,
                               double *K) {
  if (order == 1) return integrate(material, rule_p1, X, x, f, K);
  return integrate(material, rule_p2, X, x, f, K);
}

}  // namespace deformix

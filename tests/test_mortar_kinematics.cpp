// Mortar (weighted) gap kernel mortar_node: derivatives against central
// finite differences and Hessian symmetry on curved patches; the weights of
// the integral against a straight master (where the pointwise gap is the
// height of the slave boundary, so the weighted gap has closed-form
// coefficients); the slip of a slave translated along the master; and the
// defect the mortar gap exists for: a master corner that enters the slave
// between two slave nodes whose own gaps are positive.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include "deformix/pair_kinematics.hpp"

using namespace deformix;

namespace {

const double kPi = std::acos(-1.0);
constexpr int kN = 24;

struct Patch {
  double q[kN] = {}, q0[kN] = {};
  MortarSupport support;
  PairKinematics eval(const double *x, bool hessians = true, int *beyond = nullptr) const {
    return mortar_node(x, q0, support, hessians, beyond);
  }
};

// Master: seven nodes on a perturbed arc of the unit circle (counter-
// clockwise, spacing hm) around the top; slave: five nodes on the circle of
// radius 1 + off, spacing hs, ordered the other way (the neighbour's own
// boundary is counter-clockwise around its centre above), perturbed.
Patch arc_patch(std::mt19937 &rng, int order, bool vertex, double off, double hm = 0.13, double hs = 0.09) {
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  Patch p;
  p.support.order = order;
  p.support.vertex = vertex;
  const double shift = 0.3 * hm * U(rng);
  for (int j = 0; j < 7; ++j) {
    const double th = 0.5 * kPi + (j - 3) * hm, r = 1.0 + 0.01 * U(rng);
    p.q[2 * j] = r * std::cos(th), p.q[2 * j + 1] = r * std::sin(th);
  }
  for (int j = 0; j < 5; ++j) {
    const double th = 0.5 * kPi + shift - (j - 2) * hs, r = 1.0 + off + 0.01 * U(rng);
    p.q[14 + 2 * j] = r * std::cos(th), p.q[14 + 2 * j + 1] = r * std::sin(th);
  }
  p.support.length[0] = hs * (1.0 + 0.2 * U(rng)), p.support.length[1] = hs * (1.0 + 0.2 * U(rng));
  for (int i = 0; i < kN; ++i) p.q0[i] = p.q[i] + 0.03 * U(rng);
  return p;
}

double max_abs(const double *v, int n) {
  double m = 0.0;
  for (int i = 0; i < n; ++i) m = std::max(m, std::fabs(v[i]));
  return m;
}

double rel_err(const double *fd, const double *exact, int n) {
  double e = 0.0;
  for (int i = 0; i < n; ++i) e = std::max(e, std::fabs(fd[i] - exact[i]));
  return e / std::max(max_abs(exact, n), 1e-3);
}

// Straight master along +x through the origin (outward normal -y: the slave
// is below), seven nodes spaced 0.1 around x = 0; slave nodes at x = 0.1 (2 - j)
// (the slave runs the other way) with heights h[j] below the line: the gap of a
// slave point is its depth below the line.
Patch line_patch(int order, bool vertex, const double depth[5]) {
  Patch p;
  p.support.order = order, p.support.vertex = vertex;
  p.support.length[0] = p.support.length[1] = 0.1;
  for (int j = 0; j < 7; ++j) p.q[2 * j] = 0.1 * (j - 3), p.q[2 * j + 1] = 0.0;
  for (int j = 0; j < 5; ++j) p.q[14 + 2 * j] = 0.1 * (2 - j), p.q[15 + 2 * j] = -depth[j];
  std::copy(p.q, p.q + kN, p.q0);
  return p;
}

}  // namespace

TEST(MortarNode, FiniteDifferences) {
  // Order 1 and 2, the weighted node a vertex or a mid-edge node, the slave
  // apart (gap up to 0.05) or penetrating (down to -0.01).
  std::mt19937 rng(201);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  double worst[4] = {0, 0, 0, 0};
  for (int trial = 0; trial < 30; ++trial) {
    const int order = trial % 3 == 0 ? 1 : 2;
    const bool vertex = order == 1 || trial % 3 == 1;
    const Patch p = arc_patch(rng, order, vertex, 0.02 + 0.03 * U(rng));
    int beyond = 7;
    const PairKinematics k = p.eval(p.q, true, &beyond);
    ASSERT_EQ(k.ndof, kN);
    ASSERT_EQ(beyond, 0);
    const double h = 1e-5;
    double fd_dg[kN], fd_ds[kN], fd_d2g[kN * kN], fd_d2s[kN * kN];
    for (int j = 0; j < kN; ++j) {
      double xp[kN], xm[kN];
      std::copy(p.q, p.q + kN, xp);
      std::copy(p.q, p.q + kN, xm);
      xp[j] += h, xm[j] -= h;
      const PairKinematics kp = p.eval(xp), km = p.eval(xm);
      fd_dg[j] = (kp.gap - km.gap) / (2 * h);
      fd_ds[j] = (kp.slip - km.slip) / (2 * h);
      for (int i = 0; i < kN; ++i) {
        fd_d2g[i * kN + j] = (kp.dgap[i] - km.dgap[i]) / (2 * h);
        fd_d2s[i * kN + j] = (kp.dslip[i] - km.dslip[i]) / (2 * h);
      }
    }
    const double e[4] = {rel_err(fd_dg, k.dgap, kN), rel_err(fd_ds, k.dslip, kN), rel_err(fd_d2g, k.d2gap, kN * kN),
                         rel_err(fd_d2s, k.d2slip, kN * kN)};
    for (int m = 0; m < 4; ++m) {
      EXPECT_LT(e[m], 1e-6) << "trial " << trial << " quantity " << m;
      worst[m] = std::max(worst[m], e[m]);
    }
    // Every slave node matters except j +- 2 when the sub-segments around j
    // lie on the edges j-1..j+1 (order 1, or j a mid-edge node).
    for (int i = 0; i < kN; ++i) {
      const bool unused = (order == 1 || !vertex) && (i == 14 || i == 15 || i == 22 || i == 23);
      if (unused)
        EXPECT_EQ(k.dgap[i], 0.0) << i;
      else if (i >= 14)
        EXPECT_NE(k.dgap[i], 0.0) << i;
    }
  }
  std::printf("  mortar: max rel FD error dgap %.2e dslip %.2e d2gap %.2e d2slip %.2e\n", worst[0], worst[1], worst[2],
              worst[3]);
}

TEST(MortarNode, HessiansSymmetricAndOptional) {
  std::mt19937 rng(202);
  for (int trial = 0; trial < 10; ++trial) {
    const Patch p = arc_patch(rng, 2, trial % 2 == 0, 0.01);
    const PairKinematics k = p.eval(p.q, true), k1 = p.eval(p.q, false);
    const double sg = max_abs(k.d2gap, kN * kN), ss = max_abs(k.d2slip, kN * kN);
    EXPECT_GT(ss, 1e-3);
    for (int i = 0; i < kN; ++i)
      for (int j = 0; j < i; ++j) {
        EXPECT_LE(std::fabs(k.d2gap[i * kN + j] - k.d2gap[j * kN + i]), 1e-13 * sg);
        EXPECT_LE(std::fabs(k.d2slip[i * kN + j] - k.d2slip[j * kN + i]), 1e-13 * ss);
      }
    EXPECT_NEAR(k1.gap, k.gap, 1e-15);
    EXPECT_NEAR(k1.slip, k.slip, 1e-15);
    for (int i = 0; i < kN; ++i) EXPECT_NEAR(k1.dgap[i], k.dgap[i], 1e-12);
    EXPECT_EQ(max_abs(k1.d2gap, kN * kN), 0.0);
  }
}

TEST(MortarNode, WeightsAgainstAStraightMaster) {
  // g~ = sum_k c_k depth_k, with c_k = int_cell N_k / |cell| in closed form
  // (the cell of node j: r in [0, 1/2] on both sides):
  //   order 1:            c = (0, 1/8, 3/4, 1/8, 0)
  //   order 2, vertex:    c = (-1/24, 5/24, 2/3, 5/24, -1/24)
  //   order 2, mid-edge:  c = (0, 1/24, 11/12, 1/24, 0)
  struct Case {
    int order;
    bool vertex;
    double c[5];
  };
  const Case cases[3] = {{1, true, {0, 1.0 / 8, 3.0 / 4, 1.0 / 8, 0}},
                         {2, true, {-1.0 / 24, 5.0 / 24, 2.0 / 3, 5.0 / 24, -1.0 / 24}},
                         {2, false, {0, 1.0 / 24, 11.0 / 12, 1.0 / 24, 0}}};
  for (const Case &cs : cases)
    for (int node = 0; node < 5; ++node) {
      double depth[5] = {0.02, 0.02, 0.02, 0.02, 0.02};
      depth[node] += 0.01;
      const Patch p = line_patch(cs.order, cs.vertex, depth);
      int beyond = 7;
      const PairKinematics k = p.eval(p.q, false, &beyond);
      EXPECT_EQ(beyond, 0);
      EXPECT_NEAR(k.gap, 0.02 + 0.01 * cs.c[node], 1e-14) << "order " << cs.order << " vertex " << cs.vertex << " node " << node;
      EXPECT_NEAR(k.normal[0], 0.0, 1e-14);
      EXPECT_NEAR(k.normal[1], -1.0, 1e-14);
      // The gap is linear in the depths: its gradient is the coefficients.
      EXPECT_NEAR(k.dgap[14 + 2 * node + 1], -cs.c[node], 1e-12);
    }
  // A uniform depth is the weighted gap whatever the sub-segment lengths.
  const double depth[5] = {0.03, 0.03, 0.03, 0.03, 0.03};
  Patch p = line_patch(2, true, depth);
  p.support.length[0] = 0.07, p.support.length[1] = 0.13;
  EXPECT_NEAR(p.eval(p.q, false).gap, 0.03, 1e-14);
}

TEST(MortarNode, SlipOfASlaveTranslatedAlongTheMaster) {
  // The slave moved by a along the master (+x, the master's tangent) since
  // the step start, the master fixed: s~ = a; moving both: s~ = 0.
  const double depth[5] = {0.01, 0.015, 0.02, 0.01, 0.0};
  for (int order = 1; order <= 2; ++order) {
    Patch p = line_patch(order, true, depth);
    for (int j = 0; j < 5; ++j) p.q0[14 + 2 * j] -= 0.004;
    EXPECT_NEAR(p.eval(p.q, false).slip, 0.004, 1e-14);
    for (int j = 0; j < 7; ++j) p.q0[2 * j] -= 0.004;
    EXPECT_NEAR(p.eval(p.q, false).slip, 0.0, 1e-14);
  }
}

TEST(MortarNode, MasterCornerBetweenSlaveNodesGivesANegativeWeightedGap) {
  // A straight master (spacing 0.05) with one node, between slave nodes j
  // (x = 0) and j + 1 (x = -0.1), pushed 0.03 towards a straight slave that
  // lies 0.002 below the line (a conforming contact). The nodes of the slave
  // keep a positive node-to-curve gap (the one-pass node-to-segment
  // condition holds), but the master corner is 0.028 inside the slave: the
  // weighted gap sees it.
  Patch p;
  p.support.order = 1;
  p.support.length[0] = p.support.length[1] = 0.1;
  for (int j = 0; j < 7; ++j) p.q[2 * j] = 0.05 * (j - 3), p.q[2 * j + 1] = 0.0;
  p.q[2 * 2 + 1] = -0.03;  // master node at x = -0.05
  for (int j = 0; j < 5; ++j) p.q[14 + 2 * j] = 0.1 * (2 - j), p.q[15 + 2 * j] = -0.002;
  std::copy(p.q, p.q + kN, p.q0);
  for (int j = 1; j <= 3; ++j) {  // node-to-curve gaps of slave nodes at x = 0.1, 0, -0.1
    const int window = 3 - j;  // the five master nodes centred on the slave node's x
    double ql[12];
    for (int i = 0; i < 10; ++i) ql[i] = p.q[2 * window + i];
    ql[10] = p.q[14 + 2 * j], ql[11] = p.q[15 + 2 * j];
    EXPECT_GT(curve_node(ql, ql, false).gap, 0.001) << "slave node " << j;
  }
  int beyond = 7;
  const PairKinematics k = p.eval(p.q, true, &beyond);
  EXPECT_EQ(beyond, 0);
  EXPECT_LT(k.gap, -1e-3);
  std::printf("  master corner 0.028 inside the slave: weighted gap of the nearest slave node %.2e\n", k.gap);
}

TEST(MortarNode, BeyondFlagWhenTheSlaveOutrunsThePatch) {
  // Slave spacing five times the master's: the outer slave points project
  // past the seven master nodes.
  std::mt19937 rng(203);
  const Patch p = arc_patch(rng, 2, true, 0.02, 0.05, 0.25);
  int beyond = 0;
  p.eval(p.q, false, &beyond);
  EXPECT_NE(beyond, 0);
}

int main(int argc, char **argv) {
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}

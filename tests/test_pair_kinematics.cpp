// Pair kinematics tests: derivatives against central finite differences,
// Hessian symmetry, known geometric answers (gap, normal, slip of elementary
// motions), invariance of the gap under rigid rotation, consistency between
// the pair types and degenerate input; for the smooth master curve
// (curve_node) also the continuity of gap, normal and slip across master
// nodes, the straight-line and circle limits, and the "beyond" flag.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <functional>
#include <random>
#include <string>

#include "deformix/pair_kinematics.hpp"

using namespace deformix;

namespace {

const double kPi = std::acos(-1.0);

constexpr int kMax = PairKinematics::kMaxDofs;

enum class Pair { RigidRigid, RigidNode, SegmentNode, CurveNode };

struct Config {
  Pair type;
  double q[kMax] = {};
  double q0[kMax] = {};
  double rA = 0.0, rB = 0.0;
  int ndof() const { return type == Pair::RigidNode ? 5 : type == Pair::CurveNode ? 12 : 6; }
  PairKinematics eval(const double *x) const {
    switch (type) {
      case Pair::RigidRigid: return rigid_rigid(x, q0, rA, rB);
      case Pair::RigidNode: return rigid_node(x, q0, rA);
      case Pair::CurveNode: return curve_node(x, q0);
      default: return segment_node(x, q0);
    }
  }
  PairKinematics eval() const { return eval(q); }
};

// Random non-degenerate configurations with O(1) lengths; q0 differs from q
// by O(0.3) so that every term of the slip is exercised.
Config random_config(Pair type, std::mt19937 &rng) {
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  Config c;
  c.type = type;
  if (type == Pair::SegmentNode) {
    const double ang = kPi * U(rng), len = 1.0 + 0.5 * U(rng);
    const double ax = U(rng), ay = U(rng);
    const double bx = ax + len * std::cos(ang), by = ay + len * std::sin(ang);
    // Node at xi in [-0.3, 1.3], normal offset in [-0.5, 0.5].
    const double xi = 0.5 + 0.8 * U(rng), off = 0.5 * U(rng);
    const double nx = std::sin(ang), ny = -std::cos(ang);
    const double v[6] = {ax, ay, bx, by, ax + xi * (bx - ax) + off * nx, ay + xi * (by - ay) + off * ny};
    for (int i = 0; i < 6; ++i) c.q[i] = v[i];
  } else {
    c.rA = 1.0 + 0.5 * U(rng);
    c.rB = type == Pair::RigidRigid ? 0.8 + 0.5 * U(rng) : 0.0;
    const double ang = kPi * U(rng), dist = (c.rA + c.rB) * (1.0 + 0.2 * U(rng));
    c.q[0] = U(rng);
    c.q[1] = U(rng);
    c.q[2] = U(rng);
    c.q[3] = c.q[0] + dist * std::cos(ang);
    c.q[4] = c.q[1] + dist * std::sin(ang);
    c.q[5] = type == Pair::RigidRigid ? U(rng) : 0.0;
  }
  for (int i = 0; i < 6; ++i) c.q0[i] = c.q[i] + 0.3 * U(rng);
  return c;
}

double max_abs(const double *v, int n) {
  double m = 0.0;
  for (int i = 0; i < n; ++i) m = std::max(m, std::fabs(v[i]));
  return m;
}

// Relative error max|fd - exact| / max(max|exact|, floor).
double rel_err(const double *fd, const double *exact, int n, double floor = 1e-3) {
  double e = 0.0;
  for (int i = 0; i < n; ++i) e = std::max(e, std::fabs(fd[i] - exact[i]));
  return e / std::max(max_abs(exact, n), floor);
}

struct FdErrors {
  double dgap = 0, dslip = 0, d2gap = 0, d2slip = 0;
};

FdErrors fd_errors(const Config &c) {
  const int nd = c.ndof();
  const PairKinematics k = c.eval();
  const double h = 1e-5;
  double fd_dg[kMax], fd_ds[kMax], fd_d2g[kMax * kMax], fd_d2s[kMax * kMax];
  for (int j = 0; j < nd; ++j) {
    double xp[kMax], xm[kMax];
    std::copy(c.q, c.q + kMax, xp);
    std::copy(c.q, c.q + kMax, xm);
    xp[j] += h;
    xm[j] -= h;
    const PairKinematics kp = c.eval(xp), km = c.eval(xm);
    fd_dg[j] = (kp.gap - km.gap) / (2 * h);
    fd_ds[j] = (kp.slip - km.slip) / (2 * h);
    for (int i = 0; i < nd; ++i) {
      fd_d2g[i * nd + j] = (kp.dgap[i] - km.dgap[i]) / (2 * h);
      fd_d2s[i * nd + j] = (kp.dslip[i] - km.dslip[i]) / (2 * h);
    }
  }
  FdErrors e;  // Hessians are row-major ndof x ndof
  e.dgap = rel_err(fd_dg, k.dgap, nd);
  e.dslip = rel_err(fd_ds, k.dslip, nd);
  e.d2gap = rel_err(fd_d2g, k.d2gap, nd * nd);
  e.d2slip = rel_err(fd_d2s, k.d2slip, nd * nd);
  return e;
}

}  // namespace

// The header stores the Hessians row-major ndof x ndof (stride ndof, not
// kMaxDofs); check that layout explicitly for the 5-dof pair.
TEST(PairKinematics, HessianLayoutIsNdofByNdof) {
  // rigid_node has ndof = 5: entry (i, j) lives at i * 5 + j. The gap Hessian
  // in the centre block is t t^T / L; with n = (1, 0), t = (0, 1):
  // d2g/dyA2 = 1/L at index 1 * 5 + 1 = 6, d2g/dyA dpy = -1/L at 1 * 5 + 4 = 9.
  const double q[5] = {0, 0, 0, 2, 0}, q0[5] = {0, 0, 0, 2, 0};
  const PairKinematics k = rigid_node(q, q0, 1.0);
  ASSERT_EQ(k.ndof, 5);
  EXPECT_NEAR(k.d2gap[6], 0.5, 1e-15);
  EXPECT_NEAR(k.d2gap[9], -0.5, 1e-15);
  EXPECT_NEAR(k.d2gap[0], 0.0, 1e-15);
}

class FiniteDifferences : public ::testing::TestWithParam<Pair> {};

TEST_P(FiniteDifferences, FirstAndSecondDerivatives) {
  std::mt19937 rng(1234 + static_cast<int>(GetParam()));
  FdErrors worst;
  for (int trial = 0; trial < 20; ++trial) {
    const Config c = random_config(GetParam(), rng);
    const FdErrors e = fd_errors(c);
    EXPECT_LT(e.dgap, 1e-6) << "trial " << trial;
    EXPECT_LT(e.dslip, 1e-6) << "trial " << trial;
    EXPECT_LT(e.d2gap, 1e-6) << "trial " << trial;
    EXPECT_LT(e.d2slip, 1e-6) << "trial " << trial;
    worst.dgap = std::max(worst.dgap, e.dgap);
    worst.dslip = std::max(worst.dslip, e.dslip);
    worst.d2gap = std::max(worst.d2gap, e.d2gap);
    worst.d2slip = std::max(worst.d2slip, e.d2slip);
  }
  std::printf("  pair %d: max rel FD error dgap %.2e dslip %.2e d2gap %.2e d2slip %.2e\n",
              static_cast<int>(GetParam()), worst.dgap, worst.dslip, worst.d2gap, worst.d2slip);
}

TEST_P(FiniteDifferences, HessiansAreSymmetric) {
  std::mt19937 rng(99 + static_cast<int>(GetParam()));
  for (int trial = 0; trial < 20; ++trial) {
    const Config c = random_config(GetParam(), rng);
    const PairKinematics k = c.eval();
    const int nd = k.ndof;
    ASSERT_EQ(nd, c.ndof());
    const double sg = std::max(max_abs(k.d2gap, nd * nd), 1e-300);
    const double ss = std::max(max_abs(k.d2slip, nd * nd), 1e-300);
    EXPECT_GT(max_abs(k.d2slip, nd * nd), 1e-3);  // the slip Hessian is not trivially zero
    for (int i = 0; i < nd; ++i)
      for (int j = 0; j < i; ++j) {
        EXPECT_LE(std::fabs(k.d2gap[i * nd + j] - k.d2gap[j * nd + i]), 1e-13 * sg) << i << "," << j;
        EXPECT_LE(std::fabs(k.d2slip[i * nd + j] - k.d2slip[j * nd + i]), 1e-13 * ss) << i << "," << j;
      }
    // Entries beyond ndof x ndof stay zero.
    for (int i = nd * nd; i < PairKinematics::kMaxDofs * PairKinematics::kMaxDofs; ++i) {
      EXPECT_EQ(k.d2gap[i], 0.0);
      EXPECT_EQ(k.d2slip[i], 0.0);
    }
  }
}

INSTANTIATE_TEST_SUITE_P(AllPairs, FiniteDifferences,
                         ::testing::Values(Pair::RigidRigid, Pair::RigidNode, Pair::SegmentNode));

// ---------------------------------------------------------------- geometry --

TEST(RigidRigid, GapAndNormalAtKnownDistance) {
  // Centres 3 - 4 - 5 triangle apart: distance 5.
  const double q[6] = {1.0, 2.0, 0.3, 4.0, 6.0, -0.2};
  const PairKinematics k = rigid_rigid(q, q, 1.5, 2.0);
  EXPECT_NEAR(k.gap, 5.0 - 3.5, 1e-14);
  EXPECT_NEAR(k.normal[0], 0.6, 1e-15);  // from A to B
  EXPECT_NEAR(k.normal[1], 0.8, 1e-15);
  EXPECT_NEAR(k.slip, 0.0, 1e-15);
  // dg/dc_B = n, dg/dc_A = -n, no rotation dependence.
  EXPECT_NEAR(k.dgap[3], 0.6, 1e-15);
  EXPECT_NEAR(k.dgap[4], 0.8, 1e-15);
  EXPECT_NEAR(k.dgap[0], -0.6, 1e-15);
  EXPECT_NEAR(k.dgap[1], -0.8, 1e-15);
  EXPECT_EQ(k.dgap[2], 0.0);
  EXPECT_EQ(k.dgap[5], 0.0);
  // Overlap gives a negative gap.
  const double qo[6] = {0, 0, 0, 1.0, 0, 0};
  EXPECT_NEAR(rigid_rigid(qo, qo, 1.0, 0.5).gap, -0.5, 1e-15);
}

TEST(RigidRigid, RigidTranslationOfThePairGivesNoSlip) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  for (int trial = 0; trial < 10; ++trial) {
    Config c = random_config(Pair::RigidRigid, rng);
    const double dx = 3.0 * U(rng), dy = 3.0 * U(rng);
    const double q0[6] = {c.q[0] - dx, c.q[1] - dy, c.q[2], c.q[3] - dx, c.q[4] - dy, c.q[5]};
    const PairKinematics k = rigid_rigid(c.q, q0, c.rA, c.rB);
    EXPECT_NEAR(k.slip, 0.0, 1e-14);
    // Same for the rigid-node pair.
    const double qn0[5] = {q0[0], q0[1], q0[2], q0[3], q0[4]};
    EXPECT_NEAR(rigid_node(c.q, qn0, c.rA).slip, 0.0, 1e-14);
  }
}

TEST(RigidRigid, RotationOfAAboutItsCentre) {
  // Rotating A by dtheta (B fixed) moves A's contact point by r_A dtheta
  // along +t, so the slip of B relative to A is -r_A dtheta.
  const double rA = 1.3, rB = 0.7, dth = 0.37;
  const double q[6] = {0.2, -0.1, 0.5 + dth, 2.0, 1.1, 0.4};
  const double q0[6] = {0.2, -0.1, 0.5, 2.0, 1.1, 0.4};
  EXPECT_NEAR(rigid_rigid(q, q0, rA, rB).slip, -rA * dth, 1e-14);
  // Rotating B by dtheta moves B's contact point (at -r_B n) by -r_B dtheta t.
  const double q1[6] = {0.2, -0.1, 0.5, 2.0, 1.1, 0.4 + dth};
  EXPECT_NEAR(rigid_rigid(q1, q0, rA, rB).slip, -rB * dth, 1e-14);
  // Rolling without slip: A and B turning in opposite senses with r_A dthA = -r_B dthB.
  const double q2[6] = {0.2, -0.1, 0.5 + dth, 2.0, 1.1, 0.4 - rA * dth / rB};
  EXPECT_NEAR(rigid_rigid(q2, q0, rA, rB).slip, 0.0, 1e-14);
  // Rigid node: same rule.
  const double qn[5] = {0.2, -0.1, 0.5 + dth, 2.0, 1.1}, qn0[5] = {0.2, -0.1, 0.5, 2.0, 1.1};
  EXPECT_NEAR(rigid_node(qn, qn0, rA).slip, -rA * dth, 1e-14);
}

TEST(RigidRigid, TangentialTranslationOfB) {
  // Current configuration q; at the step start B was delta * t behind, with t
  // the current tangent: s = delta exactly (the slip uses the current t).
  const double rA = 1.0, rB = 0.5, delta = 0.23;
  const double q[6] = {0.3, 0.4, 0.1, 1.2, 1.7, -0.3};
  PairKinematics k = rigid_rigid(q, q, rA, rB);
  const double t[2] = {-k.normal[1], k.normal[0]};
  const double q0[6] = {q[0], q[1], q[2], q[3] - delta * t[0], q[4] - delta * t[1], q[5]};
  k = rigid_rigid(q, q0, rA, rB);
  EXPECT_NEAR(k.slip, delta, 1e-14);
  // Moving A instead by +delta t gives -delta.
  const double q0A[6] = {q[0] - delta * t[0], q[1] - delta * t[1], q[2], q[3], q[4], q[5]};
  EXPECT_NEAR(rigid_rigid(q, q0A, rA, rB).slip, -delta, 1e-14);
  // Node: the same.
  const double q0n[5] = {q[0], q[1], q[2], q[3] - delta * t[0], q[4] - delta * t[1]};
  EXPECT_NEAR(rigid_node(q, q0n, rA).slip, delta, 1e-14);
  // A purely normal motion of B gives no slip.
  const double q0N[6] = {q[0], q[1], q[2], q[3] - delta * k.normal[0], q[4] - delta * k.normal[1], q[5]};
  EXPECT_NEAR(rigid_rigid(q, q0N, rA, rB).slip, 0.0, 1e-14);
}

TEST(RigidRigid, TangentIsCounterClockwiseAroundMaster) {
  // n = (1, 0) from A to B, t = (0, 1): B moving up (counter-clockwise around A) slips positively.
  const double q[6] = {0, 0, 0, 2.0, 0.0, 0}, q0[6] = {0, 0, 0, 2.0, -0.1, 0};
  const PairKinematics k = rigid_rigid(q, q0, 1.0, 1.0);
  EXPECT_GT(k.slip, 0.0);
  EXPECT_NEAR(k.dslip[4], 1.0 - 0.0, 0.01);  // ds/dyB ~ 1 near q0
}

TEST(RigidNode, MatchesRigidRigidWithZeroRadius) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 10; ++trial) {
    const Config c = random_config(Pair::RigidRigid, rng);
    const PairKinematics kr = rigid_rigid(c.q, c.q0, c.rA, 0.0);
    const PairKinematics kn = rigid_node(c.q, c.q0, c.rA);
    EXPECT_EQ(kn.ndof, 5);
    EXPECT_NEAR(kn.gap, kr.gap, 1e-14);
    EXPECT_NEAR(kn.slip, kr.slip, 1e-14);
    for (int i = 0; i < 5; ++i) {
      EXPECT_NEAR(kn.dgap[i], kr.dgap[i], 1e-14);
      EXPECT_NEAR(kn.dslip[i], kr.dslip[i], 1e-14);
      for (int j = 0; j < 5; ++j) {
        EXPECT_NEAR(kn.d2gap[i * 5 + j], kr.d2gap[i * 6 + j], 1e-13);
        EXPECT_NEAR(kn.d2slip[i * 5 + j], kr.d2slip[i * 6 + j], 1e-13);
      }
    }
  }
}

TEST(SegmentNode, GapNormalAndOutwardSignOnCounterClockwiseBoundary) {
  // Bottom edge of the counter-clockwise unit square (0,0) -> (1,0): outward normal (0, -1).
  const double q[6] = {0, 0, 1, 0, 0.25, -0.2};
  const PairKinematics k = segment_node(q, q);
  EXPECT_NEAR(k.normal[0], 0.0, 1e-15);
  EXPECT_NEAR(k.normal[1], -1.0, 1e-15);
  EXPECT_NEAR(k.gap, 0.2, 1e-15);  // outside the square: open
  const double qin[6] = {0, 0, 1, 0, 0.25, 0.1};
  EXPECT_NEAR(segment_node(qin, qin).gap, -0.1, 1e-15);  // inside: penetration
  // dg/dp = n, dg/da = -(1 - xi) n, dg/db = -xi n with xi = 0.25.
  EXPECT_NEAR(k.dgap[5], -1.0, 1e-15);
  EXPECT_NEAR(k.dgap[1], 0.75, 1e-15);
  EXPECT_NEAR(k.dgap[3], 0.25, 1e-15);
  // Same for a segment of a counter-clockwise polygon around a disk: the
  // normal points away from the centre.
  const double th0 = 0.3, th1 = 0.6, R = 2.0;
  const double qc[6] = {R * std::cos(th0), R * std::sin(th0), R * std::cos(th1), R * std::sin(th1), 0, 0};
  const double nx = segment_node(qc, qc).normal[0], ny = segment_node(qc, qc).normal[1];
  const double mid = 0.5 * (th0 + th1);
  EXPECT_GT(nx * std::cos(mid) + ny * std::sin(mid), 0.99);
}

TEST(SegmentNode, NodeSlidingAlongFixedSegment) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  for (int trial = 0; trial < 10; ++trial) {
    Config c = random_config(Pair::SegmentNode, rng);
    const double ex = c.q[2] - c.q[0], ey = c.q[3] - c.q[1], l = std::hypot(ex, ey);
    const double d = 0.4 * U(rng);
    double q0[6];
    std::copy(c.q, c.q + 6, q0);
    q0[4] -= d * ex / l;  // node was d behind along a -> b
    q0[5] -= d * ey / l;
    const PairKinematics k = segment_node(c.q, q0);
    const PairKinematics k0 = segment_node(q0, q0);
    EXPECT_NEAR(k.slip, d, 1e-14);
    EXPECT_NEAR(k.gap, k0.gap, 1e-14);
    EXPECT_NEAR(k0.slip, 0.0, 1e-15);
    // Moving the whole segment by -d along a -> b instead gives the same slip.
    double q0s[6];
    std::copy(c.q, c.q + 6, q0s);
    for (int v = 0; v < 2; ++v) {
      q0s[2 * v] += d * ex / l;
      q0s[2 * v + 1] += d * ey / l;
    }
    EXPECT_NEAR(segment_node(c.q, q0s).slip, d, 1e-14);
  }
}

TEST(SegmentNode, RigidTranslationGivesNoSlipAndNormalMotionNoSlip) {
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  for (int trial = 0; trial < 10; ++trial) {
    const Config c = random_config(Pair::SegmentNode, rng);
    const double dx = 2.0 * U(rng), dy = 2.0 * U(rng);
    double q0[6];
    for (int v = 0; v < 3; ++v) {
      q0[2 * v] = c.q[2 * v] - dx;
      q0[2 * v + 1] = c.q[2 * v + 1] - dy;
    }
    EXPECT_NEAR(segment_node(c.q, q0).slip, 0.0, 1e-14);
    // Node moving along the normal only.
    const PairKinematics k = segment_node(c.q, c.q);
    double q0n[6];
    std::copy(c.q, c.q + 6, q0n);
    q0n[4] -= 0.3 * k.normal[0];
    q0n[5] -= 0.3 * k.normal[1];
    EXPECT_NEAR(segment_node(c.q, q0n).slip, 0.0, 1e-14);
  }
}

TEST(SegmentNode, SlipSignMatchesRigidNodeForTheSameRelativeMotion) {
  // A node moving counter-clockwise around a master body slips positively for
  // both master types: rigid disk (t counter-clockwise) and a segment of a
  // counter-clockwise boundary (t along a -> b).
  const double R = 1.0, th = 0.2, eps = 0.05;
  // Rigid master at the origin, node just outside at angle th, moved from th - eps.
  const double qn[5] = {0, 0, 0, R * std::cos(th), R * std::sin(th)};
  const double qn0[5] = {0, 0, 0, R * std::cos(th - eps), R * std::sin(th - eps)};
  const double s_rigid = rigid_node(qn, qn0, R).slip;
  // Segment of the counter-clockwise circle around it, same node motion.
  const double a0 = th - 0.3, a1 = th + 0.3;
  const double qs[6] = {R * std::cos(a0), R * std::sin(a0), R * std::cos(a1), R * std::sin(a1), qn[3], qn[4]};
  const double qs0[6] = {qs[0], qs[1], qs[2], qs[3], qn0[3], qn0[4]};
  const double s_seg = segment_node(qs, qs0).slip;
  EXPECT_GT(s_rigid, 0.0);
  EXPECT_GT(s_seg, 0.0);
  EXPECT_NEAR(s_seg, s_rigid, 0.01 * s_rigid);
}

TEST(AllPairs, GapInvariantUnderRigidRotationOfTheConfiguration) {
  std::mt19937 rng(23);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  for (Pair type : {Pair::RigidRigid, Pair::RigidNode, Pair::SegmentNode}) {
    for (int trial = 0; trial < 5; ++trial) {
      const Config c = random_config(type, rng);
      const double phi = kPi * U(rng), cx = U(rng), cy = U(rng);
      const double co = std::cos(phi), si = std::sin(phi);
      Config rc = c;
      auto rot = [&](double *x, int i) {
        const double dx = x[i] - cx, dy = x[i + 1] - cy;
        x[i] = cx + co * dx - si * dy;
        x[i + 1] = cy + si * dx + co * dy;
      };
      if (type == Pair::SegmentNode) {
        for (int v = 0; v < 3; ++v) rot(rc.q, 2 * v);
      } else {
        rot(rc.q, 0);
        rot(rc.q, 3);
        rc.q[2] += phi;
        if (type == Pair::RigidRigid) rc.q[5] += phi;
      }
      const PairKinematics k = c.eval(), kr = rc.eval();
      EXPECT_NEAR(kr.gap, k.gap, 1e-13);
      // The normal rotates with the configuration.
      EXPECT_NEAR(kr.normal[0], co * k.normal[0] - si * k.normal[1], 1e-13);
      EXPECT_NEAR(kr.normal[1], si * k.normal[0] + co * k.normal[1], 1e-13);
    }
  }
}

TEST(RigidRigid, IncrementalSlipIsObjectiveOnlyToSecondOrderInTheStepRotation) {
  // Characterisation (documents a limitation, see the header): two touching
  // disks rotated rigidly as one body by phi about A's centre within one
  // step. Physically there is no slip, but the linearised rotation
  // -r dtheta against the chord of the centres gives
  //   s = (rA + rB)(sin phi - phi) = -(rA + rB) phi^3 / 6 + O(phi^5).
  const double rA = 1.0, rB = 0.6, L = rA + rB;
  for (double phi : {1e-3, 0.05, 0.3}) {
    const double q0[6] = {0, 0, 0, L, 0, 0};
    const double q[6] = {0, 0, phi, L * std::cos(phi), L * std::sin(phi), phi};
    const PairKinematics k = rigid_rigid(q, q0, rA, rB);
    EXPECT_NEAR(k.slip, L * (std::sin(phi) - phi), 1e-14);
    EXPECT_NEAR(k.gap, 0.0, 1e-14);
  }
}

TEST(Degenerate, CoincidentCentresAndCollapsedSegment) {
  const double q[6] = {0.5, -0.3, 0.2, 0.5, -0.3, 0.1};
  const double q0[6] = {0.4, -0.3, 0.0, 0.6, -0.2, 0.0};
  const PairKinematics k = rigid_rigid(q, q0, 1.0, 0.5);
  EXPECT_EQ(k.ndof, 6);
  EXPECT_DOUBLE_EQ(k.gap, -1.5);
  EXPECT_EQ(k.normal[0], 0.0);
  EXPECT_EQ(k.normal[1], 0.0);
  EXPECT_EQ(k.slip, 0.0);
  EXPECT_EQ(max_abs(k.dgap, kMax), 0.0);
  EXPECT_EQ(max_abs(k.dslip, kMax), 0.0);
  EXPECT_EQ(max_abs(k.d2gap, kMax * kMax), 0.0);
  EXPECT_EQ(max_abs(k.d2slip, kMax * kMax), 0.0);

  const PairKinematics kn = rigid_node(q, q0, 1.0);
  EXPECT_EQ(kn.ndof, 5);
  EXPECT_DOUBLE_EQ(kn.gap, -1.0);
  EXPECT_EQ(max_abs(kn.d2slip, kMax * kMax), 0.0);

  const double qs[6] = {1.0, 2.0, 1.0, 2.0, 4.0, 6.0};
  const PairKinematics ks = segment_node(qs, qs);
  EXPECT_EQ(ks.ndof, 6);
  EXPECT_DOUBLE_EQ(ks.gap, 5.0);  // distance to the collapsed segment's point
  EXPECT_EQ(ks.normal[0], 0.0);
  EXPECT_EQ(ks.normal[1], 0.0);
  EXPECT_EQ(ks.slip, 0.0);
  EXPECT_EQ(max_abs(ks.dgap, kMax), 0.0);
  EXPECT_EQ(max_abs(ks.d2slip, kMax * kMax), 0.0);
  // Everything stays finite.
  for (int i = 0; i < kMax * kMax; ++i) {
    EXPECT_TRUE(std::isfinite(k.d2slip[i]));
    EXPECT_TRUE(std::isfinite(ks.d2gap[i]));
  }
}

// ------------------------------------------------------------- curve-node --
// Five master nodes on a perturbed circular arc (a deformed disk boundary,
// counter-clockwise), the slave node near the arc.
namespace {

// Arc of radius 1 around the origin, 5 nodes at angles -2h..2h around pi/2
// (counter-clockwise => from right to left on the top of the circle); the
// node at angle `at` (in segment units from the centre node) and radial
// offset `off` from the circle; q0 = q + O(0.05) noise.
Config curve_config(double at, double off, std::mt19937 &rng, double jitter = 0.02, double h = 0.13) {
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  Config c;
  c.type = Pair::CurveNode;
  for (int j = 0; j < 5; ++j) {
    const double th = 0.5 * kPi + (j - 2) * h;
    const double r = 1.0 + jitter * U(rng);
    c.q[2 * j] = r * std::cos(th);
    c.q[2 * j + 1] = r * std::sin(th);
  }
  const double th = 0.5 * kPi + at * h;
  c.q[10] = (1.0 + off) * std::cos(th);
  c.q[11] = (1.0 + off) * std::sin(th);
  for (int i = 0; i < 12; ++i) c.q0[i] = c.q[i] + 0.05 * U(rng);
  return c;
}

}  // namespace

TEST(CurveNode, FiniteDifferences) {
  // Outside (gap up to 0.07) and penetrating (down to -0.01) nodes, on both
  // segments of the curve, the master node m2 between them included.
  std::mt19937 rng(101);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  FdErrors worst;
  for (int trial = 0; trial < 60; ++trial) {
    const Config c = curve_config(0.95 * U(rng), 0.03 + 0.04 * U(rng), rng);
    int beyond = 7;
    const PairKinematics k = curve_node(c.q, c.q0, true, &beyond);
    ASSERT_EQ(k.ndof, 12);
    ASSERT_EQ(beyond, 0);
    const FdErrors e = fd_errors(c);
    EXPECT_LT(e.dgap, 1e-6);
    EXPECT_LT(e.dslip, 1e-6);
    EXPECT_LT(e.d2gap, 1e-6);
    EXPECT_LT(e.d2slip, 1e-6);
    worst.dgap = std::max(worst.dgap, e.dgap), worst.dslip = std::max(worst.dslip, e.dslip);
    worst.d2gap = std::max(worst.d2gap, e.d2gap), worst.d2slip = std::max(worst.d2slip, e.d2slip);
  }
  std::printf("  curve: max rel FD error dgap %.2e dslip %.2e d2gap %.2e d2slip %.2e\n", worst.dgap, worst.dslip,
              worst.d2gap, worst.d2slip);
}

TEST(CurveNode, HessiansSymmetricAndOptional) {
  std::mt19937 rng(102);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    const Config c = curve_config(0.9 * U(rng), 0.02 * U(rng), rng);
    const PairKinematics k = curve_node(c.q, c.q0, true), k1 = curve_node(c.q, c.q0, false);
    const double sg = max_abs(k.d2gap, 144), ss = max_abs(k.d2slip, 144);
    EXPECT_GT(ss, 1e-3);
    for (int i = 0; i < 12; ++i)
      for (int j = 0; j < i; ++j) {
        EXPECT_LE(std::fabs(k.d2gap[i * 12 + j] - k.d2gap[j * 12 + i]), 1e-13 * sg);
        EXPECT_LE(std::fabs(k.d2slip[i * 12 + j] - k.d2slip[j * 12 + i]), 1e-13 * ss);
      }
    // Without Hessians: the same values and gradients (to round-off: the
    // closed-form first derivatives against those of the Hessian pass),
    // zero second derivatives.
    EXPECT_NEAR(k1.gap, k.gap, 1e-15);
    EXPECT_NEAR(k1.slip, k.slip, 1e-15);
    for (int i = 0; i < 12; ++i) {
      EXPECT_NEAR(k1.dgap[i], k.dgap[i], 1e-12);
      EXPECT_NEAR(k1.dslip[i], k.dslip[i], 1e-12);
    }
    EXPECT_EQ(max_abs(k1.d2gap, 144), 0.0);
    EXPECT_EQ(max_abs(k1.d2slip, 144), 0.0);
  }
}

TEST(CurveNode, TranslatedFarFromTheOrigin) {
  // In a packing the coordinates are tens of <d> while the gaps are 1e-3
  // <d> and less: the closest point is then known to about 1e-14 in t only,
  // and the projection must still settle there. The pair translated by
  // (35, -27) gives the same kinematics to round-off of those coordinates.
  std::mt19937 rng(103);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  for (int trial = 0; trial < 40; ++trial) {
    const Config c = curve_config(0.95 * U(rng), 0.01 * U(rng), rng);
    double q[12], q0[12];
    for (int i = 0; i < 12; ++i) q[i] = c.q[i] + (i % 2 ? -27.0 : 35.0), q0[i] = c.q0[i] + (i % 2 ? -27.0 : 35.0);
    for (bool hessians : {false, true}) {
      const PairKinematics k = curve_node(c.q, c.q0, hessians), kt = curve_node(q, q0, hessians);
      EXPECT_NEAR(kt.gap, k.gap, 1e-12);
      EXPECT_NEAR(kt.slip, k.slip, 1e-12);
      for (int i = 0; i < 12; ++i) {
        EXPECT_NEAR(kt.dgap[i], k.dgap[i], 1e-10);
        EXPECT_NEAR(kt.dslip[i], k.dslip[i], 1e-10);
      }
      const double sg = max_abs(k.d2gap, 144), ss = max_abs(k.d2slip, 144);
      for (int i = 0; i < 144; ++i) {
        EXPECT_NEAR(kt.d2gap[i], k.d2gap[i], 1e-7 * sg);
        EXPECT_NEAR(kt.d2slip[i], k.d2slip[i], 1e-7 * ss);
      }
    }
  }
}

TEST(CurveNode, StraightLineEqualsSegmentNode) {
  // Equally spaced collinear master nodes: the curve is the line, and gap,
  // normal and slip are segment_node's on the segment under the node.
  std::mt19937 rng(103);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  for (int trial = 0; trial < 50; ++trial) {
    const double ang = kPi * U(rng), len = 0.2 + 0.1 * U(rng), ox = U(rng), oy = U(rng);
    const double ex = len * std::cos(ang), ey = len * std::sin(ang), nx = ey / len, ny = -ex / len;
    Config c;
    c.type = Pair::CurveNode;
    for (int j = 0; j < 5; ++j) c.q[2 * j] = ox + j * ex, c.q[2 * j + 1] = oy + j * ey;
    const double xi = 1.0 + 1.98 * (0.5 + 0.5 * U(rng)) - 0.99, off = 0.1 * U(rng);  // along m1..m3
    c.q[10] = ox + (1.0 + xi) * ex + off * nx, c.q[11] = oy + (1.0 + xi) * ey + off * ny;
    // The start of the step: the line translated, the node moved along it.
    const double sx = 0.01 * U(rng), sy = 0.01 * U(rng), along = 0.05 * U(rng);
    for (int j = 0; j < 5; ++j) c.q0[2 * j] = c.q[2 * j] + sx, c.q0[2 * j + 1] = c.q[2 * j + 1] + sy;
    c.q0[10] = c.q[10] + sx + along * ex / len, c.q0[11] = c.q[11] + sy + along * ey / len;
    const int s = xi < 1.0 ? 1 : 2;  // the master segment m_s -> m_{s+1} under the node
    const double qs[6] = {c.q[2 * s], c.q[2 * s + 1], c.q[2 * s + 2], c.q[2 * s + 3], c.q[10], c.q[11]};
    const double qs0[6] = {c.q0[2 * s], c.q0[2 * s + 1], c.q0[2 * s + 2], c.q0[2 * s + 3], c.q0[10], c.q0[11]};
    const PairKinematics k = c.eval(), ks = segment_node(qs, qs0);
    EXPECT_NEAR(k.gap, off, 1e-13);
    EXPECT_NEAR(k.gap, ks.gap, 1e-13);
    EXPECT_NEAR(k.slip, -along, 1e-13);
    EXPECT_NEAR(k.slip, ks.slip, 1e-13);
    EXPECT_NEAR(k.normal[0], ks.normal[0], 1e-13);
    EXPECT_NEAR(k.normal[1], ks.normal[1], 1e-13);
    for (int i = 0; i < 2; ++i) EXPECT_NEAR(k.dgap[10 + i], ks.dgap[4 + i], 1e-12);
  }
}

TEST(CurveNode, CircleIsApproximatedToFourthOrder) {
  // Nodes on the unit circle, the slave node at radius 1 + off: the gap
  // error of the interpolating spline falls like h^4 (a polyline's like h^2).
  std::mt19937 rng(104);
  double err[2] = {0.0, 0.0};
  const double hs[2] = {0.2, 0.1};
  for (int level = 0; level < 2; ++level)
    for (int i = 0; i <= 40; ++i) {
      const Config c = curve_config(-0.95 + 1.9 * i / 40.0, 0.01, rng, 0.0, hs[level]);
      err[level] = std::max(err[level], std::fabs(c.eval().gap - 0.01));
    }
  EXPECT_LT(err[0], 2e-4);
  EXPECT_GT(err[0] / err[1], 12.0);  // 16 for h^4, 4 for h^2
  std::printf("  circle: max gap error %.2e (h = 0.2) -> %.2e (h = 0.1)\n", err[0], err[1]);
}

TEST(CurveNode, GapNormalAndSlipContinuousAcrossTheMasterNode) {
  // A node sliding along the curve at a fixed offset, outside or penetrating,
  // crosses the master node m2 (where patch_node's polyline normal jumped by
  // the corner angle): the largest change of gap, normal and slip between
  // neighbouring samples shrinks in proportion to the sample spacing.
  std::mt19937 rng(105);
  for (double off : {0.02, -0.01}) {
    const Config base = curve_config(0.0, off, rng, 0.03);
    auto max_jumps = [&](int N, double jump[3]) {
      Config c = base;
      PairKinematics prev;
      jump[0] = jump[1] = jump[2] = 0.0;
      for (int i = 0; i <= N; ++i) {
        const double th = 0.5 * kPi + (-0.9 + 1.8 * i / N) * 0.13;
        c.q[10] = (1.0 + off) * std::cos(th), c.q[11] = (1.0 + off) * std::sin(th);
        const PairKinematics k = c.eval();
        if (i > 0) {
          jump[0] = std::max(jump[0], std::fabs(k.gap - prev.gap));
          jump[1] = std::max(jump[1], std::hypot(k.normal[0] - prev.normal[0], k.normal[1] - prev.normal[1]));
          jump[2] = std::max(jump[2], std::fabs(k.slip - prev.slip));
        }
        prev = k;
      }
    };
    double coarse[3], fine[3];
    max_jumps(1000, coarse);
    max_jumps(8000, fine);
    for (int m = 0; m < 3; ++m) EXPECT_LT(fine[m], 0.25 * coarse[m]) << "offset " << off << " quantity " << m;
    std::printf("  curve continuity (offset %+.2f): max jumps gap %.1e normal %.1e slip %.1e -> %.1e %.1e %.1e\n", off,
                coarse[0], coarse[1], coarse[2], fine[0], fine[1], fine[2]);
  }
}

TEST(CurveNode, BeyondFlagAtThePatchEnds) {
  std::mt19937 rng(106);
  int flagged[3] = {0, 0, 0};
  for (int i = 0; i <= 200; ++i) {
    const double at = -1.8 + 3.6 * i / 200.0;
    const Config c = curve_config(at, 0.02, rng, 0.0);
    int beyond = 7;
    const PairKinematics k = curve_node(c.q, c.q0, false, &beyond);
    ASSERT_TRUE(beyond >= -1 && beyond <= 1);
    ++flagged[beyond + 1];
    if (std::fabs(at) < 0.98) EXPECT_EQ(beyond, 0) << "at " << at;  // between m1 and m3
    if (at < -1.02) EXPECT_EQ(beyond, -1) << "at " << at;
    if (at > 1.02) EXPECT_EQ(beyond, 1) << "at " << at;
    // Past the ends the extrapolated cubic still gives the gap to about the circle's.
    EXPECT_NEAR(k.gap, 0.02, 2e-3) << "at " << at;
  }
  EXPECT_GT(flagged[0], 0);
  EXPECT_GT(flagged[1], 0);
  EXPECT_GT(flagged[2], 0);
}

TEST(CurveNode, DegenerateInput) {
  // All master nodes on one point: no tangent, so no normal and no derivatives.
  double q[12] = {0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 1.0, 0.5};
  const PairKinematics k = curve_node(q, q, true);
  EXPECT_EQ(k.normal[0], 0.0);
  EXPECT_EQ(k.normal[1], 0.0);
  EXPECT_NEAR(k.gap, 0.5, 1e-15);
  EXPECT_EQ(max_abs(k.dgap, 12), 0.0);
}

int main(int argc, char **argv) {
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}

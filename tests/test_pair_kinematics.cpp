// Pair kinematics tests: derivatives against central finite differences,
// Hessian symmetry, known geometric answers (gap, normal, slip of elementary
// motions), invariance of the gap under rigid rotation, consistency between
// the pair types and degenerate input; for the window pair (node against
// the two master segments around a vertex) also the continuity of gap, slip
// and normal across feature switches, the agreement with segment_node /
// rigid_node on the chosen feature and the "beyond" flag.
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

enum class Pair { RigidRigid, RigidNode, SegmentNode, WindowNode, PatchNode, CurveNode };

struct Config {
  Pair type;
  double q[kMax] = {};
  double q0[kMax] = {};
  double rA = 0.0, rB = 0.0;
  int ndof() const { return type == Pair::RigidNode ? 5 : type == Pair::WindowNode ? 8 : (type == Pair::PatchNode || type == Pair::CurveNode) ? 12 : 6; }
  PairKinematics eval(const double *x) const {
    switch (type) {
      case Pair::RigidRigid: return rigid_rigid(x, q0, rA, rB);
      case Pair::RigidNode: return rigid_node(x, q0, rA);
      case Pair::WindowNode: return window_node(x, q0);
      case Pair::PatchNode: return patch_node(x, q0);
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

// ------------------------------------------------------------ window-node --
//
// q = (a, v, b, p). The helpers below re-derive the feature choice of the
// header from xi and the line gaps (independently of the implementation),
// build random windows in prescribed regions, and walk p along paths that
// cross feature switches.

namespace {

struct WindowRef {
  double xi1, g1, xi2, g2;
  bool convex;
  int feature;  // 0: vertex, 1: segment a-v, 2: segment v-b
  int beyond;
};

WindowRef window_ref(const double *q) {
  const double ax = q[0], ay = q[1], vx = q[2], vy = q[3], bx = q[4], by = q[5], px = q[6], py = q[7];
  const double e1x = vx - ax, e1y = vy - ay, l1 = std::hypot(e1x, e1y);
  const double e2x = bx - vx, e2y = by - vy, l2 = std::hypot(e2x, e2y);
  WindowRef r;
  r.xi1 = ((px - ax) * e1x + (py - ay) * e1y) / (l1 * l1);
  r.g1 = ((px - ax) * e1y - (py - ay) * e1x) / l1;  // right normal (e_y, -e_x) / l
  r.xi2 = ((px - vx) * e2x + (py - vy) * e2y) / (l2 * l2);
  r.g2 = ((px - vx) * e2y - (py - vy) * e2x) / l2;
  r.convex = e1x * e2y - e1y * e2x > 0.0;
  r.beyond = 0;
  if (r.convex && r.xi1 > 1.0 && r.xi2 < 0.0) {
    r.feature = 0;
    return r;
  }
  bool app1 = r.xi1 <= 1.0, app2 = r.xi2 >= 0.0;
  if (!app1 && !app2) app1 = app2 = true;
  if (app1 && app2)
    r.feature = (r.convex ? r.g1 >= r.g2 : r.g1 <= r.g2) ? 1 : 2;
  else
    r.feature = app1 ? 1 : 2;
  if (r.feature == 1 && r.xi1 < 0.0) r.beyond = -1;
  if (r.feature == 2 && r.xi2 > 1.0) r.beyond = +1;
  return r;
}

// Sub-configuration (6 dofs) of feature 1 (a, v, p) or 2 (v, b, p), and the
// blocks of the window it occupies.
void sub_config(const double *q8, int feature, double *q6) {
  const int blocks[2][3] = {{0, 1, 3}, {1, 2, 3}};
  for (int X = 0; X < 3; ++X)
    for (int i = 0; i < 2; ++i) q6[2 * X + i] = q8[2 * blocks[feature - 1][X] + i];
}

enum class Region { ConvexVertex, ConvexSeg1, ConvexSeg2, Concave, ConvexPenetrating };
const char *region_name(Region r) {
  switch (r) {
    case Region::ConvexVertex: return "convex vertex";
    case Region::ConvexSeg1: return "convex seg1";
    case Region::ConvexSeg2: return "convex seg2";
    case Region::Concave: return "concave";
    default: return "convex penetrating";
  }
}

// Corner a -> v -> b with turn angle phi (> 0: convex), random orientation,
// lengths and position; p is placed by the caller.
struct Corner {
  double v[2], t1[2], t2[2], n1[2], n2[2], l1, l2;
  double q[8];
};

Corner random_corner(double phi, std::mt19937 &rng) {
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  Corner c;
  const double th1 = kPi * U(rng), th2 = th1 + phi;
  c.l1 = 1.0 + 0.4 * U(rng);
  c.l2 = 1.0 + 0.4 * U(rng);
  c.v[0] = U(rng);
  c.v[1] = U(rng);
  c.t1[0] = std::cos(th1), c.t1[1] = std::sin(th1);
  c.t2[0] = std::cos(th2), c.t2[1] = std::sin(th2);
  c.n1[0] = c.t1[1], c.n1[1] = -c.t1[0];  // outward (right) normals
  c.n2[0] = c.t2[1], c.n2[1] = -c.t2[0];
  const double w[8] = {c.v[0] - c.l1 * c.t1[0], c.v[1] - c.l1 * c.t1[1], c.v[0], c.v[1],
                       c.v[0] + c.l2 * c.t2[0], c.v[1] + c.l2 * c.t2[1], 0.0, 0.0};
  std::copy(w, w + 8, c.q);
  return c;
}

// Is q at least `margin` away from every feature switch (and from the vertex)?
bool away_from_switches(const double *q, double margin) {
  const WindowRef r = window_ref(q);
  const double l1 = std::hypot(q[2] - q[0], q[3] - q[1]), l2 = std::hypot(q[4] - q[2], q[5] - q[3]);
  return std::fabs(r.xi1 - 1.0) * l1 > margin && std::fabs(r.xi2) * l2 > margin && std::fabs(r.g1 - r.g2) > margin &&
         std::hypot(q[6] - q[2], q[7] - q[3]) > 2.0 * margin;
}

// A random window with p in `region`, at least 0.03 away from feature switches;
// q0 = q + O(0.3) for every node.
Config random_window(Region region, std::mt19937 &rng) {
  std::uniform_real_distribution<double> U(-1.0, 1.0), U01(0.0, 1.0);
  for (;;) {
    const bool concave = region == Region::Concave;
    const double phi = (concave ? -1.0 : 1.0) * (0.3 + 2.3 * U01(rng));
    Corner k = random_corner(phi, rng);
    const double th1 = std::atan2(k.t1[1], k.t1[0]);
    double px = 0.0, py = 0.0;
    int want = -1;  // required feature, -1: any
    switch (region) {
      case Region::ConvexVertex: {  // in the outer normal cone, between n1 and n2
        const double psi = th1 - 0.5 * kPi + phi * (0.1 + 0.8 * U01(rng)), rho = 0.1 + 0.5 * U01(rng);
        px = k.v[0] + rho * std::cos(psi), py = k.v[1] + rho * std::sin(psi);
        want = 0;
        break;
      }
      case Region::ConvexSeg1:
      case Region::ConvexSeg2: {  // near one segment, also outside [0, 1] and slightly inside
        const bool one = region == Region::ConvexSeg1;
        const double xi = one ? -0.3 + 1.2 * U01(rng) : 0.1 + 1.2 * U01(rng), off = -0.3 + 0.8 * U01(rng);
        const double *base = one ? k.q : k.q + 2, *end = one ? k.q + 2 : k.q + 4, *n = one ? k.n1 : k.n2;
        px = base[0] + xi * (end[0] - base[0]) + off * n[0];
        py = base[1] + xi * (end[1] - base[1]) + off * n[1];
        want = one ? 1 : 2;
        break;
      }
      case Region::Concave: {
        const double psi = kPi * U(rng), rho = 0.1 + 0.7 * U01(rng);
        px = k.v[0] + rho * std::cos(psi), py = k.v[1] + rho * std::sin(psi);
        break;
      }
      case Region::ConvexPenetrating: {  // inside the interior angle pi - phi, from t2 to -t1
        const double psi = th1 + phi + (kPi - phi) * (0.05 + 0.9 * U01(rng)), rho = 0.05 + 0.45 * U01(rng);
        px = k.v[0] + rho * std::cos(psi), py = k.v[1] + rho * std::sin(psi);
        break;
      }
    }
    Config c;
    c.type = Pair::WindowNode;
    std::copy(k.q, k.q + 8, c.q);
    c.q[6] = px;
    c.q[7] = py;
    const WindowRef r = window_ref(c.q);
    if (want >= 0 && r.feature != want) continue;
    if (region == Region::ConvexPenetrating && !(r.g1 < 0.0 && r.g2 < 0.0)) continue;
    if (!away_from_switches(c.q, 0.03)) continue;
    for (int i = 0; i < 8; ++i) c.q0[i] = c.q[i] + 0.3 * U(rng);
    return c;
  }
}

}  // namespace

class WindowFiniteDifferences : public ::testing::TestWithParam<Region> {};

TEST_P(WindowFiniteDifferences, FirstAndSecondDerivatives) {
  const Region region = GetParam();
  std::mt19937 rng(4321 + static_cast<int>(region));
  FdErrors worst;
  int count[3] = {0, 0, 0}, neither = 0, penetrating = 0;
  for (int trial = 0; trial < 40; ++trial) {
    const Config c = random_window(region, rng);
    const WindowRef r = window_ref(c.q);
    ++count[r.feature];
    if (r.xi1 > 1.0 && r.xi2 < 0.0 && r.feature != 0) ++neither;
    if (std::min(r.g1, r.g2) < 0.0) ++penetrating;
    const PairKinematics k = c.eval();
    ASSERT_EQ(k.ndof, 8);
    EXPECT_GT(max_abs(k.d2slip, 64), 1e-3);
    EXPECT_GT(max_abs(k.d2gap, 64), 1e-3);
    const FdErrors e = fd_errors(c);
    EXPECT_LT(e.dgap, 1e-6) << region_name(region) << " trial " << trial;
    EXPECT_LT(e.dslip, 1e-6) << region_name(region) << " trial " << trial;
    EXPECT_LT(e.d2gap, 1e-6) << region_name(region) << " trial " << trial;
    EXPECT_LT(e.d2slip, 1e-6) << region_name(region) << " trial " << trial;
    worst.dgap = std::max(worst.dgap, e.dgap);
    worst.dslip = std::max(worst.dslip, e.dslip);
    worst.d2gap = std::max(worst.d2gap, e.d2gap);
    worst.d2slip = std::max(worst.d2slip, e.d2slip);
    // Symmetric Hessians.
    for (int i = 0; i < 8; ++i)
      for (int j = 0; j < i; ++j) {
        EXPECT_LE(std::fabs(k.d2gap[i * 8 + j] - k.d2gap[j * 8 + i]), 1e-13 * max_abs(k.d2gap, 64));
        EXPECT_LE(std::fabs(k.d2slip[i * 8 + j] - k.d2slip[j * 8 + i]), 1e-13 * max_abs(k.d2slip, 64));
      }
  }
  // The generator reached the intended features.
  switch (region) {
    case Region::ConvexVertex: EXPECT_EQ(count[0], 40); break;
    case Region::ConvexSeg1: EXPECT_EQ(count[1], 40); break;
    case Region::ConvexSeg2: EXPECT_EQ(count[2], 40); break;
    case Region::Concave:
      EXPECT_EQ(count[0], 0);
      EXPECT_GT(count[1], 0);
      EXPECT_GT(count[2], 0);
      EXPECT_GT(neither, 0);  // xi1 > 1 and xi2 < 0 at a concave corner: both candidates
      EXPECT_GT(penetrating, 0);
      break;
    case Region::ConvexPenetrating:
      EXPECT_EQ(penetrating, 40);
      EXPECT_GT(count[1], 0);
      EXPECT_GT(count[2], 0);
      break;
  }
  std::printf("  window %-18s: max rel FD error dgap %.2e dslip %.2e d2gap %.2e d2slip %.2e (features %d/%d/%d)\n",
              region_name(region), worst.dgap, worst.dslip, worst.d2gap, worst.d2slip, count[0], count[1], count[2]);
}

INSTANTIATE_TEST_SUITE_P(Regions, WindowFiniteDifferences,
                         ::testing::Values(Region::ConvexVertex, Region::ConvexSeg1, Region::ConvexSeg2, Region::Concave,
                                           Region::ConvexPenetrating),
                         [](const ::testing::TestParamInfo<Region> &pi) {
                           std::string name = region_name(pi.param);
                           std::replace(name.begin(), name.end(), ' ', '_');
                           return name;
                         });

TEST(WindowNode, VertexFeatureKnownAnswerAndLayout) {
  // Convex corner of the counter-clockwise unit square at v = (1, 0):
  // a = (0, 0) -> v -> b = (1, 1). Node at v + (0.3, -0.4): L = 0.5, n = (0.6, -0.8),
  // t = (0.8, 0.6); the node was 0.1 t behind at the step start: s = 0.1.
  const double q[8] = {0, 0, 1, 0, 1, 1, 1.3, -0.4};
  double q0[8];
  std::copy(q, q + 8, q0);
  q0[6] -= 0.1 * 0.8;
  q0[7] -= 0.1 * 0.6;
  int beyond = 7;
  const PairKinematics k = window_node(q, q0, &beyond);
  ASSERT_EQ(k.ndof, 8);
  EXPECT_EQ(beyond, 0);
  EXPECT_NEAR(k.gap, 0.5, 1e-15);
  EXPECT_NEAR(k.normal[0], 0.6, 1e-15);
  EXPECT_NEAR(k.normal[1], -0.8, 1e-15);
  EXPECT_NEAR(k.slip, 0.1, 1e-15);
  // dg/dp = n, dg/dv = -n, a and b absent.
  EXPECT_NEAR(k.dgap[6], 0.6, 1e-15);
  EXPECT_NEAR(k.dgap[7], -0.8, 1e-15);
  EXPECT_NEAR(k.dgap[2], -0.6, 1e-15);
  EXPECT_NEAR(k.dgap[3], 0.8, 1e-15);
  for (int i : {0, 1, 4, 5}) {
    EXPECT_EQ(k.dgap[i], 0.0);
    EXPECT_EQ(k.dslip[i], 0.0);
    for (int j = 0; j < 8; ++j) {
      EXPECT_EQ(k.d2gap[i * 8 + j], 0.0);
      EXPECT_EQ(k.d2slip[j * 8 + i], 0.0);
    }
  }
  // d2g/dp2 = t t^T / L (stride 8): (py, py) at 7 * 8 + 7, (vx, py) = -t_x t_y / L at 2 * 8 + 7.
  EXPECT_NEAR(k.d2gap[63], 0.36 / 0.5, 1e-14);
  EXPECT_NEAR(k.d2gap[2 * 8 + 7], -0.48 / 0.5, 1e-14);
  EXPECT_NEAR(k.d2gap[6 * 8 + 6], 0.64 / 0.5, 1e-14);
}

TEST(WindowNode, VertexFeatureEqualsRigidNodeOfZeroRadiusAtTheVertex) {
  std::mt19937 rng(31);
  for (int trial = 0; trial < 20; ++trial) {
    const Config c = random_window(Region::ConvexVertex, rng);
    const PairKinematics k = c.eval();
    // rigid_node: q = (cx, cy, theta, px, py), radius 0, no rotation.
    const double qr[5] = {c.q[2], c.q[3], 0.0, c.q[6], c.q[7]}, qr0[5] = {c.q0[2], c.q0[3], 0.0, c.q0[6], c.q0[7]};
    const PairKinematics kr = rigid_node(qr, qr0, 0.0);
    const int map[4] = {2, 3, 6, 7};  // rigid_node dofs 0, 1, 3, 4 -> window dofs
    const int rdof[4] = {0, 1, 3, 4};
    EXPECT_NEAR(k.gap, kr.gap, 1e-14);
    EXPECT_NEAR(k.slip, kr.slip, 1e-14);
    EXPECT_NEAR(k.normal[0], kr.normal[0], 1e-15);
    EXPECT_NEAR(k.normal[1], kr.normal[1], 1e-15);
    for (int i = 0; i < 4; ++i) {
      EXPECT_NEAR(k.dgap[map[i]], kr.dgap[rdof[i]], 1e-14);
      EXPECT_NEAR(k.dslip[map[i]], kr.dslip[rdof[i]], 1e-14);
      for (int j = 0; j < 4; ++j) {
        EXPECT_NEAR(k.d2gap[map[i] * 8 + map[j]], kr.d2gap[rdof[i] * 5 + rdof[j]], 1e-12);
        EXPECT_NEAR(k.d2slip[map[i] * 8 + map[j]], kr.d2slip[rdof[i] * 5 + rdof[j]], 1e-12);
      }
    }
  }
}

TEST(WindowNode, SegmentFeatureEqualsSegmentNodeOnTheSubConfiguration) {
  std::mt19937 rng(41);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  int tested[3] = {0, 0, 0};
  for (int trial = 0; trial < 400; ++trial) {
    // Any corner (convex or concave), p anywhere around it.
    const Corner cr = random_corner(2.6 * U(rng), rng);
    Config c;
    c.type = Pair::WindowNode;
    std::copy(cr.q, cr.q + 8, c.q);
    c.q[6] = cr.v[0] + 1.2 * U(rng);
    c.q[7] = cr.v[1] + 1.2 * U(rng);
    for (int i = 0; i < 8; ++i) c.q0[i] = c.q[i] + 0.3 * U(rng);
    const WindowRef r = window_ref(c.q);
    ++tested[r.feature];
    if (r.feature == 0) continue;
    double qs[6], qs0[6];
    sub_config(c.q, r.feature, qs);
    sub_config(c.q0, r.feature, qs0);
    const PairKinematics k = c.eval(), ks = segment_node(qs, qs0);
    EXPECT_EQ(k.gap, ks.gap) << "trial " << trial;
    EXPECT_EQ(k.slip, ks.slip);
    EXPECT_EQ(k.normal[0], ks.normal[0]);
    EXPECT_EQ(k.normal[1], ks.normal[1]);
    // Window dof of sub-configuration dof i; the other master node's rows and columns are zero.
    auto W = [&](int i) { return (r.feature == 1 ? (i < 4 ? i : i + 2) : i + 2); };
    const int absent = r.feature == 1 ? 4 : 0;
    double present_sum = 0.0;
    for (int i = 0; i < 6; ++i) {
      EXPECT_EQ(k.dgap[W(i)], ks.dgap[i]);
      EXPECT_EQ(k.dslip[W(i)], ks.dslip[i]);
      for (int j = 0; j < 6; ++j) {
        EXPECT_EQ(k.d2gap[W(i) * 8 + W(j)], ks.d2gap[i * 6 + j]);
        EXPECT_EQ(k.d2slip[W(i) * 8 + W(j)], ks.d2slip[i * 6 + j]);
        present_sum += std::fabs(ks.d2slip[i * 6 + j]);
      }
    }
    EXPECT_GT(present_sum, 0.0);
    for (int i = absent; i < absent + 2; ++i) {
      EXPECT_EQ(k.dgap[i], 0.0);
      EXPECT_EQ(k.dslip[i], 0.0);
      for (int j = 0; j < 8; ++j) {
        EXPECT_EQ(k.d2gap[i * 8 + j], 0.0);
        EXPECT_EQ(k.d2gap[j * 8 + i], 0.0);
        EXPECT_EQ(k.d2slip[i * 8 + j], 0.0);
        EXPECT_EQ(k.d2slip[j * 8 + i], 0.0);
      }
    }
  }
  EXPECT_GT(tested[1], 50);
  EXPECT_GT(tested[2], 50);
  EXPECT_GT(tested[0], 5);
}

namespace {

// Walks p(s) = base + s dir, s in [s0, s1] (N steps), and records the largest
// jumps of gap, slip and normal between consecutive samples.
struct Walk {
  double step = 0, dgap = 0, dslip = 0, dnormal = 0;
  int first_feature = -1, last_feature = -1, switches = 0;
  double jump_at_switch_slip = 0;  // |slip jump| at the largest normal jump
};

Walk walk(const Config &c, const double base[2], const double dir[2], double s0, double s1, int N) {
  Walk w;
  w.step = (s1 - s0) / N * std::hypot(dir[0], dir[1]);
  double x[8];
  std::copy(c.q, c.q + 8, x);
  PairKinematics prev;
  int prev_feature = -1;
  for (int i = 0; i <= N; ++i) {
    const double s = s0 + (s1 - s0) * i / N;
    x[6] = base[0] + s * dir[0];
    x[7] = base[1] + s * dir[1];
    const PairKinematics k = window_node(x, c.q0);
    const int f = window_ref(x).feature;
    if (i == 0) w.first_feature = f;
    if (i > 0) {
      w.dgap = std::max(w.dgap, std::fabs(k.gap - prev.gap));
      w.dslip = std::max(w.dslip, std::fabs(k.slip - prev.slip));
      const double dn = std::hypot(k.normal[0] - prev.normal[0], k.normal[1] - prev.normal[1]);
      if (dn > w.dnormal) {
        w.dnormal = dn;
        w.jump_at_switch_slip = std::fabs(k.slip - prev.slip);
      }
      if (f != prev_feature) ++w.switches;
    }
    prev = k;
    prev_feature = f;
  }
  w.last_feature = prev_feature;
  return w;
}

}  // namespace

TEST(WindowNode, GapSlipAndNormalContinuousAcrossVertexSegmentSwitches) {
  std::mt19937 rng(53);
  std::uniform_real_distribution<double> U01(0.0, 1.0);
  double worst_g = 0, worst_s = 0, worst_n = 0;
  for (int trial = 0; trial < 20; ++trial) {
    const Config c = random_window(Region::ConvexVertex, rng);  // for its corner and q0
    const double v[2] = {c.q[2], c.q[3]};
    const double e1[2] = {c.q[2] - c.q[0], c.q[3] - c.q[1]}, e2[2] = {c.q[4] - c.q[2], c.q[5] - c.q[3]};
    const double l1 = std::hypot(e1[0], e1[1]), l2 = std::hypot(e2[0], e2[1]);
    const double t1[2] = {e1[0] / l1, e1[1] / l1}, t2[2] = {e2[0] / l2, e2[1] / l2};
    const double n1[2] = {t1[1], -t1[0]}, n2[2] = {t2[1], -t2[0]};
    const double off = 0.1 + 0.4 * U01(rng);
    const int N = 2000;
    // (1) seg1 -> vertex across xi1 = 1, (2) vertex -> seg2 across xi2 = 0.
    const double base1[2] = {v[0] + off * n1[0], v[1] + off * n1[1]};
    const double base2[2] = {v[0] + off * n2[0], v[1] + off * n2[1]};
    const Walk w1 = walk(c, base1, t1, -0.05, 0.05, N);
    const Walk w2 = walk(c, base2, t2, -0.05, 0.05, N);
    EXPECT_EQ(w1.first_feature, 1);
    EXPECT_EQ(w1.last_feature, 0);
    EXPECT_EQ(w1.switches, 1);
    EXPECT_EQ(w2.first_feature, 0);
    EXPECT_EQ(w2.last_feature, 2);
    EXPECT_EQ(w2.switches, 1);
    // (3) arc around the vertex from seg1 through the vertex region to seg2.
    Walk w3;
    {
      const double th_a = std::atan2(n1[1], n1[0]) - 0.3;
      double th_b = std::atan2(n2[1], n2[0]) + 0.3;
      while (th_b < th_a) th_b += 2 * kPi;
      double x[8];
      std::copy(c.q, c.q + 8, x);
      PairKinematics prev;
      int prev_f = -1;
      w3.step = off * (th_b - th_a) / N;
      for (int i = 0; i <= N; ++i) {
        const double th = th_a + (th_b - th_a) * i / N;
        x[6] = v[0] + off * std::cos(th);
        x[7] = v[1] + off * std::sin(th);
        const PairKinematics k = window_node(x, c.q0);
        const int f = window_ref(x).feature;
        if (i == 0) w3.first_feature = f;
        if (i > 0) {
          w3.dgap = std::max(w3.dgap, std::fabs(k.gap - prev.gap));
          w3.dslip = std::max(w3.dslip, std::fabs(k.slip - prev.slip));
          w3.dnormal = std::max(w3.dnormal, std::hypot(k.normal[0] - prev.normal[0], k.normal[1] - prev.normal[1]));
          if (f != prev_f) ++w3.switches;
        }
        prev = k;
        prev_f = f;
      }
      w3.last_feature = prev_f;
    }
    EXPECT_EQ(w3.first_feature, 1);
    EXPECT_EQ(w3.last_feature, 2);
    EXPECT_EQ(w3.switches, 2);
    for (const Walk *w : std::array<const Walk *, 3>{&w1, &w2, &w3}) {
      // |dg/dp| <= 1, |dn/dp| <= 1 / |p - v|, |ds/dp| <= |q0 - q| / off: O(step) jumps.
      EXPECT_LE(w->dgap, 1.01 * w->step);
      EXPECT_LE(w->dslip, 20.0 * w->step);
      EXPECT_LE(w->dnormal, 1.01 * w->step / (off - 0.05));
      worst_g = std::max(worst_g, w->dgap / w->step);
      worst_s = std::max(worst_s, w->dslip / w->step);
      worst_n = std::max(worst_n, w->dnormal / w->step);
    }
  }
  std::printf("  max jump / step: gap %.3f slip %.3f normal %.3f\n", worst_g, worst_s, worst_n);
}

TEST(WindowNode, GapContinuousAndSlipJumpsAcrossSegmentSegmentSwitch) {
  // seg1 <-> seg2 where g1 = g2: the node on the bisector of a penetrated
  // convex corner, or of the exterior of a concave corner. The gap is
  // continuous; the normal and the slip jump (each segment measures the slip
  // along its own tangent), by exactly the difference of the two segments'
  // values at the switch.
  std::mt19937 rng(61);
  std::uniform_real_distribution<double> U(-1.0, 1.0), U01(0.0, 1.0);
  double worst_g = 0, min_slip_jump = 1e300;
  for (int trial = 0; trial < 20; ++trial) {
    const bool concave = trial % 2 == 1;
    const double phi = (concave ? -1.0 : 1.0) * (0.4 + 2.0 * U01(rng));
    const Corner cr = random_corner(phi, rng);
    Config c;
    c.type = Pair::WindowNode;
    std::copy(cr.q, cr.q + 8, c.q);
    for (int i = 0; i < 8; ++i) c.q0[i] = c.q[i] + 0.3 * U(rng);
    // Bisector of -t1 (towards a) and t2 (towards b): the interior of a
    // convex corner, the exterior of a concave one; g1 = g2 on it.
    double bis[2] = {cr.t2[0] - cr.t1[0], cr.t2[1] - cr.t1[1]};
    const double lb = std::hypot(bis[0], bis[1]);
    bis[0] /= lb, bis[1] /= lb;
    const double perp[2] = {-bis[1], bis[0]};
    const double rho = 0.1 + 0.3 * U01(rng);
    const double base[2] = {cr.v[0] + rho * bis[0], cr.v[1] + rho * bis[1]};
    const Walk w = walk(c, base, perp, -0.02, 0.02, 2000);
    EXPECT_NE(w.first_feature, w.last_feature);
    EXPECT_NE(w.first_feature, 0);
    EXPECT_NE(w.last_feature, 0);
    EXPECT_EQ(w.switches, 1);
    EXPECT_LE(w.dgap, 1.01 * w.step);
    worst_g = std::max(worst_g, w.dgap / w.step);
    // Both segments' line gaps are negative (convex) / positive (concave) there.
    double qs[8];
    std::copy(c.q, c.q + 8, qs);
    qs[6] = base[0], qs[7] = base[1];
    const WindowRef r = window_ref(qs);
    EXPECT_NEAR(r.g1, r.g2, 1e-12);
    EXPECT_EQ(r.g1 < 0.0, !concave);
    // Slip jump = difference of the two segment_node slips at the switch.
    double q1[6], q10[6], q2[6], q20[6];
    sub_config(qs, 1, q1);
    sub_config(c.q0, 1, q10);
    sub_config(qs, 2, q2);
    sub_config(c.q0, 2, q20);
    const double predicted = std::fabs(segment_node(q1, q10).slip - segment_node(q2, q20).slip);
    const double slope = 20.0 * w.step;  // what the smooth part can contribute in one step
    EXPECT_NEAR(w.jump_at_switch_slip, predicted, slope);
    EXPECT_GT(w.dnormal, 0.1);  // the normal switches from n1 to n2
    min_slip_jump = std::min(min_slip_jump, predicted);
  }
  EXPECT_GT(min_slip_jump, 0.0);
  std::printf("  max gap jump / step %.3f; smallest slip jump at the switch %.3e\n", worst_g, min_slip_jump);
}

TEST(WindowNode, BeyondFlag) {
  // Convex corner (left turn) a = (-1, 0) -> v = (0, 0) -> b = (0, 1).
  const double qc[8] = {-1, 0, 0, 0, 0, 1, 0, 0};
  auto at = [](const double *q, double px, double py, int *beyond) {
    double x[8];
    std::copy(q, q + 8, x);
    x[6] = px, x[7] = py;
    return window_node(x, x, beyond);
  };
  int beyond = 99;
  // Behind a, below seg1 (xi1 = -0.5, xi2 = 0.3 / 1 < 0 ... -0.3): seg1 only, beyond a.
  PairKinematics k = at(qc, -1.5, -0.3, &beyond);
  EXPECT_EQ(beyond, -1);
  EXPECT_NEAR(k.gap, 0.3, 1e-15);
  EXPECT_NEAR(k.normal[1], -1.0, 1e-15);
  // Past b, right of seg2 (xi2 = 1.5, xi1 = 1.3): seg2 only, beyond b.
  k = at(qc, 0.3, 1.5, &beyond);
  EXPECT_EQ(beyond, +1);
  EXPECT_NEAR(k.gap, 0.3, 1e-15);
  EXPECT_NEAR(k.normal[0], 1.0, 1e-15);
  // Inside the window: seg1 at xi1 = 0.5, seg2 at xi2 = 0.5, the vertex.
  const double inside[3][2] = {{-0.5, -0.2}, {0.2, 0.5}, {0.2, -0.2}};
  for (const auto &p : inside) {
    beyond = 99;
    at(qc, p[0], p[1], &beyond);
    EXPECT_EQ(beyond, 0) << p[0] << "," << p[1];
  }
  // Penetrating under the corner: both applicable, the larger gap wins even
  // if the closest point of the other segment is out of the window.
  // Sharp convex corner a = (-1, 0) -> v = (0, 0) -> b = (-1, 0.2).
  const double qs[8] = {-1, 0, 0, 0, -1, 0.2, 0, 0};
  k = at(qs, -1.5, 0.05, &beyond);  // xi1 = -0.5, xi2 > 1; g1 = -0.05 > g2
  EXPECT_EQ(beyond, -1);
  EXPECT_NEAR(k.gap, -0.05, 1e-15);
  k = at(qs, -0.5, 0.03, &beyond);  // xi1 = 0.5, g1 = -0.03 > g2 = -0.07 / |b - v|: seg1 in the window
  EXPECT_EQ(beyond, 0);
  EXPECT_NEAR(k.gap, -0.03, 1e-15);
  k = at(qs, -0.5, 0.08, &beyond);  // g2 = -0.02 / |b - v| > g1 = -0.08: seg2 (xi2 in [0, 1])
  EXPECT_EQ(beyond, 0);
  EXPECT_NEAR(k.gap, -0.02 / std::sqrt(1.04), 1e-15);
  // Concave corner (right turn) a = (-1, 0) -> v = (0, 0) -> b = (0, -1),
  // the body is y > 0 or x > 0: beyond b below it, beyond a at its left.
  const double qv[8] = {-1, 0, 0, 0, 0, -1, 0, 0};
  at(qv, 0.3, -1.4, &beyond);
  EXPECT_EQ(beyond, +1);
  at(qv, -1.4, -0.3, &beyond);
  EXPECT_EQ(beyond, -1);
  // xi1 = 1.3 > 1, xi2 = -0.2 < 0: both candidates, the smaller gap
  // (seg2, g2 = -0.3 < g1 = -0.2); xi2 < 0 on seg2 is not flagged.
  at(qv, 0.3, 0.2, &beyond);
  EXPECT_EQ(beyond, 0);
  EXPECT_NEAR(at(qv, 0.3, 0.2, nullptr).gap, -0.3, 1e-15);  // a null flag is accepted
  // Random windows: the flag follows the reference rule.
  std::mt19937 rng(71);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  int seen[3] = {0, 0, 0};
  for (int trial = 0; trial < 500; ++trial) {
    const Corner cr = random_corner(2.8 * U(rng), rng);
    double x[8];
    std::copy(cr.q, cr.q + 8, x);
    x[6] = cr.v[0] + 2.0 * U(rng);
    x[7] = cr.v[1] + 2.0 * U(rng);
    beyond = 99;
    window_node(x, x, &beyond);
    const int expected = window_ref(x).beyond;
    EXPECT_EQ(beyond, expected) << "trial " << trial;
    ++seen[expected + 1];
  }
  EXPECT_GT(seen[0], 20);
  EXPECT_GT(seen[1], 20);
  EXPECT_GT(seen[2], 20);
}

TEST(WindowNode, DegenerateInput) {
  // Node (almost) on the vertex inside the outer normal cone of a convex corner.
  const double q[8] = {-1, 0, 0, 0, 0, 1, 1e-14, -1e-14};
  int beyond = 99;
  PairKinematics k = window_node(q, q, &beyond);
  EXPECT_EQ(beyond, 0);
  EXPECT_NEAR(k.gap, std::sqrt(2.0) * 1e-14, 1e-28);
  EXPECT_EQ(k.normal[0], 0.0);
  EXPECT_EQ(k.normal[1], 0.0);
  EXPECT_EQ(k.slip, 0.0);
  EXPECT_EQ(max_abs(k.dgap, kMax), 0.0);
  EXPECT_EQ(max_abs(k.d2slip, kMax * kMax), 0.0);
  // ... while 1e-6 away it is a regular vertex feature.
  const double q1[8] = {-1, 0, 0, 0, 0, 1, 0.6e-6, -0.8e-6};
  k = window_node(q1, q1);
  EXPECT_NEAR(k.normal[0], 0.6, 1e-9);
  EXPECT_NEAR(k.normal[1], -0.8, 1e-9);
  // Collapsed a-v: the window is the segment v-b, whatever xi1.
  const double qa[8] = {0, 0, 0, 0, 0, 1, 0.3, -0.5};
  k = window_node(qa, qa, &beyond);
  const double qs[6] = {0, 0, 0, 1, 0.3, -0.5};
  const PairKinematics ks = segment_node(qs, qs);
  EXPECT_EQ(k.gap, ks.gap);
  EXPECT_NEAR(k.gap, 0.3, 1e-15);
  EXPECT_EQ(k.normal[0], 1.0);
  EXPECT_EQ(beyond, 0);
  // Collapsed v-b: the window is a-v; beyond v (xi1 > 1) is not flagged, beyond a is.
  const double qb[8] = {-1, 0, 0, 0, 0, 0, -1.5, -0.4};
  k = window_node(qb, qb, &beyond);
  EXPECT_NEAR(k.gap, 0.4, 1e-15);
  EXPECT_EQ(beyond, -1);
  // Both collapsed: segment_node's degenerate result, distance to a.
  const double qd[8] = {1, 2, 1, 2, 1, 2, 4, 6};
  k = window_node(qd, qd, &beyond);
  EXPECT_EQ(k.ndof, 8);
  EXPECT_DOUBLE_EQ(k.gap, 5.0);
  EXPECT_EQ(k.normal[0], 0.0);
  EXPECT_EQ(k.normal[1], 0.0);
  EXPECT_EQ(beyond, 0);
  EXPECT_EQ(max_abs(k.dgap, kMax), 0.0);
  EXPECT_EQ(max_abs(k.d2gap, kMax * kMax), 0.0);
}

int main(int argc, char **argv) {
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}

// ---------------------------------------------------------------------------
// patch_node: five master nodes on a perturbed circular arc (a deformed disk
// boundary, counter-clockwise), the node near the arc.
namespace {

// Arc of radius R around the origin, 5 nodes at angles -2h..2h around pi/2
// (counter-clockwise => from right to left on the top of the circle); the
// node at angle `at` (in segment units from the centre node) and radial
// offset `off` from the circle.
Config patch_config(double at, double off, std::mt19937 &rng, double jitter = 0.02) {
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  Config c;
  c.type = Pair::PatchNode;
  const double R = 1.0, h = 0.13;
  for (int j = 0; j < 5; ++j) {
    const double th = 0.5 * kPi + (j - 2) * h;
    const double r = R * (1.0 + jitter * U(rng));
    c.q[2 * j] = r * std::cos(th);
    c.q[2 * j + 1] = r * std::sin(th);
  }
  const double th = 0.5 * kPi + at * h;
  c.q[10] = (R + off) * std::cos(th);
  c.q[11] = (R + off) * std::sin(th);
  for (int i = 0; i < 12; ++i) c.q0[i] = c.q[i] + 0.05 * U(rng);
  return c;
}

// Nearest node (0..4) to the closest point of p on the patch polyline, and
// the closest point's distance to the nearest segment midpoint switch.
int nearest_vertex(const double *q, double *to_switch) {
  double best = 1e300;
  int v = 2;
  *to_switch = 1e300;
  for (int s = 0; s < 4; ++s) {
    const double ex = q[2 * s + 2] - q[2 * s], ey = q[2 * s + 3] - q[2 * s + 1];
    const double l2 = ex * ex + ey * ey;
    const double xi = std::clamp(((q[10] - q[2 * s]) * ex + (q[11] - q[2 * s + 1]) * ey) / l2, 0.0, 1.0);
    const double d = std::hypot(q[10] - q[2 * s] - xi * ex, q[11] - q[2 * s + 1] - xi * ey);
    if (d < best) best = d, v = s + (xi < 0.5 ? 0 : 1), *to_switch = std::fabs(xi - 0.5);
  }
  return v;
}

}  // namespace

TEST(PatchNode, FiniteDifferencesAwayFromSwitches) {
  std::mt19937 rng(97);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  FdErrors worst;
  int centres[5] = {0, 0, 0, 0, 0}, tested = 0;
  while (tested < 60) {
    // Outside (gap up to 0.05) and slightly penetrating nodes, across the middle three segments.
    const Config c = patch_config(1.4 * U(rng), 0.03 + 0.04 * U(rng), rng);
    double to_switch;
    const int v = nearest_vertex(c.q, &to_switch);
    if (to_switch < 0.02) continue;  // FD stencil must not straddle a window switch
    ++centres[v];
    ++tested;
    const PairKinematics k = c.eval();
    ASSERT_EQ(k.ndof, 12);
    const FdErrors e = fd_errors(c);
    EXPECT_LT(e.dgap, 1e-6);
    EXPECT_LT(e.dslip, 1e-6);
    EXPECT_LT(e.d2gap, 1e-6);
    EXPECT_LT(e.d2slip, 1e-6);
    worst.dgap = std::max(worst.dgap, e.dgap), worst.dslip = std::max(worst.dslip, e.dslip);
    worst.d2gap = std::max(worst.d2gap, e.d2gap), worst.d2slip = std::max(worst.d2slip, e.d2slip);
  }
  // All three interior windows were exercised.
  EXPECT_GT(centres[1], 0);
  EXPECT_GT(centres[2], 0);
  EXPECT_GT(centres[3], 0);
  std::printf("  patch: max rel FD error dgap %.2e dslip %.2e d2gap %.2e d2slip %.2e\n", worst.dgap, worst.dslip,
              worst.d2gap, worst.d2slip);
}

TEST(PatchNode, EqualsWindowNodeOnTheNearestInteriorNode) {
  std::mt19937 rng(98);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  for (int trial = 0; trial < 100; ++trial) {
    const Config c = patch_config(1.9 * U(rng), 0.05 * U(rng), rng);
    double to_switch;
    const int centre = std::clamp(nearest_vertex(c.q, &to_switch), 1, 3);
    double qw[8], qw0[8];
    const int blocks[4] = {centre - 1, centre, centre + 1, 5};
    for (int X = 0; X < 4; ++X)
      for (int i = 0; i < 2; ++i) qw[2 * X + i] = c.q[2 * blocks[X] + i], qw0[2 * X + i] = c.q0[2 * blocks[X] + i];
    const PairKinematics w = window_node(qw, qw0), k = c.eval();
    EXPECT_EQ(k.gap, w.gap);
    EXPECT_EQ(k.slip, w.slip);
    for (int X = 0; X < 4; ++X)
      for (int i = 0; i < 2; ++i) {
        EXPECT_EQ(k.dgap[2 * blocks[X] + i], w.dgap[2 * X + i]);
        EXPECT_EQ(k.dslip[2 * blocks[X] + i], w.dslip[2 * X + i]);
      }
    // Unused master nodes carry nothing.
    for (int j = 0; j < 5; ++j)
      if (j < centre - 1 || j > centre + 1)
        for (int i = 0; i < 2; ++i) EXPECT_EQ(k.dgap[2 * j + i], 0.0);
  }
}

TEST(PatchNode, GapAndSlipContinuousWhenTheWindowMoves) {
  // A node sliding along the patch at a fixed offset outside it crosses the
  // two window switches (segment midpoints). Continuity: the largest change
  // of gap and slip between neighbouring samples shrinks in proportion to the
  // sample spacing (a jump would not shrink).
  std::mt19937 rng(99);
  const Config base = patch_config(0.0, 0.02, rng, 0.0);
  auto max_jumps = [&](int N, double *gap_jump, double *slip_jump) {
    Config c = base;
    double prev_gap = 0.0, prev_slip = 0.0;
    int switches = 0, prev_centre = -1;
    *gap_jump = *slip_jump = 0.0;
    for (int i = 0; i <= N; ++i) {
      const double at = -1.9 + 3.8 * i / N, th = 0.5 * kPi + at * 0.13;
      c.q[10] = 1.02 * std::cos(th), c.q[11] = 1.02 * std::sin(th);
      const PairKinematics k = c.eval();
      double to_switch;
      const int centre = std::clamp(nearest_vertex(c.q, &to_switch), 1, 3);
      if (i > 0) {
        *gap_jump = std::max(*gap_jump, std::fabs(k.gap - prev_gap));
        *slip_jump = std::max(*slip_jump, std::fabs(k.slip - prev_slip));
        switches += centre != prev_centre;
      }
      prev_gap = k.gap, prev_slip = k.slip, prev_centre = centre;
    }
    return switches;
  };
  double g1, s1, g2, s2;
  EXPECT_EQ(max_jumps(1000, &g1, &s1), 2);
  EXPECT_EQ(max_jumps(8000, &g2, &s2), 2);
  EXPECT_LT(g2, 0.25 * g1);
  EXPECT_LT(s2, 0.25 * s1);
  std::printf("  patch continuity: max jumps gap %.2e -> %.2e, slip %.2e -> %.2e for 8x finer sampling\n", g1, g2, s1, s2);
}

TEST(PatchNode, BeyondFlagAtThePatchEnds) {
  std::mt19937 rng(100);
  int flagged[3] = {0, 0, 0};
  for (int i = 0; i <= 200; ++i) {
    const double at = -2.4 + 4.8 * i / 200.0;
    const Config c = patch_config(at, 0.02, rng, 0.0);
    int beyond = 7;
    patch_node(c.q, c.q0, &beyond);
    ASSERT_TRUE(beyond >= -1 && beyond <= 1);
    ++flagged[beyond + 1];
    if (at > -1.0 && at < 1.0) EXPECT_EQ(beyond, 0) << "at " << at;      // within m1..m3: inside
    if (at < -1.6) EXPECT_EQ(beyond, -1) << "at " << at;                  // nearest node m0 or beyond
    if (at > 1.6) EXPECT_EQ(beyond, 1) << "at " << at;
  }
  EXPECT_GT(flagged[0], 0);
  EXPECT_GT(flagged[1], 0);
  EXPECT_GT(flagged[2], 0);
}

// ---------------------------------------------------------------------------
// curve_node: node against the C1 Catmull-Rom curve through five master nodes.
TEST(CurveNode, FiniteDifferences) {
  std::mt19937 rng(101);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  FdErrors worst;
  for (int trial = 0; trial < 60; ++trial) {
    Config c = patch_config(0.95 * U(rng), 0.03 + 0.04 * U(rng), rng);
    c.type = Pair::CurveNode;
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

// Scene tests of the global contact problem (CompactionProblem): one
// neo-Hookean P2 disk (diameter 1, 96 triangles) between four pressure-driven
// walls.
//
//  * Tangent: the Jacobian (elements, contact NCP rows and columns, wall
//    pressure Hessian, rotation gauge) against central differences of the
//    residual, column by column, at a perturbed state whose NCP branches are
//    kept away from their switching surface; the proximal term is exactly
//    rho on the body and wall diagonal.
//  * Conservation: the residual has no component along a rigid translation
//    of bodies + walls, and is invariant under that translation.
//  * Converged states: Signorini conditions, wall balance P x length, the
//    virial identity sum_a x_a (x) f_int,a = moment of the contact and gauge
//    forces (element kernel only; its contact diagonal is -P A_box), phi from
//    Green's theorem on the parabolic boundary, min and Fischer-Burmeister NCP
//    agreeing, and (separate test) a vanishing rotation-gauge torque.
//  * Small load: phi -> pi/4 and the area change predicted by linear
//    elasticity from the exact mean stress -P / phi; phi monotone in P.
//  * An inverted element is never accepted by Solve.
#include <gtest/gtest.h>
#include <petscsnes.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include "deformix/contact_law.hpp"
#include "deformix/disk_mesh.hpp"
#include "deformix/hyperelastic_element.hpp"
#include "deformix/load_controller.hpp"
#include "deformix/problem.hpp"
#include "deformix/wall_box.hpp"

using namespace deformix;

namespace {

const double kPi = std::acos(-1.0);
const double kRadius = 0.5;  // diameter d = 1

#define ASSERT_PETSC(call) ASSERT_EQ(static_cast<int>(call), 0) << #call

std::unique_ptr<CompactionProblem> MakeDisk(const ProblemParameters &params, int triangles = 92) {
  auto problem = std::make_unique<CompactionProblem>(PETSC_COMM_WORLD);
  if (problem->SetParameters(params)) return nullptr;
  problem->AddDeformableBody(make_disk_mesh(kRadius, triangles, 2), 0.0, 0.0);
  const double walls[4] = {-kRadius, kRadius, -kRadius, kRadius};
  problem->SetWalls(walls);
  return problem;
}

// Brings the problem to P (E = params.young) through the load controller.
void LoadTo(CompactionProblem &problem, double P, double *step, LevelReport *rep = nullptr) {
  LoadControlParameters load;
  LevelReport local;
  ASSERT_PETSC(AdvanceToPressure(problem, load, P, step, rep ? rep : &local));
  ASSERT_TRUE((rep ? rep : &local)->converged);
}

std::vector<double> VecToStd(Vec v) {
  PetscInt n;
  const PetscScalar *a;
  VecGetSize(v, &n);
  VecGetArrayRead(v, &a);
  std::vector<double> out(a, a + n);
  VecRestoreArrayRead(v, &a);
  return out;
}

void StdToVec(const std::vector<double> &x, Vec v) {
  PetscScalar *a;
  VecGetArray(v, &a);
  std::copy(x.begin(), x.end(), a);
  VecRestoreArray(v, &a);
}

PetscErrorCode Residual(CompactionProblem &problem, const std::vector<double> &z, Vec zv, Vec Fv,
                        std::vector<double> *F) {
  PetscFunctionBeginUser;
  StdToVec(z, zv);
  PetscCall(problem.EvaluateResidual(zv, Fv));
  *F = VecToStd(Fv);
  PetscFunctionReturn(0);
}

// Dense row-major copy of the Jacobian at z.
PetscErrorCode DenseJacobian(CompactionProblem &problem, Vec z, std::vector<double> *Jd) {
  Mat J, D;
  PetscInt n;
  const PetscScalar *a;
  PetscFunctionBeginUser;
  PetscCall(problem.EvaluateJacobian(z, &J));
  PetscCall(MatConvert(J, MATDENSE, MAT_INITIAL_MATRIX, &D));
  PetscCall(MatGetSize(D, &n, nullptr));
  PetscCall(MatDenseGetArrayRead(D, &a));  // column-major
  Jd->assign(n * n, 0.0);
  for (PetscInt i = 0; i < n; ++i)
    for (PetscInt j = 0; j < n; ++j) (*Jd)[i * n + j] = a[j * n + i];
  PetscCall(MatDenseRestoreArrayRead(D, &a));
  PetscCall(MatDestroy(&D));
  PetscCall(MatDestroy(&J));
  PetscFunctionReturn(0);
}

// Unknown layout, from the public description (bodies, 4 walls, gauges, multipliers).
struct Layout {
  PetscInt n_body = 0, wall = 0, gauge = 0, n_gauge = 0, mode = 0, lambda = 0, n_total = 0;
};
Layout LayoutOf(const CompactionProblem &problem, PetscInt n_total) {
  Layout l;
  for (const auto &b : problem.Bodies()) l.n_body += 2 * b.mesh.num_nodes();
  l.wall = l.n_body;
  l.gauge = l.n_body + 4;
  l.n_gauge = problem.Parameters().constrain_rotation ? static_cast<PetscInt>(problem.Bodies().size()) : 0;
  l.mode = l.gauge + l.n_gauge;  // three rigid-mode unknowns of the anchor per deformable body
  l.lambda = l.mode + 3 * static_cast<PetscInt>(problem.Bodies().size());
  l.n_total = n_total;
  return l;
}

// Gap of candidate c at the packed state z, recomputed here from the mesh
// (independent of the assembly).
double CandidateGap(const CompactionProblem &problem, const Layout &l, const std::vector<double> &z, size_t c) {
  const ContactCandidate &cc = problem.Candidates()[c];
  const DeformableBody &body = problem.Bodies()[cc.body];
  const BoundaryPoint bp = boundary_point(body.mesh, cc.point);
  double p[2] = {0.0, 0.0};
  for (int k = 0; k < bp.n; ++k)
    for (int i = 0; i < 2; ++i) {
      const int n = bp.nodes[k];
      p[i] += bp.coeff[k] * (body.center[i] + body.mesh.X[2 * n + i] + z[body.dof_offset + 2 * n + i]);
    }
  double g[4];
  WallBox::point_gaps(p, &z[l.wall], g);
  return g[cc.wall];
}

// Area enclosed by the deformed parabolic boundary of body b (Green's theorem,
// 3-point Gauss per edge: exact for the cubic integrand).
double BoundaryArea(const CompactionProblem &problem, int b) {
  const DiskMesh &m = problem.Bodies()[b].mesh;
  const int nb = static_cast<int>(m.boundary.size());
  const double gp[3] = {0.5 - std::sqrt(0.15), 0.5, 0.5 + std::sqrt(0.15)};
  const double gw[3] = {5.0 / 18.0, 8.0 / 18.0, 5.0 / 18.0};
  double area = 0.0;
  for (int e = 0; e < nb; e += 2) {
    double xa[2], xm[2], xb[2];
    problem.NodePosition(b, m.boundary[e], xa);
    problem.NodePosition(b, m.boundary[e + 1], xm);
    problem.NodePosition(b, m.boundary[(e + 2) % nb], xb);
    for (int q = 0; q < 3; ++q) {
      const double t = gp[q];
      // Lagrange interpolation through (0, xa), (1/2, xm), (1, xb).
      const double N[3] = {(1 - t) * (1 - 2 * t), 4 * t * (1 - t), t * (2 * t - 1)};
      const double dN[3] = {4 * t - 3, 4 - 8 * t, 4 * t - 1};
      double x[2] = {0, 0}, dx[2] = {0, 0};
      for (int i = 0; i < 2; ++i) {
        x[i] = N[0] * xa[i] + N[1] * xm[i] + N[2] * xb[i];
        dx[i] = dN[0] * xa[i] + dN[1] * xm[i] + dN[2] * xb[i];
      }
      area += gw[q] * 0.5 * (x[0] * dx[1] - x[1] * dx[0]);
    }
  }
  return area;
}

// Virial sum_a x_a (x) f_int,a = int sigma da (row-major 2x2) from the element kernel.
void Virial(const CompactionProblem &problem, double V[4]) {
  std::fill(V, V + 4, 0.0);
  for (int b = 0; b < static_cast<int>(problem.Bodies().size()); ++b) {
    const DeformableBody &body = problem.Bodies()[b];
    const DiskMesh &m = body.mesh;
    const int nen = m.nodes_per_cell();
    std::vector<double> Xe(2 * nen), xe(2 * nen), fe(2 * nen);
    for (int e = 0; e < m.num_cells(); ++e) {
      for (int a = 0; a < nen; ++a) {
        const int n = m.cells[e * nen + a];
        double x[2];
        problem.NodePosition(b, n, x);
        for (int i = 0; i < 2; ++i) Xe[2 * a + i] = m.X[2 * n + i], xe[2 * a + i] = x[i] - body.center[i];
      }
      const ElementResult r = triangle_element(problem.Material(), m.order, Xe.data(), xe.data(), fe.data(), nullptr);
      ASSERT_FALSE(r.inverted);
      for (int a = 0; a < nen; ++a) {
        double x[2];
        problem.NodePosition(b, m.cells[e * nen + a], x);
        for (int i = 0; i < 2; ++i)
          for (int j = 0; j < 2; ++j) V[2 * i + j] += x[i] * fe[2 * a + j];
      }
    }
  }
}

// A state near equilibrium at P/E = 0.05, perturbed so that every unknown
// enters the residual nonlinearly and no NCP function sits near its switch.
struct PerturbedState {
  std::vector<double> z;
  Layout layout;
  int active = 0, inactive = 0;
  double min_switch_distance = 0.0;  // min over candidates of |lambda - c_n g| (and of |(lambda, c_n g)| for FB)
};

void MakePerturbedState(CompactionProblem &problem, Vec zv, PerturbedState *s) {
  PetscInt n;
  VecGetSize(zv, &n);
  ASSERT_PETSC(problem.PackState(zv));
  s->z = VecToStd(zv);
  s->layout = LayoutOf(problem, n);
  const Layout &l = s->layout;
  ASSERT_EQ(l.lambda + static_cast<PetscInt>(problem.Candidates().size()), n);
  std::mt19937 rng(20240611);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  for (PetscInt i = 0; i < l.gauge; ++i) s->z[i] += 1e-3 * U(rng);           // displacements and walls
  for (PetscInt i = l.gauge; i < l.mode; ++i) s->z[i] += 1e-2 * U(rng);      // gauge torque
  const double c_n = problem.Parameters().ncp_scale * problem.Parameters().young;
  const double tau = 1e-3;
  s->min_switch_distance = 1e300;
  for (PetscInt c = 0; c < n - l.lambda; ++c) {
    double &lam = s->z[l.lambda + c];
    lam += 1e-3 * U(rng);
    const double cg = c_n * CandidateGap(problem, l, s->z, c);
    if (std::abs(lam - cg) < tau || std::hypot(lam, cg) < tau) lam += 3 * tau;  // push off the switch / kink
    const double sw = lam - cg;
    (sw >= 0 ? s->active : s->inactive)++;
    s->min_switch_distance = std::min({s->min_switch_distance, std::abs(sw), std::hypot(lam, cg)});
  }
}

class JacobianTest : public ::testing::TestWithParam<NcpFunction> {};

// 1. Jacobian against central differences of the residual, column by column.
TEST_P(JacobianTest, MatchesCentralDifferences) {
  ProblemParameters params;
  params.ncp = GetParam();
  params.prox_eta = 0.0;
  auto problem = MakeDisk(params);
  ASSERT_TRUE(problem);
  double step = -1.0;
  LoadTo(*problem, 0.05, &step);
  ASSERT_GT(problem->Summary().active_contacts, 0);

  Vec zv, Fv;
  ASSERT_PETSC(problem->CreateGlobalVector(&zv));
  ASSERT_PETSC(VecDuplicate(zv, &Fv));
  PerturbedState s;
  MakePerturbedState(*problem, zv, &s);
  ASSERT_GT(s.active, 0);
  ASSERT_GT(s.inactive, 0);
  ASSERT_GE(s.min_switch_distance, 1e-3);
  const PetscInt n = s.layout.n_total;

  StdToVec(s.z, zv);
  std::vector<double> J;
  ASSERT_PETSC(DenseJacobian(*problem, zv, &J));
  std::vector<double> F0;
  ASSERT_PETSC(Residual(*problem, s.z, zv, Fv, &F0));
  const std::vector<char> active0 = problem->ActiveSet();

  // |d(lambda - c_n g)/dz| <= c_n (2 + 1/2 + 1/2 + 1) for any unknown: with h = 1e-6
  // no switch is crossed (distance >= 1e-3); checked anyway below.
  const double h = 1e-6;
  double worst = 0.0;
  PetscInt worst_col = -1;
  int branch_changes = 0;
  std::vector<double> zp = s.z, Fp, Fm;
  for (PetscInt j = 0; j < n; ++j) {
    zp[j] = s.z[j] + h;
    ASSERT_PETSC(Residual(*problem, zp, zv, Fv, &Fp));
    branch_changes += problem->ActiveSet() != active0;
    zp[j] = s.z[j] - h;
    ASSERT_PETSC(Residual(*problem, zp, zv, Fv, &Fm));
    branch_changes += problem->ActiveSet() != active0;
    zp[j] = s.z[j];
    double scale = 0.0, err = 0.0;
    for (PetscInt i = 0; i < n; ++i) {
      const double fd = (Fp[i] - Fm[i]) / (2 * h);
      scale = std::max({scale, std::abs(fd), std::abs(J[i * n + j])});
      err = std::max(err, std::abs(fd - J[i * n + j]));
    }
    ASSERT_GT(scale, 0.0) << "column " << j << " of the Jacobian and of the difference quotient is zero";
    if (err / scale > worst) worst = err / scale, worst_col = j;
  }
  EXPECT_EQ(branch_changes, 0);
  RecordProperty("fd_jacobian_max_relative_column_error", std::to_string(worst));
  std::printf("  [%s] FD Jacobian: n = %d unknowns, %d active / %d inactive candidates, worst column %d: %.3e\n",
              GetParam() == NcpFunction::Min ? "min" : "fb", static_cast<int>(n), s.active, s.inactive,
              static_cast<int>(worst_col), worst);
  EXPECT_LT(worst, 1e-6) << "worst column " << worst_col << " (bodies < " << s.layout.wall << ", walls < "
                         << s.layout.gauge << ", gauges < " << s.layout.mode << ", rigid modes < " << s.layout.lambda << ", multipliers after)";
  VecDestroy(&zv);
  VecDestroy(&Fv);
}

INSTANTIATE_TEST_SUITE_P(Ncp, JacobianTest, ::testing::Values(NcpFunction::Min, NcpFunction::FischerBurmeister),
                         [](const ::testing::TestParamInfo<NcpFunction> &i) {
                           return std::string(i.param == NcpFunction::Min ? "min" : "fischer_burmeister");
                         });

// 1a. Merit() is the potential of the residual: with every multiplier at
// zero, the body and wall rows of F are the gradient of the enthalpy
// H = strain energy + P x box area (the energy merit of newton is built on
// it), checked against central differences of Merit() along random
// directions of the body and wall unknowns.
TEST(ContactProblem, MeritIsThePotentialOfTheResidual) {
  ProblemParameters params;
  params.constrain_rotation = PETSC_FALSE;
  auto problem = MakeDisk(params);
  ASSERT_TRUE(problem);
  double step = -1.0;
  const double P = 0.05;
  LoadTo(*problem, P, &step);
  Vec zv, Fv;
  ASSERT_PETSC(problem->CreateGlobalVector(&zv));
  ASSERT_PETSC(VecDuplicate(zv, &Fv));
  PetscInt n;
  VecGetSize(zv, &n);
  ASSERT_PETSC(problem->PackState(zv));
  std::vector<double> z = VecToStd(zv), F;
  const Layout l = LayoutOf(*problem, n);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  for (PetscInt i = 0; i < l.gauge; ++i) z[i] += 1e-5 * U(rng);
  ASSERT_GT(n, l.lambda) << "the loaded disk has contact candidates";
  for (PetscInt c = l.lambda; c < n; ++c) z[c] = 0.0;
  ASSERT_PETSC(Residual(*problem, z, zv, Fv, &F));
  const double h = 1e-7;
  for (int trial = 0; trial < 3; ++trial) {
    std::vector<double> v(n, 0.0), zp = z, zm = z;
    double slope = 0.0;
    for (PetscInt i = 0; i < l.gauge; ++i) v[i] = U(rng), slope += F[i] * v[i];
    for (PetscInt i = 0; i < l.gauge; ++i) zp[i] += h * v[i], zm[i] -= h * v[i];
    std::vector<double> Fp, Fm;
    ASSERT_PETSC(Residual(*problem, zp, zv, Fv, &Fp));
    const double mp = problem->Merit();
    ASSERT_PETSC(Residual(*problem, zm, zv, Fv, &Fm));
    const double fd = (mp - problem->Merit()) / (2 * h);
    std::printf("  direction %d: dMerit = %.10e, F . v = %.10e\n", trial, fd, slope);
    EXPECT_NEAR(fd, slope, 1e-6 * std::abs(slope) + 1e-10);
  }
  for (Vec *v : {&zv, &Fv}) VecDestroy(v);
}

// The PETSc index of the unknown that DescribeUnknown names `what` (-1: none).
PetscInt FindUnknown(const CompactionProblem &problem, Vec z, const std::string &what) {
  PetscInt n;
  VecGetSize(z, &n);
  for (PetscInt i = 0; i < n; ++i)
    if (problem.DescribeUnknown(problem.NaturalIndex(i)) == what) return i;
  return -1;
}

// A rigid disk of diameter 1 touching the four walls of a box of side 1:
// its layout vectors and its x unknown (-1 if setting up failed).
void RigidDiskInBox(const ProblemParameters &params, CompactionProblem &problem, Vec *z, Vec *F, PetscInt *x_dof) {
  *x_dof = -1;
  if (problem.SetParameters(params)) return;
  problem.AddRigidBody(0.0, 0.0, kRadius);
  const double walls[4] = {-kRadius, kRadius, -kRadius, kRadius};
  problem.SetWalls(walls);
  Mat J;
  KSP ksp;
  if (problem.RefreshCandidates() || problem.Layout(z, F, &J, &ksp)) return;
  *x_dof = FindUnknown(problem, *z, "rigid particle 0 dof 0");
}

// The contact part of newton's energy merit (ContactPenalty): a rigid disk
// of diameter 1 in a box of side 1, moved by delta towards the right wall,
// overlaps it by exactly delta and leaves the left wall by delta; the
// penalty counts the overlap beyond the overshoot a Newton step may leave
// (kOpenOvershoot <d>, here <d> = 1); the walls are frictionless, so no
// dissipation. Next test: a rigid pair with friction, where the dissipation
// is mu lambda_n |s| with lambda_n lagged by LagContactWeights at the iterate.
TEST(ContactProblem, EnergyMeritPenaltyMeasuresPenetrationAndDissipation) {
  ProblemParameters params;
  params.friction = 0.2;
  CompactionProblem problem(PETSC_COMM_WORLD);
  Vec z, F;
  PetscInt x_dof = -1;
  RigidDiskInBox(params, problem, &z, &F, &x_dof);
  ASSERT_GE(x_dof, 0);
  ASSERT_EQ(problem.Sizes().normal, 4) << "the four wall contacts";
  Vec zt;
  ASSERT_PETSC(VecDuplicate(z, &zt));
  const double overshoot = CompactionProblem::kOpenOvershoot * problem.MeanDiameter();
  for (double delta : {0.5 * overshoot, 2e-2}) {
    ASSERT_PETSC(VecCopy(z, zt));
    ASSERT_PETSC(VecSetValue(zt, x_dof, delta, ADD_VALUES));
    ASSERT_PETSC(VecAssemblyBegin(zt));
    ASSERT_PETSC(VecAssemblyEnd(zt));
    ASSERT_PETSC(problem.Residual(zt, F));
    ASSERT_PETSC(problem.LagContactWeights());
    double penetration = -1.0, dissipation = -1.0;
    ASSERT_PETSC(problem.ContactPenalty(&penetration, &dissipation));
    EXPECT_NEAR(penetration, std::max(0.0, delta - overshoot), 1e-12) << "delta " << delta;
    EXPECT_EQ(dissipation, 0.0) << "frictionless walls";
  }
  ASSERT_PETSC(VecDestroy(&zt));
}

// ContactStepFraction on a touching contact: a rigid disk of diameter 1 in a
// box of side 1 touches the right wall with a gap at round-off of zero, of
// either sign (a settled state). A step of 5 overshoots towards that wall is
// cut where the contact reaches -overshoot, at 1/5 of the step, whatever the
// sign of the round-off: the path must not depend on it (it differs between
// rank counts and BLAS libraries).
TEST(ContactProblem, StepFractionIsContinuousAtTouch) {
  ProblemParameters params;
  CompactionProblem problem(PETSC_COMM_WORLD);
  Vec z, F;
  PetscInt x_dof = -1;
  RigidDiskInBox(params, problem, &z, &F, &x_dof);
  ASSERT_GE(x_dof, 0);
  const double overshoot = CompactionProblem::kOpenOvershoot * problem.MeanDiameter();
  Vec zt, dz;
  ASSERT_PETSC(VecDuplicate(z, &zt));
  ASSERT_PETSC(VecDuplicate(z, &dz));
  ASSERT_PETSC(VecSet(dz, 0.0));
  ASSERT_PETSC(VecSetValue(dz, x_dof, 5.0 * overshoot, INSERT_VALUES));
  ASSERT_PETSC(VecAssemblyBegin(dz));
  ASSERT_PETSC(VecAssemblyEnd(dz));
  for (double eps : {-1e-15, 0.0, 1e-15}) {
    ASSERT_PETSC(VecCopy(z, zt));
    ASSERT_PETSC(VecSetValue(zt, x_dof, eps, ADD_VALUES));
    ASSERT_PETSC(VecAssemblyBegin(zt));
    ASSERT_PETSC(VecAssemblyEnd(zt));
    ASSERT_PETSC(problem.Residual(zt, F));
    double fraction = -1.0;
    ASSERT_PETSC(problem.ContactStepFraction(dz, &fraction));
    EXPECT_NEAR(fraction, 0.2, 1e-9) << "x offset " << eps;
  }
  ASSERT_PETSC(VecDestroy(&zt));
  ASSERT_PETSC(VecDestroy(&dz));
}

// CandidatesStale on two rigid disks of diameter 1 that are no candidate
// pair at a gap of 0.5 (margin 0.1): a gap inside the margin but outside
// kApproachFraction of it (0.05) needs no refresh, one inside it is an approaching
// pair, an overlap makes the candidates stale; after a refresh at a gap of
// 0.03 the pair is a candidate and nothing approaches any more.
TEST(ContactProblem, CandidatesStaleSeesApproachingAndOverlappingPairs) {
  ProblemParameters params;
  CompactionProblem problem(PETSC_COMM_WORLD);
  ASSERT_PETSC(problem.SetParameters(params));
  problem.AddRigidBody(0.0, 0.0, kRadius);
  problem.AddRigidBody(2 * kRadius + 0.5, 0.0, kRadius);
  const double walls[4] = {-kRadius - 1.0, 3 * kRadius + 1.5, -kRadius - 1.0, kRadius + 1.0};
  problem.SetWalls(walls);
  ASSERT_PETSC(problem.RefreshCandidates());
  Vec z, F;
  Mat J;
  KSP ksp;
  ASSERT_PETSC(problem.Layout(&z, &F, &J, &ksp));
  ASSERT_EQ(problem.Sizes().normal, 0) << "no pair or wall within the margin";
  const PetscInt x_dof = FindUnknown(problem, z, "rigid particle 1 dof 0");
  ASSERT_GE(x_dof, 0);
  Vec z0;  // the state at the gap of 0.5
  ASSERT_PETSC(VecDuplicate(z, &z0));
  ASSERT_PETSC(VecCopy(z, z0));
  const auto at_gap = [&](double gap, bool *stale, bool *approaching) -> PetscErrorCode {
    PetscFunctionBeginUser;
    PetscCall(VecCopy(z0, z));
    PetscCall(VecSetValue(z, x_dof, gap - 0.5, ADD_VALUES));
    PetscCall(VecAssemblyBegin(z));
    PetscCall(VecAssemblyEnd(z));
    PetscCall(problem.AdoptState(z));
    PetscCall(problem.CandidatesStale(stale, approaching));
    PetscFunctionReturn(0);
  };
  for (const auto &[gap, want_stale, want_approaching] : {std::tuple{0.08, false, false}, std::tuple{0.03, false, true}, std::tuple{-0.01, true, false}}) {
    bool stale = !want_stale, approaching = !want_approaching;
    ASSERT_PETSC(at_gap(gap, &stale, &approaching));
    EXPECT_EQ(stale, want_stale) << "gap " << gap;
    EXPECT_EQ(approaching, want_approaching) << "gap " << gap;
  }
  bool stale = true, approaching = true;
  ASSERT_PETSC(at_gap(0.03, &stale, &approaching));
  ASSERT_PETSC(VecDestroy(&z0));
  ASSERT_PETSC(problem.RefreshCandidates());
  ASSERT_PETSC(problem.Layout(&z, &F, &J, &ksp));
  EXPECT_EQ(problem.Sizes().normal, 1) << "the pair";
  ASSERT_PETSC(problem.CandidatesStale(&stale, &approaching));
  EXPECT_FALSE(stale);
  EXPECT_FALSE(approaching) << "the pair is a candidate after the refresh";
}

TEST(ContactProblem, EnergyMeritDissipationIsTrescaWithLaggedNormalForce) {
  ProblemParameters params;
  params.friction = 0.2;
  CompactionProblem problem(PETSC_COMM_WORLD);
  ASSERT_PETSC(problem.SetParameters(params));
  problem.AddRigidBody(0.0, 0.0, kRadius);
  problem.AddRigidBody(2 * kRadius, 0.0, kRadius);
  const double walls[4] = {-kRadius - 1.0, 3 * kRadius + 1.0, -kRadius - 1.0, kRadius + 1.0};
  problem.SetWalls(walls);
  ASSERT_PETSC(problem.RefreshCandidates());
  ASSERT_PETSC(problem.BeginLoadStep(1e-3));
  Vec z, F;
  Mat J;
  KSP ksp;
  ASSERT_PETSC(problem.Layout(&z, &F, &J, &ksp));
  ASSERT_EQ(problem.Sizes().normal, 1) << "the pair, no wall within reach";
  const PetscInt y_dof = FindUnknown(problem, z, "rigid particle 1 dof 1"), lambda_dof = FindUnknown(problem, z, "lambda_n");
  ASSERT_GE(y_dof, 0);
  ASSERT_GE(lambda_dof, 0);
  const double lambda_n = 0.3;
  ASSERT_PETSC(VecSetValue(z, lambda_dof, lambda_n, INSERT_VALUES));
  ASSERT_PETSC(VecAssemblyBegin(z));
  ASSERT_PETSC(VecAssemblyEnd(z));
  ASSERT_PETSC(problem.AdoptState(z));
  ASSERT_PETSC(problem.LagContactWeights());
  Vec zt;
  ASSERT_PETSC(VecDuplicate(z, &zt));
  for (double s : {1e-4, -3e-3}) {
    ASSERT_PETSC(VecCopy(z, zt));
    ASSERT_PETSC(VecSetValue(zt, lambda_dof, 0.0, INSERT_VALUES));  // the trial's multiplier does not enter
    ASSERT_PETSC(VecSetValue(zt, y_dof, s, ADD_VALUES));
    ASSERT_PETSC(VecAssemblyBegin(zt));
    ASSERT_PETSC(VecAssemblyEnd(zt));
    ASSERT_PETSC(problem.Residual(zt, F));
    double penetration = -1.0, dissipation = -1.0;
    ASSERT_PETSC(problem.ContactPenalty(&penetration, &dissipation));
    // Sliding by s along the contact plane: |slip| = |s| to first order, the
    // gap opens by s^2 / (2 d).
    EXPECT_NEAR(dissipation, 0.2 * lambda_n * std::abs(s), 1e-3 * 0.2 * lambda_n * std::abs(s)) << "slide " << s;
    EXPECT_EQ(penetration, 0.0);
  }
  ASSERT_PETSC(VecDestroy(&zt));
  ASSERT_PETSC(problem.EndLoadStep(false, nullptr));
}

// 1b. The proximal term is rho = prox_eta E on the body and wall diagonal and -prox_eta on the
// multiplier diagonal, nothing else.
TEST(ContactProblem, ProximalTermIsRhoOnBodyAndWallDiagonal) {
  ProblemParameters params;
  params.young = 2.5;
  params.prox_eta = 1e-3;  // large enough to be seen above roundoff
  auto problem = MakeDisk(params, 24);
  ASSERT_TRUE(problem);
  double step = -1.0;
  LoadTo(*problem, 0.05 * params.young, &step);
  Vec zv;
  ASSERT_PETSC(problem->CreateGlobalVector(&zv));
  PerturbedState s;
  MakePerturbedState(*problem, zv, &s);
  StdToVec(s.z, zv);
  std::vector<double> J1, J0;
  ASSERT_PETSC(DenseJacobian(*problem, zv, &J1));
  params.prox_eta = 0.0;
  ASSERT_PETSC(problem->SetParameters(params));
  Vec zv0;
  ASSERT_PETSC(problem->CreateGlobalVector(&zv0));
  StdToVec(s.z, zv0);
  ASSERT_PETSC(DenseJacobian(*problem, zv0, &J0));
  const PetscInt n = s.layout.n_total;
  ASSERT_EQ(J0.size(), J1.size());
  const double rho = 1e-3 * params.young;
  double err = 0.0;
  for (PetscInt i = 0; i < n; ++i)
    for (PetscInt j = 0; j < n; ++j) {
      // rho on body and wall unknowns, its dual -prox_eta on the multipliers.
      const double expected = i != j ? 0.0 : i < s.layout.gauge ? rho : i >= s.layout.lambda ? -1e-3 : 0.0;
      err = std::max(err, std::abs(J1[i * n + j] - J0[i * n + j] - expected));
    }
  EXPECT_LT(err, 1e-12 * params.young / (1 - 2 * params.poisson));
  VecDestroy(&zv);
  VecDestroy(&zv0);
}

// 1c. RotatedUpdate applies the mean rotation of a body's increment as a
// finite rotation: an increment that is the linearized rotation by theta
// about the centroid plus a translation t puts every node exactly at
// c + t + R(theta)(x - c), so no element changes its area; a translation, and
// every unknown that is not a node of a deformable body, is added as it is.
// StepMoves (the monitor's split of a step) reads the same rotation.
TEST(ContactProblem, RotatedUpdateAppliesTheMeanRotationExactly) {
  ProblemParameters params;
  auto problem = MakeDisk(params, 24);
  ASSERT_TRUE(problem);
  double step = -1.0;
  LoadTo(*problem, 0.05, &step);  // a deformed disk, multipliers nonzero
  Vec z, d, zt;
  ASSERT_PETSC(problem->CreateGlobalVector(&z));
  ASSERT_PETSC(problem->PackState(z));
  ASSERT_PETSC(VecDuplicate(z, &d));
  ASSERT_PETSC(VecDuplicate(z, &zt));
  const DeformableBody &body = problem->Bodies()[0];
  const int nn = body.mesh.num_nodes();
  PetscInt n;
  ASSERT_PETSC(VecGetSize(z, &n));
  std::vector<double> x(2 * nn);
  double c[2] = {0, 0};
  for (int a = 0; a < nn; ++a) {
    problem->NodePosition(0, a, &x[2 * a]);
    c[0] += x[2 * a] / nn, c[1] += x[2 * a + 1] / nn;
  }
  for (double theta : {0.0, 1e-3, 0.3, -1.2}) {
    const double t[2] = {0.01, -0.02};
    PetscScalar *da;
    ASSERT_PETSC(VecGetArray(d, &da));
    for (PetscInt i = 0; i < n; ++i) da[i] = 1e-3 * std::sin(1.0 + i);  // walls, multipliers: arbitrary
    for (int a = 0; a < nn; ++a) {
      const double r[2] = {x[2 * a] - c[0], x[2 * a + 1] - c[1]};
      da[body.dof_offset + 2 * a] = t[0] - theta * r[1];
      da[body.dof_offset + 2 * a + 1] = t[1] + theta * r[0];
    }
    ASSERT_PETSC(VecRestoreArray(d, &da));
    ASSERT_PETSC(problem->RotatedUpdate(z, d, zt));
    const PetscScalar *za, *zta, *db;
    ASSERT_PETSC(VecGetArrayRead(z, &za));
    ASSERT_PETSC(VecGetArrayRead(zt, &zta));
    ASSERT_PETSC(VecGetArrayRead(d, &db));
    double node_error = 0.0, other_error = 0.0;
    for (int a = 0; a < nn; ++a) {
      const double r[2] = {x[2 * a] - c[0], x[2 * a + 1] - c[1]};
      const double expected[2] = {c[0] + t[0] + std::cos(theta) * r[0] - std::sin(theta) * r[1],
                                  c[1] + t[1] + std::sin(theta) * r[0] + std::cos(theta) * r[1]};
      for (int i = 0; i < 2; ++i) {
        const PetscInt k = body.dof_offset + 2 * a + i;
        const double moved = body.mesh.X[2 * a + i] + zta[k];  // centre of the body at the origin
        node_error = std::max(node_error, std::abs(moved - expected[i]));
      }
    }
    for (PetscInt i = 2 * nn; i < n; ++i) other_error = std::max(other_error, std::abs(zta[i] - (za[i] + db[i])));
    ASSERT_PETSC(VecRestoreArrayRead(z, &za));
    ASSERT_PETSC(VecRestoreArrayRead(zt, &zta));
    ASSERT_PETSC(VecRestoreArrayRead(d, &db));
    EXPECT_LT(node_error, 1e-13) << "theta " << theta;
    EXPECT_EQ(other_error, 0.0) << "theta " << theta;
    // StepMoves splits the same increment into its translation |t| and
    // rotation |theta| R, with no deformation; a radial expansion e r added
    // to it is deformation only (it has no mean and no rotation about the
    // centroid), as large as e times the largest radius.
    double moves[3];
    ASSERT_PETSC(problem->StepMoves(z, d, moves));
    EXPECT_NEAR(moves[0], std::hypot(t[0], t[1]), 1e-14) << "theta " << theta;
    EXPECT_NEAR(moves[1], std::abs(theta) * body.mesh.radius, 1e-13) << "theta " << theta;
    EXPECT_LT(moves[2], 1e-13) << "theta " << theta;
    const double e = 2e-3;
    double rmax = 0.0;
    ASSERT_PETSC(VecGetArray(d, &da));
    for (int a = 0; a < nn; ++a) {
      const double r[2] = {x[2 * a] - c[0], x[2 * a + 1] - c[1]};
      da[body.dof_offset + 2 * a] += e * r[0], da[body.dof_offset + 2 * a + 1] += e * r[1];
      rmax = std::max(rmax, std::hypot(r[0], r[1]));
    }
    ASSERT_PETSC(VecRestoreArray(d, &da));
    ASSERT_PETSC(problem->StepMoves(z, d, moves));
    EXPECT_NEAR(moves[0], std::hypot(t[0], t[1]), 1e-13) << "theta " << theta;
    EXPECT_NEAR(moves[1], std::abs(theta) * body.mesh.radius, 1e-12) << "theta " << theta;
    EXPECT_NEAR(moves[2], e * rmax, 1e-13) << "theta " << theta;
  }
  VecDestroy(&z);
  VecDestroy(&d);
  VecDestroy(&zt);
}

// 3. Conservation: no residual component along a rigid translation of everything.
TEST(ContactProblem, ResidualHasNoRigidTranslationComponent) {
  ProblemParameters params;
  auto problem = MakeDisk(params);
  ASSERT_TRUE(problem);
  double step = -1.0;
  LoadTo(*problem, 0.05, &step);
  Vec zv, Fv;
  ASSERT_PETSC(problem->CreateGlobalVector(&zv));
  ASSERT_PETSC(VecDuplicate(zv, &Fv));
  PerturbedState s;
  MakePerturbedState(*problem, zv, &s);
  const Layout &l = s.layout;
  std::vector<double> F;
  ASSERT_PETSC(Residual(*problem, s.z, zv, Fv, &F));
  for (int dir = 0; dir < 2; ++dir) {
    // t: unit translation of every node and of the two walls normal to dir.
    std::vector<double> t(l.n_total, 0.0);
    for (PetscInt i = dir; i < l.n_body; i += 2) t[i] = 1.0;
    t[l.wall + 2 * dir] = t[l.wall + 2 * dir + 1] = 1.0;
    double dot = 0.0, mag = 0.0, rowmax = 0.0;
    for (PetscInt i = 0; i < l.n_total; ++i) {
      dot += t[i] * F[i];
      mag += std::abs(t[i] * F[i]);
      if (t[i] != 0.0) rowmax = std::max(rowmax, std::abs(F[i]));
    }
    // The perturbed state is far from equilibrium: the rows are O(1e-3 E d), their sum must vanish.
    EXPECT_GT(rowmax, 1e-5);
    EXPECT_LT(std::abs(dot), 1e-12 * mag) << "direction " << dir << ": t.R = " << dot;

    // Invariance: R(z + a t) = R(z).
    std::vector<double> zt = s.z, Ft;
    for (PetscInt i = 0; i < l.n_total; ++i) zt[i] += 0.01 * t[i];
    ASSERT_PETSC(Residual(*problem, zt, zv, Fv, &Ft));
    double diff = 0.0, fmax = 0.0;
    for (PetscInt i = 0; i < l.n_total; ++i)
      diff = std::max(diff, std::abs(Ft[i] - F[i])), fmax = std::max(fmax, std::abs(F[i]));
    EXPECT_LT(diff, 1e-10 * fmax) << "direction " << dir;
  }
  VecDestroy(&zv);
  VecDestroy(&Fv);
}

// 2. Converged states at several loads.
// Packed unknowns of the current state.
std::vector<double> PackedState(CompactionProblem &problem, Layout *layout) {
  Vec zv;
  PetscInt n;
  if (problem.CreateGlobalVector(&zv) || problem.PackState(zv)) return {};
  VecGetSize(zv, &n);
  std::vector<double> z = VecToStd(zv);
  VecDestroy(&zv);
  *layout = LayoutOf(problem, n);
  return z;
}

// Generalized force of the rotation gauge of body b on node a: mu_b G_a with
// G_a = (-Y_a, X_a) / n_nodes (the mean-rotation constraint, see problem.hpp).
void GaugeDirection(const DiskMesh &m, int a, double G[2]) {
  G[0] = -m.X[2 * a + 1] / m.num_nodes();
  G[1] = m.X[2 * a] / m.num_nodes();
}

// Moment about the origin of the gauge forces mu_b G on body b.
double GaugeMoment(const CompactionProblem &problem, int b, double mu) {
  const DiskMesh &m = problem.Bodies()[b].mesh;
  double M = 0.0;
  for (int a = 0; a < m.num_nodes(); ++a) {
    double x[2], G[2];
    problem.NodePosition(b, a, x);
    GaugeDirection(m, a, G);
    M += mu * (x[0] * G[1] - x[1] * G[0]);
  }
  return M;
}

void CheckConvergedState(CompactionProblem &problem, double P, const char *label) {
  const StateSummary s = problem.Summary();
  const double d = 2 * kRadius;
  std::printf("  [%s] P = %-6g phi = %.12f  penetration %.2e  min lambda %.2e  |lambda g| %.2e\n", label, P,
              s.packing_fraction, s.max_penetration, s.min_multiplier, s.max_complementarity);
  EXPECT_LE(s.max_penetration, 1e-10 * d);
  EXPECT_GE(s.min_multiplier, -1e-10 * P);
  EXPECT_LE(s.max_complementarity, 1e-10 * P * d * d);
  EXPECT_GT(s.min_cell_area_ratio, 0.0);
  const double lengths[4] = {s.box_height, s.box_height, s.box_width, s.box_width};
  double wall_err = 0.0;
  for (int k = 0; k < 4; ++k) {
    EXPECT_NEAR(s.wall_force[k], P * lengths[k], 1e-10 * P * lengths[k]) << "wall " << k;
    wall_err = std::max(wall_err, std::abs(s.wall_force[k] - P * lengths[k]) / (P * lengths[k]));
  }
  // The same sums from the candidate list, independently of Summary.
  double sums[4] = {0, 0, 0, 0};
  for (size_t c = 0; c < problem.Candidates().size(); ++c) sums[problem.Candidates()[c].wall] += problem.Multipliers()[c];
  for (int k = 0; k < 4; ++k) EXPECT_NEAR(sums[k], s.wall_force[k], 1e-14 * P);
  // Packing fraction: particle area from Green's theorem on the boundary, box from the walls.
  const double *w = problem.Walls();
  const double phi_green = BoundaryArea(problem, 0) / ((w[1] - w[0]) * (w[3] - w[2]));
  EXPECT_NEAR(s.packing_fraction, phi_green, 1e-12);

  // Virial: sum_a x_a (x) f_int,a (element kernel) must equal the same moment of
  // the external forces: contact multipliers at the boundary points along the
  // wall normals, plus the gauge forces mu G. Its xx and yy contact parts are
  // exactly -P A_box when every wall balances P x length and every loaded
  // point sits on its wall.
  Layout l;
  const std::vector<double> z = PackedState(problem, &l);
  ASSERT_FALSE(z.empty());
  double V[4], Vext[4] = {0, 0, 0, 0};
  Virial(problem, V);
  for (size_t c = 0; c < problem.Candidates().size(); ++c) {
    const ContactCandidate &cc = problem.Candidates()[c];
    double p[2];
    problem.BoundaryPointPosition(cc.body, cc.point, p);
    const double sign = (cc.wall == kLeft || cc.wall == kBottom) ? 1.0 : -1.0;
    const int dir = (cc.wall == kLeft || cc.wall == kRight) ? 0 : 1;
    for (int i = 0; i < 2; ++i) Vext[2 * i + dir] += p[i] * sign * problem.Multipliers()[c];
  }
  double M_gauge = 0.0;
  for (PetscInt b = 0; b < l.n_gauge; ++b) {
    const double mu = z[l.gauge + b];
    const DiskMesh &m = problem.Bodies()[b].mesh;
    for (int a = 0; a < m.num_nodes(); ++a) {
      double x[2], G[2];
      problem.NodePosition(static_cast<int>(b), a, x);
      GaugeDirection(m, a, G);
      for (int i = 0; i < 2; ++i)
        for (int j = 0; j < 2; ++j) Vext[2 * i + j] += x[i] * mu * G[j];
    }
    M_gauge = std::max(M_gauge, std::abs(GaugeMoment(problem, static_cast<int>(b), mu)));
  }
  const double PA = P * WallBox::area(w);
  double vir_err = 0.0, contact_xx_err = 0.0;
  for (int k = 0; k < 4; ++k) vir_err = std::max(vir_err, std::abs(V[k] - Vext[k]) / PA);
  // Newton stops at |R| <= 1e-11 E d: the virial of that residual is below ~1e-10 E d^2.
  const double E = problem.Parameters().young;
  EXPECT_LT(vir_err * PA, 1e-9 * PA + 1e-10 * E * d * d) << "internal virial differs from the external one";
  EXPECT_NEAR(V[1], V[2], 1e-12 * PA) << "virial not symmetric (Cauchy stress symmetry)";
  // Contact part alone: diagonal = -P A_box.
  double Vc[4] = {Vext[0], Vext[1], Vext[2], Vext[3]};
  for (PetscInt b = 0; b < l.n_gauge; ++b) {
    const DiskMesh &m = problem.Bodies()[b].mesh;
    for (int a = 0; a < m.num_nodes(); ++a) {
      double x[2], G[2];
      problem.NodePosition(static_cast<int>(b), a, x);
      GaugeDirection(m, a, G);
      for (int i = 0; i < 2; ++i)
        for (int j = 0; j < 2; ++j) Vc[2 * i + j] -= x[i] * z[l.gauge + b] * G[j];
    }
  }
  contact_xx_err = std::max(std::abs(Vc[0] + PA), std::abs(Vc[3] + PA)) / PA;
  EXPECT_LT(contact_xx_err, 1e-10);
  std::printf("  [%s] wall-force error %.2e  virial error %.2e  contact-virial error %.2e  |phi - phi_Green| %.2e"
              "  gauge moment / (P d^2) %.2e\n",
              label, wall_err, vir_err, contact_xx_err, std::abs(s.packing_fraction - phi_green), M_gauge / (P * d * d));
}

TEST(ContactProblem, ConvergedStatesSatisfySignoriniAndBalance) {
  const double levels[] = {1e-3, 0.1, 0.5};
  std::vector<double> phi[2];
  for (int f = 0; f < 2; ++f) {
    ProblemParameters params;
    params.ncp = f == 0 ? NcpFunction::Min : NcpFunction::FischerBurmeister;
    auto problem = MakeDisk(params);
    ASSERT_TRUE(problem);
    double step = -1.0;
    for (double P : levels) {
      LoadTo(*problem, P, &step);
      CheckConvergedState(*problem, P, f == 0 ? "min" : "fb");
      phi[f].push_back(problem->Summary().packing_fraction);
    }
  }
  for (size_t i = 0; i < phi[0].size(); ++i)
    EXPECT_NEAR(phi[0][i], phi[1][i], 1e-9) << "min vs Fischer-Burmeister at P/E = " << levels[i];
}

// Same at another modulus: the tolerances and observables scale with E.
TEST(ContactProblem, ConvergedStateScalesWithYoungModulus) {
  ProblemParameters params;
  params.young = 1000.0;
  auto stiff = MakeDisk(params);
  auto unit = MakeDisk(ProblemParameters());
  ASSERT_TRUE(stiff && unit);
  double s1 = -1.0, s2 = -1.0;
  LoadTo(*stiff, 0.1 * params.young, &s1);
  LoadTo(*unit, 0.1, &s2);
  CheckConvergedState(*stiff, 0.1 * params.young, "E=1000");
  EXPECT_NEAR(stiff->Summary().packing_fraction, unit->Summary().packing_fraction, 1e-9);
}

// 4. Small load: phi -> pi/4 and the linear-elastic area change.
TEST(ContactProblem, SmallLoadLimitAndMonotonicity) {
  ProblemParameters params;
  auto problem = MakeDisk(params);
  ASSERT_TRUE(problem);
  double step = -1.0;
  const double P = 1e-4;
  LoadTo(*problem, P, &step);
  const StateSummary s = problem->Summary();
  EXPECT_NEAR(s.packing_fraction, kPi / 4, 2e-3);
  EXPECT_GT(s.packing_fraction, kPi / 4 - 1e-4);  // compressed, never looser than the inscribed disk
  EXPECT_LT(s.area_ratio, 1.0);
  EXPECT_GT(s.area_ratio, 1.0 - 1e-3);
  // The mean Cauchy stress is exactly -P A_box / A = -P / phi in both directions
  // (virial). Linear plane-strain elasticity: dA/A = 2 sigma_m / (2 (lambda + mu))
  // = -2 (1 + nu)(1 - 2 nu) P / (E phi).
  const double nu = params.poisson;
  const double predicted = 2 * (1 + nu) * (1 - 2 * nu) * P / (params.young * s.packing_fraction);
  std::printf("  small load: phi - pi/4 = %.3e, 1 - area_ratio = %.6e, linear prediction %.6e\n",
              s.packing_fraction - kPi / 4, 1 - s.area_ratio, predicted);
  EXPECT_NEAR((1 - s.area_ratio) / predicted, 1.0, 0.01);
  CheckConvergedState(*problem, P, "small");

  double previous = s.packing_fraction;
  for (double level : {1e-3, 5e-3, 0.02, 0.05, 0.1, 0.2, 0.35, 0.5, 0.75, 1.0}) {
    LoadTo(*problem, level, &step);
    const double phi = problem->Summary().packing_fraction;
    EXPECT_GT(phi, previous) << "phi not increasing at P/E = " << level;
    EXPECT_LE(phi, 1.0 + 1e-12) << "phi above 1 at P/E = " << level;
    EXPECT_GT(problem->Summary().min_cell_area_ratio, 0.0);
    previous = phi;
  }
}

// The tangent predictor is the first-order Taylor step of the equilibrium
// path: on the single disk, whose contact patches do not change over a 1 %
// pressure increment, its predicted box misses the converged one by O(dP^2),
// while the last state (predictor none) misses it by O(dP).
TEST(ContactProblem, TangentPredictorIsSecondOrder) {
  for (double P : {0.02, 0.2}) {
    ProblemParameters params;
    params.predictor = LoadPredictor::Tangent;
    auto problem = MakeDisk(params);
    ASSERT_TRUE(problem);
    double step = -1.0;
    LoadTo(*problem, 0.5 * P, &step);
    LoadTo(*problem, P, &step);
    const double P1 = 1.01 * P;
    const StateSummary last = problem->Summary();
    ASSERT_PETSC(problem->BeginLoadStep(P1));
    const StateSummary predicted = problem->Summary();
    SolveReport undo;
    ASSERT_PETSC(problem->EndLoadStep(false, &undo));
    EXPECT_EQ(problem->Summary().box_width, last.box_width) << "a failed load step restores the state";
    LoadTo(*problem, P1, &step);
    const StateSummary converged = problem->Summary();
    const double err_tangent = std::hypot(predicted.box_width - converged.box_width, predicted.box_height - converged.box_height);
    const double err_none = std::hypot(last.box_width - converged.box_width, last.box_height - converged.box_height);
    std::printf("  P/E %g -> %g: box error of the tangent %.3e, of the last state %.3e\n", P, P1, err_tangent, err_none);
    EXPECT_GT(err_none, 0.0);
    EXPECT_LT(err_tangent, 0.02 * err_none);
  }
}

// The rotation gauge must not load the body: at a frictionless equilibrium its
// multiplier (a torque) vanishes (problem.hpp: "zero at the symmetric
// equilibrium"). Checked both as |mu| and as the moment of the gauge forces.
TEST(ContactProblem, GaugeTorqueVanishesAtEquilibrium) {
  auto problem = MakeDisk(ProblemParameters());
  ASSERT_TRUE(problem);
  double step = -1.0;
  const double d = 2 * kRadius;
  for (double P : {1e-3, 0.1, 0.5}) {
    LoadTo(*problem, P, &step);
    Layout l;
    const std::vector<double> z = PackedState(*problem, &l);
    ASSERT_EQ(l.n_gauge, 1);
    const double M = GaugeMoment(*problem, 0, z[l.gauge]);
    std::printf("  P/E = %-6g gauge multiplier %.3e  gauge moment %.3e = %.2e P d^2\n", P, z[l.gauge], M,
                M / (P * d * d));
    EXPECT_LE(problem->Summary().max_gauge_torque, 1e-8 * P * d);
    EXPECT_LE(std::abs(M), 1e-8 * P * d * d);
  }
}

// The tangent predictor factors the Newton matrix once per load step, and
// the level's report counts it: with anchored (one factorization per Newton
// iteration) the first level, which has no tangent, counts its iterations,
// the next one its iterations plus one.
TEST(ContactProblem, TangentPredictorFactorizationIsCounted) {
  ProblemParameters params;
  params.predictor = LoadPredictor::Tangent;
  auto problem = MakeDisk(params, 24);
  ASSERT_TRUE(problem);
  LoadControlParameters load;
  load.level.strategy = LevelStrategy::Anchored;
  double step = -1.0;
  const double pressures[] = {0.02, 0.05};
  for (int level = 0; level < 2; ++level) {
    LevelReport rep;
    ASSERT_PETSC(AdvanceToPressure(*problem, load, pressures[level], &step, &rep));
    ASSERT_TRUE(rep.converged);
    ASSERT_EQ(rep.cuts, 0) << "one load step per level";
    EXPECT_EQ(rep.factorizations, rep.newton_its + level) << "P/E = " << pressures[level];
  }
}

// Inverted element: no level solver accepts it. Started from a folded mesh,
// anchored fails with a domain error and leaves the state as it was (the
// load controller then cuts the step); the merit-tested strategies (newton,
// hybrid's attempt, auto, which is newton with the energy merit on this
// frictionless disk) rate the folded state as infinitely bad, so any
// unfolding step is accepted: they may reach an equilibrium, which must then
// be unfolded and balanced.
TEST(ContactProblem, InvertedStateIsNeverAccepted) {
  const char *const labels[] = {"newton", "anchored", "hybrid", "auto"};  // LevelStrategy order
  for (LevelStrategy strategy : {LevelStrategy::Anchored, LevelStrategy::Newton, LevelStrategy::Hybrid, LevelStrategy::Auto}) {
    const char *label = labels[static_cast<int>(strategy)];
    ProblemParameters params;
    auto problem = MakeDisk(params, 24);
    ASSERT_TRUE(problem);
    double step = -1.0;
    LoadTo(*problem, 0.05, &step);
    // Push an interior vertex (the centre) beyond its ring of neighbours: folds the mesh.
    CompactionProblem::State folded = problem->SaveState();
    const DiskMesh &m = problem->Bodies()[0].mesh;
    int interior = -1;
    for (int a = 0; a < m.num_vertices && interior < 0; ++a)
      if (std::hypot(m.X[2 * a], m.X[2 * a + 1]) < 0.6 * kRadius) interior = a;
    ASSERT_GE(interior, 0);
    folded.u[2 * interior] += 0.6 * kRadius;
    problem->RestoreState(folded);
    ASSERT_LT(problem->Summary().min_cell_area_ratio, 0.0) << "the fold did not invert an element";
    SolveReport rep;
    LevelSolverParameters level;
    level.strategy = strategy;
    ASSERT_PETSC(SolveLevel(*problem, level, 0.06, &rep));
    std::printf("  %s: %s (%s)\n", label, rep.converged ? "converged" : "failed", SNESConvergedReasons[rep.reason]);
    if (rep.converged) {
      EXPECT_NE(strategy, LevelStrategy::Anchored) << "anchored converged from an inverted state";
      EXPECT_GT(problem->Summary().min_cell_area_ratio, 0.0) << label << ": an inverted state accepted";
      EXPECT_LE(rep.residual, 1e-10) << label << ": accepted away from equilibrium";
    } else {
      // The documented mechanism (load_controller.hpp): an inverted element is a domain error.
      EXPECT_EQ(rep.reason, SNES_DIVERGED_FUNCTION_DOMAIN) << label << ": " << SNESConvergedReasons[rep.reason];
      EXPECT_LT(problem->Summary().min_cell_area_ratio, 0.0) << label << ": state not left unchanged after a failed solve";
    }
  }
}

}  // namespace

int main(int argc, char **argv) {
  ::testing::InitGoogleTest(&argc, argv);
  if (PetscInitialize(&argc, &argv, nullptr, nullptr)) return 1;
  const int result = RUN_ALL_TESTS();
  if (PetscFinalize()) return 1;
  return result;
}

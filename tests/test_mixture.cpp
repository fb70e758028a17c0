// Mixture scenes with analytic answers: rigid and deformable disks, every pair
// type, with and without Coulomb friction.
//
//  1. An n x n square arrangement of equal rigid disks of diameter d in the
//     box: phi = pi/4 at every pressure and a force P d at every contact
//     (each row of n disks carries the wall force P n d), with and without
//     friction.
//  2. Checkerboard mixtures of rigid and deformable disks: converged states
//     satisfy Signorini (no penetration, lambda_n >= 0, lambda_n g = 0) and
//     Coulomb (|lambda_t| <= mu lambda_n), and the contact stress equals the
//     imposed pressure (virial identity), at several pressures.
//  3. The Jacobian of a frictional mixture (rigid-rigid, rigid-node,
//     node-segment, walls) against central finite differences of the residual.
//  4. Kernel: the Coulomb NCP function's stick, slip and open branches.
//  5. A random 20-disk mixture with friction (the compact driver's scene):
//     Signorini, Coulomb, level criterion and virial check.
//  6. A rearrangement: a rigid rattler in the pore of four deformable disks
//     is caught when the pore closes, and ends in exact equilibrium.
//  7. The symmetric form of the Newton matrix: symmetric, and its LDL^T
//     gives LU's step.
#include <gtest/gtest.h>
#include <petscsnes.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "deformix/contact_law.hpp"
#include "deformix/load_controller.hpp"
#include "deformix/observables.hpp"
#include "deformix/packing.hpp"
#include "deformix/problem.hpp"

using namespace deformix;

namespace {

#define ASSERT_PETSC(call) ASSERT_EQ(static_cast<int>(call), 0) << #call

// n x n disks of diameter 1 on a unit square grid; pattern(i, j) says which are deformable.
template <class Pattern>
std::unique_ptr<CompactionProblem> Lattice(int n, double friction, Pattern deformable, bool mortar = false,
                                           int triangles = 92, double prox_eta = -1.0) {
  ProblemParameters p;
  p.friction = friction;
  if (prox_eta > 0.0) p.prox_eta = prox_eta;  // else the default
  p.deformable_contact = mortar ? DeformableContact::Mortar : DeformableContact::NodeToSegment;
  p.constrain_rotation = PETSC_FALSE;
  p.ptc_move = 0.02;  // as the compact driver: pseudo-transient continuation
  auto problem = std::make_unique<CompactionProblem>(PETSC_COMM_WORLD);
  if (problem->SetParameters(p)) return nullptr;
  const DiskMesh mesh = make_disk_mesh(0.5, triangles, 2);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      if (deformable(i, j)) problem->AddDeformableBody(mesh, i + 0.5, j + 0.5);
      else problem->AddRigidBody(i + 0.5, j + 0.5, 0.5);
    }
  const double w[4] = {0.0, double(n), 0.0, double(n)};
  problem->SetWalls(w);
  return problem;
}

void CheckSignoriniCoulomb(const CompactionProblem &problem, double P, const char *label) {
  const double mu = problem.Parameters().friction;
  const std::vector<ContactForce> forces = problem.ContactForces();
  for (const ContactForce &f : forces) {
    EXPECT_GE(f.gap, -1e-10) << label << ": penetration";
    EXPECT_GE(f.normal_multiplier, -1e-10 * P) << label << ": tensile contact force";
    // At convergence c_n g <= atol for closed contacts: |lambda g| is roundoff times P.
    EXPECT_LE(std::abs(f.normal_multiplier * f.gap), 1e-10 * P) << label << ": complementarity";
    EXPECT_LE(std::abs(f.tangential_multiplier), mu * f.normal_multiplier + 1e-10 * P) << label << ": Coulomb cone";
  }
  const PackingObservables o = ComputeObservables(problem);
  EXPECT_NEAR(o.mean_stress, P, 1e-8 * P) << label << ": contact stress vs imposed pressure";
  EXPECT_NEAR(MeanContactStress(problem), o.mean_stress, 1e-12 * P) << label << ": P_sigma alone vs the stress tensor";
}

TEST(Mixture, RigidSquareLatticeCarriesPdAtEveryContact) {
  for (double friction : {0.0, 0.3}) {
    auto problem = Lattice(3, friction, [](int, int) { return false; });
    ASSERT_TRUE(problem);
    LoadControlParameters load;
    double step = -1.0;
    for (double P : {1e-4, 1e-2, 0.1}) {
      LevelReport rep;
      ASSERT_PETSC(AdvanceToPressure(*problem, load, P, &step, &rep));
      const StateSummary s = problem->Summary();
      EXPECT_NEAR(s.packing_fraction, M_PI / 4, 1e-10) << "friction " << friction;
      int n_pair = 0;
      for (const ContactForce &f : problem->ContactForces()) {
        if (f.normal_multiplier <= 0.0) continue;
        // Rows and columns of equal disks: the force P x d (d = 1) everywhere.
        EXPECT_NEAR(f.normal_multiplier, P, 1e-5 * P) << "friction " << friction;
        EXPECT_NEAR(f.tangential_multiplier, 0.0, 1e-5 * P);
        n_pair += f.master_particle >= 0;
      }
      EXPECT_EQ(n_pair, 12);  // 2 n (n - 1) for n = 3
      CheckSignoriniCoulomb(*problem, P, "rigid lattice");
    }
  }
}

TEST(Mixture, CheckerboardSatisfiesSignoriniCoulombAndVirial) {
  for (double friction : {0.0, 0.5}) {
    auto problem = Lattice(2, friction, [](int i, int j) { return (i + j) % 2 == 0; });
    ASSERT_TRUE(problem);
    LoadControlParameters load;
    double step = -1.0, phi_prev = M_PI / 4;
    for (double P : {1e-3, 0.01, 0.05}) {
      LevelReport rep;
      ASSERT_PETSC(AdvanceToPressure(*problem, load, P, &step, &rep));
      const StateSummary s = problem->Summary();
      EXPECT_GT(s.packing_fraction, phi_prev) << "phi rises with P";
      EXPECT_GT(s.min_cell_area_ratio, 0.0);
      phi_prev = s.packing_fraction;
      CheckSignoriniCoulomb(*problem, P, friction > 0 ? "checkerboard, friction" : "checkerboard");
    }
  }
}

TEST(Mixture, AllDeformableLatticeUsesNodeSegmentContacts) {
  auto problem = Lattice(2, 0.0, [](int, int) { return true; });
  ASSERT_TRUE(problem);
  LoadControlParameters load;
  double step = -1.0;
  LevelReport rep;
  ASSERT_PETSC(AdvanceToPressure(*problem, load, 0.02, &step, &rep));
  int node_segment = 0;
  for (const ContactForce &f : problem->ContactForces()) node_segment += f.type == ContactType::NodeSegment && f.normal_multiplier > 0;
  EXPECT_GT(node_segment, 0);
  CheckSignoriniCoulomb(*problem, 0.02, "deformable lattice");
}

// Jacobian of a converged, then perturbed, frictional lattice vs central
// differences; with rho > 0 the pseudo-transient anchor's terms (on bodies,
// walls and contact forces: SetAnchor) are in the residual and must be in the
// Jacobian.
// The lattice converged at P/E 0.02, a new load step opened there (the slip
// measured from the converged state) with the anchor weight rho, and in z
// that state with every unknown (multipliers included) perturbed by up to
// `amplitude` at random.
void PerturbedConvergedState(CompactionProblem &problem, double rho, double amplitude, unsigned seed, Vec *z) {
  LoadControlParameters load;
  double step = -1.0;
  LevelReport rep;
  ASSERT_PETSC(AdvanceToPressure(problem, load, 0.02, &step, &rep));
  problem.MarkStepStart();
  problem.SetAnchor(rho, true);
  ASSERT_PETSC(problem.CreateGlobalVector(z));
  ASSERT_PETSC(problem.PackState(*z));
  PetscInt n;
  ASSERT_PETSC(VecGetLocalSize(*z, &n));
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  PetscScalar *za;
  ASSERT_PETSC(VecGetArray(*z, &za));
  for (PetscInt i = 0; i < n; ++i) za[i] += amplitude * U(rng);
  ASSERT_PETSC(VecRestoreArray(*z, &za));
}

void CheckJacobian(std::unique_ptr<CompactionProblem> problem, const char *label, double rho = 0.0) {
  ASSERT_TRUE(problem);
  Vec z = nullptr, F, Fp, Fm;
  PerturbedConvergedState(*problem, rho, 1e-6, 7, &z);
  ASSERT_TRUE(z);
  PetscInt n;
  ASSERT_PETSC(VecGetSize(z, &n));
  ASSERT_PETSC(VecDuplicate(z, &F));
  ASSERT_PETSC(VecDuplicate(z, &Fp));
  ASSERT_PETSC(VecDuplicate(z, &Fm));
  ASSERT_PETSC(problem->EvaluateResidual(z, F));
  const std::vector<char> branches = problem->ActiveSet();
  Mat J;
  ASSERT_PETSC(problem->EvaluateJacobian(z, &J));
  const double h = 1e-9;
  double worst = 0.0, scale = 0.0;
  int skipped = 0;
  for (PetscInt j = 0; j < n; ++j) {
    ASSERT_PETSC(VecSetValue(z, j, h, ADD_VALUES));
    ASSERT_PETSC(VecAssemblyBegin(z));
    ASSERT_PETSC(VecAssemblyEnd(z));
    ASSERT_PETSC(problem->EvaluateResidual(z, Fp));
    const bool same_p = problem->ActiveSet() == branches;
    ASSERT_PETSC(VecSetValue(z, j, -2 * h, ADD_VALUES));
    ASSERT_PETSC(VecAssemblyBegin(z));
    ASSERT_PETSC(VecAssemblyEnd(z));
    ASSERT_PETSC(problem->EvaluateResidual(z, Fm));
    const bool same_m = problem->ActiveSet() == branches;
    ASSERT_PETSC(VecSetValue(z, j, h, ADD_VALUES));
    ASSERT_PETSC(VecAssemblyBegin(z));
    ASSERT_PETSC(VecAssemblyEnd(z));
    if (!same_p || !same_m) {  // a contact switched branch inside the difference
      ++skipped;
      continue;
    }
    const PetscScalar *fp, *fm;
    ASSERT_PETSC(VecGetArrayRead(Fp, &fp));
    ASSERT_PETSC(VecGetArrayRead(Fm, &fm));
    for (PetscInt i = 0; i < n; ++i) {
      PetscScalar Jij;
      ASSERT_PETSC(MatGetValues(J, 1, &i, 1, &j, &Jij));
      // The proximal terms are on the Newton matrix only.
      const double fd = (fp[i] - fm[i]) / (2 * h);
      const double prox = (i == j) ? problem->ProximalDiagonal(i) : 0.0;
      worst = std::max(worst, std::abs(Jij - prox - fd));
      scale = std::max(scale, std::abs(fd));
    }
    ASSERT_PETSC(VecRestoreArrayRead(Fp, &fp));
    ASSERT_PETSC(VecRestoreArrayRead(Fm, &fm));
  }
  std::printf("%s: %" PetscInt_FMT " unknowns, worst |J - FD| = %.2e (scale %.2e), %d columns skipped\n",
              label, n, worst, scale, skipped);
  EXPECT_LT(worst, 1e-5 * scale);
  EXPECT_LT(skipped, n / 10);
  MatDestroy(&J);
  VecDestroy(&z);
  VecDestroy(&F);
  VecDestroy(&Fp);
  VecDestroy(&Fm);
}

// A checkerboard has every pair type but deformable-deformable.
TEST(Mixture, FrictionalJacobianMatchesFiniteDifferences) {
  CheckJacobian(Lattice(2, 0.4, [](int i, int j) { return (i + j) % 2 == 0; }), "frictional checkerboard");
}

TEST(Mixture, AnchoredJacobianMatchesFiniteDifferences) {
  CheckJacobian(Lattice(2, 0.4, [](int i, int j) { return (i + j) % 2 == 0; }), "anchored frictional checkerboard", 1.0);
}

// The anchor's share of the Newton matrix on one deformable disk of a
// converged checkerboard, its rigid-mode unknowns s eliminated (Schur
// complement): a rigid translation of the disk costs about rho, a rigid
// rotation about rho r^2 (a rigid disk's), a deformation rho per node and
// unit nodal motion; the anchor's part is J(rho) - J(0) on the node rows
// and J(rho) on the rows of s.
TEST(Mixture, AnchorHoldsRigidModesOfADeformableDiskAsARigidDisks) {
  PetscMPIInt size;
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  if (size > 1) GTEST_SKIP() << "natural numbering read from a 1-rank layout";
  auto problem = Lattice(2, 0.4, [](int i, int j) { return (i + j) % 2 == 0; });
  ASSERT_TRUE(problem);
  const double rho = 0.7, r = 0.5;
  Vec z = nullptr;
  PerturbedConvergedState(*problem, rho, 0.0, 3, &z);
  ASSERT_TRUE(z);
  Mat Ja, J0;
  ASSERT_PETSC(problem->EvaluateJacobian(z, &Ja));
  problem->SetAnchor(0.0);
  ASSERT_PETSC(problem->EvaluateJacobian(z, &J0));
  PetscInt n;
  ASSERT_PETSC(VecGetSize(z, &n));
  // The node unknowns of the first deformable particle and its s.
  std::vector<PetscInt> nodes, s;
  std::string particle;
  for (PetscInt i = 0; i < n; ++i) {
    const std::string what = problem->DescribeUnknown(i);
    const size_t at = what.find(" node ");
    if (particle.empty() && what.rfind("deformable particle ", 0) == 0 && at != std::string::npos) particle = what.substr(0, at);
    if (!particle.empty() && what.rfind(particle + " node ", 0) == 0) nodes.push_back(i);
    if (!particle.empty() && what == "rigid mode (anchor) of " + particle) s.push_back(i);
  }
  ASSERT_EQ(s.size(), 3u);
  ASSERT_GT(nodes.size(), 20u);
  const int m = static_cast<int>(nodes.size());
  std::vector<double> Auu(m), Aus(3 * m), Ass(9);
  for (int a = 0; a < m; ++a) {
    PetscScalar va, v0;
    ASSERT_PETSC(MatGetValues(Ja, 1, &nodes[a], 1, &nodes[a], &va));
    ASSERT_PETSC(MatGetValues(J0, 1, &nodes[a], 1, &nodes[a], &v0));
    Auu[a] = va - v0;
    EXPECT_NEAR(Auu[a], rho, 1e-12 * rho);
    ASSERT_PETSC(MatGetValues(Ja, 1, &nodes[a], 3, s.data(), &Aus[3 * a]));
  }
  ASSERT_PETSC(MatGetValues(Ja, 3, s.data(), 3, s.data(), Ass.data()));
  // The reference position of each node relative to the centre, from the
  // rotation column: A_{u theta} = -rho X^perp, X^perp = (-X_y, X_x).
  std::vector<double> X(m);
  for (int a = 0; a < m; a += 2) X[a] = Aus[3 * (a + 1) + 2] / rho, X[a + 1] = -Aus[3 * a + 2] / rho;
  // Q(v) = v' A_uu v - (A_su v)' A_ss^-1 (A_su v)
  const auto Q = [&](const std::vector<double> &v) {
    double q = 0.0, b[3] = {0, 0, 0};
    for (int a = 0; a < m; ++a) {
      q += Auu[a] * v[a] * v[a];
      for (int k = 0; k < 3; ++k) b[k] += Aus[3 * a + k] * v[a];
    }
    // 3x3 solve by Cramer's rule
    const double *A = Ass.data();
    const auto det3 = [](const double *M) {
      return M[0] * (M[4] * M[8] - M[5] * M[7]) - M[1] * (M[3] * M[8] - M[5] * M[6]) + M[2] * (M[3] * M[7] - M[4] * M[6]);
    };
    const double D = det3(A);
    double x[3];
    for (int k = 0; k < 3; ++k) {
      double Mk[9];
      std::copy(A, A + 9, Mk);
      for (int row = 0; row < 3; ++row) Mk[3 * row + k] = b[row];
      x[k] = det3(Mk) / D;
    }
    return q - (b[0] * x[0] + b[1] * x[1] + b[2] * x[2]);
  };
  std::vector<double> translate(m), rotate(m), stretch(m);
  double stretch2 = 0.0;
  for (int a = 0; a < m; a += 2) {
    translate[a] = 1.0, translate[a + 1] = 0.0;
    rotate[a] = -X[a + 1], rotate[a + 1] = X[a];
    stretch[a] = X[a], stretch[a + 1] = X[a + 1];
    stretch2 += X[a] * X[a] + X[a + 1] * X[a + 1];
  }
  const double nodes_per_body = m / 2;
  EXPECT_NEAR(Q(translate), rho * nodes_per_body / (nodes_per_body + 1), 1e-10 * rho);
  EXPECT_NEAR(Q(rotate), rho * r * r, 0.05 * rho * r * r);
  EXPECT_NEAR(Q(stretch), rho * stretch2, 1e-10 * rho * stretch2);
  MatDestroy(&Ja);
  MatDestroy(&J0);
  VecDestroy(&z);
}

// Four deformable disks in contact through the mortar gap (-contact_deformable mortar).
TEST(Mixture, MortarFrictionalJacobianMatchesFiniteDifferences) {
  CheckJacobian(Lattice(2, 0.4, [](int, int) { return true; }, true, 40), "frictional mortar lattice");
}

// ResidualFromHere: the residual at z with the slip measured from z and no
// anchor term, as the first residual of a pseudo-time step anchored at z;
// the problem's slip reference and anchor are left as they were.
TEST(Mixture, ResidualFromHereMeasuresTheSlipFromTheIterate) {
  auto problem = Lattice(2, 0.4, [](int i, int j) { return (i + j) % 2 == 0; });
  ASSERT_TRUE(problem);
  Vec z = nullptr, F0, F1, F2, F3;
  PerturbedConvergedState(*problem, 1.0, 1e-5, 11, &z);
  ASSERT_TRUE(z);
  for (Vec *v : {&F0, &F1, &F2, &F3}) ASSERT_PETSC(VecDuplicate(z, v));
  ASSERT_PETSC(problem->EvaluateResidual(z, F0));  // anchored, slip from the converged state
  ASSERT_PETSC(problem->ResidualFromHere(z, F1));
  ASSERT_PETSC(problem->EvaluateResidual(z, F2));  // the anchor and the slip reference as before
  // The same from a pseudo-time step begun at z: slip from z, no anchor.
  ASSERT_PETSC(problem->AdoptState(z));
  problem->MarkStepStart();
  problem->SetAnchor(0.0);
  ASSERT_PETSC(problem->EvaluateResidual(z, F3));
  Vec d;
  ASSERT_PETSC(VecDuplicate(z, &d));
  auto max_difference = [d](Vec a, Vec b) {  // max |a - b| over all ranks
    PetscReal m = 0.0;
    VecWAXPY(d, -1.0, b, a);
    VecNorm(d, NORM_INFINITY, &m);
    return static_cast<double>(m);
  };
  PetscReal norm0;
  ASSERT_PETSC(VecNorm(F0, NORM_INFINITY, &norm0));
  const double changed = max_difference(F0, F1), restored = max_difference(F0, F2), same = max_difference(F1, F3);
  std::printf("|F0| %.3e, |F0 - F_here| %.3e, after it %.3e, against a step begun at z %.3e\n", norm0, changed, restored, same);
  EXPECT_GT(changed, 1e-3 * norm0);  // the anchor term and the slips since the converged state are gone
  EXPECT_EQ(restored, 0.0);
  EXPECT_EQ(same, 0.0);
  for (Vec *v : {&z, &F0, &F1, &F2, &F3, &d}) VecDestroy(v);
}

// ResidualFromHere's Coulomb rows are the static conditions exactly: a
// sticking contact's tangential force put inside its cone by half the slip
// tie (kSlipTie c_t <d>) takes the slip row in a pseudo-time step's residual
// (a row of half the tie) and the stick row, exact at zero slip, in
// ResidualFromHere's; every other row is the same in both to round-off.
TEST(Mixture, ResidualFromHereAcceptsAForceInsideTheConeWithinTheSlipTie) {
  const double mu = 0.5;
  auto problem = Lattice(2, mu, [](int i, int j) { return (i + j) % 2 == 0; });
  ASSERT_TRUE(problem);
  LoadControlParameters load;
  double step = -1.0;
  LevelReport rep;
  ASSERT_PETSC(AdvanceToPressure(*problem, load, 0.02, &step, &rep));
  problem->MarkStepStart();
  problem->SetAnchor(0.0);
  const std::vector<ContactForce> forces = problem->ContactForces();
  const double c_n = problem->Parameters().ncp_scale * problem->Parameters().young;
  const double tie = CompactionProblem::kSlipTie * c_n * problem->MeanDiameter();
  // The most loaded contact with a tangential multiplier.
  int pick = -1;
  for (size_t c = 0; c < forces.size(); ++c)
    if (problem->TangentialUnknown(c) >= 0 && (pick < 0 || forces[c].normal_multiplier > forces[pick].normal_multiplier))
      pick = static_cast<int>(c);
  ASSERT_GE(pick, 0);
  const ContactForce &f = forces[pick];
  const double bound = mu * (f.normal_multiplier - c_n * f.gap);
  ASSERT_GT(bound, 100.0 * tie);
  const double sigma = f.tangential_multiplier < 0.0 ? -1.0 : 1.0, inside = sigma * (bound - 0.5 * tie);
  Vec z, Fstep, Fhere, d;
  ASSERT_PETSC(problem->CreateGlobalVector(&z));
  ASSERT_PETSC(problem->PackState(z));
  for (Vec *v : {&Fstep, &Fhere, &d}) ASSERT_PETSC(VecDuplicate(z, v));
  PetscInt lo, hi, row = -1;
  ASSERT_PETSC(VecGetOwnershipRange(z, &lo, &hi));
  for (PetscInt i = lo; i < hi; ++i)
    if (problem->NaturalIndex(i) == problem->TangentialUnknown(pick)) row = i;
  if (row >= 0) ASSERT_PETSC(VecSetValue(z, row, inside, INSERT_VALUES));
  ASSERT_PETSC(VecAssemblyBegin(z));
  ASSERT_PETSC(VecAssemblyEnd(z));
  ASSERT_PETSC(problem->EvaluateResidual(z, Fstep));
  ASSERT_PETSC(problem->ResidualFromHere(z, Fhere));
  double step_row = 0.0, here_row = 0.0;
  if (row >= 0) {
    PetscScalar a, b;
    ASSERT_PETSC(VecGetValues(Fstep, 1, &row, &a));
    ASSERT_PETSC(VecGetValues(Fhere, 1, &row, &b));
    step_row = a, here_row = b;
    ASSERT_PETSC(VecSetValue(Fstep, row, 0.0, INSERT_VALUES));
    ASSERT_PETSC(VecSetValue(Fhere, row, 0.0, INSERT_VALUES));
  }
  for (Vec v : {Fstep, Fhere}) {
    ASSERT_PETSC(VecAssemblyBegin(v));
    ASSERT_PETSC(VecAssemblyEnd(v));
  }
  double rows[2] = {step_row, here_row};
  MPI_Allreduce(MPI_IN_PLACE, rows, 2, MPI_DOUBLE, MPI_SUM, PETSC_COMM_WORLD);
  PetscReal rest;
  ASSERT_PETSC(VecWAXPY(d, -1.0, Fhere, Fstep));
  ASSERT_PETSC(VecNorm(d, NORM_INFINITY, &rest));
  std::printf("contact %d: bound %.3e, tie %.3e; its row %.3e in a step, %.3e from here; other rows differ by %.3e\n", pick,
              bound, tie, rows[0], rows[1], (double)rest);
  EXPECT_NEAR(std::abs(rows[0]), 0.5 * tie, 1e-3 * tie);  // the slip row: the force's distance to the cone
  EXPECT_LE(std::abs(rows[1]), 1e-6 * tie);               // the stick row at zero slip (round-off on several ranks)
  // Contacts of the converged state that slide have their force on the cone
  // to round-off: their rows are round-off in both, the slip row's or 0.
  EXPECT_LE(rest, 1e-6 * tie);
  for (Vec *v : {&z, &Fstep, &Fhere, &d}) VecDestroy(v);
}

// The dual proximal term of anchored's end game (SetDualRegularization): it
// is the multiplier diagonal of the Newton matrix and nothing else, it cannot
// exceed prox_eta, and it lasts until the load step ends.
TEST(Mixture, DualRegularizationIsTheMultiplierDiagonalUntilTheLoadStepEnds) {
  const double eta = 1e-4;  // large enough to be seen against the matrix entries
  auto problem = Lattice(2, 0.4, [](int i, int j) { return (i + j) % 2 == 0; }, false, 92, eta);
  ASSERT_TRUE(problem);
  LoadControlParameters load;
  double step = -1.0;
  LevelReport rep;
  ASSERT_PETSC(AdvanceToPressure(*problem, load, 0.02, &step, &rep));
  Vec z;
  ASSERT_PETSC(problem->CreateGlobalVector(&z));
  ASSERT_PETSC(problem->PackState(z));
  PetscInt n;
  ASSERT_PETSC(VecGetSize(z, &n));
  const double small = 1e-6;
  Mat Js, Jd;
  problem->SetDualRegularization(small);
  ASSERT_PETSC(problem->EvaluateJacobian(z, &Js));
  problem->SetDualRegularization(1.0);  // above prox_eta: prox_eta
  EXPECT_EQ(problem->DualRegularization(), eta);
  ASSERT_PETSC(problem->EvaluateJacobian(z, &Jd));
  int multipliers = 0;
  for (PetscInt i = 0; i < n; ++i) {
    PetscScalar a, b;
    ASSERT_PETSC(MatGetValues(Js, 1, &i, 1, &i, &a));
    ASSERT_PETSC(MatGetValues(Jd, 1, &i, 1, &i, &b));
    if (problem->ProximalDiagonal(i) < 0.0) {  // a multiplier row: -delta on its diagonal
      ++multipliers;
      EXPECT_EQ(problem->ProximalDiagonal(i), -eta);
      EXPECT_NEAR(a - b, eta - small, 1e-14) << "row " << i;
    } else {
      EXPECT_EQ(a, b) << "row " << i;
    }
  }
  EXPECT_GT(multipliers, 0);
  // Nothing off the diagonal changes.
  ASSERT_PETSC(MatAXPY(Jd, -1.0, Js, DIFFERENT_NONZERO_PATTERN));
  PetscReal frobenius;
  ASSERT_PETSC(MatNorm(Jd, NORM_FROBENIUS, &frobenius));
  EXPECT_NEAR(frobenius, std::sqrt(double(multipliers)) * (eta - small), 1e-12);
  // The end of a load step (converged or undone) restores prox_eta.
  problem->SetDualRegularization(small);
  ASSERT_PETSC(problem->BeginLoadStep(0.03));
  SolveReport undone;
  ASSERT_PETSC(problem->EndLoadStep(false, &undone));
  EXPECT_EQ(problem->DualRegularization(), eta);
  MatDestroy(&Js);
  MatDestroy(&Jd);
  VecDestroy(&z);
}

TEST(CoulombLaw, StickSlipAndOpenBranches) {
  const double mu = 0.3, c = 2.0;
  // Closed contact (lambda_n - c g = 1 > 0), trial force inside the cone: stick, C = c s.
  TangentialNcp stick = coulomb_ncp(0.1, 1.0, 0.0, 0.01, mu, c, c);
  EXPECT_EQ(stick.state, kClosed);
  EXPECT_DOUBLE_EQ(stick.value, c * 0.01);
  EXPECT_DOUBLE_EQ(stick.d_slip, c);
  // Trial force beyond mu lambda_n: slip with lambda_t = -mu lambda_n sign(s) at the root.
  TangentialNcp slip = coulomb_ncp(-0.3, 1.0, 0.0, 0.5, mu, c, c);
  EXPECT_EQ(slip.state, kSliding);
  EXPECT_NEAR(slip.value, 0.0, 1e-15);  // lambda_t = -mu lambda_n solves it
  EXPECT_DOUBLE_EQ(slip.d_lambda_n, mu);
  // Below mu lambda_n the same slip would be a stick residual, above it slip.
  EXPECT_EQ(coulomb_ncp(0.29, 1.0, 0.0, 0.0, mu, c, c).state, kClosed);
  EXPECT_EQ(coulomb_ncp(0.31, 1.0, 0.0, 0.0, mu, c, c).state, kSliding);
  // Open contact: lambda_t = 0.
  TangentialNcp open = coulomb_ncp(0.2, 0.0, 0.1, 0.3, mu, c, c);
  EXPECT_EQ(open.state, kOpen);
  EXPECT_DOUBLE_EQ(open.value, 0.2);
  // Friction switched off (mu = 0) on a closed contact at the start of a step
  // (no slip, no tangential force): lambda_t = 0, the slip stays free. (A
  // stick row c s = 0 here locked the tangential motion of every contact.)
  TangentialNcp off = coulomb_ncp(0.0, 1.0, 0.0, 0.0, 0.0, c, c);
  EXPECT_EQ(off.state, kSliding);
  EXPECT_DOUBLE_EQ(off.value, 0.0);
  EXPECT_DOUBLE_EQ(off.d_slip, 0.0);
  EXPECT_DOUBLE_EQ(off.d_lambda_t, 1.0);
}

// A contact that slid up to the start of an increment sits on its cone with
// no slip yet (|lambda_t| = mu lambda_n to the last solve's tolerance): with
// the tie it takes the slip row, whose residual there is within the tie;
// without it the stick row. Inside the cone by more than the tie it sticks.
TEST(CoulombLaw, ForceOnTheConeWithinTheTieTakesTheSlipRow) {
  const double mu = 0.2, c = 1.0, tie = 1e-8;
  for (double lt : {0.2 - 1e-10, 0.2, -0.2 + 3e-9}) {
    const TangentialNcp with_tie = coulomb_ncp(lt, 1.0, 0.0, 0.0, mu, c, c, tie);
    EXPECT_EQ(with_tie.state, kSliding) << "lambda_t " << lt;
    EXPECT_LE(std::abs(with_tie.value), tie) << "lambda_t " << lt;
    EXPECT_DOUBLE_EQ(with_tie.d_lambda_n, lt > 0.0 ? -mu : mu);
  }
  EXPECT_EQ(coulomb_ncp(0.2 - 1e-10, 1.0, 0.0, 0.0, mu, c, c).state, kClosed) << "without the tie: stick";
  EXPECT_EQ(coulomb_ncp(0.2 - 2e-8, 1.0, 0.0, 0.0, mu, c, c, tie).state, kClosed) << "inside the cone beyond the tie";
  // A slip that reverses the trial force's sign still sticks inside the cone.
  EXPECT_EQ(coulomb_ncp(0.2 - 1e-10, 1.0, 0.0, 0.1, mu, c, c, tie).state, kClosed);
}

// The min NCP row of a touching contact without force: with the tie band
// it is the closed row whatever the sign of the gap's round-off; without it
// the sign decides (the rank dependence the band removes); a gap beyond the
// band, or a contact pulling apart, is open.
TEST(CoulombLaw, TouchingContactTakesTheClosedRowWhateverItsRoundOff) {
  const double c = 1e-2, tie = 1e-12 * c;  // c_n, and the band of a gap of 1e-12 <d> (<d> = 1)
  for (double g : {-1e-16, 0.0, 1e-16, 9e-13}) {
    const NormalNcp with_band = normal_ncp(NcpFunction::Min, 0.0, g, c, tie);
    EXPECT_TRUE(with_band.active) << "gap " << g;
    EXPECT_EQ(with_band.d_gap, c) << "gap " << g;
    EXPECT_EQ(with_band.d_lambda, 0.0) << "gap " << g;
  }
  EXPECT_TRUE(normal_ncp(NcpFunction::Min, 0.0, -1e-16, c).active);
  EXPECT_FALSE(normal_ncp(NcpFunction::Min, 0.0, 1e-16, c).active) << "without the band the round-off decides";
  EXPECT_FALSE(normal_ncp(NcpFunction::Min, 0.0, 2e-12, c, tie).active) << "open beyond the band";
  EXPECT_FALSE(normal_ncp(NcpFunction::Min, -1e-13, 0.0, c, tie).active) << "a tensile multiplier beyond the band opens";
}

// Margins of the state switches and the degenerate-flip measure of the
// Newton stopping rule (ConvergenceTest): each change of state is measured by
// the quantity that decides it, at the new iterate.
TEST(CoulombLaw, SwitchMarginsOfChangedStates) {
  const double mu = 0.2, c = 2.0;
  // Normal switch at lambda_n = c g: |1e-10 - 2 * 1e-11| = 8e-11.
  EXPECT_NEAR(normal_ncp(NcpFunction::Min, 1e-10, 1e-11, c).switch_margin, 8e-11, 1e-24);
  EXPECT_NEAR(normal_ncp(NcpFunction::FischerBurmeister, 0.5, 0.0, c).switch_margin, 0.5, 1e-15);
  // Stick <-> slip at |lambda_t - c s| = mu (lambda_n - c g): |0.21 - 0.2| at lambda_n = 1.
  EXPECT_NEAR(coulomb_ncp(0.21, 1.0, 0.0, 0.0, mu, c, c).switch_margin, 0.01, 1e-15);
  EXPECT_NEAR(coulomb_ncp(0.1, 1.0, 0.0, 0.01, mu, c, c).switch_margin, 0.12, 1e-15);
  EXPECT_EQ(coulomb_ncp(0.1, -1.0, 0.0, 0.01, mu, c, c).switch_margin, 0.0);  // open: no cone
  // Three contacts; margins {normal, tangential} of contact c at 2c, 2c + 1.
  const std::vector<double> m = {1e-3, 2e-3, 1e-12, 5e-1, 7e-1, 3e-13};
  const std::vector<char> was = {kOpen, kClosed, kClosed};
  EXPECT_EQ(changed_state_margin(was, was, m), 0.0) << "nothing changed";
  EXPECT_EQ(changed_state_margin(was, {kOpen, kSliding, kClosed}, m), 5e-1) << "stick -> slip: tangential";
  EXPECT_EQ(changed_state_margin(was, {kOpen, kClosed, kOpen}, m), 7e-1) << "closed -> open: normal";
  EXPECT_EQ(changed_state_margin(was, {kSliding, kClosed, kClosed}, m), 1e-3) << "open -> sliding: normal";
  EXPECT_EQ(changed_state_margin({kSliding, kClosed, kSliding}, {kOpen, kClosed, kClosed}, m), 1e-3)
      << "the largest of sliding -> open (1e-3) and slip -> stick (3e-13)";
}

// A random 20-disk mixture (the compact driver's scene and protocol):
// Signorini and Coulomb hold exactly at every contact, the unbalanced forces
// meet the level criterion, and the contact stress matches P to that accuracy.
// The rotation gauges of the deformable disks hold while friction is off and
// are released (zero torque) once it acts: friction then loads the disks with
// torques that a gauge would otherwise carry.
// Zero penetration, multiplier signs, complementarity and the Coulomb cone
// in a random 20-disk mixture (kappa 0.5, friction 0.2), two levels, with
// the deformable pairs' contact law `law`.
std::unique_ptr<CompactionProblem> TwentyDiskMixture(DeformableContact law, int *n_def) {
  DiskPacking packing = make_jammed_packing(20, 1, PackingOptions());
  assign_deformable(packing, 0.5, 1);
  ProblemParameters p;
  p.deformable_contact = law;
  p.friction = 0.2;
  p.constrain_rotation = PETSC_TRUE;
  p.ptc_move = 0.02;
  p.level_force_rtol = 1e-4;
  auto problem = std::make_unique<CompactionProblem>(PETSC_COMM_WORLD);
  if (problem->SetParameters(p)) return nullptr;
  *n_def = problem->AddPacking(packing, make_disk_mesh(1.0, 92, 2));
  return problem;
}

void CheckRandomTwentyDiskMixture(DeformableContact law,
                                  LevelStrategy strategy = LevelStrategy::Anchored, bool body_criterion = true,
                                  LevelMerit merit = LevelMerit::Residual) {
  int n_def = 0;
  auto scene = TwentyDiskMixture(law, &n_def);
  ASSERT_TRUE(scene);
  CompactionProblem &problem = *scene;
  const int n_rigid = problem.NumParticles() - n_def;
  ASSERT_GT(n_def, 0);
  ASSERT_GT(n_rigid, 0);
  LoadControlParameters load;
  load.level.strategy = strategy;
  load.level.merit = merit;
  load.level.body_criterion = body_criterion ? PETSC_TRUE : PETSC_FALSE;
  const bool merit_newton = strategy == LevelStrategy::Newton || strategy == LevelStrategy::Hybrid;
  const bool per_body = merit_newton || body_criterion;
  double step = -1.0;
  int level = 0;
  for (double P : {1e-4, 1e-3}) {
    problem.SetFrictionActive(level++ > 0);  // the driver's protocol: settle frictionless first
    LevelReport rep;
    ASSERT_PETSC(AdvanceToPressure(problem, load, P, &step, &rep));
    EXPECT_LE(rep.force_residual, 1e-4 * P * problem.MeanDiameter());
    if (per_body) {
      // A level criterion per body (newton's, and anchored's by default): net force and torque.
      CompactionProblem::Balance b;
      ASSERT_PETSC(problem.StateBalance(&b));
      const double d = problem.MeanDiameter();
      EXPECT_LE(b.body_force, 1e-4 * P * d);
      EXPECT_LE(b.body_torque, 1e-4 * P * d * d);
      EXPECT_NEAR(ComputeObservables(problem).mean_stress, P, 1e-4 * P) << "virial identity per body";
    }
    // Both level criteria hold every contact row to ContactRowTolerance
    // (1e-4 tol P <d>, at least 1e-11 E <d>): gaps of closed contacts to
    // that over c_n (E = 1).
    const double gap_tol = ContactRowTolerance(problem, P) / problem.Parameters().ncp_scale;
    int frictional = 0, sliding = 0;
    for (const ContactForce &f : problem.ContactForces()) {
      EXPECT_GE(f.gap, -1e-9 * problem.MeanDiameter() - gap_tol) << "penetration";
      EXPECT_GE(f.normal_multiplier, -1e-10 * P - gap_tol) << "tensile contact force";
      EXPECT_LE(std::abs(f.normal_multiplier * f.gap), 1e-10 * P + gap_tol * std::abs(f.normal_multiplier))
          << "complementarity";
      // The contact rows hold to the SNES tolerance, 1e-11 E <d> (E = 1): a
      // sliding contact's lambda_t = mu (lambda_n - c_n g) with |c_n g| up to that.
      if (level > 1)
        EXPECT_LE(std::abs(f.tangential_multiplier), 0.2 * f.normal_multiplier + 1e-10 * P + 2e-11 * problem.MeanDiameter())
            << "Coulomb cone, excess " << std::abs(f.tangential_multiplier) - 0.2 * f.normal_multiplier;
      frictional += f.tangential_multiplier != 0.0;
      sliding += f.state == kSliding;
    }
    if (level > 1) EXPECT_GT(frictional, 0) << "friction carries force at the second level";
    const PackingObservables o = ComputeObservables(problem);
    // Unbalanced forces up to 1e-4 P <d> per unknown: the virial mean stress within 1e-3 P.
    EXPECT_NEAR(o.mean_stress, P, 1e-3 * P);
    EXPECT_GT(o.coordination, 2.0);
    const double d = problem.MeanDiameter();
    std::printf("  P/E = %g: largest gauge torque %.3e P <d>^2\n", P, problem.Summary().max_gauge_torque / (P * d * d));
    if (level > 1) EXPECT_LE(problem.Summary().max_gauge_torque, 1e-12 * P * d * d) << "gauge not released under friction";
  }
}

TEST(Mixture, RandomTwentyDiskMixtureWithFriction) {
  CheckRandomTwentyDiskMixture(DeformableContact::NodeToSegment);
}

// -level_solver auto is newton with the energy merit on the frictionless
// settling level, whatever -level_merit says, and hybrid with -level_merit
// (here residual, with an attempt of 30) once friction acts: the same Newton
// iterations, factorizations and state, to the last bit, as those two
// strategies chosen by hand.
// BodyBalance names the particle with the largest net force (the progress
// lines of a long sub-step print it): a residual with a uniform force on the
// nodes of one deformable disk, then a larger one on a rigid disk.
TEST(Mixture, BodyBalanceNamesTheParticleWithTheLargestNetForce) {
  int n_def = 0;
  auto scene = TwentyDiskMixture(DeformableContact::NodeToSegment, &n_def);
  ASSERT_TRUE(scene);
  CompactionProblem &problem = *scene;
  Vec z, F;
  Mat J;
  KSP ksp;
  ASSERT_PETSC(problem.Layout(&z, &F, &J, &ksp));
  PetscInt lo, hi;
  ASSERT_PETSC(VecGetOwnershipRange(F, &lo, &hi));
  const auto set = [&](PetscInt natural, double value) {
    const PetscInt i = problem.PetscIndex(natural);
    if (i >= lo && i < hi) ASSERT_PETSC(VecSetValue(F, i, value, INSERT_VALUES));
  };
  ASSERT_GE(problem.Bodies().size(), 2u);
  ASSERT_GE(problem.RigidBodies().size(), 1u);
  const DeformableBody &body = problem.Bodies()[1];
  const int nn = body.mesh.num_nodes();
  ASSERT_PETSC(VecZeroEntries(F));
  for (int a = 0; a < nn; ++a) set(body.dof_offset + 2 * a + 1, 1e-6);
  ASSERT_PETSC(VecAssemblyBegin(F));
  ASSERT_PETSC(VecAssemblyEnd(F));
  CompactionProblem::Balance b;
  ASSERT_PETSC(problem.BodyBalance(F, &b));
  EXPECT_NEAR(b.body_force, nn * 1e-6, 1e-12);
  EXPECT_EQ(b.body_force_particle, body.particle);
  EXPECT_TRUE(b.body_force_deformable);
  EXPECT_NEAR(b.node_force, 1e-6, 1e-15);

  const RigidBody &rigid = problem.RigidBodies()[0];
  set(rigid.dof_offset, 2.0 * nn * 1e-6);
  ASSERT_PETSC(VecAssemblyBegin(F));
  ASSERT_PETSC(VecAssemblyEnd(F));
  ASSERT_PETSC(problem.BodyBalance(F, &b));
  EXPECT_NEAR(b.body_force, 2.0 * nn * 1e-6, 1e-12);
  EXPECT_EQ(b.body_force_particle, rigid.particle);
  EXPECT_FALSE(b.body_force_deformable);
}

TEST(Mixture, AutoLevelSolverChoosesByFriction) {
  struct Run {
    PetscInt its[2] = {0, 0};
    PetscInt factorizations[2] = {0, 0};
    double walls[4] = {0.0, 0.0, 0.0, 0.0};
  };
  const auto run = [](bool by_hand, Run *out) {
    int n_def = 0;
    auto problem = TwentyDiskMixture(DeformableContact::Mortar, &n_def);
    ASSERT_TRUE(problem);
    LoadControlParameters load;
    EXPECT_EQ(load.level.strategy, LevelStrategy::Auto) << "the default level solver";
    load.level.merit = LevelMerit::Residual;
    load.level.attempt_its = 30;
    double step = -1.0;
    int level = 0;
    for (double P : {1e-4, 1e-3}) {
      problem->SetFrictionActive(level > 0);
      if (by_hand) {
        load.level.strategy = level > 0 ? LevelStrategy::Hybrid : LevelStrategy::Newton;
        load.level.merit = level > 0 ? LevelMerit::Residual : LevelMerit::Energy;
      }
      LevelReport rep;
      ASSERT_PETSC(AdvanceToPressure(*problem, load, P, &step, &rep));
      out->its[level] = rep.newton_its, out->factorizations[level] = rep.factorizations;
      ++level;
    }
    std::copy(problem->Walls(), problem->Walls() + 4, out->walls);
  };
  Run automatic, by_hand;
  run(false, &automatic);
  run(true, &by_hand);
  for (int level = 0; level < 2; ++level) {
    std::printf("  level %d: auto %" PetscInt_FMT " Newton its, by hand %" PetscInt_FMT "\n", level, automatic.its[level],
                by_hand.its[level]);
    EXPECT_EQ(automatic.its[level], by_hand.its[level]) << "level " << level;
    EXPECT_EQ(automatic.factorizations[level], by_hand.factorizations[level]) << "level " << level;
  }
  for (int k = 0; k < 4; ++k) EXPECT_EQ(automatic.walls[k], by_hand.walls[k]) << "wall " << k;
}

// The same with compact's default law: mortar gaps (ContactForce::gap is
// then the slave node's weighted gap).
TEST(Mixture, RandomTwentyDiskMixtureWithFrictionMortar) {
  CheckRandomTwentyDiskMixture(DeformableContact::Mortar);
}

// The same with the newton level solver (one Newton step per pseudo-time
// step), whose level criterion is per body.
TEST(Mixture, RandomTwentyDiskMixtureWithFrictionNewton) {
  CheckRandomTwentyDiskMixture(DeformableContact::Mortar, LevelStrategy::Newton);
}

// The same with the hybrid level solver (a newton attempt, then anchored).
TEST(Mixture, RandomTwentyDiskMixtureWithFrictionHybrid) {
  CheckRandomTwentyDiskMixture(DeformableContact::Mortar, LevelStrategy::Hybrid);
}

// The same with hybrid's attempt accepting steps by the energy merit too.
TEST(Mixture, RandomTwentyDiskMixtureWithFrictionHybridEnergyMerit) {
  CheckRandomTwentyDiskMixture(DeformableContact::Mortar, LevelStrategy::Hybrid, true, LevelMerit::Energy);
}

// The same with anchored's level criterion per node only (-level_body_criterion false).
TEST(Mixture, RandomTwentyDiskMixtureWithFrictionPerNodeCriterion) {
  CheckRandomTwentyDiskMixture(DeformableContact::Mortar, LevelStrategy::Anchored, false);
}

// A level that crosses a rearrangement: a rigid disk (radius 0.19) sits
// off-centre in the pore of a 2 x 2 square arrangement of deformable disks
// of diameter 1 (pore radius (sqrt 2 - 1) / 2 = 0.207), frictionless, with
// compact's mortar contact. At P/E = 1e-3 it is a rattler: no force, its
// unknowns a singular mode of the tangent. On the way to 0.05 (one jump) the
// nearly incompressible disks flatten against each other and bulge into the
// pore, which closes (between P/E 0.01 and 0.02), and the rattler is pushed
// to where the disks around it balance it. Asserted: the equilibrium it
// reaches (Signorini, the virial identity, the rattler's net force, a load
// carried by several contacts), the same with the three level solvers and
// with newton's energy merit; not how many iterations it takes.
TEST(Mixture, RattlerIsCaughtWhenThePoreCloses) {
  double carried_by[4] = {0.0, 0.0, 0.0, 0.0};
  const char *const labels[] = {"newton", "anchored", "hybrid", "newton, energy merit"};  // LevelStrategy order, then newton's energy merit
  for (int variant : {1, 0, 2, 3}) {
    const LevelStrategy strategy = variant == 3 ? LevelStrategy::Newton : static_cast<LevelStrategy>(variant);
    ProblemParameters p;
    p.deformable_contact = DeformableContact::Mortar;
    p.constrain_rotation = PETSC_TRUE;
    p.ptc_move = 0.02;
    CompactionProblem problem(PETSC_COMM_WORLD);
    ASSERT_PETSC(problem.SetParameters(p));
    const DiskMesh mesh = make_disk_mesh(0.5, 40, 2);
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 2; ++j) problem.AddDeformableBody(mesh, i + 0.5, j + 0.5);
    problem.AddRigidBody(1.01, 1.004, 0.19);
    const int rattler = problem.NumParticles() - 1;  // its particle index
    const double w[4] = {0.0, 2.0, 0.0, 2.0};
    problem.SetWalls(w);
    LoadControlParameters load;
    load.level.strategy = strategy;
    if (variant == 3) load.level.merit = LevelMerit::Energy;
    double step = -1.0;
    const char *label = labels[variant];
    for (double P : {1e-3, 0.05}) {
      LevelReport rep;
      ASSERT_PETSC(AdvanceToPressure(problem, load, P, &step, &rep));
      double net[2] = {0.0, 0.0}, carried = 0.0;
      int touching = 0;  // contacts of the rattler carrying more than round-off
      for (const ContactForce &f : problem.ContactForces()) {
        const int sign = f.slave_particle == rattler ? 1 : f.master_particle == rattler ? -1 : 0;
        if (sign == 0) continue;
        net[0] += sign * f.force[0], net[1] += sign * f.force[1];
        const double magnitude = std::hypot(f.force[0], f.force[1]);
        carried += magnitude;
        touching += magnitude > 1e-9 * P;
      }
      std::printf("  %s, P/E = %g: %" PetscInt_FMT " Newton its, %d sub-steps; the rattler carries %.4e P d on %d contacts, net %.1e P d\n",
                  label, P, rep.newton_its, rep.substeps, carried / P, touching, std::hypot(net[0], net[1]) / P);
      if (P < 0.01) {
        EXPECT_LE(carried, 1e-9 * P) << label << ": the pore is still open at P/E = " << P;
      } else {
        // Caught: held by several contacts with forces of the order of the
        // packing's contact forces (P d), and balanced.
        EXPECT_GE(touching, 2) << label;
        EXPECT_GT(carried, 0.1 * P) << label;
        EXPECT_LE(std::hypot(net[0], net[1]), 1e-9 * carried) << label << ": net force on the rattler";
        carried_by[variant] = carried;
      }
      CheckSignoriniCoulomb(problem, P, label);
    }
  }
  EXPECT_NEAR(carried_by[0], carried_by[1], 1e-6 * carried_by[1]) << "newton and anchored reach the same equilibrium";
  EXPECT_NEAR(carried_by[2], carried_by[1], 1e-6 * carried_by[1]) << "hybrid and anchored reach the same equilibrium";
  EXPECT_NEAR(carried_by[3], carried_by[1], 1e-6 * carried_by[1]) << "newton's energy merit and anchored reach the same equilibrium";
}

// The symmetric form of the Newton matrix (problem.hpp, SymmetrizeNewtonMatrix):
// a frictionless random 20-disk mixture (mortar, rotation gauges) converged
// at P/E 1e-4, then the first linearization of the load step to 2e-4, which
// has closed and open contacts and gauge rows. J_s is symmetric where J is
// not, and MUMPS LDL^T of J_s with S L b gives the step of MUMPS LU of J
// with b, for a right-hand side with every entry nonzero.
TEST(Mixture, SymmetricFormHasTheSolutionOfTheNewtonMatrix) {
  DiskPacking packing = make_jammed_packing(20, 1, PackingOptions());
  assign_deformable(packing, 0.5, 1);
  ProblemParameters p;
  p.deformable_contact = DeformableContact::Mortar;
  p.friction = 0.0;
  p.constrain_rotation = PETSC_TRUE;
  p.level_force_rtol = 1e-4;
  CompactionProblem problem(PETSC_COMM_WORLD);
  ASSERT_PETSC(problem.SetParameters(p));
  ASSERT_GT(problem.AddPacking(packing, make_disk_mesh(1.0, 92, 2)), 0);
  LoadControlParameters load;
  double step = -1.0;
  LevelReport rep;
  ASSERT_PETSC(AdvanceToPressure(problem, load, 1e-4, &step, &rep));
  ASSERT_PETSC(problem.BeginLoadStep(2e-4));
  Vec z, F, b, d_lu, bs, d_ldlt;
  Mat J, J_lu;
  KSP ksp, ksp_ldlt;
  ASSERT_PETSC(problem.Layout(&z, &F, &J, &ksp));
  ASSERT_PETSC(problem.Residual(z, F));
  int closed = 0, open = 0;
  for (char a : problem.ActiveSet()) closed += a == kClosed, open += a == kOpen;
  std::printf("  %d closed and %d open contacts\n", closed, open);
  ASSERT_GT(closed, 0);
  ASSERT_GT(open, 0);
  ASSERT_PETSC(problem.NewtonMatrix(z, J));
  ASSERT_PETSC(MatDuplicate(J, MAT_COPY_VALUES, &J_lu));
  bool done = false;
  ASSERT_PETSC(problem.SymmetrizeNewtonMatrix(J, &done));
  ASSERT_TRUE(done);
  PetscReal jmax;
  ASSERT_PETSC(MatNorm(J_lu, NORM_INFINITY, &jmax));
  // Largest |A - A^T| (MatIsSymmetric also compares the nonzero patterns,
  // which differ where an entry is structurally present on one side only).
  const auto asymmetry = [](Mat A) {
    Mat T, D;
    PetscReal norm = -1.0;
    if (MatTranspose(A, MAT_INITIAL_MATRIX, &T) || MatDuplicate(A, MAT_COPY_VALUES, &D)) return norm;
    if (!MatAXPY(D, -1.0, T, DIFFERENT_NONZERO_PATTERN)) MatNorm(D, NORM_MAX, &norm);
    MatDestroy(&T), MatDestroy(&D);
    return norm;
  };
  const PetscReal asym_s = asymmetry(J), asym = asymmetry(J_lu);
  std::printf("  largest |J - J^T| %.2e, |J_s - J_s^T| %.2e, of |J|_inf %.2e\n", asym, asym_s, jmax);
  EXPECT_LE(asym_s, 1e-13 * jmax) << "J_s is symmetric";
  EXPECT_GT(asym, 1e-3 * jmax) << "J itself is not (the test sees a difference)";
  // The level solvers shift the body and wall rows (rho D): here rho = 1e-3 E.
  {
    Vec floor, weight;
    ASSERT_PETSC(VecDuplicate(z, &floor));
    ASSERT_PETSC(VecDuplicate(z, &weight));
    ASSERT_PETSC(problem.ShiftDiagonals(floor, weight));
    ASSERT_PETSC(VecScale(weight, 1e-3));
    ASSERT_PETSC(MatDiagonalSet(J, weight, ADD_VALUES));
    ASSERT_PETSC(MatDiagonalSet(J_lu, weight, ADD_VALUES));
    VecDestroy(&floor), VecDestroy(&weight);
  }
  ASSERT_PETSC(VecDuplicate(z, &b));
  ASSERT_PETSC(VecDuplicate(z, &bs));
  ASSERT_PETSC(VecDuplicate(z, &d_lu));
  ASSERT_PETSC(VecDuplicate(z, &d_ldlt));
  {
    PetscInt lo, hi;
    PetscScalar *a;
    ASSERT_PETSC(VecGetOwnershipRange(b, &lo, &hi));
    ASSERT_PETSC(VecGetArray(b, &a));
    for (PetscInt i = lo; i < hi; ++i) a[i - lo] = 1e-4 * std::sin(0.7 * static_cast<double>(i) + 0.3);
    ASSERT_PETSC(VecRestoreArray(b, &a));
  }
  ASSERT_PETSC(KSPSetOperators(ksp, J_lu, J_lu));
  ASSERT_PETSC(KSPSolve(ksp, b, d_lu));
  ASSERT_PETSC(problem.SymmetricKsp(&ksp_ldlt));
  ASSERT_PETSC(KSPSetOperators(ksp_ldlt, J, J));
  ASSERT_PETSC(problem.SymmetricRhs(b, bs));
  ASSERT_PETSC(KSPSolve(ksp_ldlt, bs, d_ldlt));
  PetscReal norm, diff;
  ASSERT_PETSC(VecNorm(d_lu, NORM_INFINITY, &norm));
  ASSERT_PETSC(VecAXPY(d_ldlt, -1.0, d_lu));
  ASSERT_PETSC(VecNorm(d_ldlt, NORM_INFINITY, &diff));
  std::printf("  |d_LDLT - d_LU|_inf = %.2e of %.2e\n", diff, norm);
  EXPECT_LE(diff, 1e-8 * norm);
  ASSERT_PETSC(KSPSetOperators(ksp, J, J));
  for (Vec *v : {&b, &bs, &d_lu, &d_ldlt}) VecDestroy(v);
  MatDestroy(&J_lu);
}

// The overlap limit of a predicted state (BeginLoadStep). Four frictionless
// deformable disks (mortar contact) in a square box, converged at P/E =
// 0.1: the tangent prediction for 0.2 pushes the boundary nodes about to
// join the growing contact patches into the neighbours (an overlap of a few
// 1e-2 <d>). Admitted up to 0.1 <d> (hybrid's newton attempt) it is taken,
// and its box is closer to the converged box at 0.2 than the last state's;
// with the limit of 1e-3 <d> it is halved until the overlap by the contact
// laws' gaps is below it (8.9e-4 <d> here), and taken.
TEST(Mixture, PredictionOverlapLimit) {
  auto problem = Lattice(2, 0.0, [](int, int) { return true; }, true, 40);
  ASSERT_TRUE(problem);
  LoadControlParameters load;
  double step = -1.0;
  LevelReport rep;
  ASSERT_PETSC(AdvanceToPressure(*problem, load, 0.1, &step, &rep));
  const std::vector<double> last(problem->Walls(), problem->Walls() + 4);
  const auto predicted = [&](double limit, double *overlap) {
    SolveReport undone;
    std::vector<double> w;
    if (problem->BeginLoadStep(0.2, LoadPredictor::Tangent, limit)) return w;
    w.assign(problem->Walls(), problem->Walls() + 4);
    *overlap = problem->Summary().max_penetration / problem->MeanDiameter();
    if (problem->EndLoadStep(false, &undone)) w.clear();
    return w;
  };
  double loose_overlap = 0.0, tight_overlap = 0.0;
  const std::vector<double> loose = predicted(0.1, &loose_overlap);
  const std::vector<double> tight = predicted(CompactionProblem::kPredictionOverlap, &tight_overlap);
  ASSERT_EQ(loose.size(), 4u);
  ASSERT_EQ(tight.size(), 4u);
  for (int k = 0; k < 4; ++k) EXPECT_EQ(problem->Walls()[k], last[k]) << "a failed load step restores the walls";
  ASSERT_PETSC(AdvanceToPressure(*problem, load, 0.2, &step, &rep));
  const auto distance = [&](const std::vector<double> &w) {
    double e = 0.0;
    for (int k = 0; k < 4; ++k) e = std::max(e, std::abs(w[k] - problem->Walls()[k]));
    return e;
  };
  std::printf("  predicted overlap %.3e <d> (limit 0.1), %.3e <d> (limit 1e-3); box error %.3e, %.3e, last state %.3e\n",
              loose_overlap, tight_overlap, distance(loose), distance(tight), distance(last));
  EXPECT_GT(loose_overlap, CompactionProblem::kPredictionOverlap) << "the prediction overlaps beyond the tight limit";
  EXPECT_LT(loose_overlap, 0.1);
  // How much closer depends on the tangent's active set at the edges of the
  // contact patches, where nodes touch without force (g = lambda = 0 to
  // round-off), so on the round-off of the contact derivatives: 0.33 to 0.53
  // of the last state's distance measured.
  EXPECT_LT(distance(loose), 0.75 * distance(last)) << "the admitted prediction is closer to the equilibrium";
  EXPECT_LT(tight_overlap, CompactionProblem::kPredictionOverlap);
  // Under the tight limit the prediction is halved until the contact laws'
  // overlap is below it: a shorter step along the same tangent.
  EXPECT_GT(distance(tight), distance(loose)) << "the tight limit halves the prediction";
  EXPECT_LT(distance(tight), distance(last)) << "the halved prediction is still taken";
}

// A 12-disk all-deformable packing (40-triangle disks) with two-pass
// deformable contact and the compact driver's solver settings, solved by
// hybrid (the strategy of compact's frictional levels).
std::unique_ptr<CompactionProblem> TwoPassPacking(double friction) {
  DiskPacking packing = make_jammed_packing(12, 2, PackingOptions());
  assign_deformable(packing, 1.0, 1);
  ProblemParameters p;
  p.friction = friction;
  p.constrain_rotation = PETSC_TRUE;
  p.deformable_contact = DeformableContact::TwoPass;
  p.ptc_move = 0.02;
  p.level_force_rtol = 1e-4;
  p.ncp_scale = 0.01;
  auto problem = std::make_unique<CompactionProblem>(PETSC_COMM_WORLD);
  if (problem->SetParameters(p) || problem->AddPacking(packing, make_disk_mesh(1.0, 40, 2)) != 12) return nullptr;
  return problem;
}

// -contact_deformable two_pass: in a frictionless all-deformable packing at P/E = 0.05 each
// disk's boundary nodes are kept out of its neighbours both ways (one pass
// leaves the master's nodes free to enter the slave; docs/validation.md).
TEST(Mixture, TwoPassKeepsTheNodesOfBothDisksOut) {
  auto owner = TwoPassPacking(0.0);
  ASSERT_TRUE(owner);
  CompactionProblem &problem = *owner;
  LoadControlParameters load;
  double step = -1.0;
  for (double P : {1e-3, 0.05}) {
    LevelReport rep;
    ASSERT_PETSC(AdvanceToPressure(problem, load, P, &step, &rep));
  }
  int forward = 0, backward = 0;  // closed contacts of the higher / lower-numbered disk's nodes
  for (const ContactForce &f : problem.ContactForces()) {
    EXPECT_GE(f.gap, -1e-9 * problem.MeanDiameter()) << "penetration";
    EXPECT_GE(f.normal_multiplier, -1e-12) << "tensile contact force";
    if (f.type != ContactType::NodeSegment || f.normal_multiplier <= 0.0) continue;
    (f.slave_particle > f.master_particle ? forward : backward) += 1;
  }
  EXPECT_GT(forward, 0);
  EXPECT_GT(backward, 0) << "the second pass carries force";
  EXPECT_NEAR(ComputeObservables(problem).mean_stress, 0.05, 1e-3 * 0.05);
}

// Two-pass contact with friction: the two passes of a conforming contact
// share its force in an indeterminate way, so at a converged point weakly
// loaded nodes (lambda_n ~ 1e-10 E<d>) may flip between open, stick and slip
// at every Newton step. Newton must still stop there (ConvergenceTest: flips
// within 1e3 atol of their switch are degenerate) and every level converge,
// with Signorini and Coulomb exact at every contact.
TEST(Mixture, TwoPassWithFrictionConverges) {
  auto owner = TwoPassPacking(0.2);
  ASSERT_TRUE(owner);
  CompactionProblem &problem = *owner;
  LoadControlParameters load;
  // hybrid, as compact's frictional levels; it accepts a level with every
  // contact row below 1e-4 tol P <d> and at least 1e-11 E <d>, which the
  // complementarity check below assumes.
  load.level.strategy = LevelStrategy::Hybrid;
  double step = -1.0;
  int level = 0;
  for (double P : {1e-3, 3e-3}) {
    problem.SetFrictionActive(level++ > 0);
    LevelReport rep;
    ASSERT_PETSC(AdvanceToPressure(problem, load, P, &step, &rep));
    EXPECT_TRUE(rep.converged) << "P/E = " << P;
    EXPECT_NEAR(problem.Pressure(), P, 1e-12 * P) << "level not reached";
    std::printf("  two-pass, friction 0.2, P/E = %g: %" PetscInt_FMT " Newton iterations, %d cuts\n", P, rep.newton_its,
                rep.cuts);
    const double d = problem.MeanDiameter(), E = problem.Parameters().young, c_n = problem.Parameters().ncp_scale * E;
    const double row_tol = ContactRowTolerance(problem, P);  // the level criterion's
    for (const ContactForce &f : problem.ContactForces()) {
      EXPECT_GE(f.gap, -row_tol / c_n) << "penetration";
      // Every contact row within row_tol: the multiplier or the scaled gap
      // c_n g of each contact vanishes to it.
      EXPECT_GE(f.normal_multiplier, -1e-10 * d) << "tensile contact force";
      EXPECT_LE(std::min(std::abs(f.normal_multiplier), c_n * std::abs(f.gap)), row_tol) << "complementarity";
      EXPECT_LE(std::abs(f.tangential_multiplier), 0.2 * f.normal_multiplier + 1e-10 * d) << "Coulomb cone";
    }
    EXPECT_NEAR(ComputeObservables(problem).mean_stress, P, 1e-3 * P);
  }
}

// Deepest point of any deformable disk's boundary inside another deformable
// disk, measured on the element geometry itself (each quadratic boundary
// edge sampled at 16 points): an independent check of the contact
// treatment, which works on nodes and on the smooth contact curves.
double DeepestBoundaryOverlap(const CompactionProblem &problem) {
  const std::vector<DeformableBody> &bodies = problem.Bodies();
  std::vector<std::vector<double>> outline(bodies.size());
  for (size_t b = 0; b < bodies.size(); ++b) {
    const DiskMesh &m = bodies[b].mesh;
    const int nb = static_cast<int>(m.boundary.size()), step = m.order;
    for (int i = 0; i < nb; i += step) {
      double x[3][2];
      for (int k = 0; k <= step; ++k) problem.NodePosition(static_cast<int>(b), m.boundary[(i + k) % nb], x[k]);
      for (int s = 0; s < 16; ++s) {
        const double t = s / 16.0;
        const double N[3] = {(1 - t) * (1 - 2 * t), 4 * t * (1 - t), t * (2 * t - 1)};
        for (int c = 0; c < 2; ++c)
          outline[b].push_back(step == 1 ? (1 - t) * x[0][c] + t * x[1][c] : N[0] * x[0][c] + N[1] * x[1][c] + N[2] * x[2][c]);
      }
    }
  }
  double deepest = 0.0;
  for (size_t a = 0; a < bodies.size(); ++a)
    for (size_t b = 0; b < bodies.size(); ++b) {
      if (a == b) continue;
      const std::vector<double> &poly = outline[b];
      const int n = static_cast<int>(poly.size() / 2);
      for (size_t k = 0; k < outline[a].size() / 2; ++k) {
        const double px = outline[a][2 * k], py = outline[a][2 * k + 1];
        bool inside = false;
        double dist = 1e300;
        for (int i = 0, j = n - 1; i < n; j = i++) {
          const double xi = poly[2 * i], yi = poly[2 * i + 1], xj = poly[2 * j], yj = poly[2 * j + 1];
          if ((yi > py) != (yj > py) && px < (xj - xi) * (py - yi) / (yj - yi) + xi) inside = !inside;
          const double ex = xi - xj, ey = yi - yj, l2 = ex * ex + ey * ey;
          const double t = l2 > 0 ? std::clamp(((px - xj) * ex + (py - yj) * ey) / l2, 0.0, 1.0) : 0.0;
          dist = std::min(dist, std::hypot(px - xj - t * ex, py - yj - t * ey));
        }
        if (inside) deepest = std::max(deepest, dist);
      }
    }
  return deepest;
}

// -contact_deformable mortar: the weighted gap integrates each slave node's gap over
// the slave boundary around it, so a master corner cannot enter the slave
// between its nodes. The same frictionless 12-disk packing taken to
// P/E = 0.1 with one-pass node-to-segment contact and with the mortar gap:
// the boundaries of the disks overlap less with the mortar gap (measured:
// 1.3e-2 and 7.1e-3 <d>; on these coarse 54-triangle disks the cell-average
// condition itself allows ~1e-3 <d> at point contacts, mortar_kinematics.cpp),
// and the level is an equilibrium (contact stress = P, multipliers >= 0).
TEST(Mixture, MortarGapKeepsTheBoundariesApart) {
  double overlap[2] = {0.0, 0.0};
  for (int mortar = 0; mortar < 2; ++mortar) {
    DiskPacking packing = make_jammed_packing(12, 2, PackingOptions());
    assign_deformable(packing, 1.0, 1);
    ProblemParameters p;
    p.constrain_rotation = PETSC_TRUE;
    p.deformable_contact = mortar ? DeformableContact::Mortar : DeformableContact::NodeToSegment;
    p.ptc_move = 0.02;
    p.level_force_rtol = 1e-4;
    p.ncp_scale = 0.01;
    CompactionProblem problem(PETSC_COMM_WORLD);
    ASSERT_PETSC(problem.SetParameters(p));
    ASSERT_EQ(problem.AddPacking(packing, make_disk_mesh(1.0, 40, 2)), 12);
    LoadControlParameters load;
    double step = -1.0;
    PetscInt its = 0;
    for (double P : {1e-3, 0.02, 0.1}) {
      LevelReport rep;
      ASSERT_PETSC(AdvanceToPressure(problem, load, P, &step, &rep));
      ASSERT_TRUE(rep.converged) << "P/E = " << P;
      its += rep.newton_its;
    }
    const double d = problem.MeanDiameter();
    // The level criterion holds every contact row to ContactRowTolerance: a
    // closed gap to that over c_n.
    const double gap_tol = ContactRowTolerance(problem, 0.1) / p.ncp_scale;
    for (const ContactForce &f : problem.ContactForces()) {
      EXPECT_GE(f.normal_multiplier, -1e-10 * d) << "tensile contact force";
      EXPECT_GE(f.gap, -gap_tol) << "the constrained (weighted) gap is negative";
    }
    EXPECT_NEAR(ComputeObservables(problem).mean_stress, 0.1, 1e-3 * 0.1);
    overlap[mortar] = DeepestBoundaryOverlap(problem) / d;
    std::printf("  %s: deepest boundary overlap %.2e <d> at P/E = 0.1, %" PetscInt_FMT " Newton iterations\n",
                mortar ? "mortar" : "node-to-segment", overlap[mortar], its);
  }
  EXPECT_LT(overlap[1], 0.7 * overlap[0]);
}

}  // namespace

int main(int argc, char **argv) {
  ::testing::InitGoogleTest(&argc, argv);
  if (PetscInitialize(&argc, &argv, nullptr, nullptr)) return 1;
  // The compact driver's Newton settings: full steps, damping by the pseudo-transient term.
  PetscOptionsSetValue(nullptr, "-snes_linesearch_type", "basic");
  const int result = RUN_ALL_TESTS();
  PetscFinalize();
  return result;
}

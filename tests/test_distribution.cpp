// Distribution tests (run under mpirun with 1, 2 or 3 ranks, see CMakeLists.txt):
// a 30-disk frictional mixture partitioned by METIS.
//  - ownership: every particle owned by exactly one rank, the same owner
//    table on every rank, every rank owning some particles, and the PETSc
//    numbering a permutation that gives each rank exactly the unknowns of its
//    particles, the gauges of its disks and the multipliers of its contacts;
//  - parallel assembly: the residual and the Jacobian (J v) of the
//    distributed problem equal those of the same problem built on
//    PETSC_COMM_SELF on each rank (a serial reference), at a perturbed state;
//  - contact detection: each rank's narrow phase finds exactly the contacts
//    whose slave it owns, and the gathered list is the serial one;
//  - ghost data current: after a solve, the replicated state (used for
//    geometry) is bitwise the same on every rank and equals the distributed
//    solution.
#include <gtest/gtest.h>
#include <petscsnes.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <random>
#include <vector>

#include "deformix/load_controller.hpp"
#include "deformix/packing.hpp"
#include "deformix/problem.hpp"

using namespace deformix;

#define ASSERT_PETSC(call) ASSERT_EQ((call), 0)

namespace {

// Deformable-deformable contact: one node-to-segment pass, two, or the mortar gap.
enum class Pass { One, Two, Mortar };
const char *Name(Pass pass) { return pass == Pass::One ? "one pass" : pass == Pass::Two ? "two-pass" : "mortar"; }

std::unique_ptr<CompactionProblem> Build(MPI_Comm comm, Pass pass = Pass::One) {
  DiskPacking packing = make_jammed_packing(30, 3, PackingOptions());
  assign_deformable(packing, 0.5, 3);
  ProblemParameters p;
  p.deformable_contact = pass == Pass::Two      ? DeformableContact::TwoPass
                         : pass == Pass::Mortar ? DeformableContact::Mortar
                                                : DeformableContact::NodeToSegment;
  p.friction = 0.3;
  p.constrain_rotation = PETSC_FALSE;
  p.ptc_move = 0.02;
  p.level_force_rtol = 1e-4;
  auto problem = std::make_unique<CompactionProblem>(comm);
  if (problem->SetParameters(p)) return nullptr;
  problem->AddPacking(packing, make_disk_mesh(1.0, 40, 2));
  problem->SetPressure(1e-3);
  if (problem->RefreshCandidates()) return nullptr;
  return problem;
}

// Natural-order copy of a distributed vector.
std::vector<double> Natural(const CompactionProblem &problem, Vec v) {
  Vec all;
  VecScatter to_all;
  VecScatterCreateToAll(v, &to_all, &all);
  VecScatterBegin(to_all, v, all, INSERT_VALUES, SCATTER_FORWARD);
  VecScatterEnd(to_all, v, all, INSERT_VALUES, SCATTER_FORWARD);
  PetscInt n;
  VecGetSize(all, &n);
  const PetscScalar *a;
  VecGetArrayRead(all, &a);
  std::vector<double> out(n);
  for (PetscInt i = 0; i < n; ++i) out[i] = a[problem.PetscIndex(i)];
  VecRestoreArrayRead(all, &a);
  VecScatterDestroy(&to_all);
  VecDestroy(&all);
  return out;
}

// Sets a distributed vector from a natural-order array.
void SetNatural(const CompactionProblem &problem, const std::vector<double> &x, Vec v) {
  PetscInt lo, hi;
  VecGetOwnershipRange(v, &lo, &hi);
  PetscScalar *a;
  VecGetArray(v, &a);
  for (size_t i = 0; i < x.size(); ++i) {
    const PetscInt k = problem.PetscIndex(static_cast<PetscInt>(i));
    if (k >= lo && k < hi) a[k - lo] = x[i];
  }
  VecRestoreArray(v, &a);
}

double MaxAbsDiff(const std::vector<double> &a, const std::vector<double> &b, double *scale) {
  double d = 0.0, s = 0.0;
  for (size_t i = 0; i < a.size(); ++i) d = std::max(d, std::abs(a[i] - b[i])), s = std::max(s, std::abs(b[i]));
  *scale = s;
  return d;
}

TEST(Distribution, EveryParticleOwnedOnceAndNumberingContiguousPerRank) {
  PetscMPIInt rank, size;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  auto problem = Build(PETSC_COMM_WORLD);
  ASSERT_TRUE(problem);
  Vec z;
  ASSERT_PETSC(problem->CreateGlobalVector(&z));  // sets up the layout: partition and numbering
  const int np = problem->NumParticles();
  std::vector<int> owner = problem->ParticleOwners();
  if (size == 1) {
    EXPECT_TRUE(owner.empty());  // no partition on one rank
    owner.assign(np, 0);
  }
  ASSERT_EQ(static_cast<int>(owner.size()), np);
  // Same table everywhere.
  std::vector<int> lo_owner(owner), hi_owner(owner);
  MPI_Allreduce(MPI_IN_PLACE, lo_owner.data(), np, MPI_INT, MPI_MIN, PETSC_COMM_WORLD);
  MPI_Allreduce(MPI_IN_PLACE, hi_owner.data(), np, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
  EXPECT_EQ(lo_owner, owner);
  EXPECT_EQ(hi_owner, owner);
  // Exactly one owner in range; every rank owns particles.
  std::vector<int> count(size, 0);
  for (int o : owner) {
    ASSERT_GE(o, 0);
    ASSERT_LT(o, size);
    ++count[o];
  }
  for (int r = 0; r < size; ++r) EXPECT_GT(count[r], 0) << "rank " << r << " owns no particle";
  // The PETSc numbering is a permutation, and each rank's rows are exactly
  // the unknowns of what it owns.
  PetscInt n, lo, hi;
  ASSERT_PETSC(VecGetSize(z, &n));
  ASSERT_PETSC(VecGetOwnershipRange(z, &lo, &hi));
  std::vector<char> seen(n, 0);
  PetscInt mine = 0;
  for (PetscInt i = 0; i < n; ++i) {
    const PetscInt k = problem->PetscIndex(i);
    ASSERT_GE(k, 0);
    ASSERT_LT(k, n);
    EXPECT_EQ(seen[k], 0) << "PETSc index " << k << " used twice";
    seen[k] = 1;
    mine += k >= lo && k < hi;
  }
  EXPECT_EQ(mine, hi - lo);
  for (const DeformableBody &b : problem->Bodies())
    for (int a = 0; a < 2 * b.mesh.num_nodes(); ++a) {
      const PetscInt k = problem->PetscIndex(b.dof_offset + a);
      EXPECT_EQ(k >= lo && k < hi, owner[b.particle] == rank) << "deformable particle " << b.particle;
    }
  for (const RigidBody &r : problem->RigidBodies()) {
    const PetscInt k = problem->PetscIndex(r.dof_offset);
    EXPECT_EQ(k >= lo && k < hi, owner[r.particle] == rank) << "rigid particle " << r.particle;
  }
  if (rank == 0) std::printf("  %d ranks: particles per rank", size);
  for (int r = 0; r < size && rank == 0; ++r) std::printf(" %d", count[r]);
  if (rank == 0) std::printf(", %" PetscInt_FMT " unknowns\n", n);
  VecDestroy(&z);
}

// Residual and J v of the distributed problem against the serial assembly
// (one-pass, two-pass or mortar deformable contact).
void CheckAssembly(Pass pass) {
  auto problem = Build(PETSC_COMM_WORLD, pass);
  auto serial = Build(PETSC_COMM_SELF, pass);
  ASSERT_TRUE(problem && serial);
  Vec z, F, zs, Fs;
  ASSERT_PETSC(problem->CreateGlobalVector(&z));
  ASSERT_PETSC(serial->CreateGlobalVector(&zs));
  ASSERT_PETSC(problem->PackState(z));
  std::vector<double> x = Natural(*problem, z);
  // A perturbed state (the same on every rank), multipliers included.
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  for (double &v : x) v += 1e-4 * U(rng) + (v == 0.0 ? 1e-4 * std::abs(U(rng)) : 0.0);
  SetNatural(*problem, x, z);
  SetNatural(*serial, x, zs);
  ASSERT_PETSC(VecDuplicate(z, &F));
  ASSERT_PETSC(VecDuplicate(zs, &Fs));
  ASSERT_PETSC(problem->EvaluateResidual(z, F));
  ASSERT_PETSC(serial->EvaluateResidual(zs, Fs));
  double scale;
  const double dr = MaxAbsDiff(Natural(*problem, F), Natural(*serial, Fs), &scale);
  EXPECT_LE(dr, 1e-12 * scale) << "residual differs from the serial assembly";
  EXPECT_EQ(problem->ActiveSet(), serial->ActiveSet());
  // J v for a random v.
  Mat J, Js;
  ASSERT_PETSC(problem->EvaluateJacobian(z, &J));
  ASSERT_PETSC(serial->EvaluateJacobian(zs, &Js));
  std::vector<double> v(x.size());
  for (double &e : v) e = U(rng);
  Vec vp, vs, Jv, Jvs;
  ASSERT_PETSC(VecDuplicate(z, &vp));
  ASSERT_PETSC(VecDuplicate(zs, &vs));
  ASSERT_PETSC(VecDuplicate(z, &Jv));
  ASSERT_PETSC(VecDuplicate(zs, &Jvs));
  SetNatural(*problem, v, vp);
  SetNatural(*serial, v, vs);
  ASSERT_PETSC(MatMult(J, vp, Jv));
  ASSERT_PETSC(MatMult(Js, vs, Jvs));
  const double dj = MaxAbsDiff(Natural(*problem, Jv), Natural(*serial, Jvs), &scale);
  EXPECT_LE(dj, 1e-12 * scale) << "J v differs from the serial assembly";
  PetscMPIInt rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  if (rank == 0)
    std::printf("  %s: residual difference %.1e, J v difference %.1e (scale %.1e)\n", Name(pass),
                dr, dj, scale);
  for (Vec *w : {&z, &F, &zs, &Fs, &vp, &vs, &Jv, &Jvs}) VecDestroy(w);
  MatDestroy(&J);
  MatDestroy(&Js);
}

TEST(Distribution, ResidualAndJacobianEqualTheSerialAssembly) { CheckAssembly(Pass::One); }
TEST(Distribution, TwoPassResidualAndJacobianEqualTheSerialAssembly) { CheckAssembly(Pass::Two); }
TEST(Distribution, MortarResidualAndJacobianEqualTheSerialAssembly) { CheckAssembly(Pass::Mortar); }

// Contact detection on several ranks: each rank's narrow phase finds exactly
// the candidates whose slave particle it owns, no rank finds one twice, and
// the gathered list equals the serial detection on the same state.
// With -contact_deformable two_pass each pass of a deformable pair belongs to the rank
// of its own slave, so the two passes of a pair cut by the partition are
// detected on different ranks.
void CheckDetection(bool two_pass) {
  auto problem = Build(PETSC_COMM_WORLD, two_pass ? Pass::Two : Pass::One);
  auto serial = Build(PETSC_COMM_SELF, two_pass ? Pass::Two : Pass::One);
  ASSERT_TRUE(problem && serial);
  Vec z;
  ASSERT_PETSC(problem->CreateGlobalVector(&z));  // partition
  VecDestroy(&z);
  PetscMPIInt rank, size;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  const std::vector<int> &owner = problem->ParticleOwners();
  if (size > 1) ASSERT_EQ(static_cast<int>(owner.size()), problem->NumParticles());
  const double margin = problem->Parameters().contact_margin;
  auto key = [](const ContactCandidate &c) {
    return std::vector<int>{static_cast<int>(c.type), c.body, c.point, static_cast<int>(c.wall), c.master, c.segment};
  };
  const std::vector<ContactCandidate> own = problem->DetectOwnCandidates(margin);
  for (const ContactCandidate &c : own) {
    const int slave = c.type == ContactType::RigidWall || c.type == ContactType::RigidRigid
                          ? problem->RigidBodies()[c.body].particle
                          : problem->Bodies()[c.body].particle;
    EXPECT_EQ(owner.empty() ? 0 : owner[slave], rank) << "rank " << rank << " detected a contact of particle " << slave;
  }
  int n_own = static_cast<int>(own.size()), n_sum = 0;
  MPI_Allreduce(&n_own, &n_sum, 1, MPI_INT, MPI_SUM, PETSC_COMM_WORLD);
  std::vector<std::vector<int>> all, ref;
  for (const ContactCandidate &c : problem->DetectCandidates(margin)) all.push_back(key(c));
  for (const ContactCandidate &c : serial->DetectCandidates(margin)) ref.push_back(key(c));
  std::sort(all.begin(), all.end());
  std::sort(ref.begin(), ref.end());
  EXPECT_EQ(n_sum, static_cast<int>(ref.size())) << "candidates detected on no rank or on two";
  EXPECT_EQ(all, ref);
  EXPECT_GT(ref.size(), 100u);
  if (size > 1) EXPECT_GT(n_own, 0) << "rank " << rank << " detected nothing";
  if (two_pass) {  // both passes present: some pair (A, B) also appears as (B, A)
    bool reversed = false;
    for (const std::vector<int> &c : ref)
      if (c[0] == static_cast<int>(ContactType::NodeSegment))
        for (const std::vector<int> &d : ref)
          reversed = reversed || (d[0] == c[0] && d[1] == c[4] && d[4] == c[1]);
    EXPECT_TRUE(reversed) << "no deformable pair detected both ways";
  }
}

TEST(Distribution, EachRankDetectsTheContactsOfItsParticlesAndTheUnionIsTheSerialList) { CheckDetection(false); }
TEST(Distribution, TwoPassDetectionOnEachRankUnitesToTheSerialList) { CheckDetection(true); }

TEST(Distribution, ReplicatedStateIsCurrentOnEveryRankAfterASolve) {
  auto problem = Build(PETSC_COMM_WORLD);
  ASSERT_TRUE(problem);
  problem->SetPressure(0.0);  // unloaded: the load controller steps from 0
  problem->SetFrictionActive(false);
  LoadControlParameters load;
  double step = -1.0;
  LevelReport rep;
  ASSERT_PETSC(AdvanceToPressure(*problem, load, 1e-3, &step, &rep));
  problem->SetFrictionActive(true);
  ASSERT_PETSC(AdvanceToPressure(*problem, load, 2e-3, &step, &rep));
  // Bitwise equal on every rank: compare with rank 0's copy.
  std::vector<double> u = problem->Displacements(), u0 = u;
  MPI_Bcast(u0.data(), static_cast<int>(u0.size()), MPI_DOUBLE, 0, PETSC_COMM_WORLD);
  EXPECT_EQ(u, u0);
  std::vector<double> lam = problem->Multipliers(), lam0 = lam;
  MPI_Bcast(lam0.data(), static_cast<int>(lam0.size()), MPI_DOUBLE, 0, PETSC_COMM_WORLD);
  EXPECT_EQ(lam, lam0);
  // And equal to the distributed solution.
  Vec z;
  ASSERT_PETSC(problem->CreateGlobalVector(&z));
  ASSERT_PETSC(problem->PackState(z));
  const std::vector<double> x = Natural(*problem, z);
  for (size_t i = 0; i < u.size(); ++i) ASSERT_EQ(x[i], u[i]);
  VecDestroy(&z);
  const StateSummary s = problem->Summary();
  EXPECT_LE(s.max_penetration, 1e-9 * problem->MeanDiameter());
  PetscMPIInt rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  if (rank == 0) std::printf("  P/E = 2e-3: phi = %.6f, %" PetscInt_FMT " Newton iterations\n", s.packing_fraction, rep.newton_its);
}

}  // namespace

int main(int argc, char **argv) {
  ::testing::InitGoogleTest(&argc, argv);
  if (PetscInitialize(&argc, &argv, nullptr, nullptr)) return 1;
  PetscOptionsSetValue(nullptr, "-snes_linesearch_type", "basic");
  // Only rank 0 reports (gtest prints on every rank otherwise).
  PetscMPIInt rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  if (rank != 0) {
    auto &listeners = ::testing::UnitTest::GetInstance()->listeners();
    delete listeners.Release(listeners.default_result_printer());
  }
  int result = RUN_ALL_TESTS();
  MPI_Allreduce(MPI_IN_PLACE, &result, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
  PetscFinalize();
  return result;
}

// The symmetric form of the Newton matrix and its LDL^T (problem.hpp).
//
// Rows of the Newton matrix J (problem.cpp, contact_pairs.cpp) on a level
// without friction, with the min NCP function:
//   body and wall rows a:  sum_b K_ab dx_b - sum_c dg_c,a dlambda_c (- G_a dmu)
//   active normal row c:   c_n dg_c . dx - delta dlambda_c
//   inactive normal row c: (1 - delta) dlambda_c
//   gauge row (rotation of a frictionless deformable body): (E / R) G . dx
// K is the Hessian of the Lagrangian (symmetric: hyperelastic elements, the
// walls' P x area, -lambda d2g of the contacts) plus the diagonal shifts,
// -delta the dual term (DualRegularization). Only the multiplier rows break symmetry.
// An inactive multiplier's step is known from its own row, so its column
// moves to the right-hand side (L: b_a -= J_ac b_c / (1 - delta), the
// column zeroed); the active normal rows times -1 / c_n and the gauge rows
// times -R / E (S) then equal their columns. J_s = S L J has the same
// solution for S L b, and its body block is J's.
#include "deformix/problem.hpp"

namespace deformix {

PetscErrorCode CompactionProblem::SymmetrizeNewtonMatrix(Mat J, bool *done) {
  PetscFunctionBeginUser;
  *done = false;
  // Which rows can be made symmetric: every normal row an identity or a
  // min-NCP row, every tangential row an identity row (no friction acting).
  int possible = params_.ncp == NcpFunction::Min && jacobian_rows_.size() == 2 * candidates_.size();
  for (size_t c = 0; possible && c < candidates_.size(); ++c)
    if (CandidateOwner(candidates_[c]) == rank_) possible = jacobian_rows_[2 * c + 1] != 2;
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &possible, 1, MPI_INT, MPI_MIN, comm_));
  if (!possible) PetscFunctionReturn(0);

  if (!J_unsymmetric_) {
    PetscCall(MatDuplicate(J, MAT_COPY_VALUES, &J_unsymmetric_));
    for (Vec *v : {&sym_scale_, &sym_pivot_, &sym_keep_, &sym_work_}) PetscCall(MatCreateVecs(J, v, nullptr));
  } else {
    PetscCall(MatCopy(J, J_unsymmetric_, SAME_NONZERO_PATTERN));
  }
  const double delta = DualRegularization(), c_n = params_.ncp_scale * params_.young;
  PetscScalar *scale, *pivot, *keep;
  PetscCall(VecSet(sym_scale_, 1.0));
  PetscCall(VecSet(sym_pivot_, 0.0));
  PetscCall(VecSet(sym_keep_, 1.0));
  PetscCall(VecGetArray(sym_scale_, &scale));
  PetscCall(VecGetArray(sym_pivot_, &pivot));
  PetscCall(VecGetArray(sym_keep_, &keep));
  std::vector<PetscInt> moved;  // PETSc rows (and columns) of the inactive multipliers
  const auto identity_row = [&](PetscInt natural) {
    const PetscInt row = petsc_of_[natural];
    moved.push_back(row);
    pivot[row - own_lo_] = 1.0 / (1.0 - delta);
    keep[row - own_lo_] = 0.0;
  };
  for (size_t c = 0; c < candidates_.size(); ++c) {
    if (CandidateOwner(candidates_[c]) != rank_) continue;
    const PetscInt normal = MultiplierOffset() + static_cast<PetscInt>(c);
    if (jacobian_rows_[2 * c] == 1) identity_row(normal);
    else scale[petsc_of_[normal] - own_lo_] = -1.0 / c_n;
    if (jacobian_rows_[2 * c + 1] == 1) identity_row(tangential_index_[c]);
  }
  if (!FrictionActive())  // the gauge rows are constraints (Assemble); released, they are diagonal
    for (size_t b = 0; b < torque_.size(); ++b)
      if (BodyOwner(static_cast<int>(b)) == rank_)
        scale[petsc_of_[GaugeOffset() + static_cast<PetscInt>(b)] - own_lo_] = -bodies_[b].mesh.radius / params_.young;
  PetscCall(VecRestoreArray(sym_scale_, &scale));
  PetscCall(VecRestoreArray(sym_pivot_, &pivot));
  PetscCall(VecRestoreArray(sym_keep_, &keep));
  // The identity rows keep their pivot 1 - delta; their columns are zeroed
  // (the nonzero pattern stays, so the symbolic factorization does too).
  PetscCall(MatSetOption(J, MAT_KEEP_NONZERO_PATTERN, PETSC_TRUE));
  PetscCall(MatZeroRowsColumns(J, static_cast<PetscInt>(moved.size()), moved.data(), 1.0 - delta, nullptr, nullptr));
  PetscCall(MatDiagonalScale(J, sym_scale_, nullptr));
  *done = true;
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::SymmetricRhs(Vec b, Vec bs) {
  PetscFunctionBeginUser;
  PetscCall(VecPointwiseMult(sym_work_, b, sym_pivot_));  // the moved multipliers' steps b_c / (1 - delta)
  PetscCall(MatMult(J_unsymmetric_, sym_work_, bs));      // their columns times their steps
  PetscCall(VecPointwiseMult(bs, bs, sym_keep_));         // (their own rows are unchanged)
  PetscCall(VecAYPX(bs, -1.0, b));                        // L b
  PetscCall(VecPointwiseMult(bs, bs, sym_scale_));        // S L b
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::SymmetricKsp(KSP *ksp) {
  PetscFunctionBeginUser;
  if (!ksp_) PetscCall(SetUpLayout());
  if (!ksp_ldlt_) PetscCall(CreateFactorKsp(PCCHOLESKY, "ldlt_", &ksp_ldlt_));
  *ksp = ksp_ldlt_;
  PetscFunctionReturn(0);
}

}  // namespace deformix

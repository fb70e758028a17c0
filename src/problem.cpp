#include "deformix/problem.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <tuple>

namespace deformix {

namespace {
// -log_view events: where the time of a solve goes besides the factorization.
PetscLogEvent event_residual = 0, event_jacobian = 0, event_detect = 0;
PetscErrorCode RegisterEvents() {
  static bool registered = false;
  PetscClassId id;
  PetscFunctionBeginUser;
  if (registered) PetscFunctionReturn(0);
  PetscCall(PetscClassIdRegister("deformix", &id));
  PetscCall(PetscLogEventRegister("AssembleResidual", id, &event_residual));
  PetscCall(PetscLogEventRegister("AssembleJacobian", id, &event_jacobian));
  PetscCall(PetscLogEventRegister("ContactDetect", id, &event_detect));
  registered = true;
  PetscFunctionReturn(0);
}
}  // namespace

PetscErrorCode ProblemParameters::SetFromOptions(MPI_Comm comm) {
  PetscBool set = PETSC_FALSE;
  PetscInt ncp_choice = ncp == NcpFunction::Min ? 0 : 1;
  const char *const ncp_names[] = {"min", "fb", "NcpFunction", "ncp_", nullptr};
  PetscFunctionBeginUser;
  PetscOptionsBegin(comm, nullptr, "Material and contact solver", "deformix");
  PetscCall(PetscOptionsReal("-E", "Young's modulus of the deformable disks", "", young, &young, nullptr));
  PetscCall(PetscOptionsReal("-nu", "Poisson's ratio of the deformable disks (-1 < nu < 0.5)", "", poisson, &poisson,
                             nullptr));
  PetscCall(PetscOptionsEList("-contact_ncp", "NCP function of the normal contact law", "", ncp_names, 2,
                              ncp_names[ncp_choice], &ncp_choice, &set));
  PetscCall(PetscOptionsReal("-contact_ncp_scale", "c_n / E in the NCP function (changes the Newton path only)", "",
                             ncp_scale, &ncp_scale, nullptr));
  PetscCall(PetscOptionsReal("-prox_eta", "proximal regularization of the Newton step, rho / E (vanishes at equilibrium)",
                             "", prox_eta, &prox_eta, nullptr));
  PetscCall(PetscOptionsBool("-constrain_rotation",
                             "fix the mean rotation of frictionless deformable bodies (zero-energy mode; its torque is reported)",
                             "", constrain_rotation, &constrain_rotation, nullptr));
  PetscCall(PetscOptionsBool("-secant_predictor", "start each increment from the secant extrapolation of the last two states",
                             "", secant_predictor, &secant_predictor, nullptr));
  PetscCall(PetscOptionsReal("-contact_margin", "contact candidates: gap below margin x mean diameter", "",
                             contact_margin, &contact_margin, nullptr));
  PetscOptionsEnd();
  ncp = ncp_choice == 0 ? NcpFunction::Min : NcpFunction::FischerBurmeister;
  PetscCheck(young > 0.0, comm, PETSC_ERR_USER_INPUT, "-E %g: Young's modulus must be positive", young);
  PetscCheck(poisson > -1.0 && poisson < 0.5, comm, PETSC_ERR_USER_INPUT,
             "-nu %g: Poisson's ratio must satisfy -1 < nu < 0.5 (nu = 0.5 is incompressible, use e.g. 0.4999)",
             poisson);
  PetscCheck(ncp_scale > 0.0, comm, PETSC_ERR_USER_INPUT, "-contact_ncp_scale %g must be positive", ncp_scale);
  PetscCheck(prox_eta >= 0.0, comm, PETSC_ERR_USER_INPUT, "-prox_eta %g must be >= 0", prox_eta);
  PetscCheck(contact_margin > 0.0, comm, PETSC_ERR_USER_INPUT, "-contact_margin %g must be positive", contact_margin);
  PetscFunctionReturn(0);
}

CompactionProblem::CompactionProblem(MPI_Comm comm) : comm_(comm) {
  RegisterEvents();
  MPI_Comm_rank(comm, &rank_);
  MPI_Comm_size(comm, &size_);
  material_ = NeoHookean::from_young_poisson(params_.young, params_.poisson);
}

CompactionProblem::~CompactionProblem() { DestroySolver(); }

PetscErrorCode CompactionProblem::SetParameters(const ProblemParameters &p) {
  PetscFunctionBeginUser;
  params_ = p;
  material_ = NeoHookean::from_young_poisson(p.young, p.poisson);
  torque_.assign(params_.constrain_rotation ? bodies_.size() : 0, 0.0);
  PetscCall(DestroySolver());
  PetscFunctionReturn(0);
}

int CompactionProblem::AddDeformableBody(const DiskMesh &mesh, double cx, double cy) {
  DeformableBody body;
  body.mesh = mesh;
  body.center[0] = cx;
  body.center[1] = cy;
  body.dof_offset = n_body_dofs_;
  const int nen = mesh.nodes_per_cell();
  std::vector<double> Xe(2 * nen);
  for (int e = 0; e < mesh.num_cells(); ++e) {
    for (int a = 0; a < nen; ++a) {
      const int n = mesh.cells[e * nen + a];
      Xe[2 * a] = mesh.X[2 * n];
      Xe[2 * a + 1] = mesh.X[2 * n + 1];
    }
    const ElementResult r = triangle_element(material_, mesh.order, Xe.data(), Xe.data(), nullptr, nullptr);
    body.ref_cell_area.push_back(r.ref_area);
    body.ref_area += r.ref_area;
  }
  n_body_dofs_ += 2 * mesh.num_nodes();
  u_.resize(n_body_dofs_, 0.0);
  bodies_.push_back(std::move(body));
  double dsum = 0.0;
  for (const auto &b : bodies_) dsum += 2.0 * b.mesh.radius;
  mean_diameter_ = dsum / bodies_.size();
  torque_.assign(params_.constrain_rotation ? bodies_.size() : 0, 0.0);
  DestroySolver();
  return static_cast<int>(bodies_.size()) - 1;
}

void CompactionProblem::SetWalls(const double w[4]) { std::copy(w, w + 4, w_); }

void CompactionProblem::NodePosition(int b, int a, double x[2]) const {
  const DeformableBody &body = bodies_[b];
  const PetscInt d = body.dof_offset + 2 * a;
  x[0] = body.center[0] + body.mesh.X[2 * a] + u_[d];
  x[1] = body.center[1] + body.mesh.X[2 * a + 1] + u_[d + 1];
}

BoundaryPoint boundary_point(const DiskMesh &mesh, int i) {
  BoundaryPoint bp;
  const int nb = static_cast<int>(mesh.boundary.size());
  bp.nodes[0] = mesh.boundary[i];
  if (mesh.order == 2 && i % 2 == 1) {
    bp.n = 3;
    bp.nodes[1] = mesh.boundary[i - 1];
    bp.nodes[2] = mesh.boundary[(i + 1) % nb];
    bp.coeff[0] = 2.0, bp.coeff[1] = -0.5, bp.coeff[2] = -0.5;
  }
  return bp;
}

void CompactionProblem::BoundaryPointPosition(int b, int i, double x[2]) const {
  const BoundaryPoint bp = boundary_point(bodies_[b].mesh, i);
  x[0] = x[1] = 0.0;
  for (int k = 0; k < bp.n; ++k) {
    double xn[2];
    NodePosition(b, bp.nodes[k], xn);
    x[0] += bp.coeff[k] * xn[0], x[1] += bp.coeff[k] * xn[1];
  }
}

// ---------------------------------------------------------------------------
// State packing. Global unknown order: bodies' displacements, 4 walls, multipliers.
void CompactionProblem::Pack(double *z) const {
  std::copy(u_.begin(), u_.end(), z);
  std::copy(w_, w_ + 4, z + n_body_dofs_);
  std::copy(torque_.begin(), torque_.end(), z + n_body_dofs_ + 4);
  std::copy(lambda_.begin(), lambda_.end(), z + MultiplierOffset());
}

void CompactionProblem::Unpack(const double *z) {
  std::copy(z, z + n_body_dofs_, u_.begin());
  std::copy(z + n_body_dofs_, z + n_body_dofs_ + 4, w_);
  std::copy(z + n_body_dofs_ + 4, z + MultiplierOffset(), torque_.begin());
  std::copy(z + MultiplierOffset(), z + MultiplierOffset() + lambda_.size(), lambda_.begin());
}

CompactionProblem::State CompactionProblem::SaveState() const {
  State s;
  s.u = u_;
  std::copy(w_, w_ + 4, s.w);
  s.lambda = lambda_;
  s.torque = torque_;
  s.candidates = candidates_;
  return s;
}

void CompactionProblem::RestoreState(const State &s) {
  u_ = s.u;
  std::copy(s.w, s.w + 4, w_);
  if (s.candidates.size() != candidates_.size()) DestroySolver();
  candidates_ = s.candidates;
  lambda_ = s.lambda;
  torque_ = s.torque;
}

// ---------------------------------------------------------------------------
// Contact candidates: every boundary node against every wall closer than the
// margin. Cheap here (O(boundary nodes)); the mixture replaces it with a
// cell-list broad phase.
std::vector<ContactCandidate> CompactionProblem::DetectCandidates(double margin) const {
  std::vector<ContactCandidate> out;
  const double reach = margin * mean_diameter_;
  for (int b = 0; b < static_cast<int>(bodies_.size()); ++b) {
    for (int i = 0; i < static_cast<int>(bodies_[b].mesh.boundary.size()); ++i) {
      double x[2];
      BoundaryPointPosition(b, i, x);
      double gaps[4];
      WallBox::point_gaps(x, w_, gaps);
      for (int k = 0; k < 4; ++k)
        if (gaps[k] < reach) out.push_back({b, i, static_cast<Wall>(k)});
    }
  }
  return out;
}

PetscErrorCode CompactionProblem::RefreshCandidates() {
  PetscFunctionBeginUser;
  PetscCall(PetscLogEventBegin(event_detect, 0, 0, 0, 0));
  auto key = [](const ContactCandidate &c) { return std::make_tuple(c.body, c.point, static_cast<int>(c.wall)); };
  std::map<std::tuple<int, int, int>, double> old;
  for (size_t c = 0; c < candidates_.size(); ++c) old[key(candidates_[c])] = lambda_[c];
  std::vector<ContactCandidate> fresh = DetectCandidates(params_.contact_margin);
  // A candidate that still carries force stays, whatever its gap.
  for (size_t c = 0; c < candidates_.size(); ++c) {
    if (lambda_[c] <= 0.0) continue;
    const auto k = key(candidates_[c]);
    if (std::none_of(fresh.begin(), fresh.end(), [&](const ContactCandidate &f) { return key(f) == k; }))
      fresh.push_back(candidates_[c]);
  }
  std::sort(fresh.begin(), fresh.end(), [&](const ContactCandidate &a, const ContactCandidate &b) { return key(a) < key(b); });
  bool same = fresh.size() == candidates_.size();
  for (size_t c = 0; same && c < fresh.size(); ++c) same = key(fresh[c]) == key(candidates_[c]);
  if (!same) {
    std::vector<double> lam(fresh.size(), 0.0);
    for (size_t c = 0; c < fresh.size(); ++c) {
      auto it = old.find(key(fresh[c]));
      if (it != old.end()) lam[c] = it->second;
    }
    candidates_ = std::move(fresh);
    lambda_ = std::move(lam);
    PetscCall(DestroySolver());
  }
  PetscCall(PetscLogEventEnd(event_detect, 0, 0, 0, 0));
  PetscFunctionReturn(0);
}

// ---------------------------------------------------------------------------
// One walk over elements, walls and contacts serves the residual, the
// Jacobian's sparsity pattern and its values, so the three can never disagree.
PetscErrorCode CompactionProblem::Assemble(const double *z, double *F, std::vector<PetscInt> *ci,
                                           std::vector<PetscInt> *cj, std::vector<PetscScalar> *cv,
                                           bool *inverted, std::vector<char> *active) {
  const bool pattern = ci != nullptr;
  const bool values = cv != nullptr;
  const bool need_K = pattern || values;
  const PetscInt wall_off = n_body_dofs_, rot_off = n_body_dofs_ + 4, lam_off = MultiplierOffset();
  auto entry = [&](PetscInt i, PetscInt j, double v) {
    if (pattern) ci->push_back(i), cj->push_back(j);
    if (values) cv->push_back(v);
  };
  PetscFunctionBeginUser;
  if (inverted) *inverted = false;
  if (!OwnsEverything()) PetscFunctionReturn(0);

  // Bodies: hyperelastic elements.
  std::vector<double> Xe, xe, fe, Ke;
  std::vector<PetscInt> dofs;
  for (const DeformableBody &body : bodies_) {
    const DiskMesh &m = body.mesh;
    const int nen = m.nodes_per_cell(), nd = 2 * nen;
    Xe.resize(nd), xe.resize(nd), fe.resize(nd), Ke.resize(nd * nd), dofs.resize(nd);
    for (int e = 0; e < m.num_cells(); ++e) {
      for (int a = 0; a < nen; ++a) {
        const int n = m.cells[e * nen + a];
        for (int i = 0; i < 2; ++i) {
          dofs[2 * a + i] = body.dof_offset + 2 * n + i;
          Xe[2 * a + i] = m.X[2 * n + i];
          xe[2 * a + i] = pattern ? 0.0 : m.X[2 * n + i] + z[dofs[2 * a + i]];
        }
      }
      if (pattern) {
        for (int p = 0; p < nd; ++p)
          for (int q = 0; q < nd; ++q) entry(dofs[p], dofs[q], 0.0);
        continue;
      }
      const ElementResult r =
          triangle_element(material_, m.order, Xe.data(), xe.data(), F ? fe.data() : nullptr, need_K ? Ke.data() : nullptr);
      if (r.inverted) {
        if (inverted) *inverted = true;
        std::fill(fe.begin(), fe.end(), 0.0);
        std::fill(Ke.begin(), Ke.end(), 0.0);
      }
      if (F)
        for (int p = 0; p < nd; ++p) F[dofs[p]] += fe[p];
      if (values)
        for (int p = 0; p < nd; ++p)
          for (int q = 0; q < nd; ++q) entry(dofs[p], dofs[q], Ke[p * nd + q]);
    }
  }

  // Walls: the pressure load P * box area. (The pattern walk has no state: it uses zeros.)
  std::vector<double> zero;
  if (pattern) zero.assign(n_total_, 0.0), z = zero.data();
  const double *w = z + wall_off;
  if (F) {
    double g[4];
    WallBox::pressure_gradient(pressure_, w, g);
    for (int i = 0; i < 4; ++i) F[wall_off + i] += g[i];
  }
  if (need_K) {
    double H[16];
    WallBox::pressure_hessian(pressure_, H);
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) entry(wall_off + i, wall_off + j, H[4 * i + j]);
  }

  // Proximal term on the Newton step: rho on the diagonal of every body and wall unknown.
  if (need_K) {
    const double rho = params_.prox_eta * params_.young;
    for (PetscInt i = 0; i < rot_off; ++i) entry(i, i, rho);
  }

  // Rotation gauge of frictionless bodies: c_b(u) = G_b . u = mean of X x u = 0,
  // with multiplier mu_b (a torque): R_u -= mu_b G_b, R_mu = (E / R_b) c_b.
  // By the mirror symmetry of mesh and box the equilibrium torque is zero, so
  // the constraint selects the symmetric equilibrium without loading it.
  for (size_t b = 0; b < torque_.size(); ++b) {
    const DeformableBody &body = bodies_[b];
    const int nn = body.mesh.num_nodes();
    const PetscInt mu_dof = rot_off + static_cast<PetscInt>(b);
    const double mu = z[mu_dof], row_scale = params_.young / body.mesh.radius;
    double c = 0.0;
    for (int a = 0; a < nn; ++a) {
      const PetscInt d = body.dof_offset + 2 * a;
      const double G[2] = {-body.mesh.X[2 * a + 1] / nn, body.mesh.X[2 * a] / nn};
      for (int i = 0; i < 2; ++i) {
        c += G[i] * z[d + i];
        if (F) F[d + i] -= mu * G[i];
        if (need_K) entry(d + i, mu_dof, -G[i]), entry(mu_dof, d + i, row_scale * G[i]);
      }
    }
    if (F) F[mu_dof] += row_scale * c;
    if (need_K) entry(mu_dof, mu_dof, 0.0);
  }

  // Contacts: -lambda dg/dz in the equilibrium rows, the NCP function in the multiplier rows.
  if (active) active->assign(candidates_.size(), 0);
  const double c_n = params_.ncp_scale * params_.young;
  for (size_t c = 0; c < candidates_.size(); ++c) {
    const ContactCandidate &cc = candidates_[c];
    const DeformableBody &body = bodies_[cc.body];
    const BoundaryPoint bp = boundary_point(body.mesh, cc.point);
    double x[2] = {0.0, 0.0};
    int dx[3], dy[3];
    for (int a = 0; a < bp.n; ++a) {
      const int n = bp.nodes[a];
      dx[a] = static_cast<int>(body.dof_offset) + 2 * n, dy[a] = dx[a] + 1;
      x[0] += bp.coeff[a] * (body.center[0] + body.mesh.X[2 * n] + z[dx[a]]);
      x[1] += bp.coeff[a] * (body.center[1] + body.mesh.X[2 * n + 1] + z[dy[a]]);
    }
    const ContactKinematics k =
        WallBox::point_gap(cc.wall, x, w, bp.n, dx, dy, bp.coeff, static_cast<int>(wall_off) + cc.wall);
    const PetscInt lam_dof = lam_off + static_cast<PetscInt>(c);
    const double lam = z[lam_dof];
    const NormalNcp ncp = normal_ncp(params_.ncp, lam, k.gap, c_n);
    if (active) (*active)[c] = ncp.active;
    if (F) {
      for (int a = 0; a < k.ndof; ++a) F[k.dofs[a]] -= lam * k.dgap[a];
      F[lam_dof] += ncp.value;
    }
    if (need_K) {
      for (int a = 0; a < k.ndof; ++a) {
        entry(k.dofs[a], lam_dof, -k.dgap[a]);
        entry(lam_dof, k.dofs[a], ncp.d_gap * k.dgap[a]);
      }
      entry(lam_dof, lam_dof, ncp.d_lambda);
    }
  }
  PetscFunctionReturn(0);
}

// ---------------------------------------------------------------------------
// PETSc callbacks.
PetscErrorCode CompactionProblem::Gather(Vec z) {
  PetscFunctionBeginUser;
  PetscCall(VecScatterBegin(to_all_, z, zall_, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(to_all_, z, zall_, INSERT_VALUES, SCATTER_FORWARD));
  PetscFunctionReturn(0);
}

PetscErrorCode FormFunction(SNES snes, Vec z, Vec F, void *ctx) {
  auto *p = static_cast<CompactionProblem *>(ctx);
  const PetscScalar *za;
  PetscScalar *fa;
  bool inverted = false;
  PetscFunctionBeginUser;
  PetscCall(PetscLogEventBegin(event_residual, 0, 0, 0, 0));
  PetscCall(p->Gather(z));
  PetscCall(VecGetArrayRead(p->zall_, &za));
  PetscCall(VecSet(F, 0.0));
  PetscCall(VecGetArray(F, &fa));  // rank 0 owns every row in this version
  PetscCall(p->Assemble(za, p->OwnsEverything() ? fa : nullptr, nullptr, nullptr, nullptr, &inverted, &p->active_now_));
  PetscCall(VecRestoreArray(F, &fa));
  PetscCall(VecRestoreArrayRead(p->zall_, &za));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &inverted, 1, MPI_C_BOOL, MPI_LOR, p->comm_));
  p->inverted_ = inverted;
  if (inverted && snes) PetscCall(SNESSetFunctionDomainError(snes));
  PetscCall(PetscLogEventEnd(event_residual, 0, 0, 0, 0));
  PetscFunctionReturn(0);
}

PetscErrorCode FormJacobian(SNES, Vec z, Mat J, Mat, void *ctx) {
  auto *p = static_cast<CompactionProblem *>(ctx);
  const PetscScalar *za;
  PetscFunctionBeginUser;
  PetscCall(PetscLogEventBegin(event_jacobian, 0, 0, 0, 0));
  PetscCall(p->Gather(z));
  PetscCall(VecGetArrayRead(p->zall_, &za));
  p->coo_values_.clear();
  PetscCall(p->Assemble(za, nullptr, nullptr, nullptr, &p->coo_values_, nullptr, nullptr));
  PetscCall(VecRestoreArrayRead(p->zall_, &za));
  PetscCall(MatSetValuesCOO(J, p->coo_values_.data(), INSERT_VALUES));
  PetscCall(PetscLogEventEnd(event_jacobian, 0, 0, 0, 0));
  PetscFunctionReturn(0);
}

// Converged only when the residual is small and the active set is stable.
PetscErrorCode ConvergenceTest(SNES snes, PetscInt it, PetscReal, PetscReal, PetscReal fnorm,
                               SNESConvergedReason *reason, void *ctx) {
  auto *p = static_cast<CompactionProblem *>(ctx);
  PetscReal atol, rtol, stol;
  PetscInt maxit, maxf;
  PetscFunctionBeginUser;
  PetscCall(SNESGetTolerances(snes, &atol, &rtol, &stol, &maxit, &maxf));
  const bool changed = p->active_now_ != p->active_checked_;
  int changed_any = changed ? 1 : 0;
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &changed_any, 1, MPI_INT, MPI_MAX, p->comm_));
  p->active_checked_ = p->active_now_;
  *reason = SNES_CONVERGED_ITERATING;
  if (it == 0) p->fnorm0_ = fnorm;
  if (PetscIsInfOrNanReal(fnorm)) {
    *reason = SNES_DIVERGED_FNORM_NAN;
  } else if (fnorm <= std::max<PetscReal>(atol, rtol * p->fnorm0_) && (it == 0 || !changed_any)) {
    *reason = SNES_CONVERGED_FNORM_ABS;
  } else if (it >= maxit) {
    *reason = SNES_DIVERGED_MAX_IT;
  }
  PetscFunctionReturn(0);
}

static PetscErrorCode NewtonMonitor(SNES, PetscInt it, PetscReal fnorm, void *ctx) {
  auto *p = static_cast<CompactionProblem *>(ctx);
  int active = 0;
  PetscFunctionBeginUser;
  for (char a : p->ActiveSet()) active += a;
  PetscCall(PetscPrintf(PETSC_COMM_WORLD, "    newton %2" PetscInt_FMT "  |R| %.3e  active contacts %d\n", it,
                        (double)fnorm, active));
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::DestroySolver() {
  PetscFunctionBeginUser;
  PetscCall(SNESDestroy(&snes_));
  PetscCall(MatDestroy(&J_));
  PetscCall(VecDestroy(&z_));
  PetscCall(VecDestroy(&r_));
  PetscCall(VecDestroy(&zall_));
  PetscCall(VecScatterDestroy(&to_all_));
  n_total_ = -1;
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::CreateGlobalVector(Vec *z) {
  PetscFunctionBeginUser;
  if (!z_) PetscCall(SetUpLayout());
  PetscCall(VecDuplicate(z_, z));
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::PackState(Vec z) const {
  PetscScalar *za;
  PetscFunctionBeginUser;
  PetscCall(VecGetArray(z, &za));
  if (rank_ == 0) Pack(za);
  PetscCall(VecRestoreArray(z, &za));
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::SetUpLayout() {
  PetscFunctionBeginUser;
  PetscCall(DestroySolver());
  lambda_.resize(candidates_.size(), 0.0);
  n_total_ = MultiplierOffset() + static_cast<PetscInt>(candidates_.size());
  const PetscInt n_local = rank_ == 0 ? n_total_ : 0;
  PetscCall(VecCreateMPI(comm_, n_local, n_total_, &z_));
  PetscCall(VecDuplicate(z_, &r_));
  PetscCall(VecScatterCreateToAll(z_, &to_all_, &zall_));

  std::vector<PetscInt> ci, cj;
  PetscCall(Assemble(nullptr, nullptr, &ci, &cj, nullptr, nullptr, nullptr));
  PetscCall(MatCreate(comm_, &J_));
  PetscCall(MatSetSizes(J_, n_local, n_local, n_total_, n_total_));
  PetscCall(MatSetType(J_, MATAIJ));
  PetscCall(MatSetOptionsPrefix(J_, "jac_"));
  PetscCall(MatSetFromOptions(J_));
  PetscCall(MatSetPreallocationCOO(J_, static_cast<PetscCount>(ci.size()), ci.data(), cj.data()));

  PetscCall(SNESCreate(comm_, &snes_));
  PetscCall(SNESSetType(snes_, SNESNEWTONLS));
  PetscCall(SNESSetFunction(snes_, r_, FormFunction, this));
  PetscCall(SNESSetJacobian(snes_, J_, J_, FormJacobian, this));
  PetscCall(SNESSetConvergenceTest(snes_, ConvergenceTest, this, nullptr));
  // Forces are per unit thickness, in units of E * d; the tolerance is absolute in those units.
  PetscCall(SNESSetTolerances(snes_, 1e-11 * params_.young * mean_diameter_, 1e-30, 0.0, 50, -1));
  SNESLineSearch ls;
  PetscCall(SNESGetLineSearch(snes_, &ls));
  PetscCall(SNESLineSearchSetType(ls, SNESLINESEARCHBT));
  KSP ksp;
  PC pc;
  PetscCall(SNESGetKSP(snes_, &ksp));
  PetscCall(KSPSetType(ksp, KSPPREONLY));
  PetscCall(KSPGetPC(ksp, &pc));
  PetscCall(PCSetType(pc, PCLU));
  PetscCall(PCFactorSetMatSolverType(pc, MATSOLVERMUMPS));
  PetscCall(SNESSetFromOptions(snes_));
  PetscBool monitor = PETSC_FALSE;
  PetscCall(PetscOptionsGetBool(nullptr, nullptr, "-newton_monitor", &monitor, nullptr));
  if (monitor) PetscCall(SNESMonitorSet(snes_, NewtonMonitor, this, nullptr));
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::EvaluateResidual(Vec z, Vec F) {
  PetscFunctionBeginUser;
  PetscCall(FormFunction(nullptr, z, F, this));
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::EvaluateJacobian(Vec z, Mat *J) {
  PetscFunctionBeginUser;
  PetscCall(MatDuplicate(J_, MAT_DO_NOT_COPY_VALUES, J));
  PetscCall(FormJacobian(nullptr, z, *J, *J, this));
  PetscFunctionReturn(0);
}

// ---------------------------------------------------------------------------
PetscErrorCode CompactionProblem::Solve(double pressure, SolveReport *report) {
  PetscFunctionBeginUser;
  *report = SolveReport();
  const State saved = SaveState();
  const double saved_pressure = pressure_;
  // Secant predictor along the load path: extrapolate the bodies and walls
  // from the last two converged states (none for the first increment).
  if (params_.secant_predictor && have_previous_ && pressure_ != previous_pressure_) {
    const double t = (pressure - pressure_) / (pressure_ - previous_pressure_);
    for (size_t i = 0; i < u_.size(); ++i) u_[i] += t * (u_[i] - previous_.u[i]);
    for (int k = 0; k < 4; ++k) w_[k] += t * (w_[k] - previous_.w[k]);
  }
  pressure_ = pressure;
  PetscCall(RefreshCandidates());
  for (int refresh = 0;; ++refresh) {
    if (!snes_) PetscCall(SetUpLayout());
    PetscCall(PackState(z_));
    active_checked_.clear();
    PetscCall(SNESSolve(snes_, nullptr, z_));
    PetscInt its;
    PetscCall(SNESGetIterationNumber(snes_, &its));
    PetscCall(SNESGetConvergedReason(snes_, &report->reason));
    report->newton_its += its;
    PetscCall(SNESGetFunctionNorm(snes_, &report->residual));
    if (report->reason <= 0) {
      RestoreState(saved);
      pressure_ = saved_pressure;
      PetscFunctionReturn(0);
    }
    PetscCall(Gather(z_));
    const PetscScalar *za;
    PetscCall(VecGetArrayRead(zall_, &za));
    Unpack(za);
    PetscCall(VecRestoreArrayRead(zall_, &za));
    // A node that was not a candidate may have crossed a wall during the
    // solve: make it a candidate and solve again (rare, the margin is wide).
    const size_t before = candidates_.size();
    bool penetrated = false;
    for (const ContactCandidate &c : DetectCandidates(0.0)) {
      double x[2];
      BoundaryPointPosition(c.body, c.point, x);
      double g[4];
      WallBox::point_gaps(x, w_, g);
      if (g[c.wall] < 0.0) penetrated = true;
    }
    if (penetrated) PetscCall(RefreshCandidates());
    if (!penetrated || candidates_.size() == before || refresh >= 3) break;
    ++report->candidate_refreshes;
  }
  report->converged = true;
  previous_ = saved;
  previous_pressure_ = saved_pressure;
  have_previous_ = true;
  for (char a : active_now_) report->active_contacts += a;
  PetscFunctionReturn(0);
}

// ---------------------------------------------------------------------------
std::vector<double> CompactionProblem::CellAreaRatio(int b) const {
  const DeformableBody &body = bodies_[b];
  const DiskMesh &m = body.mesh;
  const int nen = m.nodes_per_cell();
  std::vector<double> Xe(2 * nen), xe(2 * nen), out(m.num_cells());
  for (int e = 0; e < m.num_cells(); ++e) {
    for (int a = 0; a < nen; ++a) {
      const int n = m.cells[e * nen + a];
      for (int i = 0; i < 2; ++i) {
        Xe[2 * a + i] = m.X[2 * n + i];
        xe[2 * a + i] = m.X[2 * n + i] + u_[body.dof_offset + 2 * n + i];
      }
    }
    const ElementResult r = triangle_element(material_, m.order, Xe.data(), xe.data(), nullptr, nullptr);
    out[e] = r.inverted ? -1.0 : r.area / body.ref_cell_area[e];
  }
  return out;
}

StateSummary CompactionProblem::Summary() const {
  StateSummary s;
  s.box_width = WallBox::width(w_);
  s.box_height = WallBox::height(w_);
  s.min_cell_area_ratio = std::numeric_limits<double>::infinity();
  for (int b = 0; b < static_cast<int>(bodies_.size()); ++b) {
    const std::vector<double> ratio = CellAreaRatio(b);
    for (size_t e = 0; e < ratio.size(); ++e) {
      s.particle_area += ratio[e] * bodies_[b].ref_cell_area[e];
      s.min_cell_area_ratio = std::min(s.min_cell_area_ratio, ratio[e]);
    }
    s.ref_particle_area += bodies_[b].ref_area;
  }
  s.packing_fraction = s.particle_area / WallBox::area(w_);
  s.area_ratio = s.particle_area / s.ref_particle_area;
  s.max_penetration = -std::numeric_limits<double>::infinity();
  for (int b = 0; b < static_cast<int>(bodies_.size()); ++b)
    for (int i = 0; i < static_cast<int>(bodies_[b].mesh.boundary.size()); ++i) {
      double x[2];
      BoundaryPointPosition(b, i, x);
      double g[4];
      WallBox::point_gaps(x, w_, g);
      for (double gi : g) s.max_penetration = std::max(s.max_penetration, -gi);
    }
  for (size_t c = 0; c < candidates_.size(); ++c) {
    double x[2];
    BoundaryPointPosition(candidates_[c].body, candidates_[c].point, x);
    double g[4];
      WallBox::point_gaps(x, w_, g);
    s.wall_force[candidates_[c].wall] += lambda_[c];
    s.min_multiplier = std::min(s.min_multiplier, lambda_[c]);
    s.max_complementarity = std::max(s.max_complementarity, std::abs(lambda_[c] * g[candidates_[c].wall]));
    if (lambda_[c] > 0.0) ++s.active_contacts;
  }
  for (double mu : torque_) s.max_gauge_torque = std::max(s.max_gauge_torque, std::abs(mu));
  return s;
}

}  // namespace deformix

#include "deformix/problem.hpp"
#include "deformix/partition.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <set>
#include <string>
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

// Identity of a candidate across refreshes (the segment of a node-segment
// pair may change while the multiplier carries over).
std::tuple<int, int, int, int, int> CandidateKey(const ContactCandidate &c) {
  return std::make_tuple(static_cast<int>(c.type), c.body, c.point, static_cast<int>(c.wall), c.master);
}
}  // namespace

PetscErrorCode ProblemParameters::SetFromOptions(MPI_Comm comm) {
  PetscBool set = PETSC_FALSE;
  PetscInt ncp_choice = ncp == NcpFunction::Min ? 0 : 1;
  const char *const ncp_names[] = {"min", "fb", "NcpFunction", "ncp_", nullptr};
  PetscInt deformable_choice = static_cast<PetscInt>(deformable_contact);
  const char *const predictor_names[] = {"none", "tangent"};  // LoadPredictor order
  PetscInt predictor_choice = static_cast<PetscInt>(predictor);
  const char *const deformable_names[] = {"nts", "two_pass", "mortar"};  // DeformableContact order
  PetscFunctionBeginUser;
  PetscOptionsBegin(comm, nullptr, "Material and contact solver", "deformix");
  PetscCall(PetscOptionsReal("-E", "Young's modulus of the deformable disks", "", young, &young, nullptr));
  PetscCall(PetscOptionsReal("-nu", "Poisson's ratio of the deformable disks (-1 < nu < 0.5)", "", poisson, &poisson,
                             nullptr));
  PetscCall(PetscOptionsReal("-friction", "Coulomb friction coefficient between particles (walls are frictionless)",
                             "", friction, &friction, nullptr));
  PetscCall(PetscOptionsEList("-contact_ncp", "NCP function of the normal contact law", "", ncp_names, 2,
                              ncp_names[ncp_choice], &ncp_choice, &set));
  PetscCall(PetscOptionsReal("-contact_ncp_scale", "c_n / E in the NCP functions (changes the Newton path only)", "",
                             ncp_scale, &ncp_scale, nullptr));
  PetscCall(PetscOptionsReal("-prox_eta", "proximal regularization of the Newton step, rho / E (vanishes at equilibrium)",
                             "", prox_eta, &prox_eta, nullptr));
  PetscCall(PetscOptionsReal("-ptc_move",
                             "pseudo-transient continuation: largest move of a body per pseudo-time step / <d>; each step is one Coulomb increment (0: plain Newton)",
                             "", ptc_move, &ptc_move, nullptr));
  PetscCall(PetscOptionsBool("-constrain_rotation",
                             "fix the mean rotation of frictionless deformable bodies (zero-energy mode; its torque is reported)",
                             "", constrain_rotation, &constrain_rotation, nullptr));
  PetscCall(PetscOptionsEList("-predictor",
                              "initial guess of each load step: none (the last converged state) or tangent (the last "
                              "state plus dP dz/dP, solved with its Newton matrix: one more factorization per level; "
                              "halved while it would make bodies overlap or invert an element); hybrid's attempt always "
                              "starts from the tangent",
                              "", predictor_names, 2, predictor_names[predictor_choice], &predictor_choice, nullptr));
  PetscCall(PetscOptionsInt("-ptc_easy_its", "pseudo-transient continuation: grow the move by 1.25 after an inner solve of at most this many Newton iterations (by 4 after every step once the largest force passes the level tolerance, up to half the least move that failed since)",
                            "", ptc_easy_its, &ptc_easy_its, nullptr));
  PetscCall(PetscOptionsInt("-ptc_stall_its", "pseudo-transient continuation: an inner solve that has not reached its 100-fold residual drop after this many Newton iterations is cut short: its last iterate is the pseudo-time step if the residual decreased, else its iterate of least residual if that one is below the start's, else it is retried with more damping",
                            "", ptc_stall_its, &ptc_stall_its, nullptr));
  PetscCall(PetscOptionsBool("-ptc_anchor_forces",
                             "pseudo-transient continuation: anchor the forces of closed and sticking contacts as well as "
                             "the bodies (a compliance proportional to rho on their rows, gone at the accepted "
                             "equilibrium); false anchors the bodies only",
                             "", ptc_anchor_forces, &ptc_anchor_forces, nullptr));
  PetscCall(PetscOptionsInt("-ptc_max_steps", "pseudo-time steps per sub-step before it counts as failed (the load step is then cut)",
                            "", ptc_max_steps, &ptc_max_steps, nullptr));
  PetscCall(PetscOptionsReal("-level_force_rtol",
                             "accept a level by the paper's criterion besides exact equilibrium (0: only exact "
                             "equilibrium): every nodal force and every body's net force and torque below this x P <d> "
                             "(<d>^2), P_sigma/P within this of 1, every contact row exact, phi settled",
                             "", level_force_rtol, &level_force_rtol, nullptr));
  PetscCall(PetscOptionsReal("-level_phi_rtol", "... and the packing fraction changed by less than this (relative) in the last pseudo-time step",
                             "", level_phi_rtol, &level_phi_rtol, nullptr));
  PetscCall(PetscOptionsReal("-progress_interval",
                             "seconds between progress lines (pressure, pseudo-time step, Newton iterations, residual, "
                             "phi; in anchored also the contact rows, whether the contact states settled, and phi's change) while "
                             "a sub-step runs long; 0: after every pseudo-time step, negative: none",
                             "", progress_interval, &progress_interval, nullptr));
  PetscCall(PetscOptionsReal("-contact_margin", "contact candidates: gap below margin x mean diameter", "",
                             contact_margin, &contact_margin, nullptr));
  PetscCall(PetscOptionsEList("-contact_deformable",
                              "deformable pairs: nts (the higher-numbered disk's boundary nodes against the other's curve), "
                              "two_pass (node-to-segment both ways), mortar (each slave node's gap averaged over its cell "
                              "of the slave boundary, so the master cannot enter between slave nodes)",
                              "", deformable_names, 3, deformable_names[deformable_choice], &deformable_choice, nullptr));
  PetscCall(PetscOptionsReal("-repartition_tol",
                             "MPI: repartition (METIS) when the edge cut can shrink by this fraction or the load imbalance "
                             "exceeds 1 + this (< 0: keep the first partition)",
                             "", repartition_tol, &repartition_tol, nullptr));
  PetscCall(PetscOptionsBool("-partition_view", "MPI: print the edge cut and load imbalance of every partition", "",
                             partition_view, &partition_view, nullptr));
  PetscOptionsEnd();
  ncp = ncp_choice == 0 ? NcpFunction::Min : NcpFunction::FischerBurmeister;
  deformable_contact = static_cast<DeformableContact>(deformable_choice);
  predictor = static_cast<LoadPredictor>(predictor_choice);
  PetscCheck(young > 0.0, comm, PETSC_ERR_USER_INPUT, "-E %g: Young's modulus must be positive", young);
  PetscCheck(poisson > -1.0 && poisson < 0.5, comm, PETSC_ERR_USER_INPUT,
             "-nu %g: Poisson's ratio must satisfy -1 < nu < 0.5 (nu = 0.5 is incompressible, use e.g. 0.4999)",
             poisson);
  PetscCheck(friction >= 0.0 && std::isfinite(friction), comm, PETSC_ERR_USER_INPUT,
             "-friction %g: the friction coefficient must be >= 0 (the paper uses 0 to 0.8)", friction);
  PetscCheck(ncp_scale > 0.0, comm, PETSC_ERR_USER_INPUT, "-contact_ncp_scale %g must be positive", ncp_scale);
  PetscCheck(prox_eta >= 0.0, comm, PETSC_ERR_USER_INPUT, "-prox_eta %g must be >= 0", prox_eta);
  PetscCheck(ptc_move >= 0.0 && ptc_move <= 1.0, comm, PETSC_ERR_USER_INPUT, "-ptc_move %g must be in [0, 1]", ptc_move);
  PetscCheck(ptc_max_steps >= 1, comm, PETSC_ERR_USER_INPUT, "-ptc_max_steps %" PetscInt_FMT " must be >= 1", ptc_max_steps);
  PetscCheck(ptc_easy_its >= 0, comm, PETSC_ERR_USER_INPUT, "-ptc_easy_its %" PetscInt_FMT " must be >= 0", ptc_easy_its);
  PetscCheck(ptc_stall_its >= 1, comm, PETSC_ERR_USER_INPUT, "-ptc_stall_its %" PetscInt_FMT " must be >= 1", ptc_stall_its);
  PetscCheck(level_force_rtol >= 0.0 && level_force_rtol < 1.0, comm, PETSC_ERR_USER_INPUT,
             "-level_force_rtol %g must be in [0, 1)", level_force_rtol);
  PetscCheck(level_phi_rtol > 0.0, comm, PETSC_ERR_USER_INPUT, "-level_phi_rtol %g must be positive", level_phi_rtol);
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
  PetscCheck(rigid_.empty() || (p.friction > 0.0) == Frictional(), comm_, PETSC_ERR_ORDER,
             "set the friction before adding rigid bodies (it decides their rotation unknowns)");
  params_ = p;
  material_ = NeoHookean::from_young_poisson(p.young, p.poisson);
  torque_.assign(params_.constrain_rotation ? bodies_.size() : 0, 0.0);
  PetscCall(DestroySolver());
  PetscFunctionReturn(0);
}

static double MeanDiameter(const std::vector<DeformableBody> &d, const std::vector<RigidBody> &r) {
  double sum = 0.0;
  for (const auto &b : d) sum += 2.0 * b.mesh.radius;
  for (const auto &b : r) sum += 2.0 * b.radius;
  return (d.size() + r.size()) ? sum / (d.size() + r.size()) : 1.0;
}

int CompactionProblem::AddDeformableBody(const DiskMesh &mesh, double cx, double cy) {
  DeformableBody body;
  body.mesh = mesh;
  body.center[0] = cx;
  body.center[1] = cy;
  body.dof_offset = n_body_dofs_;
  body.particle = NumParticles();
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
  mean_diameter_ = deformix::MeanDiameter(bodies_, rigid_);
  torque_.assign(params_.constrain_rotation ? bodies_.size() : 0, 0.0);
  DestroySolver();
  return static_cast<int>(bodies_.size()) - 1;
}

int CompactionProblem::AddRigidBody(double cx, double cy, double radius) {
  RigidBody body;
  body.center[0] = cx;
  body.center[1] = cy;
  body.radius = radius;
  body.dof_offset = n_body_dofs_;
  body.particle = NumParticles();
  n_body_dofs_ += RigidDofs();
  u_.resize(n_body_dofs_, 0.0);
  rigid_.push_back(body);
  mean_diameter_ = deformix::MeanDiameter(bodies_, rigid_);
  DestroySolver();
  return static_cast<int>(rigid_.size()) - 1;
}

void CompactionProblem::SetWalls(const double w[4]) { std::copy(w, w + 4, w_); }

int CompactionProblem::SlaveParticle(const ContactCandidate &c) const {
  const bool rigid_slave = c.type == ContactType::RigidWall || c.type == ContactType::RigidRigid;
  return rigid_slave ? rigid_[c.body].particle : bodies_[c.body].particle;
}

int CompactionProblem::MasterParticle(const ContactCandidate &c) const {
  if (c.type == ContactType::RigidRigid || c.type == ContactType::RigidNode) return rigid_[c.master].particle;
  if (c.type == ContactType::NodeSegment) return bodies_[c.master].particle;
  return -1;  // a wall
}

// METIS partition of the particle graph (partition.hpp): a vertex per
// particle weighted by its unknowns (body, gauge, and the multipliers of the
// contacts it is the slave of, which its rank owns), an edge per candidate
// between two particles. Computed on rank 0 and broadcast.
PetscErrorCode CompactionProblem::UpdatePartition() {
  PetscFunctionBeginUser;
  partition_adopted_ = false;
  if (size_ == 1) {
    particle_owner_.clear();
    PetscFunctionReturn(0);
  }
  const int np = NumParticles();
  ParticleGraph graph;
  graph.vertex_weight.assign(np, 0);
  for (const DeformableBody &b : bodies_)
    graph.vertex_weight[b.particle] += 2 * b.mesh.num_nodes() + 3 + (torque_.empty() ? 0 : 1);  // nodes, rigid modes, gauge
  for (const RigidBody &r : rigid_) graph.vertex_weight[r.particle] += RigidDofs();
  for (const ContactCandidate &c : candidates_) {
    const int slave = SlaveParticle(c), master = MasterParticle(c);
    graph.vertex_weight[slave] += HasTangential(c) ? 2 : 1;
    if (master >= 0) graph.edges.emplace_back(master, slave);
  }
  int adopt = 0;
  std::vector<int> owner(np, 0);
  std::string error;
  if (rank_ == 0) {
    try {
      Partition fresh = partition_particles(graph, size_, 1);
      if (particle_owner_.empty()) {
        adopt = 1;
      } else if (params_.repartition_tol >= 0.0) {
        Partition current;
        current.parts = size_;
        current.owner = particle_owner_;
        evaluate_partition(graph, &current);
        const double tol = params_.repartition_tol;
        adopt = (fresh.edge_cut < (1.0 - tol) * current.edge_cut && fresh.imbalance <= std::max(current.imbalance, 1.0 + tol)) ||
                (current.imbalance > 1.0 + tol && fresh.imbalance < current.imbalance);
      }
      if (adopt) {
        owner = fresh.owner;
        if (params_.partition_view)
          PetscCall(PetscPrintf(PETSC_COMM_SELF,
                                "  partition: %d particles on %d ranks, %zu candidate edges, edge cut %ld, load imbalance %.3f%s\n",
                                np, size_, graph.edges.size(), fresh.edge_cut, fresh.imbalance,
                                particle_owner_.empty() ? "" : " (repartitioned)"));
      }
    } catch (const std::exception &e) {
      error = e.what();
      adopt = -1;
    }
  }
  PetscCallMPI(MPI_Bcast(&adopt, 1, MPI_INT, 0, comm_));
  partition_adopted_ = adopt > 0;
  PetscCheck(adopt >= 0, comm_, PETSC_ERR_LIB, "partitioning the particles failed: %s", error.c_str());
  if (adopt) {
    PetscCallMPI(MPI_Bcast(owner.data(), np, MPI_INT, 0, comm_));
    particle_owner_ = owner;
  }
  PetscFunctionReturn(0);
}

int CompactionProblem::AddPacking(const DiskPacking &packing, const DiskMesh &unit_mesh) {
  int n_deformable = 0;
  for (int i = 0; i < packing.size(); ++i) {
    if (packing.deformable[i]) {
      DiskMesh mesh = unit_mesh;
      mesh.radius = packing.radius[i];
      for (double &x : mesh.X) x *= packing.radius[i];
      AddDeformableBody(mesh, packing.x[i], packing.y[i]);
      ++n_deformable;
    } else {
      AddRigidBody(packing.x[i], packing.y[i], packing.radius[i]);
    }
  }
  SetWalls(packing.walls);
  return n_deformable;
}

void CompactionProblem::NodePosition(int b, int a, double x[2]) const {
  const DeformableBody &body = bodies_[b];
  const PetscInt d = body.dof_offset + 2 * a;
  x[0] = body.center[0] + body.mesh.X[2 * a] + u_[d];
  x[1] = body.center[1] + body.mesh.X[2 * a + 1] + u_[d + 1];
}

void CompactionProblem::RigidPosition(int r, double x[2], double *theta) const {
  const RigidBody &body = rigid_[r];
  x[0] = body.center[0] + u_[body.dof_offset];
  x[1] = body.center[1] + u_[body.dof_offset + 1];
  if (theta) *theta = Frictional() ? u_[body.dof_offset + 2] : 0.0;
}

void CompactionProblem::BodyCentroid(int b, double x[2]) const {
  const int nn = bodies_[b].mesh.num_nodes();
  x[0] = x[1] = 0.0;
  for (int a = 0; a < nn; ++a) {
    double xa[2];
    NodePosition(b, a, xa);
    x[0] += xa[0] / nn, x[1] += xa[1] / nn;
  }
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
// State packing, in the global unknown order.
void CompactionProblem::Pack(double *z) const {
  std::copy(u_.begin(), u_.end(), z);
  std::copy(w_, w_ + 4, z + WallOffset());
  std::copy(torque_.begin(), torque_.end(), z + GaugeOffset());
  std::copy(mode_.begin(), mode_.end(), z + ModeOffset());
  std::copy(lambda_.begin(), lambda_.end(), z + MultiplierOffset());
  for (size_t c = 0; c < candidates_.size(); ++c)
    if (tangential_index_[c] >= 0) z[tangential_index_[c]] = lambda_t_[c];
}

void CompactionProblem::Unpack(const double *z) {
  std::copy(z, z + n_body_dofs_, u_.begin());
  std::copy(z + WallOffset(), z + WallOffset() + 4, w_);
  std::copy(z + GaugeOffset(), z + ModeOffset(), torque_.begin());
  std::copy(z + ModeOffset(), z + MultiplierOffset(), mode_.begin());
  std::copy(z + MultiplierOffset(), z + MultiplierOffset() + lambda_.size(), lambda_.begin());
  for (size_t c = 0; c < candidates_.size(); ++c)
    lambda_t_[c] = tangential_index_[c] >= 0 ? z[tangential_index_[c]] : 0.0;
}

CompactionProblem::State CompactionProblem::SaveState() const {
  State s;
  s.u = u_;
  std::copy(w_, w_ + 4, s.w);
  s.lambda = lambda_;
  s.lambda_t = lambda_t_;
  s.torque = torque_;
  s.candidates = candidates_;
  return s;
}

void CompactionProblem::RestoreState(const State &s) {
  u_ = s.u;
  std::copy(s.w, s.w + 4, w_);
  bool same = s.candidates.size() == candidates_.size();
  for (size_t c = 0; same && c < candidates_.size(); ++c)
    same = CandidateKey(s.candidates[c]) == CandidateKey(candidates_[c]) && s.candidates[c].segment == candidates_[c].segment;
  if (!same) DestroySolver();
  candidates_ = s.candidates;
  lambda_ = s.lambda;
  lambda_t_ = s.lambda_t;
  torque_ = s.torque;
}

CompactionProblem::Snapshot CompactionProblem::TakeSnapshot() const {
  Snapshot s;
  s.current = SaveState();
  s.pressure = pressure_;
  s.have_previous = have_previous_;
  return s;
}

PetscErrorCode CompactionProblem::RestoreSnapshot(const Snapshot &s) {
  PetscFunctionBeginUser;
  const State &st = s.current;
  PetscCheck(st.u.size() == u_.size() && st.torque.size() == torque_.size(), comm_, PETSC_ERR_FILE_UNEXPECTED,
             "the saved state has %zu body unknowns and %zu rotation gauges, this scene %zu and %zu", st.u.size(),
             st.torque.size(), u_.size(), torque_.size());
  PetscCheck(st.lambda.size() == st.candidates.size() && st.lambda_t.size() == st.candidates.size(), comm_,
             PETSC_ERR_FILE_UNEXPECTED, "the saved state has %zu candidates but %zu / %zu multipliers",
             st.candidates.size(), st.lambda.size(), st.lambda_t.size());
  const int n_def = static_cast<int>(bodies_.size()), n_rigid = static_cast<int>(rigid_.size());
  for (const ContactCandidate &c : st.candidates) {
    const bool rigid_slave = c.type == ContactType::RigidWall || c.type == ContactType::RigidRigid;
    const int n_slaves = rigid_slave ? n_rigid : n_def;
    bool ok = c.body >= 0 && c.body < n_slaves && static_cast<int>(c.type) >= 0 && static_cast<int>(c.type) <= 4;
    if (ok && !rigid_slave) ok = c.point >= 0 && c.point < static_cast<int>(bodies_[c.body].mesh.boundary.size());
    if (ok && (c.type == ContactType::RigidRigid || c.type == ContactType::RigidNode)) ok = c.master >= 0 && c.master < n_rigid;
    if (ok && (c.type == ContactType::PointWall || c.type == ContactType::RigidWall))
      ok = static_cast<int>(c.wall) >= 0 && static_cast<int>(c.wall) < 4;
    if (ok && c.type == ContactType::NodeSegment)
      ok = c.master >= 0 && c.master < n_def && c.segment >= 0 &&
           c.segment < static_cast<int>(bodies_[c.master].mesh.boundary.size());
    PetscCheck(ok, comm_, PETSC_ERR_FILE_UNEXPECTED,
               "the saved state has a contact candidate (type %d, body %d, point %d, master %d) that does not exist in this scene",
               static_cast<int>(c.type), c.body, c.point, c.master);
  }
  RestoreState(s.current);
  PetscCall(DestroySolver());
  have_previous_ = s.have_previous;
  pressure_ = s.pressure;
  u_start_ = u_;
  // The operator of the restored state, which an uninterrupted run holds from
  // the level before: the next load step's first Newton matrix (the tangent
  // predictor's) then costs no new layout in either run.
  Vec z, F;
  Mat J;
  KSP ksp;
  PetscCall(Layout(&z, &F, &J, &ksp));
  PetscFunctionReturn(0);
}

// ---------------------------------------------------------------------------
DetectionScene CompactionProblem::DetectionView() const {
  DetectionScene scene;
  for (int b = 0; b < static_cast<int>(bodies_.size()); ++b) {
    const DiskMesh &m = bodies_[b].mesh;
    DetectionScene::Deformable d;
    d.particle = bodies_[b].particle, d.owner = ParticleOwner(d.particle);
    d.boundary.resize(2 * m.boundary.size());
    d.points.resize(2 * m.boundary.size());
    for (size_t i = 0; i < m.boundary.size(); ++i) {
      NodePosition(b, m.boundary[i], &d.boundary[2 * i]);
      BoundaryPointPosition(b, static_cast<int>(i), &d.points[2 * i]);
    }
    scene.deformable.push_back(std::move(d));
  }
  for (int r = 0; r < static_cast<int>(rigid_.size()); ++r) {
    DetectionScene::Rigid rb;
    rb.particle = rigid_[r].particle, rb.owner = ParticleOwner(rb.particle), rb.radius = rigid_[r].radius;
    RigidPosition(r, rb.centre, nullptr);
    scene.rigid.push_back(rb);
  }
  std::copy(w_, w_ + 4, scene.walls);
  scene.two_pass = params_.deformable_contact == DeformableContact::TwoPass;
  return scene;
}

std::vector<ContactCandidate> CompactionProblem::DetectOwnCandidates(double margin) const {
  return deformix::DetectOwnCandidates(DetectionView(), margin * mean_diameter_, rank_);
}

std::vector<ContactCandidate> CompactionProblem::DetectCandidates(double margin) const {
  return GatherCandidates(comm_, DetectOwnCandidates(margin));
}

PetscErrorCode CompactionProblem::RefreshCandidates() {
  PetscFunctionBeginUser;
  PetscCall(PetscLogEventBegin(event_detect, 0, 0, 0, 0));
  std::map<std::tuple<int, int, int, int, int>, std::pair<double, double>> old;
  for (size_t c = 0; c < candidates_.size(); ++c) old[CandidateKey(candidates_[c])] = {lambda_[c], lambda_t_[c]};
  std::vector<ContactCandidate> fresh = DetectCandidates(params_.contact_margin);
  // A candidate that still carries force stays, whatever its gap.
  std::map<std::tuple<int, int, int, int, int>, int> fresh_keys;
  for (size_t c = 0; c < fresh.size(); ++c) fresh_keys[CandidateKey(fresh[c])] = static_cast<int>(c);
  for (size_t c = 0; c < candidates_.size(); ++c)
    if (lambda_[c] > 0.0 && !fresh_keys.count(CandidateKey(candidates_[c]))) fresh.push_back(candidates_[c]);
  std::sort(fresh.begin(), fresh.end(), [](const ContactCandidate &a, const ContactCandidate &b) {
    return CandidateKey(a) < CandidateKey(b);
  });
  bool same = fresh.size() == candidates_.size();
  for (size_t c = 0; same && c < fresh.size(); ++c)
    same = CandidateKey(fresh[c]) == CandidateKey(candidates_[c]) && fresh[c].segment == candidates_[c].segment;
  if (!same) {
    std::vector<double> lam(fresh.size(), 0.0), lam_t(fresh.size(), 0.0);
    for (size_t c = 0; c < fresh.size(); ++c) {
      auto it = old.find(CandidateKey(fresh[c]));
      if (it != old.end()) lam[c] = it->second.first, lam_t[c] = it->second.second;
    }
    candidates_ = std::move(fresh);
    lambda_ = std::move(lam);
    lambda_t_ = std::move(lam_t);
    PetscCall(DestroySolver());
  }
  PetscCall(PetscLogEventEnd(event_detect, 0, 0, 0, 0));
  PetscFunctionReturn(0);
}

// ---------------------------------------------------------------------------
// One walk over elements, walls and contacts serves the residual, the
// Jacobian's sparsity pattern and its values, so the three can never
// disagree: every entry is emitted whatever the state (zeros included).
PetscErrorCode CompactionProblem::Assemble(const double *z, double *F, std::vector<PetscInt> *ci,
                                           std::vector<PetscInt> *cj, std::vector<PetscScalar> *cv,
                                           bool *inverted, std::vector<char> *active) {
  const bool pattern = ci != nullptr;
  const bool values = cv != nullptr;
  const bool need_K = pattern || values;
  const PetscInt wall_off = WallOffset(), rot_off = GaugeOffset();
  // Entries in natural numbering; the pattern is stored in PETSc numbering.
  auto entry = [&](PetscInt i, PetscInt j, double v) {
    if (i < 0 || j < 0) return;
    if (pattern) ci->push_back(petsc_of_[i]), cj->push_back(petsc_of_[j]);
    if (values) cv->push_back(v);
  };
  PetscFunctionBeginUser;
  if (inverted) *inverted = false;
  if (F) merit_local_ = 0.0;
  if (active) {
    active->assign(candidates_.size(), kOpen);
    switch_margin_.assign(2 * candidates_.size(), 0.0);
    gap_bound_.assign(2 * candidates_.size(), 0.0);
    slip_now_.assign(candidates_.size(), 0.0);
  }
  // Each rank assembles what it owns: the elements of its deformable disks,
  // the walls' load (rank 0), the proximal terms of its unknowns, the gauges
  // of its disks and its contacts (those whose slave it owns).
  // The pattern walk has no state: it uses the reference configuration.
  std::vector<double> zero;
  if (pattern) zero.assign(n_total_, 0.0), z = zero.data();

  // Deformable bodies: hyperelastic elements.
  std::vector<double> Xe, xe, fe, Ke;
  std::vector<PetscInt> dofs;
  for (const DeformableBody &body : bodies_) {
    if (ParticleOwner(body.particle) != rank_) continue;
    const DiskMesh &m = body.mesh;
    const int nen = m.nodes_per_cell(), nd = 2 * nen;
    Xe.resize(nd), xe.resize(nd), fe.resize(nd), Ke.resize(nd * nd), dofs.resize(nd);
    for (int e = 0; e < m.num_cells(); ++e) {
      for (int a = 0; a < nen; ++a) {
        const int n = m.cells[e * nen + a];
        for (int i = 0; i < 2; ++i) {
          dofs[2 * a + i] = body.dof_offset + 2 * n + i;
          Xe[2 * a + i] = m.X[2 * n + i];
          xe[2 * a + i] = m.X[2 * n + i] + z[dofs[2 * a + i]];
        }
      }
      if (pattern) {
        for (int p = 0; p < nd; ++p)
          for (int q = 0; q < nd; ++q) entry(dofs[p], dofs[q], 0.0);
        continue;
      }
      const ElementResult r =
          triangle_element(material_, m.order, Xe.data(), xe.data(), F ? fe.data() : nullptr, need_K ? Ke.data() : nullptr);
      if (F) merit_local_ += r.energy;
      if (r.inverted) {
        if (inverted) *inverted = true;
        merit_local_ = INFINITY;
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

  // Walls: the pressure load P * box area.
  const double *w = z + wall_off;
  if (F && rank_ == 0) {
    double g[4];
    WallBox::pressure_gradient(pressure_, w, g);
    for (int i = 0; i < 4; ++i) F[wall_off + i] += g[i];
    merit_local_ += pressure_ * WallBox::area(w);
  }
  if (need_K && rank_ == 0) {
    double H[16];
    WallBox::pressure_hessian(pressure_, H);
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) entry(wall_off + i, wall_off + j, H[4 * i + j]);
  }

  // Proximal terms on body and wall unknowns, weighted by D (r^2 on rigid
  // rotations, which are angles): rho D on the Newton matrix only, and
  // rho_a D (z - z_a) on both the residual and the matrix (pseudo-transient
  // continuation towards equilibrium: SetAnchor, level_solver.hpp).
  if (need_K || (F && rho_anchor_ > 0.0)) {
    const std::vector<double> &weight = prox_weight_;
    const double rho = params_.prox_eta * params_.young;
    if (F && rho_anchor_ > 0.0)
      for (PetscInt i = 0; i < rot_off; ++i)
        if (OwnsNatural(i)) F[i] += rho_anchor_ * weight[i] * (z[i] - anchor_[i]);
    if (need_K)
      for (PetscInt i = 0; i < rot_off; ++i)
        if (OwnsNatural(i)) entry(i, i, (rho + rho_anchor_) * weight[i]);
  }

  // Rigid modes of the deformable bodies under the anchor. rho_a D (z - z_a)
  // alone holds a deformable disk's rigid translation by rho_a per node, n
  // times a rigid disk's (n nodes), so that a body whose nodal forces are
  // small but add up to a large net force creeps. With the auxiliary
  // unknowns s = (t, theta) of each deformable body the anchor is
  //   (rho_a / 2) sum_i |du_i - t - theta X_i^perp|^2 + (rho_a / 2)(|t|^2 + r^2 theta^2),
  // du = z - z_a, minimized over s with the rest: deformation (du with no
  // rigid part) is held by rho_a per node as before, a rigid translation or
  // rotation of the body by rho_a n / (n + 1) and about rho_a r^2 in all, as
  // a rigid disk's (docs/level-solver-measurements.md, "Measured: the rigid
  // modes of deformable disks under the anchor"). Without the anchor the
  // rows are E s = 0. The pattern is the same either way.
  {
    const PetscInt mode_off = ModeOffset();
    const double a = rho_anchor_, idle = a > 0.0 ? 0.0 : params_.young;
    const bool walk_nodes = need_K || (F && a > 0.0);  // an unanchored residual adds nothing on the nodes
    for (size_t b = 0; b < bodies_.size(); ++b) {
      const DeformableBody &body = bodies_[b];
      if (ParticleOwner(body.particle) != rank_) continue;
      const int nn = body.mesh.num_nodes();
      const PetscInt m0 = mode_off + 3 * static_cast<PetscInt>(b);
      const double r = body.mesh.radius;
      const double t[2] = {z ? z[m0] : 0.0, z ? z[m0 + 1] : 0.0}, th = z ? z[m0 + 2] : 0.0;
      double sx = 0.0, sy = 0.0, sxx = 0.0, g[3] = {0.0, 0.0, 0.0};
      for (int n = 0; walk_nodes && n < nn; ++n) {
        const PetscInt d = body.dof_offset + 2 * n;
        const double P[2] = {-body.mesh.X[2 * n + 1], body.mesh.X[2 * n]};
        sx += P[0], sy += P[1], sxx += P[0] * P[0] + P[1] * P[1];
        for (int i = 0; i < 2; ++i) {
          if (F && a > 0.0) {
            const double e = z[d + i] - anchor_[d + i] - t[i] - th * P[i];
            F[d + i] -= a * (t[i] + th * P[i]);  // the a * du part is the proximal loop's
            g[i] -= a * e, g[2] -= a * P[i] * e;
          }
          if (need_K) entry(d + i, m0 + i, -a), entry(m0 + i, d + i, -a), entry(d + i, m0 + 2, -a * P[i]), entry(m0 + 2, d + i, -a * P[i]);
        }
      }
      if (F) {
        F[m0] += g[0] + (a + idle) * t[0], F[m0 + 1] += g[1] + (a + idle) * t[1], F[m0 + 2] += g[2] + (a * r * r + idle) * th;
      }
      if (need_K) {
        entry(m0, m0, a * nn + a + idle), entry(m0 + 1, m0 + 1, a * nn + a + idle), entry(m0 + 2, m0 + 2, a * sxx + a * r * r + idle);
        entry(m0, m0 + 2, a * sx), entry(m0 + 2, m0, a * sx), entry(m0 + 1, m0 + 2, a * sy), entry(m0 + 2, m0 + 1, a * sy);
      }
    }
  }

  // Rotation gauge of frictionless bodies: c_b(u) = G_b . u = mean of X x u = 0,
  // with multiplier mu_b (a torque): R_u -= mu_b G_b, R_mu = (E / R_b) c_b.
  // While friction acts (a frictional problem with friction switched on) the
  // rotation is physical: the gauge is released, R_mu = (E / R_b) mu_b, with
  // the same sparsity pattern.
  const bool gauge_on = !FrictionActive();
  for (size_t b = 0; b < torque_.size(); ++b) {
    const DeformableBody &body = bodies_[b];
    if (ParticleOwner(body.particle) != rank_) continue;
    const int nn = body.mesh.num_nodes();
    const PetscInt mu_dof = rot_off + static_cast<PetscInt>(b);
    const double mu = z[mu_dof], row_scale = params_.young / body.mesh.radius;
    double c = 0.0;
    for (int a = 0; a < nn; ++a) {
      const PetscInt d = body.dof_offset + 2 * a;
      const double G[2] = {-body.mesh.X[2 * a + 1] / nn, body.mesh.X[2 * a] / nn};
      for (int i = 0; i < 2; ++i) {
        c += G[i] * z[d + i];
        if (F && gauge_on) F[d + i] -= mu * G[i];
        if (need_K) entry(d + i, mu_dof, gauge_on ? -G[i] : 0.0), entry(mu_dof, d + i, gauge_on ? row_scale * G[i] : 0.0);
      }
    }
    if (F) F[mu_dof] += row_scale * (gauge_on ? c : mu);
    if (need_K) entry(mu_dof, mu_dof, gauge_on ? 0.0 : row_scale);
  }

  PetscCall(AssembleContacts(z, F, ci, cj, cv, active));
  PetscFunctionReturn(0);
}

// ---------------------------------------------------------------------------
// Residual and Jacobian on the distributed layout (own + ghost unknowns gathered).
PetscErrorCode CompactionProblem::Gather(Vec z, bool full) {
  PetscFunctionBeginUser;
  VecScatter sc = full ? to_all_ : to_local_;
  PetscCall(VecScatterBegin(sc, z, zall_, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(sc, z, zall_, INSERT_VALUES, SCATTER_FORWARD));
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::FormResidual(Vec z, Vec F) {
  const PetscScalar *za;
  PetscScalar *fa;
  bool inverted = false;
  PetscFunctionBeginUser;
  PetscCall(PetscLogEventBegin(event_residual, 0, 0, 0, 0));
  PetscCall(Gather(z, false));
  PetscCall(VecGetArrayRead(zall_, &za));
  PetscCall(VecSet(fall_, 0.0));
  PetscCall(VecGetArray(fall_, &fa));
  PetscCall(Assemble(za, fa, nullptr, nullptr, nullptr, &inverted, &active_now_));
  PetscCall(VecRestoreArray(fall_, &fa));
  PetscCall(VecRestoreArrayRead(zall_, &za));
  // Sum every rank's contributions (natural order) into the distributed residual.
  PetscCall(VecSet(F, 0.0));
  PetscCall(VecScatterBegin(to_local_, fall_, F, ADD_VALUES, SCATTER_REVERSE));
  PetscCall(VecScatterEnd(to_local_, fall_, F, ADD_VALUES, SCATTER_REVERSE));
  // Contact states: each rank set those of its contacts (others are kOpen = 0).
  if (size_ > 1 && !active_now_.empty())
    PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, active_now_.data(), static_cast<int>(active_now_.size()), MPI_CHAR,
                               MPI_MAX, comm_));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &inverted, 1, MPI_C_BOOL, MPI_LOR, comm_));
  inverted_ = inverted;
  PetscCallMPI(MPI_Allreduce(&merit_local_, &merit_, 1, MPI_DOUBLE, MPI_SUM, comm_));
  PetscCall(PetscLogEventEnd(event_residual, 0, 0, 0, 0));
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::FormJacobian(Vec z, Mat J) {
  const PetscScalar *za;
  PetscFunctionBeginUser;
  PetscCall(PetscLogEventBegin(event_jacobian, 0, 0, 0, 0));
  PetscCall(Gather(z, false));
  PetscCall(VecGetArrayRead(zall_, &za));
  coo_values_.clear();
  PetscCall(Assemble(za, nullptr, nullptr, nullptr, &coo_values_, nullptr, nullptr));
  PetscCall(VecRestoreArrayRead(zall_, &za));
  PetscCall(MatSetValuesCOO(J, coo_values_.data(), INSERT_VALUES));
  PetscCall(PetscLogEventEnd(event_jacobian, 0, 0, 0, 0));
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::PrintChangedContacts(const std::vector<char> &before) const {
  const PetscScalar *za;
  PetscFunctionBeginUser;
  PetscCall(VecGetArrayRead(zall_, &za));
  if (before.size() == active_now_.size())
    for (size_t c = 0; c < candidates_.size(); ++c) {
      const ContactCandidate &cc = candidates_[c];
      if (before[c] == active_now_[c] || CandidateOwner(cc) != rank_) continue;
      LocalContact lc;
      ContactGeometry(cc, za, &lc);
      const PetscInt lt = tangential_index_[c];
      static const char *const names[] = {"open", "closed", "sliding"};
      PetscCall(PetscSynchronizedPrintf(comm_,
                                        "      contact %zu (type %d, slave %d point %d, master %d): %s -> %s  lambda_n %.3e  gap %.3e  lambda_t %.3e  slip %.3e\n",
                                        c, (int)cc.type, cc.body, cc.point, cc.master, names[(int)before[c]],
                                        names[(int)active_now_[c]], za[MultiplierOffset() + c], lc.k.gap,
                                        lt >= 0 ? za[lt] : 0.0, lc.k.slip));
    }
  PetscCall(PetscSynchronizedFlush(comm_, PETSC_STDOUT));
  PetscCall(VecRestoreArrayRead(zall_, &za));
  PetscFunctionReturn(0);
}

std::string CompactionProblem::DescribeUnknown(PetscInt where) const {
  if (where < 0) return "nothing";
  if (where >= TangentialOffset()) return "lambda_t";
  if (where >= MultiplierOffset()) return "lambda_n";
  if (where >= ModeOffset())
    return "rigid mode (anchor) of deformable particle " + std::to_string(bodies_[(where - ModeOffset()) / 3].particle);
  if (where >= GaugeOffset()) return "gauge";
  for (const DeformableBody &b : bodies_)
    if (where >= b.dof_offset && where < b.dof_offset + 2 * b.mesh.num_nodes())
      return "deformable particle " + std::to_string(b.particle) + " node " + std::to_string((where - b.dof_offset) / 2);
  for (const RigidBody &r : rigid_)
    if (where >= r.dof_offset && where < r.dof_offset + RigidDofs())
      return "rigid particle " + std::to_string(r.particle) + " dof " + std::to_string(where - r.dof_offset);
  return "wall";
}

void CompactionProblem::SetAnchor(double rho, bool forces) {
  rho_anchor_ = rho;
  std::fill(mode_.begin(), mode_.end(), 0.0);
  lambda_anchor_.clear();
  lambda_t_anchor_.clear();
  if (rho > 0.0) {
    anchor_.assign(u_.begin(), u_.end());
    anchor_.insert(anchor_.end(), w_, w_ + 4);
    if (forces) lambda_anchor_ = lambda_, lambda_t_anchor_ = lambda_t_;
  }
}

// Contacts that the linearized update dz would drive deeper than allow =
// kOpenOvershoot <d> into penetration (an overshoot of the Newton model,
// which has them open): the fraction of dz after which they reach -allow,
// never below 1/10. Every contact not yet beyond -allow counts, touching ones
// (gap at round-off of 0, as every closed contact of a settled state is)
// included: a cut for gap > 0 only would jump from allow / |dg| to none as
// the round-off of such a gap changes sign, and make the path depend on the
// number of ranks and on the BLAS. Only a contact with
// gap + allow < sum_a |dgap_a| |dz_a| can reach -allow; the last residual left
// gap and sum_a |dgap_a| in gap_bound_, so the others are skipped without
// evaluating their geometry (which costs as much as a residual at 1500
// disks). The skip is exact. Collective.
PetscErrorCode CompactionProblem::ContactStepFraction(Vec dz, double *fraction) {
  const PetscScalar *ya;
  PetscInt lo, hi;
  PetscFunctionBeginUser;
  {
    double ymax = 0.0;  // largest body or wall component of the step
    PetscCall(VecGetOwnershipRange(dz, &lo, &hi));
    PetscCall(VecGetArrayRead(dz, &ya));
    for (PetscInt i = lo; i < hi; ++i)
      if (natural_of_[i] < GaugeOffset()) ymax = std::max(ymax, std::abs(ya[i - lo]));
    PetscCall(VecRestoreArrayRead(dz, &ya));
    PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &ymax, 1, MPI_DOUBLE, MPI_MAX, comm_));
    const bool bounds = gap_bound_.size() == 2 * candidates_.size();
    Vec yall = yall_;
    const PetscScalar *xa, *yv;
    PetscCall(VecScatterBegin(to_local_, dz, yall, INSERT_VALUES, SCATTER_FORWARD));
    PetscCall(VecScatterEnd(to_local_, dz, yall, INSERT_VALUES, SCATTER_FORWARD));
    PetscCall(VecGetArrayRead(zall_, &xa));  // the current iterate (gathered by the last residual)
    PetscCall(VecGetArrayRead(yall, &yv));
    const double allow = kOpenOvershoot * mean_diameter_;
    double alpha = 1.0;
    for (size_t ci = 0; ci < candidates_.size(); ++ci) {
      const ContactCandidate &c = candidates_[ci];
      if (CandidateOwner(c) != rank_) continue;
      if (bounds && (gap_bound_[2 * ci] <= -allow ||
                     gap_bound_[2 * ci] + allow > (1.0 + 1e-8) * gap_bound_[2 * ci + 1] * ymax))
        continue;
      CompactionProblem::LocalContact lc;
      ContactGeometry(c, xa, &lc);
      if (lc.k.gap <= -allow) continue;
      double dg = 0.0;
      for (int a = 0; a < lc.k.ndof; ++a)
        if (lc.dofs[a] >= 0) dg += lc.k.dgap[a] * yv[lc.dofs[a]];
      if (lc.k.gap + dg < -allow) alpha = std::min(alpha, (lc.k.gap + allow) / -dg);
    }
    PetscCall(VecRestoreArrayRead(yall, &yv));
    PetscCall(VecRestoreArrayRead(zall_, &xa));
    PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &alpha, 1, MPI_DOUBLE, MPI_MIN, comm_));
    *fraction = std::max(alpha, 0.1);
  }
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::DestroySolver() {
  PetscFunctionBeginUser;
  PetscCall(KSPDestroy(&ksp_));
  PetscCall(KSPDestroy(&ksp_ldlt_));
  PetscCall(MatDestroy(&J_unsymmetric_));
  for (Vec *v : {&sym_scale_, &sym_pivot_, &sym_keep_, &sym_work_}) PetscCall(VecDestroy(v));
  PetscCall(MatDestroy(&J_));
  PetscCall(VecDestroy(&z_));
  PetscCall(VecDestroy(&r_));
  PetscCall(VecDestroy(&zall_));
  PetscCall(VecDestroy(&yall_));
  PetscCall(VecDestroy(&fall_));
  PetscCall(VecScatterDestroy(&to_all_));
  PetscCall(VecScatterDestroy(&to_local_));
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
  std::vector<double> full(n_total_);
  Pack(full.data());
  PetscCall(VecGetArray(z, &za));
  for (PetscInt i = own_lo_; i < own_hi_; ++i) za[i - own_lo_] = full[natural_of_[i]];
  PetscCall(VecRestoreArray(z, &za));
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::SetUpLayout() {
  PetscFunctionBeginUser;
  PetscCall(DestroySolver());
  lambda_.resize(candidates_.size(), 0.0);
  lambda_t_.resize(candidates_.size(), 0.0);
  tangential_index_.assign(candidates_.size(), -1);
  PetscInt next = TangentialOffset();
  for (size_t c = 0; c < candidates_.size(); ++c)
    if (HasTangential(candidates_[c])) tangential_index_[c] = next++;
  if (u_start_.size() != u_.size()) u_start_ = u_;
  mode_.assign(3 * bodies_.size(), 0.0);
  // Weights D of the proximal terms: 1, and r^2 on rigid rotations (angles).
  prox_weight_.assign(GaugeOffset(), 1.0);
  if (Frictional())
    for (const RigidBody &r : rigid_) prox_weight_[r.dof_offset + 2] = r.radius * r.radius;
  n_total_ = next;
  // Owner of every natural unknown (walls: rank 0), then the PETSc numbering:
  // rank by rank, natural order inside each rank.
  PetscCall(UpdatePartition());
  std::vector<int> owner(n_total_, 0);
  for (const DeformableBody &b : bodies_)
    std::fill_n(owner.begin() + b.dof_offset, 2 * b.mesh.num_nodes(), ParticleOwner(b.particle));
  for (const RigidBody &r : rigid_) std::fill_n(owner.begin() + r.dof_offset, RigidDofs(), ParticleOwner(r.particle));
  for (size_t b = 0; b < torque_.size(); ++b) owner[GaugeOffset() + b] = BodyOwner(static_cast<int>(b));
  for (size_t b = 0; b < bodies_.size(); ++b) std::fill_n(owner.begin() + ModeOffset() + 3 * b, 3, BodyOwner(static_cast<int>(b)));
  for (size_t c = 0; c < candidates_.size(); ++c) {
    const int o = CandidateOwner(candidates_[c]);
    owner[MultiplierOffset() + c] = o;
    if (tangential_index_[c] >= 0) owner[tangential_index_[c]] = o;
  }
  std::vector<PetscInt> first(size_ + 1, 0);
  for (int o : owner) ++first[o + 1];
  for (int r = 0; r < size_; ++r) first[r + 1] += first[r];
  own_lo_ = first[rank_], own_hi_ = first[rank_ + 1];
  petsc_of_.resize(n_total_);
  natural_of_.resize(n_total_);
  for (PetscInt i = 0; i < n_total_; ++i) {
    petsc_of_[i] = first[owner[i]]++;
    natural_of_[petsc_of_[i]] = i;
  }
  const PetscInt n_local = own_hi_ - own_lo_;
  PetscCall(VecCreateMPI(comm_, n_local, n_total_, &z_));
  PetscCall(VecDuplicate(z_, &r_));
  // Replicated copy in natural order, zall_[i] = z[petsc_of_[i]] (the reverse
  // scatter adds fall_ into a distributed residual).
  PetscCall(VecCreateSeq(PETSC_COMM_SELF, n_total_, &zall_));
  PetscCall(VecDuplicate(zall_, &yall_));
  PetscCall(VecDuplicate(zall_, &fall_));
  {
    IS from, to;
    PetscCall(ISCreateGeneral(PETSC_COMM_SELF, n_total_, petsc_of_.data(), PETSC_COPY_VALUES, &from));
    PetscCall(ISCreateStride(PETSC_COMM_SELF, n_total_, 0, 1, &to));
    PetscCall(VecScatterCreate(z_, from, zall_, to, &to_all_));
    PetscCall(ISDestroy(&from));
    PetscCall(ISDestroy(&to));
  }
  // What this rank's assembly reads and writes: its own unknowns, the walls
  // and the unknowns of the other bodies in its contacts (ghosts). Newton
  // iterations move only these; the whole state is gathered once per solve.
  {
    std::vector<char> need(n_total_, 0);
    for (PetscInt i = 0; i < n_total_; ++i) need[i] = owner[i] == rank_;
    for (int k = 0; k < 4; ++k) need[WallOffset() + k] = 1;
    std::vector<double> zero(n_total_, 0.0);
    LocalContact lc;
    for (const ContactCandidate &c : candidates_) {
      if (CandidateOwner(c) != rank_) continue;
      ContactGeometry(c, zero.data(), &lc);
      for (int a = 0; a < lc.k.ndof; ++a)
        if (lc.dofs[a] >= 0) need[lc.dofs[a]] = 1;
    }
    std::vector<PetscInt> from_idx, to_idx;
    for (PetscInt i = 0; i < n_total_; ++i)
      if (need[i]) from_idx.push_back(petsc_of_[i]), to_idx.push_back(i);
    n_ghost_ = static_cast<PetscInt>(from_idx.size()) - n_local;
    if (params_.partition_view && partition_adopted_) {
      // Communication per Newton iteration: the ghost unknowns each rank reads.
      PetscInt ghost[2] = {n_ghost_, -n_ghost_}, own[2] = {n_local, -n_local};
      PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, ghost, 2, MPIU_INT, MPI_MAX, comm_));
      PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, own, 2, MPIU_INT, MPI_MAX, comm_));
      PetscCall(PetscPrintf(comm_, "  partition: owned unknowns per rank %" PetscInt_FMT "..%" PetscInt_FMT
                                   ", ghost unknowns per rank %" PetscInt_FMT "..%" PetscInt_FMT "\n",
                            -own[1], own[0], -ghost[1], ghost[0]));
    }
    IS from, to;
    PetscCall(ISCreateGeneral(PETSC_COMM_SELF, static_cast<PetscInt>(from_idx.size()), from_idx.data(), PETSC_COPY_VALUES, &from));
    PetscCall(ISCreateGeneral(PETSC_COMM_SELF, static_cast<PetscInt>(to_idx.size()), to_idx.data(), PETSC_COPY_VALUES, &to));
    PetscCall(VecScatterCreate(z_, from, zall_, to, &to_local_));
    PetscCall(ISDestroy(&from));
    PetscCall(ISDestroy(&to));
  }

  std::vector<PetscInt> ci, cj;
  PetscCall(Assemble(nullptr, nullptr, &ci, &cj, nullptr, nullptr, nullptr));
  PetscCall(MatCreate(comm_, &J_));
  PetscCall(MatSetSizes(J_, n_local, n_local, n_total_, n_total_));
  PetscCall(MatSetType(J_, MATAIJ));
  PetscCall(MatSetOptionsPrefix(J_, "jac_"));
  PetscCall(MatSetFromOptions(J_));
  PetscCall(MatSetPreallocationCOO(J_, static_cast<PetscCount>(ci.size()), ci.data(), cj.data()));
  ++layouts_created_;

  // The Newton matrix is factored by MUMPS LU unless the options say
  // otherwise (-ksp_type, -pc_type, -pc_factor_mat_solver_type).
  PetscCall(CreateFactorKsp(PCLU, "", &ksp_));
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::CreateFactorKsp(PCType factor, const char *prefix, KSP *ksp) {
  PC pc;
  PetscFunctionBeginUser;
  PetscCall(KSPCreate(comm_, ksp));
  PetscCall(KSPSetOptionsPrefix(*ksp, options_prefix_.c_str()));
  PetscCall(KSPAppendOptionsPrefix(*ksp, prefix));
  PetscCall(KSPSetOperators(*ksp, J_, J_));
  PetscCall(KSPSetType(*ksp, KSPPREONLY));
  PetscCall(KSPGetPC(*ksp, &pc));
  PetscCall(PCSetType(pc, factor));
  PetscCall(PCFactorSetMatSolverType(pc, MATSOLVERMUMPS));
  // The ordering is approximate minimum degree with quasi-dense row
  // detection (QAMD, ICNTL(7) = 6) unless -mat_mumps_icntl_7 says otherwise:
  // each deformable disk's three rigid-mode unknowns are coupled to all its
  // nodal unknowns, and MUMPS's automatic choice spent 4.4-6 s per analysis
  // at 1500 disks against 0.5-0.8 s for QAMD, with the same numeric
  // factorization time on 1 rank and 11 % more on 2
  // (docs/level-solver-measurements.md, "Measured: the rigid modes of
  // deformable disks under the anchor"). Set through the options database:
  // MatMumpsSetIcntl(7) before the analysis does not reach MUMPS here.
  {
    const char *ksp_prefix = nullptr;
    PetscCall(KSPGetOptionsPrefix(*ksp, &ksp_prefix));
    PetscBool icntl7_set = PETSC_FALSE;
    PetscCall(PetscOptionsHasName(nullptr, ksp_prefix, "-mat_mumps_icntl_7", &icntl7_set));
    const std::string name = "-" + std::string(ksp_prefix ? ksp_prefix : "") + "mat_mumps_icntl_7";
    if (!icntl7_set) PetscCall(PetscOptionsSetValue(nullptr, name.c_str(), "6"));
  }
  PetscCall(KSPSetFromOptions(*ksp));
  // Contact saddle points need numerical pivoting, and MUMPS' workspace
  // estimate (made before pivoting) is then often too small (INFOG(1) = -9):
  // reserve mumps_extra_ % more (100 at first, doubled after each such
  // failure, see GrowFactorWorkspace) unless -mat_mumps_icntl_14 says otherwise.
  MatSolverType solver_type = nullptr;
  PetscBool is_lu = PETSC_FALSE, is_cholesky = PETSC_FALSE, icntl14_set = PETSC_FALSE;
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, PCLU, &is_lu));
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, PCCHOLESKY, &is_cholesky));
  if (is_lu || is_cholesky) PetscCall(PCFactorGetMatSolverType(pc, &solver_type));
  // No scaling (ICNTL(8) = 0) unless -mat_mumps_icntl_8 says otherwise: the
  // rows are in the units of E already (NCP rows scaled by c_n = ncp_scale E,
  // gauge rows by E / R, shifts by the weights D), and MUMPS's scaling,
  // recomputed at every numeric factorization, took 8 % of a 50-disk run
  // (perf) without changing its Newton iterations or phi
  // (docs/level-solver-measurements.md, "Measured: the cost of an iteration").
  PetscBool icntl8_set = PETSC_FALSE;
  PetscCall(PetscOptionsHasName(nullptr, nullptr, "-mat_mumps_icntl_14", &icntl14_set));
  PetscCall(PetscOptionsHasName(nullptr, nullptr, "-mat_mumps_icntl_8", &icntl8_set));
  if (solver_type && std::string(solver_type) == MATSOLVERMUMPS) {
    Mat mumps;
    PetscCall(PCFactorSetUpMatSolverType(pc));
    PetscCall(PCFactorGetMatrix(pc, &mumps));
    if (!icntl14_set) PetscCall(MatMumpsSetIcntl(mumps, 14, mumps_extra_));
    if (!icntl8_set) PetscCall(MatMumpsSetIcntl(mumps, 8, 0));
  }
  PetscFunctionReturn(0);
}

// Largest unbalanced force of a residual F: body and wall rows, rigid
// rotations (torques) divided by the radius.
PetscErrorCode CompactionProblem::ForceResidual(Vec F, double *force, PetscInt *where) const {
  const PetscScalar *fa;
  PetscFunctionBeginUser;
  PetscCall(VecGetArrayRead(F, &fa));
  struct {
    double value;
    int where;  // natural unknown
  } m{0.0, -1};
  for (PetscInt i = own_lo_; i < own_hi_; ++i) {
    const PetscInt n = natural_of_[i];
    if (n >= GaugeOffset()) continue;
    const double f = std::abs(fa[i - own_lo_]) / std::sqrt(prox_weight_[n]);
    if (f > m.value) m.value = f, m.where = static_cast<int>(n);
  }
  PetscCall(VecRestoreArrayRead(F, &fa));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &m, 1, MPI_DOUBLE_INT, MPI_MAXLOC, comm_));
  *force = m.value;
  if (where) *where = m.where;
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::Layout(Vec *z, Vec *F, Mat *J, KSP *ksp) {
  PetscFunctionBeginUser;
  if (!ksp_) PetscCall(SetUpLayout());
  PetscCall(PackState(z_));
  *z = z_, *F = r_, *J = J_, *ksp = ksp_;
  PetscFunctionReturn(0);
}

bool CompactionProblem::GrowFactorWorkspace() {
  if (mumps_extra_ >= 6400) return false;
  mumps_extra_ *= 2;
  DestroySolver();
  return true;
}

PetscErrorCode CompactionProblem::NewtonMatrix(Vec z, Mat J) {
  PetscFunctionBeginUser;
  PetscCall(FormJacobian(z, J));
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::ShiftDiagonals(Vec floor, Vec weight) const {
  PetscScalar *fa, *wa;
  PetscFunctionBeginUser;
  PetscCall(VecGetArray(floor, &fa));
  PetscCall(VecGetArray(weight, &wa));
  for (PetscInt i = own_lo_; i < own_hi_; ++i) {
    const PetscInt n = natural_of_[i];
    fa[i - own_lo_] = ProximalDiagonal(n);
    wa[i - own_lo_] = n < GaugeOffset() ? prox_weight_[n] : 0.0;
  }
  PetscCall(VecRestoreArray(floor, &fa));
  PetscCall(VecRestoreArray(weight, &wa));
  PetscFunctionReturn(0);
}

PetscErrorCode FactorOnEveryRank(KSP ksp, bool *ok, bool *out_of_memory, PCFailedReason *reason) {
  PC pc;
  PCFailedReason local;
  MPI_Comm comm;
  PetscFunctionBeginUser;
  PetscCall(KSPSetUp(ksp));
  PetscCall(KSPGetPC(ksp, &pc));
  PetscCall(PCGetFailedReason(pc, &local));
  int flags[2] = {local != PC_NOERROR, local == PC_FACTOR_OUTMEMORY};
  PetscCall(PetscObjectGetComm((PetscObject)ksp, &comm));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, flags, 2, MPI_INT, MPI_MAX, comm));
  *ok = !flags[0];
  if (out_of_memory) *out_of_memory = flags[1];
  if (reason) *reason = local;
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::AdoptState(Vec z) {
  const PetscScalar *za;
  PetscFunctionBeginUser;
  PetscCall(Gather(z, true));
  PetscCall(VecGetArrayRead(zall_, &za));
  Unpack(za);
  PetscCall(VecRestoreArrayRead(zall_, &za));
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::ResidualFromHere(Vec z, Vec F) {
  const PetscScalar *za;
  PetscFunctionBeginUser;
  const std::vector<double> start = u_start_;
  const double rho = rho_anchor_;
  PetscCall(Gather(z, true));
  PetscCall(VecGetArrayRead(zall_, &za));
  u_start_.assign(za, za + n_body_dofs_);
  PetscCall(VecRestoreArrayRead(zall_, &za));
  rho_anchor_ = 0.0;
  static_rows_ = true;
  const PetscErrorCode ierr = Residual(z, F);
  static_rows_ = false;  // restored on error too: the caller may go on with this problem
  u_start_ = start;
  rho_anchor_ = rho;
  PetscCall(ierr);
  PetscFunctionReturn(0);
}

namespace {

// The rigid part of a deformable body's step d at positions X + z (both
// offset to the body's first unknown, nn nodes): the centroid c, the mean
// translation t, and the rotation theta about c that fits the nodal steps
// best in least squares.
void RigidPartOfStep(const double *X, int nn, const PetscScalar *z, const PetscScalar *d, double c[2], double t[2],
                     double *theta) {
  c[0] = c[1] = t[0] = t[1] = 0.0;
  for (int a = 0; a < nn; ++a)
    for (int i = 0; i < 2; ++i) {
      c[i] += (X[2 * a + i] + z[2 * a + i]) / nn;
      t[i] += d[2 * a + i] / nn;
    }
  double num = 0.0, den = 0.0;
  for (int a = 0; a < nn; ++a) {
    const double r[2] = {X[2 * a] + z[2 * a] - c[0], X[2 * a + 1] + z[2 * a + 1] - c[1]};
    num += r[0] * (d[2 * a + 1] - t[1]) - r[1] * (d[2 * a] - t[0]);
    den += r[0] * r[0] + r[1] * r[1];
  }
  *theta = den > 0.0 ? num / den : 0.0;
}

}  // namespace

PetscErrorCode CompactionProblem::RotatedUpdate(Vec zv, Vec dv, Vec ztv) const {
  const PetscScalar *z, *d;
  PetscScalar *zt;
  PetscFunctionBeginUser;
  PetscCall(VecWAXPY(ztv, 1.0, dv, zv));
  PetscCall(VecGetArrayRead(zv, &z));
  PetscCall(VecGetArrayRead(dv, &d));
  PetscCall(VecGetArray(ztv, &zt));
  for (const DeformableBody &body : bodies_) {
    if (ParticleOwner(body.particle) != rank_) continue;
    const int nn = body.mesh.num_nodes();
    // Local (owned) index of node a's x unknown; a body's unknowns are contiguous in both numberings.
    const PetscInt first = petsc_of_[body.dof_offset] - own_lo_;
    double c[2], t[2], theta;
    RigidPartOfStep(body.mesh.X.data(), nn, z + first, d + first, c, t, &theta);
    const double cm1 = std::cos(theta) - 1.0, smt = std::sin(theta) - theta;
    for (int a = 0; a < nn; ++a) {
      const double r[2] = {body.mesh.X[2 * a] + z[first + 2 * a] - c[0], body.mesh.X[2 * a + 1] + z[first + 2 * a + 1] - c[1]};
      zt[first + 2 * a] += cm1 * r[0] - smt * r[1];
      zt[first + 2 * a + 1] += smt * r[0] + cm1 * r[1];
    }
  }
  PetscCall(VecRestoreArray(ztv, &zt));
  PetscCall(VecRestoreArrayRead(dv, &d));
  PetscCall(VecRestoreArrayRead(zv, &z));
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::StepMoves(Vec zv, Vec sv, double moves[3]) const {
  const PetscScalar *z, *d;
  PetscFunctionBeginUser;
  moves[0] = moves[1] = moves[2] = 0.0;
  PetscCall(VecGetArrayRead(zv, &z));
  PetscCall(VecGetArrayRead(sv, &d));
  for (const DeformableBody &body : bodies_) {
    if (ParticleOwner(body.particle) != rank_) continue;
    const int nn = body.mesh.num_nodes();
    const PetscInt first = petsc_of_[body.dof_offset] - own_lo_;
    double c[2], t[2], theta;
    RigidPartOfStep(body.mesh.X.data(), nn, z + first, d + first, c, t, &theta);
    moves[0] = std::max(moves[0], std::hypot(t[0], t[1]));
    moves[1] = std::max(moves[1], std::abs(theta) * body.mesh.radius);
    for (int a = 0; a < nn; ++a) {
      const double r[2] = {body.mesh.X[2 * a] + z[first + 2 * a] - c[0], body.mesh.X[2 * a + 1] + z[first + 2 * a + 1] - c[1]};
      moves[2] = std::max(moves[2], std::hypot(d[first + 2 * a] - t[0] + theta * r[1], d[first + 2 * a + 1] - t[1] - theta * r[0]));
    }
  }
  for (const RigidBody &r : rigid_) {
    if (ParticleOwner(r.particle) != rank_) continue;
    const PetscInt first = petsc_of_[r.dof_offset] - own_lo_;
    moves[0] = std::max(moves[0], std::hypot(d[first], d[first + 1]));
    if (RigidDofs() == 3) moves[1] = std::max(moves[1], std::abs(d[first + 2]) * r.radius);
  }
  PetscCall(VecRestoreArrayRead(sv, &d));
  PetscCall(VecRestoreArrayRead(zv, &z));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, moves, 3, MPI_DOUBLE, MPI_MAX, comm_));
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::BodyBalance(Vec Fv, Balance *balance) const {
  const PetscScalar *f;
  PetscFunctionBeginUser;
  Balance b;
  PetscCall(VecGetArrayRead(Fv, &f));
  const auto local = [&](PetscInt natural) { return f[petsc_of_[natural] - own_lo_]; };
  for (int d = 0; d < static_cast<int>(bodies_.size()); ++d) {
    const DeformableBody &body = bodies_[d];
    if (ParticleOwner(body.particle) != rank_) continue;
    const int nn = body.mesh.num_nodes();
    double c[2];
    BodyCentroid(d, c);
    double net[2] = {0, 0}, torque = 0.0;
    for (int a = 0; a < nn; ++a) {
      const PetscInt i = body.dof_offset + 2 * a;
      const double fa[2] = {local(i), local(i + 1)};
      double x[2];
      NodePosition(d, a, x);
      net[0] += fa[0], net[1] += fa[1];
      torque += (x[0] - c[0]) * fa[1] - (x[1] - c[1]) * fa[0];
      b.node_force = std::max(b.node_force, std::max(std::abs(fa[0]), std::abs(fa[1])));
    }
    const double force = std::hypot(net[0], net[1]);
    if (force > b.body_force) b.body_force = force, b.body_force_particle = body.particle, b.body_force_deformable = true;
    b.body_torque = std::max(b.body_torque, std::abs(torque));
  }
  for (const RigidBody &r : rigid_) {
    if (ParticleOwner(r.particle) != rank_) continue;
    const double fx = local(r.dof_offset), fy = local(r.dof_offset + 1);
    const double torque = Frictional() ? std::abs(local(r.dof_offset + 2)) : 0.0;
    const double force = std::hypot(fx, fy);
    if (force > b.body_force) b.body_force = force, b.body_force_particle = r.particle, b.body_force_deformable = false;
    b.body_torque = std::max(b.body_torque, torque);
    b.node_force = std::max({b.node_force, std::abs(fx), std::abs(fy), torque / r.radius});
  }
  for (PetscInt i = own_lo_; i < own_hi_; ++i) {
    const PetscInt n = natural_of_[i];
    if (n >= WallOffset() && n < GaugeOffset()) b.node_force = std::max(b.node_force, std::abs(f[i - own_lo_]));
    if (n >= MultiplierOffset()) b.contact_row = std::max(b.contact_row, std::abs(f[i - own_lo_]));
  }
  PetscCall(VecRestoreArrayRead(Fv, &f));
  // The largest net force and its particle (2 particle + 1 if deformable;
  // MAXLOC takes the lowest on a tie, so every rank names the same one).
  struct {
    double value;
    int where;
  } largest{b.body_force, 2 * b.body_force_particle + (b.body_force_deformable ? 1 : 0)};
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &largest, 1, MPI_DOUBLE_INT, MPI_MAXLOC, comm_));
  double rest[3] = {b.body_torque, b.node_force, b.contact_row};
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, rest, 3, MPI_DOUBLE, MPI_MAX, comm_));
  balance->body_force = largest.value, balance->body_torque = rest[0], balance->node_force = rest[1];
  balance->contact_row = rest[2];
  balance->body_force_particle = largest.where < 0 ? -1 : largest.where / 2;
  balance->body_force_deformable = largest.where >= 0 && largest.where % 2 == 1;
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::StateBalance(Balance *balance) {
  Vec z = nullptr, F = nullptr;
  Mat J = nullptr;
  KSP ksp = nullptr;
  PetscFunctionBeginUser;
  PetscCall(Layout(&z, &F, &J, &ksp));
  PetscCall(EvaluateResidual(z, F));
  PetscCall(BodyBalance(F, balance));
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::ResidualBlocks(Vec F, double norm[5]) const {
  const PetscScalar *ra;
  PetscFunctionBeginUser;
  std::fill(norm, norm + 5, 0.0);
  PetscCall(VecGetArrayRead(F, &ra));
  for (PetscInt i = own_lo_; i < own_hi_; ++i) {
    const PetscInt n = natural_of_[i];
    const int k = n < WallOffset() ? 0 : n < GaugeOffset() ? 1 : n < MultiplierOffset() ? 2 : n < TangentialOffset() ? 3 : 4;
    norm[k] += ra[i - own_lo_] * ra[i - own_lo_];
  }
  PetscCall(VecRestoreArrayRead(F, &ra));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, norm, 5, MPI_DOUBLE, MPI_SUM, comm_));
  for (int k = 0; k < 5; ++k) norm[k] = std::sqrt(norm[k]);
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::LagContactWeights() {
  PetscFunctionBeginUser;
  const double mu_f = FrictionActive() ? params_.friction : 0.0;
  tresca_bound_.assign(candidates_.size(), 0.0);
  for (size_t c = 0; c < candidates_.size() && c < lambda_.size(); ++c)
    if (tangential_index_[c] >= 0) tresca_bound_[c] = mu_f * std::max(lambda_[c], 0.0);
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::ContactPenalty(double *penetration, double *dissipation) const {
  PetscFunctionBeginUser;
  PetscCheck(tresca_bound_.size() == candidates_.size() && gap_bound_.size() == 2 * candidates_.size(), comm_,
             PETSC_ERR_ORDER, "ContactPenalty needs LagContactWeights and a residual evaluation with the current candidates");
  double local[2] = {0.0, 0.0};
  const double overshoot = kOpenOvershoot * mean_diameter_;
  for (size_t c = 0; c < candidates_.size(); ++c) {
    if (CandidateOwner(candidates_[c]) != rank_) continue;
    local[0] += std::max(0.0, -gap_bound_[2 * c] - overshoot);
    local[1] += tresca_bound_[c] * std::abs(slip_now_[c]);
  }
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, local, 2, MPI_DOUBLE, MPI_SUM, comm_));
  *penetration = local[0], *dissipation = local[1];
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::LargestNormalMultiplier(Vec z, double *largest) const {
  const PetscScalar *za;
  PetscFunctionBeginUser;
  const PetscInt lo = MultiplierOffset(), hi = lo + static_cast<PetscInt>(candidates_.size());
  double m = 0.0;
  PetscCall(VecGetArrayRead(z, &za));
  for (PetscInt i = own_lo_; i < own_hi_; ++i)
    if (natural_of_[i] >= lo && natural_of_[i] < hi) m = std::max(m, PetscRealPart(za[i - own_lo_]));
  PetscCall(VecRestoreArrayRead(z, &za));
  PetscCallMPI(MPI_Allreduce(&m, largest, 1, MPI_DOUBLE, MPI_MAX, comm_));
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::ChangedStateMargin(const std::vector<char> &was, double *margin) const {
  PetscFunctionBeginUser;
  *margin = 0.0;
  if (was == active_now_) PetscFunctionReturn(0);
  *margin = was.size() == active_now_.size() ? changed_state_margin(was, active_now_, switch_margin_) : INFINITY;
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, margin, 1, MPI_DOUBLE, MPI_MAX, comm_));
  PetscFunctionReturn(0);
}

LayoutSizes CompactionProblem::Sizes() {
  LayoutSizes s;
  if (!ksp_ && SetUpLayout() != 0) return s;
  s.total = n_total_;
  for (const RigidBody &r : rigid_) s.rigid += RigidDofs(), (void)r;
  s.deformable = n_body_dofs_ - s.rigid;
  s.gauges = static_cast<PetscInt>(torque_.size());
  s.normal = static_cast<PetscInt>(candidates_.size());
  s.tangential = n_total_ - TangentialOffset();
  MatInfo info;
  if (MatGetInfo(J_, MAT_GLOBAL_SUM, &info) == 0) s.jacobian_nonzeros = static_cast<PetscInt>(info.nz_used);
  return s;
}

double CompactionProblem::ProximalDiagonal(PetscInt i) const {
  if (i >= MultiplierOffset()) return -DualRegularization();
  if (i >= GaugeOffset()) return 0.0;
  return params_.prox_eta * params_.young * prox_weight_[i];
}

PetscErrorCode CompactionProblem::EvaluateResidual(Vec z, Vec F) {
  PetscFunctionBeginUser;
  PetscCall(FormResidual(z, F));
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::EvaluateJacobian(Vec z, Mat *J) {
  PetscFunctionBeginUser;
  // PETSc 3.18's MatDuplicate does not carry the COO map: fill J_, then copy it.
  PetscCall(FormJacobian(z, J_));
  PetscCall(MatDuplicate(J_, MAT_COPY_VALUES, J));
  PetscFunctionReturn(0);
}

// ---------------------------------------------------------------------------
// A point that was not a candidate may have crossed another body or a wall
// during a solve, or a node may have slid out of its segment window: then the
// candidates must be updated and the solve continued. A node-segment pair is
// stale only when its closest point has left the pair's two-segment window
// (inside it the gap is continuous). Where nothing is stale, a pair that is
// no candidate within kApproachFraction x the margin is approaching: a
// refresh then adds it while it is open. Reads the replicated state.
PetscErrorCode CompactionProblem::CandidatesStale(bool *stale, bool *approaching) const {
  PetscFunctionBeginUser;
  // One detection where no pair that is no candidate comes near (the usual
  // case); an overlapping pair is also one within the approach margin.
  const bool near = DetectsNonCandidate(kApproachFraction * params_.contact_margin);
  *stale = near && DetectsNonCandidate(-1e-9);
  std::vector<double> zfull(n_total_);
  Pack(zfull.data());
  for (const ContactCandidate &c : candidates_) {
    if (*stale || c.type != ContactType::NodeSegment) continue;
    LocalContact lc;
    ContactGeometry(c, zfull.data(), &lc);
    if (lc.beyond != 0 && lc.k.gap < params_.contact_margin * mean_diameter_) *stale = true;
  }
  if (approaching) *approaching = !*stale && near;
  PetscFunctionReturn(0);
}

bool CompactionProblem::DetectsNonCandidate(double margin) const {
  std::set<std::tuple<int, int, int, int, int>> current;
  for (const ContactCandidate &c : candidates_) current.insert(CandidateKey(c));
  for (const ContactCandidate &c : DetectCandidates(margin))
    if (!current.count(CandidateKey(c))) return true;
  return false;
}

bool CompactionProblem::PredictionAdmissible(double overlap_limit) const {
  const StateSummary predicted = Summary();
  // The overlaps are those of the contact laws (max_penetration over the
  // candidates and boundary points); the detection, which measures against
  // the straight chords of deformable boundaries, only has to find no
  // overlapping pair that is not a candidate. Its chord gaps of conforming
  // contacts between deformable disks exceed 1e-3 <d> beyond P/E ~ 0.1,
  // where the laws' overlaps are far smaller (docs/level-solver-
  // measurements.md, "Measured: the attempt handed over").
  const bool admissible = predicted.min_cell_area_ratio > 0.0 &&
                          predicted.max_penetration < overlap_limit * mean_diameter_ &&
                          !DetectsNonCandidate(-overlap_limit);
  // -info: why a predicted state was rejected (BeginLoadStep then halves
  // the prediction; hybrid's attempt then starts anchored from the start of
  // the load step).
  PetscInfo(nullptr, "predicted state %s: smallest cell area ratio %g, deepest overlap %g <d>\n",
            admissible ? "taken" : "rejected", predicted.min_cell_area_ratio, predicted.max_penetration / mean_diameter_);
  return admissible;
}

// The tangent predictor (BeginLoadStep): J dz = -dP dF/dP at the converged
// state, F depending on P only through the walls' load P grad A(w); the
// multipliers follow (the contact states of the converged state held fixed).
PetscErrorCode CompactionProblem::TangentPredictor(double dP, double overlap_limit, bool *applied) {
  PetscFunctionBeginUser;
  *applied = false;
  Vec z = nullptr, F = nullptr, dz = nullptr, zt = nullptr;
  Mat J = nullptr;
  KSP ksp = nullptr;
  PetscCall(Layout(&z, &F, &J, &ksp));
  PetscCall(NewtonMatrix(z, J));
  PetscCall(KSPSetOperators(ksp, J, J));
  bool ok = false;
  PetscCall(FactorOnEveryRank(ksp, &ok));
  ++predictor_factorizations_;
  if (ok) {
    PetscCall(VecDuplicate(z, &dz));
    PetscCall(VecDuplicate(z, &zt));
    PetscCall(VecSet(F, 0.0));
    double g[4];
    WallBox::pressure_gradient(-dP, w_, g);
    PetscScalar *fa;
    PetscCall(VecGetArray(F, &fa));
    for (PetscInt i = own_lo_; i < own_hi_; ++i)
      if (natural_of_[i] >= WallOffset() && natural_of_[i] < WallOffset() + 4) fa[i - own_lo_] = g[natural_of_[i] - WallOffset()];
    PetscCall(VecRestoreArray(F, &fa));
    PetscCall(KSPSolve(ksp, F, dz));
    KSPConvergedReason kreason;
    PetscCall(KSPGetConvergedReason(ksp, &kreason));
    double t = 1.0;
    for (int attempt = 0; kreason > 0 && attempt < 5 && !*applied; ++attempt, t *= 0.5) {
      PetscCall(VecWAXPY(zt, t, dz, z));
      PetscCall(AdoptState(zt));
      *applied = PredictionAdmissible(overlap_limit);
    }
    if (!*applied) PetscCall(AdoptState(z));
    PetscCall(VecDestroy(&dz));
    PetscCall(VecDestroy(&zt));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::BeginLoadStep(double pressure, LoadPredictor predictor, double overlap_limit) {
  PetscFunctionBeginUser;
  layouts_at_step_ = layouts_created_;
  // A fresh layout, and so a fresh MUMPS analysis, for every load step. On
  // one rank MUMPS chooses its pivot order from the values of the first
  // matrix it factors after an analysis (ICNTL(6)): with the last level's
  // layout kept, the tangent predictor would be factored with an order
  // chosen from that level's first matrix, while a run restarted here,
  // which has no such history, analyses this one. The two predictions
  // differ by round-off, and a 1500-disk run restarted from a checkpoint
  // then parted from the uninterrupted one in an end game (270 against 278
  // Newton iterations on one level). One analysis per load step is a
  // factorization's cost.
  if (ksp_) PetscCall(SetUpLayout());
  step_saved_ = SaveState();
  step_saved_pressure_ = pressure_;
  u_start_ = u_;
  // The tangent predictor (none for the first increment: the state at P = 0
  // is the unloaded packing) is halved while it would make bodies overlap by
  // more than overlap_limit <d> or invert an element: the first Newton step
  // has to close every predicted overlap at once, and a strongly damped one
  // closes it slowly.
  bool tangent = false;  // the multipliers come from the tangent
  if (predictor == LoadPredictor::Tangent && have_previous_ && pressure_ > 0.0 && pressure != pressure_) {
    PetscCall(TangentPredictor(pressure - pressure_, overlap_limit, &tangent));
  }
  // Contact forces scale with the pressure: for rigid disks the scaled
  // multipliers at the same geometry are the exact equilibrium of the new
  // level, for deformable ones the first-order guess.
  if (!tangent && pressure_ > 0.0 && pressure != pressure_) {
    const double scale = pressure / pressure_;
    for (double &l : lambda_) l *= scale;
    for (double &l : lambda_t_) l *= scale;
    for (double &t : torque_) t *= scale;
  }
  pressure_ = pressure;
  PetscCall(RefreshCandidates());
  PetscFunctionReturn(0);
}

PetscErrorCode CompactionProblem::EndLoadStep(bool converged, SolveReport *report) {
  PetscFunctionBeginUser;
  rho_anchor_ = 0.0;
  dual_reg_ = -1.0;
  if (!converged) {
    RestoreState(step_saved_);
    pressure_ = step_saved_pressure_;
    u_start_ = u_;
    PetscFunctionReturn(0);
  }
  report->converged = true;
  report->layouts = layouts_created_ - layouts_at_step_;
  report->active_contacts = 0;
  for (char a : active_now_) report->active_contacts += a != kOpen;
  have_previous_ = true;
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

// Particle areas of the current state: the deformable disks' current and
// reference areas and smallest cell area ratio into s; returns the rigid disks' area.
double CompactionProblem::Areas(StateSummary *s) const {
  s->min_cell_area_ratio = std::numeric_limits<double>::infinity();
  for (int b = 0; b < static_cast<int>(bodies_.size()); ++b) {
    const std::vector<double> ratio = CellAreaRatio(b);
    double area = 0.0;
    for (size_t e = 0; e < ratio.size(); ++e) {
      area += ratio[e] * bodies_[b].ref_cell_area[e];
      s->min_cell_area_ratio = std::min(s->min_cell_area_ratio, ratio[e]);
    }
    s->deformable_area += area;
    s->ref_deformable_area += bodies_[b].ref_area;
  }
  if (bodies_.empty()) s->min_cell_area_ratio = 1.0;
  double rigid_area = 0.0;
  for (const RigidBody &r : rigid_) rigid_area += M_PI * r.radius * r.radius;
  return rigid_area;
}

double CompactionProblem::PackingFraction() const {
  StateSummary s;
  const double rigid_area = Areas(&s);
  return (s.deformable_area + rigid_area) / WallBox::area(w_);
}

StateSummary CompactionProblem::Summary() const {
  StateSummary s;
  s.box_width = WallBox::width(w_);
  s.box_height = WallBox::height(w_);
  const double rigid_area = Areas(&s);
  s.particle_area = s.deformable_area + rigid_area;
  s.ref_particle_area = s.ref_deformable_area + rigid_area;
  s.packing_fraction = s.particle_area / WallBox::area(w_);
  s.area_ratio = s.particle_area / s.ref_particle_area;
  // Penetration: every boundary point against the walls, and every candidate pair.
  s.max_penetration = -std::numeric_limits<double>::infinity();
  for (int b = 0; b < static_cast<int>(bodies_.size()); ++b)
    for (int i = 0; i < static_cast<int>(bodies_[b].mesh.boundary.size()); ++i) {
      double x[2], g[4];
      BoundaryPointPosition(b, i, x);
      WallBox::point_gaps(x, w_, g);
      for (double gi : g) s.max_penetration = std::max(s.max_penetration, -gi);
    }
  for (int r = 0; r < static_cast<int>(rigid_.size()); ++r) {
    double x[2], g[4];
    RigidPosition(r, x, nullptr);
    WallBox::point_gaps(x, w_, g);
    for (double gi : g) s.max_penetration = std::max(s.max_penetration, rigid_[r].radius - gi);
  }
  const std::vector<ContactForce> forces = ContactForces();
  for (size_t c = 0; c < forces.size(); ++c) {
    const ContactForce &f = forces[c];
    s.max_penetration = std::max(s.max_penetration, -f.gap);
    if (f.master_particle < 0) s.wall_force[candidates_[c].wall] += f.normal_multiplier;
    s.min_multiplier = std::min(s.min_multiplier, f.normal_multiplier);
    s.max_complementarity = std::max(s.max_complementarity, std::abs(f.normal_multiplier * f.gap));
    if (f.normal_multiplier > 0.0) ++s.active_contacts;
    if (f.state == kSliding) ++s.sliding_contacts;
  }
  // Torque of gauge b: sum over nodes of X_a x (mu_b G_a) = mu_b * mean |X_a|^2.
  for (size_t b = 0; b < torque_.size(); ++b) {
    const DiskMesh &m = bodies_[b].mesh;
    double r2 = 0.0;
    for (int a = 0; a < m.num_nodes(); ++a) r2 += m.X[2 * a] * m.X[2 * a] + m.X[2 * a + 1] * m.X[2 * a + 1];
    s.max_gauge_torque = std::max(s.max_gauge_torque, std::abs(torque_[b]) * r2 / m.num_nodes());
  }
  return s;
}

}  // namespace deformix

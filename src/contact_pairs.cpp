// Contact pairs: the kinematics of every candidate type (the geometry
// dispatch: walls, rigid-rigid, rigid-node, node-segment and mortar gaps,
// contact_law.hpp and the *_kinematics files for the formulas), their
// contributions to the residual and the Newton matrix (NCP rows, contact
// forces), and the contact forces of the current state for the observables.
#include <algorithm>
#include <cmath>

#include "deformix/problem.hpp"

namespace deformix {

// Kinematics of one candidate: gap, slip and derivatives on its global unknowns.
void CompactionProblem::ContactGeometry(const ContactCandidate &c, const double *z, LocalContact *lc, bool hessians) const {
  const double *z0 = u_start_.empty() ? z : u_start_.data();  // slip reference: the start of the increment
  double q[PairKinematics::kMaxDofs] = {}, q0[PairKinematics::kMaxDofs] = {};
  int nq = 0;
  auto add_node = [&](const DeformableBody &body, int node) {
    for (int i = 0; i < 2; ++i) {
      const PetscInt d = body.dof_offset + 2 * node + i;
      lc->dofs[nq] = d;
      q[nq] = body.center[i] + body.mesh.X[2 * node + i] + z[d];
      q0[nq] = body.center[i] + body.mesh.X[2 * node + i] + z0[d];
      ++nq;
    }
  };
  auto add_rigid = [&](const RigidBody &body) {
    for (int i = 0; i < 3; ++i) {
      const bool present = i < 2 || Frictional();
      const PetscInt d = body.dof_offset + i;
      const double ref = i < 2 ? body.center[i] : 0.0;
      lc->dofs[nq] = present ? d : -1;
      q[nq] = present ? ref + z[d] : 0.0;
      q0[nq] = present ? ref + z0[d] : 0.0;
      ++nq;
    }
  };
  const double *w = z + WallOffset();
  const PetscInt wall_dof = WallOffset() + c.wall;
  lc->frictional = HasTangential(c);
  lc->curved = false;
  lc->beyond = 0;
  lc->slave_nodes = 1;
  lc->k = PairKinematics();
  for (PetscInt &d : lc->dofs) d = -1;
  switch (c.type) {
    case ContactType::PointWall: {
      const DeformableBody &body = bodies_[c.body];
      const BoundaryPoint bp = boundary_point(body.mesh, c.point);
      double x[2] = {0.0, 0.0};
      int dx[3], dy[3];
      for (int a = 0; a < bp.n; ++a) {
        const int n = bp.nodes[a];
        dx[a] = static_cast<int>(body.dof_offset) + 2 * n, dy[a] = dx[a] + 1;
        x[0] += bp.coeff[a] * (body.center[0] + body.mesh.X[2 * n] + z[dx[a]]);
        x[1] += bp.coeff[a] * (body.center[1] + body.mesh.X[2 * n + 1] + z[dy[a]]);
      }
      const ContactKinematics k = WallBox::point_gap(c.wall, x, w, bp.n, dx, dy, bp.coeff, static_cast<int>(wall_dof));
      lc->k.ndof = k.ndof;
      lc->k.gap = k.gap;
      for (int a = 0; a < k.ndof; ++a) lc->dofs[a] = k.dofs[a], lc->k.dgap[a] = k.dgap[a];
      lc->slave_xy = -1;
      return;
    }
    case ContactType::RigidWall: {
      const RigidBody &body = rigid_[c.body];
      const int axis = WallBox::axis(c.wall);
      const double sign = WallBox::inward_sign(c.wall);
      const PetscInt d = body.dof_offset + axis;
      const double x = body.center[axis] + z[d];
      lc->k.ndof = 2;
      lc->k.gap = sign * (x - w[c.wall]) - body.radius;
      lc->dofs[0] = d, lc->k.dgap[0] = sign;
      lc->dofs[1] = wall_dof, lc->k.dgap[1] = -sign;
      lc->slave_xy = -1;
      return;
    }
    case ContactType::RigidRigid:
      add_rigid(rigid_[c.master]);
      add_rigid(rigid_[c.body]);
      lc->k = rigid_rigid(q, q0, rigid_[c.master].radius, rigid_[c.body].radius);
      lc->slave_xy = 3;
      break;
    case ContactType::RigidNode:
      add_rigid(rigid_[c.master]);
      add_node(bodies_[c.body], bodies_[c.body].mesh.boundary[c.point]);
      lc->k = rigid_node(q, q0, rigid_[c.master].radius);
      lc->slave_xy = 3;
      break;
    case ContactType::NodeSegment: {
      const DiskMesh &m = bodies_[c.master].mesh;
      const int nb = static_cast<int>(m.boundary.size());
      // The master boundary around its node `segment`: five nodes, the smooth
      // master curve on the two segments around it.
      if (params_.deformable_contact == DeformableContact::Mortar) {
        // Mortar: seven master nodes around `segment`, the slave nodes point-2 .. point+2.
        const DiskMesh &s = bodies_[c.body].mesh;
        const int ns = static_cast<int>(s.boundary.size());
        for (int j = -3; j <= 3; ++j) add_node(bodies_[c.master], m.boundary[(c.segment + j + nb) % nb]);
        for (int j = -2; j <= 2; ++j) add_node(bodies_[c.body], s.boundary[(c.point + j + ns) % ns]);
        MortarSupport support;
        support.order = s.order;
        support.vertex = s.order == 1 || c.point % 2 == 0;
        for (int side = 0; side < 2; ++side) {
          const int a = s.boundary[(c.point + side - 1 + ns) % ns], b = s.boundary[(c.point + side) % ns];
          support.length[side] = std::hypot(s.X[2 * b] - s.X[2 * a], s.X[2 * b + 1] - s.X[2 * a + 1]);
        }
        lc->k = mortar_node(q, q0, support, hessians, &lc->beyond);
        lc->slave_xy = 14, lc->slave_nodes = 5;
        break;
      }
      for (int j = -2; j <= 2; ++j) add_node(bodies_[c.master], m.boundary[(c.segment + j + nb) % nb]);
      add_node(bodies_[c.body], bodies_[c.body].mesh.boundary[c.point]);
      lc->k = curve_node(q, q0, hessians, &lc->beyond);
      lc->slave_xy = 10;
      break;
    }
  }
  lc->curved = true;
}

// Contacts: their part of Assemble (which see), for the candidates this rank owns.
PetscErrorCode CompactionProblem::AssembleContacts(const double *z, double *F, std::vector<PetscInt> *ci,
                                                   std::vector<PetscInt> *cj, std::vector<PetscScalar> *cv,
                                                   std::vector<char> *active) {
  const bool pattern = ci != nullptr;
  const bool values = cv != nullptr;
  const bool need_K = pattern || values;
  const PetscInt lam_off = MultiplierOffset();
  auto entry = [&](PetscInt i, PetscInt j, double v) {
    if (i < 0 || j < 0) return;
    if (pattern) ci->push_back(petsc_of_[i]), cj->push_back(petsc_of_[j]);
    if (values) cv->push_back(v);
  };
  PetscFunctionBeginUser;
  // Contacts: -lambda_n dg - lambda_t ds in the equilibrium rows, the NCP
  // functions in the multiplier rows.
  const double c_n = params_.ncp_scale * params_.young, c_t = c_n, mu_f = FrictionActive() ? params_.friction : 0.0;
  // Dual proximal term: -delta on the multiplier diagonal of the Newton matrix.
  // Redundant constraints (hyperstatic rigid contacts, a square lattice) leave
  // the multipliers indeterminate and the KKT matrix singular; with the term
  // a Newton step moves the indeterminate part by (row residual) / delta
  // (SetDualRegularization) and, like rho, it never enters the residual.
  const double dual_reg = DualRegularization();
  // Pseudo-transient term on the contact forces (SetAnchor with forces): the
  // kinematic rows (c_n g of a closed contact, c_t s of a sticking one) get
  // c chi (lambda - lambda_a). The anchor on the bodies alone freezes them
  // as rho grows while those rows still ask for an exact gap and slip: in a
  // cluster of rigid disks with more closed contacts than motions, the
  // kinematic error that a change of the active set leaves can then only be
  // absorbed by the forces, by amounts that grow with rho (up to 18 E <d> at
  // P/E 0.3 and rho = 1e5 E, with gaps of 1e-5 <d>). With the term the forces
  // are held by the anchor as the bodies are; it vanishes with rho, so
  // every accepted level is exact Coulomb and Signorini.
  const bool anchored = rho_anchor_ > 0.0 && lambda_anchor_.size() == candidates_.size();
  const double chi = anchored ? kMultiplierAnchor * rho_anchor_ / (params_.young * params_.young) : 0.0;
  if (values) jacobian_rows_.assign(2 * candidates_.size(), 0);
  LocalContact lc;
  for (size_t c = 0; c < candidates_.size(); ++c) {
    if (CandidateOwner(candidates_[c]) != rank_) continue;
    const PetscInt ln_dof = lam_off + static_cast<PetscInt>(c), lt_dof = tangential_index_[c];
    const double lam_n = z[ln_dof], lam_t = lt_dof >= 0 ? z[lt_dof] : 0.0;
    // Second derivatives enter the matrix only through the multipliers.
    ContactGeometry(candidates_[c], z, &lc, values && (lam_n != 0.0 || lam_t != 0.0));
    const PairKinematics &k = lc.k;
    const int nd = k.ndof;
    NormalNcp ncp = normal_ncp(params_.ncp, lam_n, k.gap, c_n, kTouchingGap * mean_diameter_ * c_n);
    TangentialNcp tan;
    if (lt_dof >= 0)
      tan = coulomb_ncp(lam_t, lam_n, k.gap, k.slip, mu_f, c_n, c_t, static_rows_ ? 0.0 : kSlipTie * c_t * mean_diameter_);
    if (active) {
      (*active)[c] = lt_dof >= 0 ? tan.state : (ncp.active ? kClosed : kOpen);
      switch_margin_[2 * c] = ncp.switch_margin;
      switch_margin_[2 * c + 1] = lt_dof >= 0 ? tan.switch_margin : 0.0;
      double slope = 0.0;
      for (int a = 0; a < nd; ++a)
        if (lc.dofs[a] >= 0) slope += std::abs(k.dgap[a]);
      gap_bound_[2 * c] = k.gap;
      gap_bound_[2 * c + 1] = slope;
      if (lt_dof >= 0) slip_now_[c] = k.slip;
    }
    // The anchor term's coefficients on this contact's kinematic rows (0 on force rows).
    const double anchor_n = ncp.d_lambda == 0.0 ? chi * ncp.d_gap : 0.0;
    const double anchor_t = lt_dof >= 0 && tan.state == kClosed ? chi * tan.d_slip : 0.0;
    if (F) {
      if (anchor_n != 0.0) F[ln_dof] += anchor_n * (lam_n - lambda_anchor_[c]);
      if (anchor_t != 0.0) F[lt_dof] += anchor_t * (lam_t - lambda_t_anchor_[c]);
      for (int a = 0; a < nd; ++a)
        if (lc.dofs[a] >= 0) F[lc.dofs[a]] -= lam_n * k.dgap[a] + lam_t * k.dslip[a];
      F[ln_dof] += ncp.value;
      if (lt_dof >= 0) F[lt_dof] += tan.value;
    }
    if (!need_K) continue;
    if (values) {
      // Which rows are identity rows (SymmetrizeNewtonMatrix, problem.hpp).
      jacobian_rows_[2 * c] = ncp.d_gap == 0.0 && ncp.d_lambda == 1.0 ? 1 : 2;
      if (lt_dof >= 0)
        jacobian_rows_[2 * c + 1] =
            tan.d_gap == 0.0 && tan.d_slip == 0.0 && tan.d_lambda_n == 0.0 && tan.d_lambda_t == 1.0 ? 1 : 2;
    }
    if (lc.curved)
      for (int a = 0; a < nd; ++a)
        for (int b = 0; b < nd; ++b)
          entry(lc.dofs[a], lc.dofs[b], -(lam_n * k.d2gap[a * nd + b] + lam_t * k.d2slip[a * nd + b]));
    for (int a = 0; a < nd; ++a) {
      entry(lc.dofs[a], ln_dof, -k.dgap[a]);
      entry(ln_dof, lc.dofs[a], ncp.d_gap * k.dgap[a]);
    }
    entry(ln_dof, ln_dof, ncp.d_lambda - dual_reg + anchor_n);
    if (lt_dof >= 0) {
      for (int a = 0; a < nd; ++a) {
        entry(lc.dofs[a], lt_dof, -k.dslip[a]);
        entry(lt_dof, lc.dofs[a], tan.d_gap * k.dgap[a] + tan.d_slip * k.dslip[a]);
      }
      entry(lt_dof, lt_dof, tan.d_lambda_t - dual_reg + anchor_t);
      entry(lt_dof, ln_dof, tan.d_lambda_n);
    }
  }
  PetscFunctionReturn(0);
}

std::vector<ContactForce> CompactionProblem::ContactForces() const {
  std::vector<ContactForce> out;
  std::vector<double> z(MultiplierOffset() + candidates_.size(), 0.0);
  std::copy(u_.begin(), u_.end(), z.begin());
  std::copy(w_, w_ + 4, z.begin() + WallOffset());
  LocalContact lc;
  for (size_t c = 0; c < candidates_.size(); ++c) {
    const ContactCandidate &cc = candidates_[c];
    ContactGeometry(cc, z.data(), &lc);
    ContactForce f;
    f.type = cc.type;
    f.gap = lc.k.gap;
    f.normal_multiplier = lambda_[c];
    f.tangential_multiplier = lambda_t_[c];
    f.slave_particle = SlaveParticle(cc);
    f.master_particle = MasterParticle(cc);
    if (lc.slave_xy >= 0) {
      // Generalized force on the slave's translation: lambda_n dg/dx + lambda_t ds/dx.
      for (int a = 0; a < lc.slave_nodes; ++a)
        for (int i = 0; i < 2; ++i)
          f.force[i] += lambda_[c] * lc.k.dgap[lc.slave_xy + 2 * a + i] + lambda_t_[c] * lc.k.dslip[lc.slave_xy + 2 * a + i];
      if (cc.type == ContactType::RigidRigid) {
        double xa[2];
        RigidPosition(cc.master, xa, nullptr);
        for (int i = 0; i < 2; ++i) f.point[i] = xa[i] + rigid_[cc.master].radius * lc.k.normal[i];
      } else {
        NodePosition(cc.body, bodies_[cc.body].mesh.boundary[cc.point], f.point);
      }
    } else {
      // Wall: the force on the body is lambda_n along the wall's inward normal.
      const int axis = WallBox::axis(cc.wall);
      const double sign = WallBox::inward_sign(cc.wall);
      f.wall = cc.wall;
      f.force[axis] = sign * lambda_[c];
      if (cc.type == ContactType::PointWall) {
        BoundaryPointPosition(cc.body, cc.point, f.point);
      } else {
        RigidPosition(cc.body, f.point, nullptr);
        f.point[axis] -= sign * rigid_[cc.body].radius;
      }
    }
    f.state = active_now_.size() == candidates_.size() ? static_cast<int>(active_now_[c]) : (lambda_[c] > 0.0 ? static_cast<int>(kClosed) : static_cast<int>(kOpen));
    out.push_back(f);
  }
  return out;
}

}  // namespace deformix

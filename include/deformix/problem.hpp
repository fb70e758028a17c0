// The global quasistatic problem: one PETSc SNES for everything.
//
// Unknowns z = (u, w, lambda): the nodal displacements u of every deformable
// disk, the four wall positions w, and one normal multiplier lambda_c per
// contact candidate. At imposed pressure P the equations are
//     R_u = f_int(u) - sum_c lambda_c dg_c/du             = 0   (body equilibrium)
//     R_w = dPi_P/dw - sum_c lambda_c dg_c/dw              = 0   (wall equilibrium)
//     R_c = C(lambda_c, g_c(u, w))                        = 0   (Signorini, NCP)
// i.e. the KKT conditions of  min  sum W(u) + P * box_area(w)  s.t.  g >= 0.
// The system is solved by semismooth Newton (SNESNEWTONLS, generalized
// Jacobian of the NCP function, MUMPS LU by default).
//
// Singular modes. A frictionless disk may rotate freely, and the whole
// assembly (walls + bodies) may translate: the tangent is singular along
// these modes (later also for rattlers and floating particles). The
// rotation of a frictionless deformable disk is a pure gauge of the
// continuum problem, but the discrete disk has orientation-dependent
// energy and Newton wanders along this nearly flat mode from roundoff,
// landing on different orientations (and packing fractions differing by
// ~0.2 % at 96 triangles) from run to run. By default (-constrain_rotation)
// the mean rotation of each such body is fixed by a Lagrange multiplier
// (a torque) that is zero at the symmetric equilibrium, and is reported. The
// Jacobian used for the Newton step is J + rho D, where D is the identity on
// the body and wall unknowns: this is a proximal term rho/2 |z - z_k|^2
// anchored at the current iterate z_k, so it changes the path but not the
// residual, and it vanishes at equilibrium (the converged z satisfies R = 0
// exactly). rho = prox_eta * E is tiny compared with the elastic stiffness, so
// Newton keeps its quadratic rate on every non-singular mode.
//
// Newton stops only when |R| is below tolerance AND the set of active
// contacts did not change in the last iteration (deal.II step-42's rule).
//
// Parallel layout: every rank keeps a replicated copy of the state for
// geometry (contact detection, observables); each rank assembles the
// elements and contacts of the bodies it owns. In this version all bodies and
// the walls are owned by rank 0 (distribution comes with the METIS issue).
#pragma once
#include <petscsnes.h>

#include <string>
#include <vector>

#include "deformix/contact_law.hpp"
#include "deformix/disk_mesh.hpp"
#include "deformix/hyperelastic_element.hpp"
#include "deformix/wall_box.hpp"

namespace deformix {

struct ProblemParameters {
  double young = 1.0;            // E
  double poisson = 0.495;        // nu
  NcpFunction ncp = NcpFunction::Min;
  double ncp_scale = 1.0;        // c_n = ncp_scale * E
  double prox_eta = 1e-8;        // rho = prox_eta * E
  double contact_margin = 0.1;   // candidate pairs: gap < margin * (mean diameter)
  PetscBool constrain_rotation = PETSC_TRUE;
  PetscBool secant_predictor = PETSC_TRUE;    // extrapolate the initial guess along the load path  // rotation gauge for frictionless deformable bodies
  PetscErrorCode SetFromOptions(MPI_Comm comm);
};

struct DeformableBody {
  DiskMesh mesh;
  double center[2] = {0.0, 0.0};  // reference position of the mesh origin
  PetscInt dof_offset = 0;        // first global unknown of this body
  std::vector<double> ref_cell_area;
  double ref_area = 0.0;
};

// A contact point on the boundary of a deformable body, as a fixed linear
// combination of nodes. For 3-node meshes it is a boundary node. For 6-node
// meshes it is a vertex node, or, for a mid-edge node, the Bezier control
// point of the parabolic edge a-m-b,
//     B = 2 x_m - (x_a + x_b) / 2.
// The edge lies in the convex hull of (x_a, B, x_b), so gaps >= 0 at these
// points mean that the whole curved boundary stays out of a flat wall, with
// exactly one constraint per boundary node (no over-constraint).
struct BoundaryPoint {
  int n = 1;
  int nodes[3] = {0, 0, 0};
  double coeff[3] = {1.0, 0.0, 0.0};
};
BoundaryPoint boundary_point(const DiskMesh &mesh, int boundary_index);

struct ContactCandidate {
  int body = 0;
  int point = 0;  // index into the body's mesh.boundary
  Wall wall = kLeft;
};

// Outcome of one nonlinear solve at fixed pressure.
struct SolveReport {
  bool converged = false;
  PetscInt newton_its = 0;
  SNESConvergedReason reason = SNES_CONVERGED_ITERATING;
  double residual = 0.0;
  int active_contacts = 0;
  int candidate_refreshes = 0;  // times the candidate set grew because a non-candidate penetrated
};

// Observables of the current state.
struct StateSummary {
  double box_width = 0.0, box_height = 0.0;
  double particle_area = 0.0, ref_particle_area = 0.0;
  double packing_fraction = 0.0;
  double area_ratio = 0.0;                 // current / initial particle area
  double min_cell_area_ratio = 0.0;        // smallest element area change (inversion watch)
  double max_penetration = 0.0;            // max over boundary nodes and walls of -g (<= 0 means none)
  double wall_force[4] = {0, 0, 0, 0};     // sum of multipliers on each wall
  double min_multiplier = 0.0;             // most negative multiplier (>= -tol)
  double max_complementarity = 0.0;        // max |lambda g| over candidates
  double max_gauge_torque = 0.0;           // max |mu_b| of the rotation gauges (0 at a true equilibrium)
  int active_contacts = 0;
};

class CompactionProblem {
 public:
  explicit CompactionProblem(MPI_Comm comm);
  ~CompactionProblem();
  CompactionProblem(const CompactionProblem &) = delete;
  CompactionProblem &operator=(const CompactionProblem &) = delete;

  PetscErrorCode SetParameters(const ProblemParameters &p);
  // Adds a deformable disk whose mesh origin sits at (cx, cy); returns its index.
  int AddDeformableBody(const DiskMesh &mesh, double cx, double cy);
  // Places the walls (x_left, x_right, y_bottom, y_top).
  void SetWalls(const double w[4]);

  // Solves equilibrium at pressure P starting from the current state. On
  // success the state is updated; on failure it is left unchanged.
  PetscErrorCode Solve(double pressure, SolveReport *report);

  // Copy / restore of the state (for step cut-backs).
  struct State {
    std::vector<double> u;
    double w[4];
    std::vector<double> lambda;  // aligned with candidates
    std::vector<double> torque;
    std::vector<ContactCandidate> candidates;
  };
  State SaveState() const;
  void RestoreState(const State &s);

  StateSummary Summary() const;
  const std::vector<DeformableBody> &Bodies() const { return bodies_; }
  const std::vector<double> &Displacements() const { return u_; }
  const double *Walls() const { return w_; }
  const ProblemParameters &Parameters() const { return params_; }
  const NeoHookean &Material() const { return material_; }
  double Pressure() const { return pressure_; }
  // Current coordinates of node a of body b.
  void NodePosition(int b, int a, double x[2]) const;
  // Current coordinates of boundary point i of body b (see BoundaryPoint).
  void BoundaryPointPosition(int b, int i, double x[2]) const;
  // Per-cell current/reference area ratio of body b (volumetric strain J - 1 on average).
  std::vector<double> CellAreaRatio(int b) const;

  // Test access: residual and Jacobian of the current layout at z.
  PetscErrorCode CreateGlobalVector(Vec *z);
  PetscErrorCode PackState(Vec z) const;
  PetscErrorCode EvaluateResidual(Vec z, Vec F);
  PetscErrorCode EvaluateJacobian(Vec z, Mat *J);  // J is created and owned by the caller
  void SetPressure(double P) { pressure_ = P; }
  PetscErrorCode RefreshCandidates();  // rebuild the candidate list from the current state
  const std::vector<ContactCandidate> &Candidates() const { return candidates_; }
  const std::vector<double> &Multipliers() const { return lambda_; }
  // Active flags of the candidates at the last residual evaluation.
  const std::vector<char> &ActiveSet() const { return active_now_; }

 private:
  friend PetscErrorCode FormFunction(SNES, Vec, Vec, void *);
  friend PetscErrorCode FormJacobian(SNES, Vec, Mat, Mat, void *);
  friend PetscErrorCode ConvergenceTest(SNES, PetscInt, PetscReal, PetscReal, PetscReal, SNESConvergedReason *, void *);

  struct Assembly;  // shared residual / Jacobian pattern / Jacobian values walk
  PetscErrorCode SetUpLayout();      // sizes, Vec/Mat/SNES for the current candidate set
  PetscErrorCode DestroySolver();
  PetscErrorCode Gather(Vec z);      // z -> replicated zall_ array
  PetscErrorCode Assemble(const double *z, double *F, std::vector<PetscInt> *ci, std::vector<PetscInt> *cj,
                          std::vector<PetscScalar> *cv, bool *inverted, std::vector<char> *active);
  void Unpack(const double *z);
  void Pack(double *z) const;
  std::vector<ContactCandidate> DetectCandidates(double margin) const;
  bool OwnsEverything() const { return rank_ == 0; }

  MPI_Comm comm_;
  PetscMPIInt rank_ = 0, size_ = 1;
  ProblemParameters params_;
  NeoHookean material_;
  std::vector<DeformableBody> bodies_;
  PetscInt n_body_dofs_ = 0;
  PetscInt MultiplierOffset() const { return n_body_dofs_ + 4 + static_cast<PetscInt>(torque_.size()); }
  std::vector<double> torque_;  // rotation-gauge multipliers, one per constrained body
  std::vector<double> u_;  // body displacements (replicated)
  double w_[4] = {0, 0, 0, 0};
  double pressure_ = 0.0;
  State previous_;                 // last converged state before the current one (predictor)
  double previous_pressure_ = 0.0;
  bool have_previous_ = false;
  double mean_diameter_ = 1.0;
  std::vector<ContactCandidate> candidates_;
  std::vector<double> lambda_;

  // Solver objects for the current layout.
  PetscInt n_total_ = -1;
  Vec z_ = nullptr, r_ = nullptr, zall_ = nullptr;
  VecScatter to_all_ = nullptr;
  Mat J_ = nullptr;
  SNES snes_ = nullptr;
  std::vector<char> active_now_, active_checked_;
  bool inverted_ = false;
  double fnorm0_ = 0.0;
  std::vector<PetscScalar> coo_values_;
};

}  // namespace deformix

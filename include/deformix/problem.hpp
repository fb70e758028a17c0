// The global quasistatic problem: one PETSc SNES for everything.
//
// Unknowns z = (u, w, mu, s, lambda_n, lambda_t):
//   u         body unknowns, contiguous per particle in particle order:
//             nodal displacements of each deformable disk, and the centre
//             displacement (plus the rotation when friction is on) of each
//             rigid disk;
//   w         the four wall positions;
//   mu        rotation gauges of frictionless deformable disks (optional);
//   s         three per deformable disk: its rigid translation and rotation
//             under the pseudo-transient anchor (zero without it; Assemble);
//   lambda_n  one normal multiplier per contact candidate;
//   lambda_t  one tangential multiplier per frictional candidate.
// At imposed pressure P the equations are
//   R_u  = f_int(u) - sum_c (lambda_n,c dg_c/du + lambda_t,c ds_c/du)   = 0
//   R_w  = dPi_P/dw - sum_c lambda_n,c dg_c/dw                          = 0
//   R_n  = C_n(lambda_n, g)                  (Signorini, contact_law.hpp)
//   R_t  = C_t(lambda_t, lambda_n, g, s)     (Coulomb, contact_law.hpp)
// i.e. the KKT conditions of min sum W(u) + P * box_area(w) under g >= 0
// with incremental Coulomb friction on the slip s over the load step. This
// class is the operator: state, residual, Newton matrix (the generalized
// Jacobian of the NCP functions) and its MUMPS LU (by default); the level
// solvers (level_solver.hpp) drive it by semismooth Newton.
//
// Contact pairs (pair_kinematics.hpp, wall_box.hpp): a boundary point of a
// deformable disk against a wall, a rigid disk against a wall, rigid-rigid,
// rigid disk against a boundary node of a deformable disk, and a boundary
// node of one deformable disk against the boundary of another: by default
// the node's own gap (curve_node; -contact_deformable nts or two_pass), or
// the node's gap averaged over its cell of the slave boundary (mortar_node,
// -contact_deformable mortar, the compact driver's default), both against the smooth curve through the
// master's boundary nodes, so the contact may slide over a segment inside
// one solve with a C1 gap. Walls are frictionless.
//
// Singular modes. Rattlers, the free rotation of frictionless disks and the
// translation of the whole assembly (walls + bodies) make the tangent
// singular. The Jacobian used for the Newton step is J + rho D, D the
// identity on body and wall unknowns (r^2 on rigid rotations): a proximal
// term rho/2 |z - z_k|^2 anchored at the current iterate z_k. It changes the
// Newton path but not the residual, so it vanishes at equilibrium (the
// converged z satisfies R = 0 exactly), and rho = prox_eta * E is tiny
// compared with the elastic stiffness, so Newton keeps its quadratic rate on
// every non-singular mode. Its dual counterpart, -prox_eta on the multiplier
// diagonal, makes hyperstatic contact networks (redundant constraints,
// indeterminate forces) solvable the same way.
// The rotation of a frictionless deformable disk is a pure gauge of the
// continuum problem, but the discrete disk has orientation-dependent energy
// and Newton wanders along this nearly flat mode from roundoff, landing on
// different orientations (and packing fractions differing by ~0.2 % at 96
// triangles) from run to run. With -constrain_rotation the mean rotation of
// each such body is fixed by a Lagrange multiplier (a torque) that is zero
// at the symmetric equilibrium of the single-particle test, and is reported.
//
// Packings (ptc_move > 0): the pseudo-transient term rho D (z - z_anchor)
// on the body and wall rows (with the rigid modes of deformable disks held
// as a rigid disk's, through s), and its counterpart on the contact forces
// (-ptc_anchor_forces, default true; SetAnchor), which the level solvers drive.
//
// Parallel layout. Particles are the unit of ownership: METIS partitions the
// particle graph (vertices weighted by unknowns, edges = contact candidates;
// partition.hpp) and a rank owns all unknowns of its particles, the gauges
// and rigid modes s of its deformable disks and the multipliers of the contacts whose slave it
// owns; rank 0 owns the walls. The code works in the "natural" numbering
// described above (independent of the number of ranks, so results are too,
// to round-off); the distributed PETSc numbering lists each rank's unknowns
// contiguously, in natural order, and is used only at the Vec/Mat interface
// (petsc_of_ / natural_of_). Every rank keeps a replicated copy of the state
// for geometry (contact detection, observables), refreshed through a
// scatter; each rank assembles the elements of its particles and its
// contacts, the residual contributions are summed into the distributed
// residual by the reverse scatter and the Jacobian entries go through
// MatSetValuesCOO (entries of rows owned elsewhere are sent by PETSc).
// The partition is recomputed with each new candidate layout when METIS
// finds an edge cut smaller by -repartition_tol or the load imbalance
// exceeds 1 + repartition_tol (the replicated state makes the migration a
// renumbering).
#pragma once
#include <petscsnes.h>

#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "deformix/contact_detection.hpp"
#include "deformix/contact_law.hpp"
#include "deformix/disk_mesh.hpp"
#include "deformix/hyperelastic_element.hpp"
#include "deformix/packing.hpp"
#include "deformix/pair_kinematics.hpp"
#include "deformix/wall_box.hpp"

namespace deformix {

// Contact law of a pair of deformable disks (-contact_deformable):
//   NodeToSegment  the boundary nodes of the higher-numbered disk (the slave)
//                  against the other's contact curve (curve_node);
//   TwoPass        the same both ways, each disk's nodes against the other's curve;
//   Mortar         each slave node's gap averaged over its cell of the slave
//                  boundary (mortar_node).
enum class DeformableContact : int { NodeToSegment = 0, TwoPass = 1, Mortar = 2 };

// Initial guess of a load step (BeginLoadStep): the last converged state,
// or that state plus its tangent dz/dP times the load increment.
enum class LoadPredictor : int { None = 0, Tangent = 1 };

struct ProblemParameters {
  double young = 1.0;            // E
  double poisson = 0.495;        // nu
  double friction = 0.0;         // Coulomb coefficient between particles (walls are frictionless)
  NcpFunction ncp = NcpFunction::Min;
  double ncp_scale = 1.0;        // c_n = c_t = ncp_scale * E
  double prox_eta = 1e-8;        // smallest rho / E
  double ptc_move = 0.0;         // pseudo-transient continuation: move per pseudo-time step / <d> (0: plain Newton)
  PetscInt ptc_easy_its = 8;     // the move grows by 1.25 after an inner solve of at most this many Newton iterations
  PetscInt ptc_stall_its = 4;     // an inner solve short of its 100-fold residual drop after this many Newton iterations is cut short
  PetscInt ptc_max_steps = 1000; // pseudo-time steps per sub-step before it counts as failed
  PetscBool ptc_anchor_forces = PETSC_TRUE;  // anchored: the contact forces of closed and sticking contacts anchored too (SetAnchor)
  double level_force_rtol = 0.0; // accept |F|_inf <= this x P <d> with phi settled (0: exact equilibrium only)
  double level_phi_rtol = 1e-4;  // the paper's criterion: relative change of phi in the last pseudo-time step
  double contact_margin = 0.1;   // candidate pairs: gap < margin * (mean diameter)
  DeformableContact deformable_contact = DeformableContact::NodeToSegment;  // law of deformable-deformable pairs
  PetscBool constrain_rotation = PETSC_TRUE;  // rotation gauge for frictionless deformable bodies
  LoadPredictor predictor = LoadPredictor::None;  // initial guess of a load step (-predictor)
  double repartition_tol = 0.1;  // repartition when the new edge cut is smaller by this fraction or the imbalance exceeds 1 + this (< 0: never)
  PetscBool partition_view = PETSC_FALSE;     // print edge cut and imbalance of every (re)partition
  double progress_interval = 60.0;  // seconds between progress lines within a long sub-step (0: every pseudo-time step, < 0: none)
  PetscErrorCode SetFromOptions(MPI_Comm comm);
};

struct DeformableBody {
  DiskMesh mesh;
  double center[2] = {0.0, 0.0};  // reference position of the mesh origin
  PetscInt dof_offset = 0;        // first global unknown of this body
  std::vector<double> ref_cell_area;
  double ref_area = 0.0;
  int particle = 0;               // index in the particle list
};

struct RigidBody {
  double center[2] = {0.0, 0.0};  // reference position of the centre
  double radius = 0.5;
  PetscInt dof_offset = 0;        // (u_x, u_y[, theta])
  int particle = 0;
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

// Force of one contact at the current state, for observables.
struct ContactForce {
  ContactType type;
  int slave_particle = -1, master_particle = -1;  // master -1: a wall
  int wall = -1;                                  // the wall (Wall) of a wall contact, -1 otherwise
  double force[2] = {0, 0};   // force on the slave (translational part)
  double point[2] = {0, 0};   // contact point
  double normal_multiplier = 0, tangential_multiplier = 0;
  double gap = 0;
  int state = 0;              // 0 open, 1 closed (stick / frictionless), 2 sliding
};

// Outcome of one nonlinear solve at fixed pressure.
struct SolveReport {
  bool converged = false;
  PetscInt newton_its = 0;
  SNESConvergedReason reason = SNES_CONVERGED_ITERATING;
  double residual = 0.0;
  int active_contacts = 0;
  int candidate_refreshes = 0;  // re-solves because a non-candidate penetrated or a node changed segment
  int inner_solves = 0;         // SNES solves (pseudo-transient steps and re-solves included)
  double force_residual = 0.0;  // largest unbalanced force at the accepted state (PTC only)
  bool relaxed = false;         // accepted by the paper's criterion (level_force_rtol), not at |R| <= atol
  int layouts = 0;              // new unknown layouts (each one a new sparsity pattern: symbolic factorization)
  int factorizations = 0;       // numeric factorizations of the Newton matrix (the tangent predictor's included)
};

// Sizes of the current unknown layout: what the scene needs and nothing else
// (no tangential unknowns without friction, no rigid unknowns at kappa = 1, ...).
struct LayoutSizes {
  PetscInt total = 0;
  PetscInt deformable = 0;   // nodal displacements of deformable disks
  PetscInt rigid = 0;        // rigid-disk unknowns (2 or 3 per disk)
  PetscInt gauges = 0;       // rotation gauges
  PetscInt normal = 0;       // normal multipliers (= contact candidates)
  PetscInt tangential = 0;   // tangential multipliers
  PetscInt jacobian_nonzeros = 0;
};

// Observables of the current state.
struct StateSummary {
  double box_width = 0.0, box_height = 0.0;
  double particle_area = 0.0, ref_particle_area = 0.0;
  double deformable_area = 0.0, ref_deformable_area = 0.0;
  double packing_fraction = 0.0;
  double area_ratio = 0.0;                 // current / initial particle area
  double min_cell_area_ratio = 0.0;        // smallest element area change (inversion watch)
  double max_penetration = 0.0;            // max over boundary points and walls, and over candidates, of -g
  double wall_force[4] = {0, 0, 0, 0};     // sum of normal multipliers on each wall
  double min_multiplier = 0.0;             // most negative normal multiplier (>= -tol)
  double max_complementarity = 0.0;        // max |lambda_n g| over candidates
  double max_gauge_torque = 0.0;           // largest torque of the rotation gauges, mu_b * mean |X|^2 (0 at a true equilibrium)
  int active_contacts = 0;                 // candidates with lambda_n > 0
  int sliding_contacts = 0;
};

// Numeric factorization of the operators of ksp (a layout's MUMPS LU; the
// symbolic analysis is reused while the sparsity pattern holds). Collective:
// *ok when every rank factored it; *out_of_memory when MUMPS ran out of its
// workspace on a rank (INFOG(1) = -9: CompactionProblem::GrowFactorWorkspace,
// then a new Layout); *reason this rank's.
PetscErrorCode FactorOnEveryRank(KSP ksp, bool *ok, bool *out_of_memory = nullptr, PCFailedReason *reason = nullptr);

class CompactionProblem {
 public:
  explicit CompactionProblem(MPI_Comm comm);
  ~CompactionProblem();
  CompactionProblem(const CompactionProblem &) = delete;
  CompactionProblem &operator=(const CompactionProblem &) = delete;

  // Parameters first, then bodies (the friction decides the rigid unknowns).
  PetscErrorCode SetParameters(const ProblemParameters &p);
  // Adds a deformable disk whose mesh origin sits at (cx, cy); returns its index.
  int AddDeformableBody(const DiskMesh &mesh, double cx, double cy);
  // Adds a rigid disk; returns its index.
  int AddRigidBody(double cx, double cy, double radius);
  // Adds every disk of a packing (deformable ones as copies of unit_mesh, a
  // mesh of the unit-radius disk, scaled to their radius) and its walls;
  // returns the number of deformable disks.
  int AddPacking(const DiskPacking &packing, const DiskMesh &unit_mesh);
  // Places the walls (x_left, x_right, y_bottom, y_top).
  void SetWalls(const double w[4]);

  // ---- What a level solver (level_solver.hpp) drives: the operator. ----
  // Starts a load step to pressure P: saves the state (EndLoadStep(false)
  // restores it), predicts the new state along the load path (with
  // `predictor`, halved while bodies would overlap by more than
  // overlap_limit <d>), scales the multipliers with the pressure and
  // refreshes the contact candidates.
  PetscErrorCode BeginLoadStep(double pressure) { return BeginLoadStep(pressure, params_.predictor, kPredictionOverlap); }
  PetscErrorCode BeginLoadStep(double pressure, LoadPredictor predictor, double overlap_limit);
  // The deepest overlap of a predicted state, in <d>, for strategies whose
  // first steps are strongly damped (anchored).
  static constexpr double kPredictionOverlap = 1e-3;
  // How far a Newton step may drive an open contact into penetration, in
  // <d> (ContactStepFraction): the next linearization closes it. The energy
  // merit penalizes only penetration beyond it (ContactPenalty).
  static constexpr double kOpenOvershoot = 1e-3;
  // A pair that is no candidate and has come within this fraction of the
  // candidate margin is approaching (CandidatesStale): the solvers refresh
  // the candidates then, before the pair can close unseen.
  static constexpr double kApproachFraction = 0.5;
  // Gaps within this many <d> of zero are round-off of a touching contact:
  // a contact without force there has the row of a closed one (normal_ncp's tie).
  static constexpr double kTouchingGap = 1e-12;
  // Trial tangential forces within c_t x this many <d> of the Coulomb cone
  // take the slip row (coulomb_ncp's tie): 10 to 100 times the tangential
  // residual that an inexact pseudo-time step leaves, far below the level's
  // tolerance on forces.
  static constexpr double kSlipTie = 1e-8;
  // The contact forces' share of the pseudo-transient anchor (SetAnchor): a
  // closed or sticking contact's gap or slip may differ from its row's zero
  // by chi (lambda - lambda_a), chi = kMultiplierAnchor rho / E^2, during a
  // pseudo-time step (docs/level-solver-measurements.md, "Measured: the
  // contact forces in the anchor").
  static constexpr double kMultiplierAnchor = 0.1;
  // A state the first Newton step of a load step can start from: no element
  // inverted, no overlap deeper than overlap_limit <d> (BeginLoadStep).
  bool PredictionAdmissible(double overlap_limit) const;
  // Ends the load step: a converged one becomes the predictor's last state
  // (report: converged, layouts, active contacts); a failed one is undone.
  PetscErrorCode EndLoadStep(bool converged, SolveReport *report);
  // The Vec/Mat objects of the current candidate layout (created when
  // missing; owned by the problem, replaced when the candidates change).
  // z holds the state after the call.
  PetscErrorCode Layout(Vec *z, Vec *F, Mat *J, KSP *ksp);
  // MUMPS ran out of workspace (INFOG(1) = -9): the next layout reserves
  // twice as much (the current one is destroyed). False when already at the cap.
  bool GrowFactorWorkspace();
  int LayoutsCreated() const { return layouts_created_; }
  // Numeric factorizations made by the tangent predictor so far (SolveLevel
  // counts those of its load steps in its report).
  int PredictorFactorizations() const { return predictor_factorizations_; }
  // Residual F(z) (exact NCP rows; plus the anchor term of SetAnchor) and
  // the Newton matrix J(z) + diag(ProximalDiagonal) in J (the matrix of Layout()).
  PetscErrorCode Residual(Vec z, Vec F) { return EvaluateResidual(z, F); }
  PetscErrorCode NewtonMatrix(Vec z, Mat J);
  // Pseudo-transient anchor: with rho > 0 the residual gets rho D (z - z_a)
  // on the body and wall rows, z_a the current state, and with forces also
  // the kinematic contact rows (a closed contact's c_n g, a sticking one's
  // c_t s) get the compliance term c chi (lambda - lambda_a),
  // chi = kMultiplierAnchor rho / E^2 (contact_pairs.cpp); the Newton matrix
  // gets their derivatives. rho = 0 removes both (EndLoadStep does), so an
  // equilibrium is the same with or without them.
  void SetAnchor(double rho, bool forces = false);
  double AnchorWeight() const { return rho_anchor_; }
  // The dual proximal term -delta on the multiplier diagonal of the Newton
  // matrix (contact_pairs.cpp): prox_eta unless set smaller here, until
  // EndLoadStep. In a hyperstatic cluster the indeterminate contact forces
  // move by (contact row residual) / delta per Newton step; anchored's end
  // game (level_solver.cpp) lowers delta so that they move by about P <d>.
  void SetDualRegularization(double delta) { dual_reg_ = std::min(delta, params_.prox_eta); }
  double DualRegularization() const { return dual_reg_ < 0.0 ? params_.prox_eta : dual_reg_; }
  // The enthalpy H = sum of the deformable disks' strain energies + P x box
  // area at the last residual evaluation (+inf where an element inverted):
  // frictionless equilibria are its constrained stationary points (the
  // rows of F); the energy merit of newton is built on it.
  double Merit() const { return merit_; }
  // The contact part of the energy merit of the newton strategy
  // (level_solver.hpp, -level_merit energy). LagContactWeights fixes, from
  // the current state's multipliers, the Tresca bound mu lambda_n,c of every
  // frictional candidate (friction with lagged normal forces); then, at the
  // last residual evaluation, ContactPenalty gives the penetration
  // sum_c max(0, -g_c - kOpenOvershoot <d>) and the dissipation
  // sum_c mu lambda_n,c |s_c|, s_c the incremental slip of the load step.
  // Merit() + nu x penetration + dissipation is the incremental potential of
  // the frictional problem with the normal forces lagged, its penetration
  // penalized exactly for nu above every normal force, except for the
  // overshoot that a step may leave to the next linearization (a contact
  // that opened to round-off and is driven back in raises an l1 penalty at
  // first order: the merit would stop the step that closes it, the Maratos
  // effect of SQP's l1 merit). Collective; the bounds are lost with the
  // candidates.
  PetscErrorCode LagContactWeights();
  PetscErrorCode ContactPenalty(double *penetration, double *dissipation) const;
  // Largest normal multiplier of z (collective).
  PetscErrorCode LargestNormalMultiplier(Vec z, double *largest) const;
  // Prefix of the options of this problem's solvers (KSP, PC, and the level
  // solver's SNES): e.g. "settle_" for -settle_snes_*, -settle_ksp_*. Empty
  // by default (-snes_*, -ksp_*). Takes effect with the next layout.
  void SetOptionsPrefix(const std::string &prefix) { options_prefix_ = prefix; }
  const std::string &OptionsPrefix() const { return options_prefix_; }
  // Diagonal added by NewtonMatrix (floor) and the weights D of a shift on
  // the body and wall rows (1, r^2 on rigid rotations, 0 on other rows).
  PetscErrorCode ShiftDiagonals(Vec floor, Vec weight) const;
  // z becomes the state of the problem (replicated on every rank).
  PetscErrorCode AdoptState(Vec z);
  // True when a non-candidate pair penetrates or a node left its segment
  // window at the current state: RefreshCandidates, then continue. With
  // approaching, also whether a pair that is no candidate has come within
  // kApproachFraction x -contact_margin <d> (still open: a refresh then
  // leaves the contact states as they are, and the pair is seen by the
  // linearizations before it closes).
  PetscErrorCode CandidatesStale(bool *stale, bool *approaching = nullptr) const;
  // Whether the detection finds a pair closer than margin <d> (negative: an
  // overlap) that is not a contact candidate.
  bool DetectsNonCandidate(double margin) const;
  // Largest fraction (>= 1/10) of the update dz that does not drive a contact
  // (open or touching) deeper than kOpenOvershoot <d> into penetration; needs
  // the residual last evaluated at the iterate.
  PetscErrorCode ContactStepFraction(Vec dz, double *fraction);
  // The last residual evaluation met an inverted element.
  bool Inverted() const { return inverted_; }
  // Largest unbalanced force of a residual (body and wall rows, torques /
  // radius) and the natural index of its unknown (-1 if none).
  PetscErrorCode ForceResidual(Vec F, double *force, PetscInt *where = nullptr) const;
  // What a natural unknown is, for monitors: "wall", "deformable particle 3
  // node 12", "rigid particle 5 dof 2", "gauge", "lambda_n", "lambda_t".
  std::string DescribeUnknown(PetscInt natural) const;
  // Natural index of a PETSc index.
  PetscInt NaturalIndex(PetscInt petsc) const { return natural_of_[petsc]; }
  // Natural index of contact candidate c's tangential multiplier (the order
  // of ContactForces), -1 if it has none.
  PetscInt TangentialUnknown(size_t c) const { return tangential_index_[c]; }
  // Prints (PetscSynchronizedPrintf, each rank its own contacts) every
  // contact whose state differs from `before`, with its multipliers, gap and
  // slip at the last residual evaluation; collective.
  PetscErrorCode PrintChangedContacts(const std::vector<char> &before) const;
  // The trial state of an update d: zt = z + d, except that the mean rotation
  // theta of each deformable body's increment (about its centroid) is applied
  // as a finite rotation R(theta) instead of its linearization I + theta J.
  // A linearized rotation of a nearly incompressible disk changes its area by
  // theta^2 and costs lambda theta^2 of pressure, so along the free rotation
  // of a frictionless disk a Newton step would be valid only for theta <<
  // sqrt(|F| / lambda); with the rotation applied exactly it is not limited.
  PetscErrorCode RotatedUpdate(Vec z, Vec d, Vec zt) const;
  // The largest move of a body in step s from z, split into its rigid
  // translation, its rotation times the radius, and the largest nodal
  // deviation from the body's rigid motion (deformation); for -level_monitor.
  PetscErrorCode StepMoves(Vec z, Vec s, double moves[3]) const;
  // Balance of a residual F at the problem's state, for the level criterion:
  // the largest net force and net torque (about its centroid) on a body, the
  // largest nodal or wall force (torques of rigid rotations / radius), and the
  // largest contact row. Collective.
  struct Balance {
    double body_force = 0.0, body_torque = 0.0, node_force = 0.0, contact_row = 0.0;
    int body_force_particle = -1;  // the particle with the largest net force
    bool body_force_deformable = false;
  };
  PetscErrorCode BodyBalance(Vec F, Balance *balance) const;
  // The balance of the current state's residual (collective).
  PetscErrorCode StateBalance(Balance *balance);
  // 2-norms of the blocks of a residual: body, wall, gauge, normal-contact and tangential rows.
  PetscErrorCode ResidualBlocks(Vec F, double norm[5]) const;
  // Largest |contact state switch margin| of the contacts whose state differs
  // between `was` and the last residual evaluation (0: none changed); collective.
  PetscErrorCode ChangedStateMargin(const std::vector<char> &was, double *margin) const;

  // Copy / restore of the state (for step cut-backs).
  struct State {
    std::vector<double> u;
    double w[4] = {0, 0, 0, 0};
    std::vector<double> lambda;    // normal multipliers, aligned with candidates
    std::vector<double> lambda_t;  // tangential multipliers, aligned with candidates (0 when frictionless)
    std::vector<double> torque;
    std::vector<ContactCandidate> candidates;
  };
  State SaveState() const;
  void RestoreState(const State &s);

  // Everything a restart needs to continue a run exactly where it stopped
  // (checkpoint.hpp): the state, its pressure and whether a load step has
  // converged before (the tangent predictor's condition). The solver
  // objects are rebuilt from it.
  struct Snapshot {
    State current;
    double pressure = 0.0;
    bool have_previous = false;
  };
  Snapshot TakeSnapshot() const;
  // Fails (PETSC_ERR_FILE_UNEXPECTED) when the snapshot does not fit the
  // bodies added (unknown counts, candidates naming bodies or points that do
  // not exist), i.e. was taken from another scene. Builds the restored
  // state's layout (collective).
  PetscErrorCode RestoreSnapshot(const Snapshot &s);

  StateSummary Summary() const;
  // Summary().packing_fraction without the contact and penetration checks.
  double PackingFraction() const;
  LayoutSizes Sizes();
  std::vector<ContactForce> ContactForces() const;
  const std::vector<DeformableBody> &Bodies() const { return bodies_; }
  const std::vector<RigidBody> &RigidBodies() const { return rigid_; }
  int NumParticles() const { return static_cast<int>(bodies_.size() + rigid_.size()); }
  const std::vector<double> &Displacements() const { return u_; }
  const double *Walls() const { return w_; }
  const ProblemParameters &Parameters() const { return params_; }
  const NeoHookean &Material() const { return material_; }
  double Pressure() const { return pressure_; }
  double MeanDiameter() const { return mean_diameter_; }
  bool Frictional() const { return params_.friction > 0.0; }
  // Current coordinates of node a of body b.
  void NodePosition(int b, int a, double x[2]) const;
  // Current coordinates of boundary point i of body b (see BoundaryPoint).
  void BoundaryPointPosition(int b, int i, double x[2]) const;
  // Current centre (and rotation, 0 without friction) of rigid body r.
  void RigidPosition(int r, double x[2], double *theta) const;
  // Current centroid (mean node position) of deformable body b.
  void BodyCentroid(int b, double x[2]) const;
  // Per-cell current/reference area ratio of body b (volumetric strain J - 1 on average).
  std::vector<double> CellAreaRatio(int b) const;

  // Test access: residual and Jacobian of the current layout at z.
  PetscErrorCode CreateGlobalVector(Vec *z);
  PetscErrorCode PackState(Vec z) const;
  PetscErrorCode EvaluateResidual(Vec z, Vec F);
  PetscErrorCode EvaluateJacobian(Vec z, Mat *J);  // J is created and owned by the caller
  void SetPressure(double P) { pressure_ = P; }
  // Switches the Coulomb coefficient between 0 and its value without changing
  // the unknowns (the protocol: settle the packing frictionless, then turn
  // friction on).
  void SetFrictionActive(bool on) { friction_on_ = on; }
  // Friction acts in this load step: a frictional packing, out of its frictionless settling level.
  bool FrictionActive() const { return Frictional() && friction_on_; }
  // Makes the current state the reference of the incremental slip: the
  // start of the load step, or of a pseudo-time step (level_solver.hpp).
  void MarkStepStart() { u_start_ = u_; }
  // The residual at z (no anchor term) with the slip measured from z itself,
  // as the first residual of a pseudo-time step anchored at z would be,
  // except that the Coulomb rows take no slip tie (kSlipTie): its contact
  // rows are exactly the static conditions (Signorini; the tangential force
  // within the Coulomb cone, and a force inside the cone by less than the
  // tie is within it). The slip reference and the anchor are left as they
  // were; the contact states are those of this evaluation. Collective.
  PetscErrorCode ResidualFromHere(Vec z, Vec F);
  PetscErrorCode RefreshCandidates();  // rebuild the candidate list from the current state
  // Candidates within margin x <d> at the current state: all of them (gathered
  // on every rank; collective), or those found by this rank's narrow phase
  // (the pairs whose slave particle it owns).
  std::vector<ContactCandidate> DetectCandidates(double margin) const;
  std::vector<ContactCandidate> DetectOwnCandidates(double margin) const;
  const std::vector<ContactCandidate> &Candidates() const { return candidates_; }
  const std::vector<double> &Multipliers() const { return lambda_; }
  const std::vector<double> &TangentialMultipliers() const { return lambda_t_; }
  // What the Newton matrix adds to the Jacobian of the residual on diagonal
  // entry i: prox_eta E (r^2 times that on rigid rotations) on body and wall
  // unknowns, -prox_eta on multipliers (the anchor terms are in the residual).
  double ProximalDiagonal(PetscInt i) const;
  // Contact states (0 open, 1 closed/stick, 2 sliding) at the last residual evaluation.
  const std::vector<char> &ActiveSet() const { return active_now_; }

  // ---- The symmetric form of the Newton matrix (symmetric_newton.cpp). ----
  // Without friction and with the min NCP rows, the Newton matrix J of
  // NewtonMatrix is symmetric up to its multiplier rows: an active normal
  // row reads c_n dg (its column in the body rows -dg), an inactive one
  // d lambda = -lambda (its column still -dg), a rotation gauge row
  // (E / R) G (its column -G). Row operations that keep the solution make it
  // symmetric: the inactive multipliers' steps are known, so their columns
  // move to the right-hand side (L), and active and gauge rows are scaled by
  // -1 / c_n and -R / E (S):
  //     J_s = S L J,  J_s d = S L b  <=>  J d = b,
  // with the body and wall block, and so the curvature of any step, unchanged.
  // J_s is factored by MUMPS LDL^T (SymmetricKsp), cheaper than LU
  // (docs/level-solver-measurements.md, "Measured: LDL^T against LU").
  // SymmetrizeNewtonMatrix turns J (NewtonMatrix's, not yet shifted) into
  // J_s and keeps what SymmetricRhs needs; *done is false, and J unchanged,
  // where the form does not apply (friction acting, Fischer-Burmeister
  // rows). Collective.
  PetscErrorCode SymmetrizeNewtonMatrix(Mat J, bool *done);
  // bs = S L b for the last SymmetrizeNewtonMatrix.
  PetscErrorCode SymmetricRhs(Vec b, Vec bs);
  // A KSP with MUMPS LDL^T (PCCHOLESKY, MUMPS SYM = 2) on the Newton matrix
  // of Layout, for J_s (options prefix: the problem's then "ldlt_").
  PetscErrorCode SymmetricKsp(KSP *ksp);
  // Rank owning each particle (empty on one rank: everything is rank 0's); PETSc index of a natural unknown.
  const std::vector<int> &ParticleOwners() const { return particle_owner_; }
  PetscInt PetscIndex(PetscInt natural) const { return petsc_of_[natural]; }

 private:
  // The tangent predictor of BeginLoadStep: the state becomes z + t dP dz/dP
  // with the largest admissible t in 1, 1/2, ..., 1/16 (*applied), or stays z.
  PetscErrorCode TangentPredictor(double dP, double overlap_limit, bool *applied);
  // Kinematics of one candidate at state z, on at most kMaxDofs global unknowns (-1: absent).
  struct LocalContact {
    PairKinematics k;
    PetscInt dofs[PairKinematics::kMaxDofs];
    bool frictional = false;
    bool curved = false;   // the gap / slip have second derivatives
    int slave_xy = 0;      // local index of the slave's x unknown (force on the slave)
    int slave_nodes = 1;   // slave nodes from slave_xy on (mortar: 5; the force on the slave is their sum)
    int beyond = 0;        // node-segment: the closest point left the pair's window (window_node)
  };
  void ContactGeometry(const ContactCandidate &c, const double *z, LocalContact *lc, bool hessians = false) const;
  DetectionScene DetectionView() const;  // what contact detection reads, at the current state
  PetscErrorCode SetUpLayout();      // sizes, Vec/Mat/KSP for the current candidate set
  PetscErrorCode FormResidual(Vec z, Vec F);
  PetscErrorCode FormJacobian(Vec z, Mat J);
  PetscErrorCode DestroySolver();
  // A KSP on J_ that applies the factorization `factor` (PCLU, PCCHOLESKY)
  // by MUMPS unless the options (problem's prefix, then prefix) say
  // otherwise, with MUMPS's ICNTL(14) and ICNTL(8) set.
  PetscErrorCode CreateFactorKsp(PCType factor, const char *prefix, KSP *ksp);
  PetscErrorCode Gather(Vec z, bool full);  // z -> zall_ (natural order): everything, or own + ghost unknowns
  PetscErrorCode Assemble(const double *z, double *F, std::vector<PetscInt> *ci, std::vector<PetscInt> *cj,
                          std::vector<PetscScalar> *cv, bool *inverted, std::vector<char> *active);
  // The contacts' part of Assemble (contact_pairs.cpp).
  PetscErrorCode AssembleContacts(const double *z, double *F, std::vector<PetscInt> *ci, std::vector<PetscInt> *cj,
                                  std::vector<PetscScalar> *cv, std::vector<char> *active);
  double Areas(StateSummary *s) const;  // see Summary
  void Unpack(const double *z);
  void Pack(double *z) const;
  PetscErrorCode UpdatePartition();  // METIS partition of the particles for the current candidates
  int ParticleOwner(int particle) const { return particle_owner_.empty() ? 0 : particle_owner_[particle]; }
  int BodyOwner(int b) const { return ParticleOwner(bodies_[b].particle); }
  int SlaveParticle(const ContactCandidate &c) const;   // particle index of the slave body
  int MasterParticle(const ContactCandidate &c) const;  // particle index of the master body, -1 for a wall
  int CandidateOwner(const ContactCandidate &c) const { return ParticleOwner(SlaveParticle(c)); }
  bool OwnsNatural(PetscInt i) const { return petsc_of_[i] >= own_lo_ && petsc_of_[i] < own_hi_; }
  int RigidDofs() const { return Frictional() ? 3 : 2; }
  PetscInt WallOffset() const { return n_body_dofs_; }
  PetscInt GaugeOffset() const { return n_body_dofs_ + 4; }
  PetscInt ModeOffset() const { return n_body_dofs_ + 4 + static_cast<PetscInt>(torque_.size()); }
  PetscInt MultiplierOffset() const { return ModeOffset() + 3 * static_cast<PetscInt>(bodies_.size()); }
  PetscInt TangentialOffset() const { return MultiplierOffset() + static_cast<PetscInt>(candidates_.size()); }
  static bool IsFrictionalType(ContactType t) { return t == ContactType::RigidRigid || t == ContactType::RigidNode || t == ContactType::NodeSegment; }
  bool HasTangential(const ContactCandidate &c) const { return Frictional() && IsFrictionalType(c.type); }
  // Full vector of positions of body unknowns at z (reference + displacement).
  double Coordinate(const double *z, PetscInt dof, double reference) const { return reference + z[dof]; }

  MPI_Comm comm_;
  PetscMPIInt rank_ = 0, size_ = 1;
  ProblemParameters params_;
  NeoHookean material_;
  std::vector<DeformableBody> bodies_;
  std::vector<RigidBody> rigid_;
  PetscInt n_body_dofs_ = 0;
  std::vector<double> u_;        // body unknowns (replicated)
  std::vector<double> u_start_;  // body unknowns at the start of the increment (slip reference: MarkStepStart)
  std::vector<double> torque_;   // rotation-gauge multipliers, one per constrained body
  std::vector<double> mode_;     // per deformable body: t_x, t_y, theta of the anchor's rigid modes (Assemble; 0 unanchored)
  double w_[4] = {0, 0, 0, 0};
  double pressure_ = 0.0;
  bool have_previous_ = false;   // a load step has converged (the tangent predictor needs its state)
  double mean_diameter_ = 1.0;
  bool friction_on_ = true;
  std::vector<ContactCandidate> candidates_;
  std::vector<double> lambda_, lambda_t_;
  std::vector<PetscInt> tangential_index_;  // per candidate: its lambda_t unknown, or -1

  // Solver objects for the current layout.
  PetscInt n_total_ = -1;
  Vec z_ = nullptr, r_ = nullptr, zall_ = nullptr;
  Vec fall_ = nullptr;               // replicated residual contributions of this rank (natural order)
  std::vector<PetscInt> petsc_of_;   // natural unknown -> PETSc index
  std::vector<PetscInt> natural_of_; // PETSc index -> natural unknown
  PetscInt own_lo_ = 0, own_hi_ = 0; // this rank's PETSc rows
  std::vector<int> particle_owner_;  // rank of each particle (empty: everything on rank 0)
  Vec yall_ = nullptr;               // replicated Newton step (ContactStepFraction), allocated with the layout
  VecScatter to_all_ = nullptr;     // whole state, natural order (once per solve: replicated copy)
  VecScatter to_local_ = nullptr;   // own + ghost unknowns only (every Newton iteration; reverse: residual)
  PetscInt n_ghost_ = 0;            // unknowns this rank reads but does not own
  bool partition_adopted_ = false;  // the last UpdatePartition changed the owners (-partition_view reports)
  Mat J_ = nullptr;
  KSP ksp_ = nullptr;                // MUMPS LU (default) of the Newton matrix
  // The symmetric form (SymmetrizeNewtonMatrix), for the current layout.
  KSP ksp_ldlt_ = nullptr;           // MUMPS LDL^T of J_s
  Mat J_unsymmetric_ = nullptr;      // J before the row operations (its inactive columns)
  Vec sym_scale_ = nullptr;          // S: -1 / c_n on active normal rows, -R / E on gauge rows, else 1
  Vec sym_pivot_ = nullptr;          // 1 / pivot on the rows whose columns were moved (inactive multipliers), else 0
  Vec sym_keep_ = nullptr;           // 0 on those rows, else 1
  Vec sym_work_ = nullptr;
  // Per candidate {normal, tangential}: the Newton row of the last Jacobian
  // assembly is the identity row of an inactive multiplier (1), another row
  // (2), or absent / not this rank's (0).
  std::vector<char> jacobian_rows_;
  std::vector<char> active_now_;
  std::vector<double> switch_margin_;  // per candidate: |lambda_n - c_n g| and ||trial| - mu a| (own contacts; see ChangedStateMargin)
  std::vector<double> gap_bound_;      // per candidate, at the last residual: gap and sum_a |dgap_a| (own contacts; see ContactStepFraction)
  bool static_rows_ = false;  // the residual is ResidualFromHere's: Coulomb rows without the slip tie
  std::vector<double> slip_now_;       // per candidate, at the last residual: incremental slip (own frictional contacts; ContactPenalty)
  std::vector<double> tresca_bound_;   // per candidate: mu lambda_n lagged by LagContactWeights
  bool inverted_ = false;
  double rho_anchor_ = 0.0;         // pseudo-transient weight (0: plain Newton)
  double dual_reg_ = -1.0;          // dual proximal term (< 0: prox_eta; SetDualRegularization)
  std::vector<double> anchor_;      // body and wall unknowns the pseudo-transient term pulls towards
  std::vector<double> lambda_anchor_, lambda_t_anchor_;  // contact forces at the anchor (per candidate; empty: not anchored)
  std::vector<double> prox_weight_; // D of the proximal terms, per body and wall unknown (set with the layout)
  std::vector<PetscScalar> coo_values_;
  double merit_ = 0.0;                            // Merit(): summed over ranks by FormResidual
  double merit_local_ = 0.0;                      // this rank's part, accumulated by Assemble
  std::string options_prefix_;               // of the KSP (and the level solver's SNES)
  int layouts_created_ = 0;         // SetUpLayout calls (symbolic factorizations)
  int predictor_factorizations_ = 0;  // numeric factorizations of TangentPredictor
  int layouts_at_step_ = 0;         // layouts_created_ at BeginLoadStep
  State step_saved_;                // the state at BeginLoadStep (restored by a failed step)
  double step_saved_pressure_ = 0.0;
  PetscInt mumps_extra_ = 100;      // MUMPS ICNTL(14): extra workspace in percent (doubled after INFOG(1) = -9)
};

}  // namespace deformix

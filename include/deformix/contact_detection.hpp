// Contact detection: the candidate pairs within a margin of each other, as
// functions over a read-only view of the scene (DetectionScene), so that
// detection knows nothing of the unknowns, the assembly or the solver.
//
// Distribution: each rank runs the narrow phase (the per-node distances, the
// whole cost) only for the pairs whose slave particle it owns, i.e. its own
// particles against their neighbours found by the broad phase
// (DetectOwnCandidates); the candidates are then gathered on every rank, a
// few integers each (GatherCandidates), and sorted by the problem into an
// order that does not depend on the number of ranks.
//
// Broad phase: a uniform grid of cells of the size of the largest particle
// bounding circle plus the margin; each particle is binned by its centre and
// only the 3 x 3 neighbouring cells are searched, so the cost is linear in
// the number of particles.
// Narrow phase, per pair type (the slave carries the multiplier):
//   rigid - rigid            gap = |c_B - c_A| - r_A - r_B (slave: the higher particle number)
//   rigid - deformable       each boundary node of the deformable disk against the circle
//   deformable - deformable  each boundary node of the higher-numbered disk against the
//                            closest boundary segment of the other (and the other way
//                            round with two_pass)
//   any - wall               rigid disks by their radius, deformable disks by their
//                            boundary points (nodes and Bezier control points)
#pragma once
#include <mpi.h>

#include <vector>

#include "deformix/wall_box.hpp"

namespace deformix {

enum class ContactType : int {
  PointWall = 0,    // deformable boundary point (BoundaryPoint) - wall
  RigidWall = 1,    // rigid disk - wall
  RigidRigid = 2,   // rigid `master` - rigid `body`
  RigidNode = 3,    // rigid `master` - boundary node `point` of deformable `body`
  NodeSegment = 4,  // boundary segment `segment` of deformable `master` - node `point` of deformable `body`
};

struct ContactCandidate {
  ContactType type = ContactType::PointWall;
  int body = 0;      // the slave body: deformable (PointWall, RigidNode, NodeSegment) or rigid
  int point = 0;     // index into the slave's mesh.boundary (deformable slaves)
  Wall wall = kLeft; // wall pairs
  int master = -1;   // rigid body (RigidRigid, RigidNode) or deformable body (NodeSegment)
  int segment = -1;  // NodeSegment: master boundary nodes boundary[segment] -> boundary[segment + 1]
};

// What detection reads: the particles at the current state.
struct DetectionScene {
  struct Deformable {
    int particle = 0, owner = 0;   // particle index, rank owning it
    std::vector<double> boundary;  // current boundary node positions (x, y), in mesh.boundary order
    std::vector<double> points;    // current wall-contact points (BoundaryPoint i), as many
  };
  struct Rigid {
    int particle = 0, owner = 0;
    double centre[2] = {0.0, 0.0};
    double radius = 0.0;
  };
  std::vector<Deformable> deformable;  // indexed like the problem's deformable bodies
  std::vector<Rigid> rigid;            // indexed like its rigid bodies
  double walls[4] = {0.0, 0.0, 0.0, 0.0};
  bool two_pass = false;               // deformable pairs both ways (-contact_deformable two_pass)
};

// The candidates whose slave particle `rank` owns, with gap below `reach`
// (an absolute length).
std::vector<ContactCandidate> DetectOwnCandidates(const DetectionScene &scene, double reach, int rank);
// Every rank's candidates on every rank (collective), in rank order.
std::vector<ContactCandidate> GatherCandidates(MPI_Comm comm, const std::vector<ContactCandidate> &own);

}  // namespace deformix

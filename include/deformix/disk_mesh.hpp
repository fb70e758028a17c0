// Disk mesher: a disk of radius R cut into about N similar-size triangles.
//
// The mesh is built from concentric rings: ring k (k = 1..n) carries 6k
// vertices at radius k R / n, and the annulus between rings k-1 and k holds
// 6(2k-1) triangles, so the disk has 6 n^2 triangles of nearly equal area
// (n = round(sqrt(N/6)): N = 92 -> 96, 368 -> 384, 968 -> 1014, 3872 -> 3750).
// The outer ring has 6n boundary segments (24 for the paper's ~92-triangle
// disk).
//
// The mesh (vertices, triangulation and order-2 mid-edge nodes) is invariant,
// as a set of triangles, under the mirrors x -> -x and y -> -y (and the
// 60-degree rotation); mirror-image nodes have exactly negated coordinates.
// So the unrotated disk between symmetric walls is a symmetric equilibrium
// and a rotation gauge carries no reaction torque. Smallest angle: 60 deg
// (n = 1), 47.6 (n = 2, 3), 47.3 (n = 4), 45.5 (n = 8), 44.8 (n = 13),
// 44.3 (n = 25), tending to about 43.7 as n grows.
//
// Order 2 gives 6-node isoparametric triangles whose boundary mid-edge nodes
// sit on the circle, so the discrete boundary is a piecewise parabola that
// represents the disk area to O(h^4) instead of losing ~1 % with 24 straight
// segments. Order 1 gives the straight-sided 3-node mesh (kept for the
// work-precision comparison).
//
// Boundary nodes sit at equal angles 2 pi b / boundary.size() starting at
// (R, 0). The points (R,0) and (-R,0) are always nodes; (0, +-R), where the
// other pair of walls first touches, are nodes for order 2 always and for
// order 1 only when n is even. Cardinal points are exact (no cos/sin round-off).
#pragma once
#include <vector>

namespace deformix {

struct DiskMesh {
  int order = 2;               // 1: 3-node triangles, 2: 6-node isoparametric triangles
  double radius = 0.5;
  std::vector<double> X;       // reference coordinates, 2 per node, disk centred at the origin
  std::vector<int> cells;      // nodes_per_cell() entries per triangle: vertices v0 v1 v2
                               // counter-clockwise, then (order 2) mid-edge nodes m01 m12 m20
  std::vector<int> boundary;   // boundary nodes in counter-clockwise order around the disk
                               // (order 2: vertex, mid-edge, vertex, mid-edge, ...), not closed
  int num_vertices = 0;        // vertex nodes come first in the node numbering

  int num_nodes() const { return static_cast<int>(X.size() / 2); }
  int nodes_per_cell() const { return order == 1 ? 3 : 6; }
  int num_cells() const { return static_cast<int>(cells.size()) / nodes_per_cell(); }
};

// Number of rings used for a requested triangle count (>= 1).
int disk_mesh_rings(int target_triangles);

// Builds the disk mesh; throws std::invalid_argument for target_triangles < 6,
// radius <= 0 or order not in {1, 2}.
DiskMesh make_disk_mesh(double radius, int target_triangles, int order);

// Smallest interior angle, in degrees, over the straight-sided vertex triangles.
double min_angle_degrees(const DiskMesh &mesh);

}  // namespace deformix

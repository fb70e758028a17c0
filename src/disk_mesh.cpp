// Ring mesh of a disk of radius R (see include/deformix/disk_mesh.hpp).
//
// Vertices: the centre (ring 0) and, for k = 1..n, ring k with 6k vertices
//   X = (k R / n) (cos t_j, sin t_j),  t_j = 2 pi j / (6k),  j = 0..6k-1,
// numbered ring by ring, so ring k starts at 1 + 3k(k-1) and vertex 0 of
// every ring lies on the positive x axis.
//
// Triangles: the annulus between rings k-1 and k splits into 6 sectors of
// angle pi/3. A sector sees k vertices of the inner ring, a_0..a_{k-1} at
// sector fractions i/(k-1), and k+1 of the outer ring, b_0..b_k at fractions
// o/k (end points shared with the neighbouring sectors). The two sequences
// are zipped by angle: at each step the ring whose next vertex comes first
// in angle advances, which gives (k-1) + k = 2k-1 triangles per sector and
// 6(2k-1) per annulus, all counter-clockwise and of nearly equal area.
//
// Mirror symmetry. Since o/k < o/(k-1) < (o+1)/k for 1 <= o < k-1, the
// zipper strictly alternates, outer, inner, outer, ..., inner, outer, and its
// rungs (the edges a_i b_o between consecutive triangles, plus the two
// sector edges a_0 b_0 and a_{k-1} b_k) are a_j b_j and a_j b_{j+1} for
// j = 0..k-1; the only tie is at the far edge of the sector (both next
// fractions 1), where it is broken towards the inner ring. The reflection
// about the sector bisector maps a_i -> a_{k-1-i}, b_o -> b_{k-o}, hence
// rung a_j b_{j+1} <-> a_{k-1-j} b_{k-1-j}: the rung set, and so the triangulation, of every sector is
// symmetric about its bisector. The middle (k-th) triangle is its own
// mirror image: for even k it is (a_{k/2-1}, b_{k/2}, a_{k/2}), the outer
// vertex on the bisector joined to both inner neighbours; for odd k it is
// (a_{(k-1)/2}, b_{(k-1)/2}, b_{(k+1)/2}), the inner vertex on the bisector
// joined to both outer neighbours (exactly one of rings k-1, k has a vertex
// on the bisector, so no quadrilateral is ever left ambiguous). Bisector
// symmetry plus the 6-fold rotational symmetry gives symmetry about every
// multiple of 30 degrees, in particular about the x axis (y -> -y) and the
// y axis (x -> -x). Vertex and mid-edge positions are computed so that the
// mirror images are exact (see circle_point), which makes the unrotated
// disk an exactly symmetric configuration.
//
// Order 2: one mid-edge node per edge, shared by the two triangles on it.
// Interior edges get the straight midpoint; an edge joining two vertices of
// the outer ring gets its node on the circle at the mid angle, so the
// boundary becomes a piecewise parabola through 12n points of the circle.
#include "deformix/disk_mesh.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <unordered_map>

namespace deformix {

namespace {

int ring_offset(int k) { return k == 0 ? 0 : 1 + 3 * k * (k - 1); }

// Global vertex number of the j-th vertex of ring k (j taken modulo 6k).
int ring_vertex(int k, int j) {
  if (k == 0) return 0;
  const int count = 6 * k;
  return ring_offset(k) + ((j % count) + count) % count;
}

// Point at angle 2 pi num / den on the circle of radius r (den even, which
// holds for every caller: 6k and 12n). The angle is folded into the first
// quadrant by the mirrors y -> -y (num -> den - num) and x -> -x
// (num -> den/2 - num) before cos/sin are evaluated, so mirror-image angles
// give coordinates that are exact negatives of each other, and the mesh is
// mirror-symmetric bit for bit, not just to round-off. The four cardinal
// directions are returned exactly, because walls first touch the disk there
// and contact tests compare these coordinates.
void circle_point(double r, int num, int den, double &x, double &y) {
  int m = ((num % den) + den) % den;
  double sx = 1.0, sy = 1.0;
  if (2 * m > den) {  // lower half plane: mirror y -> -y
    m = den - m;
    sy = -1.0;
  }
  if (4 * m > den) {  // second quadrant: mirror x -> -x
    m = den / 2 - m;
    sx = -1.0;
  }
  // Now 0 <= m <= den/4, i.e. the angle lies in [0, pi/2].
  double c, s;
  if (m == 0) {
    c = 1.0;
    s = 0.0;
  } else if (4 * m == den) {
    c = 0.0;
    s = 1.0;
  } else {
    const double t = 2.0 * std::acos(-1.0) * m / den;
    c = std::cos(t);
    s = std::sin(t);
  }
  x = sx * r * c;
  y = sy * r * s;
}

}  // namespace

int disk_mesh_rings(int target_triangles) {
  const int rings = static_cast<int>(std::lround(std::sqrt(target_triangles / 6.0)));
  return std::max(1, rings);
}

DiskMesh make_disk_mesh(double radius, int target_triangles, int order) {
  if (target_triangles < 6)
    throw std::invalid_argument("make_disk_mesh: target_triangles must be >= 6 (got " +
                                std::to_string(target_triangles) + ")");
  if (!(radius > 0.0))
    throw std::invalid_argument("make_disk_mesh: radius must be > 0 (got " + std::to_string(radius) + ")");
  if (order != 1 && order != 2)
    throw std::invalid_argument("make_disk_mesh: order must be 1 or 2 (got " + std::to_string(order) + ")");

  const int n = disk_mesh_rings(target_triangles);
  DiskMesh mesh;
  mesh.order = order;
  mesh.radius = radius;
  mesh.num_vertices = ring_offset(n + 1);

  const int num_cells = 6 * n * n;
  mesh.X.reserve(2 * (mesh.num_vertices + (order == 2 ? 3 * num_cells / 2 + 3 * n : 0)));
  mesh.X.push_back(0.0);
  mesh.X.push_back(0.0);
  for (int k = 1; k <= n; ++k) {
    for (int j = 0; j < 6 * k; ++j) {
      double x, y;
      circle_point(radius * k / n, j, 6 * k, x, y);
      mesh.X.push_back(x);
      mesh.X.push_back(y);
    }
  }

  // Vertex triangles, counter-clockwise.
  std::vector<int> tri;
  tri.reserve(3 * num_cells);
  for (int k = 1; k <= n; ++k) {
    for (int s = 0; s < 6; ++s) {
      const int inner_count = k - 1;  // inner-ring steps in this sector
      int i = 0, o = 0;
      while (i < inner_count || o < k) {
        const int a = ring_vertex(k - 1, s * inner_count + i);
        const int b = ring_vertex(k, s * k + o);
        // Compare the angles of the next inner and next outer vertex as
        // sector fractions (i+1)/(k-1) and (o+1)/k without division. They
        // tie only at the sector's far edge (both fractions 1), and the tie
        // must go to the inner ring: the sector then ends with the triangle
        // (a_{k-1}, b_{k-1}, b_k), the mirror image of its first triangle
        // (a_0, b_0, b_1), and the whole sector is symmetric about its
        // bisector (see the comment at the top of this file).
        const bool advance_outer =
            i == inner_count || (o < k && (o + 1) * inner_count < (i + 1) * k);
        if (advance_outer) {
          tri.insert(tri.end(), {a, b, ring_vertex(k, s * k + o + 1)});
          ++o;
        } else {
          tri.insert(tri.end(), {a, b, ring_vertex(k - 1, s * inner_count + i + 1)});
          ++i;
        }
      }
    }
  }

  if (order == 1) {
    mesh.cells = std::move(tri);
    for (int j = 0; j < 6 * n; ++j) mesh.boundary.push_back(ring_vertex(n, j));
    return mesh;
  }

  // Mid-edge nodes, created in cell order so neighbouring cells get nearby numbers.
  const int outer_first = ring_offset(n);
  std::unordered_map<long long, int> edge_node;
  edge_node.reserve(2 * num_cells);
  auto mid_node = [&](int p, int q) {
    const long long key = static_cast<long long>(std::min(p, q)) * mesh.num_vertices + std::max(p, q);
    auto it = edge_node.find(key);
    if (it != edge_node.end()) return it->second;
    const int id = mesh.num_nodes();
    if (p >= outer_first && q >= outer_first) {
      // Boundary edge between outer vertices j and j+1 (mod 6n): its node
      // goes on the circle at the mid angle 2 pi (2j+1) / 12n.
      const int jp = p - outer_first, jq = q - outer_first;
      const int j = std::abs(jp - jq) == 1 ? std::min(jp, jq) : 6 * n - 1;
      double x, y;
      circle_point(radius, 2 * j + 1, 12 * n, x, y);
      mesh.X.push_back(x);
      mesh.X.push_back(y);
    } else {
      mesh.X.push_back(0.5 * (mesh.X[2 * p] + mesh.X[2 * q]));
      mesh.X.push_back(0.5 * (mesh.X[2 * p + 1] + mesh.X[2 * q + 1]));
    }
    edge_node.emplace(key, id);
    return id;
  };

  mesh.cells.reserve(6 * num_cells);
  for (int c = 0; c < num_cells; ++c) {
    const int v0 = tri[3 * c], v1 = tri[3 * c + 1], v2 = tri[3 * c + 2];
    const int m01 = mid_node(v0, v1), m12 = mid_node(v1, v2), m20 = mid_node(v2, v0);
    mesh.cells.insert(mesh.cells.end(), {v0, v1, v2, m01, m12, m20});
  }
  for (int j = 0; j < 6 * n; ++j) {
    const int v = ring_vertex(n, j), w = ring_vertex(n, j + 1);
    mesh.boundary.push_back(v);
    mesh.boundary.push_back(mid_node(v, w));
  }
  return mesh;
}

double min_angle_degrees(const DiskMesh &mesh) {
  const int npc = mesh.nodes_per_cell();
  // The smallest angle has the largest cosine.
  double max_cosine = -1.0;
  for (int c = 0; c < mesh.num_cells(); ++c) {
    const int *v = &mesh.cells[static_cast<size_t>(npc) * c];
    for (int corner = 0; corner < 3; ++corner) {
      const int p = v[corner], q = v[(corner + 1) % 3], r = v[(corner + 2) % 3];
      const double ax = mesh.X[2 * q] - mesh.X[2 * p], ay = mesh.X[2 * q + 1] - mesh.X[2 * p + 1];
      const double bx = mesh.X[2 * r] - mesh.X[2 * p], by = mesh.X[2 * r + 1] - mesh.X[2 * p + 1];
      max_cosine = std::max(max_cosine, (ax * bx + ay * by) / (std::hypot(ax, ay) * std::hypot(bx, by)));
    }
  }
  return std::acos(std::min(1.0, max_cosine)) * 180.0 / std::acos(-1.0);
}

}  // namespace deformix

// Weighted (mortar) gap of a deformable slave boundary against a smooth
// master curve: mortar_node (see pair_kinematics.hpp).
//
// Node-to-segment contact checks the slave's nodes only: the master's
// boundary may enter the slave between two slave nodes, and at high
// pressure, where deformable disks become polygons, a master corner does
// (by 2-4e-2 <d> at P/E = 0.5 with the one-pass node-to-segment pairs).
// Checking both ways (two node-to-segment passes) is exact but
// over-constrains conforming contacts. The mortar condition keeps one
// multiplier per slave node and integrates the gap over the slave boundary:
//     g~_j = int_Gamma_s phi_j g(x) ds / int_Gamma_s phi_j ds >= 0,
// phi_j the indicator of node j's dual cell, the part of the slave boundary
// nearer (in the boundary parametrization) to node j than to its neighbours:
// the halves of the two sub-segments around j (sub-segments run between
// consecutive boundary nodes, vertex and mid-edge nodes alike, so the cells
// of a quadratic mesh are as wide as those of a linear one with twice the
// edges; the cells tile the boundary). g(x) is the signed distance of the
// slave boundary point x to the master curve (curve_node), ds the reference
// arc length. The contact's virtual work is lambda_j dg~_j, so lambda_j is
// the contact force carried by node j's cell, and the incremental slip is
// weighted the same way,
//     s~_j = int phi_j s(x) ds / int phi_j ds.
// Every point of the slave boundary enters one constraint: a master corner
// can no longer reach into the slave between nodes without making a
// weighted gap negative. The price is that the condition holds on average
// over a cell: where two convex boundaries touch at a point, the slave
// boundary at the contact point lies inside the master by (h/2)^2 / (6 R_eff)
// (contact point at a node) to h^2 / (6 R_eff) (at a cell boundary), h the
// node spacing and 1/R_eff the sum of the curvatures: 0.7e-3 to 2.8e-3 <d>
// for two 96-triangle disks, where node-to-segment lets a master node in
// by up to (h/2)^2 / (2 R_eff) = 2.1e-3 <d>. Both errors vanish like h^2;
// a master corner pressed into a conforming contact is where they differ
// (docs/validation.md). A hat weight over the whole sub-segments was tried
// first: its wider support let the contact point in deeper (4.6e-3 <d>
// against 3.7e-3, 20 disks at P/E = 1e-4).
// The integrals use 3 Gauss points per half sub-segment; the weights are
// fixed by the reference mesh.
//
// The slave point x on sub-segment side sigma (-1: towards node j-1, +1:
// towards node j+1) at r in [0, 1/2] (r = 0 at node j, 1/2 at the cell's end) lies on the boundary
// edge through three nodes (A, M, B) at the edge coordinate xi, with the
// quadratic shape functions (1 - xi)(1 - 2 xi), 4 xi (1 - xi), xi (2 xi - 1):
//   order 1: the straight edge j -> j + sigma, x = (1 - r) x_j + r x_{j+sigma};
//   order 2, j a vertex:   (A, M, B) = (j, j + sigma, j + 2 sigma), xi = r / 2;
//   order 2, j mid-edge:   (A, M, B) = (j - sigma, j, j + sigma),   xi = (1 + r) / 2.
#include <cmath>

#include "deformix/pair_kinematics.hpp"

namespace deformix {

namespace {

constexpr int kMaster = 7, kSlave = 5;
constexpr int kDofs = 2 * (kMaster + kSlave);
static_assert(kDofs <= PairKinematics::kMaxDofs, "mortar_node needs 24 local unknowns");

// A point of the slave boundary as a combination of (at most 3) slave nodes.
struct SlavePoint {
  int n = 0;
  int node[3] = {0, 0, 0};      // local slave node index 0..4 (node j is 2)
  double coeff[3] = {0, 0, 0};
};

SlavePoint slave_point(int order, bool vertex, int side, double r) {
  SlavePoint s;
  if (order == 1) {
    s.n = 2;
    s.node[0] = 2, s.coeff[0] = 1.0 - r;
    s.node[1] = 2 + side, s.coeff[1] = r;
    return s;
  }
  const double xi = vertex ? 0.5 * r : 0.5 * (1.0 + r);
  s.n = 3;
  if (vertex)
    s.node[0] = 2, s.node[1] = 2 + side, s.node[2] = 2 + 2 * side;
  else
    s.node[0] = 2 - side, s.node[1] = 2, s.node[2] = 2 + side;
  s.coeff[0] = (1.0 - xi) * (1.0 - 2.0 * xi);
  s.coeff[1] = 4.0 * xi * (1.0 - xi);
  s.coeff[2] = xi * (2.0 * xi - 1.0);
  return s;
}

}  // namespace

PairKinematics mortar_node(const double q[24], const double q0[24], const MortarSupport &support, bool hessians,
                           int *beyond) {
  if (beyond) *beyond = 0;
  PairKinematics k;
  k.ndof = kDofs;
  // 3-point Gauss-Legendre on [0, 1]. (Two points saved 4 % of a 20-disk
  // run: the LU factorization takes twice the time of residual and Jacobian.)
  const double gr[3] = {0.5 - 0.5 * std::sqrt(0.6), 0.5, 0.5 + 0.5 * std::sqrt(0.6)};
  const double gw[3] = {5.0 / 18.0, 8.0 / 18.0, 5.0 / 18.0};
  const double total = 0.5 * (support.length[0] + support.length[1]);  // int phi_j ds
  double normal[2] = {0.0, 0.0};
  for (int side = -1; side <= 1; side += 2) {
    const double length = support.length[side < 0 ? 0 : 1];
    for (int g = 0; g < 3; ++g) {
      const double r = 0.5 * gr[g], weight = 0.5 * gw[g] * length / total;
      const SlavePoint sp = slave_point(support.order, support.vertex, side, r);
      double p[2] = {0, 0}, p0[2] = {0, 0};
      for (int a = 0; a < sp.n; ++a)
        for (int c = 0; c < 2; ++c) {
          p[c] += sp.coeff[a] * q[2 * (kMaster + sp.node[a]) + c];
          p0[c] += sp.coeff[a] * q0[2 * (kMaster + sp.node[a]) + c];
        }
      // The five-node window of the master patch whose two segments hold the
      // closest point: centred on master node 3, or shifted by one node.
      int window = 1, out = 0;
      PairKinematics pk;
      for (int attempt = 0; attempt < 2; ++attempt) {
        double ql[12], ql0[12];
        for (int i = 0; i < 10; ++i) ql[i] = q[2 * window + i], ql0[i] = q0[2 * window + i];
        ql[10] = p[0], ql[11] = p[1], ql0[10] = p0[0], ql0[11] = p0[1];
        pk = curve_node(ql, ql0, hessians, &out);
        if (out == 0 || attempt == 1) break;
        window += out;
      }
      if (out != 0 && beyond) *beyond = out;
      // Local unknown l of curve_node -> (global unknown, coefficient) pairs.
      int map_n[12], map_i[12][3];
      double map_c[12][3];
      for (int l = 0; l < 10; ++l) map_n[l] = 1, map_i[l][0] = 2 * window + l, map_c[l][0] = 1.0;
      for (int c = 0; c < 2; ++c) {
        map_n[10 + c] = sp.n;
        for (int a = 0; a < sp.n; ++a) map_i[10 + c][a] = 2 * (kMaster + sp.node[a]) + c, map_c[10 + c][a] = sp.coeff[a];
      }
      k.gap += weight * pk.gap;
      k.slip += weight * pk.slip;
      for (int c = 0; c < 2; ++c) normal[c] += weight * pk.normal[c];
      for (int l = 0; l < 12; ++l)
        for (int a = 0; a < map_n[l]; ++a) {
          k.dgap[map_i[l][a]] += weight * map_c[l][a] * pk.dgap[l];
          k.dslip[map_i[l][a]] += weight * map_c[l][a] * pk.dslip[l];
        }
      if (!hessians) continue;
      for (int l = 0; l < 12; ++l)
        for (int m = 0; m < 12; ++m) {
          const double hg = weight * pk.d2gap[l * 12 + m], hs = weight * pk.d2slip[l * 12 + m];
          if (hg == 0.0 && hs == 0.0) continue;
          for (int a = 0; a < map_n[l]; ++a)
            for (int b = 0; b < map_n[m]; ++b) {
              const double c = map_c[l][a] * map_c[m][b];
              k.d2gap[map_i[l][a] * kDofs + map_i[m][b]] += c * hg;
              k.d2slip[map_i[l][a] * kDofs + map_i[m][b]] += c * hs;
            }
        }
    }
  }
  const double n = std::hypot(normal[0], normal[1]);
  if (n > 0.0) k.normal[0] = normal[0] / n, k.normal[1] = normal[1] / n;
  return k;
}

}  // namespace deformix

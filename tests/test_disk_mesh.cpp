// Disk mesher tests: counts, orientation, conformity, boundary ordering,
// quality and the area of the isoparametric (order 2) versus straight-sided
// (order 1) disk.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <set>
#include <stdexcept>
#include <utility>
#include <vector>

#include "deformix/disk_mesh.hpp"
#include "deformix/hyperelastic_element.hpp"

using namespace deformix;

namespace {

const double kPi = std::acos(-1.0);
const int kTargets[] = {92, 368, 968, 3872};

double node_radius(const DiskMesh &m, int node) { return std::hypot(m.X[2 * node], m.X[2 * node + 1]); }

double node_angle(const DiskMesh &m, int node) {
  const double t = std::atan2(m.X[2 * node + 1], m.X[2 * node]);
  return t < 0.0 ? t + 2.0 * kPi : t;
}

// Sum of element reference areas through the element kernel (x = X).
double kernel_area(const DiskMesh &m) {
  const NeoHookean material = NeoHookean::from_young_poisson(1.0, 0.3);
  const int npc = m.nodes_per_cell();
  std::vector<double> Xe(2 * npc);
  double area = 0.0;
  for (int c = 0; c < m.num_cells(); ++c) {
    for (int a = 0; a < npc; ++a) {
      const int node = m.cells[c * npc + a];
      Xe[2 * a] = m.X[2 * node];
      Xe[2 * a + 1] = m.X[2 * node + 1];
    }
    const ElementResult r = triangle_element(material, m.order, Xe.data(), Xe.data(), nullptr, nullptr);
    EXPECT_FALSE(r.inverted) << "cell " << c;
    area += r.ref_area;
  }
  return area;
}

}  // namespace

TEST(DiskMesh, RingCountAndTriangleCount) {
  const int expected_rings[] = {4, 8, 13, 25};
  for (int t = 0; t < 4; ++t) {
    const int n = disk_mesh_rings(kTargets[t]);
    EXPECT_EQ(n, expected_rings[t]);
    for (int order = 1; order <= 2; ++order) {
      const DiskMesh m = make_disk_mesh(0.5, kTargets[t], order);
      EXPECT_EQ(m.num_cells(), 6 * n * n);
      EXPECT_EQ(m.num_vertices, 1 + 3 * n * (n + 1));
      // Euler: E = (3T + B)/2 edges, one mid node per edge for order 2.
      const int edges = (3 * m.num_cells() + 6 * n) / 2;
      EXPECT_EQ(m.num_nodes(), order == 1 ? m.num_vertices : m.num_vertices + edges);
      EXPECT_EQ(static_cast<int>(m.cells.size()), m.num_cells() * m.nodes_per_cell());
    }
  }
  EXPECT_EQ(make_disk_mesh(0.5, 92, 2).num_cells(), 96);
  EXPECT_EQ(make_disk_mesh(0.5, 368, 2).num_cells(), 384);
  EXPECT_EQ(make_disk_mesh(0.5, 968, 2).num_cells(), 1014);
  EXPECT_EQ(make_disk_mesh(0.5, 3872, 2).num_cells(), 3750);
}

TEST(DiskMesh, CellsCounterClockwiseAndConforming) {
  for (int target : kTargets) {
    for (int order = 1; order <= 2; ++order) {
      const DiskMesh m = make_disk_mesh(0.5, target, order);
      const int npc = m.nodes_per_cell();
      std::map<std::pair<int, int>, int> edge_count;
      std::map<std::pair<int, int>, int> edge_mid;
      std::vector<int> used(m.num_nodes(), 0);
      for (int c = 0; c < m.num_cells(); ++c) {
        const int *v = &m.cells[c * npc];
        for (int a = 0; a < npc; ++a) {
          ASSERT_GE(v[a], 0);
          ASSERT_LT(v[a], m.num_nodes());
          used[v[a]] = 1;
        }
        for (int a = 0; a < 3; ++a) ASSERT_LT(v[a], m.num_vertices);
        const double ax = m.X[2 * v[1]] - m.X[2 * v[0]], ay = m.X[2 * v[1] + 1] - m.X[2 * v[0] + 1];
        const double bx = m.X[2 * v[2]] - m.X[2 * v[0]], by = m.X[2 * v[2] + 1] - m.X[2 * v[0] + 1];
        EXPECT_GT(ax * by - ay * bx, 0.0) << "cell " << c << " not counter-clockwise";
        for (int e = 0; e < 3; ++e) {
          const int p = v[e], q = v[(e + 1) % 3];
          const std::pair<int, int> key(std::min(p, q), std::max(p, q));
          ++edge_count[key];
          if (order == 2) {
            const int mid = v[3 + e];
            ASSERT_GE(mid, m.num_vertices);
            auto it = edge_mid.find(key);
            if (it == edge_mid.end())
              edge_mid[key] = mid;
            else
              EXPECT_EQ(it->second, mid) << "mid-edge node not shared across edge";
          }
        }
      }
      int boundary_edges = 0;
      for (const auto &[edge, count] : edge_count) {
        EXPECT_LE(count, 2);
        if (count == 1) ++boundary_edges;
      }
      const int n = disk_mesh_rings(target);
      EXPECT_EQ(boundary_edges, 6 * n);
      for (int node = 0; node < m.num_nodes(); ++node) EXPECT_TRUE(used[node]) << "orphan node " << node;
      if (order == 2) {
        std::set<int> mids;
        for (const auto &[edge, mid] : edge_mid) mids.insert(mid);
        EXPECT_EQ(static_cast<int>(mids.size()), m.num_nodes() - m.num_vertices);
      }
    }
  }
}

TEST(DiskMesh, BoundaryOnCircleCounterClockwiseFromAngleZero) {
  const double R = 0.5;
  for (int target : kTargets) {
    for (int order = 1; order <= 2; ++order) {
      const DiskMesh m = make_disk_mesh(R, target, order);
      const int n = disk_mesh_rings(target);
      ASSERT_EQ(static_cast<int>(m.boundary.size()), order == 1 ? 6 * n : 12 * n);
      EXPECT_DOUBLE_EQ(m.X[2 * m.boundary[0]], R);
      EXPECT_DOUBLE_EQ(m.X[2 * m.boundary[0] + 1], 0.0);
      double previous = -1.0;
      for (size_t b = 0; b < m.boundary.size(); ++b) {
        const int node = m.boundary[b];
        EXPECT_NEAR(node_radius(m, node), R, 1e-14);
        const double angle = node_angle(m, node);
        EXPECT_GT(angle, previous);
        previous = angle;
        // Order 2 alternates vertex, mid-edge node.
        if (order == 2) {
          EXPECT_EQ(node < m.num_vertices, b % 2 == 0);
        }
        // Equal spacing: node b sits at angle 2 pi b / size.
        EXPECT_NEAR(angle, 2.0 * kPi * b / m.boundary.size(), 1e-12);
      }
    }
  }
}

TEST(DiskMesh, NodesWhereWallsFirstTouch) {
  // Walls touch the disk first at 0, 90, 180 and 270 degrees. Order 2 always
  // has nodes there (12n boundary nodes); order 1 only when n is even.
  const double R = 0.5;
  const double cx[4] = {R, 0.0, -R, 0.0}, cy[4] = {0.0, R, 0.0, -R};
  for (int target : kTargets) {
    for (int order = 1; order <= 2; ++order) {
      const DiskMesh m = make_disk_mesh(R, target, order);
      if (order == 1 && disk_mesh_rings(target) % 2 != 0) continue;
      for (int quarter = 0; quarter < 4; ++quarter) {
        bool found = false;
        for (int node : m.boundary)
          found = found || (m.X[2 * node] == cx[quarter] && m.X[2 * node + 1] == cy[quarter]);
        EXPECT_TRUE(found) << "target " << target << " order " << order << " quarter " << quarter;
      }
    }
  }
}

TEST(DiskMesh, MinimumAngle) {
  // Measured: 30.0 degrees at every size (92, 368, 968, 3872); the ring
  // construction keeps the same worst triangle shapes as it refines.
  for (int target : kTargets) {
    const double angle = min_angle_degrees(make_disk_mesh(0.5, target, 2));
    std::printf("target %4d triangles: min angle %.3f deg\n", target, angle);
    EXPECT_GT(angle, 29.5);
    EXPECT_NEAR(min_angle_degrees(make_disk_mesh(0.5, target, 1)), angle, 1e-12);
  }
}

TEST(DiskMesh, AreaOrderTwoIsExactOrderOneLosesAboutOnePercent) {
  const double R = 0.5, exact = kPi * R * R;
  const double area2 = kernel_area(make_disk_mesh(R, 92, 2));
  const double area1 = kernel_area(make_disk_mesh(R, 92, 1));
  const double err2 = std::fabs(area2 - exact) / exact, loss1 = (exact - area1) / exact;
  std::printf("96 triangles: order 2 area error %.3e, order 1 area loss %.3e\n", err2, loss1);
  EXPECT_LT(err2, 1e-4);
  EXPECT_GT(loss1, 0.005);
  EXPECT_LT(loss1, 0.02);
  // The straight-sided polygon has the closed-form area 6n/2 R^2 sin(2 pi / 6n).
  EXPECT_NEAR(area1, 0.5 * 24 * R * R * std::sin(2.0 * kPi / 24), 1e-14);
}

TEST(DiskMesh, RejectsInvalidInput) {
  EXPECT_THROW(make_disk_mesh(0.5, 5, 2), std::invalid_argument);
  EXPECT_THROW(make_disk_mesh(0.0, 92, 2), std::invalid_argument);
  EXPECT_THROW(make_disk_mesh(-1.0, 92, 1), std::invalid_argument);
  EXPECT_THROW(make_disk_mesh(0.5, 92, 3), std::invalid_argument);
  EXPECT_THROW(make_disk_mesh(0.5, 92, 0), std::invalid_argument);
  EXPECT_NO_THROW(make_disk_mesh(0.5, 6, 1));
  EXPECT_EQ(make_disk_mesh(0.5, 6, 2).num_cells(), 6);
}

int main(int argc, char **argv) {
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}

// Tests of the particle partitioner (include/deformix/partition.hpp):
// ownership, cut quality on grids against the known optimum and against
// trivial index-block partitions, balance by vertex weight, duplicate edges as
// weights, a jammed mixture packing, determinism, the recount against
// METIS's own objective, the owner-grouped numbering and degenerate input.
// Bounds were set from the numbers printed by the tests (METIS 5.1.0, seed 1)
// with some slack.
#include "deformix/partition.hpp"
#include "deformix/packing.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <map>
#include <numeric>
#include <random>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

using namespace deformix;

namespace {

// Uniform double in [0, 1) from the raw engine output (platform independent).
double uniform01(std::mt19937_64 &eng) { return static_cast<double>(eng() >> 11) * (1.0 / 9007199254740992.0); }

// n random points in the unit square, an edge between points closer than r:
// a rough stand-in for a packing's contact-candidate graph (r = 0.1, n = 300:
// mean degree ~8, above the percolation threshold ~4.5 so the graph is one big
// cluster and cuts are not found for free at bottlenecks). Particle indices are
// in random spatial order, as in a freshly generated packing.
ParticleGraph random_geometric_graph(int n, double r, unsigned seed, std::vector<double> *xy = nullptr) {
  std::mt19937_64 eng(seed);
  std::vector<double> x(n), y(n);
  for (int i = 0; i < n; ++i) x[i] = uniform01(eng), y[i] = uniform01(eng);
  ParticleGraph g;
  g.vertex_weight.assign(n, 1);
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j)
      if ((x[i] - x[j]) * (x[i] - x[j]) + (y[i] - y[j]) * (y[i] - y[j]) < r * r) g.edges.emplace_back(i, j);
  if (xy) {
    xy->clear();
    for (int i = 0; i < n; ++i) xy->push_back(x[i]), xy->push_back(y[i]);
  }
  return g;
}

// nx x ny grid, 4-neighbour edges, vertex (i, j) = i + nx j, unit weights.
ParticleGraph grid_graph(int nx, int ny) {
  ParticleGraph g;
  g.vertex_weight.assign(nx * ny, 1);
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      if (i + 1 < nx) g.edges.emplace_back(i + nx * j, i + 1 + nx * j);
      if (j + 1 < ny) g.edges.emplace_back(i + nx * j, i + nx * (j + 1));
    }
  return g;
}

// Owners by contiguous index blocks of (nearly) equal count: strips on a grid.
Partition index_blocks(const ParticleGraph &g, int parts) {
  Partition p;
  p.parts = parts;
  const int n = g.size();
  for (int i = 0; i < n; ++i) p.owner.push_back(static_cast<int>(static_cast<long>(i) * parts / n));
  evaluate_partition(g, &p);
  return p;
}

// Brute-force edge cut: merge the edge list into weighted undirected pairs
// first, then sum the weights of pairs whose owners differ.
long brute_force_cut(const ParticleGraph &g, const std::vector<int> &owner) {
  std::map<std::pair<int, int>, long> w;
  for (auto [i, j] : g.edges)
    if (i != j) ++w[std::make_pair(std::min(i, j), std::max(i, j))];
  long cut = 0;
  for (const auto &[e, k] : w)
    if (owner[e.first] != owner[e.second]) cut += k;
  return cut;
}

// Number of connected components of the subgraph induced by part q.
int components_of_part(const ParticleGraph &g, const std::vector<int> &owner, int q) {
  const int n = g.size();
  std::vector<int> parent(n);
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int a) {
    while (parent[a] != a) a = parent[a] = parent[parent[a]];
    return a;
  };
  for (auto [i, j] : g.edges)
    if (owner[i] == q && owner[j] == q) parent[find(i)] = find(j);
  int c = 0;
  for (int i = 0; i < n; ++i) c += (owner[i] == q && find(i) == i);
  return c;
}

void print(const char *what, const Partition &p) {
  std::printf("[partition] %-44s parts=%d cut=%ld metis_objval=%ld imbalance=%.4f weights=", what, p.parts,
              p.edge_cut, p.metis_objval, p.imbalance);
  for (long w : p.part_weight) std::printf(" %ld", w);
  std::printf("\n");
}

}  // namespace

// ---- ownership ----------------------------------------------------------------

TEST(Partition, EveryParticleOwnedOnceOnRandomGeometricGraph) {
  const ParticleGraph g = random_geometric_graph(300, 0.1, 7u);
  int isolated = 0;
  {
    std::vector<int> deg(300, 0);
    for (auto [i, j] : g.edges) ++deg[i], ++deg[j];
    isolated = static_cast<int>(std::count(deg.begin(), deg.end(), 0));
  }
  std::printf("[partition] random geometric graph: 300 vertices, %zu edges, %d isolated\n", g.edges.size(), isolated);
  for (int parts = 1; parts <= 4; ++parts) {
    const Partition p = partition_particles(g, parts);
    print(("random geometric graph, " + std::to_string(parts) + " parts").c_str(), p);
    ASSERT_EQ(p.parts, parts);
    ASSERT_EQ(p.owner.size(), 300u);
    std::vector<int> count(parts, 0);
    for (int o : p.owner) {
      ASSERT_GE(o, 0);
      ASSERT_LT(o, parts);
      ++count[o];
    }
    ASSERT_EQ(p.part_weight.size(), static_cast<std::size_t>(parts));
    for (int q = 0; q < parts; ++q) {
      EXPECT_EQ(p.part_weight[q], count[q]) << "part " << q;  // unit weights
      EXPECT_GT(count[q], 0) << "part " << q << " is empty";
    }
    EXPECT_EQ(std::accumulate(count.begin(), count.end(), 0), 300);
    EXPECT_LE(p.imbalance, 1.05);
    if (parts == 1) {
      EXPECT_EQ(p.edge_cut, 0);
      EXPECT_EQ(p.metis_objval, -1);  // METIS not called
    } else {
      // Points are indexed in random order, so index blocks cut a fraction
      // ~(1 - 1/parts) of all edges; METIS's parts are spatial patches.
      const Partition blocks = index_blocks(g, parts);
      EXPECT_LT(p.edge_cut, blocks.edge_cut / 3) << "index blocks cut " << blocks.edge_cut;
    }
  }
}

// ---- quality on a grid ------------------------------------------------------------

TEST(Partition, GridCutsNearOptimumAndNoWorseThanStrips) {
  const ParticleGraph g = grid_graph(20, 20);
  // 2 parts: the optimum is a straight cut through 20 edges (strips achieve it).
  const Partition p2 = partition_particles(g, 2);
  const Partition s2 = index_blocks(g, 2);
  print("20x20 grid, METIS", p2);
  print("20x20 grid, index blocks (strips)", s2);
  EXPECT_EQ(s2.edge_cut, 20);
  EXPECT_LE(p2.edge_cut, 26);
  EXPECT_LE(p2.imbalance, 1.05);
  // 4 parts: 2x2 blocks cut 40, four strips 60.
  const Partition p4 = partition_particles(g, 4);
  const Partition s4 = index_blocks(g, 4);
  print("20x20 grid, METIS", p4);
  print("20x20 grid, index blocks (strips)", s4);
  EXPECT_EQ(s4.edge_cut, 60);
  EXPECT_LE(p4.edge_cut, 45);
  EXPECT_LE(p4.edge_cut, s4.edge_cut);
  EXPECT_LE(p4.imbalance, 1.05);
  // 3 parts: strips cut 40 (the optimum for three equal parts of a square is
  // close to that).
  const Partition p3 = partition_particles(g, 3);
  const Partition s3 = index_blocks(g, 3);
  print("20x20 grid, METIS", p3);
  print("20x20 grid, index blocks (strips)", s3);
  EXPECT_LE(p3.edge_cut, 46);
  EXPECT_LE(p3.edge_cut, s3.edge_cut);
  EXPECT_LE(p3.imbalance, 1.05);
}

TEST(Partition, ConnectedGraphGivesContiguousParts) {
  // The grid is connected, so METIS_OPTION_CONTIG is requested: every part
  // must induce a connected subgraph.
  const ParticleGraph g = grid_graph(20, 20);
  for (int parts = 2; parts <= 6; ++parts) {
    const Partition p = partition_particles(g, parts, 3u);
    for (int q = 0; q < parts; ++q) EXPECT_EQ(components_of_part(g, p.owner, q), 1) << parts << " parts, part " << q;
  }
  // Dumbbell: a 10 x 6 grid A (60 vertices) whose centre is bridged to a
  // corner of a 5 x 8 grid B (40). Halving needs 10 vertices of A with B;
  // the cheapest (METIS without CONTIG, cut 7-8 for seeds 1-3) is a corner
  // of A away from the bridge, which leaves that part in two pieces. With
  // CONTIG the piece must hold the bridge end (cut 9-14).
  ParticleGraph d = grid_graph(10, 6);
  const ParticleGraph b = grid_graph(5, 8);
  d.vertex_weight.resize(100, 1);
  for (auto [i, j] : b.edges) d.edges.emplace_back(60 + i, 60 + j);
  d.edges.emplace_back(5 + 10 * 3, 60);
  for (unsigned seed = 1; seed <= 3; ++seed) {
    const Partition p = partition_particles(d, 2, seed);
    print(("dumbbell, seed " + std::to_string(seed)).c_str(), p);
    for (int q = 0; q < 2; ++q) EXPECT_EQ(components_of_part(d, p.owner, q), 1) << "seed " << seed << ", part " << q;
    EXPECT_LE(p.edge_cut, 16);
    EXPECT_LE(p.imbalance, 1.05);
  }
}

// ---- weights --------------------------------------------------------------------

TEST(Partition, BalancesVertexWeightNotCount) {
  // 40 x 10 strip; the left half (columns 0..19) weighs 10 per vertex, the
  // right half 1: total 2200. Halving the count (cut at column 20) would give
  // weights 2000 / 200 (imbalance 1.82); halving the weight needs a cut near
  // column 11, i.e. ~110 / 290 vertices.
  ParticleGraph g = grid_graph(40, 10);
  for (int j = 0; j < 10; ++j)
    for (int i = 0; i < 20; ++i) g.vertex_weight[i + 40 * j] = 10;
  const Partition p = partition_particles(g, 2);
  print("40x10 strip, weights 10 | 1", p);
  EXPECT_LE(p.imbalance, 1.1);
  EXPECT_EQ(p.part_weight[0] + p.part_weight[1], 2200);
  std::vector<int> count(2, 0);
  for (int o : p.owner) ++count[o];
  std::printf("[partition] 40x10 strip: vertex counts %d / %d\n", count[0], count[1]);
  EXPECT_GT(std::max(count[0], count[1]), 1.3 * 200) << "balanced by count, not by weight";
  EXPECT_LE(p.edge_cut, 14);  // a straight cut crosses 10 edges
}

TEST(Partition, DuplicateEdgesActAsWeightsAndSelfPairsAreIgnored) {
  // Ring of 8: pairs (0,1), (2,3), (4,5), (6,7) carry 5 candidates each (in
  // both orders), the links between pairs one. Two parts of 4 must cut two
  // single links (cut 2); cutting through a heavy pair costs at least 5.
  ParticleGraph g;
  g.vertex_weight.assign(8, 1);
  for (int k = 0; k < 8; k += 2) {
    for (int m = 0; m < 5; ++m) g.edges.emplace_back(m % 2 ? k : k + 1, m % 2 ? k + 1 : k);
    g.edges.emplace_back(k + 1, (k + 2) % 8);
    g.edges.emplace_back(k, k);  // self-pair: ignored
  }
  const Partition p = partition_particles(g, 2);
  print("ring of 8 with heavy pairs", p);
  EXPECT_EQ(p.edge_cut, 2);
  EXPECT_EQ(p.metis_objval, 2);
  EXPECT_DOUBLE_EQ(p.imbalance, 1.0);
  for (int k = 0; k < 8; k += 2) EXPECT_EQ(p.owner[k], p.owner[k + 1]) << "heavy pair " << k << " split";
}

TEST(Partition, JammedMixturePacking) {
  // The real use: the contact-candidate graph (gap < 0.05 <d>) of a jammed
  // 300-disk packing with half of the area deformable; a deformable disk
  // carries many unknowns (120 here, a mesh), a rigid one 3 (x, y, rotation).
  // The box side is L ~ 17 <d> and a straight cut crosses ~1.3 contacts per
  // <d>: ~22 for 2 parts, ~44 for 4 (two crossing cuts). Index blocks (random
  // placement order) cut about half / three quarters of the ~620 candidates.
  const int n = 300;
  DiskPacking pk = make_jammed_packing(n, 1u, PackingOptions{});
  assign_deformable(pk, 0.5, 1u);
  ParticleGraph g;
  for (int i = 0; i < n; ++i) g.vertex_weight.push_back(pk.deformable[i] ? 120 : 3);
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j)
      if (std::hypot(pk.x[i] - pk.x[j], pk.y[i] - pk.y[j]) < pk.radius[i] + pk.radius[j] + 0.05)
        g.edges.emplace_back(i, j);
  std::printf("[partition] jammed packing: %d disks, %zu candidates\n", n, g.edges.size());
  const long bound[5] = {0, 0, 30, 50, 60};
  for (int parts = 2; parts <= 4; ++parts) {
    const Partition p = partition_particles(g, parts);
    const Partition blocks = index_blocks(g, parts);
    print(("jammed packing, METIS, " + std::to_string(parts) + " parts").c_str(), p);
    print(("jammed packing, index blocks, " + std::to_string(parts) + " parts").c_str(), blocks);
    EXPECT_LE(p.edge_cut, bound[parts]);
    EXPECT_LT(p.edge_cut, blocks.edge_cut / 5);
    EXPECT_LE(p.imbalance, 1.05);
    EXPECT_EQ(p.edge_cut, p.metis_objval);
  }
}

// ---- determinism and reporting ---------------------------------------------------------

TEST(Partition, DeterministicForAGivenSeed) {
  const ParticleGraph g = random_geometric_graph(300, 0.1, 11u);
  for (int parts = 2; parts <= 4; ++parts) {
    const Partition a = partition_particles(g, parts, 5u);
    const Partition b = partition_particles(g, parts, 5u);
    EXPECT_EQ(a.owner, b.owner) << parts << " parts";
    EXPECT_EQ(a.edge_cut, b.edge_cut);
  }
  // A different seed is a different METIS run; it must still be a valid partition.
  const Partition c = partition_particles(g, 3, 6u);
  const Partition d = partition_particles(g, 3, 5u);
  std::printf("[partition] seeds 5 and 6 (3 parts): cuts %ld and %ld, owners %s\n", d.edge_cut, c.edge_cut,
              c.owner == d.owner ? "identical" : "differ");
  EXPECT_LE(c.imbalance, 1.05);
}

TEST(Partition, EvaluateAgreesWithMetisAndBruteForce) {
  // Contact candidates with duplicates, both orders and self-pairs, as a
  // contact detection would list them (deformable disks touch at several nodes).
  ParticleGraph g = random_geometric_graph(300, 0.1, 13u);
  std::mt19937_64 eng(99u);
  const std::size_t m = g.edges.size();
  for (std::size_t k = 0; k < m; ++k) {
    const auto e = g.edges[k];
    const int extra = static_cast<int>(eng() % 3);  // 0, 1 or 2 more candidates
    for (int r = 0; r < extra; ++r) g.edges.emplace_back(r % 2 ? e : std::make_pair(e.second, e.first));
  }
  for (int i = 0; i < 300; i += 37) g.edges.emplace_back(i, i);
  for (int i = 0; i < 300; ++i) g.vertex_weight[i] = 1 + static_cast<long>(eng() % 12);
  std::shuffle(g.edges.begin(), g.edges.end(), eng);
  for (int parts = 2; parts <= 5; ++parts) {
    const Partition p = partition_particles(g, parts);
    print(("weighted multigraph, " + std::to_string(parts) + " parts").c_str(), p);
    EXPECT_EQ(p.edge_cut, p.metis_objval);
    EXPECT_EQ(p.edge_cut, brute_force_cut(g, p.owner));
    EXPECT_LE(p.imbalance, 1.05);
    // Any owner vector: a round-robin assignment.
    Partition q;
    q.parts = parts;
    for (int i = 0; i < 300; ++i) q.owner.push_back((i * 7) % parts);
    evaluate_partition(g, &q);
    EXPECT_EQ(q.edge_cut, brute_force_cut(g, q.owner));
    std::vector<long> w(parts, 0);
    for (int i = 0; i < 300; ++i) w[q.owner[i]] += g.vertex_weight[i];
    EXPECT_EQ(q.part_weight, w);
    const long total = std::accumulate(w.begin(), w.end(), 0L);
    EXPECT_DOUBLE_EQ(q.imbalance, static_cast<double>(*std::max_element(w.begin(), w.end())) * parts / total);
    EXPECT_GT(q.edge_cut, 2 * p.edge_cut);
  }
  Partition bad;
  bad.parts = 2;
  bad.owner.assign(300, 0);
  bad.owner[17] = 2;
  EXPECT_THROW(evaluate_partition(g, &bad), std::invalid_argument);
  bad.owner.assign(299, 0);
  EXPECT_THROW(evaluate_partition(g, &bad), std::invalid_argument);
}

TEST(Partition, ParticlesByOwnerIsAGroupedPermutation) {
  const ParticleGraph g = random_geometric_graph(300, 0.1, 17u);
  const Partition p = partition_particles(g, 4);
  const std::vector<int> order = particles_by_owner(p);
  ASSERT_EQ(order.size(), 300u);
  std::vector<int> sorted = order;
  std::sort(sorted.begin(), sorted.end());
  for (int i = 0; i < 300; ++i) ASSERT_EQ(sorted[i], i) << "not a permutation";
  for (std::size_t k = 1; k < order.size(); ++k) {
    const int a = order[k - 1], b = order[k];
    ASSERT_LE(p.owner[a], p.owner[b]) << "owners not grouped at position " << k;
    if (p.owner[a] == p.owner[b]) ASSERT_LT(a, b) << "not increasing inside owner " << p.owner[a];
  }
  // Each owner's block has the size of its part.
  std::vector<int> count(4, 0);
  for (int o : p.owner) ++count[o];
  int k = 0;
  for (int q = 0; q < 4; ++q)
    for (int c = 0; c < count[q]; ++c, ++k) ASSERT_EQ(p.owner[order[k]], q);
  // A hand-made case.
  Partition h;
  h.parts = 3;
  h.owner = {2, 0, 2, 1, 0};
  EXPECT_EQ(particles_by_owner(h), (std::vector<int>{1, 4, 3, 0, 2}));
  h.owner[1] = 3;
  EXPECT_THROW(particles_by_owner(h), std::invalid_argument);
}

// ---- degenerate input ------------------------------------------------------------------

TEST(Partition, FewerParticlesThanParts) {
  // Documented fallback: particle i on part i, the other parts empty.
  ParticleGraph one;
  one.vertex_weight = {7};
  const Partition p = partition_particles(one, 2);
  print("1 particle", p);
  EXPECT_EQ(p.owner, std::vector<int>{0});
  EXPECT_EQ(p.part_weight, (std::vector<long>{7, 0}));
  EXPECT_DOUBLE_EQ(p.imbalance, 2.0);
  EXPECT_EQ(p.edge_cut, 0);
  EXPECT_EQ(p.metis_objval, -1);
  ParticleGraph three;
  three.vertex_weight = {1, 2, 3};
  three.edges = {{0, 1}, {1, 2}, {2, 1}};
  const Partition q = partition_particles(three, 5);
  EXPECT_EQ(q.owner, (std::vector<int>{0, 1, 2}));
  EXPECT_EQ(q.edge_cut, 3);
  EXPECT_EQ(q.part_weight, (std::vector<long>{1, 2, 3, 0, 0}));
  const Partition empty = partition_particles(ParticleGraph{}, 3);
  EXPECT_TRUE(empty.owner.empty());
  EXPECT_EQ(empty.part_weight, (std::vector<long>{0, 0, 0}));
  EXPECT_TRUE(particles_by_owner(empty).empty());
}

TEST(Partition, EmptyEdgeList) {
  // No contacts at all (a loose packing): only the balance matters, cut 0.
  ParticleGraph g;
  for (int i = 0; i < 40; ++i) g.vertex_weight.push_back(1 + i % 3);
  for (int parts = 2; parts <= 4; ++parts) {
    const Partition p = partition_particles(g, parts);
    print(("40 isolated particles, " + std::to_string(parts) + " parts").c_str(), p);
    EXPECT_EQ(p.edge_cut, 0);
    EXPECT_EQ(p.metis_objval, 0);
    ASSERT_EQ(p.owner.size(), 40u);
    for (int o : p.owner) ASSERT_TRUE(o >= 0 && o < parts);
    EXPECT_LE(p.imbalance, 1.1);
  }
  // Isolated particles next to a connected cluster (not contiguous-able).
  ParticleGraph h = grid_graph(10, 10);
  h.vertex_weight.resize(110, 1);
  const Partition q = partition_particles(h, 2);
  print("10x10 grid + 10 isolated", q);
  EXPECT_LE(q.edge_cut, 14);
  EXPECT_LE(q.imbalance, 1.05);
}

TEST(Partition, InvalidInputRejected) {
  const ParticleGraph g = grid_graph(4, 4);
  EXPECT_THROW(partition_particles(g, 0), std::invalid_argument);
  EXPECT_THROW(partition_particles(g, -3), std::invalid_argument);
  EXPECT_THROW(partition_particles(g, 2, 1u, 1.0), std::invalid_argument);
  ParticleGraph w = g;
  w.vertex_weight[5] = 0;
  EXPECT_THROW(partition_particles(w, 2), std::invalid_argument);
  ParticleGraph e = g;
  e.edges.emplace_back(3, 16);
  EXPECT_THROW(partition_particles(e, 2), std::invalid_argument);
  e.edges.back() = {-1, 2};
  EXPECT_THROW(partition_particles(e, 1), std::invalid_argument);
  try {
    partition_particles(g, 0);
  } catch (const std::invalid_argument &ex) {
    EXPECT_NE(std::string(ex.what()).find("parts = 0"), std::string::npos) << ex.what();
  }
}

int main(int argc, char **argv) {
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}

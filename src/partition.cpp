// Particle partitioning with METIS k-way (include/deformix/partition.hpp).
// Choices:
// - The CSR adjacency METIS wants is symmetric without self loops: every
//   candidate (i, j), i != j, is entered as i->j and j->i, sorted, and equal
//   entries merged into one edge whose weight is their count, so duplicates
//   and both orders add up and METIS's cut equals our recount on the raw list.
// - Everything METIS sees is idx_t (32 or 64 bit depending on the build);
//   weights and sizes are checked to fit before the call.
// - k-way rather than recursive bisection: it is the one that minimizes the
//   total cut directly and honours CONTIG; CONTIG only on connected graphs
//   (METIS errors out otherwise), checked by a breadth-first search.
// - The cut and balance are recounted by evaluate_partition, so reports do not
//   depend on what METIS returns and work for any owner vector.
#include "deformix/partition.hpp"

#include <metis.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace deformix {
namespace {

constexpr long kIdxMax = static_cast<long>(std::numeric_limits<idx_t>::max());

void check_graph(const ParticleGraph &g) {
  const int n = g.size();
  long total = 0;
  for (int i = 0; i < n; ++i) {
    const long w = g.vertex_weight[i];
    if (w < 1) throw std::invalid_argument("partition: particle " + std::to_string(i) + " has weight " +
                                           std::to_string(w) + " (must be >= 1)");
    if (w > kIdxMax - total) throw std::invalid_argument("partition: total vertex weight overflows METIS's idx_t");
    total += w;
  }
  if (static_cast<double>(g.edges.size()) * 2 > static_cast<double>(kIdxMax))
    throw std::invalid_argument("partition: too many edges for METIS's idx_t");
  for (const auto &[i, j] : g.edges)
    if (i < 0 || i >= n || j < 0 || j >= n)
      throw std::invalid_argument("partition: edge (" + std::to_string(i) + ", " + std::to_string(j) +
                                  ") has an end outside [0, " + std::to_string(n) + ")");
}

struct Csr {
  std::vector<idx_t> xadj, adjncy, adjwgt;
};

// Symmetric CSR with merged duplicates (weight = multiplicity), no self loops.
Csr build_csr(const ParticleGraph &g) {
  const int n = g.size();
  std::vector<std::pair<int, int>> arcs;
  arcs.reserve(2 * g.edges.size());
  for (const auto &[i, j] : g.edges)
    if (i != j) arcs.emplace_back(i, j), arcs.emplace_back(j, i);
  std::sort(arcs.begin(), arcs.end());
  Csr c;
  c.xadj.assign(n + 1, 0);
  for (std::size_t k = 0; k < arcs.size(); ++k) {
    if (k > 0 && arcs[k] == arcs[k - 1]) {
      ++c.adjwgt.back();
      continue;
    }
    c.adjncy.push_back(static_cast<idx_t>(arcs[k].second));
    c.adjwgt.push_back(1);
    ++c.xadj[arcs[k].first + 1];
  }
  for (int i = 0; i < n; ++i) c.xadj[i + 1] += c.xadj[i];
  return c;
}

bool connected(const Csr &c, int n) {
  if (n == 0) return true;
  std::vector<char> seen(n, 0);
  std::vector<int> queue{0};
  seen[0] = 1;
  for (std::size_t q = 0; q < queue.size(); ++q)
    for (idx_t k = c.xadj[queue[q]]; k < c.xadj[queue[q] + 1]; ++k)
      if (!seen[c.adjncy[k]]) seen[c.adjncy[k]] = 1, queue.push_back(static_cast<int>(c.adjncy[k]));
  return static_cast<int>(queue.size()) == n;
}

}  // namespace

Partition partition_particles(const ParticleGraph &g, int parts, unsigned seed, double balance_tolerance) {
  if (parts < 1) throw std::invalid_argument("partition: parts = " + std::to_string(parts) + " (must be >= 1)");
  if (!(balance_tolerance > 1.0))
    throw std::invalid_argument("partition: balance tolerance " + std::to_string(balance_tolerance) +
                                " must be > 1 (max part weight / mean part weight)");
  check_graph(g);
  const int n = g.size();
  Partition p;
  p.parts = parts;
  p.owner.assign(n, 0);
  if (parts > 1 && n < parts) {
    for (int i = 0; i < n; ++i) p.owner[i] = i;  // documented fallback: parts n .. parts-1 empty
  } else if (parts > 1) {
    Csr c = build_csr(g);
    std::vector<idx_t> vwgt(g.vertex_weight.begin(), g.vertex_weight.end());
    // METIS reads adjncy/adjwgt even when empty: give it valid pointers.
    if (c.adjncy.empty()) c.adjncy.push_back(0), c.adjwgt.push_back(0);
    idx_t options[METIS_NOPTIONS];
    METIS_SetDefaultOptions(options);
    options[METIS_OPTION_OBJTYPE] = METIS_OBJTYPE_CUT;
    options[METIS_OPTION_NUMBERING] = 0;
    options[METIS_OPTION_SEED] = static_cast<idx_t>(seed & 0x7fffffffu);
    const long ufactor = std::lround(1000 * std::min(balance_tolerance - 1, 1000.0));  // 1.03 -> 30
    options[METIS_OPTION_UFACTOR] = static_cast<idx_t>(std::max(1L, ufactor));
    options[METIS_OPTION_CONTIG] = connected(c, n) ? 1 : 0;
    idx_t nvtxs = n, ncon = 1, nparts = parts, objval = 0;
    std::vector<idx_t> part(n, 0);
    const int rc = METIS_PartGraphKway(&nvtxs, &ncon, c.xadj.data(), c.adjncy.data(), vwgt.data(), nullptr,
                                       c.adjwgt.data(), &nparts, nullptr, nullptr, options, &objval, part.data());
    if (rc != METIS_OK)
      throw std::runtime_error("partition: METIS_PartGraphKway failed with code " + std::to_string(rc) +
                               (rc == METIS_ERROR_INPUT ? " (METIS_ERROR_INPUT)" :
                                rc == METIS_ERROR_MEMORY ? " (METIS_ERROR_MEMORY)" : " (METIS_ERROR)") +
                               " for " + std::to_string(n) + " particles into " + std::to_string(parts) + " parts");
    for (int i = 0; i < n; ++i) p.owner[i] = static_cast<int>(part[i]);
    p.metis_objval = static_cast<long>(objval);
  }
  evaluate_partition(g, &p);
  return p;
}

void evaluate_partition(const ParticleGraph &g, Partition *p) {
  check_graph(g);
  const int n = g.size();
  if (p->parts < 1) throw std::invalid_argument("partition: parts = " + std::to_string(p->parts) + " (must be >= 1)");
  if (static_cast<int>(p->owner.size()) != n)
    throw std::invalid_argument("partition: " + std::to_string(p->owner.size()) + " owners for " +
                                std::to_string(n) + " particles");
  p->part_weight.assign(p->parts, 0);
  long total = 0;
  for (int i = 0; i < n; ++i) {
    const int o = p->owner[i];
    if (o < 0 || o >= p->parts)
      throw std::invalid_argument("partition: particle " + std::to_string(i) + " owned by " + std::to_string(o) +
                                  ", outside [0, " + std::to_string(p->parts) + ")");
    p->part_weight[o] += g.vertex_weight[i];
    total += g.vertex_weight[i];
  }
  p->edge_cut = 0;
  for (const auto &[i, j] : g.edges)
    if (p->owner[i] != p->owner[j]) ++p->edge_cut;  // self-pairs never cut
  const long max_w = *std::max_element(p->part_weight.begin(), p->part_weight.end());
  p->imbalance = total > 0 ? static_cast<double>(max_w) * p->parts / static_cast<double>(total) : 1.0;
}

std::vector<int> particles_by_owner(const Partition &p) {
  std::vector<int> start(std::max(p.parts, 0) + 1, 0);
  for (std::size_t i = 0; i < p.owner.size(); ++i) {
    const int o = p.owner[i];
    if (o < 0 || o >= p.parts)
      throw std::invalid_argument("partition: particle " + std::to_string(i) + " owned by " + std::to_string(o) +
                                  ", outside [0, " + std::to_string(p.parts) + ")");
    ++start[o + 1];
  }
  for (int q = 0; q < p.parts; ++q) start[q + 1] += start[q];
  std::vector<int> order(p.owner.size());
  for (std::size_t i = 0; i < p.owner.size(); ++i) order[start[p.owner[i]]++] = static_cast<int>(i);
  return order;
}

}  // namespace deformix

// Particle partitioning for the MPI distribution: particles are the unit of
// ownership (all unknowns of a particle live on one rank), so the work is a
// weighted graph partition of the particle contact graph.
//
//   vertices  particles, weight w_i = number of unknowns of particle i (>= 1)
//   edges     contact candidates between two particles; k candidates between
//             the same pair give one edge of weight k (the coupling blocks of
//             the tangent that cross ranks grow with it)
//   edge cut  C = sum of the weights of edges whose ends have different owners
//   imbalance I = max_p W_p / (sum_p W_p / parts), W_p = sum of w_i owned by p
//
// METIS k-way (METIS_PartGraphKway) minimizes C subject to I <= tolerance.
// Plain C++17, no PETSc; METIS 5 is an implementation detail of the .cpp.
#pragma once
#include <utility>
#include <vector>

namespace deformix {

struct ParticleGraph {
  std::vector<long> vertex_weight;         // per particle: its number of unknowns (>= 1)
  std::vector<std::pair<int, int>> edges;  // one entry per contact candidate between particles i != j; duplicates
                                           // and both orders allowed (they add up as edge weight); self-pairs are
                                           // ignored; wall contacts are never given
  int size() const { return static_cast<int>(vertex_weight.size()); }
};

struct Partition {
  int parts = 1;
  std::vector<int> owner;         // rank of each particle, in [0, parts)
  long edge_cut = 0;              // C above, recounted from the graph (not taken from METIS)
  double imbalance = 1.0;         // I above (1 when the total weight is 0)
  std::vector<long> part_weight;  // W_p, per part
  long metis_objval = -1;         // edge cut reported by METIS (-1: METIS was not called); equals edge_cut
};

// Partition of the particle graph into `parts` parts.
// - parts == 1: everything on 0, METIS not called.
// - n < parts (fewer particles than parts): no METIS either; particle i goes
//   to part i and parts n .. parts-1 stay empty (a valid, if wasteful,
//   distribution: PETSc accepts ranks that own nothing).
// - otherwise METIS k-way, edge-cut objective, load tolerance
//   `balance_tolerance` (METIS ufactor = 1000 (tolerance - 1), 1.03 -> 30),
//   seeded with `seed` (METIS_OPTION_SEED): the same input gives the same
//   owners. Contiguous parts (METIS_OPTION_CONTIG) are requested when the
//   graph is connected; METIS refuses them on a disconnected graph (e.g. one
//   with rattlers), which is then partitioned without that request. METIS
//   may leave parts empty or exceed the tolerance on tiny graphs.
// Throws std::invalid_argument for parts < 1, a vertex weight < 1, an edge
// end outside [0, n), balance_tolerance <= 1 or weights too large for METIS's
// idx_t; std::runtime_error (naming the METIS return code) when METIS fails.
Partition partition_particles(const ParticleGraph &g, int parts, unsigned seed = 1,
                              double balance_tolerance = 1.03);

// Fills p->edge_cut, p->imbalance and p->part_weight for the owners in
// p->owner and p->parts (e.g. after the contact graph changed); leaves
// metis_objval alone. Throws std::invalid_argument when p->owner does not
// have one entry per particle in [0, p->parts) or the graph is invalid.
void evaluate_partition(const ParticleGraph &g, Partition *p);

// Particles ordered by (owner, original index): entry k is the original index
// of the particle numbered k in the numbering where each rank's particles are
// contiguous (rank 0's first). Throws std::invalid_argument for owners outside
// [0, p.parts).
std::vector<int> particles_by_owner(const Partition &p);

}  // namespace deformix

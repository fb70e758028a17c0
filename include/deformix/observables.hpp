// Observables of a packing state (the paper's section III and IV).
//
//   packing fraction  phi = (sum of current particle areas) / box area
//   coordination      Z = 2 N_c / N_p, N_c the particle pairs carrying a
//                     normal force above 1e-5 P <d> (several node contacts
//                     between two deformable disks count once); Z_nr the same without
//                     rattlers: particles with fewer than 3 force-carrying
//                     contacts (2 with friction), walls included, removed
//                     iteratively
//   stress            sigma_ij = (1/V) sum_c f_i l_j with l the branch
//                     vector from the master particle to the slave one for
//                     particle pairs, and -(x_c - x_p) for wall contacts
//                     (compression positive). At equilibrium the mean
//                     P_sigma = (sigma_xx + sigma_yy) / 2 equals the imposed
//                     P exactly: Sum_p x_p (x) F_p = 0 when every particle's
//                     net force vanishes, so only the walls' virial remains.
//   volumetric strain mean over deformable disks of (A / A_0 - 1).
#pragma once
#include <vector>

#include "deformix/problem.hpp"

namespace deformix {

struct PackingObservables {
  double packing_fraction = 0.0;
  double coordination = 0.0;             // Z
  double coordination_no_rattlers = 0.0; // Z_nr
  int rattlers = 0;
  int force_pairs = 0;                   // particle pairs carrying force
  int contacts = 0;                      // contact points carrying force (walls included)
  int sliding_contacts = 0;
  double stress[4] = {0, 0, 0, 0};       // sigma_xx, sigma_xy, sigma_yx, sigma_yy (compression > 0)
  double mean_stress = 0.0;              // P_sigma
  double mean_volumetric_strain = 0.0;   // deformable disks
  double max_penetration = 0.0;
};

PackingObservables ComputeObservables(const CompactionProblem &problem);
// P_sigma alone (the mean of ComputeObservables' stress, one pass over the
// contact forces): the virial part of the level criteria.
double MeanContactStress(const CompactionProblem &problem);

// The contact network (force chains): one segment per force-carrying
// particle pair, between the two particle centres (rigid centres, deformable
// centroids), and one per particle-wall pair, from the particle centre to
// the foot of the perpendicular on the wall. The forces of the pair's
// contacts (several nodes of a deformable disk) are summed; normal_force is
// the component of that force on the slave along the unit vector from the
// master's centre (or the wall) to the slave's (compression positive),
// tangential_force the component along that vector turned by +90 degrees.
// Pairs whose normal force is at most 1e-5 P <d> are left out (as for Z).
struct ForceNetwork {
  std::vector<double> points;  // 2 per segment: (x, y) of its two ends, i.e. 4 values per segment
  std::vector<int> particles;  // 2 per segment: slave particle, master particle (-1..-4: left, right, bottom, top wall)
  std::vector<double> normal_force, tangential_force;
  int segments() const { return static_cast<int>(normal_force.size()); }
};
ForceNetwork ComputeForceNetwork(const CompactionProblem &problem);

}  // namespace deformix

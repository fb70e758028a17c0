#include "deformix/observables.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <set>
#include <utility>

namespace deformix {

namespace {
// Particle centres (x, y per particle): rigid centres, deformable centroids.
std::vector<double> ParticleCentres(const CompactionProblem &problem) {
  std::vector<double> centre(2 * problem.NumParticles(), 0.0);
  for (int b = 0; b < static_cast<int>(problem.Bodies().size()); ++b)
    problem.BodyCentroid(b, &centre[2 * problem.Bodies()[b].particle]);
  for (int r = 0; r < static_cast<int>(problem.RigidBodies().size()); ++r)
    problem.RigidPosition(r, &centre[2 * problem.RigidBodies()[r].particle], nullptr);
  return centre;
}

// The branch vector l of a contact force on the slave (ComputeObservables).
void BranchVector(const ContactForce &f, const std::vector<double> &centre, double l[2]) {
  const int a = f.master_particle, b = f.slave_particle;
  if (a >= 0) {
    l[0] = centre[2 * b] - centre[2 * a], l[1] = centre[2 * b + 1] - centre[2 * a + 1];
  } else {
    l[0] = -(f.point[0] - centre[2 * b]), l[1] = -(f.point[1] - centre[2 * b + 1]);
  }
}
}  // namespace

double MeanContactStress(const CompactionProblem &problem) {
  const StateSummary s = problem.Summary();
  const std::vector<double> centre = ParticleCentres(problem);
  double trace = 0.0;
  for (const ContactForce &f : problem.ContactForces()) {
    if (!(f.normal_multiplier > 0.0)) continue;
    double l[2];
    BranchVector(f, centre, l);
    trace += f.force[0] * l[0] + f.force[1] * l[1];
  }
  return 0.5 * trace / (s.box_width * s.box_height);
}

PackingObservables ComputeObservables(const CompactionProblem &problem) {
  PackingObservables o;
  const StateSummary s = problem.Summary();
  o.packing_fraction = s.packing_fraction;
  o.max_penetration = s.max_penetration;
  const int np = problem.NumParticles();

  const std::vector<double> centre = ParticleCentres(problem);

  std::set<std::pair<int, int>> pairs;
  std::vector<std::set<int>> neighbours(np);  // force-carrying partners; walls as -1..-4
  const double V = s.box_width * s.box_height;
  // A contact counts (Z, rattlers, contacts) when it carries more than
  // 1e-5 P <d>. Smaller forces are below what a level resolves (its criterion
  // allows unbalanced forces of 1e-4 P <d>; at P/E = 1e-4 the SNES tolerance
  // alone, 1e-11 E <d>, is 1e-7 P <d>), and exactly touching contacts with
  // round-off forces are common in a settled packing: counting them made Z
  // depend on the number of ranks. Every force enters the stress.
  const double carrying = 1e-5 * problem.Pressure() * problem.MeanDiameter();
  for (const ContactForce &f : problem.ContactForces()) {
    if (f.state == kSliding) ++o.sliding_contacts;
    if (!(f.normal_multiplier > 0.0)) continue;
    const int a = f.master_particle, b = f.slave_particle;
    const bool counts = f.normal_multiplier > carrying;
    o.contacts += counts;
    double l[2];
    BranchVector(f, centre, l);
    if (a >= 0) {
      if (counts) pairs.insert({std::min(a, b), std::max(a, b)}), neighbours[a].insert(b), neighbours[b].insert(a);
    } else {
      // Which wall: the force direction tells.
      const int wall = f.force[0] > 0 ? -1 : f.force[0] < 0 ? -2 : f.force[1] > 0 ? -3 : -4;
      if (counts) neighbours[b].insert(wall);
    }
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 2; ++j) o.stress[2 * i + j] += f.force[i] * l[j] / V;
  }
  o.mean_stress = 0.5 * (o.stress[0] + o.stress[3]);
  o.force_pairs = static_cast<int>(pairs.size());
  o.coordination = np ? 2.0 * pairs.size() / np : 0.0;

  // Rattlers: fewer than 3 force-carrying contacts (2 with friction), removed iteratively.
  const size_t min_contacts = problem.Frictional() ? 2 : 3;
  std::vector<char> rattler(np, 0);
  for (bool changed = true; changed;) {
    changed = false;
    for (int p = 0; p < np; ++p) {
      if (rattler[p]) continue;
      size_t count = 0;
      for (int q : neighbours[p]) count += (q < 0 || !rattler[q]);
      if (count < min_contacts) rattler[p] = 1, changed = true;
    }
  }
  int n_pairs_nr = 0;
  for (const auto &pr : pairs) n_pairs_nr += !rattler[pr.first] && !rattler[pr.second];
  o.rattlers = static_cast<int>(std::count(rattler.begin(), rattler.end(), 1));
  o.coordination_no_rattlers = np > o.rattlers ? 2.0 * n_pairs_nr / (np - o.rattlers) : 0.0;

  double strain = 0.0;
  for (int b = 0; b < static_cast<int>(problem.Bodies().size()); ++b) {
    const std::vector<double> ratio = problem.CellAreaRatio(b);
    double area = 0.0;
    for (size_t e = 0; e < ratio.size(); ++e) area += ratio[e] * problem.Bodies()[b].ref_cell_area[e];
    strain += area / problem.Bodies()[b].ref_area - 1.0;
  }
  if (!problem.Bodies().empty()) o.mean_volumetric_strain = strain / problem.Bodies().size();
  return o;
}

ForceNetwork ComputeForceNetwork(const CompactionProblem &problem) {
  const std::vector<double> centre = ParticleCentres(problem);
  const double *w = problem.Walls();
  const double carrying = 1e-5 * problem.Pressure() * problem.MeanDiameter();  // as for Z (ComputeObservables)
  // Sum of the forces on the slave per (slave, master) pair; walls are
  // masters -1..-4 (left, right, bottom, top).
  std::map<std::pair<int, int>, std::array<double, 2>> sum;
  for (const ContactForce &f : problem.ContactForces()) {
    if (!(f.normal_multiplier > 0.0)) continue;
    const int master = f.master_particle >= 0 ? f.master_particle : -1 - f.wall;
    std::array<double, 2> &s = sum[{f.slave_particle, master}];
    s[0] += f.force[0], s[1] += f.force[1];
  }
  ForceNetwork net;
  for (const auto &[pair, F] : sum) {
    const auto [slave, master] = pair;
    const double *xs = &centre[2 * slave];
    double xm[2];
    if (master >= 0) {
      xm[0] = centre[2 * master], xm[1] = centre[2 * master + 1];
    } else {  // the foot of the perpendicular on the wall
      const Wall wall = static_cast<Wall>(-1 - master);
      xm[0] = xs[0], xm[1] = xs[1];
      xm[WallBox::axis(wall)] = w[wall];
    }
    double n[2] = {xs[0] - xm[0], xs[1] - xm[1]};
    const double len = std::hypot(n[0], n[1]);
    if (!(len > 0.0)) continue;
    n[0] /= len, n[1] /= len;
    const double fn = F[0] * n[0] + F[1] * n[1];
    if (!(fn > carrying)) continue;
    net.points.insert(net.points.end(), {xs[0], xs[1], xm[0], xm[1]});
    net.particles.insert(net.particles.end(), {slave, master});
    net.normal_force.push_back(fn);
    net.tangential_force.push_back(-F[0] * n[1] + F[1] * n[0]);
  }
  return net;
}

}  // namespace deformix

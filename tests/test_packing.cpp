// Tests of the packing generator (include/deformix/packing.hpp): diameter
// distribution, jammed frictionless packings (overlap, walls, packing
// fraction, isostatic contact count), determinism, deformable assignment.
// Bounds were set from measurements (seeds 1-12, see comments) and the
// physics they encode is stated next to each one.
#include "deformix/packing.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <map>
#include <numeric>
#include <stdexcept>
#include <string>
#include <vector>

using namespace deformix;

namespace {

constexpr double kPi = 3.14159265358979323846;

double mean_diameter(const DiskPacking &p) {
  double s = 0;
  for (double r : p.radius) s += 2 * r;
  return s / p.size();
}

double disk_area(const DiskPacking &p, int i) { return kPi * p.radius[i] * p.radius[i]; }

// Packings are cached: several tests inspect the same ones.
const DiskPacking &cached_packing(int n, unsigned seed, JammingStats *stats = nullptr) {
  static std::map<std::pair<int, unsigned>, std::pair<DiskPacking, JammingStats>> cache;
  auto key = std::make_pair(n, seed);
  auto it = cache.find(key);
  if (it == cache.end()) {
    JammingStats st;
    const auto t0 = std::chrono::steady_clock::now();
    DiskPacking p = make_jammed_packing(n, seed, PackingOptions{}, &st);
    const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::printf("[packing] n=%d seed=%u: %.2f s, %d minimizations, %lld FIRE steps, phi=%.5f, max overlap/<d>=%.2e\n", n,
                seed, t, st.minimizations, st.fire_iterations, packing_fraction(p), st.max_overlap);
    it = cache.emplace(key, std::make_pair(std::move(p), st)).first;
  }
  if (stats) *stats = it->second.second;
  return it->second.first;
}

}  // namespace

// ---- diameters ----------------------------------------------------------------

TEST(SampleDiameters, AreaFractionUniformOverDiameter) {
  const int n = 20000;
  const double dmin = 0.8, dmax = 1.2;
  const std::vector<double> d = sample_diameters(n, 12345u, dmin, dmax);
  ASSERT_EQ(static_cast<int>(d.size()), n);
  const int nb = 10;
  std::vector<double> area(nb, 0.0);
  std::vector<int> count(nb, 0);
  double total = 0;
  for (double di : d) {
    ASSERT_GE(di, dmin);
    ASSERT_LE(di, dmax);
    const int b = std::min(nb - 1, static_cast<int>((di - dmin) / (dmax - dmin) * nb));
    area[b] += di * di;
    ++count[b];
    total += di * di;
  }
  // Area fraction per diameter bin is 1/nb. Its sampling std is about
  // 0.1 * (1/sqrt(2000)) ~ 0.0023; 0.01 is > 4 sigma, while sampling the
  // number uniformly in d (a plausible bug) gives 0.065 ... 0.135.
  for (int b = 0; b < nb; ++b) EXPECT_NEAR(area[b] / total, 1.0 / nb, 0.01) << "bin " << b;
  // Chi-square of the counts against the number CDF
  // F(d) = (1/dmin - 1/d) / (1/dmin - 1/dmax); 9 dof, 30 ~ p = 4e-4.
  auto F = [&](double x) { return (1 / dmin - 1 / x) / (1 / dmin - 1 / dmax); };
  double chi2 = 0;
  for (int b = 0; b < nb; ++b) {
    const double lo = dmin + (dmax - dmin) * b / nb, hi = dmin + (dmax - dmin) * (b + 1) / nb;
    const double e = n * (F(hi) - F(lo));
    chi2 += (count[b] - e) * (count[b] - e) / e;
  }
  EXPECT_LT(chi2, 30.0);
  // Kolmogorov-Smirnov on the number CDF: sqrt(n) D < 1.95 (p ~ 0.001).
  std::vector<double> s = d;
  std::sort(s.begin(), s.end());
  double D = 0;
  for (int i = 0; i < n; ++i)
    D = std::max({D, std::fabs(F(s[i]) - static_cast<double>(i) / n), std::fabs(F(s[i]) - static_cast<double>(i + 1) / n)});
  EXPECT_LT(std::sqrt(static_cast<double>(n)) * D, 1.95);
  // Both ends of the range are reached (1/d is uniform: P(bin) ~ 0.1 each).
  EXPECT_LT(s.front(), dmin + 0.001);
  EXPECT_GT(s.back(), dmax - 0.001);
}

TEST(SampleDiameters, SeedDeterminesResult) {
  const auto a = sample_diameters(1000, 7u, 0.8, 1.2);
  const auto b = sample_diameters(1000, 7u, 0.8, 1.2);
  const auto c = sample_diameters(1000, 8u, 0.8, 1.2);
  ASSERT_EQ(a.size(), b.size());
  EXPECT_EQ(0, std::memcmp(a.data(), b.data(), a.size() * sizeof(double)));
  int same = 0;
  for (std::size_t i = 0; i < a.size(); ++i) same += (a[i] == c[i]);
  EXPECT_LT(same, 5);
}

TEST(SampleDiameters, DegenerateAndInvalidRanges) {
  for (double x : sample_diameters(10, 1u, 1.0, 1.0)) EXPECT_EQ(x, 1.0);
  EXPECT_TRUE(sample_diameters(0, 1u, 0.8, 1.2).empty());
  EXPECT_THROW(sample_diameters(-1, 1u, 0.8, 1.2), std::invalid_argument);
  EXPECT_THROW(sample_diameters(10, 1u, 0.0, 1.2), std::invalid_argument);
  EXPECT_THROW(sample_diameters(10, 1u, 1.2, 0.8), std::invalid_argument);
}

// ---- jammed packings ------------------------------------------------------------

namespace {

// Checks common to every jammed packing; phi band per size.
void check_jammed(int n, unsigned seed, double phi_lo, double phi_hi, double zm_lo, double zm_hi) {
  SCOPED_TRACE("n=" + std::to_string(n) + " seed=" + std::to_string(seed));
  JammingStats st;
  const DiskPacking &p = cached_packing(n, seed, &st);
  ASSERT_EQ(p.size(), n);
  ASSERT_EQ(static_cast<int>(p.radius.size()), n);
  ASSERT_EQ(static_cast<int>(p.deformable.size()), n);
  for (char c : p.deformable) EXPECT_EQ(c, 0);
  const double dm = mean_diameter(p);
  EXPECT_NEAR(st.mean_diameter, dm, 1e-12);
  const double tol = PackingOptions{}.target_overlap * dm;

  // Overlaps (pairs and walls) vanish to the target.
  const double mo = max_overlap(p);
  EXPECT_LE(mo, tol);
  EXPECT_NEAR(st.max_overlap * dm, mo, 1e-12);
  EXPECT_LE(st.residual_force, 1e-4);  // force-balanced soft state
  EXPECT_GT(st.energy, 0.0);           // jammed: positive (tiny) pressure

  // Every disk inside the walls (to the overlap tolerance); walls at {0,Lx,0,Ly}.
  EXPECT_EQ(p.walls[0], 0.0);
  EXPECT_EQ(p.walls[2], 0.0);
  EXPECT_GT(p.walls[1], 0.5 * p.walls[3]);  // nearly square (Lx/Ly 0.83-1.15 measured over 12 seeds, n = 50)
  EXPECT_LT(p.walls[1], 2.0 * p.walls[3]);
  for (int i = 0; i < n; ++i) {
    EXPECT_GE(p.x[i] - p.radius[i], p.walls[0] - tol);
    EXPECT_LE(p.x[i] + p.radius[i], p.walls[1] + tol);
    EXPECT_GE(p.y[i] - p.radius[i], p.walls[2] - tol);
    EXPECT_LE(p.y[i] + p.radius[i], p.walls[3] + tol);
  }

  // Mechanically stable: each wall carries force (some disk overlaps it), so
  // the box cannot shrink without overlap.
  const ContactNetwork touching = contact_network(p, 0.0);  // force-carrying: overlap > 0
  int wall_hits[4] = {0, 0, 0, 0};
  for (int k = 0; k < touching.size(); ++k)
    if (touching.j[k] < 0) ++wall_hits[-1 - touching.j[k]];
  for (int w = 0; w < 4; ++w) EXPECT_GT(wall_hits[w], 0) << "wall " << w;

  // Isotropic stress, as under the four pressure-driven walls of the contact
  // solver: the wall forces (sum of overlaps, unit stiffness) per unit wall
  // length are equal on all four walls, and equal to the virial stress of the
  // pair contacts. (A fixed square box jams with |sigma_xx / sigma_yy - 1| up
  // to 0.18 at 400 disks.)
  double wall_force[4] = {0, 0, 0, 0}, virial[2] = {0, 0};
  const double Lx = p.walls[1] - p.walls[0], Ly = p.walls[3] - p.walls[2];
  for (int i = 0; i < n; ++i) {
    const double r = p.radius[i];
    const double ov[4] = {r - p.x[i], p.x[i] + r - p.walls[1], r - p.y[i], p.y[i] + r - p.walls[3]};
    for (int w = 0; w < 4; ++w) wall_force[w] += std::max(0.0, ov[w]);
  }
  for (int k = 0; k < touching.size(); ++k) {
    const int i = touching.i[k], j = touching.j[k];
    if (j < 0) {
      const double arm[4] = {p.x[i], p.walls[1] - p.x[i], p.y[i], p.walls[3] - p.y[i]};  // wall to centre
      virial[(-1 - j) / 2] += -touching.gap[k] * arm[-1 - j];
      continue;
    }
    const double dx = p.x[j] - p.x[i], dy = p.y[j] - p.y[i], d = std::hypot(dx, dy);
    virial[0] += -touching.gap[k] * dx * dx / d;
    virial[1] += -touching.gap[k] * dy * dy / d;
  }
  const double s_left = wall_force[0] / Ly, s_right = wall_force[1] / Ly;
  const double s_bottom = wall_force[2] / Lx, s_top = wall_force[3] / Lx;
  EXPECT_NEAR(s_right / s_left, 1.0, 1e-4);
  EXPECT_NEAR(s_top / s_bottom, 1.0, 1e-4);
  EXPECT_NEAR(s_bottom / s_left, 1.0, 1e-4);
  EXPECT_NEAR(virial[0] / (Lx * Ly) / s_left, 1.0, 1e-4);
  EXPECT_NEAR(virial[1] / (Lx * Ly) / s_left, 1.0, 1e-4);
  EXPECT_LT(st.stress_anisotropy, 1e-4);

  // Packing fraction: walls lower phi by a boundary layer ~ perimeter/area,
  // measured phi ~ 0.84 - 0.43/sqrt(n) (n = 50: 0.769-0.794, n = 200:
  // 0.810-0.820, n = 1500: 0.830-0.834 over 12 seeds each).
  const double phi = packing_fraction(p);
  EXPECT_GT(phi, phi_lo);
  EXPECT_LT(phi, phi_hi);

  // Isostaticity at vanishing pressure (frictionless, walls, free box
  // lengths Lx and Ly): force-carrying contacts among non-rattlers =
  // 2 N_nr + 2. Measured exactly for every seed.
  const Coordination zf = coordination(p, touching);
  const int excess = zf.pair_contacts + zf.wall_contacts - (2 * zf.non_rattlers + 2);
  EXPECT_GE(excess, -1);
  EXPECT_LE(excess, 2);

  // Coordination with contact = gap < 1e-4 <d> (also picks up a few
  // near-contacts that carry no force). Rattlers: < 3 contacts, iterated.
  const Coordination z = coordination(p, contact_network(p, 1e-4 * dm));
  EXPECT_GT(z.rattler_fraction, 0.0 - 1e-12);
  EXPECT_LT(z.rattler_fraction, 0.15);  // measured 0.01-0.12
  // z_mirror counts a wall contact twice (isostatic 4 + 2/N_nr); z counts it
  // once, i.e. 4 + (2 - N_wall)/N_nr, below 4 by the wall contacts.
  EXPECT_GT(z.z_mirror, zm_lo);
  EXPECT_LT(z.z_mirror, zm_hi);
  EXPECT_NEAR(z.z, z.z_mirror - static_cast<double>(z.wall_contacts) / z.non_rattlers, 1e-12);
  std::printf("[packing] n=%d seed=%u phi=%.5f Z(nonrattler, wall once)=%.4f Z_mirror=%.4f rattlers=%.3f excess=%d\n", n,
              seed, phi, z.z, z.z_mirror, z.rattler_fraction, excess);
}

}  // namespace

TEST(JammedPacking, Small50) {
  for (unsigned seed : {1u, 2u, 3u, 4u}) check_jammed(50, seed, 0.74, 0.81, 3.95, 4.15);
}

TEST(JammedPacking, Medium200) {
  for (unsigned seed : {1u, 2u, 3u}) {
    check_jammed(200, seed, 0.79, 0.83, 3.97, 4.06);
    // The brief's band for the coordination of non-rattlers (wall contacts
    // counted once): measured 3.77-3.81 for n = 200.
    const DiskPacking &p = cached_packing(200, seed);
    const Coordination z = coordination(p, contact_network(p, 1e-4 * mean_diameter(p)));
    EXPECT_GT(z.z, 3.7);
    EXPECT_LT(z.z, 3.9);
  }
}

TEST(JammedPacking, Paper1500) {
  // Measured 3-9 s on one core (seeds 1-12).
  check_jammed(1500, 1u, 0.82, 0.84, 3.99, 4.03);
}

TEST(JammedPacking, SingleDiskFillsTheBox) {
  const DiskPacking p = make_jammed_packing(1, 3u, PackingOptions{});
  ASSERT_EQ(p.size(), 1);
  const double d = 2 * p.radius[0];
  // The box is d minus the two wall overlaps (each <= target_overlap <d>),
  // and strictly smaller than d (the disk is jammed, pressure > 0).
  EXPECT_LT(p.walls[1], d);
  EXPECT_GE(p.walls[1], d - 2e-6 * d);
  EXPECT_NEAR(packing_fraction(p), kPi / 4, 1e-5);
  EXPECT_NEAR(p.x[0], 0.5 * p.walls[1], 1e-6);
  EXPECT_NEAR(p.y[0], 0.5 * p.walls[3], 1e-6);
}

TEST(JammedPacking, Deterministic) {
  const DiskPacking a = make_jammed_packing(200, 2u, PackingOptions{});
  const DiskPacking b = make_jammed_packing(200, 2u, PackingOptions{});
  const DiskPacking c = make_jammed_packing(200, 3u, PackingOptions{});
  ASSERT_EQ(a.size(), b.size());
  const std::size_t bytes = a.x.size() * sizeof(double);
  EXPECT_EQ(0, std::memcmp(a.x.data(), b.x.data(), bytes));
  EXPECT_EQ(0, std::memcmp(a.y.data(), b.y.data(), bytes));
  EXPECT_EQ(0, std::memcmp(a.radius.data(), b.radius.data(), bytes));
  EXPECT_EQ(0, std::memcmp(a.walls, b.walls, sizeof a.walls));
  EXPECT_NE(0, std::memcmp(a.x.data(), c.x.data(), bytes));
  EXPECT_NE(a.walls[1], c.walls[1]);
}

TEST(JammedPacking, RejectsBadArguments) {
  EXPECT_THROW(make_jammed_packing(0, 1u, PackingOptions{}), std::invalid_argument);
  EXPECT_THROW(make_jammed_packing(-5, 1u, PackingOptions{}), std::invalid_argument);
  PackingOptions o;
  o.initial_fraction = 0.9;
  EXPECT_THROW(make_jammed_packing(10, 1u, o), std::invalid_argument);
}

// ---- contact diagnostics on hand-made configurations ------------------------

TEST(ContactNetwork, HandMadeTriangleInBox) {
  // Box [0, 3] x [0, 3]; disk 0 touches disk 1 (gap 0) and the left wall
  // (overlap 0.01); disk 2 is isolated (gap 0.5 to the bottom wall).
  DiskPacking p;
  p.x = {0.49, 1.49, 2.0};
  p.y = {1.0, 1.0, 2.0};
  p.radius = {0.5, 0.5, 0.5};
  p.deformable.assign(3, 0);
  p.walls[0] = 0;
  p.walls[1] = 3;
  p.walls[2] = 0;
  p.walls[3] = 3;
  EXPECT_NEAR(max_overlap(p), 0.01, 1e-12);
  const ContactNetwork net = contact_network(p, 1e-9);
  ASSERT_EQ(net.size(), 2);
  EXPECT_EQ(net.i[0], 0);
  EXPECT_EQ(net.j[0], 1);
  EXPECT_NEAR(net.gap[0], 0.0, 1e-12);
  EXPECT_EQ(net.i[1], 0);
  EXPECT_EQ(net.j[1], -1);  // left wall
  EXPECT_NEAR(net.gap[1], -0.01, 1e-12);
  // Top-wall contact of disk 2 once the tolerance reaches its gap 0.5.
  const ContactNetwork wide = contact_network(p, 0.6);
  bool top = false;
  for (int k = 0; k < wide.size(); ++k) top = top || (wide.i[k] == 2 && wide.j[k] == -4);
  EXPECT_TRUE(top);
  // All have < 3 contacts: everyone is a rattler.
  const Coordination z = coordination(p, net);
  EXPECT_EQ(z.non_rattlers, 0);
  EXPECT_EQ(z.rattler_fraction, 1.0);
  // With min_contacts = 1 disks 0 and 1 stay, and disk 2 goes.
  const Coordination z1 = coordination(p, net, 1);
  EXPECT_EQ(z1.non_rattlers, 2);
  EXPECT_EQ(z1.pair_contacts, 1);
  EXPECT_EQ(z1.wall_contacts, 1);
  EXPECT_DOUBLE_EQ(z1.z, 1.5);
  EXPECT_DOUBLE_EQ(z1.z_mirror, 2.0);
}

TEST(PackingFraction, OneDiskInUnitBox) {
  DiskPacking p;
  p.x = {0.5};
  p.y = {0.5};
  p.radius = {0.5};
  p.deformable = {0};
  p.walls[1] = 1;
  p.walls[3] = 2;
  EXPECT_DOUBLE_EQ(packing_fraction(p), kPi / 8);
}

// ---- deformable assignment --------------------------------------------------

TEST(AssignDeformable, AreaFractionMatchesKappa) {
  for (int n : {400, 1500}) {
    DiskPacking p = cached_packing(n, 1u);
    double total = 0, amax = 0;
    for (int i = 0; i < n; ++i) {
      total += disk_area(p, i);
      amax = std::max(amax, disk_area(p, i));
    }
    for (double kappa : {0.0, 0.2, 0.5, 0.8, 1.0}) {
      SCOPED_TRACE("n=" + std::to_string(n) + " kappa=" + std::to_string(kappa));
      assign_deformable(p, kappa, 11u);
      double def = 0;
      int count = 0;
      for (int i = 0; i < n; ++i)
        if (p.deformable[i]) {
          def += disk_area(p, i);
          ++count;
        }
      // Error diffusion keeps the deformable area within a_max/2 of the target.
      EXPECT_LE(std::fabs(def - kappa * total), 0.5 * amax + 1e-9);
      if (kappa == 0.0) {
        EXPECT_EQ(count, 0);
      }
      if (kappa == 1.0) {
        EXPECT_EQ(count, n);
      }
    }
  }
}

TEST(AssignDeformable, HomogeneousInSpace) {
  for (int n : {400, 1500}) {
    DiskPacking p = cached_packing(n, 1u);
    const double xm = 0.5 * (p.walls[0] + p.walls[1]), ym = 0.5 * (p.walls[2] + p.walls[3]);
    for (double kappa : {0.2, 0.5, 0.8}) {
      for (unsigned seed : {1u, 2u, 3u}) {
        assign_deformable(p, kappa, seed);
        // Quadrants by disk centre; each is a contiguous quarter of the
        // Hilbert walk, so its error is ~ a_max / quadrant area
        // (~0.004 at n = 1500, ~0.015 at n = 400).
        double def[4] = {0, 0, 0, 0}, all[4] = {0, 0, 0, 0};
        for (int i = 0; i < n; ++i) {
          const int q = (p.x[i] >= xm ? 1 : 0) + (p.y[i] >= ym ? 2 : 0);
          all[q] += disk_area(p, i);
          if (p.deformable[i]) def[q] += disk_area(p, i);
        }
        const double tol = (n >= 1500) ? 0.01 : 0.025;
        for (int q = 0; q < 4; ++q)
          EXPECT_NEAR(def[q] / all[q], kappa, tol) << "n=" << n << " kappa=" << kappa << " seed=" << seed << " quadrant " << q;
        // Finer: 4 x 4 blocks at n = 1500 (~94 disks each).
        if (n >= 1500) {
          double bdef[16] = {0}, ball[16] = {0};
          const double Lx = p.walls[1] - p.walls[0], Ly = p.walls[3] - p.walls[2];
          for (int i = 0; i < n; ++i) {
            const int bx = std::min(3, static_cast<int>((p.x[i] - p.walls[0]) / Lx * 4));
            const int by = std::min(3, static_cast<int>((p.y[i] - p.walls[2]) / Ly * 4));
            ball[4 * by + bx] += disk_area(p, i);
            if (p.deformable[i]) bdef[4 * by + bx] += disk_area(p, i);
          }
          for (int b = 0; b < 16; ++b) EXPECT_NEAR(bdef[b] / ball[b], kappa, 0.03) << "block " << b;
        }
      }
    }
  }
}

TEST(AssignDeformable, SeedAndReassignment) {
  DiskPacking p = cached_packing(400, 1u);
  assign_deformable(p, 0.5, 1u);
  const std::vector<char> a = p.deformable;
  assign_deformable(p, 0.5, 1u);
  EXPECT_EQ(a, p.deformable);
  assign_deformable(p, 0.5, 2u);
  EXPECT_NE(a, p.deformable);
  assign_deformable(p, 0.0, 2u);  // replaces the previous marking
  for (char c : p.deformable) EXPECT_EQ(c, 0);
}

TEST(AssignDeformable, RejectsKappaOutsideUnitInterval) {
  DiskPacking p = cached_packing(50, 1u);
  for (double kappa : {-0.1, 1.0 + 1e-12, 2.0, std::numeric_limits<double>::quiet_NaN()}) {
    try {
      assign_deformable(p, kappa, 1u);
      ADD_FAILURE() << "no exception for kappa = " << kappa;
    } catch (const std::invalid_argument &e) {
      EXPECT_NE(std::string(e.what()).find("kappa"), std::string::npos);
    }
  }
}

// ---- report only (not run by default) ----------------------------------------
// ./test_packing --gtest_also_run_disabled_tests --gtest_filter='*Report*'
// Prints time, phi, Z for n = 100, 400, 1500 and seeds 1..5. With
// DEFORMIX_PACKING_DUMP=dir it also writes dir/packing_<n>_<seed>.txt
// (walls, then "x y r" per disk) for scripts/plot_packing.py.
TEST(JammedPacking, DISABLED_Report) {
  const char *dump = std::getenv("DEFORMIX_PACKING_DUMP");
  for (int n : {100, 400, 1500})
    for (unsigned seed = 1; seed <= 5; ++seed) {
      JammingStats st;
      const auto t0 = std::chrono::steady_clock::now();
      const DiskPacking p = make_jammed_packing(n, seed, PackingOptions{}, &st);
      const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      const double dm = st.mean_diameter;
      const Coordination z = coordination(p, contact_network(p, 1e-4 * dm));
      const Coordination zf = coordination(p, contact_network(p, 0.0));
      // phi in the central window [L/4, 3L/4]^2 by grid sampling
      const double L = p.walls[1], w0 = 0.25 * L, w1 = 0.75 * L;
      const int G = 400;
      long in = 0;
      for (int a = 0; a < G; ++a)
        for (int b = 0; b < G; ++b) {
          const double px = w0 + (a + 0.5) * (w1 - w0) / G, py = w0 + (b + 0.5) * (w1 - w0) / G;
          for (int i = 0; i < n; ++i) {
            const double dx = p.x[i] - px, dy = p.y[i] - py;
            if (dx * dx + dy * dy < p.radius[i] * p.radius[i]) {
              ++in;
              break;
            }
          }
        }
      std::printf("n=%4d seed=%u time=%6.2fs FIRE=%7lld phi=%.5f phi_centre=%.4f maxov=%.1e resF=%.1e "
                  "Z=%.4f Z_mirror=%.4f rattlers=%.3f | force-carrying: Z=%.4f excess=%d\n",
                  n, seed, t, st.fire_iterations, packing_fraction(p), static_cast<double>(in) / G / G, st.max_overlap,
                  st.residual_force, z.z, z.z_mirror, z.rattler_fraction, zf.z,
                  zf.pair_contacts + zf.wall_contacts - 2 * zf.non_rattlers - 1);
      if (dump) {
        const std::string path = std::string(dump) + "/packing_" + std::to_string(n) + "_" + std::to_string(seed) + ".txt";
        if (FILE *f = std::fopen(path.c_str(), "w")) {
          std::fprintf(f, "%.17g %.17g %.17g %.17g\n", p.walls[0], p.walls[1], p.walls[2], p.walls[3]);
          for (int i = 0; i < n; ++i)
            std::fprintf(f, "%.17g %.17g %.17g %d\n", p.x[i], p.y[i], p.radius[i], z.rattler[i] ? 1 : 0);
          std::fclose(f);
        }
      }
    }
}

int main(int argc, char **argv) {
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}

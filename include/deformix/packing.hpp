// Packing generation: the paper's protocol for the initial state.
//
// 1. N_p diameters in [0.8, 1.2] <d> (<d> = 1) with a uniform distribution
//    of particle area over the diameter range: the number density is
//    proportional to d^-2, sampled by inverting its CDF,
//      d(u) = 1 / (1/d_min - u (1/d_min - 1/d_max)),  u ~ U(0, 1).
// 2. A dense random packing of rigid frictionless disks in a box of four
//    walls: random non-overlapping placement in a loose square box, then
//    isotropic compression of soft (harmonic-overlap) disks under a
//    pressure p applied to the four walls (enthalpy minimization by FIRE
//    over the centres and the box lengths), p lowered until the assembly is
//    jammed at vanishing overlap. The result is the jammed state phi_0
//    (about 0.84 in 2D, slightly less with walls) under an isotropic stress,
//    which the exact-contact solver then takes over: under its four
//    pressure-driven walls it is an equilibrium with the same contacts.
//    (A fixed square box would jam with an anisotropic stress, 10-20 %
//    between sigma_xx and sigma_yy at 400 disks; the rigid packing then has
//    to shear, by slow plastic rearrangement, before it carries an
//    isotropic pressure.)
// 3. A fraction kappa of the total particle area is turned deformable,
//    homogeneously in space.
// Everything is deterministic for a given seed.
#pragma once
#include <string>
#include <vector>

namespace deformix {

struct DiskPacking {
  std::vector<double> x, y;        // centres
  std::vector<double> radius;
  std::vector<char> deformable;    // 1: deformable disk, 0: rigid (all 0 after make_jammed_packing)
  double walls[4] = {0, 0, 0, 0};  // x_left, x_right, y_bottom, y_top
  int size() const { return static_cast<int>(x.size()); }
};

struct PackingOptions {
  double d_min = 0.8, d_max = 1.2;
  double target_overlap = 1e-6;    // lower the pressure until the largest overlap / <d> is below this
  double initial_fraction = 0.3;   // packing fraction of the loose initial state (0 < f <= 0.5)
  int max_iterations = 2000000;    // FIRE iterations cap, per enthalpy minimization (one pressure)
};

// Diagnostics of one make_jammed_packing run.
struct JammingStats {
  int minimizations = 0;           // FIRE minimizations (box sizes tried)
  long long fire_iterations = 0;   // total FIRE steps
  int capped_minimizations = 0;    // minimizations that hit opts.max_iterations
  double energy = 0;               // final soft energy, sum over overlaps of 0.5 delta^2 (delta in units of <d>)
  double max_overlap = 0;          // final largest overlap / <d> (pairs and walls)
  double residual_force = 0;       // final largest net force on a disk / mean contact force
  double pressure = 0;             // final pressure p (units: overlap stiffness 1, forces = overlap lengths)
  double stress_anisotropy = 0;    // final |sigma_xx - sigma_yy| / p
  double mean_diameter = 1;        // <d> of the sample
};

std::vector<double> sample_diameters(int n, unsigned seed, double d_min, double d_max);

// Jammed frictionless packing of n disks; throws std::invalid_argument for n < 1
// or inconsistent options. Protocol (O'Hern et al. 2003, pressure-controlled
// with walls): random sequential placement at opts.initial_fraction in a
// square box, then FIRE minimizations of the enthalpy H = U + p Lx Ly,
// U = sum 1/2 delta^2 over the overlaps (pairs and the four walls), over the
// centres and the box lengths Lx, Ly: first at p = 1e-2, then at pressures
// lowered by up to a decade each until the largest overlap is <=
// opts.target_overlap <d>. The result is force-balanced with an isotropic
// stress p. Walls returned: {0, Lx, 0, Ly}; disks may overlap each other or
// the walls by at most the target. Cost ~ linear in n (Verlet list built on
// a cell grid). Deterministic: identical bytes for a given (n, seed, opts) on
// IEEE-754 doubles.
DiskPacking make_jammed_packing(int n, unsigned seed, const PackingOptions &opts);
DiskPacking make_jammed_packing(int n, unsigned seed, const PackingOptions &opts, JammingStats *stats);

// Marks deformable disks until their area is as close as possible to kappa
// times the total particle area, spread homogeneously over the box;
// throws std::invalid_argument for kappa outside [0, 1] (or NaN).
// Method: disks are walked along a Hilbert curve of their centres (2^16 x 2^16
// grid on the box; the seed picks a random starting point on the closed walk
// and breaks ties), with error diffusion on the area: a disk is marked when
// the accumulated target area kappa*sum(a) minus the marked area exceeds half
// its area. The deformable area is within a_max/2 of kappa * total area
// (exactly 0 at kappa = 0, everything at kappa = 1), and every contiguous
// stretch of the curve (e.g. each quadrant of the box) is within ~a_max of
// its own target. Replaces any previous marking.
void assign_deformable(DiskPacking &packing, double kappa, unsigned seed);

// A packing from a CSV file with the columns of compact's packing.csv: a
// header naming x, y, radius and deformable (0 or 1) in any order, then one
// row per disk. The walls are the disks' bounding box. Throws
// std::runtime_error, saying what is wrong and where, for an unreadable or
// empty file, a missing, repeated or unknown column, a row with the wrong
// number of fields, a value that is not a finite number, a radius <= 0, a
// deformable flag other than 0 or 1, and two disks overlapping by more than
// overlap_tol times their mean diameter.
DiskPacking read_packing_csv(const std::string &path, double overlap_tol = 1e-6);

// Packing fraction of rigid disks: sum of disk areas / box area.
double packing_fraction(const DiskPacking &packing);

// ---- contact-network diagnostics --------------------------------------------
// Pairs (and disk-wall pairs) with gap < gap_tol (absolute length).
// j >= 0: disk j (i < j); j = -1, -2, -3, -4: wall left, right, bottom, top.
struct ContactNetwork {
  std::vector<int> i, j;
  std::vector<double> gap;         // negative: overlap
  int size() const { return static_cast<int>(i.size()); }
};
ContactNetwork contact_network(const DiskPacking &packing, double gap_tol);

// Largest overlap (>= 0, absolute length) over all disk pairs and disk-wall pairs.
double max_overlap(const DiskPacking &packing);

// Rattler analysis of a contact network: disks with fewer than min_contacts
// contacts (wall contacts count) are removed iteratively.
struct Coordination {
  std::vector<char> rattler;       // 1: rattler
  int non_rattlers = 0;
  int pair_contacts = 0;           // contacts between two non-rattlers
  int wall_contacts = 0;           // non-rattler-wall contacts
  // Mean contacts per non-rattler disk, wall contacts counted once:
  // (2 pair + wall) / non_rattlers. Isostatic with walls and a free box size:
  // pair + wall = 2 non_rattlers + 1, i.e. z = 4 + (2 - wall) / non_rattlers.
  double z = 0;
  // Same with each wall contact counted twice (as against a mirror image):
  // 2 (pair + wall) / non_rattlers, isostatic value 4 + 2 / non_rattlers.
  double z_mirror = 0;
  double rattler_fraction = 0;     // rattlers / all disks
};
Coordination coordination(const DiskPacking &packing, const ContactNetwork &contacts,
                          int min_contacts = 3);

}  // namespace deformix

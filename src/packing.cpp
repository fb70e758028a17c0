// Packing generation: diameters, jammed frictionless packing (O'Hern-style
// FIRE on the enthalpy with a free rectangular box and walls), deformable assignment along a Hilbert
// curve. Plain C++17, no PETSc. Reproducible: random numbers come from the raw
// std::mt19937_64 output (fully specified by the standard), never from the
// implementation-defined std::*_distribution classes.
#include "deformix/packing.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <limits>
#include <numeric>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>

namespace deformix {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Uniform double in [0, 1) from the top 53 bits of one engine draw.
double uniform01(std::mt19937_64 &eng) {
  return static_cast<double>(eng() >> 11) * (1.0 / 9007199254740992.0);
}

// Uniform integer in [0, m) by rejection (unbiased, platform independent).
std::uint64_t uniform_index(std::mt19937_64 &eng, std::uint64_t m) {
  const std::uint64_t limit = std::numeric_limits<std::uint64_t>::max() -
                              std::numeric_limits<std::uint64_t>::max() % m;
  std::uint64_t v;
  do { v = eng(); } while (v >= limit);
  return v % m;
}

// Independent stream for a given purpose derived from the user seed.
std::mt19937_64 make_engine(unsigned seed, std::uint64_t stream) {
  return std::mt19937_64(static_cast<std::uint64_t>(seed) ^ (0x9E3779B97F4A7C15ull * (stream + 1)));
}

// ---- cell grid over [x0, x0 + nx h] x [y0, y0 + ny h] ------------------------
// Points outside are clamped to the border cells. Disks are stored in cell
// order (counting sort): start[c] .. start[c + 1] in `items`.
struct CellGrid {
  double x0 = 0, y0 = 0, h = 1;
  int nx = 1, ny = 1;
  std::vector<int> start, items;

  int cx(double x) const { return std::min(nx - 1, std::max(0, static_cast<int>(std::floor((x - x0) / h)))); }
  int cy(double y) const { return std::min(ny - 1, std::max(0, static_cast<int>(std::floor((y - y0) / h)))); }

  void setup(double xlo, double xhi, double ylo, double yhi, double min_h) {
    x0 = xlo;
    y0 = ylo;
    const double wx = std::max(xhi - xlo, min_h), wy = std::max(yhi - ylo, min_h);
    nx = std::max(1, static_cast<int>(wx / min_h));
    ny = std::max(1, static_cast<int>(wy / min_h));
    // keep the grid size bounded (huge boxes with few disks)
    while (static_cast<long long>(nx) * ny > 4000000LL) { nx = std::max(1, nx / 2); ny = std::max(1, ny / 2); }
    h = std::max(wx / nx, wy / ny);
  }

  void fill(const std::vector<double> &x, const std::vector<double> &y) {
    const int n = static_cast<int>(x.size());
    std::vector<int> cell(n);
    start.assign(static_cast<std::size_t>(nx) * ny + 1, 0);
    for (int i = 0; i < n; ++i) {
      cell[i] = cy(y[i]) * nx + cx(x[i]);
      ++start[cell[i] + 1];
    }
    for (std::size_t c = 1; c < start.size(); ++c) start[c] += start[c - 1];
    items.assign(n, 0);
    std::vector<int> pos(start.begin(), start.end() - 1);
    for (int i = 0; i < n; ++i) items[pos[cell[i]]++] = i;
  }
};

// All pairs i < j with centre distance < r_i + r_j + extra (cell size must be
// >= 2 r_max + extra). Deterministic order.
void build_pairs(const std::vector<double> &x, const std::vector<double> &y, const std::vector<double> &r,
                 double xlo, double xhi, double ylo, double yhi, double extra,
                 std::vector<std::pair<int, int>> &pairs) {
  pairs.clear();
  const int n = static_cast<int>(x.size());
  if (n < 2) return;
  const double rmax = *std::max_element(r.begin(), r.end());
  CellGrid g;
  g.setup(xlo, xhi, ylo, yhi, 2 * rmax + extra);
  g.fill(x, y);
  static const int off[5][2] = {{0, 0}, {1, 0}, {-1, 1}, {0, 1}, {1, 1}};  // half stencil
  for (int cy = 0; cy < g.ny; ++cy)
    for (int cx = 0; cx < g.nx; ++cx) {
      const int c = cy * g.nx + cx;
      for (int k = 0; k < 5; ++k) {
        const int ox = cx + off[k][0], oy = cy + off[k][1];
        if (ox < 0 || ox >= g.nx || oy >= g.ny) continue;
        const int o = oy * g.nx + ox;
        for (int a = g.start[c]; a < g.start[c + 1]; ++a) {
          const int i = g.items[a];
          const int b0 = (k == 0) ? a + 1 : g.start[o];
          for (int b = b0; b < g.start[o + 1]; ++b) {
            const int j = g.items[b];
            const double dx = x[j] - x[i], dy = y[j] - y[i], s = r[i] + r[j] + extra;
            if (dx * dx + dy * dy < s * s) pairs.emplace_back(std::min(i, j), std::max(i, j));
          }
        }
      }
    }
}

// ---- soft-disk system in the box [0, Lx] x [0, Ly] -----------------------------
struct SoftSystem {
  std::vector<double> x, y, r, fx, fy, vx, vy, xref, yref;
  std::vector<std::pair<int, int>> pairs;
  double Lx = 1, Ly = 1;
  double skin = 0.2;
  // results of the last force evaluation
  double energy = 0, max_ov = 0, sum_ov = 0, fmax2 = 0;
  double wxx = 0, wyy = 0;  // virial: -dU/d(ln Lx), -dU/d(ln Ly) under affine box strain
  int n_ov = 0;

  int n() const { return static_cast<int>(x.size()); }

  void rebuild() {
    build_pairs(x, y, r, 0.0, Lx, 0.0, Ly, skin, pairs);
    xref = x;
    yref = y;
  }

  void maybe_rebuild() {
    const double lim2 = 0.25 * skin * skin;
    for (int i = 0; i < n(); ++i) {
      const double dx = x[i] - xref[i], dy = y[i] - yref[i];
      if (dx * dx + dy * dy > lim2) { rebuild(); return; }
    }
  }

  void forces() {
    const int nn = n();
    std::fill(fx.begin(), fx.end(), 0.0);
    std::fill(fy.begin(), fy.end(), 0.0);
    energy = 0;
    max_ov = 0;
    sum_ov = 0;
    wxx = wyy = 0;
    n_ov = 0;
    for (const auto &p : pairs) {
      const int i = p.first, j = p.second;
      const double dx = x[j] - x[i], dy = y[j] - y[i], s = r[i] + r[j];
      const double d2 = dx * dx + dy * dy;
      if (d2 >= s * s) continue;
      const double d = std::sqrt(d2);
      const double ov = s - d;
      energy += 0.5 * ov * ov;
      sum_ov += ov;
      ++n_ov;
      max_ov = std::max(max_ov, ov);
      if (d > 0) {
        const double f = ov / d;
        fx[i] -= f * dx;
        fy[i] -= f * dy;
        fx[j] += f * dx;
        fy[j] += f * dy;
        wxx += f * dx * dx;
        wyy += f * dy * dy;
      } else {  // coincident centres: push apart along x (deterministic)
        fx[i] -= ov;
        fx[j] += ov;
      }
    }
    for (int i = 0; i < nn; ++i) {
      const double ri = r[i];
      const double ovs[4] = {ri - x[i], x[i] + ri - Lx, ri - y[i], y[i] + ri - Ly};
      for (int w = 0; w < 4; ++w) {
        const double ov = ovs[w];
        if (ov <= 0) continue;
        energy += 0.5 * ov * ov;
        sum_ov += ov;
        ++n_ov;
        max_ov = std::max(max_ov, ov);
        // Branch vectors from the wall to the centre: x, Lx - x, y, Ly - y.
        switch (w) {
          case 0: fx[i] += ov; wxx += ov * x[i]; break;
          case 1: fx[i] -= ov; wxx += ov * (Lx - x[i]); break;
          case 2: fy[i] += ov; wyy += ov * y[i]; break;
          default: fy[i] -= ov; wyy += ov * (Ly - y[i]); break;
        }
      }
    }
    fmax2 = 0;
    for (int i = 0; i < nn; ++i) fmax2 = std::max(fmax2, fx[i] * fx[i] + fy[i] * fy[i]);
  }

  // Affine box strain: Lx -> Lx e^ex, Ly -> Ly e^ey, centres with it.
  void strain_box(double ex, double ey) {
    const double sx = std::exp(ex), sy = std::exp(ey);
    for (int i = 0; i < n(); ++i) {
      x[i] *= sx;
      y[i] *= sy;
    }
    Lx *= sx;
    Ly *= sy;
  }
};

// FIRE (Bitzek et al. 2006, with the FIRE 2.0 half-step correction of Guenole
// et al. 2020), unit masses, semi-implicit Euler, on the enthalpy
//   H = U + p Lx Ly,   U = sum over overlaps of delta^2 / 2,
// over the centres and the two box strains (ln Lx, ln Ly; as lengths
// q = L0 ln L with unit mass, so that their stiffness is that of a disk).
// The generalized box forces are (A sigma_xx - p A) / L0 with the virial
// stress A sigma = wxx: at the minimum the packing is force-balanced and its
// stress is isotropic, sigma_xx = sigma_yy = p, as under the four
// pressure-driven walls of the contact solver. Converged when the largest
// net force on a disk < force_rel * mean overlap (the mean contact force)
// and |sigma - p| < force_rel p in both directions.
bool fire_enthalpy(SoftSystem &s, double p, double force_rel, int max_it, double max_box_move, long long &iters) {
  const double dt0 = 0.1, dt_max = 0.5, dt_min = 1e-3;
  const double f_inc = 1.1, f_dec = 0.5, alpha0 = 0.1, f_alpha = 0.99;
  const int n_delay = 5;
  const int nn = s.n();
  const double L0 = std::sqrt(s.Lx * s.Ly);
  std::fill(s.vx.begin(), s.vx.end(), 0.0);
  std::fill(s.vy.begin(), s.vy.end(), 0.0);
  double vq[2] = {0, 0}, gq[2];
  double dt = dt0, alpha = alpha0;
  int n_pos = 0;
  s.forces();
  for (int it = 0;; ++it) {
    const double A = s.Lx * s.Ly;
    gq[0] = (s.wxx - p * A) / L0;
    gq[1] = (s.wyy - p * A) / L0;
    const double fmean = s.n_ov > 0 ? s.sum_ov / s.n_ov : 0.0;
    if (s.n_ov > 0 && s.fmax2 <= force_rel * force_rel * fmean * fmean &&
        std::abs(s.wxx - p * A) <= force_rel * p * A && std::abs(s.wyy - p * A) <= force_rel * p * A)
      return true;
    if (it >= max_it) return false;
    ++iters;
    double P = gq[0] * vq[0] + gq[1] * vq[1], ff = gq[0] * gq[0] + gq[1] * gq[1];
    for (int i = 0; i < nn; ++i) {
      P += s.fx[i] * s.vx[i] + s.fy[i] * s.vy[i];
      ff += s.fx[i] * s.fx[i] + s.fy[i] * s.fy[i];
    }
    if (P > 0) {
      if (++n_pos > n_delay) {
        dt = std::min(dt * f_inc, dt_max);
        alpha *= f_alpha;
      }
    } else {
      n_pos = 0;
      if (dt * f_dec >= dt_min) dt *= f_dec;
      alpha = alpha0;
      for (int i = 0; i < nn; ++i) {
        s.x[i] -= 0.5 * dt * s.vx[i];
        s.y[i] -= 0.5 * dt * s.vy[i];
        s.vx[i] = 0;
        s.vy[i] = 0;
      }
      s.strain_box(-0.5 * dt * vq[0] / L0, -0.5 * dt * vq[1] / L0);
      vq[0] = vq[1] = 0;
    }
    // MD step, then FIRE mixing with the updated velocity.
    double vv = 0;
    for (int i = 0; i < nn; ++i) {
      s.vx[i] += dt * s.fx[i];
      s.vy[i] += dt * s.fy[i];
      vv += s.vx[i] * s.vx[i] + s.vy[i] * s.vy[i];
    }
    for (int k = 0; k < 2; ++k) {
      vq[k] += dt * gq[k];
      vv += vq[k] * vq[k];
    }
    const double mix = (ff > 0) ? alpha * std::sqrt(vv / ff) : 0.0;
    for (int i = 0; i < nn; ++i) {
      s.vx[i] = (1 - alpha) * s.vx[i] + mix * s.fx[i];
      s.vy[i] = (1 - alpha) * s.vy[i] + mix * s.fy[i];
      s.x[i] += dt * s.vx[i];
      s.y[i] += dt * s.vy[i];
    }
    for (int k = 0; k < 2; ++k) {
      vq[k] = (1 - alpha) * vq[k] + mix * gq[k];
      // The box moves by at most max_box_move per step (a fast collapse of a
      // loose box would otherwise push disks through each other).
      vq[k] = std::max(-max_box_move / dt, std::min(max_box_move / dt, vq[k]));
    }
    s.strain_box(dt * vq[0] / L0, dt * vq[1] / L0);
    s.maybe_rebuild();
    s.forces();
  }
}

// Random sequential placement of non-overlapping disks (gap >= 0) inside [0, L]^2.
void random_placement(SoftSystem &s, std::mt19937_64 &eng) {
  const int n = s.n();
  const double rmax = *std::max_element(s.r.begin(), s.r.end());
  const double h = 2 * rmax;
  const int nc = std::max(1, static_cast<int>(s.Lx / h));
  const double hc = s.Lx / nc;
  std::vector<std::vector<int>> cells(static_cast<std::size_t>(nc) * nc);
  auto cell_of = [&](double v) { return std::min(nc - 1, std::max(0, static_cast<int>(v / hc))); };
  const long long max_tries = 100000000LL;
  long long tries = 0;
  for (int i = 0; i < n; ++i) {
    const double ri = s.r[i];
    if (2 * ri > s.Lx) throw std::runtime_error("make_jammed_packing: box smaller than a disk");
    for (;;) {
      if (++tries > max_tries)
        throw std::runtime_error("make_jammed_packing: random placement failed; lower opts.initial_fraction");
      const double xi = ri + uniform01(eng) * (s.Lx - 2 * ri);
      const double yi = ri + uniform01(eng) * (s.Lx - 2 * ri);
      const int cx = cell_of(xi), cy = cell_of(yi);
      const int reach = static_cast<int>(std::ceil((ri + rmax) / hc));
      bool ok = true;
      for (int oy = std::max(0, cy - reach); ok && oy <= std::min(nc - 1, cy + reach); ++oy)
        for (int ox = std::max(0, cx - reach); ok && ox <= std::min(nc - 1, cx + reach); ++ox)
          for (int j : cells[static_cast<std::size_t>(oy) * nc + ox]) {
            const double dx = s.x[j] - xi, dy = s.y[j] - yi, d = ri + s.r[j];
            if (dx * dx + dy * dy < d * d) { ok = false; break; }
          }
      if (!ok) continue;
      s.x[i] = xi;
      s.y[i] = yi;
      cells[static_cast<std::size_t>(cy) * nc + cx].push_back(i);
      break;
    }
  }
}

// Hilbert index of (x, y) in [0, 2^order)^2 (Wikipedia's xy2d). Each
// quadrant of the square is a contiguous quarter of the index range.
std::uint64_t hilbert_index(std::uint32_t x, std::uint32_t y, int order) {
  const std::uint32_t n = 1u << order;
  std::uint64_t d = 0;
  for (std::uint32_t s = n / 2; s > 0; s /= 2) {
    const std::uint32_t rx = (x & s) ? 1u : 0u, ry = (y & s) ? 1u : 0u;
    d += static_cast<std::uint64_t>(s) * s * ((3u * rx) ^ ry);
    if (ry == 0) {
      if (rx == 1) {
        x = n - 1 - x;
        y = n - 1 - y;
      }
      std::swap(x, y);
    }
  }
  return d;
}

}  // namespace

std::vector<double> sample_diameters(int n, unsigned seed, double d_min, double d_max) {
  if (n < 0) throw std::invalid_argument("sample_diameters: n must be >= 0");
  if (!(d_min > 0) || !(d_max >= d_min) || !std::isfinite(d_max))
    throw std::invalid_argument("sample_diameters: need 0 < d_min <= d_max < inf");
  std::mt19937_64 eng = make_engine(seed, 0);
  const double a = 1.0 / d_min, b = 1.0 / d_min - 1.0 / d_max;
  std::vector<double> d(n);
  for (int i = 0; i < n; ++i) {
    const double u = uniform01(eng);
    d[i] = std::min(d_max, std::max(d_min, 1.0 / (a - u * b)));
  }
  return d;
}

DiskPacking make_jammed_packing(int n, unsigned seed, const PackingOptions &opts) {
  return make_jammed_packing(n, seed, opts, nullptr);
}

DiskPacking make_jammed_packing(int n, unsigned seed, const PackingOptions &opts, JammingStats *stats) {
  if (n < 1) throw std::invalid_argument("make_jammed_packing: n must be >= 1");
  if (!(opts.initial_fraction > 0 && opts.initial_fraction <= 0.5))
    throw std::invalid_argument("make_jammed_packing: opts.initial_fraction must be in (0, 0.5]");
  if (!(opts.target_overlap > 0 && opts.target_overlap < 0.1))
    throw std::invalid_argument("make_jammed_packing: opts.target_overlap must be in (0, 0.1)");
  if (opts.max_iterations < 1) throw std::invalid_argument("make_jammed_packing: opts.max_iterations must be >= 1");

  const std::vector<double> d = sample_diameters(n, seed, opts.d_min, opts.d_max);
  double dmean = 0, area = 0;
  for (double di : d) {
    dmean += di;
    area += 0.25 * kPi * di * di;
  }
  dmean /= n;

  SoftSystem s;
  s.r.resize(n);
  for (int i = 0; i < n; ++i) s.r[i] = 0.5 * d[i];
  s.x.assign(n, 0);
  s.y.assign(n, 0);
  s.fx.assign(n, 0);
  s.fy.assign(n, 0);
  s.vx.assign(n, 0);
  s.vy.assign(n, 0);
  s.skin = 0.3 * dmean;
  s.Lx = s.Ly = std::sqrt(area / opts.initial_fraction);
  std::mt19937_64 eng = make_engine(seed, 1);
  random_placement(s, eng);
  s.rebuild();

  // Pressure-controlled jamming: minimize the enthalpy at p = 1e-2 (overlaps
  // of about 1 % <d>: the quench from the loose state), then lower p by
  // decades (at most) until the largest overlap is below the target; the
  // last state is balanced to force_final. The contact solver then finds
  // the same network in exact contact, with the same forces to O(overlap),
  // in equilibrium under four walls at the same isotropic pressure.
  const double tol = opts.target_overlap * dmean;
  const double force_rel = 1e-4;    // balance (net force / mean contact force, stress / p) of the stages
  const double force_final = 1e-6;  // ... and of the accepted state
  const double max_box_move = 0.05 * dmean;
  double pressure = 1e-2;
  JammingStats st;
  st.mean_diameter = dmean;
  for (;;) {
    ++st.minimizations;
    if (!fire_enthalpy(s, pressure, force_rel, opts.max_iterations, max_box_move, st.fire_iterations))
      ++st.capped_minimizations;
    if (s.max_ov <= tol) {
      ++st.minimizations;
      if (!fire_enthalpy(s, pressure, force_final, opts.max_iterations, max_box_move, st.fire_iterations))
        ++st.capped_minimizations;
      if (s.max_ov <= tol) break;
    }
    pressure *= std::max(0.1, std::min(0.5, 0.8 * tol / s.max_ov));
    if (pressure < 1e-14 * dmean) {
      std::ostringstream msg;
      msg << "make_jammed_packing: the largest overlap stays above " << opts.target_overlap
          << " <d> down to pressure " << pressure << "; raise opts.max_iterations";
      throw std::runtime_error(msg.str());
    }
  }
  st.pressure = pressure;

  st.energy = s.energy / (dmean * dmean);
  st.max_overlap = s.max_ov / dmean;
  st.residual_force = std::sqrt(s.fmax2) / (s.sum_ov / s.n_ov);
  st.stress_anisotropy = std::abs(s.wxx - s.wyy) / (st.pressure * s.Lx * s.Ly);
  if (stats) *stats = st;

  DiskPacking p;
  p.x = s.x;
  p.y = s.y;
  p.radius = s.r;
  p.deformable.assign(n, 0);
  p.walls[0] = 0;
  p.walls[1] = s.Lx;
  p.walls[2] = 0;
  p.walls[3] = s.Ly;
  return p;
}

DiskPacking read_packing_csv(const std::string &path, double overlap_tol) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot read the packing file '" + path + "'");
  const auto split = [](const std::string &line) {
    std::vector<std::string> out;
    std::string field;
    std::istringstream ss(line);
    while (std::getline(ss, field, ',')) {
      const size_t a = field.find_first_not_of(" \t\r"), b = field.find_last_not_of(" \t\r");
      out.push_back(a == std::string::npos ? "" : field.substr(a, b - a + 1));
    }
    if (!line.empty() && line.back() == ',') out.push_back("");
    return out;
  };
  std::string line;
  if (!std::getline(in, line) || line.find_first_not_of(" \t\r") == std::string::npos)
    throw std::runtime_error("packing file '" + path + "' is empty: expected a header x,y,radius,deformable and one row per disk");
  const std::vector<std::string> header = split(line);
  const char *const names[4] = {"x", "y", "radius", "deformable"};
  int column[4] = {-1, -1, -1, -1};
  for (size_t c = 0; c < header.size(); ++c) {
    int k = 0;
    while (k < 4 && header[c] != names[k]) ++k;
    if (k == 4)
      throw std::runtime_error("packing file '" + path + "': unknown column '" + header[c] +
                               "' (the columns are x, y, radius, deformable)");
    if (column[k] >= 0) throw std::runtime_error("packing file '" + path + "': column '" + header[c] + "' appears twice");
    column[k] = static_cast<int>(c);
  }
  for (int k = 0; k < 4; ++k)
    if (column[k] < 0)
      throw std::runtime_error("packing file '" + path + "': no column '" + names[k] +
                               "' (the columns are x, y, radius, deformable)");
  DiskPacking p;
  int row = 1;
  while (std::getline(in, line)) {
    ++row;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    const std::vector<std::string> f = split(line);
    std::ostringstream where;
    where << "packing file '" << path << "', line " << row;
    if (f.size() != header.size())
      throw std::runtime_error(where.str() + ": " + std::to_string(f.size()) + " fields for " +
                               std::to_string(header.size()) + " columns");
    double v[4];
    for (int k = 0; k < 4; ++k) {
      const std::string &t = f[column[k]];
      size_t used = 0;
      try {
        v[k] = std::stod(t, &used);
      } catch (const std::exception &) {
        used = 0;
      }
      if (t.empty() || used != t.size() || !std::isfinite(v[k]))
        throw std::runtime_error(where.str() + ": " + names[k] + " '" + t + "' is not a finite number");
    }
    if (!(v[2] > 0.0)) throw std::runtime_error(where.str() + ": radius " + f[column[2]] + " must be positive");
    if (v[3] != 0.0 && v[3] != 1.0)
      throw std::runtime_error(where.str() + ": deformable " + f[column[3]] + " must be 0 (rigid) or 1 (deformable)");
    p.x.push_back(v[0]), p.y.push_back(v[1]), p.radius.push_back(v[2]), p.deformable.push_back(v[3] != 0.0);
  }
  const int n = p.size();
  if (n == 0) throw std::runtime_error("packing file '" + path + "' has a header but no disk");
  p.walls[0] = p.walls[2] = INFINITY;
  p.walls[1] = p.walls[3] = -INFINITY;
  double dmean = 0.0;
  for (int i = 0; i < n; ++i) {
    p.walls[0] = std::min(p.walls[0], p.x[i] - p.radius[i]), p.walls[1] = std::max(p.walls[1], p.x[i] + p.radius[i]);
    p.walls[2] = std::min(p.walls[2], p.y[i] - p.radius[i]), p.walls[3] = std::max(p.walls[3], p.y[i] + p.radius[i]);
    dmean += 2.0 * p.radius[i] / n;
  }
  const ContactNetwork close = contact_network(p, -overlap_tol * dmean);
  for (int c = 0; c < close.size(); ++c)
    if (close.j[c] >= 0) {
      std::ostringstream msg;
      msg << "packing file '" << path << "': disks " << close.i[c] << " and " << close.j[c] << " (rows "
          << close.i[c] + 2 << " and " << close.j[c] + 2 << ") overlap by " << -close.gap[c] << ", more than "
          << overlap_tol << " times the mean diameter";
      throw std::runtime_error(msg.str());
    }
  return p;
}

void assign_deformable(DiskPacking &packing, double kappa, unsigned seed) {
  if (!(kappa >= 0.0 && kappa <= 1.0)) {
    std::ostringstream msg;
    msg << "assign_deformable: kappa (deformable area fraction) must be in [0, 1], got " << kappa;
    throw std::invalid_argument(msg.str());
  }
  const int n = packing.size();
  packing.deformable.assign(n, 0);
  if (n == 0) return;
  const int order = 16;
  const double side = static_cast<double>(1u << order);
  const double xl = packing.walls[0], yb = packing.walls[2];
  const double wx = packing.walls[1] - xl, wy = packing.walls[3] - yb;
  auto grid = [&](double v, double lo, double w) -> std::uint32_t {
    const double t = (w > 0) ? (v - lo) / w * side : 0.0;
    return static_cast<std::uint32_t>(std::min(side - 1, std::max(0.0, std::floor(t))));
  };
  std::mt19937_64 eng = make_engine(seed, 2);
  struct Key {
    std::uint64_t h, tie;
    int i;
  };
  std::vector<Key> keys(n);
  for (int i = 0; i < n; ++i)
    keys[i] = {hilbert_index(grid(packing.x[i], xl, wx), grid(packing.y[i], yb, wy), order), eng(), i};
  std::sort(keys.begin(), keys.end(), [](const Key &a, const Key &b) {
    return a.h != b.h ? a.h < b.h : (a.tie != b.tie ? a.tie < b.tie : a.i < b.i);
  });
  const std::size_t start = static_cast<std::size_t>(uniform_index(eng, static_cast<std::uint64_t>(n)));
  double err = 0;  // accumulated target area minus marked area
  for (int k = 0; k < n; ++k) {
    const int i = keys[(start + k) % n].i;
    const double a = kPi * packing.radius[i] * packing.radius[i];
    err += kappa * a;
    if (err > 0.5 * a) {
      packing.deformable[i] = 1;
      err -= a;
    }
  }
}

double packing_fraction(const DiskPacking &packing) {
  double area = 0;
  for (double r : packing.radius) area += kPi * r * r;
  const double box = (packing.walls[1] - packing.walls[0]) * (packing.walls[3] - packing.walls[2]);
  if (!(box > 0)) throw std::invalid_argument("packing_fraction: box has non-positive area");
  return area / box;
}

ContactNetwork contact_network(const DiskPacking &packing, double gap_tol) {
  ContactNetwork net;
  const int n = packing.size();
  if (n == 0) return net;
  std::vector<std::pair<int, int>> pairs;
  build_pairs(packing.x, packing.y, packing.radius, packing.walls[0], packing.walls[1], packing.walls[2],
              packing.walls[3], std::max(0.0, gap_tol), pairs);
  std::sort(pairs.begin(), pairs.end());
  for (const auto &p : pairs) {
    const int i = p.first, j = p.second;
    const double dx = packing.x[j] - packing.x[i], dy = packing.y[j] - packing.y[i];
    const double gap = std::sqrt(dx * dx + dy * dy) - packing.radius[i] - packing.radius[j];
    if (gap < gap_tol) {
      net.i.push_back(i);
      net.j.push_back(j);
      net.gap.push_back(gap);
    }
  }
  for (int i = 0; i < n; ++i) {
    const double r = packing.radius[i];
    const double gaps[4] = {packing.x[i] - r - packing.walls[0], packing.walls[1] - packing.x[i] - r,
                            packing.y[i] - r - packing.walls[2], packing.walls[3] - packing.y[i] - r};
    for (int w = 0; w < 4; ++w)
      if (gaps[w] < gap_tol) {
        net.i.push_back(i);
        net.j.push_back(-1 - w);
        net.gap.push_back(gaps[w]);
      }
  }
  return net;
}

double max_overlap(const DiskPacking &packing) {
  const ContactNetwork net = contact_network(packing, 0.0);
  double m = 0;
  for (double g : net.gap) m = std::max(m, -g);
  return m;
}

Coordination coordination(const DiskPacking &packing, const ContactNetwork &contacts, int min_contacts) {
  const int n = packing.size();
  Coordination c;
  c.rattler.assign(n, 0);
  std::vector<int> count(n, 0);
  std::vector<std::vector<int>> partners(n);
  for (int k = 0; k < contacts.size(); ++k) {
    ++count[contacts.i[k]];
    if (contacts.j[k] >= 0) {
      ++count[contacts.j[k]];
      partners[contacts.i[k]].push_back(contacts.j[k]);
      partners[contacts.j[k]].push_back(contacts.i[k]);
    }
  }
  std::vector<int> stack;
  for (int i = 0; i < n; ++i)
    if (count[i] < min_contacts) {
      c.rattler[i] = 1;
      stack.push_back(i);
    }
  while (!stack.empty()) {  // removing a rattler may make its partners rattlers
    const int i = stack.back();
    stack.pop_back();
    for (int j : partners[i])
      if (!c.rattler[j] && --count[j] < min_contacts) {
        c.rattler[j] = 1;
        stack.push_back(j);
      }
  }
  for (int k = 0; k < contacts.size(); ++k) {
    const int a = contacts.i[k], b = contacts.j[k];
    if (c.rattler[a]) continue;
    if (b < 0) ++c.wall_contacts;
    else if (!c.rattler[b]) ++c.pair_contacts;
  }
  for (int i = 0; i < n; ++i) c.non_rattlers += c.rattler[i] ? 0 : 1;
  if (c.non_rattlers > 0) {
    c.z = (2.0 * c.pair_contacts + c.wall_contacts) / c.non_rattlers;
    c.z_mirror = 2.0 * (c.pair_contacts + c.wall_contacts) / c.non_rattlers;
  }
  c.rattler_fraction = n > 0 ? static_cast<double>(n - c.non_rattlers) / n : 0.0;
  return c;
}

}  // namespace deformix

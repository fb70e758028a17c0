// Contact detection: candidate pairs within a margin, refreshed between load
// steps (and after a solve that moved a point past its candidate set).
//
// Distribution: each rank runs the narrow phase (the per-node distances, the
// whole cost) only for the pairs whose slave particle it owns, i.e. its own
// particles against their neighbours (ghosts) found by the broad phase; the
// candidates are then gathered on every rank (a few integers each), so every
// rank holds the same list, sorted by RefreshCandidates into an order that does
// not depend on the number of ranks.
//
// Broad phase: a uniform grid of cells of the size of the largest particle
// bounding circle plus the margin; each particle is binned by its centre and
// only the 3 x 3 neighbouring cells are searched, so the cost is linear in
// the number of particles.
// Narrow phase, per pair type (the slave carries the multiplier):
//   rigid - rigid            gap = |c_B - c_A| - r_A - r_B
//   rigid - deformable       each boundary node of the deformable disk against the circle
//   deformable - deformable  each boundary node of the higher-numbered disk against the
//                            closest boundary segment of the other (single pass)
//   any - wall               rigid disks by their radius, deformable disks by their
//                            boundary points (nodes and Bezier control points)
#include <algorithm>
#include <cmath>
#include <limits>

#include "deformix/problem.hpp"

namespace deformix {

namespace {

struct Bound {
  double x, y, r;
  bool rigid;
  int index;  // into bodies_ or rigid_
};

// Closest boundary segment of a counter-clockwise boundary polygon to p, and
// the signed gap to it (outward normal = right normal of a -> b).
void ClosestSegment(const std::vector<double> &xb, const double p[2], int *segment, double *gap, double *xi_out) {
  const int nb = static_cast<int>(xb.size() / 2);
  double best = std::numeric_limits<double>::infinity();
  for (int s = 0; s < nb; ++s) {
    const double *a = &xb[2 * s], *b = &xb[2 * ((s + 1) % nb)];
    const double ex = b[0] - a[0], ey = b[1] - a[1], l2 = ex * ex + ey * ey;
    const double xi = std::clamp(((p[0] - a[0]) * ex + (p[1] - a[1]) * ey) / l2, 0.0, 1.0);
    const double dx = p[0] - a[0] - xi * ex, dy = p[1] - a[1] - xi * ey;
    const double dist = std::hypot(dx, dy);
    if (dist < best) {
      best = dist;
      *segment = s;
      *xi_out = xi;
      const double l = std::sqrt(l2);
      *gap = ((p[0] - a[0]) * ey - (p[1] - a[1]) * ex) / l;
    }
  }
}

}  // namespace

std::vector<ContactCandidate> CompactionProblem::DetectCandidates(double margin) const {
  std::vector<ContactCandidate> own = DetectOwnCandidates(margin);
  if (size_ == 1) return own;
  // Gather: 6 integers per candidate.
  std::vector<int> send;
  for (const ContactCandidate &c : own)
    send.insert(send.end(), {static_cast<int>(c.type), c.body, c.point, static_cast<int>(c.wall), c.master, c.segment});
  int count = static_cast<int>(send.size());
  std::vector<int> counts(size_), displs(size_, 0);
  MPI_Allgather(&count, 1, MPI_INT, counts.data(), 1, MPI_INT, comm_);
  for (int r = 1; r < size_; ++r) displs[r] = displs[r - 1] + counts[r - 1];
  std::vector<int> all(static_cast<size_t>(displs[size_ - 1] + counts[size_ - 1]));
  MPI_Allgatherv(send.data(), count, MPI_INT, all.data(), counts.data(), displs.data(), MPI_INT, comm_);
  std::vector<ContactCandidate> out(all.size() / 6);
  for (size_t i = 0; i < out.size(); ++i) {
    const int *v = &all[6 * i];
    out[i].type = static_cast<ContactType>(v[0]), out[i].body = v[1], out[i].point = v[2];
    out[i].wall = static_cast<Wall>(v[3]), out[i].master = v[4], out[i].segment = v[5];
  }
  return out;
}

std::vector<ContactCandidate> CompactionProblem::DetectOwnCandidates(double margin) const {
  std::vector<ContactCandidate> out;
  const double reach = margin * mean_diameter_;

  // Current boundary node positions and bounding circles of every particle.
  std::vector<std::vector<double>> boundary(bodies_.size());
  std::vector<Bound> bounds;
  for (int b = 0; b < static_cast<int>(bodies_.size()); ++b) {
    const DiskMesh &m = bodies_[b].mesh;
    boundary[b].resize(2 * m.boundary.size());
    double c[2] = {0.0, 0.0};
    for (size_t i = 0; i < m.boundary.size(); ++i) {
      NodePosition(b, m.boundary[i], &boundary[b][2 * i]);
      c[0] += boundary[b][2 * i] / m.boundary.size(), c[1] += boundary[b][2 * i + 1] / m.boundary.size();
    }
    double r = 0.0;
    for (size_t i = 0; i < m.boundary.size(); ++i)
      r = std::max(r, std::hypot(boundary[b][2 * i] - c[0], boundary[b][2 * i + 1] - c[1]));
    bounds.push_back({c[0], c[1], r, false, b});
  }
  for (int r = 0; r < static_cast<int>(rigid_.size()); ++r) {
    double c[2];
    RigidPosition(r, c, nullptr);
    bounds.push_back({c[0], c[1], rigid_[r].radius, true, r});
  }
  auto particle_of = [&](const Bound &b) { return b.rigid ? rigid_[b.index].particle : bodies_[b.index].particle; };

  // Walls.
  for (const Bound &bd : bounds) {
    if (ParticleOwner(particle_of(bd)) != rank_) continue;
    if (bd.rigid) {
      double g[4];
      const double c[2] = {bd.x, bd.y};
      WallBox::point_gaps(c, w_, g);
      for (int k = 0; k < 4; ++k)
        if (g[k] - bd.r < reach) {
          ContactCandidate cc;
          cc.type = ContactType::RigidWall, cc.body = bd.index, cc.wall = static_cast<Wall>(k);
          out.push_back(cc);
        }
      continue;
    }
    double g[4];
    const double c[2] = {bd.x, bd.y};
    WallBox::point_gaps(c, w_, g);
    if (*std::min_element(g, g + 4) - bd.r >= reach) continue;
    for (int i = 0; i < static_cast<int>(bodies_[bd.index].mesh.boundary.size()); ++i) {
      double x[2];
      BoundaryPointPosition(bd.index, i, x);
      WallBox::point_gaps(x, w_, g);
      for (int k = 0; k < 4; ++k)
        if (g[k] < reach) {
          ContactCandidate cc;
          cc.type = ContactType::PointWall, cc.body = bd.index, cc.point = i, cc.wall = static_cast<Wall>(k);
          out.push_back(cc);
        }
    }
  }
  if (bounds.size() < 2) return out;

  // Broad phase: uniform grid.
  double rmax = 0.0, xmin = 1e300, ymin = 1e300, xmax = -1e300, ymax = -1e300;
  for (const Bound &b : bounds) {
    rmax = std::max(rmax, b.r);
    xmin = std::min(xmin, b.x), xmax = std::max(xmax, b.x);
    ymin = std::min(ymin, b.y), ymax = std::max(ymax, b.y);
  }
  const double cell = 2.0 * rmax + std::max(reach, 0.0) + 1e-12;
  const int nx = std::max(1, static_cast<int>((xmax - xmin) / cell) + 1);
  const int ny = std::max(1, static_cast<int>((ymax - ymin) / cell) + 1);
  std::vector<std::vector<int>> grid(static_cast<size_t>(nx) * ny);
  auto cell_of = [&](const Bound &b, int *ix, int *iy) {
    *ix = std::min(nx - 1, static_cast<int>((b.x - xmin) / cell));
    *iy = std::min(ny - 1, static_cast<int>((b.y - ymin) / cell));
  };
  for (int i = 0; i < static_cast<int>(bounds.size()); ++i) {
    int ix, iy;
    cell_of(bounds[i], &ix, &iy);
    grid[static_cast<size_t>(iy) * nx + ix].push_back(i);
  }

  // Boundary nodes of the deformable slave S against the curve of the deformable master M.
  auto node_segment_candidates = [&](const Bound &M, const Bound &S) {
    const std::vector<double> &xs = boundary[S.index], &xm = boundary[M.index];
    for (int k = 0; k < static_cast<int>(xs.size() / 2); ++k) {
      const double *p = &xs[2 * k];
      if (std::hypot(p[0] - M.x, p[1] - M.y) - M.r >= reach) continue;
      int segment = -1;
      double gap = 0.0, xi = 0.0;
      ClosestSegment(xm, p, &segment, &gap, &xi);
      // A node deeper than half the master's radius is on the far side: not this pair.
      if (gap < reach && gap > -0.5 * M.r) {
        ContactCandidate cc;
        cc.type = ContactType::NodeSegment, cc.master = M.index, cc.body = S.index, cc.point = k;
        // The pair's window: the two master segments around the
        // master boundary node nearest to the closest point.
        cc.segment = (segment + (xi < 0.5 ? 0 : 1)) % static_cast<int>(xm.size() / 2);
        out.push_back(cc);
      }
    }
  };

  for (int i = 0; i < static_cast<int>(bounds.size()); ++i) {
    int ix, iy;
    cell_of(bounds[i], &ix, &iy);
    for (int jy = std::max(0, iy - 1); jy <= std::min(ny - 1, iy + 1); ++jy)
      for (int jx = std::max(0, ix - 1); jx <= std::min(nx - 1, ix + 1); ++jx)
        for (int j : grid[static_cast<size_t>(jy) * nx + jx]) {
          // Each pair once, ordered by particle number: A (master) before B (slave).
          if (particle_of(bounds[j]) <= particle_of(bounds[i])) continue;
          const Bound &A = bounds[i], &B = bounds[j];
          if (std::hypot(B.x - A.x, B.y - A.y) - A.r - B.r >= reach) continue;
          if (!A.rigid && !B.rigid) {
            // Deformable pair: B's nodes against A's curve, and with
            // -contact_deformable two_pass also A's nodes against B's curve. Each pass
            // belongs to the rank of its slave.
            if (ParticleOwner(particle_of(B)) == rank_) node_segment_candidates(A, B);
            const bool two_pass = params_.deformable_contact == DeformableContact::TwoPass;
            if (two_pass && ParticleOwner(particle_of(A)) == rank_) node_segment_candidates(B, A);
            continue;
          }
          // The slave: the deformable disk of a rigid-deformable pair, else B.
          const Bound &slave = A.rigid != B.rigid ? (A.rigid ? B : A) : B;
          if (ParticleOwner(particle_of(slave)) != rank_) continue;
          if (A.rigid && B.rigid) {
            ContactCandidate cc;
            cc.type = ContactType::RigidRigid, cc.master = A.index, cc.body = B.index;
            out.push_back(cc);
          } else {
            const Bound &R = A.rigid ? A : B, &D = A.rigid ? B : A;
            const std::vector<double> &xb = boundary[D.index];
            for (int k = 0; k < static_cast<int>(xb.size() / 2); ++k)
              if (std::hypot(xb[2 * k] - R.x, xb[2 * k + 1] - R.y) - R.r < reach) {
                ContactCandidate cc;
                cc.type = ContactType::RigidNode, cc.master = R.index, cc.body = D.index, cc.point = k;
                out.push_back(cc);
              }
          }
        }
  }
  return out;
}

}  // namespace deformix

// Contact detection (contact_detection.hpp).
#include <algorithm>
#include <cmath>
#include <limits>

#include "deformix/contact_detection.hpp"

namespace deformix {

namespace {

struct Bound {
  double x, y, r;
  bool rigid;
  int index;  // into scene.deformable or scene.rigid
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

std::vector<ContactCandidate> GatherCandidates(MPI_Comm comm, const std::vector<ContactCandidate> &own) {
  int size = 1;
  MPI_Comm_size(comm, &size);
  if (size == 1) return own;
  // Gather: 6 integers per candidate.
  std::vector<int> send;
  for (const ContactCandidate &c : own)
    send.insert(send.end(), {static_cast<int>(c.type), c.body, c.point, static_cast<int>(c.wall), c.master, c.segment});
  int count = static_cast<int>(send.size());
  std::vector<int> counts(size), displs(size, 0);
  MPI_Allgather(&count, 1, MPI_INT, counts.data(), 1, MPI_INT, comm);
  for (int r = 1; r < size; ++r) displs[r] = displs[r - 1] + counts[r - 1];
  std::vector<int> all(static_cast<size_t>(displs[size - 1] + counts[size - 1]));
  MPI_Allgatherv(send.data(), count, MPI_INT, all.data(), counts.data(), displs.data(), MPI_INT, comm);
  std::vector<ContactCandidate> out(all.size() / 6);
  for (size_t i = 0; i < out.size(); ++i) {
    const int *v = &all[6 * i];
    out[i].type = static_cast<ContactType>(v[0]), out[i].body = v[1], out[i].point = v[2];
    out[i].wall = static_cast<Wall>(v[3]), out[i].master = v[4], out[i].segment = v[5];
  }
  return out;
}

std::vector<ContactCandidate> DetectOwnCandidates(const DetectionScene &scene, double reach, int rank) {
  std::vector<ContactCandidate> out;
  const double *walls = scene.walls;

  // Bounding circles of every particle: deformable disks around the mean of their boundary nodes.
  std::vector<Bound> bounds;
  for (int b = 0; b < static_cast<int>(scene.deformable.size()); ++b) {
    const std::vector<double> &xb = scene.deformable[b].boundary;
    const size_t nb = xb.size() / 2;
    double c[2] = {0.0, 0.0};
    for (size_t i = 0; i < nb; ++i) c[0] += xb[2 * i] / nb, c[1] += xb[2 * i + 1] / nb;
    double r = 0.0;
    for (size_t i = 0; i < nb; ++i) r = std::max(r, std::hypot(xb[2 * i] - c[0], xb[2 * i + 1] - c[1]));
    bounds.push_back({c[0], c[1], r, false, b});
  }
  for (int r = 0; r < static_cast<int>(scene.rigid.size()); ++r)
    bounds.push_back({scene.rigid[r].centre[0], scene.rigid[r].centre[1], scene.rigid[r].radius, true, r});
  auto particle_of = [&](const Bound &b) {
    return b.rigid ? scene.rigid[b.index].particle : scene.deformable[b.index].particle;
  };
  auto owner_of = [&](const Bound &b) { return b.rigid ? scene.rigid[b.index].owner : scene.deformable[b.index].owner; };

  // Walls.
  for (const Bound &bd : bounds) {
    if (owner_of(bd) != rank) continue;
    if (bd.rigid) {
      double g[4];
      const double c[2] = {bd.x, bd.y};
      WallBox::point_gaps(c, walls, g);
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
    WallBox::point_gaps(c, walls, g);
    if (*std::min_element(g, g + 4) - bd.r >= reach) continue;
    const std::vector<double> &points = scene.deformable[bd.index].points;
    for (int i = 0; i < static_cast<int>(points.size() / 2); ++i) {
      WallBox::point_gaps(&points[2 * i], walls, g);
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
    const std::vector<double> &xs = scene.deformable[S.index].boundary, &xm = scene.deformable[M.index].boundary;
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
            if (owner_of(B) == rank) node_segment_candidates(A, B);
            if (scene.two_pass && owner_of(A) == rank) node_segment_candidates(B, A);
            continue;
          }
          // The slave: the deformable disk of a rigid-deformable pair, else B.
          const Bound &slave = A.rigid != B.rigid ? (A.rigid ? B : A) : B;
          if (owner_of(slave) != rank) continue;
          if (A.rigid && B.rigid) {
            ContactCandidate cc;
            cc.type = ContactType::RigidRigid, cc.master = A.index, cc.body = B.index;
            out.push_back(cc);
          } else {
            const Bound &R = A.rigid ? A : B, &D = A.rigid ? B : A;
            const std::vector<double> &xb = scene.deformable[D.index].boundary;
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

// The box: four rigid, frictionless walls whose positions are unknowns.
//
// Wall coordinates w = (x_left, x_right, y_bottom, y_top). Each wall is
// pushed inwards by the imposed pressure P times its current length, which
// is exactly the load derived from the potential of the pressure acting on
// the box area,
//     Pi_P(w) = P (x_right - x_left) (y_top - y_bottom),
// so the whole problem (elastic energy + Pi_P under g >= 0) is a constrained
// minimization and its tangent is symmetric up to the NCP rows. The gap of a
// point x against each wall is linear:
//     left: x - x_left,  right: x_right - x,  bottom: y - y_bottom,  top: y_top - y.
#pragma once
#include <array>

#include "deformix/contact_law.hpp"

namespace deformix {

enum Wall { kLeft = 0, kRight = 1, kBottom = 2, kTop = 3 };

struct WallBox {
  // Width and height of the box for wall coordinates w.
  static double width(const double w[4]) { return w[kRight] - w[kLeft]; }
  static double height(const double w[4]) { return w[kTop] - w[kBottom]; }
  static double area(const double w[4]) { return width(w) * height(w); }

  // Gradient g[4] and Hessian H[16] (row-major) of Pi_P = P * area(w).
  static void pressure_gradient(double P, const double w[4], double g[4]);
  static void pressure_hessian(double P, double H[16]);

  // The walls' one sign convention: wall k's inward normal is
  // inward_sign(k) e_axis(k), so the gap of a point p against it is
  // inward_sign(k) (p[axis(k)] - w[k]) (left and bottom: p - w; right and
  // top: w - p), and a contact force lambda pushes the body along the normal.
  static int axis(Wall k) { return k == kLeft || k == kRight ? 0 : 1; }
  static double inward_sign(Wall k) { return k == kLeft || k == kBottom ? 1.0 : -1.0; }

  // Gaps of a point against the four walls, indexed by Wall.
  static void point_gaps(const double p[2], const double w[4], double g[4]) {
    for (int k = 0; k < 4; ++k) g[k] = inward_sign(Wall(k)) * (p[axis(Wall(k))] - w[k]);
  }

  // Gap against `wall` of a point p = sum_k coeff[k] x_k that is a fixed
  // linear combination of n nodes (a node: n = 1, coeff = 1), with its
  // derivatives with respect to the nodes' unknowns (dof_x[k], dof_y[k]) and
  // the wall's unknown dof_wall.
  static ContactKinematics point_gap(Wall wall, const double p[2], const double w[4], int n, const int dof_x[],
                                     const int dof_y[], const double coeff[], int dof_wall);
};

}  // namespace deformix

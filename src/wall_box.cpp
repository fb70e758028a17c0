#include "deformix/wall_box.hpp"

namespace deformix {

void WallBox::pressure_gradient(double P, const double w[4], double g[4]) {
  const double lx = width(w), ly = height(w);
  g[kLeft] = -P * ly;
  g[kRight] = P * ly;
  g[kBottom] = -P * lx;
  g[kTop] = P * lx;
}

void WallBox::pressure_hessian(double P, double H[16]) {
  for (int i = 0; i < 16; ++i) H[i] = 0.0;
  auto set = [&](int a, int b, double v) { H[4 * a + b] = H[4 * b + a] = v; };
  set(kLeft, kBottom, P);
  set(kLeft, kTop, -P);
  set(kRight, kBottom, -P);
  set(kRight, kTop, P);
}

ContactKinematics WallBox::point_gap(Wall wall, const double p[2], const double w[4], int n, const int dof_x[],
                                     const int dof_y[], const double coeff[], int dof_wall) {
  const double sign = inward_sign(wall);
  const bool horizontal = axis(wall) == 0;
  double g[4];
  point_gaps(p, w, g);
  ContactKinematics k;
  k.gap = g[wall];
  k.ndof = n + 1;
  for (int a = 0; a < n; ++a) {
    k.dofs[a] = horizontal ? dof_x[a] : dof_y[a];
    k.dgap[a] = sign * coeff[a];
  }
  k.dofs[n] = dof_wall;
  k.dgap[n] = -sign;
  return k;
}

}  // namespace deformix

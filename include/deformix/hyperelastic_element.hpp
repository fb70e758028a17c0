// Plane-strain compressible neo-Hookean solid on Lagrange triangles.
//
// Strain energy per unit reference area (F 2x2, F33 = 1, J = det F):
//   W(F) = mu/2 (F:F + 1 - 3) - mu ln J + lambda/2 (ln J)^2
// (the law LMGC90's neoh_ uses). First Piola-Kirchhoff stress
//   P = mu (F - F^-T) + lambda ln J F^-T,
// and the tangent A = dP/dF. The element energy, internal force
//   f_a = int_Omega0 P grad_X N_a dA
// and its consistent stiffness K = df/dx are integrated with a 6-point
// degree-4 Gauss rule (order 2) or the centroid rule (order 1, exact there
// because F is constant on an affine triangle) through the isoparametric
// map, so curved boundary edges are exact in the reference configuration.
//
// Near incompressibility (nu = 0.495): 3-node triangles lock; 6-node
// isoparametric triangles do not at the resolutions used here (see the
// work-precision benchmark, docs/single-particle.md).
#pragma once

namespace deformix {

struct NeoHookean {
  double mu = 0.0;      // shear modulus
  double lambda = 0.0;  // first Lame parameter
  // Plane-strain Lame parameters from Young's modulus and Poisson's ratio.
  static NeoHookean from_young_poisson(double E, double nu);

  // F and P are 2x2 row-major: [F11 F12 F21 F22]. J must be > 0.
  double energy_density(const double F[4]) const;
  void first_piola(const double F[4], double P[4]) const;
  // A[(2i+J)*4 + 2k+L] = dP_iJ / dF_kL
  void tangent(const double F[4], double A[16]) const;
};

struct ElementResult {
  double energy = 0.0;      // int W dA0
  double area = 0.0;        // current area int J dA0
  double ref_area = 0.0;    // reference area int dA0
  bool inverted = false;    // J <= 0 or det dX/dxi <= 0 at some quadrature point
                            // (evaluation stops there: energy, areas, f, K not valid)
};

// Nodes per triangle of the given order (1 -> 3, 2 -> 6).
int triangle_nodes(int order);

// Element kernel. X, x: reference and current nodal coordinates (2 per node,
// node order as in DiskMesh::cells). f (size 2n) receives the internal force,
// K (size 2n x 2n, row-major, dof 2a+i) the stiffness; either may be nullptr.
ElementResult triangle_element(const NeoHookean &material, int order, const double *X, const double *x,
                               double *f, double *K);

}  // namespace deformix

// Contact kinematics of the mixture's pair types: gap, incremental tangential
// slip, and their first and second derivatives with respect to the local
// unknowns of the pair.
//
// Local unknowns q (positions, not displacements):
//   rigid disk     (x, y, theta)   centre and rotation angle, radius r
//   boundary node  (x, y)          of a deformable disk (slave node p, or a
//                                  node a, b or m0..m4 of a master's boundary)
// Conventions: the normal n is a unit vector pointing from the "master" A
// to the "slave" B (rigid-rigid: from centre A to centre B; node-rigid: from
// the disk centre to the node; node-segment: the segment's outward normal,
// which for the counter-clockwise boundaries of DiskMesh is the RIGHT normal
// of a -> b, n = (e_y, -e_x) / |e| with e = b - a; the left normal would point
// into the body; curve-node: the same for the curve's tangent); the tangent
// is t = (-n_y, n_x), i.e. counter-clockwise around a rigid master and along
// the master's counter-clockwise boundary, so s > 0 means the slave moves counter-clockwise around the
// master for every pair type.
// The gap g >= 0 when the bodies are apart.
//
// Incremental slip over a load step, with q0 the unknowns at the start of
// the step and Delta = q - q0, is the tangential displacement of the slave
// contact point relative to the master's material point, measured with the
// current tangent (linearized rotation of rigid bodies over a step):
//   rigid A - rigid B:  g = |c_B - c_A| - r_A - r_B
//                       s = t . (Delta c_B - Delta c_A) - r_A Delta theta_A - r_B Delta theta_B
//   rigid A - node p:   g = |p - c_A| - r_A
//                       s = t . (Delta p - Delta c_A) - r_A Delta theta_A
//   segment a-b - node p (straight segment of a deformable boundary):
//                       xi = (p - a).(b - a) / |b - a|^2 (closest point, may leave [0, 1];
//                            the caller chooses the segment),
//                       n = right normal of (b - a) / |b - a| (outward, see above),
//                       g = (p - a) . n (signed distance to the segment's LINE, also
//                           when xi is outside [0, 1]),  t = (b - a) / |b - a|,
//                       s = t . (Delta p - (1 - xi) Delta a - xi Delta b)
//   curve - node p: p against the smooth master curve through five master
//       boundary nodes (curve_node below, src/curve_kinematics.cpp).
// The Hessians are exact (they enter the consistent Newton tangent through
// the multipliers: -lambda_n d2g - lambda_t d2s); both are symmetric and
// stored row-major with stride ndof (entries past ndof*ndof stay zero).
//
// Degenerate input (coincident centres, |c_B - c_A| <= 1e-12 (r_A + r_B +
// |c_B0 - c_A0|); collapsed segment, |b - a| <= 1e-12 (|b0 - a0| + |p - a|);
// the normal is undefined, so normal = (0, 0), slip = 0 and all derivatives
// are zero; gap = -r_A - r_B (rigid-rigid, full overlap), -r_A (rigid-node),
// |p - a| (collapsed segment, reported as open); curve-node: see below.
// A zero normal flags this case.
//
// Limitations of the incremental slip (relevant to the friction law):
//  - the rotation is linearised over the step (r Delta theta) while the
//    relative centre motion is projected on the CURRENT tangent, so s is not
//    objective for finite step rotations: two touching disks rotated rigidly
//    together by phi give s = (r_A + r_B)(sin phi - phi) ~ -(r_A + r_B) phi^3 / 6
//    (exact zero only for pure translations);
//  - s is relative to the configuration at the step start q0: it assumes the
//    same pair (and, for segments, the same segment) throughout the step.
#pragma once

namespace deformix {

struct PairKinematics {
  static constexpr int kMaxDofs = 24;
  int ndof = 0;                             // number of local unknowns of the pair
  double gap = 0.0;
  double slip = 0.0;                        // incremental tangential slip s
  double normal[2] = {0.0, 0.0};
  double dgap[kMaxDofs] = {};               // dg/dq
  double dslip[kMaxDofs] = {};              // ds/dq
  double d2gap[kMaxDofs * kMaxDofs] = {};   // d2g/dq2, row-major ndof x ndof
  double d2slip[kMaxDofs * kMaxDofs] = {};  // d2s/dq2
};

// q = (xA, yA, thA, xB, yB, thB), q0 the same at the step start.
PairKinematics rigid_rigid(const double q[6], const double q0[6], double rA, double rB);
// q = (xA, yA, thA, px, py).
PairKinematics rigid_node(const double q[5], const double q0[5], double rA);
// q = (ax, ay, bx, by, px, py).
// The solver uses curve_node for deformable masters; segment_node is the
// straight-segment pair that curve_node reduces to on a straight line (its
// test reference).
PairKinematics segment_node(const double q[6], const double q0[6]);
// q = (m0, m1, m2, m3, m4, p), 12 unknowns: node p against the smooth
// (C1) master curve through the five nodes, the uniform Catmull-Rom spline,
// on its two segments m1 -> m2 and m2 -> m3 that the five nodes define
// (src/curve_kinematics.cpp). The closest point t* on the curve gives
//   g = (p - x(t*)) . n,  n = right normal of the curve tangent (outward),
//   s = tau . [(p - p0) - sum_i N_i(t*) (m_i - m0_i)]   (tau = x'/|x'|, N_i the
//       spline's basis functions: the slave's displacement relative to the
//       master's material point, as for segment_node).
// Gap, normal and slip are continuous (C1 in q) wherever the closest point
// is unique, also across the master nodes: no vertex features, so a slave
// node pressed onto a master node has a smooth equilibrium (against a
// polyline master Newton cycles there between the two segments, whose
// normals differ by the corner angle).
// On equally spaced collinear master nodes the curve is the straight line.
// Second derivatives (d2gap, d2slip) only if `hessians` (exact: the
// implicit function theorem over the closed-form gap and slip in (q, t)).
// *beyond = -1 / +1 when the closest point lies before m1 / after m3 (the
// curve is then the extrapolated end segment: re-centre the patch).
// Degenerate input (collapsed tangent, or no closest point: a node far on
// the concave side) gives a zero normal and zero derivatives.
PairKinematics curve_node(const double q[12], const double q0[12], bool hessians = true, int *beyond = nullptr);

// Mortar (weighted) gap and slip of slave boundary node j against the smooth
// master curve (src/mortar_kinematics.cpp):
//   g~_j = int phi_j g ds / int phi_j ds,   s~_j = int phi_j s ds / int phi_j ds,
// phi_j the indicator of node j's dual cell (the halves of the two boundary
// sub-segments around it), g and s those of curve_node at each slave
// boundary point, integrated over the slave's boundary edges (straight or
// quadratic) in the reference arc length.
// q = (m0..m6, s0..s4), 24 unknowns: seven consecutive master boundary nodes
// (the closest point of every slave point must lie on the four segments
// m1 -> m5; else *beyond = -1 / +1: re-centre the patch) and the slave
// boundary nodes j-2..j+2 (s2 = node j; the edges through them carry the
// slave points). Exact first and (if `hessians`) second derivatives.
struct MortarSupport {
  int order = 2;          // slave mesh order: 1 straight edges, 2 quadratic edges
  bool vertex = true;     // order 2: node j is a vertex (else a mid-edge node)
  double length[2] = {1.0, 1.0};  // reference lengths of the sub-segments j-1 -> j and j -> j+1
};
PairKinematics mortar_node(const double q[24], const double q0[24], const MortarSupport &support, bool hessians = true,
                           int *beyond = nullptr);

}  // namespace deformix

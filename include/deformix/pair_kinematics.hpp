// Contact kinematics of the mixture's pair types: gap, incremental tangential
// slip, and their first and second derivatives with respect to the local
// unknowns of the pair.
//
// Local unknowns q (positions, not displacements):
//   rigid disk     (x, y, theta)   centre and rotation angle, radius r
//   boundary node  (x, y)          of a deformable disk (slave node p, or a
//                                  node a, v, b of a master's boundary)
// Conventions: the normal n is a unit vector pointing from the "master" A
// to the "slave" B (rigid-rigid: from centre A to centre B; node-rigid: from
// the disk centre to the node; node-segment: the segment's outward normal,
// which for the counter-clockwise boundaries of DiskMesh is the RIGHT normal
// of a -> b, n = (e_y, -e_x) / |e| with e = b - a; the left normal would point
// into the body; window-node: that of the chosen segment, or from the vertex
// v to the node for a vertex feature); the tangent is t = (-n_y, n_x), i.e.
// counter-clockwise around a rigid master or a master vertex and along a -> b
// on a segment, so s > 0 means the slave moves counter-clockwise around the
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
//   window a -> v -> b - node p (the two boundary segments of a deformable
//   master around its vertex v; ndof = 8, q = (a, v, b, p)): one feature is
//   chosen, with xi1, g1 (xi2, g2) those of segment_node on a-v (v-b) and
//   convex = cross(v - a, b - v) > 0 (left turn of the counter-clockwise boundary):
//     VERTEX if convex and xi1 > 1 and xi2 < 0 (p in the outer normal cone
//       of the corner):  n = (p - v) / |p - v| (from v to p),  g = |p - v|,
//                        s = t . (Delta p - Delta v) = -t . (p0 - v0);
//       a and b get zero derivatives;
//     otherwise a SEGMENT: seg1 is applicable if xi1 <= 1, seg2 if xi2 >= 0
//       (both if neither is); of two applicable ones the larger gap is taken
//       at a convex corner (the body is locally the intersection of the two
//       half-planes), the smaller at a non-convex one (the union); gap,
//       slip, normal and derivatives are those of segment_node on (a, v, p)
//       or (v, b, p), scattered into the 8 unknowns.
//     A collapsed segment (segment_node's test) is skipped and the other one
//     chosen (no vertex feature); if both are collapsed, the result is
//     segment_node's degenerate one on (a, v, p) (see below).
//   The gap is continuous in q across every feature switch and the normal
//   across vertex <-> segment switches (n = n1 at xi1 = 1, n2 at xi2 = 0),
//   and so is the slip there. At a seg1 <-> seg2 switch (g1 = g2: the node
//   on the bisector of a penetrated convex corner or of the exterior of a
//   concave one) the normal and the slip JUMP: each segment measures the slip
//   along its own tangent (a node moving by d relative to a fixed master has
//   s = tau1 . d or tau2 . d); the Newton derivatives are those of the chosen
//   feature (one-sided there).
//   The optional output *beyond is 0, or -1 / +1 when the chosen feature is
//   seg1 with xi1 < 0 / seg2 with xi2 > 1 (closest point outside the window:
//   the caller re-centres the window on a neighbouring vertex).
// The Hessians are exact (they enter the consistent Newton tangent through
// the multipliers: -lambda_n d2g - lambda_t d2s); both are symmetric and
// stored row-major with stride ndof (entries past ndof*ndof stay zero).
//
// Degenerate input (coincident centres, |c_B - c_A| <= 1e-12 (r_A + r_B +
// |c_B0 - c_A0|); collapsed segment, |b - a| <= 1e-12 (|b0 - a0| + |p - a|);
// window: both segments collapsed, or a VERTEX feature with the node on the
// vertex, |p - v| <= 1e-12 (|v - a| + |b - v| + |p0 - v0|)):
// the normal is undefined, so normal = (0, 0), slip = 0 and all derivatives
// are zero; gap = -r_A - r_B (rigid-rigid, full overlap), -r_A (rigid-node),
// |p - a| (collapsed segment or window, reported as open), |p - v| (window
// vertex).
// A zero normal flags this case.
//
// Limitations of the incremental slip (relevant to the friction law):
//  - the rotation is linearised over the step (r Delta theta) while the
//    relative centre motion is projected on the CURRENT tangent, so s is not
//    objective for finite step rotations: two touching disks rotated rigidly
//    together by phi give s = (r_A + r_B)(sin phi - phi) ~ -(r_A + r_B) phi^3 / 6
//    (exact zero only for pure translations);
//  - s is relative to the configuration at the step start q0: it assumes the
//    same pair (and, for segments, the same segment) throughout the step;
//    window_node's slip is continuous across vertex <-> segment switches but
//    not across seg1 <-> seg2 switches (see above).
#pragma once

namespace deformix {

struct PairKinematics {
  static constexpr int kMaxDofs = 12;
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
PairKinematics segment_node(const double q[6], const double q0[6]);
// q = (ax, ay, vx, vy, bx, by, px, py): boundary node p of a deformable slave
// against the master's boundary polyline a -> v -> b (the two boundary
// segments around master vertex v, counter-clockwise boundary, outward normal =
// right normal of each segment as in segment_node). q0 = the same at the step start.
// *beyond (if not null) is set to 0, or -1 / +1 when the chosen feature is
// segment a-v with xi < 0 / segment v-b with xi > 1 (closest point outside the
// window: the caller re-centres the window on another vertex).
PairKinematics window_node(const double q[8], const double q0[8], int *beyond = nullptr);

// q = (m0, m1, m2, m3, m4, p), 12 unknowns: node p against five consecutive
// master boundary nodes m0 -> ... -> m4 (four segments around m2). The pair
// is window_node on the three nodes around the interior node m1, m2 or m3
// nearest to p's closest point on the polyline, embedded in the 12 unknowns.
// The choice switches at a segment's midpoint, where both windows choose the
// same segment for a node outside the master, so the gap is continuous while
// p's closest point stays within about 1.5 segments of m2: a contact can slide
// that far inside one Newton solve without a change of sparsity pattern.
// *beyond = -1 / +1 when the closest point lies beyond m1 / m3 (re-centre).
PairKinematics patch_node(const double q[12], const double q0[12], int *beyond = nullptr);
// q = (m0, m1, m2, m3, m4, p) as for patch_node: node p against the smooth
// (C1) master curve through the five nodes, the uniform Catmull-Rom spline,
// on its two segments m1 -> m2 and m2 -> m3 that the five nodes define
// (src/curve_kinematics.cpp). The closest point t* on the curve gives
//   g = (p - x(t*)) . n,  n = right normal of the curve tangent (outward),
//   s = tau . [(p - p0) - sum_i N_i(t*) (m_i - m0_i)]   (tau = x'/|x'|, N_i the
//       spline's basis functions: the slave's displacement relative to the
//       master's material point, as for segment_node).
// Gap, normal and slip are continuous (C1 in q) wherever the closest point
// is unique, also across the master nodes: no vertex features, so a slave
// node pressed onto a master node has a smooth equilibrium (with the
// polyline master, patch_node, Newton cycles between the two segments).
// On equally spaced collinear master nodes the curve is the straight line.
// Second derivatives (d2gap, d2slip) only if `hessians` (exact, by forward
// automatic differentiation; they cost about 20 times the rest).
// *beyond = -1 / +1 when the closest point lies before m1 / after m3 (the
// curve is then the extrapolated end segment: re-centre the patch).
// Degenerate input (collapsed tangent, or no closest point: a node far on
// the concave side) gives a zero normal and zero derivatives.
PairKinematics curve_node(const double q[12], const double q0[12], bool hessians = true, int *beyond = nullptr);

}  // namespace deformix

// Edge-edge geometry for self-collision. Vertex-triangle tests alone (paper §1) let two edges
// pass through each other; the tangle that leaves is then held by the vertex-triangle responses
// and stretches the cloth. These close that gap: closest points of two segments and the
// continuous-time crossing of two edges (Provot 1997; Bridson, Fedkiw, Anderson 2002 §6).
#pragma once
#include <Eigen/Geometry>

#include "common/types.h"

namespace flagsim {

/// Parameters (s, u) in [0, 1]^2 of the closest points p1 + s (p2 - p1) and q1 + u (q2 - q1) of
/// segments p1p2 and q1q2 (Ericson, Real-Time Collision Detection §5.1.9).
Vec2 closest_segment_parameters(const Vec3& p1, const Vec3& p2, const Vec3& q1, const Vec3& q2);

/// Continuous edge-edge test under linear motion over the step (t in [0, 1]): the earliest time at
/// which segments p1p2 and q1q2 intersect, found among the roots of the coplanarity cubic of the
/// four points. Parallel edges (no well-defined crossing) are skipped. On true, t_hit and the
/// segment parameters (s, u) at t_hit are written.
bool edge_edge_ccd(const Vec3& p1_0, const Vec3& p2_0, const Vec3& q1_0, const Vec3& q2_0,
                   const Vec3& p1_1, const Vec3& p2_1, const Vec3& q1_1, const Vec3& q2_1,
                   double& t_hit, Vec2& su);

/// For edges crossing at t_hit: the latest time in [0, t_hit] at which the edges' lines are still
/// min(gap, d(0)) apart on the side they started on, d(t) being the signed distance between the
/// lines along (p2 - p1) x (q2 - q1), by bisection (1e-9 in t); 0 if they start on one line.
double edge_separation_time(const Vec3& p1_0, const Vec3& p2_0, const Vec3& q1_0, const Vec3& q2_0,
                            const Vec3& p1_1, const Vec3& p2_1, const Vec3& q1_1, const Vec3& q2_1,
                            double t_hit, double gap);

}  // namespace flagsim

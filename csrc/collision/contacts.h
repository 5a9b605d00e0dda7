// Self-collision narrow phase: the two kinds of candidate pair as two types with one interface,
// so that the sweeps and the fallback (self_collision.cpp) are written once for both.
//   VertexTriangleContact: vertex p against triangle abc (paper §1);
//   EdgeEdgeContact: edge pa against edge bc, without which two edges can pass through each other.
// A pair is four points, ordered (p, a, b, c) as above; x0 and x1 hold them at the step's start
// and end (m), every point moving linearly between them. The response acts on
// C = (sum_k g_k x_k) . n - thickness >= 0 (self_collision.h), whose coefficients g each type
// writes into its Contact.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>

#include "collision/candidates.h"
#include "collision/edge_edge.h"
#include "collision/vertex_triangle.h"
#include "common/types.h"

namespace flagsim {

/// One pair's response in a sweep.
struct Contact {
  // kDegenerate: a crossing or touch with no usable normal, left to the fallback.
  enum Kind : uint8_t { kNone, kCrossing, kProximity, kDegenerate } kind;
  // The constraint's coefficients: vertex-triangle g = (1, -b_a, -b_b, -b_c) with b the
  // barycentric coordinates of the triangle's point, edge-edge g = (1 - s, s, -(1 - u), -u) with
  // (s, u) the segment parameters of the edges' points.
  double g[4];
  Vec3 n;    // unit direction, from the second point set to the first
  double C;  // proximity: distance - thickness at detection, < 0
};

using PairPoints = Vec3[4];

struct VertexTriangleContact {
  /// The pair's vertices (p, a, b, c) for pr = (vertex, triangle) of the candidates' mesh.
  static void corners(const Candidates& mesh, const CandidatePair& pr, int32_t idx[4]) {
    const MatX3i& tris = mesh.triangles();
    idx[0] = pr.a, idx[1] = tris(pr.b, 0), idx[2] = tris(pr.b, 1), idx[3] = tris(pr.b, 2);
  }
  /// An upper bound of reach() from each vertex's own displacement m (m, per vertex): the
  /// vertex's plus the largest of the triangle's.
  static double motion_bound(const double* m, const int32_t i[4]) {
    return m[i[0]] + std::max({m[i[1]], m[i[2]], m[i[3]]});
  }
  /// How far the two sides can have approached over the step, from the points' displacements d
  /// (m): the largest displacement of the vertex relative to a point of the triangle (convex
  /// combinations of the corners, so the largest over the corners).
  static double reach(const PairPoints& d) {
    double r2 = 0;
    for (int b = 1; b < 4; ++b) r2 = std::max(r2, (d[0] - d[b]).squaredNorm());
    return std::sqrt(r2);
  }
  /// The distance (m) between the vertex and the triangle.
  static double distance(const PairPoints& x) {
    const Vec3 &p = x[0], &a = x[1], &b = x[2], &c = x[3];
    bool interior;
    const Vec3 w = closest_point_barycentric(p, a, b, c, interior);
    return (p - (w[0] * a + w[1] * b + w[2] * c)).norm();
  }
  /// The earliest crossing of the vertex through the triangle, at t in [0, 1].
  static bool crossing(const PairPoints& x0, const PairPoints& x1, double& t) {
    Vec3 bary;
    return vertex_triangle_ccd(x0[0], x0[1], x0[2], x0[3], x1[0], x1[1], x1[2], x1[3], t, bary);
  }
  /// For a crossing at t: the time to stop at, `gap` short of it (separation_time).
  static double separation(const PairPoints& x0, const PairPoints& x1, double t, double gap) {
    return separation_time(x0[0], x0[1], x0[2], x0[3], x1[0], x1[1], x1[2], x1[3], t, gap);
  }
  /// A crossing of the step's trajectory, with the hit's points (g) and the triangle's normal at
  /// the hit time towards the side the vertex started on (Bridson et al. 2002 §7.3, for the
  /// impulse); otherwise a proximity at x1 closer than the thickness, along the closest-points
  /// direction (the triangle's normal when the vertex lies on it); else kNone.
  static void detect(const PairPoints& x0, const PairPoints& x1, double thickness, Contact& ct);
  /// Whether the vertex is closer than gap to the triangle (the fallback's floor).
  static bool closer_than(const PairPoints& x, double gap);
};

struct EdgeEdgeContact {
  /// The pair's vertices (p, a, b, c) for pr = (edge pa, edge bc) of the candidates' mesh.
  static void corners(const Candidates& mesh, const CandidatePair& pr, int32_t idx[4]) {
    const MatX2i& edges = mesh.edges();
    idx[0] = edges(pr.a, 0), idx[1] = edges(pr.a, 1);
    idx[2] = edges(pr.b, 0), idx[3] = edges(pr.b, 1);
  }
  /// An upper bound of reach() from each vertex's own displacement m: the largest of each edge's.
  static double motion_bound(const double* m, const int32_t i[4]) {
    return std::max(m[i[0]], m[i[1]]) + std::max(m[i[2]], m[i[3]]);
  }
  /// As VertexTriangleContact::reach: the largest displacement of a point of the first edge
  /// relative to a point of the second (the largest over the corner pairs).
  static double reach(const PairPoints& d) {
    double r2 = 0;
    for (int a = 0; a < 2; ++a)
      for (int b = 2; b < 4; ++b) r2 = std::max(r2, (d[a] - d[b]).squaredNorm());
    return std::sqrt(r2);
  }
  /// The distance (m) between the two segments.
  static double distance(const PairPoints& x) {
    const Vec3 &p = x[0], &a = x[1], &b = x[2], &c = x[3];
    const Vec2 su = closest_segment_parameters(p, a, b, c);
    return ((p + su[0] * (a - p)) - (b + su[1] * (c - b))).norm();
  }
  /// The earliest crossing of the two edges, at t in [0, 1].
  static bool crossing(const PairPoints& x0, const PairPoints& x1, double& t) {
    Vec2 su;
    return edge_edge_ccd(x0[0], x0[1], x0[2], x0[3], x1[0], x1[1], x1[2], x1[3], t, su);
  }
  /// For a crossing at t: the time to stop at, `gap` short of it (edge_separation_time).
  static double separation(const PairPoints& x0, const PairPoints& x1, double t, double gap) {
    return edge_separation_time(x0[0], x0[1], x0[2], x0[3], x1[0], x1[1], x1[2], x1[3], t, gap);
  }
  /// A crossing, with the edges' points at the hit (g) and the normal of the two edges at the hit
  /// time towards the side they started on; otherwise a proximity at x1 closer than the
  /// thickness, along the closest-points direction; else kNone.
  static void detect(const PairPoints& x0, const PairPoints& x1, double thickness, Contact& ct);
  /// Edges never trigger the fallback by proximity alone (only by crossing): false.
  static bool closer_than(const PairPoints&, double) { return false; }
};

}  // namespace flagsim

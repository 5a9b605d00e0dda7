// Self-collision of a cloth: vertex against triangle (paper §1), and edge against edge, without
// which two edges can pass through each other and leave a tangle the vertex-triangle responses
// then hold, stretching the cloth.
//
// One call of resolve() takes the step's start positions x0 (collision-free) and the integrator's
// end positions x and velocities v, and changes x and v so that
//   (1) no vertex crosses a triangle, and no edge crosses an edge, while everything moves
//       linearly from x0 to x, and
//   (2) no vertex ends closer than thickness / 2 to a triangle it does not belong to
//       (the response aims at the full thickness; / 2 is the guaranteed floor),
//   (3) with a pole, no vertex ends inside the pole.
// Pipeline:
//   broad phase (candidates.h): candidate pairs (vertex, triangle) and (edge, edge) from swept
//     boxes over the step, through box trees or a Verlet list of them;
//   narrow phase (contacts.h): vertex-triangle and edge-edge pairs, one type each with one
//     interface (corners, crossing, proximity, distance), so what follows is written once;
//   sweeps (<= params.iterations), each detecting on one state (in parallel), then answering in
//     pair order:
//     - a crossing of the trajectory x0 -> x (roots of the coplanarity cubic, Provot 1997,
//       Bridson et al. 2002) moves the pair's four points back along their paths to the time
//       they were still the thickness apart (vertex off the triangle's plane, or edge off edge):
//       an inelastic stop short of the hit that only undoes motion, so it cannot push anything
//       through a third layer;
//     - a proximity (closest points closer than the thickness) is pushed apart by the
//       mass-weighted projection of C = (sum_k g_k x_k) . n - thickness >= 0 (PBD, Mueller et
//       al. 2007; g = (1, -b) for a vertex and its triangle's barycentric point b, (1 - s, s,
//       -(1 - u), -u) for two edges' closest points): x_k moves by w_k g_k lambda n,
//       lambda = -C / sum_k g_k^2 w_k, w = inverse mass, no vertex further than |C|;
//     - the approaching normal relative velocity is removed by the impulse with the same weights,
//       and Coulomb friction (mu) takes up to mu |dv_n| of the tangential relative velocity;
//       impulses are averaged per vertex (Jacobi) so contacts sharing a vertex do not overshoot;
//     - the caller's constraints (the Simulation passes the cloth's strain limit) are projected
//       after a sweep that moved anything: contacts alone would hold a stretched cloth stretched;
//     - with a pole, its projection ends the sweep, and vertices resting on it count as
//       immovable for the pushes (contact mass scaling), so stacked layers do not fight it;
//     - a pair is skipped outright when its start-of-step distance exceeds the largest relative
//       displacement of its points plus the thickness (linear motion cannot close that gap);
//       that distance is bounded from below first, by the pair's distance in a snapshot of an
//       earlier step's positions less its points' largest relative displacement since, and
//       computed only where the bound leaves the answer open (the same answers);
//   fallback (impact_zones.h): a pair still crossing (vertex-triangle or edge-edge), a vertex
//     closer than thickness / 2 to a triangle, or a vertex in the pole, has its free vertices
//     sent back to x0 with their momentum-weighted mean velocity (an inelastic
//     impact zone in the sense of Provot 1997 / Bridson et al. 2002, with zero motion over the
//     step), with candidates recollected in the world frame, repeated until clean: x0 is clean,
//     so this terminates.
// Candidates are complete for any end state within `thickness` of the broad-phase boxes; a sweep
// that moves a vertex further triggers a new broad phase (at most kMaxRebuilds).
// Scratch is allocated at construction; a step allocates only if it needs more candidate pairs
// than any step before. Broad phase and detection run in OpenMP loops; corrections are applied
// sequentially in pair order, so results do not depend on the thread count.
#pragma once
#include <cstdint>
#include <functional>
#include <vector>

#include "collision/candidates.h"
#include "collision/contacts.h"
#include "collision/impact_zones.h"
#include "collision/params.h"
#include "common/types.h"

namespace flagsim {

struct SelfCollisionStats {
  Index candidates = 0;  ///< vertex-triangle and edge-edge pairs from the (last) broad phase
  Index contacts = 0;    ///< proximity responses applied
  Index crossings = 0;   ///< continuous-time crossings found and stopped short
  Index pole = 0;        ///< pole responses applied
  Index frozen = 0;      ///< vertices sent back to x0 by the fallback
  int sweeps = 0;        ///< response sweeps run
  int broad_phases = 0;  ///< broad phases run (1 unless a sweep moved a vertex out of its box)
  int tree_queries = 0;  ///< of those, how many queried the box trees (the rest filtered the list)
  /// Candidates' start-of-step distances computed exactly; the rest were bounded from below by
  /// the snapshot's, which decided their pairs (every candidate's on a new snapshot).
  Index exact_gaps = 0;
};

class SelfCollision {
 public:
  static constexpr int kMaxRebuilds = 3;

  /// triangles: T x 3 vertex indices into [0, num_vertices); params validated by the caller.
  SelfCollision(const MatX3i& triangles, Index num_vertices, const SelfCollisionParams& params);

  /// Other position constraints to keep in the same sweeps (e.g. the cloth's strain limit):
  /// called as (*constraints)(x, v) after each sweep's contact responses, before the pole.
  using Projector = std::function<void(MatX3& x, MatX3& v)>;

  /// One step's response (see above). x0, x, v: N x 3 (m, m, m/s); inv_mass: N (1/kg, 0 pinned);
  /// pole: the pole to keep vertices out of in the same sweeps, or nullptr; constraints: see
  /// Projector, or nullptr; pole_motion: a moving pole, nullptr at rest. The response then runs
  /// in its frame: x0 carried by pole_motion to the piece's end (the pole at pole_motion->to at
  /// both ends), velocities into it taken relative to its surface (collide_pole_carried).
  const SelfCollisionStats& resolve(const MatX3& x0, MatX3& x, MatX3& v, const VecX& inv_mass,
                                    const PoleParams* pole = nullptr,
                                    const Projector* constraints = nullptr,
                                    const RigidMotion* pole_motion = nullptr);

  const SelfCollisionStats& stats() const { return stats_; }
  const SelfCollisionParams& params() const { return params_; }
  /// (E x 2) the mesh's edges, each once, lower vertex index first.
  const MatX2i& edges() const { return candidates_.edges(); }

 private:
  void broad_phase(const MatX3& x0, const MatX3& x, const VecX& inv_mass, bool shifted);
  void measure_motion(const MatX3& x0, const MatX3& x);
  void carry_snapshot_gaps(const MatX3& x0, size_t exact);
  Index exact_gaps() const;
  template <class K>
  bool out_of_reach(const int32_t idx[4], Index k, const MatX3& x0, const MatX3& x, double need);
  bool find_violations(const MatX3& x0, const MatX3& x, const VecX& inv_mass,
                       const PoleParams* pole);
  // What a sweep's responses did: any response, a degenerate contact left to the fallback, a
  // crossing stopped or a proximity deeper than 1% of the thickness (worth another sweep).
  struct Responses {
    bool any = false, degenerate = false, changed = false;
  };
  void mark_on_pole(const PoleParams& pole, const MatX3& x);
  Index collide_with_pole(const PoleParams& pole, const MatX3& x0, MatX3& x, MatX3& v,
                          const VecX& inv_mass, double* max_move) const;
  void detect_contacts(const MatX3& x0, const MatX3& x, bool first);
  Responses respond(const MatX3& x0, MatX3& x, MatX3& v, const VecX& inv_mass);
  bool sweep(const MatX3& x0, MatX3& x, MatX3& v, const VecX& inv_mass, const PoleParams* pole,
             const Projector* constraints, bool first);
  void freeze_fallback(const MatX3& x0, MatX3& x, MatX3& v, const VecX& inv_mass,
                       const PoleParams* pole);
  bool weights(const int32_t idx[4], const Contact& c, const VecX& inv_mass, double w[4], double& W,
               double& limit) const;
  void project(const int32_t idx[4], const Contact& c, double C, MatX3& x,
               const VecX& inv_mass) const;
  void accumulate_impulse(const int32_t idx[4], const Contact& c, const MatX3& v,
                          const VecX& inv_mass);

  Index n_;
  SelfCollisionParams params_;
  Candidates candidates_;
  ImpactZones zones_;
  // Per candidate pair (vertex-triangle pairs, then edge-edge pairs, as candidates_.pairs()):
  std::vector<uint8_t> flag_;      // violation found by the parallel pass
  std::vector<double> start_gap_;  // distance at x0, m; NaN until out_of_reach needs it
  std::vector<double> snap_gap_;   // distance at snap_x_, m; NaN until out_of_reach needs it
  std::vector<Contact> contacts_;  // response in a sweep
  MatX3 x_sweep_;                  // N x 3 positions at the start of a sweep
  MatX3 dv_;                       // N x 3 summed velocity changes of a sweep
  std::vector<int> count_v_;       // per vertex: impulses in that sum
  std::vector<uint8_t> on_pole_;   // per vertex: resting on the pole in this sweep
  std::vector<uint8_t> moved_;     // per vertex: moved by the last sweep
  VecX motion_;                    // per vertex: displacement less the shift (measure_motion), m
  double motion_guard_ = 0;        // m, round-off guard of the bounds on motion_
  // The snapshot the start gaps are bounded from (carry_snapshot_gaps): positions of an earlier
  // broad phase's x0, the candidate pairs snap_gap_ was last carried to (in their order), and the
  // round-off guard of the snapshot's coordinates.
  MatX3 snap_x_;
  MatX3 drift_;  // N x 3: x0 - snap_x_ (m), unless the snapshot is x0
  CandidatePairs snap_pairs_;
  std::vector<double> snap_carry_;  // scratch of the carry
  double snap_guard_ = 0;
  bool snapshot_ = false;  // snap_x_ holds a snapshot
  bool snap_now_ = false;  // it was taken at the last broad phase's x0
  // The last sweep detected every candidate pair (the first of its broad phase) and found nothing
  // to do: no contact, no degenerate one, no pole push. Every candidate is then at least the
  // thickness apart along the whole step, so find_violations has no pair to flag at that x.
  bool quiet_ = false;
  SelfCollisionStats stats_;
  // resolve()'s pole_motion during the call (nullptr: the pole at rest, or none).
  const RigidMotion* pole_motion_ = nullptr;
};

}  // namespace flagsim

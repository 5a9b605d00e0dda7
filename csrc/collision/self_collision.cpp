#include "collision/self_collision.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "collision/pole.h"
#include "common/parallel.h"
#include "common/simd.h"

namespace flagsim {

namespace {

// The pair's four points in x.
inline void gather(const MatX3& x, const int32_t idx[4], PairPoints& p) {
  for (int k = 0; k < 4; ++k) p[k] = row(x, idx[k]);
}

// Pair loops whose pairs each write their own slot k share their pairs with the SideBySide helper
// (for_each_chunk) from this many pairs, in chunks of at least kPairsPerChunk: a chunk of 128
// pairs is ~10-25k instructions (start gaps, detection), far above taking it (an atomic add), and
// the paper flag's ~530 pairs make 4 chunks that a helper done with its air step can share.
constexpr Index kPairShareGrain = 256, kPairsPerChunk = 128, kMaxPairChunks = 32;

// body(K{}, pair, k) for every candidate pair k (vertex-triangle pairs, then edge-edge pairs,
// numbered on), K its contact type: one loop per type, so each body is compiled for its type.
// When `parallel` (each pair writes its own slot k, so the split does not matter): on the OpenMP
// team in static blocks when use_team(parallel), else in chunks of pairs that the SideBySide
// helper may share (for_each_chunk). Else in pair order on the calling thread.
template <class Body>
void for_each_pair(const CandidatePairs& pairs, bool parallel, const Body& body) {
  const std::vector<CandidatePair>& vt = pairs.vertex_triangle;
  const std::vector<CandidatePair>& ee = pairs.edge_edge;
  const auto V = static_cast<Index>(vt.size()), E = static_cast<Index>(ee.size());
  auto range = [&](Index k0, Index k1) {  // pairs [k0, k1) of the numbering above
    for (Index k = k0; k < std::min(k1, V); ++k) body(VertexTriangleContact{}, vt[size_t(k)], k);
    for (Index k = std::max(k0, V); k < k1; ++k) body(EdgeEdgeContact{}, ee[size_t(k - V)], k);
  };
#ifdef _OPENMP
  if (use_team(parallel && V + E >= kPairGrain)) {
#pragma omp parallel
    {
#pragma omp for schedule(static) nowait
      for (Index k = 0; k < V; ++k) body(VertexTriangleContact{}, vt[size_t(k)], k);
#pragma omp for schedule(static)
      for (Index k = 0; k < E; ++k) body(EdgeEdgeContact{}, ee[size_t(k)], V + k);
    }
    return;
  }
#endif
  const Index P = V + E;
  if (parallel && P >= kPairShareGrain) {
    const Index C = std::min(kMaxPairChunks, P / kPairsPerChunk);
    for_each_chunk(C, [&](Index c) { range(c * P / C, (c + 1) * P / C); });
    return;
  }
  range(0, P);
}

}  // namespace

SelfCollision::SelfCollision(const MatX3i& triangles, Index num_vertices,
                             const SelfCollisionParams& params)
    : n_(num_vertices),
      params_(params),
      candidates_(triangles, num_vertices, params.thickness),
      zones_(num_vertices),
      x_sweep_(num_vertices, 3),
      dv_(num_vertices, 3),
      count_v_(static_cast<size_t>(num_vertices), 0),
      on_pole_(static_cast<size_t>(num_vertices), 0),
      moved_(static_cast<size_t>(num_vertices), 0),
      motion_(num_vertices),
      snap_x_(num_vertices, 3),
      drift_(num_vertices, 3) {
  const size_t pairs = candidates_.reserved();
  flag_.reserve(pairs);
  contacts_.reserve(pairs);
  start_gap_.reserve(pairs);
  snap_gap_.reserve(pairs);
  snap_carry_.reserve(pairs);
  snap_pairs_.vertex_triangle.reserve(pairs);
  snap_pairs_.edge_edge.reserve(pairs);
}

namespace {

constexpr double kUnknown = std::numeric_limits<double>::quiet_NaN();

// A new snapshot is taken when more than 1 / kSnapshotStale of a broad phase's candidates needed
// their exact start gap: the cloth has moved too far from the old one for its bound to decide.
constexpr size_t kSnapshotStale = 8;

// A pair's place in the candidates' order (by first item, then by second) as one number.
inline uint64_t pair_key(const CandidatePair& p) {
  return uint64_t(uint32_t(p.a)) << 32 | uint32_t(p.b);
}

// out[k] = the value of `from` for pair k of `to` where from_pairs holds the same pair (both in
// the candidates' order), else kUnknown.
void carry(const std::vector<CandidatePair>& from_pairs, const double* from,
           const std::vector<CandidatePair>& to, double* out) {
  const size_t m = from_pairs.size();
  size_t j = 0;
  for (size_t k = 0; k < to.size(); ++k) {
    const uint64_t key = pair_key(to[k]);
    while (j < m && pair_key(from_pairs[j]) < key) ++j;
    out[k] = j < m && pair_key(from_pairs[j]) == key ? from[j] : kUnknown;
  }
}

// Whether a and b hold the same pairs in the same order.
bool same_pairs(const CandidatePairs& a, const CandidatePairs& b) {
  auto same = [](const std::vector<CandidatePair>& u, const std::vector<CandidatePair>& v) {
    return u.size() == v.size() &&
           (u.empty() || std::memcmp(u.data(), v.data(), u.size() * sizeof(CandidatePair)) == 0);
  };
  return same(a.vertex_triangle, b.vertex_triangle) && same(a.edge_edge, b.edge_edge);
}

}  // namespace

// Before a broad phase's candidates replace the last ones: whether to keep the snapshot (the last
// broad phase's start gaps were mostly bounded, not computed; the bound holds at any x0, so this
// only decides what the gaps cost), and, after them, each candidate's snapshot distance carried
// over from the last candidates where it was one of them.
void SelfCollision::carry_snapshot_gaps(const MatX3& x0, size_t exact) {
  const CandidatePairs& pairs = candidates_.pairs();
  // `exact`: the last broad phase's start gaps computed from its x0 (the rest were bounded);
  // after a snapshot at its own x0, it computed every gap it asked for.
  const bool stale = !snapshot_ || (!snap_now_ && kSnapshotStale * exact > start_gap_.size());
  snap_now_ = stale;
  if (stale) {
    snap_x_ = x0;
    snapshot_ = true;
    snap_guard_ = roundoff_guard(x0.size() ? x0.cwiseAbs().maxCoeff() : 0.0);
    snap_gap_.assign(pairs.size(), kUnknown);
    snap_pairs_ = pairs;  // within the reserved capacity: no allocation
  } else if (!same_pairs(snap_pairs_, pairs)) {
    snap_carry_.resize(pairs.size());
    carry(snap_pairs_.vertex_triangle, snap_gap_.data(), pairs.vertex_triangle, snap_carry_.data());
    carry(snap_pairs_.edge_edge, snap_gap_.data() + snap_pairs_.vertex_triangle.size(),
          pairs.edge_edge, snap_carry_.data() + pairs.vertex_triangle.size());
    snap_gap_.swap(snap_carry_);
    snap_pairs_ = pairs;
  }  // (the same pairs: nothing to carry or copy)
  // Each vertex's displacement since the snapshot, for the bounds (out_of_reach).
  if (!snap_now_) drift_ = x0 - snap_x_;
}

void SelfCollision::broad_phase(const MatX3& x0, const MatX3& x, const VecX& inv_mass,
                                bool shifted) {
  const Index exact = exact_gaps();                           // of the last broad phase
  if (stats_.broad_phases++ > 0) stats_.exact_gaps += exact;  // (a later one of this resolve)
  quiet_ = false;  // new candidates: no sweep has looked at them yet
  candidates_.collect(x0, x, inv_mass, shifted);
  stats_.tree_queries += !candidates_.from_list();
  const CandidatePairs& pairs = candidates_.pairs();
  carry_snapshot_gaps(x0, static_cast<size_t>(exact));
  flag_.resize(pairs.size());
  contacts_.resize(pairs.size());
  // Each pair's distance at the start of the step, computed (or bounded) by out_of_reach when a
  // pass first asks for it.
  start_gap_.assign(pairs.size(), kUnknown);
  stats_.candidates = static_cast<Index>(pairs.size());
}

// The start gaps out_of_reach computed since the last broad phase (the rest it bounded).
Index SelfCollision::exact_gaps() const {
  Index n = 0;
  for (const double g : start_gap_) n += !std::isnan(g);
  return n;
}

// motion_ = each vertex's displacement over the step less the broad phase's common one (any
// common vector would do: two points approach by at most the sum of theirs), and the round-off
// guard of the bounds built on it.
void SelfCollision::measure_motion(const MatX3& x0, const MatX3& x) {
  const Vec3& shift = candidates_.shift();
  double scale = 0;
  for (Index i = 0; i < n_; ++i) {
    motion_[i] = (row(x, i) - row(x0, i) - shift).norm();
    scale =
        std::max(scale, std::max(x.row(i).cwiseAbs().maxCoeff(), x0.row(i).cwiseAbs().maxCoeff()));
  }
  motion_guard_ = roundoff_guard(scale + shift.norm());
}

// Whether pair k (vertices idx) stays at least `need` apart over the whole step: start gap -
// reach >= need (the distance at any t in [0, 1] is at least start gap - t reach, everything
// moving linearly), with the reach computed only when the cheap bound above it (from the
// vertices' own motions, grown by the guard) leaves that open. The start gap itself is computed
// only when a lower bound of it leaves the answer open: the pair's distance in the snapshot less
// the largest relative displacement of its points since (reach() again: a point of one side
// moves relative to a point of the other by a convex combination of the corners' relative
// displacements), grown by both guards. The answer is always the one the exact start gap gives.
template <class K>
FLAGSIM_INLINE bool SelfCollision::out_of_reach(const int32_t idx[4], Index k, const MatX3& x0,
                                                const MatX3& x, double need) {
  const double bound = K::motion_bound(motion_.data(), idx) + motion_guard_;
  double gap = start_gap_[k];
  PairPoints p, d;
  if (std::isnan(gap)) {
    double& snap = snap_gap_[k];
    if (snap_now_) {  // the snapshot is x0
      gather(x0, idx, p);
      if (std::isnan(snap)) snap = K::distance(p);
      gap = start_gap_[k] = snap;
    } else {
      if (std::isnan(snap)) {
        PairPoints s;
        gather(snap_x_, idx, s);
        snap = K::distance(s);
      }
      gather(drift_, idx, d);
      const double lower = snap - K::reach(d) - (snap_guard_ + motion_guard_);
      if (lower - bound >= need) return true;
      gather(x0, idx, p);
      for (int j = 0; j < 4; ++j) d[j] = row(x, idx[j]) - p[j];
      const double step_reach = K::reach(d);
      if (lower - step_reach >= need) return true;
      gap = start_gap_[k] = K::distance(p);
      return gap - step_reach >= need;
    }
  }
  if (gap - bound >= need) return true;
  for (int j = 0; j < 4; ++j) d[j] = row(x, idx[j]) - row(x0, idx[j]);
  return gap - K::reach(d) >= need;
}

bool SelfCollision::weights(const int32_t idx[4], const Contact& c, const VecX& inv_mass,
                            double w[4], double& W, double& limit) const {
  // Vertices resting on the pole count as immovable (contact mass scaling): the layers on top
  // take the whole correction instead of pushing the bottom one back into the pole each sweep,
  // unless that leaves the constraint nearly immovable (only small-coefficient points free).
  double W_full = 0;
  W = 0;
  for (int k = 0; k < 4; ++k) {
    W_full += c.g[k] * c.g[k] * inv_mass[idx[k]];
    W += c.g[k] * c.g[k] * (w[k] = on_pole_[idx[k]] ? 0.0 : inv_mass[idx[k]]);
  }
  if (!(W_full > 0)) return false;
  if (W < 0.25 * W_full) {
    W = W_full;
    for (int k = 0; k < 4; ++k) w[k] = inv_mass[idx[k]];
  }
  // No vertex moves further than the constraint's own change (it never needs to when a point
  // with a large coefficient is free; when only a small-coefficient one is, the full answer
  // C / g_k would fling it, so the rest is left to later sweeps and the fallback).
  double largest = 0;
  for (int k = 0; k < 4; ++k) largest = std::max(largest, std::abs(w[k] * c.g[k]) / W);
  limit = largest > 1 ? 1 / largest : 1.0;
  return true;
}

void SelfCollision::project(const int32_t idx[4], const Contact& c, double C, MatX3& x,
                            const VecX& inv_mass) const {
  double w[4], W, limit;
  if (C >= 0 || !weights(idx, c, inv_mass, w, W, limit)) return;
  // PBD projection of C = (sum_k g_k x_k) . n - thickness onto C >= 0, mass-weighted.
  const double lambda = -C / W * limit;
  for (int k = 0; k < 4; ++k) x.row(idx[k]) += (lambda * w[k] * c.g[k]) * c.n.transpose();
}

void SelfCollision::accumulate_impulse(const int32_t idx[4], const Contact& c, const MatX3& v,
                                       const VecX& inv_mass) {
  double w[4], W, limit;
  if (!weights(idx, c, inv_mass, w, W, limit)) return;
  // Remove the approaching normal relative velocity, then Coulomb friction takes up to mu times
  // that change off the tangential relative velocity.
  Vec3 vrel = Vec3::Zero();
  for (int k = 0; k < 4; ++k) vrel += c.g[k] * v.row(idx[k]).transpose();
  const double vn = vrel.dot(c.n);
  if (vn >= 0) return;
  Vec3 dvrel = -vn * c.n;
  if (params_.friction > 0) {
    const Vec3 vt = vrel - vn * c.n;
    const double speed = vt.norm();
    if (speed > 0) dvrel -= std::min(params_.friction * (-vn), speed) / speed * vt;
  }
  for (int k = 0; k < 4; ++k) {
    const double s = limit * w[k] * c.g[k] / W;
    if (s == 0) continue;
    dv_.row(idx[k]) += s * dvrel.transpose();
    ++count_v_[idx[k]];
  }
}

// on_pole_: the vertices within half the thickness of the pole's surface (the sweeps end on the
// pole's projection, so these are the vertices it holds).
void SelfCollision::mark_on_pole(const PoleParams& pole, const MatX3& x) {
  const double h = params_.thickness;
  PoleParams grown = pole;
  grown.radius += 0.5 * h;
  grown.height += h;
  grown.base.y() -= 0.5 * h;
  for (Index i = 0; i < n_; ++i) on_pole_[i] = inside_moved_pole(grown, pole_motion_, row(x, i));
}

// The pole's projection at rest, or moving in its frame (resolve()'s pole_motion).
Index SelfCollision::collide_with_pole(const PoleParams& pole, const MatX3& x0, MatX3& x, MatX3& v,
                                       const VecX& inv_mass, double* max_move) const {
  if (pole_motion_) return collide_pole_carried(pole, *pole_motion_, x0, x, v, inv_mass, max_move);
  return collide_pole(pole, x0, x, v, inv_mass, max_move);
}

// contacts_ for every pair, in parallel on one state; after the first sweep only pairs with a
// vertex the last sweep moved can have changed.
void SelfCollision::detect_contacts(const MatX3& x0, const MatX3& x, bool first) {
  const double h = params_.thickness;
  const CandidatePairs& pairs = candidates_.pairs();
  measure_motion(x0, x);
  for_each_pair(pairs, true, [&](auto kind, const CandidatePair& pr, Index k) {
    using K = decltype(kind);
    contacts_[k].kind = Contact::kNone;
    int32_t i[4];
    K::corners(candidates_, pr, i);
    if (!first && !moved_[i[0]] && !moved_[i[1]] && !moved_[i[2]] && !moved_[i[3]]) return;
    if (out_of_reach<K>(i, k, x0, x, h)) return;  // never within the thickness
    PairPoints p0, p1;
    gather(x0, i, p0);
    gather(x, i, p1);
    K::detect(p0, p1, h, contacts_[k]);
  });
}

// The responses to contacts_, in pair order. A crossing moves the pair's four points back along
// their paths to the time they were still the thickness (or their starting distance) apart: an
// inelastic stop short of the hit, which only ever undoes motion, so it cannot push anything
// through a third layer (the freeze fallback is its limit, everything back at x0). A proximity is
// projected apart (Gauss-Seidel, C re-evaluated on the current positions along its detected
// normal and points). Velocities: Jacobi, every impulse from the sweep's starting velocities,
// averaged per vertex over the impulses that move it, so contacts sharing a vertex (a vertex over
// a shared edge, a triangle on two pinned bumps) neither add up nor bounce it.
SelfCollision::Responses SelfCollision::respond(const MatX3& x0, MatX3& x, MatX3& v,
                                                const VecX& inv_mass) {
  const double h = params_.thickness;
  Responses r;
  dv_.setZero();
  std::fill(count_v_.begin(), count_v_.end(), 0);
  for_each_pair(candidates_.pairs(), false, [&](auto kind, const CandidatePair& pr, Index k) {
    using K = decltype(kind);
    const Contact& ct = contacts_[k];
    if (ct.kind == Contact::kNone) return;
    if (ct.kind == Contact::kDegenerate) {
      r.degenerate = true;
      return;
    }
    r.any = true;
    int32_t idx[4];
    K::corners(candidates_, pr, idx);
    if (ct.kind == Contact::kCrossing) {
      PairPoints p0, p1;
      gather(x0, idx, p0);
      gather(x, idx, p1);
      double t;
      if (!K::crossing(p0, p1, t)) return;  // an earlier answer undid it
      const double back = K::separation(p0, p1, t, h);
      for (const int32_t i : idx)
        if (inv_mass[i] > 0) x.row(i) = x0.row(i) + back * (x.row(i) - x0.row(i));
      ++stats_.crossings;
      r.changed = true;
    } else {
      Vec3 gap = Vec3::Zero();
      for (int j = 0; j < 4; ++j) gap += ct.g[j] * row(x, idx[j]);
      project(idx, ct, gap.dot(ct.n) - h, x, inv_mass);
      ++stats_.contacts;
      r.changed = r.changed || ct.C < -1e-2 * h;
    }
    accumulate_impulse(idx, ct, v, inv_mass);
  });
  for (Index i = 0; i < n_; ++i)
    if (count_v_[i]) v.row(i) += dv_.row(i) / count_v_[i];
  return r;
}

bool SelfCollision::sweep(const MatX3& x0, MatX3& x, MatX3& v, const VecX& inv_mass,
                          const PoleParams* pole, const Projector* constraints, bool first) {
  const double h = params_.thickness;
  x_sweep_ = x;  // to see, at the end, which vertices this sweep moved
  if (pole) mark_on_pole(*pole, x);
  detect_contacts(x0, x, first);
  const Responses r = respond(x0, x, v, inv_mass);
  bool changed = r.changed;
  // The caller's constraints next, when the responses moved anything (contacts alone would hold
  // a stretched cloth stretched).
  if (constraints && r.any) (*constraints)(x, v);
  // The pole last: no sweep leaves a vertex inside it.
  Index pushed = 0;
  if (pole) {
    double largest = 0;
    pushed = collide_with_pole(*pole, x0, x, v, inv_mass, &largest);
    stats_.pole += pushed;
    changed = changed || largest > 1e-2 * h;
  }
  quiet_ = first && !r.any && !r.degenerate && pushed == 0;
  for (Index i = 0; i < n_; ++i) moved_[i] = x.row(i) != x_sweep_.row(i);
  return changed;
}

// Flags (flag_) every pair that still crosses over the step, or whose vertex ends closer than
// thickness / 2 to its triangle, unless none of its vertices can move; true when a pair is
// flagged or a vertex that can move is inside the pole.
bool SelfCollision::find_violations(const MatX3& x0, const MatX3& x, const VecX& inv_mass,
                                    const PoleParams* pole) {
  const double floor = 0.5 * params_.thickness;
  const CandidatePairs& pairs = candidates_.pairs();
  if (quiet_) {  // the last sweep saw every pair at this x and found none within the thickness
    std::fill(flag_.begin(), flag_.end(), uint8_t{0});
  } else {
    measure_motion(x0, x);
    for_each_pair(pairs, true, [&](auto kind, const CandidatePair& pr, Index k) {
      using K = decltype(kind);
      int32_t i[4];
      K::corners(candidates_, pr, i);
      flag_[k] = 0;
      auto still = [&](int j) { return zones_.still(i[j], inv_mass); };
      if (still(0) && still(1) && still(2) && still(3)) return;  // nothing to undo
      if (out_of_reach<K>(i, k, x0, x, floor)) return;           // cannot have crossed or closed in
      PairPoints p0, p1;
      gather(x0, i, p0);
      gather(x, i, p1);
      double t;
      flag_[k] = K::crossing(p0, p1, t) || K::closer_than(p1, floor);
    });
  }
  const bool any = std::find(flag_.begin(), flag_.end(), uint8_t{1}) != flag_.end();
  return any || (pole && zones_.any_in_pole(*pole, x, inv_mass, pole_motion_));
}

void SelfCollision::freeze_fallback(const MatX3& x0, MatX3& x, MatX3& v, const VecX& inv_mass,
                                    const PoleParams* pole) {
  zones_.clear();
  if (!find_violations(x0, x, inv_mass, pole)) return;
  // Frozen vertices stay at x0 in the world frame, so collect candidates there (no shift): every
  // state the loop can reach lies within these boxes.
  broad_phase(x0, x, inv_mass, /*shifted=*/false);
  for (Index round = 0; round <= n_ && find_violations(x0, x, inv_mass, pole); ++round) {
    for_each_pair(candidates_.pairs(), false, [&](auto kind, const CandidatePair& pr, Index k) {
      using K = decltype(kind);
      if (!flag_[k]) return;
      int32_t group[4];
      K::corners(candidates_, pr, group);
      stats_.frozen += zones_.freeze(group, x0, x, v, inv_mass);
    });
    if (pole) stats_.frozen += zones_.freeze_in_pole(*pole, x0, x, v, inv_mass, pole_motion_);
  }
}

const SelfCollisionStats& SelfCollision::resolve(const MatX3& x0, MatX3& x, MatX3& v,
                                                 const VecX& inv_mass, const PoleParams* pole,
                                                 const Projector* constraints,
                                                 const RigidMotion* pole_motion) {
  stats_ = SelfCollisionStats{};
  pole_motion_ = pole ? pole_motion : nullptr;
  if (pole) stats_.pole += collide_with_pole(*pole, x0, x, v, inv_mass, nullptr);  // start outside
  bool complete = false;  // candidates cover every pair that can violate at the current x
  for (int attempt = 0; attempt <= kMaxRebuilds && !complete; ++attempt) {
    broad_phase(x0, x, inv_mass, /*shifted=*/true);
    for (int s = 0; s < params_.iterations; ++s) {
      ++stats_.sweeps;
      if (!sweep(x0, x, v, inv_mass, pole, constraints, s == 0)) break;
    }
    // Else a push left the candidates' reach: collect again.
    complete = candidates_.within_boxes(x);
  }
  if (!complete) broad_phase(x0, x, inv_mass, /*shifted=*/true);
  freeze_fallback(x0, x, v, inv_mass, pole);
  stats_.exact_gaps += exact_gaps();
  pole_motion_ = nullptr;  // the caller's, valid for this call only
  return stats_;
}

}  // namespace flagsim

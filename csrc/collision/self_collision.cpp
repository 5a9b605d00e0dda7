#include "collision/self_collision.h"

#include <algorithm>
#include <atomic>
#include <cmath>

#include "collision/edge_edge.h"
#include "collision/pole.h"
#include "collision/vertex_triangle.h"
#include "common/parallel.h"
#include "common/simd.h"
#ifdef _OPENMP
#include <omp.h>
#endif

namespace flagsim {

namespace {

int max_threads() {
#ifdef _OPENMP
  return omp_get_max_threads();
#else
  return 1;
#endif
}

int thread_id() {
#ifdef _OPENMP
  return omp_get_thread_num();
#else
  return 0;
#endif
}

int team_size() {
#ifdef _OPENMP
  return omp_get_num_threads();
#else
  return 1;
#endif
}

inline Vec3 row(const MatX3& m, Index i) { return m.row(i).transpose(); }

// The margin by which a cheap test on coordinates of magnitude up to `size` (m) must clear its
// bound so that round-off (~1e-16 of the size) never decides: far above it, far below any gap.
inline double roundoff_guard(double size) { return 1e-12 * (1 + size); }

// A pair with no free vertex (all four inverse masses 0) is never a candidate: nothing to move.
inline bool none_free(const VecX& inv_mass, int32_t a, int32_t b, int32_t c, int32_t d) {
  return inv_mass[a] == 0 && inv_mass[b] == 0 && inv_mass[c] == 0 && inv_mass[d] == 0;
}

// Pair loops parallelise above this many pairs: a pair costs about a vertex update, and waking a
// thread team on a loaded machine costs far more than a few thousand of them.
constexpr Index kPairGrain = 4 * kParallelGrain;

// Each edge of the mesh once, (lower, higher) vertex index, sorted.
MatX2i mesh_edges(const MatX3i& tris) {
  std::vector<std::pair<int32_t, int32_t>> e;
  e.reserve(3 * static_cast<size_t>(tris.rows()));
  for (Index t = 0; t < tris.rows(); ++t)
    for (int k = 0; k < 3; ++k) {
      const int32_t a = tris(t, k), b = tris(t, (k + 1) % 3);
      e.emplace_back(std::min(a, b), std::max(a, b));
    }
  std::sort(e.begin(), e.end());
  e.erase(std::unique(e.begin(), e.end()), e.end());
  MatX2i out(static_cast<Index>(e.size()), 2);
  for (size_t i = 0; i < e.size(); ++i) out.row(static_cast<Index>(i)) << e[i].first, e[i].second;
  return out;
}

// Concatenate per-thread buffers (in thread order) onto out.
template <class T>
void append(const std::vector<std::vector<T>>& buffers, std::vector<T>& out) {
  for (const auto& b : buffers) out.insert(out.end(), b.begin(), b.end());
}

}  // namespace

SelfCollision::SelfCollision(const MatX3i& triangles, Index num_vertices,
                             const SelfCollisionParams& params)
    : tris_(triangles),
      edges_(mesh_edges(triangles)),
      n_(num_vertices),
      params_(params),
      zones_(num_vertices),
      vlo_(num_vertices, 3),
      vhi_(num_vertices, 3),
      tlo_(triangles.rows(), 3),
      thi_(triangles.rows(), 3),
      elo_(edges_.rows(), 3),
      ehi_(edges_.rows(), 3),
      ref_lo_(num_vertices, 3),
      ref_hi_(num_vertices, 3),
      x_sweep_(num_vertices, 3),
      dv_(num_vertices, 3),
      count_v_(static_cast<size_t>(num_vertices), 0),
      on_pole_(static_cast<size_t>(num_vertices), 0),
      moved_(static_cast<size_t>(num_vertices), 0),
      motion_(num_vertices) {
  const size_t threads = static_cast<size_t>(max_threads());
  thread_pairs_.resize(threads);
  thread_edge_pairs_.resize(threads);
  const size_t expected = 8 * static_cast<size_t>(num_vertices) + 64;
  const size_t expected_edges = 8 * static_cast<size_t>(edges_.rows()) + 64;
  // Thread 0 collects every pair when the broad phase runs on one thread.
  for (auto& buffer : thread_pairs_) buffer.reserve(expected);
  for (auto& buffer : thread_edge_pairs_) buffer.reserve(expected_edges);
  pairs_.reserve(expected + expected_edges);
  list_.reserve(expected + expected_edges);  // a list that pays is at most 1.5x the candidates
  flag_.reserve(expected + expected_edges);
  contacts_.reserve(expected + expected_edges);
  start_gap_.reserve(expected + expected_edges);
}

FLAGSIM_INLINE void SelfCollision::corners(const Pair& pr, int32_t idx[4]) const {
  if (pr.edge_pair) {
    idx[0] = edges_(pr.a, 0), idx[1] = edges_(pr.a, 1);
    idx[2] = edges_(pr.b, 0), idx[3] = edges_(pr.b, 1);
  } else {
    idx[0] = pr.a, idx[1] = tris_(pr.b, 0), idx[2] = tris_(pr.b, 1), idx[3] = tris_(pr.b, 2);
  }
}

// Whether the list still holds every pair the trees could give now: each vertex box, less the
// mean start position, within skin_ of its box when the list was built (a common translation
// cannot bring two boxes together). Then a vertex box, and with it every triangle or edge box,
// has grown by at most skin_ on each side, and the list was collected 2 skin_ wider.
bool SelfCollision::list_covers(const Vec3& centre) const {
  if (!list_valid_) return false;
  const double s = skin_ - roundoff_guard(centre.cwiseAbs().maxCoeff() + ref_scale_);
  for (Index i = 0; i < n_; ++i)
    for (int d = 0; d < 3; ++d)
      if (vlo_(i, d) - centre[d] < ref_lo_(i, d) - s || vhi_(i, d) - centre[d] > ref_hi_(i, d) + s)
        return false;
  return true;
}

// The skin of the next list, and the reference boxes it is measured from. The skin is
// kSkinSteps times the step's largest relative motion (the largest vertex box), at least the
// thickness and at most 4 times it, twice the query's own reach (a sheet's list grows as the
// square of its width).
// A list pays only while it is about as short as its candidates and serves several broad
// phases: that is a cloth whose close pairs are its mesh neighbours, thickness well below the
// spacing, as in the paper's flag. One that came out longer than kListRatio times its
// candidates, or served one broad phase only, missed: the next kDirectBuilds queries go straight
// to the candidates, twice as many after each further miss up to kMaxDirectBuilds. The first
// queries are direct too (a cloth let go moves fastest). Deterministic, and it decides only
// which pairs get tested, never which are candidates.
double SelfCollision::next_skin(const Vec3& centre) {
  if (skin_ > 0) {
    if (served_ <= 1)
      miss();
    else
      direct_streak_ = kDirectBuilds;
  }
  served_ = 1;
  if (direct_left_ > 0) {
    --direct_left_;
    skin_ = 0;
    list_valid_ = false;
    return skin_;
  }
  double motion = 0, size = 0;
  for (Index i = 0; i < n_; ++i) {
    motion = std::max(motion, (vhi_.row(i) - vlo_.row(i)).maxCoeff());
    size = std::max(size,
                    std::max(vlo_.row(i).cwiseAbs().maxCoeff(), vhi_.row(i).cwiseAbs().maxCoeff()));
  }
  const double h = params_.thickness;
  skin_ = std::min(std::max(kSkinSteps * motion, h), 4 * h);
  list_valid_ = true;
  ref_scale_ = size;
  ref_lo_ = vlo_.rowwise() - centre.transpose();
  ref_hi_ = vhi_.rowwise() - centre.transpose();
  return skin_;
}

void SelfCollision::miss() {
  direct_left_ = direct_streak_;
  direct_streak_ = std::min(2 * direct_streak_, kMaxDirectBuilds);
}

// A list longer than kListRatio times the last candidates does not pay (see next_skin).
size_t SelfCollision::list_budget() const {
  return static_cast<size_t>(kListRatio * double(last_candidates_)) + 64;
}

// Box-tree queries (the trees refitted to the current boxes), every query `wide` wider, into out:
// vertex-triangle pairs by vertex, then edge-edge pairs by edge, each group by its second item.
// With inv_mass, pairs with no free vertex are left out. Returns false, with out incomplete, as
// soon as out would hold more than `budget` pairs (each thread stops at its share).
bool SelfCollision::query_trees(double wide, const VecX* inv_mass, std::vector<Pair>& out,
                                size_t budget) {
  const double h = params_.thickness, reach = 2 * params_.thickness;
  // The trees take their shape from the first query's boxes and are refitted after that.
  if (tri_tree_.built()) {
    tri_tree_.refit(tlo_, thi_);
    edge_tree_.refit(elo_, ehi_);
  } else {
    tri_tree_.build(tlo_, thi_);
    edge_tree_.build(elo_, ehi_);
  }
  const size_t threads = static_cast<size_t>(max_threads());
  if (thread_pairs_.size() < threads) {
    thread_pairs_.resize(threads);
    thread_edge_pairs_.resize(threads);
  }
  for (auto& buffer : thread_pairs_) buffer.clear();
  for (auto& buffer : thread_edge_pairs_) buffer.clear();
  auto by_b = [](const Pair& p, const Pair& q) { return p.b < q.b; };
  auto collect_vertex = [&](Index i, std::vector<Pair>& buffer) {
    const Vec3 qlo = vlo_.row(i).transpose().array() - (reach + wide);
    const Vec3 qhi = vhi_.row(i).transpose().array() + (reach + wide);
    const size_t begin = buffer.size();
    const auto vi = static_cast<int32_t>(i);
    tri_tree_.query(tlo_, thi_, qlo, qhi, [&](int32_t t) {
      const int32_t a = tris_(t, 0), b = tris_(t, 1), c = tris_(t, 2);
      if (a == vi || b == vi || c == vi) return;  // never against its own triangles
      if (inv_mass && none_free(*inv_mass, vi, a, b, c)) return;
      buffer.push_back({vi, t, false});
    });
    std::sort(buffer.begin() + static_cast<std::ptrdiff_t>(begin), buffer.end(), by_b);
  };
  auto collect_edge = [&](Index e, std::vector<Pair>& buffer) {
    const Vec3 qlo = elo_.row(e).transpose().array() - (h + wide);
    const Vec3 qhi = ehi_.row(e).transpose().array() + (h + wide);
    const size_t begin = buffer.size();
    const int32_t a = edges_(e, 0), b = edges_(e, 1);
    edge_tree_.query(
        elo_, ehi_, qlo, qhi,
        [&](int32_t f) {  // f > e: each pair once
          const int32_t c = edges_(f, 0), d = edges_(f, 1);
          if (a == c || a == d || b == c || b == d) return;  // edges sharing a vertex never cross
          if (inv_mass && none_free(*inv_mass, a, b, c, d)) return;
          buffer.push_back({static_cast<int32_t>(e), f, true});
        },
        static_cast<int32_t>(e));
    std::sort(buffer.begin() + static_cast<std::ptrdiff_t>(begin), buffer.end(), by_b);
  };
  const Index E = edges_.rows();
  bool within = true;
  if (use_team(n_ >= kParallelGrain)) {
    std::atomic<bool> over{false};
#pragma omp parallel
    {
      const size_t id = static_cast<size_t>(thread_id());
      const size_t share = budget / static_cast<size_t>(team_size()) + 1;
      std::vector<Pair>& pv = thread_pairs_[id];
      std::vector<Pair>& pe = thread_edge_pairs_[id];
      auto full = [&] {
        if (pv.size() + pe.size() > share) over.store(true, std::memory_order_relaxed);
        return over.load(std::memory_order_relaxed);
      };
      // Static schedule: thread k gets the k-th contiguous block, so concatenating the buffers
      // in thread order lists pairs by vertex (edge) whatever the thread count.
#pragma omp for schedule(static)
      for (Index i = 0; i < n_; ++i)
        if (!full()) collect_vertex(i, pv);
#pragma omp for schedule(static)
      for (Index e = 0; e < E; ++e)
        if (!full()) collect_edge(e, pe);
    }
    within = !over.load();
  } else {
    std::vector<Pair>& pv = thread_pairs_[0];
    std::vector<Pair>& pe = thread_edge_pairs_[0];
    for (Index i = 0; i < n_ && within; ++i) {
      collect_vertex(i, pv);
      within = pv.size() <= budget;
    }
    for (Index e = 0; e < E && within; ++e) {
      collect_edge(e, pe);
      within = pv.size() + pe.size() <= budget;
    }
  }
  out.clear();
  append(thread_pairs_, out);
  append(thread_edge_pairs_, out);
  return within;
}

// pairs_ = the list's pairs the trees would give now: a free vertex, and boxes that overlap by the
// trees' own test on the same numbers (so the same pairs, in the list's order, which is theirs).
void SelfCollision::filter_list(const VecX& inv_mass) {
  const double h = params_.thickness, reach = 2 * params_.thickness;
  auto keep = [&](const Pair& p) {
    int32_t i[4];
    corners(p, i);
    if (none_free(inv_mass, i[0], i[1], i[2], i[3])) return false;
    const double r = p.edge_pair ? h : reach;
    const double* q0 = (p.edge_pair ? elo_ : vlo_).data() + 3 * Index(p.a);
    const double* q1 = (p.edge_pair ? ehi_ : vhi_).data() + 3 * Index(p.a);
    const double* l = (p.edge_pair ? elo_ : tlo_).data() + 3 * Index(p.b);
    const double* u = (p.edge_pair ? ehi_ : thi_).data() + 3 * Index(p.b);
    return l[0] <= q1[0] + r && u[0] >= q0[0] - r && l[1] <= q1[1] + r && u[1] >= q0[1] - r &&
           l[2] <= q1[2] + r && u[2] >= q0[2] - r;
  };
  const auto L = static_cast<Index>(list_.size());
  pairs_.clear();
  if (use_team(L >= kPairGrain)) {
    for (auto& buffer : thread_pairs_) buffer.clear();
#pragma omp parallel
    {
      std::vector<Pair>& buffer = thread_pairs_[static_cast<size_t>(thread_id())];
#pragma omp for schedule(static)
      for (Index k = 0; k < L; ++k)
        if (keep(list_[size_t(k)])) buffer.push_back(list_[size_t(k)]);
    }
    append(thread_pairs_, pairs_);  // static blocks in thread order: the list's order
  } else {
    for (const Pair& p : list_)
      if (keep(p)) pairs_.push_back(p);
  }
  // Too long to pay (see next_skin) at its first use; long later (it came from a fast
  // transient and the motion has calmed): build it again.
  const double ratio = served_ == 1 ? kListRatio : 4;
  if (double(list_.size()) > ratio * double(pairs_.size()) + 64) list_valid_ = false;
}

void SelfCollision::broad_phase(const MatX3& x0, const MatX3& x, const VecX& inv_mass,
                                bool shifted) {
  const double margin = params_.thickness;
  ++stats_.broad_phases;
  quiet_ = false;  // new candidates: no sweep has looked at them yet
  shift_.setZero();
  if (shifted) {
    for (Index i = 0; i < n_; ++i) shift_ += row(x, i) - row(x0, i);
    shift_ /= static_cast<double>(std::max<Index>(n_, 1));
  }
  Vec3 centre = Vec3::Zero();
  for (Index i = 0; i < n_; ++i) {
    const Vec3 a = row(x0, i), b = row(x, i) - shift_;
    vlo_.row(i) = a.cwiseMin(b).transpose();
    vhi_.row(i) = a.cwiseMax(b).transpose();
    centre += a;
  }
  centre /= static_cast<double>(std::max<Index>(n_, 1));
  const Index T = tris_.rows(), E = edges_.rows();
  for (Index t = 0; t < T; ++t) {
    const int32_t a = tris_(t, 0), b = tris_(t, 1), c = tris_(t, 2);
    tlo_.row(t) = vlo_.row(a).cwiseMin(vlo_.row(b)).cwiseMin(vlo_.row(c)).array() - margin;
    thi_.row(t) = vhi_.row(a).cwiseMax(vhi_.row(b)).cwiseMax(vhi_.row(c)).array() + margin;
  }
  for (Index e = 0; e < E; ++e) {
    const int32_t a = edges_(e, 0), b = edges_(e, 1);
    elo_.row(e) = vlo_.row(a).cwiseMin(vlo_.row(b)).array() - margin;
    ehi_.row(e) = vhi_.row(a).cwiseMax(vhi_.row(b)).array() + margin;
  }
  // The candidates: from the pair list while it covers the motion, else from the trees.
  const bool listed = list_covers(centre);
  stats_.tree_queries += !listed;
  if (listed) {
    ++served_;
    filter_list(inv_mass);
  } else if (const double skin = next_skin(centre);
             skin > 0 && query_trees(2 * skin, nullptr, list_, list_budget())) {
    filter_list(inv_mass);
  } else {
    if (skin_ > 0) {  // the list outgrew its budget before it was complete: a miss
      list_valid_ = false;
      skin_ = 0;
      miss();
    }
    query_trees(0, &inv_mass, pairs_);
  }
  flag_.resize(pairs_.size());
  contacts_.resize(pairs_.size());
  start_gap_.resize(pairs_.size());
  stats_.candidates = last_candidates_ = static_cast<Index>(pairs_.size());
  // Each pair's distance at the start of the step: with it, a pair whose points cannot have
  // closed that gap (see out_of_reach) needs no test at all.
  const auto P = static_cast<Index>(pairs_.size());
  parallel_for_if(P >= kPairGrain, P,
                  [&](Index k) { start_gap_[k] = start_distance(pairs_[k], x0); });
}

// The distance between the pair's two sides at x0.
double SelfCollision::start_distance(const Pair& pr, const MatX3& x0) const {
  int32_t i[4];
  corners(pr, i);
  const Vec3 p = row(x0, i[0]), a = row(x0, i[1]), b = row(x0, i[2]), c = row(x0, i[3]);
  if (pr.edge_pair) {
    const Vec2 su = closest_segment_parameters(p, a, b, c);
    return ((p + su[0] * (a - p)) - (b + su[1] * (c - b))).norm();
  }
  bool interior;
  const Vec3 w = closest_point_barycentric(p, a, b, c, interior);
  return (p - (w[0] * a + w[1] * b + w[2] * c)).norm();
}

// motion_ = each vertex's displacement over the step less the broad phase's common one (any
// common vector would do: two points approach by at most the sum of theirs), and the round-off
// guard of the bounds built on it.
void SelfCollision::measure_motion(const MatX3& x0, const MatX3& x) {
  double scale = 0;
  for (Index i = 0; i < n_; ++i) {
    motion_[i] = (row(x, i) - row(x0, i) - shift_).norm();
    scale =
        std::max(scale, std::max(x.row(i).cwiseAbs().maxCoeff(), x0.row(i).cwiseAbs().maxCoeff()));
  }
  motion_guard_ = roundoff_guard(scale + shift_.norm());
}

// Whether pair k's sides stay at least `need` apart over the whole step: start gap - reach >=
// need, with reach() computed only when the cheap bound above it (the sum of two motions, grown
// by the guard) leaves that open, so the answer is always the exact one.
bool SelfCollision::out_of_reach(Index k, const MatX3& x0, const MatX3& x, double need) const {
  const Pair& pr = pairs_[k];
  int32_t i[4];
  corners(pr, i);
  const double* m = motion_.data();
  const double bound = (pr.edge_pair ? std::max(m[i[0]], m[i[1]]) + std::max(m[i[2]], m[i[3]])
                                     : m[i[0]] + std::max({m[i[1]], m[i[2]], m[i[3]]})) +
                       motion_guard_;
  return start_gap_[k] - bound >= need || start_gap_[k] - reach(pr, x0, x) >= need;
}

// How far the pair's two sides can have approached over the step: the largest displacement of a
// point of one side relative to a point of the other (convex combinations of the corners, so the
// largest over corner pairs). The distance at any time t in [0, 1] is at least start gap - t *
// that (everything moves linearly).
double SelfCollision::reach(const Pair& pr, const MatX3& x0, const MatX3& x) const {
  int32_t i[4];
  corners(pr, i);
  Vec3 d[4];
  for (int k = 0; k < 4; ++k) d[k] = row(x, i[k]) - row(x0, i[k]);
  double r2 = 0;
  if (pr.edge_pair) {
    for (int a = 0; a < 2; ++a)
      for (int b = 2; b < 4; ++b) r2 = std::max(r2, (d[a] - d[b]).squaredNorm());
  } else {
    for (int b = 1; b < 4; ++b) r2 = std::max(r2, (d[0] - d[b]).squaredNorm());
  }
  return std::sqrt(r2);
}

bool SelfCollision::within_boxes(const MatX3& x) const {
  const double margin = params_.thickness;
  for (Index i = 0; i < n_; ++i) {
    const Vec3 p = row(x, i) - shift_;
    if ((p.array() < vlo_.row(i).transpose().array() - margin).any() ||
        (p.array() > vhi_.row(i).transpose().array() + margin).any())
      return false;
  }
  return true;
}

bool SelfCollision::crossing(const Pair& pr, const MatX3& x0, const MatX3& x, double& t) const {
  int32_t i[4];
  corners(pr, i);
  if (pr.edge_pair) {
    Vec2 su;
    return edge_edge_ccd(row(x0, i[0]), row(x0, i[1]), row(x0, i[2]), row(x0, i[3]), row(x, i[0]),
                         row(x, i[1]), row(x, i[2]), row(x, i[3]), t, su);
  }
  Vec3 bary;
  return vertex_triangle_ccd(row(x0, i[0]), row(x0, i[1]), row(x0, i[2]), row(x0, i[3]),
                             row(x, i[0]), row(x, i[1]), row(x, i[2]), row(x, i[3]), t, bary);
}

double SelfCollision::separation(const Pair& pr, const MatX3& x0, const MatX3& x, double t) const {
  int32_t i[4];
  corners(pr, i);
  const double h = params_.thickness;
  return pr.edge_pair
             ? edge_separation_time(row(x0, i[0]), row(x0, i[1]), row(x0, i[2]), row(x0, i[3]),
                                    row(x, i[0]), row(x, i[1]), row(x, i[2]), row(x, i[3]), t, h)
             : separation_time(row(x0, i[0]), row(x0, i[1]), row(x0, i[2]), row(x0, i[3]),
                               row(x, i[0]), row(x, i[1]), row(x, i[2]), row(x, i[3]), t, h);
}

// A crossing of the step's trajectory x0 -> x, with the hit's points (g) and the normal at the
// hit time towards the side the pair started on (Bridson et al. 2002 §7.3, for the impulse);
// otherwise a proximity at x closer than the thickness, along the closest-points direction.
void SelfCollision::detect(const Pair& pr, const MatX3& x0, const MatX3& x, Contact& ct) const {
  const double h = params_.thickness;
  int32_t i[4];
  corners(pr, i);
  ct.kind = Contact::kNone;
  const Vec3 p0 = row(x0, i[0]), a0 = row(x0, i[1]), b0 = row(x0, i[2]), c0 = row(x0, i[3]);
  const Vec3 p1 = row(x, i[0]), a1 = row(x, i[1]), b1 = row(x, i[2]), c1 = row(x, i[3]);
  double t;
  if (pr.edge_pair) {
    // Edges p0a0 -> p1a1 (points 0, 1) and b0c0 -> b1c1 (points 2, 3).
    Vec2 su;
    if (edge_edge_ccd(p0, a0, b0, c0, p1, a1, b1, c1, t, su)) {
      const Vec3 n =
          ((1 - t) * (a0 - p0) + t * (a1 - p1)).cross((1 - t) * (c0 - b0) + t * (c1 - b1));
      const double len = n.norm();
      if (!(len > 0)) {
        ct.kind = Contact::kDegenerate;
        return;
      }
      const Vec3 gap0 = (p0 + su[0] * (a0 - p0)) - (b0 + su[1] * (c0 - b0));
      ct.n = gap0.dot(n) >= 0 ? Vec3(n / len) : Vec3(-n / len);
      ct.g[0] = 1 - su[0], ct.g[1] = su[0], ct.g[2] = -(1 - su[1]), ct.g[3] = -su[1];
      ct.kind = Contact::kCrossing;
      return;
    }
    const Vec3 mp = 0.5 * (p1 + a1), mq = 0.5 * (b1 + c1);
    if ((mp - mq).norm() > 0.5 * ((a1 - p1).norm() + (c1 - b1).norm()) + h) return;
    const Vec2 su2 = closest_segment_parameters(p1, a1, b1, c1);
    const Vec3 r = (p1 + su2[0] * (a1 - p1)) - (b1 + su2[1] * (c1 - b1));
    const double d = r.norm();
    if (d >= h || !(d > 1e-9 * h)) return;  // touching exactly: left to the crossing test
    ct.n = r / d;
    ct.g[0] = 1 - su2[0], ct.g[1] = su2[0], ct.g[2] = -(1 - su2[1]), ct.g[3] = -su2[1];
    ct.C = d - h;
    ct.kind = Contact::kProximity;
    return;
  }
  Vec3 bary;
  if (vertex_triangle_ccd(p0, a0, b0, c0, p1, a1, b1, c1, t, bary)) {
    const Vec3 n = ((1 - t) * (b0 - a0) + t * (b1 - a1)).cross((1 - t) * (c0 - a0) + t * (c1 - a1));
    const double len = n.norm();
    if (!(len > 0)) {  // a degenerate triangle: left to the fallback
      ct.kind = Contact::kDegenerate;
      return;
    }
    const double f0 = (b0 - a0).cross(c0 - a0).dot(p0 - a0);
    const double f1 = (b1 - a1).cross(c1 - a1).dot(p1 - a1);
    ct.n = (f0 > 0 || (f0 == 0 && f1 >= 0)) ? Vec3(n / len) : Vec3(-n / len);
    ct.g[0] = 1, ct.g[1] = -bary[0], ct.g[2] = -bary[1], ct.g[3] = -bary[2];
    ct.kind = Contact::kCrossing;
    return;
  }
  if (beyond_reach(p1, a1, b1, c1, h)) return;
  bool interior;
  bary = closest_point_barycentric(p1, a1, b1, c1, interior);
  const Vec3 r = p1 - (bary[0] * a1 + bary[1] * b1 + bary[2] * c1);
  const double d = r.norm();
  if (d >= h) return;
  if (d > 1e-9 * h) {
    ct.n = r / d;
  } else {  // on the triangle: its normal, towards the side the vertex started on
    const Vec3 n = (b1 - a1).cross(c1 - a1);
    if (!(n.norm() > 0)) {
      ct.kind = Contact::kDegenerate;
      return;
    }
    const double f0 = (b0 - a0).cross(c0 - a0).dot(p0 - a0);
    ct.n = f0 < 0 ? Vec3(-n.normalized()) : Vec3(n.normalized());
  }
  ct.g[0] = 1, ct.g[1] = -bary[0], ct.g[2] = -bary[1], ct.g[3] = -bary[2];
  ct.C = d - h;
  ct.kind = Contact::kProximity;
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

bool SelfCollision::sweep(const MatX3& x0, MatX3& x, MatX3& v, const VecX& inv_mass,
                          const PoleParams* pole, const Projector* constraints, bool first) {
  const double h = params_.thickness;
  bool changed = false;
  x_sweep_ = x;  // to see, at the end, which vertices this sweep moved
  if (pole) {
    // On the pole: within half the thickness of its surface (the sweeps end on the pole's
    // projection, so these are the vertices it holds).
    PoleParams grown = *pole;
    grown.radius += 0.5 * h;
    grown.height += h;
    grown.base.y() -= 0.5 * h;
    for (Index i = 0; i < n_; ++i) on_pole_[i] = inside_pole(grown, row(x, i));
  }
  // Detection in parallel on one state; after the first sweep only pairs with a vertex the last
  // sweep moved can have changed.
  const auto P = static_cast<Index>(pairs_.size());
  measure_motion(x0, x);
  parallel_for_if(P >= kPairGrain, P, [&](Index k) {
    contacts_[k].kind = Contact::kNone;
    if (!first) {
      int32_t i[4];
      corners(pairs_[k], i);
      if (!moved_[i[0]] && !moved_[i[1]] && !moved_[i[2]] && !moved_[i[3]]) return;
    }
    if (out_of_reach(k, x0, x, h)) return;  // never within the thickness
    detect(pairs_[k], x0, x, contacts_[k]);
  });
  // Response, in pair order. A crossing moves the pair's four points back along their paths to
  // the time they were still the thickness (or their starting distance) apart: an inelastic stop
  // short of the hit, which only ever undoes motion, so it cannot push anything through a third
  // layer (the freeze fallback is its limit, everything back at x0). A proximity is projected
  // apart (Gauss-Seidel, C re-evaluated on the current positions along its detected normal and
  // points). Velocities: Jacobi, every impulse from the sweep's starting velocities, averaged per
  // vertex over the impulses that move it, so contacts sharing a vertex (a vertex over a shared
  // edge, a triangle on two pinned bumps) neither add up nor bounce it.
  dv_.setZero();
  std::fill(count_v_.begin(), count_v_.end(), 0);
  bool responded = false, degenerate = false;
  for (Index k = 0; k < P; ++k) {
    const Contact& ct = contacts_[k];
    if (ct.kind == Contact::kNone) continue;
    if (ct.kind == Contact::kDegenerate) {
      degenerate = true;
      continue;
    }
    responded = true;
    int32_t idx[4];
    corners(pairs_[k], idx);
    if (ct.kind == Contact::kCrossing) {
      double t;
      if (!crossing(pairs_[k], x0, x, t)) continue;  // an earlier answer undid it
      const double back = separation(pairs_[k], x0, x, t);
      for (const int32_t i : idx)
        if (inv_mass[i] > 0) x.row(i) = x0.row(i) + back * (x.row(i) - x0.row(i));
      ++stats_.crossings;
      changed = true;
    } else {
      Vec3 gap = Vec3::Zero();
      for (int j = 0; j < 4; ++j) gap += ct.g[j] * row(x, idx[j]);
      project(idx, ct, gap.dot(ct.n) - h, x, inv_mass);
      ++stats_.contacts;
      changed = changed || ct.C < -1e-2 * h;
    }
    accumulate_impulse(idx, ct, v, inv_mass);
  }
  for (Index i = 0; i < n_; ++i)
    if (count_v_[i]) v.row(i) += dv_.row(i) / count_v_[i];
  // The caller's constraints next, when the responses moved anything (contacts alone would hold
  // a stretched cloth stretched).
  if (constraints && responded) (*constraints)(x, v);
  // The pole last: no sweep leaves a vertex inside it.
  Index pushed = 0;
  if (pole) {
    double largest = 0;
    pushed = collide_pole(*pole, x0, x, v, inv_mass, &largest);
    stats_.pole += pushed;
    changed = changed || largest > 1e-2 * h;
  }
  quiet_ = first && !responded && !degenerate && pushed == 0;
  for (Index i = 0; i < n_; ++i) moved_[i] = x.row(i) != x_sweep_.row(i);
  return changed;
}

bool SelfCollision::find_violations(const MatX3& x0, const MatX3& x, const VecX& inv_mass,
                                    const PoleParams* pole) {
  const double floor = 0.5 * params_.thickness;
  auto still = [&](int32_t i) { return zones_.still(i, inv_mass); };
  const auto P = static_cast<Index>(pairs_.size());
  if (quiet_) {  // the last sweep saw every pair at this x and found none within the thickness
    std::fill(flag_.begin(), flag_.end(), uint8_t{0});
  } else {
    measure_motion(x0, x);
    parallel_for_if(P >= kPairGrain, P, [&](Index k) {
      const Pair& pr = pairs_[k];
      int32_t i[4];
      corners(pr, i);
      flag_[k] = 0;
      if (still(i[0]) && still(i[1]) && still(i[2]) && still(i[3])) return;  // nothing to undo
      if (out_of_reach(k, x0, x, floor)) return;  // cannot have crossed or closed in
      double t;
      if (crossing(pr, x0, x, t)) {
        flag_[k] = 1;
      } else if (!pr.edge_pair) {
        const Vec3 p = row(x, i[0]), a = row(x, i[1]), b = row(x, i[2]), c = row(x, i[3]);
        if (beyond_reach(p, a, b, c, floor)) return;
        bool interior;
        const Vec3 bary = closest_point_barycentric(p, a, b, c, interior);
        flag_[k] = (p - (bary[0] * a + bary[1] * b + bary[2] * c)).norm() < floor;
      }
    });
  }
  const bool any = std::find(flag_.begin(), flag_.end(), uint8_t{1}) != flag_.end();
  return any || (pole && zones_.any_in_pole(*pole, x, inv_mass));
}

void SelfCollision::freeze_fallback(const MatX3& x0, MatX3& x, MatX3& v, const VecX& inv_mass,
                                    const PoleParams* pole) {
  zones_.clear();
  if (!find_violations(x0, x, inv_mass, pole)) return;
  // Frozen vertices stay at x0 in the world frame, so collect candidates there (no shift): every
  // state the loop can reach lies within these boxes.
  broad_phase(x0, x, inv_mass, /*shifted=*/false);
  for (Index round = 0; round <= n_ && find_violations(x0, x, inv_mass, pole); ++round) {
    for (size_t k = 0; k < pairs_.size(); ++k) {
      if (!flag_[k]) continue;
      int32_t group[4];
      corners(pairs_[k], group);
      stats_.frozen += zones_.freeze(group, x0, x, v, inv_mass);
    }
    if (pole) stats_.frozen += zones_.freeze_in_pole(*pole, x0, x, v, inv_mass);
  }
}

const SelfCollisionStats& SelfCollision::resolve(const MatX3& x0, MatX3& x, MatX3& v,
                                                 const VecX& inv_mass, const PoleParams* pole,
                                                 const Projector* constraints) {
  stats_ = SelfCollisionStats{};
  if (pole) stats_.pole += collide_pole(*pole, x0, x, v, inv_mass);  // the sweeps start outside
  bool complete = false;  // candidates cover every pair that can violate at the current x
  for (int attempt = 0; attempt <= kMaxRebuilds && !complete; ++attempt) {
    broad_phase(x0, x, inv_mass, /*shifted=*/true);
    for (int s = 0; s < params_.iterations; ++s) {
      ++stats_.sweeps;
      if (!sweep(x0, x, v, inv_mass, pole, constraints, s == 0)) break;
    }
    complete = within_boxes(x);  // else a push left the candidates' reach: collect again
  }
  if (!complete) broad_phase(x0, x, inv_mass, /*shifted=*/true);
  freeze_fallback(x0, x, v, inv_mass, pole);
  return stats_;
}

}  // namespace flagsim

#include "collision/candidates.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>

#include "common/simd.h"

namespace flagsim {

namespace {

// Box reach in thicknesses: triangle and edge boxes carry one; a vertex query adds two and an
// edge query one (the other edge's box carries its own), so every pair is seen within three.
constexpr double kBoxMargin = 1, kVertexQuery = 2, kEdgeQuery = 1;
// The list's skin: this many times the step's largest vertex box (so it serves several steps)...
constexpr double kSkinSteps = 6;
// ...at most this many thicknesses (a sheet's list grows as the square of the query's reach).
constexpr double kMaxSkin = 4;
// A list longer than this many times its candidates at first use does not pay: a miss.
constexpr double kListRatio = 1.5;
// A list that has served and grew this many times its candidates (the motion calmed): rebuilt.
constexpr double kStaleRatio = 4;
// Pairs of slack on those ratios, so that tiny cloths do not miss on a handful of pairs.
constexpr size_t kListSlack = 64;
// Direct queries after a miss (and at the start), doubled per further miss up to the maximum.
constexpr int kDirectBuilds = 8, kMaxDirectBuilds = 512;
// Items per tree descent (see collect_vertices).
constexpr Index kQueryGroup = 8;
// Pairs per vertex (and per edge) the scratch is reserved for at construction.
constexpr size_t kExpectedPerItem = 8;
// The queries and the list's filter run in up to kMaxChunks chunks of at least kGroupsPerChunk
// query groups each (run_chunks): fine enough that a thread that joins late still takes a fair
// share (the paper flag's 40 groups make 5 chunks), coarse enough that a chunk costs far more
// than taking it.
constexpr Index kMaxChunks = 32, kGroupsPerChunk = 8;

// A pair with no free vertex (all four inverse masses 0) is never a candidate: nothing to move.
inline bool none_free(const VecX& inv_mass, int32_t a, int32_t b, int32_t c, int32_t d) {
  return inv_mass[a] == 0 && inv_mass[b] == 0 && inv_mass[c] == 0 && inv_mass[d] == 0;
}

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

// Concatenate per-thread buffers (in thread order) onto out, each kind of pair onto its list.
template <class Buffers>
void append(const Buffers& buffers, CandidatePairs& out) {
  for (const CandidatePairs& b : buffers)
    out.vertex_triangle.insert(out.vertex_triangle.end(), b.vertex_triangle.begin(),
                               b.vertex_triangle.end());
  for (const CandidatePairs& b : buffers)
    out.edge_edge.insert(out.edge_edge.end(), b.edge_edge.begin(), b.edge_edge.end());
}

// Sorts buffer[begin, end) by the pairs' second item (one first item's pairs: the tree's order
// is not sorted).
void sort_by_second(std::vector<CandidatePair>& buffer, size_t begin) {
  std::sort(buffer.begin() + static_cast<std::ptrdiff_t>(begin), buffer.end(),
            [](const CandidatePair& p, const CandidatePair& q) { return p.b < q.b; });
}

// Closed boxes [q0 - r, q1 + r] and [l, u] (3 doubles each) overlap: the trees' own test.
inline bool boxes_meet(const double* q0, const double* q1, const double* l, const double* u,
                       double r) {
  return l[0] <= q1[0] + r && u[0] >= q0[0] - r && l[1] <= q1[1] + r && u[1] >= q0[1] - r &&
         l[2] <= q1[2] + r && u[2] >= q0[2] - r;
}

}  // namespace

Candidates::Candidates(const MatX3i& triangles, Index num_vertices, double thickness)
    : tris_(triangles),
      edges_(mesh_edges(triangles)),
      n_(num_vertices),
      thickness_(thickness),
      vlo_(num_vertices, 3),
      vhi_(num_vertices, 3),
      tlo_(triangles.rows(), 3),
      thi_(triangles.rows(), 3),
      elo_(edges_.rows(), 3),
      ehi_(edges_.rows(), 3),
      ref_lo_(num_vertices, 3),
      ref_hi_(num_vertices, 3),
      direct_left_(kDirectBuilds),
      direct_streak_(kDirectBuilds) {
  const size_t expected = kExpectedPerItem * static_cast<size_t>(num_vertices) + kListSlack;
  const size_t expected_edges = kExpectedPerItem * static_cast<size_t>(edges_.rows()) + kListSlack;
  reserved_ = expected + expected_edges;
  const Index groups = (n_ + edges_.rows()) / kQueryGroup;
  chunk_pairs_.resize(size_t(std::clamp<Index>(groups / kGroupsPerChunk, 1, kMaxChunks)));
  // Each chunk twice its share (a chunk holds a block of the mesh; a fold may crowd one).
  const size_t chunks = chunk_pairs_.size();
  for (ChunkPairs& buffer : chunk_pairs_) {
    buffer.vertex_triangle.reserve(2 * expected / chunks + kListSlack);
    buffer.edge_edge.reserve(2 * expected_edges / chunks + kListSlack);
    buffer.hits.reserve(kExpectedPerItem * kQueryGroup * 4);
  }
  // A list that pays is at most kListRatio times the candidates.
  for (CandidatePairs* p : {&pairs_, &list_}) {
    p->vertex_triangle.reserve(expected);
    p->edge_edge.reserve(expected_edges);
  }
}

// Whether the list still holds every pair the trees could give now: each vertex box, less the
// mean start position, within skin_ of its box when the list was built (a common translation
// cannot bring two boxes together). Then a vertex box, and with it every triangle or edge box,
// has grown by at most skin_ on each side, and the list was collected 2 skin_ wider.
bool Candidates::list_covers(const Vec3& centre) const {
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
// thickness and at most kMaxSkin times it.
// A list pays only while it is about as short as its candidates and serves several broad
// phases: that is a cloth whose close pairs are its mesh neighbours, thickness well below the
// spacing, as in the paper's flag. One that came out longer than kListRatio times its
// candidates, or served one broad phase only, missed: the next kDirectBuilds queries go straight
// to the candidates, twice as many after each further miss up to kMaxDirectBuilds. The first
// queries are direct too (a cloth let go moves fastest). Deterministic, and it decides only
// which pairs get tested, never which are candidates.
double Candidates::next_skin(const Vec3& centre) {
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
  const double h = thickness_;
  skin_ = std::min(std::max(kSkinSteps * motion, h), kMaxSkin * h);
  list_valid_ = true;
  ref_scale_ = size;
  ref_lo_ = vlo_.rowwise() - centre.transpose();
  ref_hi_ = vhi_.rowwise() - centre.transpose();
  return skin_;
}

void Candidates::miss() {
  direct_left_ = direct_streak_;
  direct_streak_ = std::min(2 * direct_streak_, kMaxDirectBuilds);
}

// A list longer than kListRatio times the last candidates does not pay (see next_skin).
size_t Candidates::list_budget() const {
  return static_cast<size_t>(kListRatio * double(last_candidates_)) + kListSlack;
}

// Items are queried in groups of kQueryGroup consecutive ones, which are neighbours on the mesh
// (vertices along a row; a vertex's edges, then the next vertex's): one descent of the tree with
// the group's union box gathers a superset of each member's hits, which each member then filters
// by its own box with the tree's test on the same numbers. The same pairs as one descent per
// item, in the same order, for a fraction of the descents (the large scene's edge queries were
// 18 % of its step).
namespace {

// hits = the items of `tree` above `after` whose boxes (item_lo, item_hi) overlap the union of
// the boxes [lo, hi] of rows [first, last), grown by reach: every member's hits, and more.
void query_group(const BoxTree& tree, const MatX3& item_lo, const MatX3& item_hi, const MatX3& lo,
                 const MatX3& hi, Index first, Index last, double reach, int32_t after,
                 QueryGroupHits& hits) {
  Vec3 glo = lo.row(first).transpose(), ghi = hi.row(first).transpose();
  for (Index i = first + 1; i < last; ++i) {
    glo = glo.cwiseMin(lo.row(i).transpose());
    ghi = ghi.cwiseMax(hi.row(i).transpose());
  }
  hits.clear();
  tree.query(
      item_lo, item_hi, glo.array() - reach, ghi.array() + reach,
      [&](int32_t t) { hits.add(t, item_lo.data() + 3 * Index(t), item_hi.data() + 3 * Index(t)); },
      after);
  hits.finish();
}

// out[0, n) = the items of the hits above `after` whose boxes meet [qlo, qhi] (closed: the
// trees' test on the same numbers), in order; returns n. Lane type L as in common/simd.h (void:
// scalars), the same comparisons at every width (item numbers are exact as doubles). Branch-free:
// whether a hit is kept is close to random for the branch predictor, whose misses were most of
// the filter's time; every hit is written, and a kept one moves the end on.
template <class L>
FLAGSIM_INLINE size_t meeting_on(const QueryGroupHits& g, const Vec3& qlo, const Vec3& qhi,
                                 int32_t after, int32_t* out) {
  constexpr size_t B = QueryGroupHits::kBlock, R = QueryGroupHits::kRuns;
  const size_t blocks = g.blocks.size() / (R * B);
  const double* runs = g.blocks.data();
  const double above = after;
  size_t n = 0;
  if constexpr (std::is_void<L>::value) {
    for (size_t h = 0; h < g.items.size(); ++h) {
      const double* b = runs + R * B * (h / B) + h % B;
      const bool meets = (b[0] <= qhi[0]) & (b[B] <= qhi[1]) & (b[2 * B] <= qhi[2]) &
                         (b[3 * B] >= qlo[0]) & (b[4 * B] >= qlo[1]) & (b[5 * B] >= qlo[2]) &
                         (b[6 * B] > above);
      out[n] = g.items[h];
      n += meets;
    }
  } else {
    using V = typename L::V;
    constexpr size_t W = L::W;
    const V x0 = V{} + qlo[0], y0 = V{} + qlo[1], z0 = V{} + qlo[2];
    const V x1 = V{} + qhi[0], y1 = V{} + qhi[1], z1 = V{} + qhi[2], a = V{} + above;
    for (size_t k = 0; k < blocks; ++k)
      for (size_t w = 0; w < B; w += W) {
        const double* b = runs + R * B * k + w;
        const auto meets = (load_lanes<V>(b) <= x1) & (load_lanes<V>(b + B) <= y1) &
                           (load_lanes<V>(b + 2 * B) <= z1) & (load_lanes<V>(b + 3 * B) >= x0) &
                           (load_lanes<V>(b + 4 * B) >= y0) & (load_lanes<V>(b + 5 * B) >= z0) &
                           (load_lanes<V>(b + 6 * B) > a);
        for (size_t lane = 0; lane < W; ++lane) {
          out[n] = g.items[B * k + w + lane];
          n += size_t(meets[lane] & 1);
        }
      }
  }
  return n;
}

}  // namespace

void QueryGroupHits::reserve(size_t n) {
  items.reserve(n + kBlock);
  kept.reserve(n + kBlock);
  blocks.reserve(kRuns * (n + kBlock));
}

void QueryGroupHits::clear() {
  items.clear();
  blocks.clear();
}

void QueryGroupHits::add(int32_t item, const double* lo, const double* hi) {
  const size_t h = items.size() % kBlock;
  items.push_back(item);
  if (h == 0) blocks.resize(blocks.size() + kRuns * kBlock);
  double* b = blocks.data() + blocks.size() - kRuns * kBlock + h;
  for (size_t d = 0; d < 3; ++d) {
    b[d * kBlock] = lo[d];
    b[(3 + d) * kBlock] = hi[d];
  }
  b[6 * kBlock] = item;
}

// The last block's unused lanes: NaN boxes (never kept) and item 0, so that items fill whole
// blocks.
void QueryGroupHits::finish() {
  const size_t used = items.size() % kBlock;
  if (used > 0) {
    double* b = blocks.data() + blocks.size() - kRuns * kBlock;
    for (size_t r = 0; r < kRuns; ++r)
      for (size_t h = used; h < kBlock; ++h)
        b[r * kBlock + h] = std::numeric_limits<double>::quiet_NaN();
    items.resize(items.size() + kBlock - used, 0);
  }
  kept.resize(items.size());
}

// kept[0, n) = the items above `after` whose boxes meet [qlo, qhi], in the hits' order; returns
// n. On the widest lanes the CPU has (meeting_on).
size_t QueryGroupHits::meeting(const Vec3& qlo, const Vec3& qhi, int32_t after) {
  if (items.empty()) return 0;
  const auto meet = [&](auto c) FLAGSIM_INLINE_LAMBDA {
    return meeting_on<typename decltype(c)::L>(*this, qlo, qhi, after, kept.data());
  };
  return on_widest_lanes<double, size_t()>(meet)();
}

// Appends to buffer the pairs of each vertex i in [i0, i1) with the triangles whose boxes the
// tree finds within the vertex query's reach, `wide` wider, by vertex, then by triangle. hits:
// scratch.
void Candidates::collect_vertices(Index i0, Index i1, double wide, const VecX* inv_mass,
                                  std::vector<CandidatePair>& buffer, QueryGroupHits& hits) const {
  const double reach = kVertexQuery * thickness_ + wide;
  query_group(tri_tree_, tlo_, thi_, vlo_, vhi_, i0, i1, reach, -1, hits);
  for (Index i = i0; i < i1; ++i) {
    const Vec3 qlo = vlo_.row(i).transpose().array() - reach;
    const Vec3 qhi = vhi_.row(i).transpose().array() + reach;
    const size_t begin = buffer.size();
    const auto vi = static_cast<int32_t>(i);
    // Own triangles out without a branch (they are a vertex's nearest hits), then the rare
    // pairs with no free vertex.
    const size_t n = hits.meeting(qlo, qhi, -1);
    int32_t* kept = hits.kept.data();
    size_t m = 0;
    for (size_t k = 0; k < n; ++k) {
      const int32_t t = kept[k];
      kept[m] = t;
      m += (tris_(t, 0) != vi) & (tris_(t, 1) != vi) & (tris_(t, 2) != vi);
    }
    for (size_t k = 0; k < m; ++k) {
      const int32_t t = kept[k];
      if (inv_mass && none_free(*inv_mass, vi, tris_(t, 0), tris_(t, 1), tris_(t, 2))) continue;
      buffer.push_back({vi, t});
    }
    sort_by_second(buffer, begin);
  }
}

// Appends to buffer the pairs of each edge e in [e0, e1) with the edges above it whose boxes the
// tree finds within the edge query's reach, `wide` wider, by edge, then by the second edge.
void Candidates::collect_edges(Index e0, Index e1, double wide, const VecX* inv_mass,
                               std::vector<CandidatePair>& buffer, QueryGroupHits& hits) const {
  const double reach = kEdgeQuery * thickness_ + wide;
  query_group(edge_tree_, elo_, ehi_, elo_, ehi_, e0, e1, reach, static_cast<int32_t>(e0), hits);
  for (Index e = e0; e < e1; ++e) {
    const Vec3 qlo = elo_.row(e).transpose().array() - reach;
    const Vec3 qhi = ehi_.row(e).transpose().array() + reach;
    const size_t begin = buffer.size();
    const int32_t a = edges_(e, 0), b = edges_(e, 1);
    // f > e (each pair once) and edges sharing a vertex (they never cross) out without a
    // branch, then the rare pairs with no free vertex.
    const size_t n = hits.meeting(qlo, qhi, static_cast<int32_t>(e));
    int32_t* kept = hits.kept.data();
    size_t m = 0;
    for (size_t k = 0; k < n; ++k) {
      const int32_t f = kept[k], c = edges_(f, 0), d = edges_(f, 1);
      kept[m] = f;
      m += (a != c) & (a != d) & (b != c) & (b != d);
    }
    for (size_t k = 0; k < m; ++k) {
      const int32_t f = kept[k];
      if (inv_mass && none_free(*inv_mass, a, b, edges_(f, 0), edges_(f, 1))) continue;
      buffer.push_back({static_cast<int32_t>(e), f});
    }
    sort_by_second(buffer, begin);
  }
}

// Box-tree queries (the trees refitted to the current boxes), every query `wide` wider, into out
// (ordered as the header says). With inv_mass, pairs with no free vertex are left out. Returns
// false, with out incomplete, as soon as out would hold more than `budget` pairs.
bool Candidates::query_trees(double wide, const VecX* inv_mass, CandidatePairs& out,
                             size_t budget) {
  // The trees take their shape from the first query's boxes and are refitted after that.
  if (tri_tree_.built()) {
    tri_tree_.refit(tlo_, thi_);
    edge_tree_.refit(elo_, ehi_);
  } else {
    tri_tree_.build(tlo_, thi_);
    edge_tree_.build(elo_, ehi_);
  }
  const Index E = edges_.rows();
  const Index VG = (n_ + kQueryGroup - 1) / kQueryGroup, EG = (E + kQueryGroup - 1) / kQueryGroup;
  const auto C = static_cast<Index>(chunk_pairs_.size());
  // Pairs so far over all chunks; a chunk stops once they pass the budget, which a complete query
  // never does, so `within` is the same whoever ran which chunk.
  std::atomic<size_t> total{0};
  const bool budgeted = budget != SIZE_MAX;
  auto add = [&](size_t before, const ChunkPairs& p) {
    return !budgeted || total.fetch_add(p.size() - before) + (p.size() - before) <= budget;
  };
  // Chunk c: the c-th block of vertex groups, then the c-th block of edge groups.
  run_chunks(n_ >= kParallelGrain, C, [&](Index c) {
    ChunkPairs& p = chunk_pairs_[size_t(c)];
    p.clear();
    bool ok = true;
    for (Index g = c * VG / C; g < (c + 1) * VG / C && ok; ++g) {
      const size_t before = p.size();
      if (budgeted && total.load() > budget) break;
      collect_vertices(g * kQueryGroup, std::min(n_, (g + 1) * kQueryGroup), wide, inv_mass,
                       p.vertex_triangle, p.hits);
      ok = add(before, p);
    }
    for (Index g = c * EG / C; g < (c + 1) * EG / C && ok; ++g) {
      const size_t before = p.size();
      if (budgeted && total.load() > budget) break;
      collect_edges(g * kQueryGroup, std::min(E, (g + 1) * kQueryGroup), wide, inv_mass,
                    p.edge_edge, p.hits);
      ok = add(before, p);
    }
  });
  const bool within = !budgeted || total.load() <= budget;
  out.clear();
  append(chunk_pairs_, out);
  return within;
}

// pairs_ = the list's pairs the trees would give now: a free vertex, and boxes that overlap by the
// trees' own test on the same numbers (so the same pairs, in the list's order, which is theirs).
void Candidates::filter_list(const VecX& inv_mass) {
  const double h = kEdgeQuery * thickness_, reach = kVertexQuery * thickness_;
  auto keep_vertex = [&](const CandidatePair& p) {
    if (none_free(inv_mass, p.a, tris_(p.b, 0), tris_(p.b, 1), tris_(p.b, 2))) return false;
    return boxes_meet(vlo_.data() + 3 * Index(p.a), vhi_.data() + 3 * Index(p.a),
                      tlo_.data() + 3 * Index(p.b), thi_.data() + 3 * Index(p.b), reach);
  };
  auto keep_edge = [&](const CandidatePair& p) {
    if (none_free(inv_mass, edges_(p.a, 0), edges_(p.a, 1), edges_(p.b, 0), edges_(p.b, 1)))
      return false;
    return boxes_meet(elo_.data() + 3 * Index(p.a), ehi_.data() + 3 * Index(p.a),
                      elo_.data() + 3 * Index(p.b), ehi_.data() + 3 * Index(p.b), h);
  };
  const std::vector<CandidatePair>& lv = list_.vertex_triangle;
  const std::vector<CandidatePair>& le = list_.edge_edge;
  const auto LV = static_cast<Index>(lv.size()), LE = static_cast<Index>(le.size());
  pairs_.clear();
  // Chunk c keeps from the c-th blocks of the list's two parts: concatenated, the list's order.
  const auto C = static_cast<Index>(chunk_pairs_.size());
  run_chunks(LV + LE >= kPairGrain, C, [&](Index c) {
    ChunkPairs& p = chunk_pairs_[size_t(c)];
    p.clear();
    for (Index k = c * LV / C; k < (c + 1) * LV / C; ++k)
      if (keep_vertex(lv[size_t(k)])) p.vertex_triangle.push_back(lv[size_t(k)]);
    for (Index k = c * LE / C; k < (c + 1) * LE / C; ++k)
      if (keep_edge(le[size_t(k)])) p.edge_edge.push_back(le[size_t(k)]);
  });
  append(chunk_pairs_, pairs_);
  // Too long to pay (see next_skin) at its first use; long later (it came from a fast
  // transient and the motion has calmed): build it again.
  const double ratio = served_ == 1 ? kListRatio : kStaleRatio;
  if (double(list_.size()) > ratio * double(pairs_.size()) + kListSlack) list_valid_ = false;
}

void Candidates::collect(const MatX3& x0, const MatX3& x, const VecX& inv_mass, bool shifted) {
  const double margin = kBoxMargin * thickness_;
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
  // From the pair list while it covers the motion, else from the trees.
  from_list_ = list_covers(centre);
  if (from_list_) {
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
  last_candidates_ = static_cast<Index>(pairs_.size());
}

bool Candidates::within_boxes(const MatX3& x) const {
  const double margin = kBoxMargin * thickness_;
  for (Index i = 0; i < n_; ++i) {
    const Vec3 p = row(x, i) - shift_;
    if ((p.array() < vlo_.row(i).transpose().array() - margin).any() ||
        (p.array() > vhi_.row(i).transpose().array() + margin).any())
      return false;
  }
  return true;
}

}  // namespace flagsim

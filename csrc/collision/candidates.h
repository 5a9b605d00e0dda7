// Self-collision broad phase: the candidate pairs of one step, (vertex, triangle) with the vertex
// not in the triangle and (edge, edge) sharing no vertex, whose swept boxes come close enough
// over the step that the pair may cross or end within the thickness.
//
// Boxes: each vertex's segment x0 -> x in a frame moving with the cloth's mean displacement
// (crossings are invariant under a common translation, so a 30 m/s gust does not stretch the
// boxes); triangle and edge boxes hold their vertices' boxes grown by the thickness. The pairs
// come from box trees (box_tree.h) queried so that a pair is a candidate when its boxes come
// within 3 thicknesses: each side may end up to a thickness outside its box (within_boxes) and
// the response acts within one thickness.
//
// Verlet list: the trees are queried wider than needed (a skin) into a pair list that later broad
// phases filter by the same box test, for as long as no vertex box has left its box at the list's
// build by more than the skin: the same candidates, in the same order, without the queries. Used
// only while it pays (see Candidates::next_skin in candidates.cpp).
//
// Candidates are ordered: vertex-triangle pairs by vertex, then by triangle; edge-edge pairs by
// their first edge, then by the second; the same whatever the thread count.
#pragma once
#include <cstdint>
#include <vector>

#include "collision/box_tree.h"
#include "common/parallel.h"
#include "common/types.h"

namespace flagsim {

/// Pair loops parallelise above this many pairs: a pair costs about a vertex update, and waking a
/// thread team on a loaded machine costs far more than a few thousand of them.
constexpr Index kPairGrain = 4 * kParallelGrain;

/// The margin by which a cheap test on coordinates of magnitude up to `size` (m) must clear its
/// bound so that round-off (~1e-16 of the size) never decides: far above it, far below any gap.
inline double roundoff_guard(double size) { return 1e-12 * (1 + size); }

/// A candidate: (vertex a, triangle b) in CandidatePairs::vertex_triangle, (edge a, edge b),
/// a < b, in CandidatePairs::edge_edge (edges as Candidates::edges() numbers them).
struct CandidatePair {
  int32_t a, b;
};

struct CandidatePairs {
  std::vector<CandidatePair> vertex_triangle;  ///< by vertex, then by triangle
  std::vector<CandidatePair> edge_edge;        ///< by first edge, then by second
  size_t size() const { return vertex_triangle.size() + edge_edge.size(); }
  void clear() {
    vertex_triangle.clear();
    edge_edge.clear();
  }
};

// Scratch of the broad phase's tree queries (Candidates): a query group's hits, in the tree's
// order, with their boxes and item numbers in blocks of kBlock hits laid out run by run (lo x, y,
// z, hi x, y, z, the item as a double; a block's unused lanes are NaN, which meets nothing), and
// the hits one member keeps.
struct QueryGroupHits {
  static constexpr size_t kBlock = 4, kRuns = 7;
  std::vector<int32_t> items, kept;
  std::vector<double> blocks;  // kRuns kBlock per block
  void reserve(size_t n);
  void clear();
  void add(int32_t item, const double* lo, const double* hi);
  void finish();
  size_t meeting(const Vec3& qlo, const Vec3& qhi, int32_t after);
};

class Candidates {
 public:
  /// triangles: T x 3 vertex indices into [0, num_vertices); thickness: m, > 0.
  Candidates(const MatX3i& triangles, Index num_vertices, double thickness);

  /// The step's candidates for positions moving linearly from x0 to x (N x 3, m). Pairs with no
  /// free vertex (all inverse masses 0) are left out. shifted: boxes in the frame moving with the
  /// mean displacement (false: the world frame, shift() = 0).
  void collect(const MatX3& x0, const MatX3& x, const VecX& inv_mass, bool shifted);

  /// True when every vertex of x lies within a thickness of its box: the candidates are complete
  /// for x (else a response moved it too far and collect must run again).
  bool within_boxes(const MatX3& x) const;

  const CandidatePairs& pairs() const { return pairs_; }
  /// The mean displacement x - x0 of the last collect (m), 0 unless shifted.
  const Vec3& shift() const { return shift_; }
  /// Whether the last collect filtered the pair list (else it queried the trees).
  bool from_list() const { return from_list_; }
  /// The pair list's skin (m); 0 while queries go straight to the candidates.
  double skin() const { return skin_; }
  /// Pairs the scratch holds without allocating (per-pair arrays of the caller may reserve it).
  size_t reserved() const { return reserved_; }

  const MatX3i& triangles() const { return tris_; }
  /// (E x 2) the mesh's edges, each once, lower vertex index first, sorted.
  const MatX2i& edges() const { return edges_; }

 private:
  bool list_covers(const Vec3& centre) const;
  double next_skin(const Vec3& centre);
  void miss();
  size_t list_budget() const;
  void collect_vertices(Index i0, Index i1, double wide, const VecX* inv_mass,
                        std::vector<CandidatePair>& buffer, QueryGroupHits& hits) const;
  void collect_edges(Index e0, Index e1, double wide, const VecX* inv_mass,
                     std::vector<CandidatePair>& buffer, QueryGroupHits& hits) const;
  bool query_trees(double wide, const VecX* inv_mass, CandidatePairs& out,
                   size_t budget = SIZE_MAX);
  void filter_list(const VecX& inv_mass);

  MatX3i tris_;
  MatX2i edges_;
  Index n_;
  double thickness_;  // m
  size_t reserved_;
  BoxTree tri_tree_, edge_tree_;  // shaped on the first query, refitted after
  Vec3 shift_ = Vec3::Zero();     // mean displacement over the step (broad-phase frame)
  MatX3 vlo_, vhi_;               // N x 3 swept vertex boxes in the shifted frame
  MatX3 tlo_, thi_;               // T x 3 swept triangle boxes, grown by the thickness
  MatX3 elo_, ehi_;               // E x 3 swept edge boxes, grown by the thickness
  // Per chunk of the queries and of the list's filter (run_chunks: any thread may run any chunk,
  // and the chunks' pairs are concatenated in chunk order), each on cache lines of its own: two
  // threads push pairs at the same time, and two vector ends on one line could bounce it between
  // the cores at every push (false sharing).
  struct alignas(64) ChunkPairs : CandidatePairs {
    QueryGroupHits hits;
  };
  std::vector<ChunkPairs> chunk_pairs_;
  CandidatePairs pairs_;
  // The pair list (a Verlet list): every pair whose boxes come within 2 skin_ of the query, from
  // the vertex boxes ref_lo_/ref_hi_ (less their mean position) of the step that built it.
  CandidatePairs list_;
  MatX3 ref_lo_, ref_hi_;      // N x 3
  double skin_ = 0;            // m; 0: no list (direct queries)
  double ref_scale_ = 0;       // m, largest coordinate of those boxes (round-off guard)
  bool list_valid_ = false;    // false: the next collect builds the list
  bool from_list_ = false;     // the last collect filtered the list
  int served_ = 0;             // collects the list has served
  Index last_candidates_ = 0;  // candidates of the last collect
  int direct_left_;            // queries still to make without a list
  int direct_streak_;          // how many after the next miss (doubles per miss)
};

}  // namespace flagsim

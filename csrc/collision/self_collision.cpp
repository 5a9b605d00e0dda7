#include "collision/self_collision.h"

#include <algorithm>
#include <cmath>

#include "collision/pole.h"
#include "collision/vertex_triangle.h"
#include "common/parallel.h"
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

inline Vec3 row(const MatX3& m, Index i) { return m.row(i).transpose(); }

// Pair loops parallelise above this many pairs: a pair costs about a vertex update, and waking a
// thread team on a loaded machine costs far more than a few thousand of them.
constexpr Index kPairGrain = 4 * kParallelGrain;

}  // namespace

SelfCollision::SelfCollision(const MatX3i& triangles, Index num_vertices,
                             const SelfCollisionParams& params)
    : tris_(triangles),
      n_(num_vertices),
      params_(params),
      vlo_(num_vertices, 3),
      vhi_(num_vertices, 3),
      tlo_(triangles.rows(), 3),
      thi_(triangles.rows(), 3),
      x_sweep_(num_vertices, 3),
      dv_(num_vertices, 3),
      count_v_(static_cast<size_t>(num_vertices), 0),
      on_pole_(static_cast<size_t>(num_vertices), 0),
      moved_(static_cast<size_t>(num_vertices), 0),
      frozen_(static_cast<size_t>(num_vertices), 0) {
  hash_.reserve(triangles.rows());
  const int threads = max_threads();
  thread_pairs_.resize(static_cast<size_t>(threads));
  const size_t expected = 8 * static_cast<size_t>(num_vertices) + 64;
  // Thread 0 collects every pair when the broad phase runs on one thread.
  for (auto& buffer : thread_pairs_) buffer.reserve(expected);
  pairs_.reserve(expected);
  flag_.reserve(expected);
  contacts_.reserve(expected);
}

void SelfCollision::broad_phase(const MatX3& x0, const MatX3& x, const VecX& inv_mass,
                                bool shifted) {
  const double h = params_.thickness, margin = params_.thickness;
  ++stats_.broad_phases;
  shift_.setZero();
  if (shifted) {
    for (Index i = 0; i < n_; ++i) shift_ += row(x, i) - row(x0, i);
    shift_ /= static_cast<double>(std::max<Index>(n_, 1));
  }
  for (Index i = 0; i < n_; ++i) {
    const Vec3 a = row(x0, i), b = row(x, i) - shift_;
    vlo_.row(i) = a.cwiseMin(b).transpose();
    vhi_.row(i) = a.cwiseMax(b).transpose();
  }
  const Index T = tris_.rows();
  double extent = 0;
  for (Index t = 0; t < T; ++t) {
    const int32_t a = tris_(t, 0), b = tris_(t, 1), c = tris_(t, 2);
    tlo_.row(t) = vlo_.row(a).cwiseMin(vlo_.row(b)).cwiseMin(vlo_.row(c)).array() - margin;
    thi_.row(t) = vhi_.row(a).cwiseMax(vhi_.row(b)).cwiseMax(vhi_.row(c)).array() + margin;
    extent += (thi_.row(t) - tlo_.row(t)).maxCoeff();
  }
  // Cell about the mean swept triangle size (Teschner et al. 2003 §4).
  double cell = T > 0 ? extent / static_cast<double>(T) : h;
  if (!(cell > 0) || !std::isfinite(cell)) cell = h;
  hash_.build(tlo_, thi_, cell);

  const int threads = max_threads();
  if (static_cast<int>(thread_pairs_.size()) < threads) thread_pairs_.resize(threads);
  for (auto& buffer : thread_pairs_) buffer.clear();
  const double reach = h + margin;
  auto collect = [&](Index i, std::vector<Pair>& buffer) {
    const Vec3 qlo = vlo_.row(i).transpose().array() - reach;
    const Vec3 qhi = vhi_.row(i).transpose().array() + reach;
    const size_t begin = buffer.size();
    const auto vi = static_cast<int32_t>(i);
    hash_.query(qlo, qhi, [&](int32_t t) {
      const int32_t a = tris_(t, 0), b = tris_(t, 1), c = tris_(t, 2);
      if (a == vi || b == vi || c == vi) return;  // never against its own triangles
      if (inv_mass[i] == 0 && inv_mass[a] == 0 && inv_mass[b] == 0 && inv_mass[c] == 0) return;
      buffer.push_back({vi, t});
    });
    std::sort(buffer.begin() + static_cast<std::ptrdiff_t>(begin), buffer.end(),
              [](const Pair& p, const Pair& q) { return p.t < q.t; });
  };
  if (use_team(n_ >= kParallelGrain)) {
#pragma omp parallel
    {
      std::vector<Pair>& buffer = thread_pairs_[static_cast<size_t>(thread_id())];
      // Static schedule: thread k gets the k-th contiguous block of vertices, so concatenating
      // the buffers in thread order lists pairs by vertex whatever the thread count.
#pragma omp for schedule(static)
      for (Index i = 0; i < n_; ++i) collect(i, buffer);
    }
  } else {
    for (Index i = 0; i < n_; ++i) collect(i, thread_pairs_[0]);
  }
  pairs_.clear();
  for (const auto& buffer : thread_pairs_) pairs_.insert(pairs_.end(), buffer.begin(), buffer.end());
  flag_.resize(pairs_.size());
  contacts_.resize(pairs_.size());
  stats_.candidates = static_cast<Index>(pairs_.size());
}

bool SelfCollision::within_boxes(const MatX3& x0, const MatX3& x) const {
  (void)x0;
  const double margin = params_.thickness;
  for (Index i = 0; i < n_; ++i) {
    const Vec3 p = row(x, i) - shift_;
    if ((p.array() < vlo_.row(i).transpose().array() - margin).any() ||
        (p.array() > vhi_.row(i).transpose().array() + margin).any())
      return false;
  }
  return true;
}

bool SelfCollision::weights(const Pair& pr, const Contact& c, const VecX& inv_mass, double w[4],
                            double& W, double& limit) const {
  const int32_t idx[4] = {pr.v, tris_(pr.t, 0), tris_(pr.t, 1), tris_(pr.t, 2)};
  const double g[4] = {1.0, -c.bary[0], -c.bary[1], -c.bary[2]};
  // Vertices resting on the pole count as immovable (contact mass scaling): the layers on top
  // take the whole correction instead of pushing the bottom one back into the pole each sweep,
  // unless that leaves the constraint nearly immovable (only small-barycentric vertices free).
  double W_full = 0;
  W = 0;
  for (int k = 0; k < 4; ++k) {
    W_full += g[k] * g[k] * inv_mass[idx[k]];
    W += g[k] * g[k] * (w[k] = on_pole_[idx[k]] ? 0.0 : inv_mass[idx[k]]);
  }
  if (!(W_full > 0)) return false;
  if (W < 0.25 * W_full) {
    W = W_full;
    for (int k = 0; k < 4; ++k) w[k] = inv_mass[idx[k]];
  }
  // No vertex moves further than the constraint's own change (it never needs to when the vertex
  // or the nearest triangle corner is free; when only a far corner is free, the full answer
  // C / b_k would fling it, so the rest is left to later sweeps and the fallback).
  double largest = 0;
  for (int k = 0; k < 4; ++k) largest = std::max(largest, std::abs(w[k] * g[k]) / W);
  limit = largest > 1 ? 1 / largest : 1.0;
  return true;
}

void SelfCollision::project(const Pair& pr, const Contact& c, double C, MatX3& x,
                            const VecX& inv_mass) const {
  double w[4], W, limit;
  if (C >= 0 || !weights(pr, c, inv_mass, w, W, limit)) return;
  const int32_t idx[4] = {pr.v, tris_(pr.t, 0), tris_(pr.t, 1), tris_(pr.t, 2)};
  const double g[4] = {1.0, -c.bary[0], -c.bary[1], -c.bary[2]};
  // PBD projection of C = (p - sum_k b_k x_k) . n - thickness onto C >= 0, mass-weighted.
  const double lambda = -C / W * limit;
  for (int k = 0; k < 4; ++k) x.row(idx[k]) += (lambda * w[k] * g[k]) * c.n.transpose();
}

void SelfCollision::accumulate_impulse(const Pair& pr, const Contact& c, const MatX3& v,
                                       const VecX& inv_mass) {
  double w[4], W, limit;
  if (!weights(pr, c, inv_mass, w, W, limit)) return;
  const int32_t idx[4] = {pr.v, tris_(pr.t, 0), tris_(pr.t, 1), tris_(pr.t, 2)};
  const double g[4] = {1.0, -c.bary[0], -c.bary[1], -c.bary[2]};
  // Remove the approaching normal relative velocity, then Coulomb friction takes up to mu times
  // that change off the tangential relative velocity.
  Vec3 vrel = Vec3::Zero();
  for (int k = 0; k < 4; ++k) vrel += g[k] * v.row(idx[k]).transpose();
  const double vn = vrel.dot(c.n);
  if (vn >= 0) return;
  Vec3 dvrel = -vn * c.n;
  if (params_.friction > 0) {
    const Vec3 vt = vrel - vn * c.n;
    const double speed = vt.norm();
    if (speed > 0) dvrel -= std::min(params_.friction * (-vn), speed) / speed * vt;
  }
  for (int k = 0; k < 4; ++k) {
    const double s = limit * w[k] * g[k] / W;
    if (s == 0) continue;
    dv_.row(idx[k]) += s * dvrel.transpose();
    ++count_v_[idx[k]];
  }
}

bool SelfCollision::sweep(const MatX3& x0, MatX3& x, MatX3& v, const VecX& inv_mass,
                          const PoleParams* pole, bool first) {
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
  // Detection (parallel, one state for all pairs): a crossing of the step's trajectory x0 -> x,
  // with its hit point and the triangle's normal at the hit time towards the side the vertex
  // started on (Bridson et al. 2002 §7.3, for the impulse); otherwise a proximity at x closer
  // than the thickness, along the closest-point direction.
  const auto P = static_cast<Index>(pairs_.size());
  // After the first sweep only pairs with a vertex the last sweep moved can have changed.
  parallel_for_if(P >= kPairGrain, P, [&](Index k) {
    const Pair pr = pairs_[k];
    const int32_t a = tris_(pr.t, 0), b = tris_(pr.t, 1), c = tris_(pr.t, 2);
    Contact& ct = contacts_[k];
    ct.kind = Contact::kNone;
    if (!first && !moved_[pr.v] && !moved_[a] && !moved_[b] && !moved_[c]) return;
    const Vec3 p0 = row(x0, pr.v), a0 = row(x0, a), b0 = row(x0, b), c0 = row(x0, c);
    const Vec3 p1 = row(x, pr.v), a1 = row(x, a), b1 = row(x, b), c1 = row(x, c);
    double t;
    if (vertex_triangle_ccd(p0, a0, b0, c0, p1, a1, b1, c1, t, ct.bary)) {
      Vec3 n = ((1 - t) * (b0 - a0) + t * (b1 - a1)).cross((1 - t) * (c0 - a0) + t * (c1 - a1));
      const double len = n.norm();
      if (len > 0) {  // else a degenerate triangle: left to the fallback
        const double f0 = (b0 - a0).cross(c0 - a0).dot(p0 - a0);
        const double f1 = (b1 - a1).cross(c1 - a1).dot(p1 - a1);
        ct.n = (f0 > 0 || (f0 == 0 && f1 >= 0)) ? Vec3(n / len) : Vec3(-n / len);
        ct.kind = Contact::kCrossing;
      }
      return;
    }
    if (beyond_reach(p1, a1, b1, c1, h)) return;
    bool interior;
    ct.bary = closest_point_barycentric(p1, a1, b1, c1, interior);
    const Vec3 r = p1 - (ct.bary[0] * a1 + ct.bary[1] * b1 + ct.bary[2] * c1);
    const double d = r.norm();
    if (d >= h) return;
    if (d > 1e-9 * h) {
      ct.n = r / d;
    } else {  // on the triangle: its normal, towards the side the vertex started on
      const Vec3 n = (b1 - a1).cross(c1 - a1);
      if (!(n.norm() > 0)) return;
      const double f0 = (b0 - a0).cross(c0 - a0).dot(p0 - a0);
      ct.n = f0 < 0 ? Vec3(-n.normalized()) : Vec3(n.normalized());
    }
    ct.C = d - h;
    ct.kind = Contact::kProximity;
  });
  // Response, in pair order. A crossing moves the pair's four points back along their paths to
  // the time the vertex was still the thickness (or its starting distance) off the triangle's
  // plane: an inelastic stop short of the hit, which only ever undoes motion, so it cannot push
  // anything through a third layer (the freeze fallback is its limit, everything back at x0).
  // A proximity is projected apart (Gauss-Seidel, C re-evaluated on the current positions along
  // its detected normal and point). Velocities: Jacobi, every impulse from the sweep's starting
  // velocities, averaged per vertex over the impulses that move it, so contacts sharing a vertex
  // (a vertex over a shared edge, a triangle on two pinned bumps) neither add up nor bounce it.
  dv_.setZero();
  std::fill(count_v_.begin(), count_v_.end(), 0);
  for (Index k = 0; k < P; ++k) {
    Contact& ct = contacts_[k];
    if (ct.kind == Contact::kNone) continue;
    const Pair pr = pairs_[k];
    const int32_t idx[4] = {pr.v, tris_(pr.t, 0), tris_(pr.t, 1), tris_(pr.t, 2)};
    if (ct.kind == Contact::kCrossing) {
      double t;
      Vec3 bary;
      const Vec3 p0 = row(x0, idx[0]), a0 = row(x0, idx[1]), b0 = row(x0, idx[2]), c0 = row(x0, idx[3]);
      const Vec3 p1 = row(x, idx[0]), a1 = row(x, idx[1]), b1 = row(x, idx[2]), c1 = row(x, idx[3]);
      if (!vertex_triangle_ccd(p0, a0, b0, c0, p1, a1, b1, c1, t, bary)) continue;  // undone
      const double back = separation_time(p0, a0, b0, c0, p1, a1, b1, c1, t, h);
      for (const int32_t i : idx)
        if (inv_mass[i] > 0) x.row(i) = x0.row(i) + back * (x.row(i) - x0.row(i));
      ++stats_.crossings;
      changed = true;
    } else {
      const double C = (row(x, idx[0]) - (ct.bary[0] * row(x, idx[1]) + ct.bary[1] * row(x, idx[2]) +
                                          ct.bary[2] * row(x, idx[3])))
                           .dot(ct.n) - h;
      project(pr, ct, C, x, inv_mass);
      ++stats_.contacts;
      changed = changed || ct.C < -1e-2 * h;
    }
    accumulate_impulse(pr, ct, v, inv_mass);
  }
  for (Index i = 0; i < n_; ++i)
    if (count_v_[i]) v.row(i) += dv_.row(i) / count_v_[i];
  // The pole last: no sweep leaves a vertex inside it.
  if (pole) {
    double largest = 0;
    stats_.pole += collide_pole(*pole, x0, x, v, inv_mass, &largest);
    changed = changed || largest > 1e-2 * h;
  }
  for (Index i = 0; i < n_; ++i) moved_[i] = x.row(i) != x_sweep_.row(i);
  return changed;
}

bool SelfCollision::find_violations(const MatX3& x0, const MatX3& x, const VecX& inv_mass,
                                    const PoleParams* pole) {
  const double floor = 0.5 * params_.thickness;
  auto still = [&](int32_t i) { return frozen_[i] || inv_mass[i] == 0; };
  const auto P = static_cast<Index>(pairs_.size());
  parallel_for_if(P >= kPairGrain, P, [&](Index k) {
    const Pair pr = pairs_[k];
    const int32_t a = tris_(pr.t, 0), b = tris_(pr.t, 1), c = tris_(pr.t, 2);
    flag_[k] = 0;
    if (still(pr.v) && still(a) && still(b) && still(c)) return;  // nothing left to undo
    const Vec3 p = row(x, pr.v), xa = row(x, a), xb = row(x, b), xc = row(x, c);
    bool interior;
    Vec3 bary = closest_point_barycentric(p, xa, xb, xc, interior);
    const double d = (p - (bary[0] * xa + bary[1] * xb + bary[2] * xc)).norm();
    double t;
    flag_[k] = d < floor || vertex_triangle_ccd(row(x0, pr.v), row(x0, a), row(x0, b),
                                                row(x0, c), p, xa, xb, xc, t, bary);
  });
  bool any = std::find(flag_.begin(), flag_.end(), uint8_t{1}) != flag_.end();
  if (pole)
    for (Index i = 0; i < n_ && !any; ++i)
      any = !still(static_cast<int32_t>(i)) && inside_pole(*pole, row(x, i));
  return any;
}

void SelfCollision::freeze_fallback(const MatX3& x0, MatX3& x, MatX3& v, const VecX& inv_mass,
                                    const PoleParams* pole) {
  std::fill(frozen_.begin(), frozen_.end(), uint8_t{0});
  if (!find_violations(x0, x, inv_mass, pole)) return;
  // Frozen vertices stay at x0 in the world frame, so collect candidates there (no shift): every
  // state the loop can reach lies within these boxes.
  broad_phase(x0, x, inv_mass, /*shifted=*/false);
  auto still = [&](int32_t i) { return frozen_[i] || inv_mass[i] == 0; };
  for (Index round = 0; round <= n_ && find_violations(x0, x, inv_mass, pole); ++round) {
    for (size_t k = 0; k < pairs_.size(); ++k) {
      if (!flag_[k]) continue;
      const int32_t group[4] = {pairs_[k].v, tris_(pairs_[k].t, 0), tris_(pairs_[k].t, 1),
                                tris_(pairs_[k].t, 2)};
      // Inelastic impact zone: the group keeps its momentum, moves as one, and stays at x0.
      Vec3 momentum = Vec3::Zero();
      double mass = 0;
      bool pinned = false;
      for (const int32_t i : group) {
        if (inv_mass[i] == 0) {
          pinned = true;
          continue;
        }
        momentum += row(v, i) / inv_mass[i];
        mass += 1 / inv_mass[i];
      }
      const Vec3 common = pinned || !(mass > 0) ? Vec3::Zero() : Vec3(momentum / mass);
      for (const int32_t i : group) {
        if (inv_mass[i] == 0) continue;
        x.row(i) = x0.row(i);
        v.row(i) = common.transpose();
        if (!frozen_[i]) {
          frozen_[i] = 1;
          ++stats_.frozen;
        }
      }
    }
    if (!pole) continue;
    for (Index i = 0; i < n_; ++i) {
      if (still(static_cast<int32_t>(i)) || !inside_pole(*pole, row(x, i))) continue;
      x.row(i) = x0.row(i);
      const Vec3 radial(x0(i, 0) - pole->base.x(), 0.0, x0(i, 2) - pole->base.z());
      const double r = radial.norm();
      if (r > 0) {
        const double vn = v.row(i).dot(radial.transpose()) / r;
        if (vn < 0) v.row(i) -= (vn / r) * radial.transpose();
      }
      frozen_[i] = 1;
      ++stats_.frozen;
    }
  }
}

const SelfCollisionStats& SelfCollision::resolve(const MatX3& x0, MatX3& x, MatX3& v,
                                                 const VecX& inv_mass, const PoleParams* pole) {
  stats_ = SelfCollisionStats{};
  if (pole) stats_.pole += collide_pole(*pole, x0, x, v, inv_mass);  // the sweeps start outside
  bool complete = false;  // candidates cover every pair that can violate at the current x
  for (int attempt = 0; attempt <= kMaxRebuilds && !complete; ++attempt) {
    broad_phase(x0, x, inv_mass, /*shifted=*/true);
    for (int s = 0; s < params_.iterations; ++s) {
      ++stats_.sweeps;
      if (!sweep(x0, x, v, inv_mass, pole, s == 0)) break;
    }
    complete = within_boxes(x0, x);  // else a push left the candidates' reach: collect again
  }
  if (!complete) broad_phase(x0, x, inv_mass, /*shifted=*/true);
  freeze_fallback(x0, x, v, inv_mass, pole);
  return stats_;
}

}  // namespace flagsim

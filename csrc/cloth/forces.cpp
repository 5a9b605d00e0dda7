#include "cloth/forces.h"

#include <cmath>

#include <algorithm>
#include <array>
#include <limits>
#include <utility>

#include "common/parallel.h"

namespace flagsim {

namespace {
constexpr double kTinyLength = 1e-12;  // m; below this a spring has no direction

// The energy sums and the largest strain run over fixed chunks of at least kItemsPerReduceChunk
// vertices or springs (at most kMaxReduceChunks of each), each chunk's partial result combined
// in chunk order afterwards: the bits depend on the mesh only, never on the thread count or on
// which thread ran a chunk, and a SideBySide helper with nothing left of its own takes chunks
// (run_chunks). A mesh of one chunk sums as one loop does.
constexpr Index kItemsPerReduceChunk = 1024, kMaxReduceChunks = 64;
struct Chunks {
  Index size, count;  // items per chunk (the last may hold fewer), chunks
};
inline Chunks chunks_of(Index n) {
  const Index size = std::max(kItemsPerReduceChunk, (n + kMaxReduceChunks - 1) / kMaxReduceChunks);
  return {size, (n + size - 1) / size};
}

// Spring force on the first vertex, k (l - L) d/l (eq. 4). A spring of zero rest length is a
// linear spring k (x_j - x_i), defined even when both ends coincide.
inline Vec3 spring_force(const Vec3& d, double k, double L) {
  const double l = d.norm();
  if (l < kTinyLength) return L == 0.0 ? Vec3(k * d) : Vec3::Zero();
  return (k * (l - L) / l) * d;
}
}  // namespace

void add_gravity(const ClothTopology& topo, const Vec3& g, MatX3& f) {
  const Index n = topo.num_vertices();
  parallel_for(n, [&](Index i) { f.row(i) += topo.mass[i] * g.transpose(); });
}

void add_spring_forces(const ClothTopology& topo, const MatX3& x, const MatX3& v, MatX3& f) {
  const Index n = topo.num_vertices();
  parallel_for(n, [&](Index i) {
    Vec3 fi = Vec3::Zero();
    const Vec3 xi = x.row(i), vi = v.row(i);
    for (int32_t k = topo.adj_offset[i]; k < topo.adj_offset[i + 1]; ++k) {
      const int32_t s = topo.adj_spring[k], j = topo.adj_other[k];
      fi += spring_force(Vec3(x.row(j)) - xi, topo.stiffness[s], topo.rest_length[s]);
      fi += topo.damping[s] * (Vec3(v.row(j)) - vi);
    }
    f.row(i) += fi;
  });
}

namespace {

// Per-triangle relative air velocity w = mean(u) - mean(v), unit normal n and area A.
inline void triangle_frame(const ClothTopology& topo, Index t, const MatX3& x, const MatX3& v,
                           const MatX3& u, Vec3& w, Vec3& n, double& A) {
  const int a = topo.triangles(t, 0), b = topo.triangles(t, 1), c = topo.triangles(t, 2);
  const Vec3 cr = (Vec3(x.row(b)) - Vec3(x.row(a))).cross(Vec3(x.row(c)) - Vec3(x.row(a)));
  const double len = cr.norm();
  A = 0.5 * len;
  n = len > 0 ? Vec3(cr / len) : Vec3::Zero();
  w = (Vec3(u.row(a) + u.row(b) + u.row(c)) - Vec3(v.row(a) + v.row(b) + v.row(c))) / 3.0;
}

}  // namespace

void add_drag(const ClothTopology& topo, const DragParams& drag, double rho, const MatX3& x,
              const MatX3& v, const MatX3& u, MatX3& f) {
  const Index n = topo.num_vertices();
  const double c = 0.5 * drag.coefficient * rho;
  if (drag.model == DragModel::kPaper) {
    // eq. 3: D = 1/2 C_D rho S (|u| u - |v| v)
    parallel_for(n, [&](Index i) {
      const Vec3 ui = u.row(i), vi = v.row(i);
      f.row(i) += c * topo.area[i] * (ui.norm() * ui - vi.norm() * vi);
    });
  } else if (drag.model == DragModel::kRelative) {
    parallel_for(n, [&](Index i) {
      const Vec3 w = Vec3(u.row(i)) - Vec3(v.row(i));
      f.row(i) += c * topo.area[i] * w.norm() * w;
    });
  } else {  // "triangle": flat plate, F = 1/2 rho A (C_D |w.n| (w.n) n + C_T |w_t| w_t)
    const double ct = 0.5 * drag.tangential_coefficient * rho;
    parallel_for(n, [&](Index i) {
      Vec3 fi = Vec3::Zero();
      for (int32_t k = topo.tri_adj_offset[i]; k < topo.tri_adj_offset[i + 1]; ++k) {
        Vec3 w, nn;
        double A;
        triangle_frame(topo, topo.tri_adj[k], x, v, u, w, nn, A);
        const double wn = w.dot(nn);
        const Vec3 wt = w - wn * nn;
        fi += (A / 3.0) * (c * std::abs(wn) * wn * nn + ct * wt.norm() * wt);
      }
      f.row(i) += fi;
    });
  }
}

void spring_position_jacobians(const ClothTopology& topo, const MatX3& x, bool clamp_compression,
                               std::vector<SpringBlock>& K) {
  const Index S = topo.num_springs();
  K.resize(S);
  parallel_for(S, [&](Index s) {
    const Vec3 d = x.row(topo.springs(s, 1)) - x.row(topo.springs(s, 0));
    const double l = d.norm(), k = topo.stiffness[s], L = topo.rest_length[s];
    if (l < kTinyLength) {
      K[s].a = L == 0.0 ? k : 0.0;
      K[s].e.setZero();
      return;
    }
    // k [a (I - P) + P] = k a I + k (1 - a) P, a = 1 - L/l (clamped: max(0, that)), P = d d^T /
    // l^2; 1 - a = L/l >= 0 either way, so e is real.
    const double a = clamp_compression ? std::max(0.0, 1.0 - L / l) : 1.0 - L / l;
    K[s].a = k * a;
    K[s].e = (std::sqrt(k * (1.0 - a)) / l) * d;
  });
}

void apply_position_jacobian(const ClothTopology& topo, const std::vector<SpringBlock>& K,
                             const MatX3& p, MatX3& out) {
  const Index n = topo.num_vertices();
  out.resize(n, 3);
  parallel_for(n, [&](Index i) {
    Vec3 acc = Vec3::Zero();
    const Vec3 pi = p.row(i);
    for (int32_t k = topo.adj_offset[i]; k < topo.adj_offset[i + 1]; ++k)
      acc += K[topo.adj_spring[k]].apply(Vec3(p.row(topo.adj_other[k])) - pi);
    out.row(i) = acc;
  });
}

void drag_velocity_jacobians(const ClothTopology& topo, const DragParams& drag, double rho,
                             const MatX3& x, const MatX3& v, const MatX3& u, std::vector<Mat3>& Dv,
                             std::vector<Mat3>& Jw) {
  const Index n = topo.num_vertices();
  const double c = 0.5 * drag.coefficient * rho;
  Dv.resize(n);
  Jw.clear();
  // d(|a| a)/da = |a| I + a a^T / |a|
  auto dnorm = [](const Vec3& a) -> Mat3 {
    const double l = a.norm();
    if (l == 0) return Mat3::Zero();
    return l * Mat3::Identity() + a * a.transpose() / l;
  };
  if (drag.model == DragModel::kPaper) {
    // Exact: c S (|v| I + v v^T / |v|), which vanishes at rest, so a gust on a resting light flag
    // would get dv = h F / m. Adding c S |u| I changes the step by O(h^2) (first-order
    // consistency is kept) and bounds it: a free mass from rest gets dv -> u as h grows.
    for (Index i = 0; i < n; ++i)
      Dv[i] = c * topo.area[i] * (dnorm(v.row(i)) + Vec3(u.row(i)).norm() * Mat3::Identity());
  } else if (drag.model == DragModel::kRelative) {
    for (Index i = 0; i < n; ++i) Dv[i] = c * topo.area[i] * dnorm(Vec3(u.row(i)) - Vec3(v.row(i)));
  } else {
    for (Index i = 0; i < n; ++i) Dv[i].setZero();
    const double ct = 0.5 * drag.tangential_coefficient * rho;
    const Index T = topo.triangles.rows();
    Jw.resize(T);
    for (Index t = 0; t < T; ++t) {
      Vec3 w, nn;
      double A;
      triangle_frame(topo, t, x, v, u, w, nn, A);
      const double wn = w.dot(nn);
      const Mat3 N = nn * nn.transpose(), P = Mat3::Identity() - N;
      const Vec3 wt = P * w;
      const double lt = wt.norm();
      Mat3 J = c * 2.0 * std::abs(wn) * N;
      if (lt > 0) J += ct * (lt * P + wt * wt.transpose() / lt);
      Jw[t] = A * J;
    }
  }
}

void apply_velocity_jacobian(const ClothTopology& topo, const std::vector<Mat3>& Dv,
                             const std::vector<Mat3>& Jw, const MatX3& p, MatX3& out) {
  const Index n = topo.num_vertices();
  out.resize(n, 3);
  parallel_for(n, [&](Index i) {
    const Vec3 pi = p.row(i);
    Vec3 acc = Vec3::Zero();
    for (int32_t k = topo.adj_offset[i]; k < topo.adj_offset[i + 1]; ++k)
      acc += topo.damping[topo.adj_spring[k]] * (Vec3(p.row(topo.adj_other[k])) - pi);
    if (!Dv.empty()) acc -= Dv[i] * pi;
    if (!Jw.empty())
      for (int32_t k = topo.tri_adj_offset[i]; k < topo.tri_adj_offset[i + 1]; ++k) {
        const int32_t t = topo.tri_adj[k];
        const Vec3 sum =
            p.row(topo.triangles(t, 0)) + p.row(topo.triangles(t, 1)) + p.row(topo.triangles(t, 2));
        acc -= Jw[t] * sum / 9.0;
      }
    out.row(i) = acc;
  });
}

double stable_step_estimate(const ClothTopology& topo, const DragParams& drag, double rho,
                            bool has_drag, const MatX3& x, const MatX3& v, const MatX3& u) {
  // Gershgorin on M^-1/2 K M^-1/2 and M^-1/2 C M^-1/2, row i: sum over incident springs of
  // k (1/m_i + 1/sqrt(m_i m_j)). The spring's stiffness along and across its axis is bounded by
  // k max(1, |1 - L/l|).
  const Index n = topo.num_vertices();
  double lam = 0, gam = 0;
  for (Index i = 0; i < n; ++i) {
    if (topo.inv_mass[i] == 0) continue;
    const double mi = topo.mass[i];
    double ki = 0, ci = 0;
    for (int32_t k = topo.adj_offset[i]; k < topo.adj_offset[i + 1]; ++k) {
      const int32_t s = topo.adj_spring[k], j = topo.adj_other[k];
      const double l = (x.row(j) - x.row(i)).norm(), L = topo.rest_length[s];
      const double stiff =
          topo.stiffness[s] * std::max(1.0, l > kTinyLength ? std::abs(1 - L / l) : 1.0);
      const double w = 1.0 / mi + 1.0 / std::sqrt(mi * topo.mass[j]);
      ki += stiff * w;
      ci += topo.damping[s] * w;
    }
    if (has_drag) {
      // |d drag / d v| <= 2 x 1/2 C rho S |a| with a = v ("paper") or u - v; both are bounded by
      // |u| + |v|, which also covers a mass about to be accelerated towards the air speed.
      // "triangle" takes a factor 2 for a vertex's coupling to neighbours through triangles.
      const double a = Vec3(u.row(i)).norm() + Vec3(v.row(i)).norm();
      const double cd = drag.model == DragModel::kTriangle
                            ? 2.0 * std::max(drag.coefficient, drag.tangential_coefficient)
                            : drag.coefficient;
      ci += cd * rho * topo.area[i] * a / mi;
    }
    lam = std::max(lam, ki);
    gam = std::max(gam, 0.5 * ci);
  }
  if (lam == 0 && gam == 0) return std::numeric_limits<double>::infinity();
  return 2.0 / (gam + std::sqrt(gam * gam + lam));
}

namespace {
// The largest strain so far and its first spring (-1: none above 0). A NaN strain wins over any
// number (its first spring).
struct StrainMax {
  double m = 0;
  Index w = -1;
  void take(double e, Index s) {
    if (!(e <= m) && !std::isnan(m)) {
      m = e;
      w = s;
    }
  }
};

// Springs [s0, end): the sum of 1/2 k (l - L)^2 in order (when energy) and the largest strain
// of those with L > 0 (when strain).
struct SpringSums {
  double energy = 0;
  StrainMax strain;
};
SpringSums spring_chunk(const ClothTopology& topo, const MatX3& x, Index s0, Index end, bool energy,
                        bool strain) {
  SpringSums out;
  for (Index s = s0; s < end; ++s) {
    const double L = topo.rest_length[s];
    if (!energy && !(L > 0)) continue;
    const double l = (x.row(topo.springs(s, 1)) - x.row(topo.springs(s, 0))).norm();
    if (energy) out.energy += 0.5 * topo.stiffness[s] * (l - L) * (l - L);
    if (strain && L > 0) out.strain.take((l - L) / L, s);
  }
  return out;
}

// The chunks' largest strains combined in chunk order: the first spring with the largest strain,
// as one loop over the springs finds it.
StrainMax first_largest(const std::array<StrainMax, kMaxReduceChunks>& part, Index count) {
  StrainMax sm;
  for (Index c = 0; c < count; ++c)
    if (part[std::size_t(c)].w >= 0) sm.take(part[std::size_t(c)].m, part[std::size_t(c)].w);
  return sm;
}

// cloth_energy, and into *strain (when not null) max_strain of the same lengths.
ClothEnergy energy_pass(const ClothTopology& topo, const Vec3& g, const MatX3& x, const MatX3& v,
                        StrainMax* strain) {
  const Index n = topo.num_vertices(), S = topo.num_springs();
  const Chunks cv = chunks_of(n), cs = chunks_of(S);
  std::array<ClothEnergy, 2 * kMaxReduceChunks> part;   // vertex chunks, then spring chunks
  std::array<StrainMax, kMaxReduceChunks> part_strain;  // spring chunks
  run_chunks(n + S >= kParallelGrain, cv.count + cs.count, [&](Index c) {
    ClothEnergy e;
    if (c < cv.count) {
      for (Index i = c * cv.size, end = std::min(n, i + cv.size); i < end; ++i) {
        e.kinetic += 0.5 * topo.mass[i] * v.row(i).squaredNorm();
        e.gravity -= topo.mass[i] * g.dot(Vec3(x.row(i)));
      }
    } else {
      const Index s0 = (c - cv.count) * cs.size;
      const SpringSums sums =
          spring_chunk(topo, x, s0, std::min(S, s0 + cs.size), true, strain != nullptr);
      e.spring = sums.energy;
      part_strain[std::size_t(c - cv.count)] = sums.strain;
    }
    part[std::size_t(c)] = e;
  });
  ClothEnergy e;
  for (Index c = 0; c < cv.count; ++c) {
    e.kinetic += part[std::size_t(c)].kinetic;
    e.gravity += part[std::size_t(c)].gravity;
  }
  for (Index c = cv.count; c < cv.count + cs.count; ++c) e.spring += part[std::size_t(c)].spring;
  if (strain) *strain = first_largest(part_strain, cs.count);
  return e;
}
}  // namespace

ClothEnergy cloth_energy(const ClothTopology& topo, const Vec3& g, const MatX3& x, const MatX3& v) {
  return energy_pass(topo, g, x, v, nullptr);
}

ClothEnergy cloth_energy_and_max_strain(const ClothTopology& topo, const Vec3& g, const MatX3& x,
                                        const MatX3& v, double& strain, Index* worst) {
  StrainMax sm;
  const ClothEnergy e = energy_pass(topo, g, x, v, &sm);
  strain = sm.m;
  if (worst) *worst = sm.w;
  return e;
}

double total_energy(const ClothTopology& topo, const Vec3& g, const MatX3& x, const MatX3& v) {
  return cloth_energy(topo, g, x, v).total();
}

double max_strain(const ClothTopology& topo, const MatX3& x, Index* worst) {
  const Index S = topo.num_springs();
  const Chunks cs = chunks_of(S);
  std::array<StrainMax, kMaxReduceChunks> part;
  run_chunks(S >= kParallelGrain, cs.count, [&](Index c) {
    const Index s0 = c * cs.size;
    part[std::size_t(c)] = spring_chunk(topo, x, s0, std::min(S, s0 + cs.size), false, true).strain;
  });
  const StrainMax sm = first_largest(part, cs.count);
  if (worst) *worst = sm.w;
  return sm.m;
}

}  // namespace flagsim

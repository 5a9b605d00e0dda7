#include "cloth/integrators.h"

#include <cmath>

#include "common/parallel.h"

#include "common/timer.h"

namespace flagsim {

IntegratorScratch::IntegratorScratch(const ClothTopology& topo) {
  const Index n = topo.num_vertices();
  for (MatX3* m : {&f, &x0, &v0, &dv, &r, &z, &p, &q, &b, &tmp, &dv_prev}) m->setZero(n, 3);
  sys.B.resize(topo.num_springs());
  sys.D.resize(n);
  sys.J.reserve(topo.triangles.rows());
  sys.diag.resize(n);
  sys.Pinv.resize(n);
  sys.off.build(topo);
  if (multigrid_applies(topo)) multigrid_build(topo, mg);
}

void compute_forces(const ClothTopology& topo, const ForceSet& fs, const MatX3& x, const MatX3& v,
                    const MatX3& u, MatX3& f, ForceTimings* t) {
  static thread_local ForceTimings unused;
  ForceTimings& tm = t ? *t : unused;
  f.setZero();
  if (fs.gravity) {
    ScopedTimer timer(tm.gravity);
    add_gravity(topo, fs.g, f);
  }
  if (fs.drag) {
    ScopedTimer timer(tm.drag);
    add_drag(topo, fs.drag_params, fs.rho, x, v, u, f);
  }
  if (fs.springs) {
    ScopedTimer timer(tm.springs);
    add_spring_forces(topo, x, v, f);
  }
}

namespace {

// Zero the rows of pinned vertices (Baraff-Witkin's filter S for fully constrained vertices).
inline void filter_pinned(const ClothTopology& topo, MatX3& a) {
  for (Index i = 0; i < a.rows(); ++i)
    if (topo.inv_mass[i] == 0.0) a.row(i).setZero();
}

// Multigrid when asked for ("auto": on grids of at least kAutoMultigridVertices vertices, where it
// measured faster; docs/design.md) and when the topology is a grid it can coarsen.
constexpr Index kAutoMultigridVertices = 200;
bool use_multigrid(const ClothTopology& topo, const IntegratorParams& ip, const IntegratorScratch& s) {
  if (s.mg.levels.empty() || ip.preconditioner == "jacobi") return false;
  return ip.preconditioner == "multigrid" || topo.num_vertices() >= kAutoMultigridVertices;
}

// Symplectic Euler over h. With ip.adaptive, every substep is at most safety x the stable step
// estimated from the state at its start (the state can stiffen within a step: a gust accelerates
// the masses, a stretched spring stiffens), and the substep count is bounded by max_substeps.
IntegrateStatus explicit_step(const ClothTopology& topo, const ForceSet& fs,
                              const IntegratorParams& ip, double h, const MatX3& u, MatX3& x,
                              MatX3& v, IntegratorScratch& s, IntegratorStats& stats,
                              ForceTimings* t) {
  const Index N = topo.num_vertices();
  double done = 0;
  long n = 0;
  while (done < h) {
    double hs = h - done;
    const double stable = stable_step_estimate(topo, fs.drag_params, fs.rho, fs.drag, x, v, u);
    if (n == 0) stats.stable_step = stable;
    if (!ip.adaptive && hs > stable) return IntegrateStatus::kUnstableStep;
    if (ip.adaptive) {
      const double remaining_pieces = std::ceil(hs / (ip.safety * stable));
      if (remaining_pieces + n > ip.max_substeps) return IntegrateStatus::kTooManySubsteps;
      hs = hs / remaining_pieces;  // even pieces of what is left, each below the stable step
    }
    compute_forces(topo, fs, x, v, u, s.f, t);
    // symplectic Euler: v <- v + h M^-1 f(x, v); x <- x + h v
    parallel_for(N, [&](Index i) {
      v.row(i) += (hs * topo.inv_mass[i]) * s.f.row(i);
      x.row(i) += hs * v.row(i);
    });
    if (ip.strain_limit > 0) {
      ScopedTimer timer(t ? t->strain_limit : s.unused_timer);
      limit_strain(topo, ip.strain_limit, ip.strain_limit_iterations, hs, x, v);
    }
    ++n;
    done = (h - done <= hs) ? h : done + hs;
  }
  stats.substeps = n;
  return IntegrateStatus::kOk;
}

}  // namespace

void assemble_implicit_system(const ClothTopology& topo, const ForceSet& fs, double h,
                              const MatX3& x, const MatX3& v, const MatX3& u, ClothSystem& A,
                              MatX3& Kv) {
  const Index N = topo.num_vertices();
  if (fs.springs) {
    spring_position_jacobians(topo, x, /*clamp_compression=*/true, A.B);
  } else {
    for (auto& k : A.B) k = SpringBlock{};
  }
  if (fs.drag) {
    drag_velocity_jacobians(topo, fs.drag_params, fs.rho, x, v, u, A.D, A.J);
  } else {
    for (auto& d : A.D) d.setZero();
    A.J.clear();
  }
  apply_position_jacobian(topo, A.B, v, Kv);
  // Fold h and the masses into A's terms (see ClothSystem): B_s = h^2 K_s + h k_d I.
  const Index S = topo.num_springs();
  parallel_for(S, [&](Index sp) {
    A.B[sp].a = (h * h) * A.B[sp].a + h * topo.damping[sp];
    A.B[sp].e *= h;
  });
  parallel_for(N, [&](Index i) { A.D[i] = topo.mass[i] * Mat3::Identity() + h * A.D[i]; });
  for (auto& j : A.J) j *= h / 9.0;
  // A's 3x3 diagonal blocks and their inverses (block Jacobi and the Gauss-Seidel smoother).
  // The spring blocks a I + e e^T are added entry by entry in scalars: the same sums as adding
  // B.matrix(), without the Mat3 temporaries whose mixed scalar stores and vector loads stalled
  // store forwarding (this loop was 6 % of the paper scene's step).
  parallel_for(N, [&](Index i) {
    Mat3 D = A.D[i];
    double d[3][3];
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) d[r][c] = D(r, c);
    for (int32_t k = topo.adj_offset[i]; k < topo.adj_offset[i + 1]; ++k) {
      const SpringBlock& B = A.B[topo.adj_spring[k]];
      const double e[3] = {B.e[0], B.e[1], B.e[2]};
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) d[r][c] += r == c ? B.a + e[r] * e[c] : e[r] * e[c];
    }
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) D(r, c) = d[r][c];
    if (!A.J.empty())
      for (int32_t k = topo.tri_adj_offset[i]; k < topo.tri_adj_offset[i + 1]; ++k)
        D += A.J[topo.tri_adj[k]];
    A.diag[i] = D;
    A.Pinv[i] = D.inverse();
  });
  A.off.fill(topo, A.B);
}

namespace {

// Preconditioner z = P^-1 r: one multigrid cycle, or block Jacobi z_i = D_i^-1 r_i. Returns r.z.
double precondition(const ClothTopology& topo, IntegratorScratch& s, bool multigrid, const MatX3& r,
                    MatX3& z) {
  if (multigrid) {
    multigrid_vcycle(topo, s.sys, s.mg, r, z);
    return dot(r, z);
  }
  double rz = 0;
  const Index N = topo.num_vertices();
  for (Index i = 0; i < N; ++i) {
    if (topo.inv_mass[i] == 0.0) {
      z.row(i).setZero();
      continue;
    }
    const Vec3 ri = r.row(i);
    const Vec3 zi = s.sys.Pinv[i] * ri;
    z.row(i) = zi.transpose();
    rz += ri.dot(zi);
  }
  return rz;
}

// One linearised backward Euler step (Baraff-Witkin eq. 16):
// (M - h df/dv - h^2 df/dx) dv = h (f0 + h df/dx v0), then v += dv, x += h v.
IntegrateStatus implicit_once(const ClothTopology& topo, const ForceSet& fs,
                              const IntegratorParams& ip, double h, const MatX3& u, MatX3& x,
                              MatX3& v, IntegratorScratch& s, IntegratorStats& stats,
                              ForceTimings* t) {
  const Index N = topo.num_vertices();
  ClothSystem& A = s.sys;
  compute_forces(topo, fs, x, v, u, s.f, t);
  assemble_implicit_system(topo, fs, h, x, v, u, A, s.tmp);
  // b = h (f0 + h K v0)
  s.b = h * (s.f + h * s.tmp);
  filter_pinned(topo, s.b);
  const bool multigrid = use_multigrid(topo, ip, s);
  if (multigrid) multigrid_setup(topo, A, s.mg);

  // PCG warm start: the point of the line through the last two steps' dv, dv_1 + theta (dv_1 -
  // dv_2), closest to the solution in A's energy norm, theta = r_1 . d / d^T A d (one more
  // product). Never further than dv_1 alone in that norm, so never worse than it when the motion
  // turns, and near the straight-line extrapolation (theta ~ 1) when it is smooth.
  filter_pinned(topo, s.dv);
  apply_system(topo, A, s.dv, s.q);
  s.r = s.b - s.q;
  s.z = s.dv - s.dv_prev;  // d (zero rows where pinned: both are filtered)
  s.dv_prev = s.dv;
  apply_system(topo, A, s.z, s.p);
  const double dAd = dot(s.z, s.p);
  if (dAd > 0) {
    const double theta = dot(s.r, s.z) / dAd;
    s.dv += theta * s.z;
    s.r -= theta * s.p;
  }
  const double bnorm = s.b.norm();
  if (bnorm == 0.0) {
    s.dv.setZero();
  } else {
    const double tol2 = (ip.cg_tolerance * bnorm) * (ip.cg_tolerance * bnorm);
    int it = 0;
    bool converged = s.r.squaredNorm() <= tol2;
    double rz = 0;
    if (!converged) {
      rz = precondition(topo, s, multigrid, s.r, s.z);
      s.p = s.z;
    }
    for (; !converged && it < ip.cg_max_iterations; ++it) {
      apply_system(topo, A, s.p, s.q);
      const double pq = dot(s.p, s.q);
      if (!(pq > 0)) break;  // not SPD along p (or NaN): give up, the caller halves h
      const double alpha = rz / pq;
      s.dv += alpha * s.p;
      s.r -= alpha * s.q;
      if (s.r.squaredNorm() <= tol2) {
        converged = true;
        ++it;
        break;
      }
      const double rz_new = precondition(topo, s, multigrid, s.r, s.z);
      // Multigrid's K-cycle is not quite linear: flexible CG (Polak-Ribiere, Notay 2000),
      // beta = z_new . (r_new - r_old) / rz_old with r_new - r_old = -alpha q. Equal to
      // rz_new / rz_old in exact arithmetic for a fixed preconditioner (block Jacobi keeps that).
      const double beta = multigrid ? -alpha * dot(s.z, s.q) / rz : rz_new / rz;
      s.p = s.z + beta * s.p;
      rz = rz_new;
    }
    stats.cg_iterations += it;
    if (!converged) return IntegrateStatus::kCgFailed;
  }
  parallel_for(N, [&](Index i) {
    v.row(i) += s.dv.row(i);
    x.row(i) += h * v.row(i);
  });
  if (ip.strain_limit > 0) {
    ScopedTimer timer(t ? t->strain_limit : s.unused_timer);
    limit_strain(topo, ip.strain_limit, ip.strain_limit_iterations, h, x, v);
  }
  return IntegrateStatus::kOk;
}

// Implicit step of h; if CG fails, restart from the same state with two steps of h/2, and so on
// down to ip.max_halvings levels.
IntegrateStatus implicit_step(const ClothTopology& topo, const ForceSet& fs,
                              const IntegratorParams& ip, double h, const MatX3& u, MatX3& x,
                              MatX3& v, IntegratorScratch& s, IntegratorStats& stats,
                              ForceTimings* t) {
  for (int level = 0; level <= ip.max_halvings; ++level) {
    const long pieces = 1L << level;
    const double hp = h / double(pieces);
    s.x0 = x;
    s.v0 = v;
    bool ok = true;
    for (long k = 0; k < pieces && ok; ++k)
      ok = implicit_once(topo, fs, ip, hp, u, x, v, s, stats, t) == IntegrateStatus::kOk;
    if (ok) return IntegrateStatus::kOk;
    x = s.x0;
    v = s.v0;
    s.dv.setZero();  // the extrapolation's steps were of another length
    s.dv_prev.setZero();
    ++stats.halvings;
  }
  return IntegrateStatus::kCgFailed;
}

}  // namespace

IntegrateStatus integrate(const ClothTopology& topo, const ForceSet& fs, const IntegratorParams& ip,
                          double h, const MatX3& u, MatX3& x, MatX3& v, IntegratorScratch& s,
                          IntegratorStats& stats, ForceTimings* t) {
  stats = IntegratorStats{};
  const double hs = h / double(ip.substeps);
  long explicit_substeps = 0;
  for (int k = 0; k < ip.substeps; ++k) {
    IntegrateStatus st;
    if (ip.method == "explicit") {
      st = explicit_step(topo, fs, ip, hs, u, x, v, s, stats, t);
      explicit_substeps += stats.substeps;
    } else if (ip.method == "implicit") {
      st = implicit_step(topo, fs, ip, hs, u, x, v, s, stats, t);
    } else {
      throw std::logic_error("integrate: unknown method '" + ip.method + "' (validate() lets none through)");
    }
    if (st != IntegrateStatus::kOk) return st;
  }
  if (ip.method == "explicit") stats.substeps = explicit_substeps;
  return IntegrateStatus::kOk;
}

void limit_strain(const ClothTopology& topo, double limit, int iterations, double h, MatX3& x,
                  MatX3& v) {
  // Long-range attachments first: one exact projection per vertex onto the ball of radius
  // (1 + limit) x rest distance around its nearest pin removes gross stretch in a single pass
  // (Gauss-Seidel over springs alone needs O(cols^2) sweeps for that).
  const Index N = topo.num_vertices();
  for (Index i = 0; i < N; ++i) {
    const int32_t a = topo.tether_anchor[i];
    if (a < 0) continue;
    const Vec3 d = x.row(i) - x.row(a);
    const double l = d.norm(), lmax = (1.0 + limit) * topo.tether_length[i];
    if (l <= lmax) continue;
    const Vec3 corr = d * (lmax / l - 1.0);
    x.row(i) += corr.transpose();
    v.row(i) += corr.transpose() / h;
  }
  // Then Provot's local projection, Gauss-Seidel over springs in index order: deterministic.
  for (int it = 0; it < iterations; ++it) {
    bool violated = false;
    for (Index s = 0; s < topo.num_springs(); ++s) {
      if (topo.spring_kind[s] == SpringKind::kBend) continue;  // bending is not stretching
      const int a = topo.springs(s, 0), b = topo.springs(s, 1);
      const double wa = topo.inv_mass[a], wb = topo.inv_mass[b];
      if (wa + wb == 0) continue;
      const Vec3 d = x.row(b) - x.row(a);
      const double l = d.norm(), lmax = (1.0 + limit) * topo.rest_length[s];
      if (l <= lmax || l == 0) continue;
      violated = violated || l > lmax * 1.001;
      const Vec3 corr = (l - lmax) / l * d / (wa + wb);
      x.row(a) += wa * corr.transpose();
      x.row(b) -= wb * corr.transpose();
      v.row(a) += (wa / h) * corr.transpose();
      v.row(b) -= (wb / h) * corr.transpose();
    }
    if (!violated) break;
  }
}

}  // namespace flagsim

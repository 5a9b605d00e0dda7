#include "cloth/integrators.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "common/parallel.h"

#include "common/timer.h"

namespace flagsim {

IntegratorScratch::IntegratorScratch(const ClothTopology& topo) {
  const Index n = topo.num_vertices();
  for (MatX3* m :
       {&f, &fd, &x0, &v0, &dv, &r, &z, &p, &q, &b, &tmp, &t, &u, &Dw, &dv_prev, &impulse0})
    m->setZero(n, 3);
  held.reserve(std::size_t(n));
  is_held.assign(std::size_t(n), 0);
  sys.B.resize(topo.num_springs());
  sys.D.resize(n);
  sys.J.reserve(topo.triangles.rows());
  sys.diag.resize(n);
  sys.Pinv.resize(n);
  sys.off.build(topo);
  if (multigrid_applies(topo)) multigrid_build(topo, mg);
}

void compute_forces(const ClothTopology& topo, const ForceSet& fs, const MatX3& x, const MatX3& v,
                    const MatX3& u, MatX3& f, MatX3& drag, StageClock* t) {
  f.setZero();
  if (fs.gravity) {
    StageClock::Scope timer(t, Stage::kGravity);
    add_gravity(topo, fs.g, f);
  }
  if (fs.drag) {
    StageClock::Scope timer(t, Stage::kDrag);
    drag.setZero();
    add_drag(topo, fs.drag_params, fs.rho, x, v, u, drag);
    if (fs.drag_scale) drag.array().colwise() *= fs.drag_scale->array();
    f += drag;
  }
  if (fs.springs) {
    StageClock::Scope timer(t, Stage::kSprings);
    add_spring_forces(topo, x, v, f);
  }
  if (fs.external) f += *fs.external;
}

namespace {

// Zero the rows of pinned vertices (Baraff-Witkin's filter S for fully constrained vertices).
inline void filter_pinned(const ClothTopology& topo, MatX3& a) {
  for (Index i = 0; i < a.rows(); ++i)
    if (topo.inv_mass[i] == 0.0) a.row(i).setZero();
}

// The speed of vertex i's contact plane along its normal over the piece, m/s (0: still).
inline double plane_speed(const ForceSet& fs, Index i) {
  return fs.contact_speed ? (*fs.contact_speed)[i] : 0.0;
}

// How far vertex i is out of its contact plane (normal n) as the plane is `left` s before the
// piece's end, at offset - w left, m: <= 0 touching. At the piece's start, left = h.
inline double plane_gap(const ForceSet& fs, const MatX3& x, Index i, const Vec3& n, double left) {
  return x.row(i).dot(n) - ((*fs.contact_offset)[i] - plane_speed(fs, i) * left);
}

// The contacts the solve holds first: those of fs.contacts that touch (on or inside their plane
// at the piece's start), that the forces f push into their solid and whose velocity does not
// leave it (move out faster than the plane). A vertex the last solve held has v . n = w to
// round-off: "leaves" means faster than kLeaving beyond it, so that round-off of either sign does
// not decide it. They end the piece moving with the plane.
constexpr double kLeaving = 1e-9;  // m/s
void hold_contacts(const ClothTopology& topo, const ForceSet& fs, const MatX3& f, const MatX3& x,
                   const MatX3& v, double h, IntegratorScratch& s) {
  for (const RestingContact& c : s.held) s.is_held[std::size_t(c.vertex)] = 0;
  s.held.clear();
  if (!fs.contacts) return;
  const MatX3& normal = *fs.contacts;
  for (Index i = 0; i < normal.rows(); ++i) {
    const Vec3 n = row(normal, i);
    if (topo.inv_mass[i] == 0.0 || n.isZero()) continue;
    const double w = plane_speed(fs, i);
    if (plane_gap(fs, x, i, n, h) <= 0 && f.row(i).dot(n) < 0 && v.row(i).dot(n) <= w + kLeaving) {
      s.held.push_back({int32_t(i), n, w, w});
      s.is_held[std::size_t(i)] = 1;
    }
  }
}

// Contacts of fs.contacts not held yet that the answer v + dv (and the drift) leaves more than
// kCrossing behind their plane at the piece's end: held from now on, ending the piece on the
// plane (approach w - gap / h, gap >= 0 at the start). Returns how many were added.
constexpr double kCrossing = 1e-6;  // m
constexpr int kContactRounds = 3;
std::size_t hold_crossing(const ClothTopology& topo, const ForceSet& fs, const MatX3& x,
                          const MatX3& v, const MatX3& dv, double h, IntegratorScratch& s) {
  if (!fs.contacts) return 0;
  const std::size_t before = s.held.size();
  const MatX3& normal = *fs.contacts;
  for (Index i = 0; i < normal.rows(); ++i) {
    const Vec3 n = row(normal, i);
    if (topo.inv_mass[i] == 0.0 || n.isZero() || s.is_held[std::size_t(i)]) continue;
    const double w = plane_speed(fs, i), gap = std::max(0.0, plane_gap(fs, x, i, n, h));
    // The end velocity and the drift (eq. 5 "displace") carry the vertex over the piece.
    const double drift = fs.drift ? fs.drift->row(i).dot(n) : 0.0;
    if (h * ((v.row(i) + dv.row(i)).dot(n) + drift) < h * w - gap - kCrossing) {
      s.held.push_back({int32_t(i), n, w - gap / h, w});
      s.is_held[std::size_t(i)] = 1;
    }
  }
  return s.held.size() - before;
}

// Baraff-Witkin's filter S = I - n n^T on the held contacts' rows.
inline void filter_held(const RestingContact* held, std::size_t n, MatX3& a) {
  for (std::size_t k = 0; k < n; ++k) {
    const RestingContact& c = held[k];
    const double an = a.row(c.vertex).dot(c.normal);
    a.row(c.vertex) -= an * c.normal.transpose();
  }
}
inline void filter_held(const std::vector<RestingContact>& held, MatX3& a) {
  filter_held(held.data(), held.size(), a);
}

// a without its component into the surface (along -n) on the held rows.
inline void filter_inward(const std::vector<RestingContact>& held, MatX3& a) {
  for (const RestingContact& c : held) {
    const double an = a.row(c.vertex).dot(c.normal);
    if (an < 0) a.row(c.vertex) -= an * c.normal.transpose();
  }
}

// dv = S dv + z, z = (approach - v . n) n on the held rows: velocity `approach` along n at the
// piece's end.
inline void prescribe_held(const std::vector<RestingContact>& held, const MatX3& v, MatX3& dv) {
  filter_held(held, dv);
  for (const RestingContact& c : held)
    dv.row(c.vertex) += (c.approach - v.row(c.vertex).dot(c.normal)) * c.normal.transpose();
}

// The gravity the energy bookkeeping sees: none when the stage is not built.
inline Vec3 gravity_of(const ForceSet& fs) { return fs.gravity ? fs.g : Vec3::Zero(); }

// Work of forces f (N x 3) over the displacement h v (N x 3), J.
double work_over(const MatX3& f, const MatX3& v, double h) {
  double w = 0;
  for (Index i = 0; i < f.rows(); ++i) w += f.row(i).dot(v.row(i));
  return h * w;
}

// Work of spring damping k_d (a_j - a_i) (eq. 4, velocities a as the integrator applied it) over
// the displacement h b, J: sum over springs of k_d (a_j - a_i) . h (b_i - b_j).
double damping_work(const ClothTopology& topo, const MatX3& a, const MatX3& b, double h) {
  double w = 0;
  for (Index s = 0; s < topo.num_springs(); ++s) {
    const double kd = topo.damping[s];
    if (kd == 0) continue;
    const int i = topo.springs(s, 0), j = topo.springs(s, 1);
    w += kd * (a.row(j) - a.row(i)).dot(b.row(i) - b.row(j));
  }
  return h * w;
}

// Work of the pins on pinned vertices that move with velocity v over h: they hold the vertex
// against the force f on it, so they do -f . h v, J. Zero for pins at rest. f must be the force
// the integrator applied (explicit: at the substep's start; implicit: pinned_forces_applied),
// the one whose reaction the free vertices felt: then the remainder is the same in a frame that
// moves with the pins (docs/design.md "Moving pins and Galilean invariance").
double pin_work(const ClothTopology& topo, const MatX3& f, const MatX3& v, double h) {
  double w = 0;
  for (Index i = 0; i < topo.num_vertices(); ++i)
    if (topo.inv_mass[i] == 0.0) w -= f.row(i).dot(v.row(i));
  return h * w;
}

// The work of the forces as the integrator applied them over the displacement h v (J, into
// work): the drag s.fd, the external force, spring damping at velocities a, and the pins (s.f on
// pinned vertices that move; their v is the same before and after a step). A drift books its own.
void book_force_work(const ClothTopology& topo, const ForceSet& fs, const MatX3& a, const MatX3& v,
                     double h, const IntegratorScratch& s, StepWork& work) {
  if (fs.drag) work.drag += work_over(s.fd, v, h);
  if (fs.drag && fs.drag_impulse) *fs.drag_impulse += h * s.fd;
  if (fs.external) work.external += work_over(*fs.external, v, h);
  work.damping += damping_work(topo, a, v, h);
  work.pins += pin_work(topo, s.f, v, h);
}

// total_energy, timed as the plausibility check's bookkeeping (Stage::kCheck).
double timed_energy(const ClothTopology& topo, const ForceSet& fs, const MatX3& x, const MatX3& v,
                    IntegratorScratch& /*s*/, StageClock* t) {
  StageClock::Scope timer(t, Stage::kCheck);
  return total_energy(topo, gravity_of(fs), x, v);
}

// Minus the work of the conservative forces (springs, gravity) as the integrator applied them,
// f_c = f - drag - k_d (a_j - a_i) - external with f the total applied force (explicit: at the
// substep's start, damping at velocities a = v; implicit: M dv / h, a = v'), over the drift's
// share h r of the displacement (r: fs.drift as applied), J. The first-order work of the prescribed
// motion: what is left of the change of potential energy is the integrator's own, in its remainder
// (docs/energy.md). Pinned rows have no drift.
double drift_work(const ClothTopology& topo, const ForceSet& fs, const MatX3& r, const MatX3& f,
                  const MatX3& a, const MatX3& fd, double h) {
  double w = 0;
  for (Index i = 0; i < topo.num_vertices(); ++i) {
    if (topo.inv_mass[i] == 0.0) continue;
    Vec3 fc = f.row(i);
    for (int32_t k = topo.adj_offset[i]; k < topo.adj_offset[i + 1]; ++k)
      fc -= topo.damping[topo.adj_spring[k]] * (Vec3(a.row(topo.adj_other[k])) - Vec3(a.row(i)));
    if (fs.drag) fc -= Vec3(fd.row(i));
    if (fs.external) fc -= Vec3(fs.external->row(i));
    w -= fc.dot(Vec3(r.row(i)));
  }
  return h * w;
}

// The preconditioner a solve runs: multigrid when asked for ("auto": on grids of at least
// kAutoMultigridVertices vertices, where it measured faster; docs/design.md) and when the topology
// is a grid it can coarsen, else block Jacobi when asked for, else SSOR.
constexpr Index kAutoMultigridVertices = 500;
Preconditioner preconditioner_for(const ClothTopology& topo, const IntegratorParams& ip,
                                  const IntegratorScratch& s) {
  switch (ip.preconditioner) {
    case Preconditioner::kJacobi: return Preconditioner::kJacobi;
    case Preconditioner::kSsor: return Preconditioner::kSsor;
    case Preconditioner::kMultigrid:
      return s.mg.levels.empty() ? Preconditioner::kJacobi : Preconditioner::kMultigrid;
    case Preconditioner::kAuto:
      return !s.mg.levels.empty() && topo.num_vertices() >= kAutoMultigridVertices
                 ? Preconditioner::kMultigrid
                 : Preconditioner::kSsor;
  }
  throw std::logic_error("preconditioner_for: unknown preconditioner");
}

// Explicit substeps hold no contact inside their update: a vertex a substep carries through its
// contact plane (ForceSet::contacts, where it is at the substep's end, `left` s before the
// piece's) is put back on it and loses its velocity into it beyond the plane's own. Substeps are
// short, so each such move is small; at the end of the step the pole and solids stages would
// otherwise push back a whole step's worth at once, against the springs. The planes' impulse
// goes to work.contact_impulse, a moving plane's work (impulse . w n) to work.pins.
void keep_out_of_planes(const ClothTopology& topo, const ForceSet& fs, double left, MatX3& x,
                        MatX3& v, StepWork& work) {
  if (!fs.contacts) return;
  const MatX3& normal = *fs.contacts;
  for (Index i = 0; i < normal.rows(); ++i) {
    const Vec3 n = row(normal, i);
    const double w = plane_speed(fs, i), gap = plane_gap(fs, x, i, n, left);
    if (!(gap < 0) || n.isZero() || topo.inv_mass[i] == 0.0) continue;
    x.row(i) -= gap * n.transpose();
    const double vn = v.row(i).dot(n);
    if (vn < w) {
      v.row(i) += (w - vn) * n.transpose();
      const double jn = topo.mass[i] * (w - vn);
      work.contact_impulse += jn * n;
      work.pins += jn * w;
    }
  }
}

// Symplectic Euler over h. With ip.adaptive, every substep is at most safety x the stable step
// estimated from the state at its start (the state can stiffen within a step: a gust accelerates
// the masses, a stretched spring stiffens), and the substep count is bounded by max_substeps.
IntegrateStatus explicit_step(const ClothTopology& topo, const ForceSet& fs,
                              const IntegratorParams& ip, double h, const MatX3& u, MatX3& x,
                              MatX3& v, IntegratorScratch& s, IntegratorStats& stats,
                              StepWork& work, StageClock* t) {
  const Index N = topo.num_vertices();
  double done = 0;
  long n = 0;
  while (done < h) {
    double hs = h - done;
    const double stable = stable_step_estimate(topo, fs.drag_params, fs.rho, fs.drag, x, v, u);
    if (n == 0) stats.stable_step = stable;
    if (!ip.adaptive && hs > stable) return IntegrateStatus::kUnstableStep;
    if (ip.adaptive) {
      const double remaining_pieces = std::ceil(hs / (ip.safety * fs.refine * stable));
      if (remaining_pieces + n > ip.max_substeps) return IntegrateStatus::kTooManySubsteps;
      hs = hs / remaining_pieces;  // even pieces of what is left, each below the stable step
    }
    compute_forces(topo, fs, x, v, u, s.f, s.fd, t);
    s.v0 = v;
    // symplectic Euler: v <- v + h M^-1 f(x, v); x <- x + h v
    parallel_for(N, [&](Index i) {
      v.row(i) += (hs * topo.inv_mass[i]) * s.f.row(i);
      x.row(i) += hs * v.row(i);
    });
    if (fs.drift) x += hs * *fs.drift;
    {
      StageClock::Scope timer(t, Stage::kCheck);
      if (fs.drift) work.drift += drift_work(topo, fs, *fs.drift, s.f, s.v0, s.fd, hs);
      book_force_work(topo, fs, s.v0, v, hs, s, work);  // forces at the substep's start
    }
    keep_out_of_planes(topo, fs, h - done <= hs ? 0.0 : h - (done + hs), x, v, work);
    if (ip.strain_limit > 0) {
      StageClock::Scope timer(t, Stage::kStrainLimit);
      work.strain_limit +=
          limit_strain_work(topo, gravity_of(fs), ip.strain_limit, ip.strain_limit_iterations, x, v,
                            fs.contacts, fs.contact_offset, &work.pins, fs.contact_speed);
    }
    ++n;
    done = (h - done <= hs) ? h : done + hs;
  }
  stats.substeps = n;
  return IntegrateStatus::kOk;
}

// The drag Jacobians times each mass's factor; a triangle block by the mean of its three.
void scale_drag_jacobians(const ClothTopology& topo, const VecX& scale, ClothSystem& A) {
  for (Index i = 0; i < topo.num_vertices(); ++i) A.D[i] *= scale[i];
  for (std::size_t t = 0; t < A.J.size(); ++t)
    A.J[t] *= (scale[topo.triangles(Index(t), 0)] + scale[topo.triangles(Index(t), 1)] +
               scale[topo.triangles(Index(t), 2)]) /
              3.0;
}

}  // namespace

void assemble_implicit_system(const ClothTopology& topo, const ForceSet& fs, double h,
                              const MatX3& x, const MatX3& v, const MatX3& u, ClothSystem& A,
                              MatX3& Kv, const MatX3* moving_velocity) {
  const MatX3& moving = moving_velocity ? *moving_velocity : v;
  const Index N = topo.num_vertices();
  if (fs.springs) {
    spring_position_jacobians(topo, x, /*clamp_compression=*/true, A.B);
  } else {
    for (auto& k : A.B) k = SpringBlock{};
  }
  if (fs.drag) {
    drag_velocity_jacobians(topo, fs.drag_params, fs.rho, x, v, u, A.D, A.J);
    if (fs.drag_scale) scale_drag_jacobians(topo, *fs.drag_scale, A);
  } else {
    for (auto& d : A.D) d.setZero();
    A.J.clear();
  }
  apply_position_jacobian(topo, A.B, moving, Kv);
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

// z = D r (D A's diagonal blocks; zero on pinned rows). Returns r . z.
double times_diagonal(const ClothTopology& topo, const ClothSystem& A, const MatX3& r, MatX3& z) {
  double rz = 0;
  for (Index i = 0; i < topo.num_vertices(); ++i) {
    if (topo.inv_mass[i] == 0.0) {
      z.row(i).setZero();
      continue;
    }
    const Vec3 ri = r.row(i);
    const Vec3 zi = A.diag[size_t(i)] * ri;
    z.row(i) = zi.transpose();
    rz += ri.dot(zi);
  }
  return rz;
}

// CG preconditioned by symmetric block Gauss-Seidel, M = (D + L) D^-1 (D + U) (A = L + D + U),
// in Eisenstat's form: CG on (D + L)^-1 A (D + U)^-1 y = (D + L)^-1 b preconditioned by D, whose
// iterates map to those of CG on A preconditioned by M (residual r^ = (D + L)^-1 r, z = D r^, so
// r^ . z = r . M^-1 r; dv = (D + U)^-1 y moves along t = (D + U)^-1 p), and whose product needs
// no product with A (eisenstat_product). Converged when r . M^-1 r <= tol^2 b . M^-1 b, the
// relative residual in M^-1's norm. From dv with residual r = b - A dv (s.r, turned into r^);
// no held contacts (the filter S is not in the triangular factors). False when it did not converge.
bool ssor_cg(const ClothTopology& topo, const ClothSystem& A, const IntegratorParams& ip,
             IntegratorScratch& s, IntegratorStats& stats) {
  lower_block_solve(topo, A, s.b, s.z);  // c = (D + L)^-1 b: b . M^-1 b = c . D c
  const double tol2 = ip.cg_tolerance * ip.cg_tolerance * times_diagonal(topo, A, s.z, s.z);
  lower_block_solve(topo, A, s.r, s.r);  // in place: row i reads the rows j < i already solved
  double rz = times_diagonal(topo, A, s.r, s.z);
  bool converged = rz <= tol2;
  int it = 0;
  if (!converged) s.p = s.z;
  for (; !converged && it < ip.cg_max_iterations; ++it) {
    const double pw = eisenstat_product(topo, A, s.p, s.t, s.u, s.q, s.Dw);
    if (!(pw > 0)) break;  // not SPD along p (or NaN): give up, the caller halves h
    const double alpha = rz / pw;
    s.dv += alpha * s.t;
    s.r -= alpha * s.q;
    s.z -= alpha * s.Dw;  // z = D r^ by the same recurrence
    const double rz_new = dot(s.r, s.z);
    if (rz_new <= tol2) {
      converged = true;
      ++it;
      break;
    }
    s.p = s.z + (rz_new / rz) * s.p;
    rz = rz_new;
  }
  stats.cg_iterations += it;
  return converged;
}

// fd (N x 3): the drag at the start of a piece becomes the drag the implicit solve applied,
// fd + (d fd / d v) dv. A holds M + h D_drag (A.D) and h Jw / 9 (A.J), see
// assemble_implicit_system, so D_drag = (A.D - m I) / h.
// The drag change on a pinned row (its dv is 0: only "triangle" drag's blocks reach it) goes into
// pinned_f's row too (pinned_forces_applied).
void implicit_drag_applied(const ClothTopology& topo, const ClothSystem& A, double h,
                           const MatX3& dv, MatX3& fd, MatX3& pinned_f) {
  for (Index i = 0; i < topo.num_vertices(); ++i) {
    const Vec3 dvi = dv.row(i);
    Vec3 df = -(A.D[i] * dvi - topo.mass[i] * dvi) / h;
    if (!A.J.empty())
      for (int32_t k = topo.tri_adj_offset[i]; k < topo.tri_adj_offset[i + 1]; ++k) {
        const int32_t tr = topo.tri_adj[k];
        const Vec3 sum = dv.row(topo.triangles(tr, 0)) + dv.row(topo.triangles(tr, 1)) +
                         dv.row(topo.triangles(tr, 2));
        df -= A.J[tr] * sum / h;
      }
    fd.row(i) += df.transpose();
    if (topo.inv_mass[i] == 0.0) pinned_f.row(i) += df.transpose();
  }
}

// The force the solve applied to each pinned vertex, Baraff-Witkin eq. 16's f0 + K dx + D dv
// there (dx = h v' with the pin's own dv = 0), into f's pinned rows, which hold f0 + h K w from
// when b was formed: what reaches it through its springs, (h K_s + k_d I) dv_j = B_s dv_j / h.
// (The drag's change: implicit_drag_applied.) The free vertices felt its reaction, so the pins'
// work is this force times their velocity; f0 alone left U . h (K dx + D dv) in the remainder of
// a flag whose pins move at U (docs/design.md "Moving pins and Galilean invariance").
void pinned_forces_applied(const ClothTopology& topo, const ClothSystem& A, double h,
                           const MatX3& dv, MatX3& f) {
  for (Index i = 0; i < topo.num_vertices(); ++i) {
    if (topo.inv_mass[i] != 0.0) continue;
    Vec3 sum = Vec3::Zero();
    for (int32_t k = topo.adj_offset[i]; k < topo.adj_offset[i + 1]; ++k)
      sum += A.B[topo.adj_spring[k]].apply(Vec3(dv.row(topo.adj_other[k])));
    f.row(i) += (sum / h).transpose();
  }
}

// One linearised backward Euler step (Baraff-Witkin eq. 16):
// (M - h df/dv - h^2 df/dx) dv = h (f0 + h df/dx v0), then v += dv, x += h v.
IntegrateStatus implicit_once(const ClothTopology& topo, const ForceSet& fs,
                              const IntegratorParams& ip, double h, const MatX3& u, MatX3& x,
                              MatX3& v, IntegratorScratch& s, IntegratorStats& stats,
                              StepWork& work, StageClock* t) {
  const Index N = topo.num_vertices();
  ClothSystem& A = s.sys;
  compute_forces(topo, fs, x, v, u, s.f, s.fd, t);
  if (fs.drift) s.p = v + *fs.drift;  // the positions move with v + drift: K sees both
  assemble_implicit_system(topo, fs, h, x, v, u, A, s.tmp, fs.drift ? &s.p : nullptr);
  // b = h (f0 + h K v0); f's pinned rows become f0 + h K v0 too, the start of the force the
  // solve applies to them (pinned_forces_applied adds the rest once dv is known).
  s.b = h * (s.f + h * s.tmp);
  for (Index i = 0; i < N; ++i)
    if (topo.inv_mass[i] == 0.0) s.f.row(i) += h * s.tmp.row(i);
  filter_pinned(topo, s.b);
  // Held contacts: dv = S dv + z (prescribe_held), r = S (b - A dv), and every product and
  // preconditioned residual filtered by S (Baraff-Witkin §5.3).
  hold_contacts(topo, fs, s.f, x, v, h, s);
  const auto book_held = [&](std::size_t first) {  // the planes' impulse is A dv - b along n
    for (std::size_t k = first; k < s.held.size(); ++k) {
      RestingContact& c = s.held[k];
      c.bn = s.b.row(c.vertex).dot(c.normal);  // b unfiltered
      work.contact_impulse -= c.bn * c.normal;
    }
    filter_held(s.held.data() + first, s.held.size() - first, s.b);
  };
  book_held(0);
  const Preconditioner pc = preconditioner_for(topo, ip, s);
  const bool multigrid = pc == Preconditioner::kMultigrid;
  if (multigrid) multigrid_setup(topo, A, s.mg);

  // PCG warm start: the point of the line through the last two steps' dv, dv_1 + theta (dv_1 -
  // dv_2), closest to the solution in A's energy norm, theta = r_1 . d / d^T A d (one more
  // product). Never further than dv_1 alone in that norm, so never worse than it when the motion
  // turns, and near the straight-line extrapolation (theta ~ 1) when it is smooth.
  filter_pinned(topo, s.dv);
  prescribe_held(s.held, v, s.dv);
  apply_system(topo, A, s.dv, s.q);
  s.r = s.b - s.q;
  filter_held(s.held, s.r);
  s.z = s.dv - s.dv_prev;  // d (zero rows where pinned: both are filtered)
  s.dv_prev = s.dv;
  filter_held(s.held, s.z);
  apply_system(topo, A, s.z, s.p);
  filter_held(s.held, s.p);
  const double dAd = dot(s.z, s.p);
  if (dAd > 0) {
    const double theta = dot(s.r, s.z) / dAd;
    s.dv += theta * s.z;
    s.r -= theta * s.p;
  }
  // CG from dv with residual r (both filtered): false when it did not converge.
  const auto solve = [&]() {
    const double bnorm = s.b.norm();
    if (bnorm == 0.0) {
      s.dv.setZero();
      prescribe_held(s.held, v, s.dv);
      return true;
    }
    if (pc == Preconditioner::kSsor && s.held.empty()) return ssor_cg(topo, A, ip, s, stats);
    const double tol2 = (ip.cg_tolerance * bnorm) * (ip.cg_tolerance * bnorm);
    int it = 0;
    bool converged = s.r.squaredNorm() <= tol2;
    double rz = 0;
    if (!converged) {
      rz = precondition(topo, s, multigrid, s.r, s.z);  // r = S r: r . z = r . S z
      filter_held(s.held, s.z);
      s.p = s.z;
    }
    for (; !converged && it < ip.cg_max_iterations; ++it) {
      apply_system(topo, A, s.p, s.q);
      filter_held(s.held, s.q);
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
      filter_held(s.held, s.z);
      // Multigrid's K-cycle is not quite linear: flexible CG (Polak-Ribiere, Notay 2000),
      // beta = z_new . (r_new - r_old) / rz_old with r_new - r_old = -alpha q. Equal to
      // rz_new / rz_old in exact arithmetic for a fixed preconditioner (block Jacobi keeps that).
      const double beta = multigrid ? -alpha * dot(s.z, s.q) / rz : rz_new / rz;
      s.p = s.z + beta * s.p;
      rz = rz_new;
    }
    stats.cg_iterations += it;
    return converged;
  };
  if (!solve()) return IntegrateStatus::kCgFailed;
  // Contacts the answer carries through their planes are held too, and the solve finished with
  // them; a few rounds (the projection stages answer what is left).
  for (int round = 0; round < kContactRounds; ++round) {
    const std::size_t first = s.held.size();
    if (hold_crossing(topo, fs, x, v, s.dv, h, s) == 0) break;
    book_held(first);
    prescribe_held(s.held, v, s.dv);
    apply_system(topo, A, s.dv, s.q);
    s.r = s.b - s.q;
    filter_held(s.held, s.r);
    if (!solve()) return IntegrateStatus::kCgFailed;
  }
  if (!s.held.empty()) {  // the rest of the planes' impulses: A dv along the normals
    apply_system(topo, A, s.dv, s.q);
    for (const RestingContact& c : s.held) {
      const double qn = s.q.row(c.vertex).dot(c.normal);
      work.contact_impulse += qn * c.normal;
      // A moving plane's work: its impulse times its own speed along n (a still one does none;
      // the speculative part, -gap / h, stays the integrator's: <= 0 for a push).
      work.pins += (qn - c.bn) * c.w;
    }
  }
  parallel_for(N, [&](Index i) {
    v.row(i) += s.dv.row(i);
    x.row(i) += h * v.row(i);
  });
  // The drift as applied: none into the surface on a held row (eq. 5's displacement of a vertex
  // the solve holds on the pole would carry it in, and the pole's stage would push it back).
  const MatX3* drift = fs.drift;
  if (drift && !s.held.empty()) {
    s.tmp = *drift;  // free since b was formed
    filter_inward(s.held, s.tmp);
    drift = &s.tmp;
  }
  if (drift) x += h * *drift;
  {
    // The linearised end-of-step forces over the displacement h v'; damping is linear in v, so
    // the applied damping is exactly k_d (v'_j - v'_i).
    StageClock::Scope timer(t, Stage::kCheck);
    if (fs.drag) implicit_drag_applied(topo, A, h, s.dv, s.fd, s.f);
    pinned_forces_applied(topo, A, h, s.dv, s.f);
    if (fs.drift) {
      for (Index i = 0; i < N; ++i) s.q.row(i) = (topo.mass[i] / h) * s.dv.row(i);  // applied f
      work.drift += drift_work(topo, fs, *drift, s.q, v, s.fd, h);
    }
    book_force_work(topo, fs, v, v, h, s, work);
  }
  if (ip.strain_limit > 0) {
    StageClock::Scope timer(t, Stage::kStrainLimit);
    work.strain_limit +=
        limit_strain_work(topo, gravity_of(fs), ip.strain_limit, ip.strain_limit_iterations, x, v,
                          fs.contacts, fs.contact_offset, &work.pins, fs.contact_speed);
  }
  return IntegrateStatus::kOk;
}

// Implicit step of h; if CG fails, or a piece makes more energy than fs.energy_guard beyond the
// work of the forces, restart from the same state with two steps of h/2, and so on down to
// ip.max_halvings levels. E: total_energy at (x, v) in, at the end out.
IntegrateStatus implicit_step(const ClothTopology& topo, const ForceSet& fs,
                              const IntegratorParams& ip, double h, const MatX3& u, MatX3& x,
                              MatX3& v, IntegratorScratch& s, IntegratorStats& stats, double& E,
                              StepWork& work, StageClock* t) {
  IntegrateStatus failure = IntegrateStatus::kCgFailed;
  for (int level = 0; level <= ip.max_halvings; ++level) {
    const long pieces = 1L << level;
    const double hp = h / double(pieces);
    s.x0 = x;
    s.v0 = v;
    if (fs.drag_impulse) s.impulse0 = *fs.drag_impulse;
    StepWork level_work;
    double e = E;
    failure = IntegrateStatus::kOk;
    for (long k = 0; k < pieces && failure == IntegrateStatus::kOk; ++k) {
      StepWork pw;
      if (implicit_once(topo, fs, ip, hp, u, x, v, s, stats, pw, t) != IntegrateStatus::kOk) {
        failure = IntegrateStatus::kCgFailed;
        break;
      }
      const double e1 = timed_energy(topo, fs, x, v, s, t);
      pw.remainder = e1 - e - pw.booked();
      e = e1;
      level_work += pw;
      // Backward Euler should only dissipate and a projection only take energy out: what
      // either makes is counted on its own, so that one cannot hide behind the other (a
      // projection pumping the springs that the next solve damps).
      if (fs.energy_guard > 0 &&
          std::max(pw.remainder, 0.0) + std::max(pw.strain_limit, 0.0) > fs.energy_guard)
        failure = IntegrateStatus::kEnergyGain;
    }
    if (failure == IntegrateStatus::kOk) {
      work += level_work;
      E = e;
      return IntegrateStatus::kOk;
    }
    x = s.x0;
    v = s.v0;
    if (fs.drag_impulse) *fs.drag_impulse = s.impulse0;
    s.dv.setZero();  // the extrapolation's steps were of another length
    s.dv_prev.setZero();
    ++stats.halvings;
    if (failure == IntegrateStatus::kEnergyGain) ++stats.energy_halvings;
  }
  return failure;
}

}  // namespace

IntegrateStatus integrate(const ClothTopology& topo, const ForceSet& fs, const IntegratorParams& ip,
                          double h, const MatX3& u, MatX3& x, MatX3& v, IntegratorScratch& s,
                          IntegratorStats& stats, StageClock* t) {
  stats = IntegratorStats{};
  double E = stats.energy_before = timed_energy(topo, fs, x, v, s, t);
  StepWork work;
  const double hs = h / double(ip.substeps);
  long explicit_substeps = 0;
  for (int k = 0; k < ip.substeps; ++k) {
    IntegrateStatus st;
    switch (ip.method) {
      case Method::kExplicit:
        st = explicit_step(topo, fs, ip, hs, u, x, v, s, stats, work, t);
        explicit_substeps += stats.substeps;
        break;
      case Method::kImplicit: st = implicit_step(topo, fs, ip, hs, u, x, v, s, stats, E, work, t);
    }
    if (st != IntegrateStatus::kOk) return st;
  }
  if (ip.method == Method::kExplicit) {
    stats.substeps = explicit_substeps;
    E = timed_energy(topo, fs, x, v, s, t);
    work.remainder = E - stats.energy_before - work.booked();
  }
  stats.energy_after = E;
  stats.work = work;
  return IntegrateStatus::kOk;
}

}  // namespace flagsim

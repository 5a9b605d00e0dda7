#include "fluid/solids.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "common/parallel.h"

namespace flagsim {

namespace {

/// Index along an axis of n entries after a step, wrapped when periodic; -1 beyond a bounded end.
inline int step_index(int a, int step, int n, bool periodic) {
  const int m = a + step;
  if (m >= 0 && m < n) return m;
  if (!periodic) return -1;
  return m < 0 ? m + n : m - n;
}

}  // namespace

uint16_t SolidMap::cell_owner(int i, int j, int k) const {
  if (owner.empty()) return 0;  // nothing built: no solids, no no-slip walls
  const int ijk[3] = {i, j, k};
  int w[3];
  for (int d = 0; d < 3; ++d) {
    const int n = geo.n(d);
    if (ijk[d] >= 0 && ijk[d] < n) {
      w[d] = ijk[d];
    } else {
      if (!geo.periodic) return 0;
      w[d] = ((ijk[d] % n) + n) % n;
    }
  }
  return owner[geo.cells().index(w[0], w[1], w[2])];
}

void SolidMap::build(const GridGeometry& g, const FluidParams& p) {
  geo = g;
  const Shape3 sc = g.cells();
  cell_count.assign(p.obstacles.size(), 0);
  slip.clear();
  for (const ObstacleParams& o : p.obstacles) slip.push_back(o.slip);
  any_no_slip = false;
  for (int d = 1; d < 3; ++d)
    for (int hi = 0; hi < 2; ++hi) {
      wall[d][hi] = g.periodic ? Slip::kFreeSlip : p.wall(d, hi);
      any_no_slip = any_no_slip || wall[d][hi] == Slip::kNoSlip;
    }
  any_solid = false;
  if (p.obstacles.empty() && !any_no_slip) {  // nothing to hold: no masks (no memory, no work)
    owner.clear();
    solid.clear();
    for (int c = 0; c < 3; ++c) {
      face[c].clear();
      closed[c].clear();
    }
    return;
  }
  owner.assign(sc.size(), 0);
  solid.assign(sc.size(), 0);
  if (!p.obstacles.empty()) {
    for (int i = 0; i < g.nx; ++i)
      for (int j = 0; j < g.ny; ++j)
        for (int k = 0; k < g.nz; ++k) {
          const Vec3 x = g.origin + g.h * Vec3(i + 0.5, j + 0.5, k + 0.5);
          for (std::size_t o = 0; o < p.obstacles.size(); ++o)
            if (p.obstacles[o].contains(x)) {
              const std::size_t q = sc.index(i, j, k);
              owner[q] = uint16_t(o + 1);
              solid[q] = 1;
              ++cell_count[o];
              any_solid = true;
              any_no_slip = any_no_slip || p.obstacles[o].slip == Slip::kNoSlip;
              break;
            }
        }
  }
  for (int c = 0; c < 3; ++c) {
    const Shape3 sh = g.face_shape(c);
    face[c].assign(sh.size(), uint8_t(FaceKind::kOpen));
    closed[c].clear();
    for (int i = 0; i < sh.n[0]; ++i)
      for (int j = 0; j < sh.n[1]; ++j)
        for (int k = 0; k < sh.n[2]; ++k) {
          int lo[3] = {i, j, k};
          lo[c] -= 1;  // the cells on either side of this face: lo and (i, j, k)
          const bool a = cell_owner(lo[0], lo[1], lo[2]) != 0;
          const bool b = cell_owner(i, j, k) != 0;
          FaceKind kind = a && b ? FaceKind::kInside : (a || b ? FaceKind::kHeld : FaceKind::kOpen);
          const int ijk[3] = {i, j, k};
          const bool domain_held =
              !g.periodic && ((c == 0 && i == 0) || (c > 0 && (ijk[c] == 0 || ijk[c] == g.n(c))));
          if (domain_held && kind == FaceKind::kOpen) kind = FaceKind::kDomain;
          const std::size_t q = sh.index(i, j, k);
          face[c][q] = uint8_t(kind);
          if (kind == FaceKind::kHeld || kind == FaceKind::kInside)
            closed[c].push_back(uint32_t(q));
        }
  }
}

std::vector<std::string> SolidMap::warnings(const std::vector<ObstacleParams>& obstacles) const {
  std::vector<std::string> out;
  for (std::size_t o = 0; o < obstacles.size(); ++o) {
    const double across = obstacles[o].thickness() / geo.h;
    std::ostringstream s;
    s << "air.obstacles[" << o << "] ";
    if (o < cell_count.size() && cell_count[o] == 0) {
      s << "covers no cell centre (it is " << across
        << " cells across): the air does not see it; use a finer grid (cell_size) or a larger "
           "solid";
      out.push_back(s.str());
    } else if (across < kWakeCellsAcross) {
      s << "is " << across << " cells across, fewer than the " << kWakeCellsAcross
        << " its wake needs (docs/accuracy.md, 'Solids in the air'): the air sees it, but the "
           "vortices it sheds are not resolved; use a smaller cell_size";
      out.push_back(s.str());
    }
  }
  return out;
}

template <class T>
void enforce_solids(const SolidMap& map, MacGrid<T>& u) {
  for (int c = 0; c < 3; ++c) {
    T* q = u.comp[c].data();
    for (uint32_t n : map.closed[c]) q[n] = T(0);
  }
}

template <class T>
void set_air_mean_flow(const SolidMap& map, const Vec3& target, MacGrid<T>& u) {
  for (int c = 0; c < 3; ++c) {
    T* q = u.comp[c].data();
    const uint8_t* kind = map.face[c].data();
    const std::size_t n = u.comp[c].size();
    auto open = [&](std::size_t i) { return kind[i] == uint8_t(FaceKind::kOpen); };
    const double count = deterministic_sum(n, [&](std::size_t i) { return open(i) ? 1.0 : 0.0; });
    if (count == 0) continue;
    const double mean =
        deterministic_sum(n, [&](std::size_t i) { return open(i) ? double(q[i]) : 0.0; }) / count;
    const double shift = target[c] - mean;
    parallel_for_cells(long(n), [&](Index i) {
      if (open(std::size_t(i))) q[i] = T(q[i] + shift);
    });
  }
}

std::vector<double> inflow_weights(const GridGeometry& g, const FluidParams& p) {
  const InflowShape shape = inflow_shape(g, p);
  std::vector<double> w(std::size_t(g.ny) * g.nz, 1.0);
  for (int j = 0; j < g.ny; ++j)
    for (int k = 0; k < g.nz; ++k) {
      const int a[3] = {0, j, k};
      double f = 1;
      for (int d = 1; d < 3; ++d) {
        if (!shape.parabolic[d]) continue;
        // Mean of 6 s (1 - s) over the cell [s0, s1]: 3 (s0 + s1) - 2 (s0^2 + s0 s1 + s1^2).
        const double s0 = double(a[d]) / g.n(d), s1 = double(a[d] + 1) / g.n(d);
        f *= 3 * (s0 + s1) - 2 * (s0 * s0 + s0 * s1 + s1 * s1);
      }
      w[std::size_t(j) * g.nz + k] = f;
    }
  return w;
}

InflowShape inflow_shape(const GridGeometry& g, const FluidParams& p) {
  InflowShape s;
  for (int d = 0; d < 3; ++d) s.n[d] = g.n(d);
  if (g.periodic || p.inflow_profile != InflowProfile::kParabolic) return s;
  for (int d = 1; d < 3; ++d)
    s.parabolic[d] = p.wall(d, 0) == Slip::kNoSlip && p.wall(d, 1) == Slip::kNoSlip;
  return s;
}

template <class T>
int diffuse_explicit(const SolidMap& map, double nu_dt, MacGrid<T>& u, MacGrid<T>& scratch) {
  const GridGeometry& g = map.geo;
  const double r = nu_dt / (g.h * g.h);
  if (!(r > 0)) return 0;
  if (map.face[0].empty())
    throw std::logic_error("diffuse_explicit: the map holds no solids and no no-slip walls");
  const int substeps = std::max(1, int(std::ceil(r / 0.15)));
  const double a = r / substeps;
  const uint8_t kOpen = uint8_t(FaceKind::kOpen), kInside = uint8_t(FaceKind::kInside);
  for (int s = 0; s < substeps; ++s) {
    copy_grid(u, scratch);
    for (int c = 0; c < 3; ++c) {
      const Shape3 sh = u.shape[c];
      const T* src = scratch.comp[c].data();
      T* dst = u.comp[c].data();
      const uint8_t* kind = map.face[c].data();
      // One open node: acc sums its six neighbours' differences in the order d = 0, 1, 2, side
      // -1 then +1 (both paths below keep that order, so they give the same bits).
      auto node = [&](int i, int j, int k) {
        const std::size_t q = sh.index(i, j, k);
        const double xc = src[q];
        double acc = 0;
        const int ijk[3] = {i, j, k};
        for (int d = 0; d < 3; ++d)
          for (int side = -1; side <= 1; side += 2) {
            const int m = step_index(ijk[d], side, sh.n[d], g.periodic);
            if (m < 0) {
              // Beyond the grid: a y or z wall's mirror; the x ends (inflow face for the
              // tangential components, outflow) are zero-gradient.
              if (d != 0 && d != c && map.wall[d][side > 0] == Slip::kNoSlip) acc -= 2 * xc;
              continue;
            }
            int nb[3] = {i, j, k};
            nb[d] = m;
            const std::size_t qn = sh.index(nb[0], nb[1], nb[2]);
            if (kind[qn] == kInside) {
              // an inside node's two cells share an owner
              const uint16_t o = map.cell_owner(nb[0], nb[1], nb[2]);
              if (o != 0 && map.slip[o - 1] == Slip::kNoSlip) acc -= 2 * xc;
            } else {
              acc += double(src[qn]) - xc;
            }
          }
        dst[q] = T(xc + a * acc);
      };
      const int nk = sh.n[2];
      auto row_pass = [&](Index row) {
        const int i = int(row / sh.n[1]), j = int(row % sh.n[1]);
        const int im = step_index(i, -1, sh.n[0], g.periodic),
                  ip = step_index(i, 1, sh.n[0], g.periodic),
                  jm = step_index(j, -1, sh.n[1], g.periodic),
                  jp = step_index(j, 1, sh.n[1], g.periodic);
        const bool inner_row = im >= 0 && ip >= 0 && jm >= 0 && jp >= 0;
        if (!inner_row) {
          for (int k = 0; k < nk; ++k)
            if (kind[sh.index(i, j, k)] == kOpen) node(i, j, k);
          return;
        }
        // the row and its four neighbouring rows (d = 0, then d = 1)
        const std::size_t q0 = sh.index(i, j, 0);
        const std::size_t rows[4] = {sh.index(im, j, 0), sh.index(ip, j, 0), sh.index(i, jm, 0),
                                     sh.index(i, jp, 0)};
        for (int k = 0; k < nk; ++k) {
          if (kind[q0 + k] != kOpen) continue;
          const int km = step_index(k, -1, nk, g.periodic), kp = step_index(k, 1, nk, g.periodic);
          // A node whose six neighbours are in the grid (across a periodic wrap too) and none
          // inside a solid: the plain 7-point sum, no wall or solid rules.
          const bool plain = km >= 0 && kp >= 0 && kind[rows[0] + k] != kInside &&
                             kind[rows[1] + k] != kInside && kind[rows[2] + k] != kInside &&
                             kind[rows[3] + k] != kInside && kind[q0 + km] != kInside &&
                             kind[q0 + kp] != kInside;
          if (!plain) {
            node(i, j, k);
            continue;
          }
          const double xc = src[q0 + k];
          double acc = 0;
          acc += double(src[rows[0] + k]) - xc;
          acc += double(src[rows[1] + k]) - xc;
          acc += double(src[rows[2] + k]) - xc;
          acc += double(src[rows[3] + k]) - xc;
          acc += double(src[q0 + km]) - xc;
          acc += double(src[q0 + kp]) - xc;
          dst[q0 + k] = T(xc + a * acc);
        }
      };
      parallel_for_if(Index(sh.size()) > kGridParallelGrain, long(sh.n[0]) * sh.n[1], row_pass);
    }
  }
  return substeps;
}

template <class T>
Vec3 obstacle_force(const SolidMap& map, int index, const MacGrid<T>& u, const T* phi, double dt,
                    double rho, double nu) {
  const GridGeometry& g = map.geo;
  const Shape3 sc = g.cells();
  const uint16_t id = uint16_t(index + 1);
  const double area = g.h * g.h, p_scale = rho / dt;
  Vec3 f(0, 0, 0);
  // Pressure: -p n dA on each face between a cell of the obstacle and an air cell (n points out
  // of the solid, into the air). p at the face: extrapolated linearly from the first two air
  // cells along n (1.5 p1 - 0.5 p2, second order), or p1 when the second is not air.
  for (int i = 0; i < g.nx; ++i)
    for (int j = 0; j < g.ny; ++j)
      for (int k = 0; k < g.nz; ++k) {
        if (map.owner[sc.index(i, j, k)] != id) continue;
        const int ijk[3] = {i, j, k};
        for (int d = 0; d < 3; ++d)
          for (int side = -1; side <= 1; side += 2) {
            const int m = step_index(ijk[d], side, g.n(d), g.periodic);
            if (m < 0) continue;  // the domain's edge: no air there
            int nb[3] = {i, j, k};
            nb[d] = m;
            const std::size_t qn = sc.index(nb[0], nb[1], nb[2]);
            if (map.owner[qn] != 0) continue;
            double p1 = phi[qn];
            const int m2 = step_index(m, side, g.n(d), g.periodic);
            if (m2 >= 0) {
              nb[d] = m2;
              const std::size_t q2 = sc.index(nb[0], nb[1], nb[2]);
              if (map.owner[q2] == 0) p1 = 1.5 * p1 - 0.5 * double(phi[q2]);
            }
            f[d] -= side * p_scale * p1 * area;
          }
      }
  if (map.slip[std::size_t(index)] != Slip::kNoSlip) return f;
  // Viscous shear on each open tangential node whose mirror lies inside this obstacle:
  // rho nu (u_t - 0) / (h / 2) per unit area, along the node's own component.
  const double shear = rho * nu * 2.0 / g.h * area;
  for (int c = 0; c < 3; ++c) {
    const Shape3 sh = u.shape[c];
    const uint8_t* kind = map.face[c].data();
    for (int i = 0; i < sh.n[0]; ++i)
      for (int j = 0; j < sh.n[1]; ++j)
        for (int k = 0; k < sh.n[2]; ++k) {
          const std::size_t q = sh.index(i, j, k);
          if (kind[q] != uint8_t(FaceKind::kOpen)) continue;
          const int ijk[3] = {i, j, k};
          for (int d = 0; d < 3; ++d) {
            if (d == c) continue;
            for (int side = -1; side <= 1; side += 2) {
              const int m = step_index(ijk[d], side, sh.n[d], g.periodic);
              if (m < 0) continue;
              int nb[3] = {i, j, k};
              nb[d] = m;
              if (map.face[c][sh.index(nb[0], nb[1], nb[2])] != uint8_t(FaceKind::kInside))
                continue;
              if (map.cell_owner(nb[0], nb[1], nb[2]) != id) continue;
              f[c] += shear * double(u.comp[c][q]);
            }
          }
        }
  }
  return f;
}

#define FLAGSIM_INSTANTIATE_SOLIDS(T)                                                        \
  template void enforce_solids<T>(const SolidMap&, MacGrid<T>&);                             \
  template void set_air_mean_flow<T>(const SolidMap&, const Vec3&, MacGrid<T>&);             \
  template int diffuse_explicit<T>(const SolidMap&, double, MacGrid<T>&, MacGrid<T>&);       \
  template Vec3 obstacle_force<T>(const SolidMap&, int, const MacGrid<T>&, const T*, double, \
                                  double, double);
FLAGSIM_INSTANTIATE_SOLIDS(float)
FLAGSIM_INSTANTIATE_SOLIDS(double)

}  // namespace flagsim

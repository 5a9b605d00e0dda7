#include "cloth/strain_limit.h"

#include <algorithm>

#include "cloth/forces.h"

namespace flagsim {

namespace {

// Keeps vertex i (at x) on its side of its contact plane: a move a is cut where it would cross
// the plane, or, when i is on (or past) the plane, loses its component along -n. With velocity
// = true, a is a velocity change: it loses its component along -n when i is on the plane.
struct Surface {
  const MatX3* normal;
  const VecX* offset;
  Vec3 operator()(Index i, const Vec3& x, const Vec3& a, bool velocity = false) const {
    if (!normal) return a;
    const Vec3 n = row(*normal, i);
    const double an = a.dot(n);
    if (!(an < 0)) return a;
    const double gap = offset ? x.dot(n) - (*offset)[i] : x.dot(n);
    const double keep = velocity ? (gap > 0 ? an : 0.0) : std::max(an, std::min(0.0, -gap));
    return a + (keep - an) * n;
  }
};

}  // namespace

void limit_strain(const ClothTopology& topo, double limit, int iterations, MatX3& x, MatX3& v,
                  const MatX3* surface, const VecX* offset, double* pin_work, const VecX* speed) {
  const Surface along{surface, offset};
  // The work of pin a's impulse m_i dv_i on vertex i (a pin moves with v_a; its own v is kept).
  double pins = 0;
  const auto from_pin = [&](Index i, Index a, const Vec3& dv) {
    if (topo.inv_mass[a] == 0.0) pins += topo.mass[i] * dv.dot(Vec3(v.row(a)));
  };
  // A velocity change a of vertex i as its plane lets it (along); the plane's impulse m (dv - a)
  // does the work m (dv - a) . n w when it moves (speed w along n), booked with the pins'.
  const auto change = [&](Index i, const Vec3& a) {
    const Vec3 dv = along(i, row(x, i), a, true);
    if (surface && speed) pins += topo.mass[i] * (dv - a).dot(Vec3(surface->row(i))) * (*speed)[i];
    return dv;
  };
  // Velocities: the limited pair loses the relative velocity along it that still stretches it
  // (an inelastic, momentum-conserving impulse, as Bridson, Fedkiw, Anderson 2002 §7 limit
  // strain rates), so a correction never adds kinetic energy. Turning the correction itself into
  // velocity (v += correction / h, PBD-style) did: a violation the step inherited, corrected in
  // a 1e-5 s substep, became thousands of m/s (docs/energy.md).
  //
  // Long-range attachments first: one exact projection per vertex onto the ball of radius
  // (1 + limit) x rest distance around its nearest pin removes gross stretch in a single pass
  // (Gauss-Seidel over springs alone needs O(cols^2) sweeps for that).
  // Each vertex's tethers in turn: its nearest pin, then the two ends of the pins.
  const auto tether = [&](Index i, int32_t a, double rest) {
    if (a < 0) return;
    const Vec3 d = x.row(i) - x.row(a);
    const double l = d.norm(), lmax = (1.0 + limit) * rest;
    if (l <= lmax) return;
    x.row(i) += along(i, row(x, i), d * (lmax / l - 1.0)).transpose();
    const Vec3 n = d / l;
    const double vr = (v.row(i) - v.row(a)).dot(n.transpose());  // the pin does not move for it
    if (vr > 0) {
      const Vec3 dv = change(i, -vr * n);
      v.row(i) += dv.transpose();
      from_pin(i, a, dv);
    }
  };
  const Index N = topo.num_vertices();
  for (Index i = 0; i < N; ++i) {
    tether(i, topo.tether_anchor[i], topo.tether_length[i]);
    for (Index k = 2 * i; k < 2 * i + 2; ++k)
      tether(i, topo.tether_end_anchor[k], topo.tether_end_length[k]);
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
      x.row(a) += along(a, row(x, a), wa * corr).transpose();
      x.row(b) += along(b, row(x, b), -wb * corr).transpose();
      const Vec3 n = d / l;
      const double vr = (v.row(b) - v.row(a)).dot(n.transpose());
      if (vr > 0) {
        const Vec3 j = (vr / (wa + wb)) * n;  // impulse per unit inverse mass
        const Vec3 dva = change(a, wa * j), dvb = change(b, -wb * j);
        v.row(a) += dva.transpose();
        v.row(b) += dvb.transpose();
        from_pin(a, b, dva);
        from_pin(b, a, dvb);
      }
    }
    if (!violated) break;
  }
  if (pin_work) *pin_work += pins;
}

bool strain_limit_violated(const ClothTopology& topo, double limit, const MatX3& x) {
  const auto stretched = [&](Index i, int32_t a, double rest) {
    return a >= 0 && (x.row(i) - x.row(a)).norm() > (1.0 + limit) * rest;
  };
  for (Index i = 0; i < topo.num_vertices(); ++i) {
    if (stretched(i, topo.tether_anchor[i], topo.tether_length[i])) return true;
    for (Index k = 2 * i; k < 2 * i + 2; ++k)
      if (stretched(i, topo.tether_end_anchor[k], topo.tether_end_length[k])) return true;
  }
  for (Index s = 0; s < topo.num_springs(); ++s) {
    if (topo.spring_kind[s] == SpringKind::kBend) continue;
    const int a = topo.springs(s, 0), b = topo.springs(s, 1);
    if (topo.inv_mass[a] + topo.inv_mass[b] == 0) continue;
    if ((x.row(b) - x.row(a)).norm() > (1.0 + limit) * topo.rest_length[s]) return true;
  }
  return false;
}

double limit_strain_work(const ClothTopology& topo, const Vec3& g, double limit, int iterations,
                         MatX3& x, MatX3& v, const MatX3* surface, const VecX* offset,
                         double* pin_work, const VecX* speed) {
  if (!strain_limit_violated(topo, limit, x)) return 0.0;
  const double before = total_energy(topo, g, x, v);
  double pins = 0;
  limit_strain(topo, limit, iterations, x, v, surface, offset, &pins, speed);
  if (pin_work) *pin_work += pins;
  return total_energy(topo, g, x, v) - before - (pin_work ? pins : 0.0);
}

}  // namespace flagsim

// Strain limiting (cloth/strain_limit.h): the limit holds afterwards, the velocity update is
// inelastic (never adds kinetic energy) and momentum-conserving, and the work it reports is the
// energy change it made.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "cloth/forces.h"
#include "cloth/strain_limit.h"
#include "cloth/topology.h"

using namespace flagsim;

namespace {

// The paper flag stretched at random: positions scaled up to 1.5x about the origin corner plus
// noise, random velocities.
struct Stretched {
  ClothTopology t;
  MatX3 x, v;
  explicit Stretched(Pin pin, unsigned seed = 7) {
    FlagParams p;
    p.rows = 12;
    p.cols = 16;
    p.pin = pin;
    t = build_flag_topology(p);
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1, 1);
    x = t.rest_positions;
    v = MatX3::Zero(t.num_vertices(), 3);
    for (Index i = 0; i < t.num_vertices(); ++i) {
      if (t.inv_mass[i] == 0) continue;
      x.row(i) = (t.rest_positions.row(i) * (1.25 + 0.25 * u(rng)) +
                  0.01 * Vec3(u(rng), u(rng), u(rng)).transpose())
                     .eval();
      v.row(i) << u(rng), u(rng), u(rng);
    }
  }
};

double kinetic(const ClothTopology& t, const MatX3& v) {
  double k = 0;
  for (Index i = 0; i < t.num_vertices(); ++i) k += 0.5 * t.mass[i] * v.row(i).squaredNorm();
  return k;
}

double worst_ratio(const ClothTopology& t, const MatX3& x) {  // largest l / rest, not bending
  double w = 0;
  for (Index s = 0; s < t.num_springs(); ++s) {
    if (t.spring_kind[s] == SpringKind::kBend) continue;
    const int a = t.springs(s, 0), b = t.springs(s, 1);
    if (t.inv_mass[a] + t.inv_mass[b] == 0) continue;
    w = std::max(w, (x.row(b) - x.row(a)).norm() / t.rest_length[s]);
  }
  return w;
}

}  // namespace

TEST(StrainLimit, HoldsTheLimitAndNeverAddsKineticEnergy) {
  for (Pin pin : {Pin::kPole, Pin::kTop, Pin::kNone}) {
    Stretched f(pin);
    const double limit = 0.1;
    ASSERT_GT(worst_ratio(f.t, f.x), 1.2);
    ASSERT_TRUE(strain_limit_violated(f.t, limit, f.x));
    const double k0 = kinetic(f.t, f.v);
    limit_strain(f.t, limit, 200, f.x, f.v);
    // Gauss-Seidel: a later correction can stretch an earlier spring a little again; the promise
    // is the limit plus kStrainLimitSlack (cloth/params.h), which the Simulation checks.
    EXPECT_LE(worst_ratio(f.t, f.x), 1 + limit + kStrainLimitSlack) << name_of(pin);
    EXPECT_LE(kinetic(f.t, f.v), k0 * (1 + 1e-12)) << name_of(pin);
    for (Index i = 0; i < f.t.num_vertices(); ++i) {  // tethers: the same promise
      const int a = f.t.tether_anchor[i];
      if (a >= 0)
        EXPECT_LE((f.x.row(i) - f.x.row(a)).norm(),
                  (1 + limit + kStrainLimitSlack) * f.t.tether_length[i]);
    }
  }
}

// A hanging pole flag can swing down about its pins with every nearest-pin tether intact: each
// row at full tether length, turned down by 0.4 rad about its own pin, and only the shear springs
// notice (Gauss-Seidel over springs needs O(cols^2) sweeps to carry that back to the pole: the
// 128 x 128 flag of docs/energy.md). The tethers to the pole's two ends catch it in one pass:
// with no spring sweeps at all, every tether holds its limit afterwards and the lower rows,
// which hang farthest below the top pin, swing back up.
TEST(StrainLimit, EndTethersCatchASwingAboutTheNearestPins) {
  FlagParams p;
  p.rows = 32;
  p.cols = 48;
  p.pin = Pin::kPole;
  const ClothTopology t = build_flag_topology(p);
  const double limit = 0.1, theta = 0.4;
  MatX3 x = t.rest_positions, v = MatX3::Zero(t.num_vertices(), 3);
  const auto pin_of = [&](Index i) { return i - i % p.cols; };
  for (Index i = 0; i < t.num_vertices(); ++i) {
    const Vec3 d =
        ((1 + limit) * (t.rest_positions.row(i) - t.rest_positions.row(pin_of(i)))).transpose();
    x.row(i) = t.rest_positions.row(pin_of(i)) +
               Vec3(d.x() * std::cos(theta), d.y() - d.x() * std::sin(theta), d.z()).transpose();
  }
  const auto angle = [&](Index i) {  // below the rest row, about the vertex's own pin
    const Vec3 d = (x.row(i) - x.row(pin_of(i))).transpose();
    return std::atan2(-d.y(), std::hypot(d.x(), d.z()));
  };
  for (Index i = 0; i < t.num_vertices(); ++i) {  // every nearest tether intact
    if (i == pin_of(i)) continue;
    ASSERT_EQ(t.tether_anchor[i], pin_of(i));
    ASSERT_LE((x.row(i) - x.row(pin_of(i))).norm(), (1 + limit) * t.tether_length[i] * (1 + 1e-12));
  }
  ASSERT_TRUE(strain_limit_violated(t, limit, x));
  limit_strain(t, limit, 0, x, v);
  for (Index i = 0; i < t.num_vertices(); ++i) {
    const auto holds = [&](int a, double rest) {
      if (a >= 0) EXPECT_LE((x.row(i) - x.row(a)).norm(), (1 + limit) * rest * (1 + 1e-12)) << i;
    };
    holds(t.tether_anchor[i], t.tether_length[i]);
    holds(t.tether_end_anchor[2 * i], t.tether_end_length[2 * i]);
    holds(t.tether_end_anchor[2 * i + 1], t.tether_end_length[2 * i + 1]);
  }
  // The far edge: the top row is free to droop (that only compresses the cloth), the rows below
  // swing back up the more the farther they hang below the top pin.
  const Index far = p.cols - 1,
              top = t.rest_positions(far, 1) > t.rest_positions(far + (p.rows - 1) * p.cols, 1)
                        ? 0
                        : p.rows - 1,
              bottom = p.rows - 1 - top;
  EXPECT_NEAR(angle(top * p.cols + far), theta, 1e-9);
  EXPECT_LT(angle(bottom * p.cols + far), 0.85 * theta);
  for (Index r = 1; r < p.rows; ++r) {
    const Index lower = (top == 0 ? r : p.rows - 1 - r) * p.cols + far;
    const Index upper = (top == 0 ? r - 1 : p.rows - r) * p.cols + far;
    EXPECT_LT(angle(lower), angle(upper)) << "row " << r << " below the top";
  }
}

TEST(StrainLimit, ConservesMomentumWithoutPins) {
  Stretched f(Pin::kNone);
  Vec3 p0 = Vec3::Zero(), c0 = Vec3::Zero();
  double m = 0;
  for (Index i = 0; i < f.t.num_vertices(); ++i) {
    p0 += f.t.mass[i] * f.v.row(i).transpose();
    c0 += f.t.mass[i] * f.x.row(i).transpose();
    m += f.t.mass[i];
  }
  limit_strain(f.t, 0.1, 200, f.x, f.v);
  Vec3 p1 = Vec3::Zero(), c1 = Vec3::Zero();
  for (Index i = 0; i < f.t.num_vertices(); ++i) {
    p1 += f.t.mass[i] * f.v.row(i).transpose();
    c1 += f.t.mass[i] * f.x.row(i).transpose();
  }
  EXPECT_LT((p1 - p0).norm(), 1e-12 * (1 + p0.norm()));
  EXPECT_LT((c1 - c0).norm() / m, 1e-12);  // mass-weighted moves keep the centre of mass
}

TEST(StrainLimit, WorkIsTheEnergyChangeAndZeroWhenNothingIsViolated) {
  const Vec3 g(0, -9.81, 0);
  Stretched f(Pin::kPole);
  const MatX3 x0 = f.x, v0 = f.v;
  const double before = total_energy(f.t, g, x0, v0);
  const double work = limit_strain_work(f.t, g, 0.1, 200, f.x, f.v);
  EXPECT_NEAR(work, total_energy(f.t, g, f.x, f.v) - before, 1e-12 * std::abs(before));
  EXPECT_LT(work, 0.0);  // it takes energy out
  // at rest nothing exceeds the limit: nothing is moved and nothing is booked
  Stretched rest(Pin::kPole);
  rest.x = rest.t.rest_positions;
  const MatX3 x_rest = rest.x, v_rest = rest.v;
  EXPECT_FALSE(strain_limit_violated(rest.t, 0.1, rest.x));
  EXPECT_EQ(limit_strain_work(rest.t, g, 0.1, 200, rest.x, rest.v), 0.0);
  EXPECT_TRUE(rest.x == x_rest && rest.v == v_rest);
}

// Contact planes (a flag held on a surface: limit_strain's `surface`): every free vertex of the
// stretched flag starts on a plane of its own, normal +z, every other one 2 mm above it. Pulls
// with a -z part move a vertex on its plane along it and one above it at most onto it; the limit
// is still reached by sliding, no vertex on its plane is given velocity into it, and no kinetic
// energy is added.
TEST(StrainLimit, VerticesOnAContactPlaneSlideAlongItAndStayOut) {
  Stretched f(Pin::kPole);
  const Index N = f.t.num_vertices();
  const double limit = 0.1;
  MatX3 normal = MatX3::Zero(N, 3);
  VecX offset = VecX::Zero(N);
  for (Index i = 0; i < N; ++i) {
    if (f.t.inv_mass[i] == 0) continue;
    normal(i, 2) = 1.0;
    offset[i] = f.x(i, 2) - (i % 2 ? 0.002 : 0.0);
  }
  const MatX3 v0 = f.v;
  MatX3 x_free = f.x, v_free = f.v;
  limit_strain(f.t, limit, 200, x_free, v_free);  // the same flag with no planes
  Index pulled_down = 0;
  for (Index i = 0; i < N; ++i) pulled_down += f.t.inv_mass[i] > 0 && x_free(i, 2) < offset[i];
  ASSERT_GT(pulled_down, N / 4);  // without planes many would cross theirs

  limit_strain(f.t, limit, 200, f.x, f.v, &normal, &offset);
  EXPECT_LE(worst_ratio(f.t, f.x), 1 + limit + kStrainLimitSlack);
  EXPECT_LE(kinetic(f.t, f.v), kinetic(f.t, v0) * (1 + 1e-12));
  for (Index i = 0; i < N; ++i) {
    if (f.t.inv_mass[i] == 0) continue;
    EXPECT_GE(f.x(i, 2), offset[i] - 1e-15) << i;  // never through its plane
    if (i % 2 == 0 && v0(i, 2) >= 0)               // started on it, not moving into it: none given
      EXPECT_GE(f.v(i, 2), 0.0) << i;
  }
}

// Planes with no offsets are planes through the origin (x . n >= 0): the same moves, bit for bit,
// as zero offsets given explicitly (the missing offsets used to be read through a null pointer).
TEST(StrainLimit, ContactPlanesWithoutOffsetsPassThroughTheOrigin) {
  Stretched a(Pin::kPole), b(Pin::kPole);
  const Index N = a.t.num_vertices();
  MatX3 normal = MatX3::Zero(N, 3);
  for (Index i = 0; i < N; ++i) normal(i, 2) = a.t.inv_mass[i] > 0 && a.x(i, 2) >= 0 ? 1.0 : 0.0;
  ASSERT_GT(normal.col(2).sum(), 0.0);
  const VecX zero = VecX::Zero(N);
  limit_strain(a.t, 0.1, 200, a.x, a.v, &normal, &zero);
  limit_strain(b.t, 0.1, 200, b.x, b.v, &normal);
  EXPECT_TRUE(a.x == b.x && a.v == b.v);
  EXPECT_LE(worst_ratio(b.t, b.x), 1 + 0.1 + kStrainLimitSlack);
}

#include "fluid/solids.h"

#include <gtest/gtest.h>

#include <cmath>

namespace flagsim {

namespace {

GridGeometry grid(int nx, int ny, int nz, double h, bool periodic) {
  GridGeometry g;
  g.nx = nx;
  g.ny = ny;
  g.nz = nz;
  g.h = h;
  g.origin = Vec3::Zero();
  g.periodic = periodic;
  return g;
}

ObstacleParams sphere(const Vec3& c, double r, Slip slip = Slip::kNoSlip) {
  ObstacleParams o;
  o.shape = ObstacleShape::kSphere;
  o.center = c;
  o.radius = r;
  o.slip = slip;
  return o;
}

}  // namespace

TEST(Solids, CellsAreThoseWhoseCentresLieInside) {
  const GridGeometry g = grid(10, 12, 8, 0.1, false);
  FluidParams p;
  p.boundary = Boundary::kTunnel;
  ObstacleParams cyl;
  cyl.shape = ObstacleShape::kCylinder;
  cyl.center = Vec3(0.5, 0.6, 0.4);
  cyl.axis = Vec3(0, 1, 0);
  cyl.radius = 0.22;
  cyl.length = 0.8;
  p.obstacles = {sphere(Vec3(0.3, 0.3, 0.3), 0.2), cyl};
  SolidMap m;
  m.build(g, p);
  long count[2] = {0, 0};
  for (int i = 0; i < g.nx; ++i)
    for (int j = 0; j < g.ny; ++j)
      for (int k = 0; k < g.nz; ++k) {
        const Vec3 x = g.h * Vec3(i + 0.5, j + 0.5, k + 0.5);
        const int expect = p.obstacles[0].contains(x) ? 1 : (p.obstacles[1].contains(x) ? 2 : 0);
        EXPECT_EQ(m.cell_owner(i, j, k), expect);
        if (expect) ++count[expect - 1];
      }
  EXPECT_EQ(m.cell_count[0], count[0]);
  EXPECT_EQ(m.cell_count[1], count[1]);
  EXPECT_GT(count[0], 0);
  EXPECT_GT(count[1], 0);
}

// Held faces are exactly the faces between a solid and an air cell; inside faces have solid on
// both sides; the count of held faces is the solid's surface in faces.
TEST(Solids, FaceKindsFollowTheCells) {
  const GridGeometry g = grid(8, 8, 8, 0.125, true);
  FluidParams p;
  ObstacleParams box;
  box.center = Vec3(0.5, 0.5, 0.5);
  box.half_size = Vec3(0.2, 0.13, 0.26);  // 4 x 2 x 4 cells (centres at .3125 ... .6875)
  p.obstacles = {box};
  SolidMap m;
  m.build(g, p);
  EXPECT_EQ(m.cell_count[0], 4 * 2 * 4);
  long held = 0, inside = 0;
  for (int c = 0; c < 3; ++c)
    for (uint8_t k : m.face[c]) {
      held += k == uint8_t(FaceKind::kHeld);
      inside += k == uint8_t(FaceKind::kInside);
    }
  EXPECT_EQ(held, 2 * (4 * 2 + 2 * 4 + 4 * 4));                // the box's surface
  EXPECT_EQ(inside, (3 * 2 * 4) + (4 * 1 * 4) + (4 * 2 * 3));  // its interior faces
  EXPECT_EQ(long(m.closed[0].size() + m.closed[1].size() + m.closed[2].size()), held + inside);

  MacGrid<double> u(g);
  for (int c = 0; c < 3; ++c) std::fill(u.comp[c].begin(), u.comp[c].end(), 1.5);
  enforce_solids(m, u);
  for (int c = 0; c < 3; ++c)
    for (std::size_t q = 0; q < u.comp[c].size(); ++q)
      EXPECT_EQ(u.comp[c][q], m.face[c][q] == uint8_t(FaceKind::kOpen) ? 1.5 : 0.0);
}

// The parabolic inflow's weights average to 1 exactly (the flux equals the uniform inflow's),
// vanish nowhere inside, are symmetric, and follow 6 s (1 - s) to O(h^2).
TEST(Solids, ParabolicInflowKeepsTheFlux) {
  const GridGeometry g = grid(4, 10, 6, 0.1, false);
  FluidParams p;
  p.boundary = Boundary::kTunnel;
  p.inflow_profile = InflowProfile::kParabolic;
  p.wall_y_min = p.wall_y_max = Slip::kNoSlip;
  const std::vector<double> w = inflow_weights(g, p);
  double sum = 0;
  for (double x : w) sum += x;
  EXPECT_NEAR(sum / w.size(), 1.0, 1e-14);
  for (int j = 0; j < g.ny; ++j)
    for (int k = 0; k < g.nz; ++k) {
      const double s = (j + 0.5) / g.ny;
      EXPECT_NEAR(w[j * g.nz + k], 6 * s * (1 - s), 1.0 / (g.ny * g.ny));  // + 1/(2 n^2) exactly
      EXPECT_NEAR(w[j * g.nz + k], w[(g.ny - 1 - j) * g.nz + k], 1e-14);
    }
  p.wall_z_min = p.wall_z_max = Slip::kNoSlip;  // both axes: the product, mean still 1
  double sum2 = 0;
  for (double x : inflow_weights(g, p)) sum2 += x;
  EXPECT_NEAR(sum2 / w.size(), 1.0, 1e-14);
  p.inflow_profile = InflowProfile::kUniform;
  for (double x : inflow_weights(g, p)) EXPECT_EQ(x, 1.0);
}

// The no-slip mirror is second order: the discrete channel profile u = A y (H - y) + A h^2 / 4
// has the same Laplacian, -2A, at every node, the wall nodes included; so one explicit viscous
// step adds the same increment everywhere. With free-slip walls a uniform flow is untouched.
TEST(Solids, NoSlipWallsMirrorTheVelocity) {
  const int ny = 10;
  const double h = 0.1, H = ny * h, A = 3.0, nu_dt = 0.1 * h * h;  // one substep
  const GridGeometry g = grid(6, ny, 4, h, false);
  FluidParams p;
  p.boundary = Boundary::kTunnel;
  p.wall_y_min = p.wall_y_max = Slip::kNoSlip;
  SolidMap m;
  m.build(g, p);
  MacGrid<double> u(g), scratch(g);
  for (int i = 0; i < g.nx + 1; ++i)
    for (int j = 0; j < ny; ++j)
      for (int k = 0; k < g.nz; ++k) {
        const double y = (j + 0.5) * h;
        u.at(0, i, j, k) = A * y * (H - y) + A * h * h / 4;
      }
  const MacGrid<double> before = u;
  EXPECT_EQ(diffuse_explicit(m, nu_dt, u, scratch), 1);
  for (int i = 1; i < g.nx + 1; ++i)  // i = 0 is the inflow face, held
    for (int j = 0; j < ny; ++j)
      for (int k = 0; k < g.nz; ++k)
        EXPECT_NEAR(u.at(0, i, j, k) - before.at(0, i, j, k), -2 * A * nu_dt, 1e-13);

  // Free-slip y walls leave a uniform flow alone; no-slip z walls slow the layers beside them.
  p.wall_y_min = p.wall_y_max = Slip::kFreeSlip;
  p.wall_z_min = p.wall_z_max = Slip::kNoSlip;
  m.build(g, p);
  for (int c = 0; c < 3; ++c) std::fill(u.comp[c].begin(), u.comp[c].end(), 0.0);
  for (double& x : u.comp[0]) x = 2.0;
  EXPECT_EQ(diffuse_explicit(m, 0.1 * h * h, u, scratch), 1);
  for (int i = 0; i < g.nx + 1; ++i)
    for (int j = 0; j < ny; ++j)
      for (int k = 0; k < g.nz; ++k) {
        const bool beside = i > 0 && (k == 0 || k == g.nz - 1);  // i = 0: the inflow, held
        EXPECT_NEAR(u.at(0, i, j, k), beside ? 2.0 - 0.1 * 2 * 2.0 : 2.0, 1e-15);
      }
}

// Away from walls and solids the explicit viscous step is the 7-point Laplacian: of u = x^2 + 2
// y^2 + 3 z^2 it is 12 at every such node, in each component (the axes weighted apart, so a
// neighbour taken along the wrong axis shows), on a bounded and a periodic grid with a solid.
TEST(Solids, ExplicitViscosityIsTheLaplacianAwayFromWallsAndSolids) {
  for (const bool periodic : {false, true}) {
    const double h = 0.1, nu_dt = 0.1 * h * h;  // one substep
    const GridGeometry g = grid(10, 9, 8, h, periodic);
    FluidParams p;
    p.boundary = periodic ? Boundary::kPeriodic : Boundary::kTunnel;
    ObstacleParams box;
    box.center = Vec3(0.5, 0.45, 0.4);
    box.half_size = Vec3(0.12, 0.12, 0.12);
    p.obstacles = {box};
    SolidMap m;
    m.build(g, p);
    MacGrid<double> u(g), scratch(g);
    auto field = [](const Vec3& x) {
      return x.x() * x.x() + 2 * x.y() * x.y() + 3 * x.z() * x.z();
    };
    for (int c = 0; c < 3; ++c) {
      const Shape3 s = u.shape[c];
      for (int i = 0; i < s.n[0]; ++i)
        for (int j = 0; j < s.n[1]; ++j)
          for (int k = 0; k < s.n[2]; ++k) u.at(c, i, j, k) = field(g.face_position(c, i, j, k));
    }
    const MacGrid<double> before = u;
    EXPECT_EQ(diffuse_explicit(m, nu_dt, u, scratch), 1);
    int checked = 0;
    for (int c = 0; c < 3; ++c) {
      const Shape3 s = u.shape[c];
      const uint8_t* kind = m.face[c].data();
      // nodes at least two faces from the grid's ends (no wrap: the field is not periodic) whose
      // six neighbours are open
      for (int i = 2; i + 2 < s.n[0]; ++i)
        for (int j = 2; j + 2 < s.n[1]; ++j)
          for (int k = 2; k + 2 < s.n[2]; ++k) {
            bool open = kind[s.index(i, j, k)] == uint8_t(FaceKind::kOpen);
            for (int d = 0; d < 3 && open; ++d)
              for (int side = -1; side <= 1; side += 2) {
                int nb[3] = {i, j, k};
                nb[d] += side;
                open = open && kind[s.index(nb[0], nb[1], nb[2])] == uint8_t(FaceKind::kOpen);
              }
            if (!open) continue;
            ++checked;
            EXPECT_NEAR(u.at(c, i, j, k) - before.at(c, i, j, k), 12 * nu_dt, 1e-12)
                << c << " " << i << " " << j << " " << k;
          }
    }
    EXPECT_GT(checked, 100);
  }
}

// Inside a solid the mirror holds too: a free-slip slab leaves a uniform flow along it alone, a
// no-slip slab slows the nodes beside it.
TEST(Solids, SlabSlipDecidesTheShear) {
  const GridGeometry g = grid(8, 8, 4, 0.125, true);
  for (Slip slip : {Slip::kFreeSlip, Slip::kNoSlip}) {
    FluidParams p;
    ObstacleParams slab;
    slab.center = Vec3(0.5, 0.5, 0.25);
    slab.half_size = Vec3(10, 0.13, 10);  // two cell layers across y, through the periodic box
    slab.slip = slip;
    p.obstacles = {slab};
    SolidMap m;
    m.build(g, p);
    MacGrid<double> u(g), scratch(g);
    std::fill(u.comp[0].begin(), u.comp[0].end(), 1.0);
    enforce_solids(m, u);
    diffuse_explicit(m, 0.1 * g.h * g.h, u, scratch);
    for (int j = 0; j < g.ny; ++j) {
      const bool solid = m.cell_owner(0, j, 0) != 0;
      const bool beside = !solid && (m.cell_owner(0, j - 1, 0) || m.cell_owner(0, j + 1, 0));
      const double v = u.at(0, 3, j, 1);
      if (solid)
        EXPECT_EQ(v, 0.0);
      else if (beside && slip == Slip::kNoSlip)
        EXPECT_NEAR(v, 1.0 - 0.2, 1e-14);  // mirror -1: (-1 - 1) * 0.1
      else
        EXPECT_EQ(v, 1.0);
    }
  }
}

// Pressure on a solid: a uniform pressure pushes on it with zero net force; a linear pressure
// with Archimedes' force -grad p * V, exactly (the face values are extrapolated linearly).
// Shear on a no-slip plate in a linear (Couette) profile: mu S per unit area.
TEST(Solids, ForcesOnAnObstacle) {
  const double h = 0.1, rho = 1.2, dt = 0.01, nu = 1e-3;
  const GridGeometry g = grid(12, 10, 10, h, false);
  FluidParams p;
  p.boundary = Boundary::kTunnel;
  ObstacleParams box;
  box.center = Vec3(0.6, 0.5, 0.55);
  box.half_size = Vec3(0.2, 0.1, 0.14);  // 4 x 2 x 3 cells
  p.obstacles = {box};
  SolidMap m;
  m.build(g, p);
  ASSERT_EQ(m.cell_count[0], 4 * 2 * 3);
  const double volume = m.cell_count[0] * h * h * h;
  MacGrid<double> u(g);
  std::vector<double> phi(g.cells().size());
  const double G = 7.0;  // Pa/m along x
  for (int i = 0; i < g.nx; ++i)
    for (int j = 0; j < g.ny; ++j)
      for (int k = 0; k < g.nz; ++k) {
        const double x = (i + 0.5) * h;
        phi[g.cells().index(i, j, k)] = m.cell_owner(i, j, k) ? 0.0 : (3.0 + G * x) * dt / rho;
      }
  Vec3 f = obstacle_force(m, 0, u, phi.data(), dt, rho, nu);
  EXPECT_NEAR(f.x(), -G * volume, 1e-12);
  EXPECT_NEAR(f.y(), 0.0, 1e-12);
  EXPECT_NEAR(f.z(), 0.0, 1e-12);

  std::fill(phi.begin(), phi.end(), 0.0);
  const double S = 4.0;  // 1/s: u = S (y - y_top) above the box's top face
  const double top = box.center.y() + 0.1;
  for (int i = 0; i < g.nx + 1; ++i)
    for (int j = 0; j < g.ny; ++j)
      for (int k = 0; k < g.nz; ++k) {
        const double y = (j + 0.5) * h;
        u.at(0, i, j, k) = y > top ? S * (y - top) : 0.0;
      }
  enforce_solids(m, u);
  f = obstacle_force(m, 0, u, phi.data(), dt, rho, nu);
  // Open x-faces above the top: i = 5 .. 7 (i = 4 and 8 are the box's front and back x-faces,
  // held), 3 cells deep in z, h^2 each; below the box the profile is 0.
  const double plate = 3 * 3 * h * h;
  EXPECT_NEAR(f.x(), rho * nu * S * plate, 1e-12);
}

}  // namespace flagsim

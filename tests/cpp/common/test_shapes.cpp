#include <gtest/gtest.h>

#include <random>

#include "common/errors.h"
#include "common/shapes.h"

namespace flagsim {

// A closed triangle mesh of the box centre c, half extents h (12 triangles, outward winding).
SolidGeometry box_mesh(const Vec3& c, const Vec3& h) {
  SolidGeometry g;
  g.shape = ObstacleShape::kMesh;
  g.vertices.resize(8, 3);
  for (int i = 0; i < 8; ++i)
    g.vertices.row(i) =
        (c + Vec3(i & 1 ? h.x() : -h.x(), i & 2 ? h.y() : -h.y(), i & 4 ? h.z() : -h.z()))
            .transpose();
  g.faces.resize(12, 3);
  g.faces << 0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4, 2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4,
      6, 1, 3, 5, 3, 7, 5;
  return g;
}

TEST(Shapes, MeshOfABoxHasTheBoxsDistanceAndInside) {
  SolidGeometry box;
  box.center = Vec3(0.1, -0.2, 0.3);
  box.half_size = Vec3(0.3, 0.2, 0.1);
  const SolidGeometry mesh = box_mesh(box.center, box.half_size);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-0.6, 0.6);
  for (int k = 0; k < 500; ++k) {
    const Vec3 p = box.center + Vec3(u(rng), u(rng), u(rng));
    Vec3 gb, gm;
    const double db = solid_distance(box, p, &gb), dm = solid_distance(mesh, p, &gm);
    EXPECT_NEAR(dm, db, 1e-12) << p.transpose();
    EXPECT_EQ(mesh.contains(p), box.contains(p)) << p.transpose();
    if (db > 1e-9) {
      EXPECT_LT((gm - gb).norm(), 1e-9) << p.transpose();
    }
  }
  EXPECT_NEAR(winding_number(mesh.vertices, mesh.faces, box.center), 1.0, 1e-12);
  EXPECT_NEAR(winding_number(mesh.vertices, mesh.faces, Vec3(5, 5, 5)), 0.0, 1e-12);
}

TEST(Shapes, CapsuleDistanceIsToItsSegment) {
  SolidGeometry c;
  c.shape = ObstacleShape::kCapsule;
  c.axis = Vec3(0, 2, 0);
  c.length = 1.0;
  c.radius = 0.1;
  EXPECT_NEAR(solid_distance(c, Vec3(0.5, 0.2, 0)), 0.4, 1e-15);      // beside the segment
  EXPECT_NEAR(solid_distance(c, Vec3(0, 1.0, 0)), 0.4, 1e-15);        // beyond an end
  EXPECT_NEAR(solid_distance(c, Vec3(0, 0.54, 0.03)), -0.05, 1e-15);  // inside a cap
  EXPECT_TRUE(c.contains(Vec3(0, 0.55, 0)));
  EXPECT_FALSE(c.contains(Vec3(0, 0.65, 0)));
}

TEST(Shapes, MeshWithBadIndicesNamesTheFace) {
  SolidGeometry g = box_mesh(Vec3::Zero(), Vec3::Ones());
  g.faces(3, 1) = 8;
  try {
    g.validate_geometry("solids[0]");
    FAIL() << "accepted index 8 of 8 vertices";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("solids[0].faces[3]"), std::string::npos) << e.what();
  }
  g.faces.resize(2, 3);
  g.faces.setZero();
  EXPECT_THROW(g.validate_mesh("s"), InvalidArgument);  // not a closed mesh
}

}  // namespace flagsim

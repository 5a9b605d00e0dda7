#include <gtest/gtest.h>

#include <cmath>

#include "collision/params.h"
#include "common/errors.h"

namespace flagsim {
namespace {

template <class P>
std::string message(const P& p, const char* prefix) {
  try {
    p.validate(prefix);
  } catch (const InvalidArgument& e) {
    return e.what();
  }
  return "no error";
}

TEST(SelfCollisionParams, ValidateNamesTheParameter) {
  SelfCollisionParams p;
  EXPECT_EQ(message(p, "self_collision"), "no error");
  p.thickness = -0.001;
  EXPECT_EQ(message(p, "self_collision"),
            "self_collision.thickness should be finite and > 0, got -0.001");
  p = SelfCollisionParams{};
  p.friction = NAN;
  EXPECT_EQ(message(p, "self_collision"),
            "self_collision.friction should be finite and >= 0, got nan");
  p = SelfCollisionParams{};
  p.iterations = 0;
  EXPECT_EQ(message(p, "self_collision"),
            "self_collision.iterations should be in [1, 1000], got 0");
}

TEST(PoleParams, ValidateNamesTheParameter) {
  PoleParams p;
  EXPECT_EQ(message(p, "pole"), "no error");
  p.radius = 0;
  EXPECT_EQ(message(p, "pole"), "pole.radius should be in (0, 1e+06] m, got 0");
  p = PoleParams{};
  p.height = -2;
  EXPECT_EQ(message(p, "pole"), "pole.height should be in (0, 1e+06] m, got -2");
  p = PoleParams{};
  p.base.y() = INFINITY;
  EXPECT_EQ(message(p, "pole").rfind("pole.base should be finite, got (", 0), 0u);
}

}  // namespace
}  // namespace flagsim

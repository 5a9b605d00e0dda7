#include <gtest/gtest.h>

#include "common/errors.h"
#include "common/keyframes.h"

namespace flagsim {

TEST(WindSchedule, InterpolatesLinearlyAndHoldsEnds) {
  WindSchedule w;
  w.keys = {{0.0, Vec3(2, 0, 0)}, {1.0, Vec3(4, 0, 2)}, {3.0, Vec3(-4, 0, 2)}};
  EXPECT_TRUE(w.at(-1.0).isApprox(Vec3(2, 0, 0)));
  EXPECT_TRUE(w.at(0.25).isApprox(Vec3(2.5, 0, 0.5)));
  EXPECT_TRUE(w.at(2.0).isApprox(Vec3(0, 0, 2)));
  EXPECT_TRUE(w.at(10.0).isApprox(Vec3(-4, 0, 2)));
  EXPECT_FALSE(w.constant());
  EXPECT_DOUBLE_EQ(w.max_speed(), std::sqrt(20.0));
  EXPECT_TRUE(WindSchedule().at(1.0).isZero());
  EXPECT_TRUE(WindSchedule(Vec3(1, 2, 3)).constant());
}

TEST(WindSchedule, RejectsUnorderedOrNonFiniteKeys) {
  WindSchedule w;
  w.keys = {{1.0, Vec3(1, 0, 0)}, {1.0, Vec3(2, 0, 0)}};
  EXPECT_THROW(
      {
        try {
          w.validate("air.wind");
        } catch (const InvalidArgument& e) {
          EXPECT_NE(std::string(e.what()).find("air.wind[1].time"), std::string::npos);
          throw;
        }
      },
      InvalidArgument);
  w.keys = {{0.0, Vec3(NAN, 0, 0)}};
  EXPECT_THROW(w.validate("air.wind"), InvalidArgument);
}

TEST(ScalarSchedule, FallbackWhenEmpty) {
  ScalarSchedule s;
  EXPECT_EQ(s.at(3.0, 1.0), 1.0);
  s.keys = {{0.0, 0.0}, {2.0, 1.0}};
  EXPECT_DOUBLE_EQ(s.at(0.5), 0.25);
}

}  // namespace flagsim

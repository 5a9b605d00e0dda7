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

TEST(MotionSchedule, RotatesAboutThePivotAndTranslatesLinearly) {
  MotionSchedule m;
  m.pivot = Vec3(1, 0, 0);
  m.keys = {{0.0, Vec3::Zero(), Vec3::Zero()}, {2.0, Vec3(0, 2, 0), Vec3(0, 0, 90)}};
  // halfway: 45 degrees about z through the pivot, then up 1 m
  const Pose p = m.at(1.0);
  const double c = std::sqrt(0.5);
  EXPECT_TRUE(p.apply(Vec3(1, 0, 0)).isApprox(Vec3(1, 1, 0)));  // the pivot only translates
  EXPECT_TRUE(p.apply(Vec3(2, 0, 0)).isApprox(Vec3(1 + c, 1 + c, 0)));
  EXPECT_TRUE(p.inverse(p.apply(Vec3(0.3, -2, 5))).isApprox(Vec3(0.3, -2, 5)));
  EXPECT_TRUE(m.at(-1.0).R.isApprox(Mat3::Identity()));  // first key held before
  EXPECT_TRUE(m.at(5.0).apply(Vec3(2, 0, 0)).isApprox(Vec3(1, 3, 0), 1e-12));  // last after
  EXPECT_TRUE(MotionSchedule().at(3.0).R.isIdentity());
}

TEST(MotionSchedule, RepeatPlaysTheKeysAgain) {
  MotionSchedule m;
  m.repeat = true;
  m.keys = {{0.0, Vec3::Zero(), Vec3::Zero()},
            {1.0, Vec3(1, 0, 0), Vec3::Zero()},
            {2.0, Vec3::Zero(), Vec3::Zero()}};
  for (double t : {0.25, 0.5, 1.75})
    EXPECT_NEAR((m.at(t + 2.0).t - m.at(t).t).norm(), 0.0, 1e-12) << t;
  EXPECT_NEAR(m.at(-0.5).t.x(), 0.5, 1e-12);
}

TEST(MotionSchedule, RejectsNonMonotoneKeysNamingThem) {
  MotionSchedule m;
  m.keys = {{0.0, Vec3::Zero(), Vec3::Zero()},
            {1.0, Vec3::Zero(), Vec3::Zero()},
            {0.5, Vec3::Zero(), Vec3::Zero()}};
  try {
    m.validate("flag.pin_motion");
    FAIL() << "accepted keys out of order";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("flag.pin_motion.keys[2].time"), std::string::npos);
  }
  m.keys.resize(1);
  m.repeat = true;  // no period: the one pose holds
  m.validate("m");
  EXPECT_TRUE(m.at(7.0).R.isIdentity());
}

}  // namespace flagsim

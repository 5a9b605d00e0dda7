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

// A point carried at 5 m/s along x for 10 s through a wind rising from 2 to 8 m/s along x: the
// wind relative to it is |w - 5| (3 m/s at both ends), then 8 m/s once it stops (exact for a
// translation); no motion: the wind's own largest speed.
TEST(CarriedSpeeds, WindRelativeToATranslationIsExact) {
  MotionSchedule carry;
  carry.keys = {{0.0, Vec3::Zero(), Vec3::Zero()}, {10.0, Vec3(50, 0, 0), Vec3::Zero()}};
  WindSchedule w(Vec3(2, 0, 0));
  CarriedSpeeds c = carried_speeds(w, carry, Vec3(0.3, 1, 0));
  EXPECT_NEAR(c.relative, 3.0, 1e-12);
  EXPECT_NEAR(c.own, 5.0, 1e-12);
  w.keys = {{0.0, Vec3(2, 0, 0)}, {10.0, Vec3(8, 0, 0)}};
  EXPECT_NEAR(carried_speeds(w, carry, Vec3::Zero()).relative, 8.0, 1e-12);
  carry.keys.push_back({20.0, Vec3(50, 0, 0), Vec3::Zero()});  // still from 10 s: 8 m/s then
  w.keys = {{0.0, Vec3(2, 0, 0)}, {10.0, Vec3(8, 0, 0)}, {10.5, Vec3(5, 0, 0)}};
  EXPECT_NEAR(carried_speeds(w, carry, Vec3::Zero()).relative, 8.0, 1e-12);
  c = carried_speeds(w, MotionSchedule{}, Vec3::Zero());
  EXPECT_NEAR(c.relative, w.max_speed(), 1e-12);
  EXPECT_EQ(c.own, 0.0);
}

// A repeating carry (5 m along x in 1 s, then back to the start and again) in a wind that
// moves with it: the jump back at each period is never taken for a velocity.
TEST(CarriedSpeeds, ARepeatingMotionIsFollowedWithoutItsJumpBack) {
  MotionSchedule carry;
  carry.repeat = true;
  carry.keys = {{0.0, Vec3::Zero(), Vec3::Zero()}, {1.0, Vec3(5, 0, 0), Vec3::Zero()}};
  const CarriedSpeeds c = carried_speeds(WindSchedule(Vec3(5, 0, 0)), carry, Vec3(0, 1, 0));
  EXPECT_NEAR(c.relative, 0.0, 1e-12);
  EXPECT_NEAR(c.own, 5.0, 1e-12);
}

// Turning about y at 90 degrees/s, a point 2 m from the axis moves at pi m/s (the secants over
// an eighth of the piece come within 0.1 % of it), in still air.
TEST(CarriedSpeeds, ARotationIsSampledWithinItsPieces) {
  MotionSchedule turn;
  turn.keys = {{0.0, Vec3::Zero(), Vec3::Zero()}, {1.0, Vec3::Zero(), Vec3(0, 90, 0)}};
  const CarriedSpeeds c = carried_speeds(WindSchedule{}, turn, Vec3(2, 0, 0));
  const double pi = 3.14159265358979323846;
  EXPECT_NEAR(c.own, pi, 1e-3 * pi);
  EXPECT_LE(c.own, pi);
  EXPECT_EQ(c.relative, c.own);
}

}  // namespace flagsim

#include <gtest/gtest.h>

#include "common/errors.h"
#include "fluid/fluid.h"
#include "fluid/params.h"

namespace flagsim {

namespace {
std::string error_of(const FluidParams& p, const std::string& prefix = "air") {
  try {
    p.validate(prefix);
    p.validate_combination(prefix);
  } catch (const InvalidArgument& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(FluidParams, DefaultsAreValid) { EXPECT_EQ(error_of(FluidParams()), ""); }

TEST(FluidParams, ErrorsNameTheParameter) {
  FluidParams p;
  p.resolution = {16, 0, 16};
  EXPECT_NE(error_of(p).find("air.resolution should be"), std::string::npos) << error_of(p);
  p = FluidParams();
  p.cell_size = -0.1;
  EXPECT_NE(error_of(p).find("air.cell_size should be in [1e-06, 10000], got -0.1"),
            std::string::npos);
  EXPECT_THROW(
      {
        try {
          parse_enum<Advection>("air.advection", "upwind");
        } catch (const InvalidArgument& e) {
          EXPECT_STREQ(e.what(),
                       "air.advection should be one of \"semi_lagrangian\", \"maccormack\", "
                       "got \"upwind\"");
          throw;
        }
      },
      InvalidArgument);
  p = FluidParams();
  p.pressure = Pressure::kFft;
  p.boundary = Boundary::kTunnel;
  EXPECT_NE(
      error_of(p).find("air.pressure should be \"pcg\" or \"multigrid\" with boundary \"tunnel\""),
      std::string::npos)
      << error_of(p);
  p = FluidParams();
  p.viscosity = -1;
  EXPECT_NE(error_of(p).find("air.viscosity"), std::string::npos);
  p = FluidParams();
  p.fans.emplace_back();
  p.fans[0].radius = 0;
  EXPECT_NE(error_of(p).find("air.fans[0].radius"), std::string::npos);
  p.fans[0] = FanParams();
  p.fans[0].direction = Vec3::Zero();
  EXPECT_NE(error_of(p).find("air.fans[0].direction"), std::string::npos);
  EXPECT_THROW(parse_enum<Precision>("precision", "half"), InvalidArgument);
  EXPECT_STREQ(name_of(Precision::kFloat), "float");
}

// The message a build without FFTW gives, tested in every build; validate_combination asks for it
// exactly when this build has no FFTW.
TEST(FluidParams, FftWithoutFftwIsAMissingFeature) {
  FluidParams p;
  p.pressure = Pressure::kFft;
  EXPECT_NO_THROW(p.validate("air"));  // each field is fine on its own
  if (kBuiltWithFftw) {
    EXPECT_NO_THROW(p.validate_combination("air"));
  } else {
    EXPECT_THROW(p.validate_combination("air"), MissingFeature);
  }
  try {
    require_fftw("air.pressure", false);
    ADD_FAILURE() << "no MissingFeature";
  } catch (const MissingFeature& e) {
    EXPECT_STREQ(e.what(),
                 "air.pressure should be \"pcg\" or \"multigrid\": this flagsim was built without "
                 "FFTW "
                 "(FLAGSIM_WITH_FFTW=OFF), got \"fft\"");
  }
  EXPECT_NO_THROW(require_fftw("air.pressure", true));
}

}  // namespace flagsim

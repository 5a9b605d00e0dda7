#include "fluid/params.h"

#include <cmath>

#include "common/errors.h"
#include "common/memory.h"

namespace flagsim {

namespace {

std::string join(const std::string& prefix, const std::string& field) {
  return prefix.empty() ? field : prefix + "." + field;
}

}  // namespace

void FanParams::validate(const std::string& prefix) const {
  check_position(join(prefix, "center"), center);
  for (int d = 0; d < 3; ++d)
    if (!(std::isfinite(half_size[d]) && half_size[d] > 0 && half_size[d] <= kMaxCoordinate))
      fail_param(join(prefix, "half_size"), "in (0, 1e6] m in every component",
                 detail::to_text(half_size.transpose()));
  check_length(join(prefix, "radius"), radius);
  check_finite_vec(join(prefix, "direction"), direction);
  if (!(direction.norm() > 0))
    fail_param(join(prefix, "direction"), "a non-zero vector", "(0 0 0)");
  check_finite(join(prefix, "force_density"), force_density);
  check_nonnegative(join(prefix, "max_speed"), max_speed);
  strength.validate(join(prefix, "strength"));
}

void FluidParams::validate(const std::string& prefix) const {
  const std::string res = join(prefix, "resolution");
  long long cells = 1;
  for (int d = 0; d < 3; ++d) {
    if (resolution[d] < 1 || resolution[d] > 4096)
      fail_param(res, "3 cell counts in [1, 4096]",
                 std::to_string(resolution[0]) + " x " + std::to_string(resolution[1]) + " x " +
                     std::to_string(resolution[2]));
    cells *= resolution[d];
  }
  if (cells > (1LL << 28)) fail_param(res, "at most 2^28 cells in all", cells);
  // Below a micrometre h^3 and the pressure scale underflow long before any flag needs it.
  check_range(join(prefix, "cell_size"), cell_size, kMinCellSize, kMaxCellSize);
  check_position(join(prefix, "origin"), origin);
  check_nonnegative(join(prefix, "viscosity"), viscosity);
  check_positive(join(prefix, "density"), density);
  if (!(std::isfinite(pcg_tolerance) && pcg_tolerance > 0 && pcg_tolerance < 1))
    fail_param(join(prefix, "pcg_tolerance"), "in (0, 1)", pcg_tolerance);
  if (pcg_max_iterations < 1)
    fail_param(join(prefix, "pcg_max_iterations"), ">= 1", pcg_max_iterations);
  wind.validate(join(prefix, "wind"));
  for (size_t i = 0; i < fans.size(); ++i)
    fans[i].validate(join(prefix, "fans[" + std::to_string(i) + "]"));
}

double FluidParams::memory_bytes() const {
  return cells() * kValuesPerCell *
         double(precision == Precision::kFloat ? sizeof(float) : sizeof(double));
}

void FluidParams::validate_combination(const std::string& prefix) const {
  if (pressure == Pressure::kFft && boundary != Boundary::kPeriodic)
    fail_param(join(prefix, "pressure"),
               "\"pcg\" with boundary \"" + std::string(name_of(boundary)) +
                   "\" (fft needs a periodic domain)",
               "\"fft\"");
#ifndef FLAGSIM_HAVE_FFTW
  if (pressure == Pressure::kFft)
    throw MissingFeature(join(prefix, "pressure") +
                         " should be \"pcg\": this flagsim was built without FFTW "
                         "(FLAGSIM_WITH_FFTW=OFF), got \"fft\"");
#endif
}

}  // namespace flagsim

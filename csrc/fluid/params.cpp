#include "fluid/params.h"

#include "common/errors.h"

namespace flagsim {

void FanParams::validate(const std::string& p) const {
  if (shape != "box" && shape != "sphere") fail_param(p + ".shape", "one of 'box', 'sphere'", "'" + shape + "'");
  check_finite_vec(p + ".center", center);
  check_finite_vec(p + ".half_size", half_size);
  check_positive(p + ".radius", radius);
  check_finite_vec(p + ".direction", direction);
  check_finite(p + ".force_density", force_density);
  strength.validate(p + ".strength");
}

void FluidParams::validate(const std::string& p) const {
  throw InvalidArgument(p + ".model 'grid' is not available yet (the air solver is being built)");
  (void)p;
}

}  // namespace flagsim

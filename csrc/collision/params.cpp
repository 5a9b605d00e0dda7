#include "collision/params.h"

#include "common/errors.h"

namespace flagsim {

void SelfCollisionParams::validate(const std::string& prefix) const {
  check_positive(prefix + ".thickness", thickness);
  check_nonnegative(prefix + ".friction", friction);
  if (iterations < 1 || iterations > 1000)
    fail_param(prefix + ".iterations", "in [1, 1000]", iterations);
}

void PoleParams::validate(const std::string& prefix) const {
  check_positive(prefix + ".radius", radius);
  check_positive(prefix + ".height", height);
  check_finite_vec(prefix + ".base", base);
}

}  // namespace flagsim

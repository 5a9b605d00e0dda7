#include "collision/params.h"

#include "common/errors.h"

namespace flagsim {

void SelfCollisionParams::validate(const std::string& p) const {
  check_positive(p + ".thickness", thickness);
  check_nonnegative(p + ".friction", friction);
  if (iterations < 1 || iterations > 1000)
    fail_param(p + ".iterations", "in [1, 1000]", iterations);
}

void PoleParams::validate(const std::string& p) const {
  check_length(p + ".radius", radius);
  check_length(p + ".height", height);
  check_position(p + ".base", base);
}

}  // namespace flagsim

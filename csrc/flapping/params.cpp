#include "flapping/params.h"

#include "common/errors.h"

namespace flagsim {

void FlappingParams::validate(const std::string& p) const {
  check_nonnegative(p + ".amplitude", amplitude);
  check_positive(p + ".l_max", l_max);
  check_finite(p + ".speed", speed);
  check_finite(p + ".parabola", parabola);
  check_positive(p + ".frequency", frequency);
  check_nonnegative(p + ".ramp", ramp);
}

}  // namespace flagsim

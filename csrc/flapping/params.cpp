#include "flapping/params.h"

#include "common/errors.h"

namespace flagsim {

void FlappingParams::validate(const std::string& p) const {
  if (mode != "displace" && mode != "force" && mode != "visual" && mode != "off")
    fail_param(p + ".mode", "one of 'displace', 'force', 'visual', 'off'", "'" + mode + "'");
  check_nonnegative(p + ".amplitude", amplitude);
  check_positive(p + ".l_max", l_max);
  check_finite(p + ".speed", speed);
  check_finite(p + ".parabola", parabola);
  check_positive(p + ".frequency", frequency);
  check_nonnegative(p + ".ramp", ramp);
}

}  // namespace flagsim

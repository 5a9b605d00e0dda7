#include "flapping/params.h"

#include "common/errors.h"

namespace flagsim {

void FlappingParams::validate(const std::string& prefix) const {
  if (mode != "displace" && mode != "force" && mode != "visual" && mode != "off")
    fail_param(prefix + ".mode", "one of \"displace\", \"force\", \"visual\", \"off\"",
               "\"" + mode + "\"");
  check_nonnegative(prefix + ".amplitude", amplitude);
  check_positive(prefix + ".l_max", l_max);
  check_finite(prefix + ".speed", speed);
  check_finite(prefix + ".parabola", parabola);
  check_positive(prefix + ".frequency", frequency);
}

}  // namespace flagsim

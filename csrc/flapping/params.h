// Parameters of the paper's flapping model (eq. 5).
#pragma once
#include <cstdint>
#include <string>

#include "common/enums.h"

namespace flagsim {

/// Eq. 5 as the paper (displace: moves the cloth), as a normal force, on the exported geometry
/// only (visual), or off.
enum class FlapMode { kDisplace, kForce, kVisual, kOff };
template <>
struct EnumNames<FlapMode> {
  static constexpr std::array<const char*, 4> names{"displace", "force", "visual", "off"};
};

struct FlappingParams {
  FlapMode mode = FlapMode::kOff;
  double amplitude = 0.01;  ///< A at L >= l_max, m of displacement per m/s of u_p
  double l_max = 0.2;       ///< m, distance from the nearest pin where A stops growing
  double speed = 1.0;       ///< v, wave speed in normalised flag lengths per second
  double parabola = 1.0;    ///< a, parabola shape coefficient (eq. 5)
  double frequency = 3.0;   ///< noise lattice cells per normalised flag length
  double ramp = 0.5;        ///< s, eq. 5 fades in over this time from a flat flag at t = 0
                            ///< (C1 smoothstep, as A(L)); 0 = the whole wave from the start
  uint32_t seed = 0;
  void validate(const std::string& prefix) const;
};

}  // namespace flagsim

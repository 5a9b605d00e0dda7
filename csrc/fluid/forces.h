// External force on the air (paper eq. 1, term f): fan regions, each a box or a sphere pushing
// with a force density (N/m^3) along a direction, scaled by a keyframed strength.
#pragma once
#include <array>
#include <cstdint>
#include <utility>
#include <vector>

#include "fluid/grid.h"
#include "fluid/params.h"

namespace flagsim {

/// The faces a fan covers, with the acceleration f / rho (m/s^2) it gives each along that face's
/// axis. Built once; apply_fans only reads it.
template <class T>
struct FanStencil {
  std::array<std::vector<std::pair<uint32_t, T>>, 3> faces;  ///< (face index, m/s^2) per component
  ScalarSchedule strength;                                   ///< factor over time, 1 when empty
  Vec3 target{0, 0, 0};  ///< m/s, max_speed * direction (fan curve), per component; 0: no curve
};

/// Stencils of `fans` on grid `geo` for air of density rho (kg/m^3). A face belongs to a fan when
/// its centre lies inside the box (closed) or the sphere.
template <class T>
std::vector<FanStencil<T>> build_fan_stencils(const GridGeometry& geo,
                                              const std::vector<FanParams>& fans, double rho);

/// u += dt * strength(t) * f / rho * (1 - u / target)_+ on every covered face (the last factor
/// only when the fan has a max_speed). t, dt in s. No allocation.
template <class T>
void apply_fans(const std::vector<FanStencil<T>>& fans, double t, double dt, MacGrid<T>& u);

}  // namespace flagsim

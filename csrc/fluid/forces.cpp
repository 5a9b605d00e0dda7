#include "fluid/forces.h"

#include <algorithm>

namespace flagsim {

template <class T>
std::vector<FanStencil<T>> build_fan_stencils(const GridGeometry& geo,
                                              const std::vector<FanParams>& fans, double rho) {
  std::vector<FanStencil<T>> out;
  out.reserve(fans.size());
  for (const FanParams& f : fans) {
    FanStencil<T> s;
    s.strength = f.strength;
    const Vec3 acc = f.direction.normalized() * (f.force_density / rho);
    s.target = f.direction.normalized() * f.max_speed;
    for (int c = 0; c < 3; ++c) {
      if (acc[c] == 0) continue;
      const Shape3 sh = geo.face_shape(c);
      for (int i = 0; i < sh.n[0]; ++i)
        for (int j = 0; j < sh.n[1]; ++j)
          for (int k = 0; k < sh.n[2]; ++k) {
            const Vec3 d = geo.face_position(c, i, j, k) - f.center;
            const bool inside = f.shape == FanShape::kSphere
                                    ? d.squaredNorm() <= f.radius * f.radius
                                    : (d.array().abs() <= f.half_size.array()).all();
            if (inside) s.faces[c].emplace_back(uint32_t(sh.index(i, j, k)), T(acc[c]));
          }
    }
    out.push_back(std::move(s));
  }
  return out;
}

template <class T>
void apply_fans(const std::vector<FanStencil<T>>& fans, double t, double dt, MacGrid<T>& u) {
  for (const FanStencil<T>& f : fans) {
    const double s = dt * f.strength.at(t, 1.0);
    if (s == 0) continue;
    for (int c = 0; c < 3; ++c) {
      T* q = u.comp[c].data();
      if (f.target[c] == 0) {
        for (const auto& e : f.faces[c]) q[e.first] = T(q[e.first] + s * e.second);
      } else {
        const double inv_target = 1.0 / f.target[c];
        for (const auto& e : f.faces[c]) {
          const double fade = std::max(0.0, 1.0 - q[e.first] * inv_target);
          q[e.first] = T(q[e.first] + s * e.second * fade);
        }
      }
    }
  }
}

template std::vector<FanStencil<float>> build_fan_stencils<float>(const GridGeometry&,
                                                                  const std::vector<FanParams>&,
                                                                  double);
template std::vector<FanStencil<double>> build_fan_stencils<double>(const GridGeometry&,
                                                                    const std::vector<FanParams>&,
                                                                    double);
template void apply_fans<float>(const std::vector<FanStencil<float>>&, double, double,
                                MacGrid<float>&);
template void apply_fans<double>(const std::vector<FanStencil<double>>&, double, double,
                                 MacGrid<double>&);

}  // namespace flagsim

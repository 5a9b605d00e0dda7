#include "collision/impact_zones.h"

#include <algorithm>

#include "collision/pole.h"

namespace flagsim {

ImpactZones::ImpactZones(Index num_vertices) : frozen_(static_cast<size_t>(num_vertices), 0) {}

void ImpactZones::clear() { std::fill(frozen_.begin(), frozen_.end(), uint8_t{0}); }

Index ImpactZones::freeze(const int32_t group[4], const MatX3& x0, MatX3& x, MatX3& v,
                          const VecX& inv_mass) {
  Vec3 momentum = Vec3::Zero(), pin = Vec3::Zero();
  double mass = 0;
  bool pinned = false;
  for (int k = 0; k < 4; ++k) {
    const int32_t i = group[k];
    if (inv_mass[i] == 0) {
      if (!pinned) pin = row(v, i);
      pinned = true;
      continue;
    }
    momentum += row(v, i) / inv_mass[i];
    mass += 1 / inv_mass[i];
  }
  const Vec3 common = pinned ? pin : !(mass > 0) ? Vec3::Zero() : Vec3(momentum / mass);
  Index added = 0;
  for (int k = 0; k < 4; ++k) {
    const int32_t i = group[k];
    if (inv_mass[i] == 0) continue;
    x.row(i) = x0.row(i);
    v.row(i) = common.transpose();
    if (!frozen_[i]) {
      frozen_[i] = 1;
      ++added;
    }
  }
  return added;
}

bool ImpactZones::any_in_pole(const PoleParams& pole, const MatX3& x, const VecX& inv_mass,
                              const RigidMotion* motion) const {
  const Index n = x.rows();
  for (Index i = 0; i < n; ++i)
    if (!still(static_cast<int32_t>(i), inv_mass) && inside_moved_pole(pole, motion, row(x, i)))
      return true;
  return false;
}

Index ImpactZones::freeze_in_pole(const PoleParams& pole, const MatX3& x0, MatX3& x, MatX3& v,
                                  const VecX& inv_mass, const RigidMotion* motion) {
  Index added = 0;
  const Index n = x.rows();
  for (Index i = 0; i < n; ++i) {
    if (still(static_cast<int32_t>(i), inv_mass) || !inside_moved_pole(pole, motion, row(x, i)))
      continue;
    x.row(i) = x0.row(i);
    if (!motion) {
      const Vec3 radial(x0(i, 0) - pole.base.x(), 0.0, x0(i, 2) - pole.base.z());
      const double r = radial.norm();
      if (r > 0) {
        const double vn = v.row(i).dot(radial.transpose()) / r;
        if (vn < 0) v.row(i) -= (vn / r) * radial.transpose();
      }
    } else {
      // In the pole's frame, relative to its surface (as collide_pole_carried).
      const Vec3 q = motion->to.inverse(row(x0, i)), surface = motion->velocity_at(q);
      const Vec3 radial = motion->to.R * Vec3(q.x() - pole.base.x(), 0.0, q.z() - pole.base.z());
      const double r = radial.norm();
      if (r > 0) {
        const double vn = (row(v, i) - surface).dot(radial) / r;
        if (vn < 0) v.row(i) -= ((vn / r) * radial).transpose();
      }
    }
    frozen_[i] = 1;
    ++added;
  }
  return added;
}

}  // namespace flagsim

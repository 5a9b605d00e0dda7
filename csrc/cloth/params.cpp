#include "cloth/params.h"

#include "common/errors.h"

namespace flagsim {

void FlagParams::validate(const std::string& p) const {
  if (rows < 2) fail_param(p + ".rows", ">= 2", rows);
  if (cols < 2) fail_param(p + ".cols", ">= 2", cols);
  if (static_cast<long long>(rows) * cols > 50'000'000)
    fail_param(p + ".rows * " + p + ".cols", "<= 5e7", 1LL * rows * cols);
  check_length(p + ".width", width);
  check_length(p + ".height", height);
  check_position(p + ".origin", origin);
  check_positive(p + ".areal_density", areal_density);
  check_nonnegative(p + ".stretch_stiffness", stretch_stiffness);
  check_nonnegative(p + ".shear_stiffness", shear_stiffness);
  check_nonnegative(p + ".bend_stiffness", bend_stiffness);
  check_nonnegative(p + ".damping", damping);
  check_nonnegative(p + ".imperfection", imperfection);
  if (!(imperfection <= kMaxCoordinate)) fail_param(p + ".imperfection", "<= 1e6 m", imperfection);
  for (size_t k = 0; k < pinned_vertices.size(); ++k) {
    int i = pinned_vertices[k];
    if (i < 0 || i >= rows * cols)
      fail_param(p + ".pinned_vertices[" + std::to_string(k) + "]",
                 "a vertex index in [0, " + std::to_string(rows * cols - 1) + "]", i);
  }
  pin_motion.validate(p + ".pin_motion");
}

void DragParams::validate(const std::string& p) const {
  check_nonnegative(p + ".coefficient", coefficient);
  check_nonnegative(p + ".tangential_coefficient", tangential_coefficient);
}

void IntegratorParams::validate(const std::string& p) const {
  if (substeps < 1 || substeps > 1000000) fail_param(p + ".substeps", "in [1, 1000000]", substeps);
  if (!(safety > 0 && safety <= 1)) fail_param(p + ".safety", "in (0, 1]", safety);
  if (max_substeps < 1) fail_param(p + ".max_substeps", ">= 1", max_substeps);
  if (!(cg_tolerance > 0 && cg_tolerance < 1))
    fail_param(p + ".cg_tolerance", "in (0, 1)", cg_tolerance);
  if (cg_max_iterations < 1) fail_param(p + ".cg_max_iterations", ">= 1", cg_max_iterations);
  if (max_halvings < 0 || max_halvings > 30)
    fail_param(p + ".max_halvings", "in [0, 30]", max_halvings);
  check_positive(p + ".max_strain", max_strain);
  check_nonnegative(p + ".strain_limit", strain_limit);
  if (strain_limit_iterations < 1)
    fail_param(p + ".strain_limit_iterations", ">= 1", strain_limit_iterations);
  check_nonnegative(p + ".energy_tolerance", energy_tolerance);
}

}  // namespace flagsim

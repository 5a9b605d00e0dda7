#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "bindings/fields.h"
#include "cloth/params.h"

namespace py = pybind11;

namespace flagsim::bindings {

void bind_cloth(py::module_& m) {
  m.attr("STRAIN_LIMIT_SLACK") = kStrainLimitSlack;  // the strain limit's promise: limit + this
  py::class_<FlagParams> flag(m, "FlagParams",
                              "The mass-spring flag (paper §3): a rows x cols grid of masses.");
  flag.def(py::init<>());
  def_field(flag, "rows", &FlagParams::rows, "flag", "masses along the height (>= 2)");
  def_field(flag, "cols", &FlagParams::cols, "flag", "masses along the width (>= 2)");
  def_field(flag, "width", &FlagParams::width, "flag", "m, along +x away from the pole");
  def_field(flag, "height", &FlagParams::height, "flag", "m, along -y from the origin");
  def_field(flag, "origin", &FlagParams::origin, "flag", "m, top pole-side corner");
  def_field(flag, "areal_density", &FlagParams::areal_density, "flag", "kg/m^2");
  def_field(flag, "stretch_stiffness", &FlagParams::stretch_stiffness, "flag",
            "N/m, structural springs (k_s)");
  def_field(flag, "shear_stiffness", &FlagParams::shear_stiffness, "flag", "N/m, diagonal springs");
  def_field(flag, "bend_stiffness", &FlagParams::bend_stiffness, "flag", "N/m, skip-one springs");
  def_field(flag, "damping", &FlagParams::damping, "flag", "N s/m, k_d of eq. 4");
  def_field(flag, "pin", &FlagParams::pin, "flag", "'pole' | 'grommets' | 'top' | 'none'");
  def_field(flag, "pinned_vertices", &FlagParams::pinned_vertices, "flag",
            "explicit pinned vertex indices; replaces `pin` when non-empty");
  def_field(flag, "imperfection", &FlagParams::imperfection, "flag",
            "m, largest seeded offset of an unpinned mass out of the flag's plane at the start "
            "(0 = flat; breaks the mirror symmetry a flat flag in still air rests on)");
  flag.def_property(
      "imperfection_seed", [](const FlagParams& p) { return p.imperfection_seed; },
      [](FlagParams& p, const py::object& seed) {
        p.imperfection_seed = checked_seed("flag.imperfection_seed",
                                           from_py<int64_t>("flag.imperfection_seed", seed));
      },
      "seed of the imperfection's offsets, an integer in [0, 2**32)");

  py::class_<DragParams> drag(m, "DragParams",
                              "Air drag: 'paper' (eq. 3), 'relative' or 'triangle'.");
  drag.def(py::init<>());
  def_field(drag, "model", &DragParams::model, "drag", "'paper' | 'relative' | 'triangle'");
  def_field(drag, "coefficient", &DragParams::coefficient, "drag", "C_D");
  def_field(drag, "tangential_coefficient", &DragParams::tangential_coefficient, "drag",
            "C_T ('triangle' only)");

  py::class_<IntegratorParams> in(m, "IntegratorParams", "Time integration of the cloth.");
  in.def(py::init<>());
  def_field(in, "method", &IntegratorParams::method, "integrator", "'explicit' | 'implicit'");
  def_field(in, "substeps", &IntegratorParams::substeps, "integrator",
            "fixed substeps per step, each of dt / substeps (explicit adaptive may add more)");
  def_field(in, "adaptive", &IntegratorParams::adaptive, "integrator",
            "explicit: substep below the stable step estimate");
  def_field(in, "safety", &IntegratorParams::safety, "integrator",
            "fraction of the stable step used when substepping, (0, 1]");
  def_field(in, "max_substeps", &IntegratorParams::max_substeps, "integrator",
            "explicit: substeps per step before DivergenceError");
  def_field(in, "cg_tolerance", &IntegratorParams::cg_tolerance, "integrator",
            "implicit: CG relative residual");
  def_field(in, "preconditioner", &IntegratorParams::preconditioner, "integrator",
            "implicit: CG preconditioner, 'auto' | 'jacobi' | 'multigrid' (grid flags)");
  def_field(in, "cg_max_iterations", &IntegratorParams::cg_max_iterations, "integrator",
            "implicit: CG iterations per solve before halving the step");
  def_field(in, "max_halvings", &IntegratorParams::max_halvings, "integrator",
            "implicit: step halvings before DivergenceError");
  def_field(in, "max_strain", &IntegratorParams::max_strain, "integrator",
            "strain beyond which a step raises DivergenceError");
  def_field(in, "strain_limit", &IntegratorParams::strain_limit, "integrator",
            "> 0: Provot strain limiting to (1 + strain_limit) x rest length");
  def_field(in, "strain_limit_iterations", &IntegratorParams::strain_limit_iterations, "integrator",
            "Gauss-Seidel sweeps of strain limiting");
  def_field(in, "energy_tolerance", &IntegratorParams::energy_tolerance, "integrator",
            "energy a step may make beyond its stages' work, as a fraction of "
            "Simulation.energy_scale, before DivergenceError('energy'); 0 = off");
}

}  // namespace flagsim::bindings

#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "bindings/fields.h"
#include "cloth/params.h"

namespace py = pybind11;

namespace flagsim::bindings {

namespace {

// Motion keys from Python: [(time s, (tx, ty, tz) m, (rx, ry, rz) degrees), ...]; each part of a
// bad value named ("flag.pin_motion.keys[2].time").
std::vector<MotionKey> motion_keys_from_py(const std::string& name, py::handle o) {
  auto seq = conv::sequence_of(name, "keyframes [(time, (tx, ty, tz), (rx, ry, rz)), ...]", o, -1);
  std::vector<MotionKey> keys;
  for (size_t i = 0; i < py::len(seq); ++i) {
    const std::string key = name + "[" + std::to_string(i) + "]";
    auto k = conv::sequence_of(key, "a triple (time s, translation m, rotation vector degrees)",
                               seq[i], 3);
    keys.push_back({from_py<double>(key + ".time", k[0]), from_py<Vec3>(key + ".translation", k[1]),
                    from_py<Vec3>(key + ".rotation", k[2])});
  }
  return keys;
}

void bind_motion(py::module_& m) {
  py::class_<MotionSchedule> ms(m, "MotionSchedule", R"doc(Keyframed rigid motion.

pose(t) maps a point p at rest to pivot + translation(t) + R(rotation(t)) (p - pivot); the
translation (m) and the rotation vector (unit axis x angle, degrees) are interpolated linearly
between keys. Before the first key the first pose holds, after the last the last one (or, with
repeat, the keys play again with period last time - first time). Empty: no motion.)doc");
  ms.def(py::init([](const py::kwargs& kw) {
           return from_fields<MotionSchedule>(kw, "MotionSchedule");
         }),
         "MotionSchedule(**fields), e.g. MotionSchedule(keys=[(0, (0, 0, 0), (0, 0, 0)), (1, (0, "
         "0.5, 0), (0, 0, 90))], pivot=(0, 0, 0), repeat=False); no fields: no motion");
  ms.def_property(
      "keys",
      [](const MotionSchedule& s) {
        py::list out;
        for (const MotionKey& k : s.keys)
          out.append(
              py::make_tuple(k.time, vec3_to_tuple(k.translation), vec3_to_tuple(k.rotation)));
        return out;
      },
      [](MotionSchedule& s, const py::object& o) {
        MotionSchedule copy = s;
        copy.keys = motion_keys_from_py("motion.keys", o);
        copy.validate("motion");
        s = copy;
      },
      "[(time s, (tx, ty, tz) m, (rx, ry, rz) degrees), ...], times strictly increasing");
  def_field(ms, "pivot", &MotionSchedule::pivot, "motion", "m, the point the rotation turns about");
  def_field(ms, "repeat", &MotionSchedule::repeat, "motion",
            "play the keys again after the last one (period: last time - first time)");
  ms.def("validate", &MotionSchedule::validate, py::arg("prefix") = "motion");
  ms.def(
      "apply",
      [](const MotionSchedule& s, double t, const MatX3& points) {
        const Pose p = s.at(t);
        MatX3 out(points.rows(), 3);
        for (Index i = 0; i < points.rows(); ++i) out.row(i) = p.apply(row(points, i)).transpose();
        return out;
      },
      py::arg("time"), py::arg("points"),
      "The points (M x 3, m, at rest) where pose(time) puts them (M x 3, m).");
}

}  // namespace

void bind_cloth(py::module_& m) {
  bind_motion(m);
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
  def_ref_field(
      flag, "pin_motion", &FlagParams::pin_motion, "flag",
      "MotionSchedule: keyframed rigid motion of the pinned vertices and the pole together");

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
            "implicit: CG preconditioner, 'auto' | 'jacobi' | 'multigrid' (grid flags) | 'ssor'");
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

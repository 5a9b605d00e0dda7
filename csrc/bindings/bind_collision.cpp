// Collisions: SelfCollisionParams and PoleParams (the scene's [self_collision] and [pole]).
#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>

#include "collision/params.h"
#include "common/errors.h"

namespace py = pybind11;
using namespace pybind11::literals;

namespace flagsim::bindings {

namespace {

// Python's shortest round-trip repr of a number (0.2, not 0.20000000000000001).
template <class T>
std::string num(T x) {
  return std::string(py::str(py::repr(py::cast(x))));
}

// Setter that validates the edited copy under the scene section's name and leaves the object
// unchanged when the value is rejected.
template <class P, class T>
auto checked_setter(T P::*field, const char* section) {
  return [field, section](P& p, const T& value) {
    P edited = p;
    edited.*field = value;
    edited.validate(section);
    p = edited;
  };
}

template <class P, class T>
auto getter(T P::*field) {
  return [field](const P& p) { return p.*field; };
}

}  // namespace

void bind_collision(py::module_& m) {
  using SC = SelfCollisionParams;
  py::class_<SC>(m, "SelfCollisionParams",
                 "Vertex-triangle self-collision (spatial hash, continuous, mass-weighted).")
      .def(py::init<>())
      .def_property("enabled", getter(&SC::enabled), checked_setter(&SC::enabled, "self_collision"),
                    "off means no stage")
      .def_property("thickness", getter(&SC::thickness),
                    checked_setter(&SC::thickness, "self_collision"),
                    "m, vertex-triangle distance the response keeps")
      .def_property("friction", getter(&SC::friction),
                    checked_setter(&SC::friction, "self_collision"), "Coulomb coefficient, >= 0")
      .def_property("iterations", getter(&SC::iterations),
                    checked_setter(&SC::iterations, "self_collision"),
                    "response sweeps per step before the freeze fallback, in [1, 1000]")
      .def("validate", &SC::validate, "prefix"_a = "self_collision")
      .def("__repr__", [](const SC& p) {
        return "SelfCollisionParams(enabled=" + std::string(p.enabled ? "True" : "False") +
               ", thickness=" + num(p.thickness) +
               ", friction=" + num(p.friction) +
               ", iterations=" + num(p.iterations) + ")";
      });

  py::class_<PoleParams>(m, "PoleParams", "Vertical (+y) cylinder the flag is pinned to.")
      .def(py::init<>())
      .def_property("enabled", getter(&PoleParams::enabled),
                    checked_setter(&PoleParams::enabled, "pole"), "collide with the pole")
      .def_property("radius", getter(&PoleParams::radius),
                    checked_setter(&PoleParams::radius, "pole"), "m")
      .def_property("height", getter(&PoleParams::height),
                    checked_setter(&PoleParams::height, "pole"), "m")
      .def_property("base", getter(&PoleParams::base), checked_setter(&PoleParams::base, "pole"),
                    "m, centre of the bottom cap (3 values; assign a new triple to change)")
      .def("validate", &PoleParams::validate, "prefix"_a = "pole")
      .def("__repr__", [](const PoleParams& p) {
        return "PoleParams(enabled=" + std::string(p.enabled ? "True" : "False") +
               ", radius=" + num(p.radius) + ", height=" + num(p.height) +
               ", base=(" + num(p.base.x()) + ", " + num(p.base.y()) +
               ", " + num(p.base.z()) + "))";
      });
}

}  // namespace flagsim::bindings

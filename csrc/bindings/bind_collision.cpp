// Collisions: SelfCollisionParams and PoleParams (the scene's [self_collision] and [pole]).
#include <pybind11/pybind11.h>

#include "bindings/fields.h"
#include "collision/params.h"

namespace py = pybind11;
using namespace pybind11::literals;

namespace flagsim::bindings {

void bind_collision(py::module_& m) {
  py::class_<SelfCollisionParams> sc(
      m, "SelfCollisionParams",
      "Vertex-triangle self-collision: spatial hash, continuous (no crossing between steps), "
      "mass-weighted push-apart.");
  sc.def(py::init<>());
  def_field(sc, "enabled", &SelfCollisionParams::enabled, "self_collision", "off: no stage");
  def_field(sc, "thickness", &SelfCollisionParams::thickness, "self_collision",
            "m, vertex-triangle distance the response keeps (at least half of it is guaranteed)");
  def_field(sc, "friction", &SelfCollisionParams::friction, "self_collision",
            "Coulomb coefficient, >= 0");
  def_field(sc, "iterations", &SelfCollisionParams::iterations, "self_collision",
            "response sweeps per step before the freeze fallback, in [1, 1000]");
  sc.def("validate", &SelfCollisionParams::validate, "prefix"_a = "self_collision");

  py::class_<PoleParams> pole(m, "PoleParams",
                              "The vertical (+y) cylinder the flag is pinned to; vertices collide "
                              "with it.");
  pole.def(py::init<>());
  def_field(pole, "enabled", &PoleParams::enabled, "pole", "collide with the pole");
  def_field(pole, "radius", &PoleParams::radius, "pole", "m");
  def_field(pole, "height", &PoleParams::height, "pole", "m");
  def_field(pole, "base", &PoleParams::base, "pole", "m, centre of the bottom cap");
  pole.def("validate", &PoleParams::validate, "prefix"_a = "pole");
}

}  // namespace flagsim::bindings

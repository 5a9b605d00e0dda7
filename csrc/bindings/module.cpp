// flagsim._core: one bind_<area>() per area, called here in dependency order.
#include <pybind11/pybind11.h>

namespace py = pybind11;

namespace flagsim::bindings {
void bind_common(py::module_& m);
void bind_fluid(py::module_& m);
void bind_cloth(py::module_& m);
void bind_collision(py::module_& m);
void bind_flapping(py::module_& m);
void bind_scene(py::module_& m);
void bind_io(py::module_& m);
}  // namespace flagsim::bindings

PYBIND11_MODULE(_core, m) {
  using namespace flagsim::bindings;
  m.doc() = "flagsim compiled core (use the flagsim package, not this module)";
  m.attr("__version__") = FLAGSIM_VERSION;
  bind_common(m);
  bind_fluid(m);
  bind_cloth(m);
  bind_collision(m);
  bind_flapping(m);
  bind_scene(m);
  bind_io(m);
}

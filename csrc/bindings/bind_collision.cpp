#include <pybind11/pybind11.h>

namespace py = pybind11;

namespace flagsim::bindings {
void bind_collision(py::module_& m) { (void)m; }
}  // namespace flagsim::bindings

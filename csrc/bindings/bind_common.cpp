#include <pybind11/pybind11.h>

#include "common/errors.h"
#include "common/parallel.h"

namespace py = pybind11;

namespace flagsim::bindings {

void bind_common(py::module_& m) {
  // DivergenceError(RuntimeError) carrying step, time, vertex and cause as attributes.
  // Leaked on purpose: the type must outlive every translator call, up to interpreter exit.
  static auto* div_type =
      new py::object(py::exception<DivergenceError>(m, "DivergenceError", PyExc_RuntimeError));
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const DivergenceError& e) {
      py::object exc = (*div_type)(e.what());
      exc.attr("step") = e.step;
      exc.attr("time") = e.time;
      exc.attr("vertex") = e.vertex;
      exc.attr("cause") = e.cause;
      PyErr_SetObject(div_type->ptr(), exc.ptr());
    }
  });
  m.def("num_threads", &num_threads, "Number of threads flagsim's loops use.");
  m.def("set_num_threads", &set_num_threads, py::arg("n"),
        "Set the number of threads for flagsim's loops (n >= 1).");
  m.def("has_openmp", &has_openmp, "True when the core was compiled with OpenMP.");
#ifdef FLAGSIM_HAVE_FFTW
  m.def("has_fftw", []() { return true; }, "True when the FFT pressure solver (FFTW) is built in.");
#else
  m.def("has_fftw", []() { return false; }, "True when the FFT pressure solver (FFTW) is built in.");
#endif
}

}  // namespace flagsim::bindings

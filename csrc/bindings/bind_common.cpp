#include <pybind11/pybind11.h>

#include <string>

#include "common/errors.h"
#include "common/memory.h"
#include "common/parallel.h"
#include "common/types.h"

#if defined(FLAGSIM_HAVE_FFTW) && __has_include(<fftw3.h>)
#include <fftw3.h>
#define FLAGSIM_FFTW_VERSION_KNOWN 1
#endif
#ifdef _OPENMP
#include <omp.h>
#endif

namespace py = pybind11;

namespace flagsim::bindings {

namespace {

#ifndef FLAGSIM_BUILD_TYPE
#define FLAGSIM_BUILD_TYPE ""
#endif
#ifndef FLAGSIM_CXX_FLAGS
#define FLAGSIM_CXX_FLAGS ""
#endif
#ifndef FLAGSIM_COMPILER_ID
#define FLAGSIM_COMPILER_ID ""
#endif
#ifndef FLAGSIM_COMPILER_VERSION
#define FLAGSIM_COMPILER_VERSION ""
#endif
#ifndef FLAGSIM_GIT_REVISION
#define FLAGSIM_GIT_REVISION ""
#endif
#ifndef FLAGSIM_OPENMP_FLAGS
#define FLAGSIM_OPENMP_FLAGS ""
#endif

// How this module was compiled: benchmarks record it next to their figures.
py::dict build_info() {
  py::dict d;
  d["compiler_id"] = FLAGSIM_COMPILER_ID;
  d["compiler_version"] = FLAGSIM_COMPILER_VERSION;
  d["compiler"] = std::string(FLAGSIM_COMPILER_ID) + " " + FLAGSIM_COMPILER_VERSION;
  d["build_type"] = FLAGSIM_BUILD_TYPE;
  d["git_revision"] = FLAGSIM_GIT_REVISION;  // configured from; "" outside a checkout
  d["cxx_flags"] = FLAGSIM_CXX_FLAGS;
  d["cxx_standard"] = long(__cplusplus);
  d["eigen"] = std::to_string(EIGEN_WORLD_VERSION) + "." + std::to_string(EIGEN_MAJOR_VERSION) +
               "." + std::to_string(EIGEN_MINOR_VERSION);
  d["eigen_simd"] = std::string(Eigen::SimdInstructionSetsInUse());
  d["pybind11"] = std::to_string(PYBIND11_VERSION_MAJOR) + "." +
                  std::to_string(PYBIND11_VERSION_MINOR) + "." +
                  std::to_string(PYBIND11_VERSION_PATCH);
#ifdef _OPENMP
  d["openmp"] = true;
  d["openmp_version"] = long(_OPENMP);
  d["openmp_flags"] = FLAGSIM_OPENMP_FLAGS;
#else
  d["openmp"] = false;
  d["openmp_version"] = 0L;
  d["openmp_flags"] = "";
#endif
#ifdef FLAGSIM_HAVE_FFTW
  d["fftw"] = true;
#ifdef FLAGSIM_FFTW_VERSION_KNOWN
  d["fftw_version"] = std::string(fftw_version);
#else
  d["fftw_version"] = "";
#endif
#else
  d["fftw"] = false;
  d["fftw_version"] = "";
#endif
#ifdef FLAGSIM_HAVE_FFTW_OMP
  d["fftw_threads"] = true;  // grids of 32^3 cells and more transform on num_threads() threads
#else
  d["fftw_threads"] = false;
#endif
#ifdef NDEBUG
  d["assertions"] = false;
#else
  d["assertions"] = true;
#endif
  d["pointer_bits"] = long(8 * sizeof(void*));
  return d;
}

}  // namespace

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
  m.def("build_info", &build_info,
        "dict: compiler id, version and flags, build type, Eigen version and SIMD set, OpenMP and "
        "FFTW presence and versions (how this module was compiled).");
  m.def("available_memory", &available_memory,
        "Bytes a Simulation or Fluid may still allocate (MemAvailable, the cgroup limit and "
        "$FLAGSIM_MEMORY_LIMIT); their constructors refuse a scene estimated to need more");
  m.def("has_openmp", &has_openmp, "True when the core was compiled with OpenMP.");
#ifdef FLAGSIM_HAVE_FFTW
  m.def("has_fftw", []() { return true; }, "True when the FFT pressure solver (FFTW) is built in.");
#else
  m.def(
      "has_fftw", []() { return false; }, "True when the FFT pressure solver (FFTW) is built in.");
#endif
}

}  // namespace flagsim::bindings

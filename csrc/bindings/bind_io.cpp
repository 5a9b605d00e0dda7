#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <string>

#include "io/mesh2.h"

namespace py = pybind11;

namespace flagsim::bindings {

namespace {
Mesh2Options mesh2_options(const std::string& name, int decimals, int normal_decimals,
                           const std::string& comment) {
  Mesh2Options o;
  o.name = name;
  o.decimals = decimals;
  o.normal_decimals = normal_decimals;
  o.comment = comment;
  return o;
}
}  // namespace

void bind_io(py::module_& m) {
  // IoError -> OSError(errno, strerror, filename): Python picks the matching subclass
  // (FileNotFoundError, PermissionError, ...) from errno.
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const IoError& e) {
      py::object exc =
          py::module_::import("builtins").attr("OSError")(e.error_number, e.reason, e.path);
      PyErr_SetObject(reinterpret_cast<PyObject*>(Py_TYPE(exc.ptr())), exc.ptr());
    }
  });

  using CMatX3 = Eigen::Ref<const MatX3>;
  using CMatX2 = Eigen::Ref<const MatX2>;
  using CMatX3i = Eigen::Ref<const MatX3i>;

  m.def(
      "format_mesh2",
      [](CMatX3 positions, CMatX3 normals, CMatX2 uv, CMatX3i triangles, const std::string& name,
         int decimals, int normal_decimals, const std::string& comment) {
        const Mesh2Options o = mesh2_options(name, decimals, normal_decimals, comment);
        std::string text;
        {
          py::gil_scoped_release release;
          text = format_mesh2(positions, normals, uv, triangles, o);
        }
        return text;
      },
      py::arg("positions"), py::arg("normals"), py::arg("uv"), py::arg("triangles"), py::kw_only(),
      py::arg("name") = "FlagMesh", py::arg("decimals") = 7, py::arg("normal_decimals") = 6,
      py::arg("comment") = "",
      "POV-Ray mesh2 text (#declare <name> = mesh2 {...}) for a triangle mesh, converted to\n"
      "POV-Ray's left-handed frame (z negated, winding flipped). positions, normals: (N, 3);\n"
      "uv: (N, 2); triangles: (T, 3) vertex indices.");

  m.def(
      "write_mesh2_arrays",
      [](const std::string& path, CMatX3 positions, CMatX3 normals, CMatX2 uv, CMatX3i triangles,
         const std::string& name, int decimals, int normal_decimals, const std::string& comment) {
        const Mesh2Options o = mesh2_options(name, decimals, normal_decimals, comment);
        py::gil_scoped_release release;
        write_mesh2(path, positions, normals, uv, triangles, o);
      },
      py::arg("path"), py::arg("positions"), py::arg("normals"), py::arg("uv"),
      py::arg("triangles"), py::kw_only(), py::arg("name") = "FlagMesh", py::arg("decimals") = 7,
      py::arg("normal_decimals") = 6, py::arg("comment") = "",
      "format_mesh2(...) written to path whole or not at all (temporary file, then rename).");

  m.def(
      "write_file_atomic",
      [](const std::string& path, const std::string& text) {
        py::gil_scoped_release release;
        write_file_atomic(path, text);
      },
      py::arg("path"), py::arg("text"),
      "Write text (UTF-8) to path whole or not at all: a temporary file next to it, flushed to\n"
      "disk, then renamed over it. Raises OSError and leaves path untouched on failure.");
}

}  // namespace flagsim::bindings

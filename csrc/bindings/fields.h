// Helpers binding plain parameter structs as validated Python properties: assigning a field
// validates a copy of the struct and only then commits, so a bad value raises ValueError naming
// "<section>.<field>" and leaves the object unchanged.
#pragma once
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <array>
#include <string>

#include "common/types.h"

namespace flagsim::bindings {

namespace py = pybind11;

/// Vec3 <-> tuple of 3 floats (a tuple, so `p.origin[0] = 1` fails loudly instead of editing a copy).
inline py::tuple vec3_to_tuple(const Vec3& v) { return py::make_tuple(v.x(), v.y(), v.z()); }
inline Vec3 vec3_from(const std::string& name, const py::object& o) {
  std::array<double, 3> a;
  try {
    a = o.cast<std::array<double, 3>>();
  } catch (const py::cast_error&) {
    throw std::invalid_argument(name + " should be a sequence of 3 numbers, got " +
                                std::string(py::str(py::repr(o))));
  }
  return Vec3(a[0], a[1], a[2]);
}

template <class S, class T>
void def_field(py::class_<S>& cls, const char* name, T S::*member, std::string section,
               const char* doc) {
  cls.def_property(
      name, [member](const S& s) { return s.*member; },
      [member, section](S& s, const T& value) {
        S copy = s;
        copy.*member = value;
        copy.validate(section);
        s = copy;
      },
      doc);
}

template <class S>
void def_vec3_field(py::class_<S>& cls, const char* name, Vec3 S::*member, std::string section,
                    const char* doc) {
  cls.def_property(
      name, [member](const S& s) { return vec3_to_tuple(s.*member); },
      [member, section, name](S& s, const py::object& value) {
        S copy = s;
        copy.*member = vec3_from(section + "." + name, value);
        copy.validate(section);
        s = copy;
      },
      doc);
}

}  // namespace flagsim::bindings

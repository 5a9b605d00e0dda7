// Helpers binding plain parameter structs as validated Python properties: assigning a field
// converts the value strictly (from_py), validates a copy of the struct and only then commits,
// so a bad value raises ValueError (TypeError for a value of the wrong type) naming
// "<section>.<field>" and leaves the object unchanged. No pybind11 cast error reaches a user.
#pragma once
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <array>
#include <limits>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "common/errors.h"
#include "common/types.h"

namespace flagsim::bindings {

namespace py = pybind11;

inline std::string repr_of(py::handle o) {
  std::string s = py::str(py::repr(o));
  return s.size() > 80 ? s.substr(0, 77) + "..." : s;
}

/// TypeError "<name> should be <expected>, got <repr>".
[[noreturn]] inline void wrong_type(const std::string& name, const std::string& expected,
                                    py::handle o) {
  throw py::type_error(name + " should be " + expected + ", got " + repr_of(o));
}

namespace conv {
template <class T>
struct is_vector : std::false_type {};
template <class T>
struct is_vector<std::vector<T>> : std::true_type {};
template <class T>
struct is_pair : std::false_type {};
template <class A, class B>
struct is_pair<std::pair<A, B>> : std::true_type {};
template <class T>
struct is_array : std::false_type {};
template <class T, std::size_t N>
struct is_array<std::array<T, N>> : std::true_type {};

inline bool is_numpy_bool(py::handle o) {
  const py::handle t = py::type::handle_of(o);
  return py::str(t.attr("__module__")).cast<std::string>() == "numpy" &&
         py::str(t.attr("__name__")).cast<std::string>().rfind("bool", 0) == 0;
}
inline bool is_bool(py::handle o) { return PyBool_Check(o.ptr()) || is_numpy_bool(o); }
/// A sequence of exactly n items that is not a string (n < 0: any length).
/// A sequence of the wrong length is a ValueError; anything else a TypeError.
inline py::sequence sequence_of(const std::string& name, const std::string& expected, py::handle o,
                                long n) {
  if (!PySequence_Check(o.ptr()) || PyUnicode_Check(o.ptr()) || PyBytes_Check(o.ptr()))
    wrong_type(name, expected, o);
  if (n >= 0 && long(py::len(o)) != n)
    throw InvalidArgument(name + " should be " + expected + ", got " + repr_of(o));
  return py::reinterpret_borrow<py::sequence>(o);
}
}  // namespace conv

/// A Python value as T, strictly: booleans only for bool; integers (not bools, not floats) for
/// integer types, range-checked; numbers (not bools) for double; str for std::string; sequences
/// of these for std::vector, std::pair, std::array and Vec3; instances for bound structs.
template <class T>
T from_py(const std::string& name, py::handle o) {
  if constexpr (std::is_same_v<T, bool>) {
    if (!conv::is_bool(o)) wrong_type(name, "a boolean (true or false)", o);
    return PyObject_IsTrue(o.ptr()) == 1;
  } else if constexpr (std::is_integral_v<T>) {
    if (conv::is_bool(o) || !PyIndex_Check(o.ptr())) wrong_type(name, "an integer", o);
    py::int_ i = py::reinterpret_steal<py::int_>(PyNumber_Index(o.ptr()));
    if (!i) throw py::error_already_set();
    int overflow = 0;
    const long long v = PyLong_AsLongLongAndOverflow(i.ptr(), &overflow);
    if (overflow != 0 || v < (long long)std::numeric_limits<T>::min() ||
        (unsigned long long)(v < 0 ? 0 : v) > (unsigned long long)std::numeric_limits<T>::max())
      throw InvalidArgument(name + " should be an integer in [" +
                            std::to_string((long long)std::numeric_limits<T>::min()) + ", " +
                            std::to_string((unsigned long long)std::numeric_limits<T>::max()) +
                            "], got " + repr_of(o));
    return T(v);
  } else if constexpr (std::is_floating_point_v<T>) {
    if (conv::is_bool(o) || !(PyFloat_Check(o.ptr()) || PyIndex_Check(o.ptr())))
      wrong_type(name, "a number", o);
    const double v = PyFloat_AsDouble(o.ptr());
    if (v == -1.0 && PyErr_Occurred()) {  // an integer too large for a double
      PyErr_Clear();
      throw InvalidArgument(name + " should be a finite number, got " + repr_of(o));
    }
    return T(v);
  } else if constexpr (std::is_same_v<T, std::string>) {
    if (!PyUnicode_Check(o.ptr())) wrong_type(name, "a string", o);
    return o.cast<std::string>();
  } else if constexpr (std::is_same_v<T, Vec3>) {
    auto s = conv::sequence_of(name, "a sequence of 3 numbers", o, 3);
    return Vec3(from_py<double>(name + "[0]", s[0]), from_py<double>(name + "[1]", s[1]),
                from_py<double>(name + "[2]", s[2]));
  } else if constexpr (conv::is_array<T>::value) {
    constexpr long n = long(std::tuple_size<T>::value);
    auto s = conv::sequence_of(name, "a sequence of " + std::to_string(n) + " values", o, n);
    T out{};
    for (long i = 0; i < n; ++i)
      out[i] = from_py<typename T::value_type>(name + "[" + std::to_string(i) + "]", s[i]);
    return out;
  } else if constexpr (conv::is_pair<T>::value) {
    auto s = conv::sequence_of(name, "a pair", o, 2);
    return T(from_py<typename T::first_type>(name + "[0]", s[0]),
             from_py<typename T::second_type>(name + "[1]", s[1]));
  } else if constexpr (conv::is_vector<T>::value) {
    auto s = conv::sequence_of(name, "a list", o, -1);
    T out;
    out.reserve(py::len(s));
    for (size_t i = 0; i < py::len(s); ++i)
      out.push_back(from_py<typename T::value_type>(name + "[" + std::to_string(i) + "]", s[i]));
    return out;
  } else {  // a bound struct
    if (!py::isinstance<T>(o))
      wrong_type(
          name, std::string("a ") + py::str(py::type::of<T>().attr("__name__")).cast<std::string>(),
          o);
    return o.cast<T>();
  }
}

/// Vec3 <-> tuple of 3 floats (a tuple, so `p.origin[0] = 1` fails loudly instead of editing a
/// copy).
inline py::tuple vec3_to_tuple(const Vec3& v) { return py::make_tuple(v.x(), v.y(), v.z()); }
inline Vec3 vec3_from(const std::string& name, const py::object& o) {
  return from_py<Vec3>(name, o);
}

template <class S, class T>
void def_field(py::class_<S>& cls, const char* name, T S::*member, std::string section,
               const char* doc) {
  cls.def_property(
      name, [member](const S& s) { return s.*member; },
      [member, section, name](S& s, const py::object& value) {
        S copy = s;
        copy.*member = from_py<T>(section + "." + name, value);
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
        copy.*member = from_py<Vec3>(section + "." + name, value);
        copy.validate(section);
        s = copy;
      },
      doc);
}

}  // namespace flagsim::bindings

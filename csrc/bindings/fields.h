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

#include "common/enums.h"
#include "common/errors.h"
#include "common/keyframes.h"
#include "common/types.h"

namespace flagsim::bindings {

namespace py = pybind11;

/// A short repr for messages: reprlib's (bounded length and nesting, so a 3,000-deep list or
/// a long non-ASCII string cannot break the message), or a placeholder if even that fails.
inline std::string repr_of(py::handle o) {
  try {
    return py::str(py::module_::import("reprlib").attr("repr")(o)).cast<std::string>();
  } catch (const py::error_already_set&) {
    return "<" + std::string(py::str(py::type::handle_of(o).attr("__name__"))) + " object>";
  }
}

/// TypeError "<name> should be <expected>, got <repr>".
[[noreturn]] inline void wrong_type(const std::string& name, const std::string& expected,
                                    py::handle o) {
  throw py::type_error(name + " should be " + expected + ", got " + repr_of(o));
}

/// A seed from Python: an integer in [0, 2**32), ValueError naming `name` otherwise.
inline uint32_t checked_seed(const std::string& name, int64_t seed) {
  if (seed < 0 || seed > 0xFFFFFFFFll) fail_param(name, "in [0, 4294967295]", seed);
  return static_cast<uint32_t>(seed);
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
/// A real number: int or float, numpy's too (any object with __float__ or __index__ that is not
/// a string, bytes, bool or complex); arrays are refused by the conversion itself.
inline bool is_real(py::handle o) {
  if (is_bool(o) || PyUnicode_Check(o.ptr()) || PyBytes_Check(o.ptr()) || PyComplex_Check(o.ptr()))
    return false;
  return PyFloat_Check(o.ptr()) || PyIndex_Check(o.ptr()) || py::hasattr(o, "__float__");
}
/// A sequence of exactly n items that is not a string (n < 0: any length).
/// A sequence of the wrong length is a ValueError; anything else a TypeError.
inline py::sequence sequence_of(const std::string& name, const std::string& expected, py::handle o,
                                long n) {
  if (!PySequence_Check(o.ptr()) || PyUnicode_Check(o.ptr()) || PyBytes_Check(o.ptr()))
    wrong_type(name, expected, o);
  const Py_ssize_t size = PySequence_Size(o.ptr());
  if (size < 0) {  // a sequence type without a length (a 0-d numpy array)
    PyErr_Clear();
    wrong_type(name, expected, o);
  }
  if (n >= 0 && long(size) != n)
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
    if (!i) {  // __index__ refused (a float numpy array)
      PyErr_Clear();
      wrong_type(name, "an integer", o);
    }
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
    if (!conv::is_real(o)) wrong_type(name, "a number", o);
    const double v = PyFloat_AsDouble(o.ptr());
    if (v == -1.0 && PyErr_Occurred()) {
      const bool overflow = PyErr_ExceptionMatches(PyExc_OverflowError);
      PyErr_Clear();
      if (overflow)  // an integer too large for a double
        throw InvalidArgument(name + " should be a finite number, got " + repr_of(o));
      wrong_type(name, "a number", o);  // e.g. an array of more than one value
    }
    return T(v);
  } else if constexpr (std::is_enum_v<T>) {  // a mode: its name, as EnumNames<T> lists them
    if (!PyUnicode_Check(o.ptr())) wrong_type(name, "one of " + enum_choices<T>(), o);
    return parse_enum<T>(name, from_py<std::string>(name, o));
  } else if constexpr (std::is_same_v<T, std::string>) {
    if (!PyUnicode_Check(o.ptr())) wrong_type(name, "a string", o);
    Py_ssize_t size = 0;
    const char* text = PyUnicode_AsUTF8AndSize(o.ptr(), &size);
    if (!text) {  // lone surrogates cannot be UTF-8
      PyErr_Clear();
      throw InvalidArgument(name + " should be text UTF-8 can encode, got " + repr_of(o));
    }
    return std::string(text, std::size_t(size));
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

/// A C++ value as Python: an enum as its name, a Vec3 as a tuple, anything else as pybind11
/// casts it.
template <class T>
py::object to_py(const T& v) {
  if constexpr (std::is_enum_v<T>)
    return py::str(name_of(v));
  else if constexpr (std::is_same_v<T, Vec3>)
    return vec3_to_tuple(v);
  else
    return py::cast(v);
}

/// A wind: a constant velocity (3 numbers), keyframes [(time, (vx, vy, vz)), ...], or (when
/// allow_none) None for no keys. Each part of a bad value is named: "air.wind[1].time".
inline WindSchedule wind_from_py(const std::string& name, py::handle o, bool allow_none) {
  if (allow_none && o.is_none()) return WindSchedule();
  const std::string expected = std::string(allow_none ? "None, " : "") +
                               "a 3-vector (vx, vy, vz) or keyframes [(time, (vx, vy, vz)), ...]";
  auto seq = conv::sequence_of(name, expected, o, -1);
  const size_t n = py::len(seq);
  bool constant = n == 3;
  for (size_t i = 0; constant && i < n; ++i) constant = conv::is_real(seq[i]);
  if (constant) return WindSchedule(from_py<Vec3>(name, o));
  WindSchedule w;
  for (size_t i = 0; i < n; ++i) {
    const std::string key = name + "[" + std::to_string(i) + "]";
    auto pair = conv::sequence_of(key, "a pair (time, (vx, vy, vz))", seq[i], 2);
    w.keys.push_back(
        {from_py<double>(key + ".time", pair[0]), from_py<Vec3>(key + ".velocity", pair[1])});
  }
  return w;
}

inline py::list wind_to_list(const WindSchedule& w) {
  py::list out;
  for (const auto& k : w.keys) out.append(py::make_tuple(k.time, vec3_to_tuple(k.velocity)));
  return out;
}

/// The setter of a validated property: the value converted (named section.name in errors), set
/// on a copy, the copy validated, then kept; a bad value leaves the object as it was.
template <class S, class T>
auto validated_setter(T S::*member, std::string section, const char* name) {
  return [member, section, name](S& s, const py::object& value) {
    S copy = s;
    copy.*member = from_py<T>(section + "." + name, value);
    copy.validate(section);
    s = copy;
  };
}

/// A field of S as a validated property whose getter returns a Python value (to_py).
template <class S, class T, class... Bases>
void def_field(py::class_<S, Bases...>& cls, const char* name, T S::*member, std::string section,
               const char* doc) {
  cls.def_property(
      name, [member](const S& s) { return to_py(s.*member); },
      validated_setter(member, std::move(section), name), doc);
}

/// A field of S as a validated property whose getter returns the C++ object itself (kept alive by
/// its owner), so that it can be changed in place: the keyframed schedules.
template <class S, class T, class... Bases>
void def_ref_field(py::class_<S, Bases...>& cls, const char* name, T S::*member,
                   std::string section, const char* doc) {
  cls.def_property(
      name, [member](S& s) -> T& { return s.*member; },
      validated_setter(member, std::move(section), name),
      py::return_value_policy::reference_internal, doc);
}

/// T(**fields) for a bound struct: a default T, then each keyword assigned in the order given
/// through its validated property (def_field), so a bad value raises what assigning it would. A
/// keyword that names no property of T (a method, a private name, a typo) raises ValueError
/// "unknown key '<key>' for <type_name>".
template <class T>
T from_fields(const py::kwargs& kw, const char* type_name) {
  py::object o = py::cast(T());
  const py::object cls = py::type::of(o);
  const py::object property = py::module_::import("builtins").attr("property");
  for (const auto& item : kw) {
    const std::string key = py::str(item.first);
    if (key.rfind('_', 0) == 0 ||
        !py::isinstance(py::getattr(cls, key.c_str(), py::none()), property))
      throw InvalidArgument("unknown key '" + key + "' for " + type_name);
    py::setattr(o, item.first, item.second);
  }
  return o.cast<T>();
}

}  // namespace flagsim::bindings

// Modes as enum classes, parsed once at the boundary (TOML, Python) and compared as integers
// inside the kernels, as MuJoCo's mjtIntegrator. Each enum lists its names in an EnumNames
// specialisation, in the order of its values; name_of and parse_enum convert, and the bindings
// bind every enum field through them (bindings/fields.h), so the names are written once.
#pragma once
#include <array>
#include <cstddef>
#include <string>

#include "common/errors.h"

namespace flagsim {

/// Specialise for each mode enum: static constexpr std::array<const char*, N> names, where
/// names[i] is the text of the enumerator with value i.
template <class E>
struct EnumNames;

template <class E>
constexpr const char* name_of(E e) {
  return EnumNames<E>::names[static_cast<std::size_t>(e)];
}

/// "\"a\", \"b\", \"c\"": the accepted names, for messages and docs.
template <class E>
std::string enum_choices() {
  std::string out;
  for (const char* n : EnumNames<E>::names)
    out += (out.empty() ? "\"" : ", \"") + std::string(n) + "\"";
  return out;
}

/// The enumerator named `text`, or InvalidArgument "<field> should be one of "a", "b", got "c"".
template <class E>
E parse_enum(const std::string& field, const std::string& text) {
  const auto& names = EnumNames<E>::names;
  for (std::size_t i = 0; i < names.size(); ++i)
    if (text == names[i]) return static_cast<E>(i);
  fail_param(field, "one of " + enum_choices<E>(), "\"" + text + "\"");
}

}  // namespace flagsim

#include "io/mesh2.h"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>

#include "common/errors.h"

namespace flagsim {

namespace {

bool is_identifier(const std::string& s) {
  if (s.empty() || s.size() > 40) return false;
  if (!((s[0] >= 'A' && s[0] <= 'Z') || (s[0] >= 'a' && s[0] <= 'z'))) return false;
  bool upper = false;
  for (char ch : s) {
    const bool alpha_lower = ch >= 'a' && ch <= 'z';
    const bool alpha_upper = ch >= 'A' && ch <= 'Z';
    const bool digit = ch >= '0' && ch <= '9';
    if (!(alpha_lower || alpha_upper || digit || ch == '_')) return false;
    upper = upper || alpha_upper;
  }
  return upper;
}

// Appends text and fixed-point numbers to one growing buffer (no locale, no iostreams).
class TextBuffer {
 public:
  explicit TextBuffer(std::size_t reserve) { text_.reserve(reserve); }
  void put(std::string_view s) { text_.append(s); }
  void put(char c) { text_.push_back(c); }
  void fixed(double v, int decimals) {
    // 309 integer digits + sign + point + decimals fit: any finite double prints.
    char buf[384];
    auto r = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::fixed, decimals);
    text_.append(buf, r.ptr);
  }
  void integer(long v) {
    char buf[24];
    auto r = std::to_chars(buf, buf + sizeof buf, v);
    text_.append(buf, r.ptr);
  }
  std::string take() { return std::move(text_); }

 private:
  std::string text_;
};

template <class M>
void check_rows(const std::string& name, const M& m, Index n, const char* per) {
  if (m.rows() != n)
    fail_param(name, std::to_string(n) + " x " + std::to_string(m.cols()) + " (" + per + ")",
               std::to_string(m.rows()) + " x " + std::to_string(m.cols()));
}

template <class M>
void check_all_finite(const std::string& name, const M& m) {
  for (Index i = 0; i < m.rows(); ++i)
    for (Index j = 0; j < m.cols(); ++j)
      if (!std::isfinite(m(i, j)))
        fail_param(name, "finite", detail::to_text(m(i, j)) + " at row " + std::to_string(i));
}

// Removes the temporary file (if any) and throws IoError for `path`.
[[noreturn]] void fail_io(const std::string& path, const std::string& tmp, const char* doing,
                          int err) {
  if (!tmp.empty()) ::unlink(tmp.c_str());
  throw IoError(err, std::string(doing) + ": " + std::strerror(err), path);
}

}  // namespace

void Mesh2Options::validate() const {
  if (!is_identifier(name))
    fail_param("name",
               "a POV-Ray identifier (letters, digits, '_', starting with a letter, at most 40 "
               "characters, with an upper-case letter so it is not a keyword)",
               "'" + name + "'");
  if (decimals < 1 || decimals > 17) fail_param("decimals", "in [1, 17]", decimals);
  if (normal_decimals < 1 || normal_decimals > 17)
    fail_param("normal_decimals", "in [1, 17]", normal_decimals);
  if (comment.find_first_of("\r\n") != std::string::npos)
    fail_param("comment", "a single line", "a text with a line break");
}

std::string format_mesh2(const Eigen::Ref<const MatX3>& positions,
                         const Eigen::Ref<const MatX3>& normals, const Eigen::Ref<const MatX2>& uv,
                         const Eigen::Ref<const MatX3i>& triangles, const Mesh2Options& options) {
  options.validate();
  const Index n = positions.rows();
  const Index t = triangles.rows();
  if (n < 3) fail_param("positions", "at least 3 vertices", n);
  if (t < 1) fail_param("triangles", "at least 1 triangle", t);
  check_rows("normals", normals, n, "one per vertex");
  check_rows("uv", uv, n, "one per vertex");
  check_all_finite("positions", positions);
  check_all_finite("normals", normals);
  check_all_finite("uv", uv);
  for (Index f = 0; f < t; ++f)
    for (Index k = 0; k < 3; ++k)
      if (triangles(f, k) < 0 || triangles(f, k) >= n)
        fail_param("triangles", "vertex indices in [0, " + std::to_string(n) + ")",
                   std::to_string(triangles(f, k)) + " in triangle " + std::to_string(f));

  const int dp = options.decimals;
  const int dn = options.normal_decimals;
  TextBuffer out(static_cast<std::size_t>(n) * (3 * (dp + 6) + 3 * (dn + 5) + 2 * (dp + 4) + 16) +
                 static_cast<std::size_t>(t) * 30 + 256);
  if (!options.comment.empty()) {
    out.put("// ");
    out.put(options.comment);
    out.put('\n');
  }
  out.put("#declare ");
  out.put(options.name);
  out.put(" = mesh2 {");
  // One block of n vectors; `sign` multiplies the third column (the mirror below).
  auto block = [&](const char* name, const auto& m, int digits, double sign) {
    out.put("\n  ");
    out.put(name);
    out.put(" {\n    ");
    out.integer(n);
    for (Index i = 0; i < n; ++i) {
      out.put(",\n    <");
      for (Index c = 0; c < m.cols(); ++c) {
        if (c > 0) out.put(',');
        out.fixed(c == 2 ? sign * m(i, c) : m(i, c), digits);
      }
      out.put('>');
    }
    out.put("\n  }");
  };
  // Handedness: (x, y, z) -> (x, y, -z) for positions and normals (see header).
  block("vertex_vectors", positions, dp, -1.0);
  block("normal_vectors", normals, dn, -1.0);
  block("uv_vectors", uv, dp, 1.0);
  out.put("\n  face_indices {\n    ");
  out.integer(t);
  // The mirror reverses orientation; swapping two corners restores it: (a, b, c) -> (a, c, b).
  for (Index f = 0; f < t; ++f) {
    out.put(",\n    <");
    out.integer(triangles(f, 0));
    out.put(',');
    out.integer(triangles(f, 2));
    out.put(',');
    out.integer(triangles(f, 1));
    out.put('>');
  }
  out.put("\n  }\n}\n");
  return out.take();
}

void write_mesh2(const std::string& path, const Eigen::Ref<const MatX3>& positions,
                 const Eigen::Ref<const MatX3>& normals, const Eigen::Ref<const MatX2>& uv,
                 const Eigen::Ref<const MatX3i>& triangles, const Mesh2Options& options) {
  write_file_atomic(path, format_mesh2(positions, normals, uv, triangles, options));
}

void write_file_atomic(const std::string& path, std::string_view text) {
  if (path.empty() || path.back() == '/') fail_param("path", "a file path", "'" + path + "'");
  // Unique per process and call, so concurrent writers of the same file never share a temp file.
  static std::atomic<unsigned long> counter{0};
  const std::size_t slash = path.rfind('/');
  const std::string dir = slash == std::string::npos ? std::string() : path.substr(0, slash + 1);
  const std::string base = slash == std::string::npos ? path : path.substr(slash + 1);
  const std::string tmp = dir + "." + base + "." + std::to_string(::getpid()) + "-" +
                          std::to_string(counter.fetch_add(1)) + ".tmp";

  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
  if (fd < 0) fail_io(path, std::string(), "cannot create a temporary file", errno);
  const char* p = text.data();
  std::size_t left = text.size();
  while (left > 0) {
    const ssize_t w = ::write(fd, p, left);
    if (w < 0) {
      if (errno == EINTR) continue;
      const int err = errno;
      ::close(fd);
      fail_io(path, tmp, "cannot write", err);
    }
    p += w;
    left -= static_cast<std::size_t>(w);
  }
  if (::fsync(fd) != 0) {
    const int err = errno;
    ::close(fd);
    fail_io(path, tmp, "cannot flush", err);
  }
  if (::close(fd) != 0) fail_io(path, tmp, "cannot close", errno);
  if (std::rename(tmp.c_str(), path.c_str()) != 0)
    fail_io(path, tmp, "cannot rename into place", errno);
}

}  // namespace flagsim

// POV-Ray mesh2 export of a triangle mesh (the flag), the per-frame fast path of the exporter.
//
// flagsim is right-handed with y up; POV-Ray is left-handed with y up. Mirroring z (z -> -z)
// maps one onto the other so the picture is not mirrored. A mirror reverses orientation, so each
// triangle's winding is flipped too: in the file, cross(b - a, c - a) points the same way as the
// (mirrored) vertex normals, as it did in the simulation. POV-Ray 3.7 reference §mesh2:
// vertex_vectors, normal_vectors, uv_vectors, face_indices; normal and uv indices default to the
// face indices when there is one normal and one uv per vertex, as here.
#pragma once
#include <stdexcept>
#include <string>
#include <string_view>

#include <Eigen/Core>

#include "common/types.h"

namespace flagsim {

/// A file could not be written (errno from the failing call). Python: OSError with errno,
/// strerror and the file name.
class IoError : public std::runtime_error {
 public:
  IoError(int error_number, std::string reason, std::string path)
      : std::runtime_error(path + ": " + reason),
        error_number(error_number),
        reason(std::move(reason)),
        path(std::move(path)) {}
  int error_number;    ///< errno of the failing call
  std::string reason;  ///< strerror(errno) and what was being done
  std::string path;    ///< the file being written
};

struct Mesh2Options {
  /// Identifier the file #declares. Letters, digits and '_', starting with a letter, at most 40
  /// characters and containing an upper-case letter: POV-Ray keywords are all lower case, so such
  /// a name can never be read as syntax.
  std::string name = "FlagMesh";
  int decimals = 7;         ///< digits after the point for positions (m) and uv: error <= 0.5e-7
  int normal_decimals = 6;  ///< digits after the point for unit normals
  std::string comment;      ///< one line written as a `//` comment at the top; no line breaks
  void validate() const;
};

/// Formats one mesh2 #declare in POV-Ray's frame.
///   positions  N x 3 vertex positions, m (flagsim frame)
///   normals    N x 3 unit vertex normals (flagsim frame, same orientation as the winding)
///   uv         N x 2 texture coordinates
///   triangles  T x 3 vertex indices, counter-clockwise seen from the normals' side
/// Requires N >= 3, T >= 1, matching row counts, finite values and indices in [0, N): otherwise
/// InvalidArgument naming the array, the expectation and the offending value.
std::string format_mesh2(const Eigen::Ref<const MatX3>& positions,
                         const Eigen::Ref<const MatX3>& normals, const Eigen::Ref<const MatX2>& uv,
                         const Eigen::Ref<const MatX3i>& triangles,
                         const Mesh2Options& options = {});

/// format_mesh2(...) written to `path` whole or not at all (write_file_atomic).
void write_mesh2(const std::string& path, const Eigen::Ref<const MatX3>& positions,
                 const Eigen::Ref<const MatX3>& normals, const Eigen::Ref<const MatX2>& uv,
                 const Eigen::Ref<const MatX3i>& triangles, const Mesh2Options& options = {});

/// Writes `text` to a new temporary file next to `path` (".<name>.<pid>-<n>.tmp"), flushes it to
/// disk, then renames it over `path`: readers see the old file or the whole new one, never a
/// part. On any failure the temporary file is removed, `path` is untouched and IoError is thrown.
void write_file_atomic(const std::string& path, std::string_view text);

}  // namespace flagsim

// Eigen aliases shared by every area. Cloth state is row-major N x 3 so numpy sees (N, 3) views.
#pragma once
#include <Eigen/Dense>
#include <cstdint>

namespace flagsim {

using Vec3 = Eigen::Vector3d;
using Vec2 = Eigen::Vector2d;
using Mat3 = Eigen::Matrix3d;
using VecX = Eigen::VectorXd;
/// (N x 3) row-major: one 3-vector per row (positions, velocities, forces, normals).
using MatX3 = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;
/// (N x 2) row-major: texture coordinates.
using MatX2 = Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor>;
/// (T x 3) row-major vertex indices of triangles.
using MatX3i = Eigen::Matrix<int32_t, Eigen::Dynamic, 3, Eigen::RowMajor>;
/// (S x 2) row-major vertex index pairs (springs).
using MatX2i = Eigen::Matrix<int32_t, Eigen::Dynamic, 2, Eigen::RowMajor>;

using Index = Eigen::Index;

/// Row i of an N x 3 matrix as a Vec3 (a copy: Eigen row views of a row-major matrix are
/// transposes of column vectors).
inline Vec3 row(const MatX3& m, Index i) { return m.row(i).transpose(); }

}  // namespace flagsim

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>

#include <cerrno>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "common/errors.h"
#include "io/mesh2.h"

namespace flagsim {
namespace {

namespace fs = std::filesystem;

// A wavy rows x cols sheet in the x-y plane, triangles counter-clockwise seen from +z, and
// area-weighted vertex normals (which then agree with the winding).
struct Sheet {
  MatX3 x, n;
  MatX2 uv;
  MatX3i tri;
};

Sheet make_sheet(int rows, int cols) {
  Sheet s;
  const int nv = rows * cols;
  s.x.resize(nv, 3);
  s.uv.resize(nv, 2);
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) {
      const int i = r * cols + c;
      const double u = double(c) / (cols - 1), v = 1.0 - double(r) / (rows - 1);
      s.x.row(i) << 1.5 * u + 0.01 * r, 1.0 * v - 0.3, 0.2 * std::sin(5.0 * u) * std::cos(3.0 * v);
      s.uv.row(i) << u, v;
    }
  s.tri.resize(2 * (rows - 1) * (cols - 1), 3);
  int f = 0;
  for (int r = 0; r + 1 < rows; ++r)
    for (int c = 0; c + 1 < cols; ++c) {
      const int a = r * cols + c, b = a + 1, d = a + cols, e = d + 1;  // r = 0 is the top row
      s.tri.row(f++) << a, d, b;
      s.tri.row(f++) << b, d, e;
    }
  s.n = MatX3::Zero(nv, 3);
  for (int k = 0; k < s.tri.rows(); ++k) {
    const Vec3 p0 = s.x.row(s.tri(k, 0)), p1 = s.x.row(s.tri(k, 1)), p2 = s.x.row(s.tri(k, 2));
    const Vec3 fn = (p1 - p0).cross(p2 - p0);
    for (int j = 0; j < 3; ++j) s.n.row(s.tri(k, j)) += fn.transpose();
  }
  s.n.rowwise().normalize();
  return s;
}

// Reads the blocks of a mesh2 text back: "name { count, <a,b,c>, ... }".
std::vector<std::vector<double>> parse_block(const std::string& text, const std::string& name,
                                             long* count) {
  const auto start = text.find(name + " {");
  EXPECT_NE(start, std::string::npos) << name;
  const auto open = text.find('{', start), close = text.find('}', open);
  std::string body = text.substr(open + 1, close - open - 1);
  std::istringstream in(body);
  in >> *count;
  std::vector<std::vector<double>> rows;
  char ch;
  while (in >> ch) {
    if (ch != '<') continue;
    std::vector<double> row;
    double v;
    while (in >> v) {
      row.push_back(v);
      in >> ch;
      if (ch == '>') break;
    }
    rows.push_back(row);
  }
  return rows;
}

TEST(Mesh2, ParsesBackInPovrayFrameWithWindingMatchingNormals) {
  const Sheet s = make_sheet(9, 13);
  const std::string text = format_mesh2(s.x, s.n, s.uv, s.tri);
  long nv = 0, nn = 0, nuv = 0, nf = 0;
  const auto v = parse_block(text, "vertex_vectors", &nv);
  const auto n = parse_block(text, "normal_vectors", &nn);
  const auto uv = parse_block(text, "uv_vectors", &nuv);
  const auto f = parse_block(text, "face_indices", &nf);
  ASSERT_EQ(nv, s.x.rows());
  ASSERT_EQ(long(v.size()), nv);
  ASSERT_EQ(nn, nv);
  ASSERT_EQ(nuv, nv);
  ASSERT_EQ(nf, s.tri.rows());
  ASSERT_EQ(long(f.size()), nf);
  EXPECT_NE(text.find("#declare FlagMesh = mesh2 {"), std::string::npos);
  double err = 0;
  for (long i = 0; i < nv; ++i) {
    // Undo the handedness conversion: z -> -z.
    err = std::max({err, std::abs(v[i][0] - s.x(i, 0)), std::abs(v[i][1] - s.x(i, 1)),
                    std::abs(-v[i][2] - s.x(i, 2)), std::abs(uv[i][0] - s.uv(i, 0)),
                    std::abs(uv[i][1] - s.uv(i, 1))});
  }
  EXPECT_LT(err, 1e-6);
  EXPECT_LE(err, 0.5e-7 + 1e-15);  // 7 decimals
  // In the file's own (left-handed) coordinates each face's cross(b - a, c - a) agrees with the
  // file's vertex normals: POV-Ray's smooth triangles are oriented like the simulation's.
  for (long k = 0; k < nf; ++k) {
    const int a = int(f[k][0]), b = int(f[k][1]), c = int(f[k][2]);
    const Vec3 pa(v[a][0], v[a][1], v[a][2]), pb(v[b][0], v[b][1], v[b][2]),
        pc(v[c][0], v[c][1], v[c][2]);
    const Vec3 fn = (pb - pa).cross(pc - pa);
    const Vec3 vn = Vec3(n[a][0], n[a][1], n[a][2]) + Vec3(n[b][0], n[b][1], n[b][2]) +
                    Vec3(n[c][0], n[c][1], n[c][2]);
    EXPECT_GT(fn.normalized().dot(vn.normalized()), 0.5) << "face " << k;
  }
}

template <class F>
std::string invalid_message(F f) {
  try {
    f();
  } catch (const InvalidArgument& e) {
    return e.what();
  }
  return "no exception";
}

TEST(Mesh2, RejectsMismatchedNonFiniteOrOutOfRangeInput) {
  Sheet s = make_sheet(3, 3);
  MatX3 short_n = s.n.topRows(5);
  EXPECT_EQ(invalid_message([&] { format_mesh2(s.x, short_n, s.uv, s.tri); }),
            "normals should be 9 x 3 (one per vertex), got 5 x 3");
  MatX3 bad = s.x;
  bad(4, 1) = std::nan("");
  EXPECT_EQ(invalid_message([&] { format_mesh2(bad, s.n, s.uv, s.tri); }),
            "positions should be finite, got nan at row 4");
  MatX3i tri = s.tri;
  tri(2, 1) = 9;
  EXPECT_EQ(invalid_message([&] { format_mesh2(s.x, s.n, s.uv, tri); }),
            "triangles should be vertex indices in [0, 9), got 9 in triangle 2");
  for (const char* name : {"mesh2", "flag", "1Flag", "Flag Mesh", "Flag\"", "Flag;#"}) {
    Mesh2Options o;
    o.name = name;
    EXPECT_NE(invalid_message([&] { format_mesh2(s.x, s.n, s.uv, s.tri, o); }).find("name should"),
              std::string::npos)
        << name;
  }
  Mesh2Options o;
  o.comment = "two\nlines";
  EXPECT_NE(invalid_message([&] { format_mesh2(s.x, s.n, s.uv, s.tri, o); }).find("comment"),
            std::string::npos);
}

std::string read_all(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

fs::path fresh_dir(const std::string& name) {
  const fs::path d =
      fs::temp_directory_path() / ("flagsim_io_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

TEST(WriteFileAtomic, ReplacesWholeFileAndLeavesNoTemporaries) {
  const fs::path d = fresh_dir("replace");
  const Sheet s = make_sheet(4, 5);
  const fs::path p = d / "flag 0001.inc";  // spaces in file names are fine here
  write_mesh2(p.string(), s.x, s.n, s.uv, s.tri);
  EXPECT_EQ(read_all(p), format_mesh2(s.x, s.n, s.uv, s.tri));
  write_file_atomic(p.string(), "second");
  EXPECT_EQ(read_all(p), "second");
  EXPECT_EQ(std::distance(fs::directory_iterator(d), fs::directory_iterator()), 1);
  fs::remove_all(d);
}

TEST(WriteFileAtomic, FailureMidWriteKeepsOldFileAndRemovesTemporary) {
  const fs::path d = fresh_dir("midwrite");
  const fs::path p = d / "frame.inc";
  write_file_atomic(p.string(), "old, whole");
  // Simulated crash mid-write: the file-size limit makes write() fail with EFBIG after 100
  // bytes of a 1 MB text (SIGXFSZ ignored so the failure is reported, not fatal).
  struct rlimit old_limit;
  ASSERT_EQ(::getrlimit(RLIMIT_FSIZE, &old_limit), 0);
  auto old_handler = ::signal(SIGXFSZ, SIG_IGN);
  struct rlimit small = old_limit;
  small.rlim_cur = 100;
  ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &small), 0);
  int err = 0;
  try {
    write_file_atomic(p.string(), std::string(1 << 20, 'x'));
  } catch (const IoError& e) {
    err = e.error_number;
    EXPECT_EQ(e.path, p.string());
  }
  ::setrlimit(RLIMIT_FSIZE, &old_limit);
  ::signal(SIGXFSZ, old_handler);
  EXPECT_EQ(err, EFBIG);
  EXPECT_EQ(read_all(p), "old, whole");
  EXPECT_EQ(std::distance(fs::directory_iterator(d), fs::directory_iterator()), 1);
  fs::remove_all(d);
}

TEST(WriteFileAtomic, ReportsMissingFolderAndFailedRename) {
  const fs::path d = fresh_dir("errors");
  try {
    write_file_atomic((d / "missing" / "a.inc").string(), "x");
    FAIL() << "no exception";
  } catch (const IoError& e) {
    EXPECT_EQ(e.error_number, ENOENT);
  }
  fs::create_directories(d / "taken");  // renaming a file over a folder fails after the write
  EXPECT_THROW(write_file_atomic((d / "taken").string(), "x"), IoError);
  EXPECT_TRUE(fs::is_directory(d / "taken"));
  EXPECT_EQ(std::distance(fs::directory_iterator(d), fs::directory_iterator()), 1);
  fs::remove_all(d);
}

}  // namespace
}  // namespace flagsim

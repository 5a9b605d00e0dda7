// Flapping (paper §4, eq. 5): FlappingParams, perlin1d, flapping_ramp, flapping_displacement.
#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cmath>
#include <vector>

#include "bindings/fields.h"
#include "common/errors.h"
#include "flapping/flapping.h"
#include "flapping/params.h"
#include "flapping/perlin.h"

namespace py = pybind11;
using namespace pybind11::literals;

namespace flagsim::bindings {

void bind_flapping(py::module_& m) {
  py::class_<FlappingParams> fp(
      m, "FlappingParams",
      "Paper eq. 5 flapping: z = u_p A(L) f_n(frequency (x - speed t - parabola (1 - y) y)).");
  fp.def(py::init<>());
  def_field(fp, "mode", &FlappingParams::mode, "flapping",
            "'displace' (paper: moves the cloth) | 'force' (a normal force) | 'visual' (exported "
            "geometry only) | 'off'");
  def_field(fp, "amplitude", &FlappingParams::amplitude, "flapping",
            "A for L >= l_max: m of displacement per m/s of u_p");
  def_field(fp, "l_max", &FlappingParams::l_max, "flapping",
            "m, distance from the nearest pin beyond which A(L) is constant");
  def_field(fp, "speed", &FlappingParams::speed, "flapping",
            "v, wave speed, flag lengths per second");
  def_field(fp, "parabola", &FlappingParams::parabola, "flapping",
            "a, parabola coefficient of the wave front, flag lengths");
  def_field(fp, "frequency", &FlappingParams::frequency, "flapping",
            "noise lattice cells per flag length");
  def_field(fp, "ramp", &FlappingParams::ramp, "flapping",
            "s, the wave fades in over this time from a flat flag at t = 0 (smoothstep); 0 = "
            "the whole wave from the first step, as the paper");
  fp.def_property(
      "seed", [](const FlappingParams& p) { return p.seed; },
      [](FlappingParams& p, const py::object& seed) {
        p.seed = checked_seed("flapping.seed", from_py<int64_t>("flapping.seed", seed));
      },
      "noise seed, an integer in [0, 2**32)");
  fp.def("validate", &FlappingParams::validate, "prefix"_a = "flapping",
         "Raise ValueError naming the first invalid field.");

  m.def(
      "perlin1d",
      [](py::array_t<double, py::array::c_style | py::array::forcecast> x,
         int64_t seed) -> py::object {
        const Perlin1D noise(checked_seed("seed", seed));
        const py::ssize_t n = x.size();
        const double* in = x.data();
        for (py::ssize_t i = 0; i < n; ++i)
          if (!std::isfinite(in[i])) fail_param("x", "finite", in[i]);
        py::array_t<double> out(std::vector<py::ssize_t>(x.shape(), x.shape() + x.ndim()));
        double* o = out.mutable_data();
        {
          py::gil_scoped_release release;
          for (py::ssize_t i = 0; i < n; ++i) o[i] = noise(in[i]);
        }
        if (x.ndim() == 0) return py::float_(o[0]);
        return std::move(out);
      },
      "x"_a, "seed"_a = 0,
      "Improved Perlin noise in 1-D (Perlin 2002), elementwise; |value| <= 1, 0 at integers.\n"
      "Definition in csrc/flapping/perlin.h. Seeds are integers in [0, 2**32).");

  m.def(
      "flapping_ramp", [](double L, const FlappingParams& p) { return flapping_ramp(L, p); }, "L"_a,
      "params"_a, "A(L) = amplitude * S(min(L / l_max, 1)), S(u) = 3u^2 - 2u^3 (m per m/s).");

  m.def(
      "flapping_displacement",
      [](const MatX2& xy, const VecX& L, double u_p, double t, const FlappingParams& p) {
        if (xy.rows() != L.size())
          fail_param("L", "of length " + std::to_string(xy.rows()) + " (one per row of xy)",
                     L.size());
        check_finite_vec("xy", Eigen::Map<const VecX>(xy.data(), xy.size()));
        check_finite_vec("L", L);
        check_finite("u_p", u_p);
        check_finite("t", t);
        p.validate("flapping");
        VecX z;
        flapping_displacement(Perlin1D(p.seed), xy, L, u_p, t, p, z);
        return z;
      },
      "xy"_a, "L"_a, "u_p"_a, "t"_a, "params"_a,
      "Paper eq. 5 per vertex: xy (N, 2) normalised (x along the flag from the pole, y across),\n"
      "L (N,) distance to the nearest pin (m), u_p air speed at the pole (m/s), t (s).\n"
      "Returns z (N,), the displacement along each normal (m).");
}

}  // namespace flagsim::bindings

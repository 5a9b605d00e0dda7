// flagsim.Fluid (the air solver alone) and flagsim.FanParams.
#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <string>

#include "bindings/fields.h"
#include "bindings/fluid_fields.h"
#include "common/errors.h"
#include "fluid/fluid.h"
#include "fluid/params.h"
#include "fluid/turbulence.h"
#include "scene/scene.h"

namespace py = pybind11;

namespace flagsim::bindings {

namespace {

/// Each message as a Python UserWarning (an error when the warnings filter says so).
void warn_all(const std::vector<std::string>& messages) {
  for (const std::string& m : messages)
    if (PyErr_WarnEx(PyExc_UserWarning, m.c_str(), 2) != 0) throw py::error_already_set();
}

py::array component_view(py::object self, int c) {
  Fluid& f = self.cast<Fluid&>();
  const Shape3 sh = f.component_shape(c);
  const std::vector<py::ssize_t> shape = {sh.n[0], sh.n[1], sh.n[2]};
  if (f.is_double())
    return py::array_t<double>(shape, static_cast<double*>(f.component_data(c)), self);
  return py::array_t<float>(shape, static_cast<float*>(f.component_data(c)), self);
}

void set_component_from(Fluid& f, int c, const py::handle& values) {
  const Shape3 sh = f.component_shape(c);
  auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(values);
  const std::string name = std::string(1, "uvw"[c]);
  if (!a || std::size_t(a.size()) != sh.size())
    fail_param(name,
               "an array of shape (" + std::to_string(sh.n[0]) + ", " + std::to_string(sh.n[1]) +
                   ", " + std::to_string(sh.n[2]) + ")",
               a ? std::to_string(a.size()) + " values" : std::string(py::str(values)));
  f.set_component(c, a.data());
}

// Cell counts (nx, ny, nz); a count far outside int becomes -1, so validate() names the field
// with its own range ([1, 4096]) rather than the conversion naming int's.
std::array<int, 3> resolution_from_py(const std::string& name, py::handle o) {
  const auto n = from_py<std::array<long long, 3>>(name, o);
  std::array<int, 3> r;
  for (int d = 0; d < 3; ++d) r[d] = (n[d] < -1000000 || n[d] > 1000000) ? -1 : int(n[d]);
  return r;
}

}  // namespace

// A turbulence schedule from Python: a number (constant) or keyframes [(time s, value), ...].
ScalarSchedule schedule_from_py(const std::string& name, const py::object& o) {
  ScalarSchedule s;
  if (py::isinstance<py::float_>(o) || py::isinstance<py::int_>(o))
    s.keys = {{0.0, from_py<double>(name, o)}};
  else
    s.keys = from_py<std::vector<std::pair<double, double>>>(name, o);
  return s;
}

void def_schedule(py::class_<TurbulenceParams>& cls, const char* name,
                  ScalarSchedule TurbulenceParams::*member, const char* doc) {
  cls.def_property(
      name, [member](const TurbulenceParams& t) { return (t.*member).keys; },
      [member, name](TurbulenceParams& t, const py::object& o) {
        TurbulenceParams copy = t;
        copy.*member = schedule_from_py(std::string("air.turbulence.") + name, o);
        copy.validate("air.turbulence");
        t = copy;
      },
      doc);
}

void bind_turbulence(py::module_& m) {
  py::class_<TurbulenceParams> t(
      m, "TurbulenceParams",
      "Curl-noise turbulence (Bridson et al. 2007): u = curl psi, psi three noise channels, "
      "ramped to 0 near solids. Schedules take a number or keyframes [(time s, value), ...] and "
      "read back as keyframes.");
  t.def(py::init<>());
  def_schedule(t, "intensity", &TurbulenceParams::intensity,
               "m/s, velocity scale of the noise (empty or 0: off)");
  def_schedule(t, "length_scale", &TurbulenceParams::length_scale,
               "m, noise lattice spacing, about the eddies' size (empty: 0.3)");
  def_schedule(t, "evolution", &TurbulenceParams::evolution,
               "1/s, noise slices per second: how fast the eddies change (empty: 0.5)");
  def_field(t, "ramp_distance", &TurbulenceParams::ramp_distance, "air.turbulence",
            "m, width of Bridson's ramp beside solids (the pole, obstacles)");
  t.def_property(
      "seed", [](const TurbulenceParams& p) { return p.seed; },
      [](TurbulenceParams& p, const py::object& seed) {
        p.seed = checked_seed("air.turbulence.seed", from_py<int64_t>("air.turbulence.seed", seed));
      },
      "noise seed, an integer in [0, 2**32)");
  t.def("validate", &TurbulenceParams::validate, py::arg("prefix") = "air.turbulence");
  t.def(
      "velocity",
      [](const TurbulenceParams& p, const MatX3& x, double time,
         const std::vector<ObstacleParams>& solids) {
        CurlNoise noise(p, solids);
        MatX3 out(x.rows(), 3);
        for (Index i = 0; i < x.rows(); ++i)
          out.row(i) = noise.velocity(x.row(i).transpose(), time).transpose();
        return out;
      },
      py::arg("points"), py::arg("time") = 0.0, py::arg("solids") = std::vector<ObstacleParams>(),
      "The curl-noise velocity (M x 3, m/s) at points (M x 3, m) and time (s), ramped near the "
      "solids ([ObstacleParams, ...]).");
}

// An (n, 3) array of T from any array-like: floats for points, integers (no fractions) for faces.
template <class T>
Eigen::Matrix<T, Eigen::Dynamic, 3, Eigen::RowMajor> mesh_array(const std::string& name,
                                                                const py::object& value) {
  const char* what = std::is_integral_v<T> ? "integers" : "numbers";
  py::array a;  // an empty array by default (py::array() is not null), hence `read`
  bool read = false;
  try {
    a = py::array::ensure(py::module_::import("numpy").attr("asarray")(value, "float64"));
    read = bool(a);
  } catch (const py::error_already_set&) {
  }
  if (!read || (a.ndim() != 2 && !(a.ndim() == 1 && a.shape(0) == 0)) ||
      (a.ndim() == 2 && a.shape(1) != 3))
    throw InvalidArgument(name + " should be an array of shape (n, 3) of " + what + ", got " +
                          py::str(py::repr(value)).cast<std::string>());
  const Index n = a.ndim() == 2 ? a.shape(0) : 0;
  auto d = a.cast<py::array_t<double, py::array::c_style | py::array::forcecast>>();
  Eigen::Matrix<T, Eigen::Dynamic, 3, Eigen::RowMajor> out(n, 3);
  for (Index i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) {
      const double x = d.at(i, k);
      if constexpr (std::is_integral_v<T>) {
        if (!(std::isfinite(x) && x == std::floor(x) && std::fabs(x) < 2e9))
          fail_param(name + "[" + std::to_string(i) + "]", "integer vertex indices", x);
      }
      out(i, k) = T(x);
    }
  return out;
}

void def_fluid_fields(py::class_<AirParams>& cls, const std::string& section) {
  cls.def_property(
      "turbulence", [](AirParams& a) -> TurbulenceParams& { return a.turbulence; },
      [section](AirParams& a, const py::object& o) {
        AirParams copy = a;
        copy.turbulence = from_py<TurbulenceParams>(section + ".turbulence", o);
        copy.validate(section);
        a = copy;
      },
      py::return_value_policy::reference_internal,
      "TurbulenceParams: curl noise on the wind ('uniform') or injected into the grid ('grid')");
  cls.def_property(
      "resolution",
      [](const AirParams& a) {
        return py::make_tuple(a.resolution[0], a.resolution[1], a.resolution[2]);
      },
      [section](AirParams& a, const py::object& o) {
        AirParams copy = a;
        copy.resolution = resolution_from_py(section + ".resolution", o);
        copy.validate(section);
        a = copy;
      },
      "grid cells (nx, ny, nz) ('grid')");
  def_field<AirParams, double>(cls, "cell_size", &AirParams::cell_size, section, "m ('grid')");
  def_field<AirParams, Vec3>(cls, "origin", &AirParams::origin, section,
                             "m, min corner of the grid ('grid')");
  def_field<AirParams, Boundary>(
      cls, "boundary", &AirParams::boundary, section,
      "'periodic' (mean flow = wind) | 'tunnel' (inflow = wind through x-min)");
  def_field<AirParams, Advection>(cls, "advection", &AirParams::advection, section,
                                  "'semi_lagrangian' | 'maccormack'");
  def_field<AirParams, Pressure>(
      cls, "pressure", &AirParams::pressure, section,
      "'fft' (periodic, FFTW) | 'pcg' (MIC(0) conjugate gradient) | 'multigrid' (CG with a "
      "multigrid V-cycle: periodic or tunnel, with solids)");
  def_field<AirParams, Precision>(cls, "precision", &AirParams::precision, section,
                                  "'double' | 'float'");
  def_field<AirParams, double>(cls, "pcg_tolerance", &AirParams::pcg_tolerance, section,
                               "relative max-norm residual of the pcg and multigrid solves");
  def_field<AirParams, int>(cls, "pcg_max_iterations", &AirParams::pcg_max_iterations, section,
                            "iteration cap of each pcg or multigrid solve");
  def_field<AirParams, Slip>(cls, "wall_y_min", &AirParams::wall_y_min, section,
                             "tunnel wall at y-min: 'free_slip' | 'no_slip'");
  def_field<AirParams, Slip>(cls, "wall_y_max", &AirParams::wall_y_max, section,
                             "tunnel wall at y-max: 'free_slip' | 'no_slip'");
  def_field<AirParams, Slip>(cls, "wall_z_min", &AirParams::wall_z_min, section,
                             "tunnel wall at z-min: 'free_slip' | 'no_slip'");
  def_field<AirParams, Slip>(cls, "wall_z_max", &AirParams::wall_z_max, section,
                             "tunnel wall at z-max: 'free_slip' | 'no_slip'");
  def_field<AirParams, InflowProfile>(
      cls, "inflow_profile", &AirParams::inflow_profile, section,
      "tunnel inflow: 'uniform' | 'parabolic' (between the no-slip walls, same mean as the wind)");
  cls.def_property(
      "obstacles", [](const AirParams& a) { return a.obstacles; },
      [section](AirParams& a, const py::object& obstacles) {
        AirParams copy = a;
        copy.obstacles = from_py<std::vector<ObstacleParams>>(section + ".obstacles", obstacles);
        copy.validate(section);
        a = copy;
      },
      "[ObstacleParams, ...]: static solids in the air ('grid'); a list copy: assign to change");
  cls.def_property(
      "fans", [](const AirParams& a) { return a.fans; },
      [section](AirParams& a, const py::object& fans) {
        AirParams copy = a;
        copy.fans = from_py<std::vector<FanParams>>(section + ".fans", fans);
        copy.validate(section);
        a = copy;
      },
      "[FanParams, ...]: regions pushing the air ('grid'); a list copy: assign to change");
}

namespace {
// An (M, 3) array of finite numbers as a matrix, or ValueError naming `name`.
MatX3 finite_rows(const std::string& name, const py::object& o) {
  auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(o);
  if (!a || a.ndim() != 2 || a.shape(1) != 3)
    fail_param(name, "an (M, 3) array", a ? "ndim " + std::to_string(a.ndim()) : "not an array");
  MatX3 m = Eigen::Map<const MatX3>(a.data(), a.shape(0), 3);
  if (!m.allFinite()) fail_param(name, "finite everywhere", "a non-finite value");
  return m;
}
}  // namespace

void bind_fan(py::module_& m) {
  py::class_<FanParams> fan_cls(
      m, "FanParams",
      "A region pushing the air: force density (N/m^3) along direction inside a box "
      "or a sphere, times a keyframed strength.");
  fan_cls.def(
      py::init([](const py::object& shape, const py::object& center, const py::object& half_size,
                  const py::object& radius, const py::object& direction,
                  const py::object& force_density, const py::object& max_speed,
                  const py::object& strength) {
        FanParams f;
        f.shape = from_py<FanShape>("shape", shape);
        f.center = from_py<Vec3>("center", center);
        f.half_size = from_py<Vec3>("half_size", half_size);
        f.radius = from_py<double>("radius", radius);
        f.direction = from_py<Vec3>("direction", direction);
        f.force_density = from_py<double>("force_density", force_density);
        f.max_speed = from_py<double>("max_speed", max_speed);
        f.strength.keys = from_py<std::vector<std::pair<double, double>>>("strength", strength);
        f.validate("");
        return f;
      }),
      py::kw_only(), py::arg("shape") = "box", py::arg("center") = py::make_tuple(0.0, 0.0, 0.0),
      py::arg("half_size") = py::make_tuple(0.25, 0.25, 0.25), py::arg("radius") = 0.25,
      py::arg("direction") = py::make_tuple(1.0, 0.0, 0.0), py::arg("force_density") = 20.0,
      py::arg("max_speed") = 0.0, py::arg("strength") = py::list());
  py::class_<FanParams>& fan = fan_cls;
  def_field(fan, "shape", &FanParams::shape, "fan", "'box' | 'sphere'");
  def_field<FanParams, Vec3>(fan, "center", &FanParams::center, "fan", "m");
  def_field<FanParams, Vec3>(fan, "half_size", &FanParams::half_size, "fan", "m, box half extents");
  def_field<FanParams, double>(fan, "radius", &FanParams::radius, "fan", "m, sphere radius");
  def_field<FanParams, Vec3>(fan, "direction", &FanParams::direction, "fan", "normalised on use");
  def_field<FanParams, double>(fan, "force_density", &FanParams::force_density, "fan", "N/m^3");
  def_field<FanParams, double>(
      fan, "max_speed", &FanParams::max_speed, "fan",
      "m/s: the force fades to 0 as the air reaches max_speed along direction; 0 = constant");
  fan.def_property(
         "strength", [](const FanParams& f) { return f.strength.keys; },
         [](FanParams& f, const py::object& k) {
           FanParams copy = f;
           copy.strength.keys = from_py<std::vector<std::pair<double, double>>>("fan.strength", k);
           copy.validate("fan");
           f = copy;
         },
         "(time s, factor) keyframes; empty = always 1")
      .def("validate", &FanParams::validate, py::arg("prefix") = "");
}

/// A mesh array of S (vertices, faces) as a property: the getter returns a copy, the setter
/// converts with mesh_array (errors name "<section>.<name>") and validates a copy of S first.
template <class S, class M, class C, class... Bases>
void def_mesh_field(py::class_<S, Bases...>& cls, const char* name, M C::*member,
                    const std::string& section, const char* doc) {
  cls.def_property(
      name, [member](const S& o) { return M(o.*member); },
      [member, section, name](S& o, const py::object& value) {
        S copy = o;
        copy.*member = mesh_array<typename M::Scalar>(section + "." + name, value);
        copy.validate(section);
        o = copy;
      },
      doc);
}

/// The ObstacleParams fields (shape, center, half_size, radius, axis, length, vertices, faces,
/// slip) as validated properties of S (ObstacleParams or a struct deriving from it): errors name
/// "<section>.<field>" and a new value is checked by S's own validate.
template <class S, class... Bases>
void def_obstacle_fields_of(py::class_<S, Bases...>& cls, const std::string& section) {
  def_field<S, ObstacleShape>(cls, "shape", &ObstacleParams::shape, section,
                              "'box' | 'sphere' | 'cylinder' | 'capsule' | 'mesh'");
  def_field<S, Vec3>(cls, "center", &ObstacleParams::center, section, "m");
  def_field<S, Vec3>(cls, "half_size", &ObstacleParams::half_size, section, "m, box half extents");
  def_field<S, double>(cls, "radius", &ObstacleParams::radius, section,
                       "m, sphere or cylinder radius");
  def_field<S, Vec3>(cls, "axis", &ObstacleParams::axis, section,
                     "cylinder axis, normalised on use");
  def_field<S, double>(cls, "length", &ObstacleParams::length, section,
                       "m, cylinder length between its caps, capsule segment");
  def_mesh_field(cls, "vertices", &ObstacleParams::vertices, section,
                 "(M, 3) m, the mesh's points (shape 'mesh'); a copy: assign to change");
  def_mesh_field(cls, "faces", &ObstacleParams::faces, section,
                 "(F, 3) indices into vertices, one closed triangle mesh (shape 'mesh'); a copy");
  def_field<S, Slip>(cls, "slip", &ObstacleParams::slip, section, "'no_slip' | 'free_slip'");
}

void def_obstacle_fields(py::class_<SolidParams, ObstacleParams>& cls, const std::string& section) {
  def_obstacle_fields_of(cls, section);
}

void bind_obstacle(py::module_& m) {
  py::class_<ObstacleParams> obs(
      m, "ObstacleParams",
      "A static solid in the air: a box, a sphere or a capped cylinder, free-slip or no-slip. "
      "The cells whose centres lie inside it are solid.");
  obs.def(py::init([](const py::object& shape, const py::object& center,
                      const py::object& half_size, const py::object& radius, const py::object& axis,
                      const py::object& length, const py::object& slip) {
            ObstacleParams o;
            o.shape = from_py<ObstacleShape>("shape", shape);
            o.center = from_py<Vec3>("center", center);
            o.half_size = from_py<Vec3>("half_size", half_size);
            o.radius = from_py<double>("radius", radius);
            o.axis = from_py<Vec3>("axis", axis);
            o.length = from_py<double>("length", length);
            o.slip = from_py<Slip>("slip", slip);
            o.validate("");
            return o;
          }),
          py::kw_only(), py::arg("shape") = "box",
          py::arg("center") = py::make_tuple(0.0, 0.0, 0.0),
          py::arg("half_size") = py::make_tuple(0.1, 0.1, 0.1), py::arg("radius") = 0.1,
          py::arg("axis") = py::make_tuple(0.0, 0.0, 1.0), py::arg("length") = 1.0,
          py::arg("slip") = "no_slip");
  def_obstacle_fields_of(obs, "obstacle");
  obs.def("validate", &ObstacleParams::validate, py::arg("prefix") = "")
      .def(
          "contains",
          [](const ObstacleParams& o, const py::object& x) {
            return o.contains(from_py<Vec3>("point", x));
          },
          py::arg("point"), "True when the point (m) lies inside the solid.");
}

void bind_fluid_class(py::module_& m) {
  py::class_<Fluid>(m, "Fluid", R"doc(
Stable Fluids (Stam 1999) on a staggered MAC grid: the air solver alone.

Component arrays (views, m/s): u (x-faces), v (y-faces), w (z-faces). Periodic grids store
nx x ny x nz of each; tunnel grids one more face along the component's own axis.
Pressure: "fft" (FFTW, periodic only; divergence at round-off), "pcg" (MIC(0)-preconditioned
CG) or "multigrid" (CG preconditioned by a multigrid V-cycle; periodic or tunnel, with solid
cells; iterations about flat in the grid size). Tunnel: inflow = wind through the x-min face,
p = 0 at x-max, free-slip walls.
)doc")
      .def(py::init([](const py::object& resolution, const py::object& cell_size,
                       const py::object& origin, const py::object& boundary,
                       const py::object& viscosity, const py::object& density,
                       const py::object& advection, const py::object& pressure,
                       const py::object& precision, const py::object& pcg_tolerance,
                       const py::object& pcg_max_iterations, const py::object& wind,
                       const py::object& fans, const py::object& obstacles, const py::object& walls,
                       const py::object& inflow_profile) {
             FluidParams p;
             p.resolution = resolution_from_py("resolution", resolution);
             p.cell_size = from_py<double>("cell_size", cell_size);
             p.origin = from_py<Vec3>("origin", origin);
             p.boundary = from_py<Boundary>("boundary", boundary);
             p.viscosity = from_py<double>("viscosity", viscosity);
             p.density = from_py<double>("density", density);
             p.advection = from_py<Advection>("advection", advection);
             p.pressure = from_py<Pressure>("pressure", pressure);
             p.precision = from_py<Precision>("precision", precision);
             p.pcg_tolerance = from_py<double>("pcg_tolerance", pcg_tolerance);
             p.pcg_max_iterations = from_py<int>("pcg_max_iterations", pcg_max_iterations);
             p.wind = wind_from_py("wind", wind, true);
             p.fans = from_py<std::vector<FanParams>>("fans", fans);
             p.obstacles = from_py<std::vector<ObstacleParams>>("obstacles", obstacles);
             if (!walls.is_none()) {
               if (PyUnicode_Check(walls.ptr())) {  // one condition for the four walls
                 p.wall_y_min = p.wall_y_max = p.wall_z_min = p.wall_z_max =
                     from_py<Slip>("walls", walls);
               } else {
                 if (!py::isinstance<py::dict>(walls))
                   fail_param("walls", "'free_slip', 'no_slip' or a dict {'y_min': ...}",
                              repr_of(walls));
                 for (auto item : py::reinterpret_borrow<py::dict>(walls)) {
                   const std::string side = from_py<std::string>("walls", item.first);
                   Slip* target = side == "y_min"   ? &p.wall_y_min
                                  : side == "y_max" ? &p.wall_y_max
                                  : side == "z_min" ? &p.wall_z_min
                                  : side == "z_max" ? &p.wall_z_max
                                                    : nullptr;
                   if (!target)
                     fail_param("walls", "keys among y_min, y_max, z_min, z_max", "'" + side + "'");
                   *target = from_py<Slip>("walls." + side, item.second);
                 }
               }
             }
             p.inflow_profile = from_py<InflowProfile>("inflow_profile", inflow_profile);
             auto f = std::make_unique<Fluid>(p);
             warn_all(f->warnings());
             return f;
           }),
           py::kw_only(), py::arg("resolution") = py::make_tuple(16, 16, 16),
           py::arg("cell_size") = 0.125, py::arg("origin") = py::make_tuple(-0.5, -1.0, -1.0),
           py::arg("boundary") = "periodic", py::arg("viscosity") = 1.5e-5,
           py::arg("density") = 1.2, py::arg("advection") = "semi_lagrangian",
           py::arg("pressure") = name_of(FluidParams().pressure), py::arg("precision") = "double",
           py::arg("pcg_tolerance") = 1e-8, py::arg("pcg_max_iterations") = 500,
           py::arg("wind") = py::none(), py::arg("fans") = py::list(),
           py::arg("obstacles") = py::list(), py::arg("walls") = py::none(),
           py::arg("inflow_profile") = "uniform",
           "resolution (nx, ny, nz) cells; cell_size m; origin m (min corner); viscosity m^2/s; "
           "density kg/m^3; wind: None, a 3-vector (m/s) or [(time s, (vx, vy, vz)), ...]: the "
           "periodic mean flow or the tunnel inflow; fans: [FanParams, ...]; obstacles: "
           "[ObstacleParams, ...]; walls (tunnel): 'free_slip' (default) | 'no_slip' for all four, "
           "or {'y_min': ..., 'y_max': ..., 'z_min': ..., 'z_max': ...}; inflow_profile (tunnel): "
           "'uniform' | 'parabolic'. Obstacles thinner than the wake needs warn (UserWarning).")
      .def(
          "add_obstacle",
          [](Fluid& f, const ObstacleParams& o) {
            f.add_obstacle(o);
            const auto w = f.warnings();
            if (!w.empty()) warn_all({w.back()});
          },
          py::arg("obstacle"),
          "Add a static solid (ObstacleParams): its cells turn solid and its faces are held at "
          "once. Warns (UserWarning) when it is thinner than its wake needs.")
      .def(
          "obstacle_force",
          [](const Fluid& f, const py::object& index) {
            return vec3_to_tuple(f.obstacle_force(from_py<int>("index", index)));
          },
          py::arg("index"),
          "The force (fx, fy, fz) N the air exerts on obstacle `index`: pressure plus viscous "
          "shear (no-slip), from the last step. Drag coefficient: fx / (0.5 rho U^2 A).")
      .def_property_readonly(
          "obstacles", [](const Fluid& f) { return f.params().obstacles; },
          "[ObstacleParams, ...] (copies)")
      .def(
          "solid_cells",
          [](const Fluid& f) {
            const GridGeometry& g = f.geometry();
            py::array_t<uint16_t> out({g.nx, g.ny, g.nz});
            const std::vector<uint16_t>& owner = f.solid_owner();  // empty: no solids
            if (owner.empty())
              std::fill(out.mutable_data(), out.mutable_data() + out.size(), uint16_t(0));
            else
              std::copy(owner.begin(), owner.end(), out.mutable_data());
            return out;
          },
          "Per cell (nx, ny, nz): 0 = air, 1 + index of the obstacle that owns it.")
      .def("warnings", &Fluid::warnings,
           "What the solids' resolution leaves out, one sentence each (empty when all is well).")
      .def(
          "step",
          [](Fluid& f, const py::object& dt_, const py::object& n_, const py::object& points,
             const py::object& impulses) {
            const double dt = from_py<double>("dt", dt_);
            const long n = from_py<long>("n", n_);
            check_positive("dt", dt);
            if (n < 0) fail_param("n", ">= 0", n);
            if (points.is_none() != impulses.is_none())
              fail_param("impulses", "given together with points (or neither)",
                         impulses.is_none() ? "None" : "an array");
            MatX3 p, j;
            const std::vector<PointImpulses> pi{{&p, &j}};
            if (!points.is_none()) {
              p = finite_rows("points", points);
              j = finite_rows("impulses", impulses);
              if (j.rows() != p.rows())
                fail_param("impulses", "shape (" + std::to_string(p.rows()) + ", 3) as points",
                           "(" + std::to_string(j.rows()) + ", 3)");
            }
            py::gil_scoped_release release;
            for (long i = 0; i < n; ++i) f.step(dt, points.is_none() ? nullptr : &pi);
          },
          py::arg("dt"), py::arg("n") = 1, py::arg("points") = py::none(),
          py::arg("impulses") = py::none(),
          "Advance the air n steps of dt seconds (GIL released). points, impulses: (M, 3) m and "
          "N s, impulses a body gives the air in each step, spread onto the faces with the "
          "weights sample() uses at those points (its transpose) after advection, before the "
          "projection (two-way coupling, docs/coupling.md).")
      .def_property_readonly("time", &Fluid::time, "Simulated time, s.")
      .def(
          "set_velocity",
          [](Fluid& f, const py::function& fn) {
            for (int c = 0; c < 3; ++c) {
              const MatX3 x = f.face_positions(c);
              py::array pts = py::cast(x);
              py::object result = fn(pts);
              auto val =
                  py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(result);
              if (result.is_none() || !val || val.ndim() != 2 || val.shape(0) != x.rows() ||
                  val.shape(1) != 3)
                fail_param(
                    "fn(points)", "an (M, 3) array for M = " + std::to_string(x.rows()) + " points",
                    !result.is_none() && val ? "shape " + std::string(py::str(val.attr("shape")))
                                             : repr_of(result));
              std::vector<double> col(std::size_t(x.rows()));
              for (py::ssize_t r = 0; r < x.rows(); ++r) col[std::size_t(r)] = val.at(r, c);
              f.set_component(c, col.data());
            }
          },
          py::arg("fn"),
          "Set the velocity from fn(points (M, 3) m) -> (M, 3) m/s, evaluated at the u, v and w "
          "face positions (component c of fn's value goes to the c-faces).")
      .def(
          "sample",
          [](const Fluid& f, const py::object& points) {
            auto p = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(points);
            if (!p || p.ndim() != 2 || p.shape(1) != 3)
              fail_param("points", "an (M, 3) array",
                         p ? "ndim " + std::to_string(p.ndim()) : "not an array");
            py::array_t<double> out({p.shape(0), py::ssize_t(3)});
            const double* src = p.data();
            double* dst = out.mutable_data();
            const long m = long(p.shape(0));
            {
              py::gil_scoped_release release;
              f.sample(src, m, dst);
            }
            return out;
          },
          py::arg("points"),
          "Trilinear air velocity (M, 3) m/s at points (M, 3) m. Points outside the domain take "
          "the "
          "nearest boundary value and are counted in stats['samples_outside'].")
      .def(
          "divergence",
          [](const Fluid& f) {
            const GridGeometry& g = f.geometry();
            py::array_t<double> out({g.nx, g.ny, g.nz});
            f.divergence(out.mutable_data());
            return out;
          },
          "Cell divergence (nx, ny, nz) of the current field, 1/s (after a step: after its "
          "projection).")
      .def("max_divergence", &Fluid::max_divergence, "max |divergence|, 1/s.")
      .def(
          "set_solid_cells",
          [](Fluid& f, const py::object& mask) {
            const GridGeometry& g = f.geometry();
            auto a = py::array_t<uint8_t, py::array::c_style | py::array::forcecast>::ensure(mask);
            if (!a || a.ndim() != 3 || a.shape(0) != g.nx || a.shape(1) != g.ny ||
                a.shape(2) != g.nz)
              fail_param("mask",
                         "a boolean array of shape (" + std::to_string(g.nx) + ", " +
                             std::to_string(g.ny) + ", " + std::to_string(g.nz) + ")",
                         a ? "shape " + std::string(py::str(a.attr("shape"))) : repr_of(mask));
            f.set_solid_cells(a.data());
          },
          py::arg("mask"),
          "The pressure solve's solid cells: mask (nx, ny, nz), true = solid (no unknown of the "
          "projection, no flux across its faces). Low level: obstacles set it and also hold the "
          "velocity on solid faces; on its own it changes only the pressure solve. Needs pressure "
          "'multigrid' or 'pcg'.")
      .def_property(
          "u", [](py::object self) { return component_view(self, 0); },
          [](Fluid& f, const py::object& a) { set_component_from(f, 0, a); },
          "x-face velocities (view), m/s")
      .def_property(
          "v", [](py::object self) { return component_view(self, 1); },
          [](Fluid& f, const py::object& a) { set_component_from(f, 1, a); },
          "y-face velocities (view), m/s")
      .def_property(
          "w", [](py::object self) { return component_view(self, 2); },
          [](Fluid& f, const py::object& a) { set_component_from(f, 2, a); },
          "z-face velocities (view), m/s")
      .def(
          "face_positions",
          [](const Fluid& f, const py::object& c_) {
            const long c = from_py<long>("component", c_);
            if (c < 0 || c > 2) fail_param("component", "0, 1 or 2", c);
            return f.face_positions(c);
          },
          py::arg("component"), "World positions (size, 3) of the u (0), v (1) or w (2) nodes, m.")
      .def_property_readonly("resolution",
                             [](const Fluid& f) {
                               const GridGeometry& g = f.geometry();
                               return py::make_tuple(g.nx, g.ny, g.nz);
                             })
      .def_property_readonly("cell_size", [](const Fluid& f) { return f.geometry().h; })
      .def_property_readonly("origin", [](const Fluid& f) { return f.geometry().origin; })
      .def_property_readonly("boundary",
                             [](const Fluid& f) { return name_of(f.params().boundary); })
      .def_property_readonly("advection",
                             [](const Fluid& f) { return name_of(f.params().advection); })
      .def_property_readonly("pressure",
                             [](const Fluid& f) { return name_of(f.params().pressure); })
      .def_property_readonly("precision",
                             [](const Fluid& f) { return name_of(f.params().precision); })
      .def_property_readonly("viscosity", [](const Fluid& f) { return f.params().viscosity; })
      .def_property_readonly("density", [](const Fluid& f) { return f.params().density; })
      .def_property_readonly("wind", [](const Fluid& f) { return wind_to_list(f.params().wind); })
      .def_property_readonly("stats",
                             [](const Fluid& f) {
                               const FluidStats& s = f.stats();
                               py::dict d;
                               d["steps"] = s.steps;
                               d["pressure_iterations"] = s.pressure_iterations;
                               d["pressure_residual"] = s.pressure_residual;
                               d["pressure_converged"] = s.pressure_converged;
                               d["diffusion_iterations"] = s.diffusion_iterations;
                               d["samples_outside"] = s.samples_outside;
                               d["seconds_advect"] = s.seconds_advect;
                               d["seconds_forces"] = s.seconds_forces;
                               d["seconds_project"] = s.seconds_project;
                               return d;
                             })
      .def("__repr__", [](const Fluid& f) {
        const GridGeometry& g = f.geometry();
        const FluidParams& p = f.params();
        return "Fluid(resolution=(" + std::to_string(g.nx) + ", " + std::to_string(g.ny) + ", " +
               std::to_string(g.nz) + "), cell_size=" + detail::to_text(g.h) + ", boundary='" +
               name_of(p.boundary) + "', advection='" + name_of(p.advection) + "', pressure='" +
               name_of(p.pressure) + "', precision='" + name_of(p.precision) +
               "', time=" + detail::to_text(f.time()) + ")";
      });
}

void bind_fluid(py::module_& m) {
  bind_turbulence(m);
  bind_fan(m);
  bind_obstacle(m);
  bind_fluid_class(m);
}

}  // namespace flagsim::bindings

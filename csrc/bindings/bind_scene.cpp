#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "bindings/fields.h"
#include "bindings/fluid_fields.h"
#include "common/errors.h"
#include "scene/scene.h"
#include "scene/simulation.h"

namespace py = pybind11;

namespace flagsim::bindings {

namespace {

// A numpy view of an Eigen row-major matrix owned by `owner` (keeps it alive via base).
template <class Mat>
py::array view_of(Mat& m, py::handle owner, bool writeable) {
  using Scalar = typename Mat::Scalar;
  std::vector<py::ssize_t> shape{m.rows(), m.cols()};
  std::vector<py::ssize_t> strides{py::ssize_t(sizeof(Scalar) * m.cols()),
                                   py::ssize_t(sizeof(Scalar))};
  py::array a(py::dtype::of<Scalar>(), shape, strides, m.data(), owner);
  if (!writeable) a.attr("setflags")(py::arg("write") = false);
  return a;
}

template <class Vec>
py::array view_of_vec(const Vec& v, py::handle owner) {
  py::array a(py::dtype::of<typename Vec::Scalar>(), {v.size()},
              {py::ssize_t(sizeof(typename Vec::Scalar))}, v.data(), owner);
  a.attr("setflags")(py::arg("write") = false);
  return a;
}

using DoubleArray = py::array_t<double, py::array::c_style | py::array::forcecast>;

// An array-like of numbers as a float64 array, or TypeError naming `name`.
DoubleArray double_array(const std::string& name, const py::object& o) {
  DoubleArray a;
  if (!PyUnicode_Check(o.ptr()) && !PyBytes_Check(o.ptr())) {
    try {
      a = DoubleArray::ensure(o);
    } catch (const py::error_already_set&) {
    }
  }
  if (!a) {
    PyErr_Clear();
    wrong_type(name, "an array of numbers", o);
  }
  return a;
}

// Copy an (N, 3) array-like into m in place (views stay valid); rejects other shapes and
// non-finite.
void assign_rows(MatX3& m, const std::string& name, const py::object& o) {
  const DoubleArray a = double_array(name, o);
  if (a.ndim() != 2 || a.shape(0) != m.rows() || a.shape(1) != 3)
    throw InvalidArgument(name + " should have shape (" + std::to_string(m.rows()) + ", 3), got " +
                          std::string(py::str(a.attr("shape"))));
  auto r = a.unchecked<2>();
  for (py::ssize_t i = 0; i < r.shape(0); ++i)
    for (int k = 0; k < 3; ++k)
      if (!std::isfinite(r(i, k)))
        fail_param(name + "[" + std::to_string(i) + "]", "finite", r(i, k));
  std::copy(a.data(), a.data() + a.size(), m.data());
}

}  // namespace

void bind_solids(py::module_& m) {
  py::class_<SolidParams, ObstacleParams> solid(m, "SolidParams", R"doc(A solid of the scene.

One description for the air and the cloth ([[solids]] in TOML): a box, sphere, capped cylinder,
capsule or closed triangle mesh (the ObstacleParams fields), a solid of the air grid when air is
true (static only), collided with by the flag when cloth is true (keeping `thickness` from its
surface, Coulomb `friction`), at rest or keyframed (motion, cloth only).)doc");
  solid.def(
      py::init([](const py::kwargs& kw) { return from_fields<SolidParams>(kw, "SolidParams"); }),
      "SolidParams(**fields), e.g. SolidParams(shape='sphere', center=(0, 0, 0), radius=0.1)");
  def_obstacle_fields(solid, "solid");
  def_field(solid, "air", &SolidParams::air, "solid", "a solid of the air grid (static)");
  def_field(solid, "cloth", &SolidParams::cloth, "solid", "the flag collides with it");
  def_field(solid, "thickness", &SolidParams::thickness, "solid",
            "m, the distance the flag's vertices keep from its surface");
  def_field(solid, "friction", &SolidParams::friction, "solid", "Coulomb coefficient (>= 0)");
  def_ref_field(solid, "motion", &SolidParams::motion, "solid",
                "MotionSchedule: keyframed rigid motion (cloth only); empty = at rest");
  solid.def("validate", &SolidParams::validate, py::arg("prefix") = "solid");
}

void bind_air_params(py::module_& m) {
  py::class_<AirParams> air(
      m, "AirParams", "The air: 'none', 'uniform' (analytic wind) or 'grid' (Stable Fluids).");
  air.def(py::init<>());
  def_field(air, "model", &AirParams::model, "air", "'none' | 'uniform' | 'grid'");
  air.def_property(
      "wind", [](const AirParams& a) { return wind_to_list(a.wind); },
      [](AirParams& a, const py::object& o) {
        AirParams copy = a;
        copy.wind = wind_from_py("air.wind", o, false);
        copy.validate("air");
        a = copy;
      },
      "m/s: a constant (vx, vy, vz) or keyframes [(time s, (vx, vy, vz)), ...], linear between "
      "keys; "
      "reads back as keyframes");
  def_field<AirParams, double>(air, "density", &AirParams::density, "air", "kg/m^3");
  def_field<AirParams, double>(air, "viscosity", &AirParams::viscosity, "air",
                               "m^2/s, kinematic ('grid'; 0 = no diffusion)");
  def_fluid_fields(air, "air");
  def_field<AirParams, bool>(
      air, "pole_obstacle", &AirParams::pole_obstacle, "air",
      "the pole is a no-slip solid of the air grid too, so it sheds a wake ('grid', pole.enabled)");
  def_field<AirParams, bool>(air, "pipeline", &AirParams::pipeline, "air",
                             "'grid' on >= 2 threads, coupling 'one_way' or 'two_way_lagged': the "
                             "air steps on its own thread beside the cloth (same results); false: "
                             "one after the other");
  def_field(air, "coupling", &AirParams::coupling, "air",
            "'one_way' (the paper: the air never feels the flag) | 'two_way' (the flag's drag goes "
            "back into the grid in the same step; 'grid'; docs/coupling.md) | 'two_way_lagged' "
            "(the same a step later, so the air can step beside the cloth: another scheme)");
}

void bind_flag_spec(py::module_& m) {
  py::class_<FlagSpec> spec(m, "FlagSpec", R"doc(One flag of a scene with several (TOML [[flags]]).

Its keys are the flag's (rows, cols, width, origin, pin, ...), and its own drag, integrator,
flapping and pole sections; Scene.flags lists them, flag 0 first.)doc");
  spec.def(py::init<>());
  // The flag's own fields are forwarded from `_flag` in python/flagsim/scene.py, so a [[flags]]
  // table reads like a [flag] section with sub-tables.
  auto spec_part = [&spec](const char* name, auto member, const char* doc) {
    using T = std::remove_reference_t<decltype(std::declval<FlagSpec>().*member)>;
    spec.def_property(
        name, [member](FlagSpec& s) -> T& { return s.*member; },
        [member, name](FlagSpec& s, const py::object& value) {
          s.*member = from_py<T>(name, value);
        },
        py::return_value_policy::reference_internal, doc);
  };
  spec_part("_flag", &FlagSpec::flag, "FlagParams");
  spec_part("drag", &FlagSpec::drag, "DragParams");
  spec_part("integrator", &FlagSpec::integrator, "IntegratorParams");
  spec_part("flapping", &FlagSpec::flapping, "FlappingParams (paper eq. 5)");
  spec_part("pole", &FlagSpec::pole, "PoleParams");
  spec.def("__copy__", [](const FlagSpec& s) { return FlagSpec(s); });
  spec.def(
      "__deepcopy__", [](const FlagSpec& s, py::dict) { return FlagSpec(s); }, py::arg("memo"));
}

void bind_scene_class(py::module_& m) {
  py::class_<Scene> scene(m, "Scene", R"doc(Everything a Simulation needs, in SI units.

Sections: flag, air, drag, integrator (and the areas' own sections); top-level dt and gravity.
Every assignment is validated: a bad value raises ValueError naming the parameter and leaves
the scene unchanged. Build one with Scene.paper(), Scene.named(name) or Scene.load(path).)doc");
  scene.def(py::init<>());
  scene.def_static("paper", &Scene::paper,
                   "Paper §5: 8 x 11 flag, 0.54 m tall, dt = 0.01 s, 2 m/s air.");
  scene.def_static("banner", &Scene::banner,
                   "Banner hanging from its top edge in a 3 m/s wind along +z.");
  scene.def_static("flapping_demo", &Scene::flapping_demo,
                   "Paper §4.3 (Fig. 6): eq. 5 flapping alone; no air solver, no gravity, every "
                   "mass pulled along +x.");
  scene.def_static("large", &Scene::large,
                   "The paper scene meshed finer: 64 x 64 flag with self-collision and eq. 5 in a "
                   "64^3 air grid, dt = 0.01 s (real time: 100 steps/s).");
  scene.def_static("pole_wake", &Scene::pole_wake,
                   "The paper's flag behind its pole as a solid of the air (a 2 m/s tunnel), eq. 5 "
                   "off.");
  scene.def_static("emergent", &Scene::emergent,
                   "A flag that flaps with eq. 5 off: two-way coupling, curl-noise turbulence and "
                   "the pole as a solid of the air (docs/coupling.md).");
  scene.def_static("boat", &Scene::boat,
                   "A flag on the mast of a boat rolling and pitching in a 6 m/s wind.");
  scene.def_static("_builtins", &builtin_scenes);
  scene.def_static("_named", &builtin_scene, py::arg("name"));
  scene.def_property(
      "name", [](const Scene& s) { return s.name; },
      [](Scene& s, const py::object& o) { s.name = from_py<std::string>("name", o); },
      "free text, used in exports and reports");
  auto part = [&scene](const char* name, auto member, const char* doc) {
    using T = std::remove_reference_t<decltype(std::declval<Scene>().*member)>;
    scene.def_property(
        name, [member](Scene& s) -> T& { return s.*member; },
        [member, name](Scene& s, const py::object& value) {
          Scene copy = s;
          copy.*member = from_py<T>(name, value);
          copy.validate();
          s = copy;
        },
        py::return_value_policy::reference_internal, doc);
  };
  part("flag", &Scene::flag, "FlagParams");
  part("air", &Scene::air, "AirParams");
  part("drag", &Scene::drag, "DragParams");
  part("integrator", &Scene::integrator, "IntegratorParams");
  part("flapping", &Scene::flapping, "FlappingParams (paper eq. 5)");
  part("self_collision", &Scene::self_collision, "SelfCollisionParams");
  part("pole", &Scene::pole, "PoleParams");
  scene.def_property(
      "solids", [](const Scene& s) { return s.solids; },
      [](Scene& s, const py::object& o) {
        Scene copy = s;
        copy.solids = from_py<std::vector<SolidParams>>("solids", o);
        copy.validate();
        s = copy;
      },
      "[SolidParams, ...]: solids of the air and the cloth; a list copy: assign to change");
  scene.def_property(
      "dt", [](const Scene& s) { return s.dt; },
      [](Scene& s, const py::object& o) {
        const double dt = from_py<double>("dt", o);
        check_positive("dt", dt);
        s.dt = dt;
      },
      "s, one Simulation step");
  scene.def_property(
      "gravity", [](const Scene& s) { return vec3_to_tuple(s.gravity); },
      [](Scene& s, const py::object& o) {
        Vec3 g = from_py<Vec3>("gravity", o);
        check_finite_vec("gravity", g);
        s.gravity = g;
      },
      "m/s^2");
  scene.def_property(
      "flags", [](const Scene& s) { return s.flags(); },
      [](Scene& s, const py::object& o) {
        Scene copy = s;
        copy.set_flags(from_py<std::vector<FlagSpec>>("flags", o));
        copy.validate();
        s = copy;
      },
      "[FlagSpec, ...]: every flag, flag 0 first (flag 0 is the scene's flag, drag, integrator, "
      "flapping and pole); a list copy: assign to change. The flags share air, gravity, dt and "
      "self_collision");
  scene.def("validate", &Scene::validate, "Raise ValueError naming the first bad parameter.");
  scene.def("__copy__", [](const Scene& s) { return Scene(s); });
  scene.def("__deepcopy__", [](const Scene& s, py::dict) { return Scene(s); }, py::arg("memo"));
}

void bind_simulation(py::module_& m) {
  py::class_<Simulation> sim(m, "Simulation", R"doc(A scene built into the stages it needs.

sim.step(n) advances n steps of scene.dt with the GIL released. positions, velocities and normals
are (N, 3) float64 views into the simulation (no copy per access; they stay valid across steps
and keep the simulation alive); assigning `sim.positions = x` copies into the same buffer.)doc");
  sim.def(py::init([](const py::object& scene) {
            const Scene s = from_py<Scene>("scene", scene);
            std::unique_ptr<Simulation> out;
            {
              py::gil_scoped_release release;  // a large flag takes seconds to build
              out = std::make_unique<Simulation>(s);
            }
            if (out->fluid())
              for (const std::string& w : out->fluid()->warnings())
                if (PyErr_WarnEx(PyExc_UserWarning, w.c_str(), 1) != 0)
                  throw py::error_already_set();
            return out;
          }),
          py::arg("scene"));
  sim.def(
      "step",
      [](Simulation& s, const py::object& n_) {
        const long n = from_py<long>("n", n_);
        if (n < 0) fail_param("n", ">= 0", n);
        py::gil_scoped_release release;
        s.step(n);
      },
      py::arg("n") = 1, "Advance n steps of scene.dt. Raises DivergenceError (state restored).");
  sim.def_property_readonly("num_flags", &Simulation::num_flags, "flags in the scene");
  sim.def_property_readonly(
      "flags",
      [](py::object self) {
        Simulation& s = self.cast<Simulation&>();
        py::list out;
        for (int i = 0; i < s.num_flags(); ++i)
          out.append(py::cast(&s.flag(i), py::return_value_policy::reference_internal, self));
        return py::tuple(out);
      },
      "(Simulation, ...) one per flag, flag 0 (this Simulation itself) first: each flag's "
      "positions, velocities, normals, uv, triangles, energy, ledger and stats as views without "
      "a copy; they keep this Simulation alive. Step the scene through this Simulation (a flag's "
      "own step() raises)");
  sim.def_property_readonly("time", &Simulation::time, "simulated time, s");
  sim.def_property_readonly("step_count", &Simulation::step_count);
  sim.def_property_readonly("pipelined", &Simulation::pipelined,
                            "True when the air steps beside the cloth (air.pipeline, a grid, "
                            "coupling 'one_way' or 'two_way_lagged'; on two threads when "
                            "flagsim.num_threads() >= 2); same results as the serial order");
  sim.def_property_readonly(
      "scene", [](const Simulation& s) { return Scene(s.scene()); },
      "a copy of the scene this simulation was built from");
  sim.def_property(
      "positions",
      [](py::object self) { return view_of(self.cast<Simulation&>().positions(), self, true); },
      [](Simulation& s, const py::object& a) {
        assign_rows(s.positions(), "positions", a);
        s.update_normals();
      },
      "(N, 3) m, view");
  sim.def_property_readonly(
      "pinned_vertices",
      [](const Simulation& s) {
        return py::array_t<Index>(py::ssize_t(s.pinned_vertices().size()),
                                  s.pinned_vertices().data());
      },
      "(P,) indices of the pinned vertices, the order set_pin_targets takes");
  sim.def(
      "set_pin_targets",
      [](Simulation& s, const py::object& targets) {
        MatX3 t(Index(s.pinned_vertices().size()), 3);
        assign_rows(t, "targets", targets);
        s.set_pin_targets(t);
      },
      py::arg("targets"),
      "Where the pinned vertices are at the end of the next step ((P, 3) m, in pinned_vertices "
      "order): they move there at constant velocity over the step (their velocity that of the "
      "motion; the pins' work is in energy_ledger()['pins']) and stay there until set again. "
      "The pole stays (set_pin_pose moves both).");
  sim.def(
      "set_pin_pose",
      [](Simulation& s, const py::object& translation, const py::object& rotation) {
        s.set_pin_pose(from_py<Vec3>("translation", translation),
                       from_py<Vec3>("rotation", rotation));
      },
      py::arg("translation") = py::make_tuple(0.0, 0.0, 0.0),
      py::arg("rotation") = py::make_tuple(0.0, 0.0, 0.0),
      "The pins and the pole together at a rigid pose at the end of the next step: translation "
      "(m) and rotation vector (degrees, about flag.pin_motion.pivot) from where they are at "
      "rest.");
  sim.def_property_readonly(
      "pole_pose",
      [](const Simulation& s) {
        return py::make_tuple(Mat3(s.pole_pose().R), Vec3(s.pole_pose().t));
      },
      "(R, t): the pole (and the pins) now at R p + t of their rest positions p");
  sim.def_property(
      "velocities",
      [](py::object self) { return view_of(self.cast<Simulation&>().velocities(), self, true); },
      [](Simulation& s, const py::object& a) { assign_rows(s.velocities(), "velocities", a); },
      "(N, 3) m/s, view");
  sim.def_property_readonly(
      "normals",
      [](py::object self) {
        return view_of(const_cast<MatX3&>(self.cast<Simulation&>().normals()), self, false);
      },
      "(N, 3) unit vertex normals, read-only view");
  sim.def_property_readonly(
      "triangles",
      [](py::object self) {
        return view_of(const_cast<MatX3i&>(self.cast<Simulation&>().topology().triangles), self,
                       false);
      },
      "(T, 3) int32 vertex indices, counter-clockwise seen from +z at rest");
  sim.def_property_readonly(
      "uv",
      [](py::object self) {
        return view_of(const_cast<MatX2&>(self.cast<Simulation&>().topology().uv), self, false);
      },
      "(N, 2) texture coordinates in [0, 1]");
  sim.def_property_readonly(
      "rest_positions",
      [](py::object self) {
        return view_of(const_cast<MatX3&>(self.cast<Simulation&>().topology().rest_positions), self,
                       false);
      },
      "(N, 3) m");
  sim.def_property_readonly(
      "springs",
      [](py::object self) {
        return view_of(const_cast<MatX2i&>(self.cast<Simulation&>().topology().springs), self,
                       false);
      },
      "(S, 2) int32 vertex pairs (structural, shear, bend)");
  sim.def_property_readonly(
      "rest_lengths",
      [](py::object self) {
        return view_of_vec(self.cast<Simulation&>().topology().rest_length, self);
      },
      "(S,) m");
  sim.def_property_readonly(
      "node_mass",
      [](py::object self) { return view_of_vec(self.cast<Simulation&>().topology().mass, self); },
      "(N,) kg, areal density x node_area");
  sim.def_property_readonly(
      "node_area",
      [](py::object self) { return view_of_vec(self.cast<Simulation&>().topology().area, self); },
      "(N,) m^2, a third of each adjacent triangle's rest area (S of eq. 3)");
  sim.def_property_readonly(
      "pinned",
      [](const Simulation& s) {
        const auto& im = s.topology().inv_mass;
        py::array_t<bool> out(im.size());
        auto w = out.mutable_unchecked<1>();
        for (Index i = 0; i < im.size(); ++i) w(i) = im[i] == 0.0;
        return out;
      },
      "(N,) bool, pinned vertices (inverse mass 0)");
  sim.def_property_readonly(
      "stages", [](const Simulation& s) { return py::tuple(py::cast(s.stages())); },
      "names of the stages this scene runs, in step order");
  sim.def_property_readonly(
      "timings",
      [](const Simulation& s) {
        py::dict d;
        for (const auto& [k, v] : s.timings()) d[py::str(k)] = v;
        return d;
      },
      "seconds spent per stage since construction");
  sim.def(
      "energy",
      [](const Simulation& s) {
        const ClothEnergy e = s.energy();
        py::dict d;
        d["kinetic"] = e.kinetic;
        d["gravity"] = e.gravity;
        d["spring"] = e.spring;
        return d;
      },
      "dict of kinetic, gravity (potential) and spring energies, J");
  sim.def(
      "energy_ledger",
      [](const Simulation& s) {
        const EnergyLedger l = s.energy_ledger();
        py::dict d;
        for (const auto& [name, entry] : kLedgerEntries) d[name] = l.*entry;
        return d;
      },
      "dict of the energy each stage gave the flag since construction, J (docs/energy.md): "
      "gravity, drag, damping, flap, strain_limit, pole, self_collision, pins, edits (state "
      "written between steps) and integrator (the remainder). Their sum is the change of "
      "kinetic + spring energy; without 'gravity', the change of the total of energy()");
  sim.def_property_readonly("energy_scale", &Simulation::energy_scale,
                            "J, m |g| H + m U^2 / 2: the scale integrator.energy_tolerance is a "
                            "fraction of (m (1 m/s)^2 / 2 without gravity and wind)");
  sim.def("holdable_energy", &Simulation::holdable_energy,
          "J: the bound on the net unexplained energy the check counts (docs/energy.md): the "
          "kinetic and spring energy and the rise since construction, relative to the pins' "
          "centre of mass once the pins move");
  sim.def("max_strain", &Simulation::max_strain, "largest spring strain (l - L) / L now");
  sim.def_property_readonly(
      "render_positions",
      [](py::object self) {
        return view_of(const_cast<MatX3&>(self.cast<Simulation&>().render_positions()), self,
                       false);
      },
      "(N, 3) m, read-only view of the geometry to export: with flapping.mode 'visual' the "
      "positions displaced by eq. 5 along the normals (physics untouched), else the positions");
  sim.def_property_readonly(
      "render_normals",
      [](py::object self) {
        return view_of(const_cast<MatX3&>(self.cast<Simulation&>().render_normals()), self, false);
      },
      "(N, 3) unit normals of render_positions, read-only view");
  sim.def_property_readonly(
      "flap_displacement",
      [](py::object self) {
        return view_of_vec(self.cast<Simulation&>().flap_displacement(), self);
      },
      "(N,) m, eq. 5 displacement z of each vertex at the current time (zeros when off)");
  sim.def_property_readonly("pole_air_speed", &Simulation::pole_air_speed,
                            "u_p of eq. 5 at the last flap stage: mean air speed along the "
                            "pole-side edge, m/s");
  sim.def_property_readonly(
      "self_collision_stats",
      [](const Simulation& s) -> py::object {
        const SelfCollisionStats* st = s.self_collision_stats();
        if (!st) return py::none();
        py::dict d;
        d["candidates"] = st->candidates;
        d["contacts"] = st->contacts;
        d["crossings"] = st->crossings;
        d["pole"] = st->pole;
        d["frozen"] = st->frozen;
        d["sweeps"] = st->sweeps;
        d["broad_phases"] = st->broad_phases;
        d["tree_queries"] = st->tree_queries;
        d["exact_gaps"] = st->exact_gaps;
        return d;
      },
      "the last step's self-collision counts (None when self_collision is off): candidate pairs, "
      "proximity contacts, continuous crossings stopped short, pole contacts, vertices frozen by "
      "the fallback, sweeps, broad phases, those that queried the box trees, and the candidates' "
      "start gaps computed exactly (the rest bounded from a snapshot)");
  sim.def_property_readonly(
      "between_flags_stats",
      [](const Simulation& s) -> py::object {
        const SelfCollisionStats* st = s.between_flags_stats();
        if (!st) return py::none();
        py::dict d;
        d["candidates"] = st->candidates;
        d["contacts"] = st->contacts;
        d["crossings"] = st->crossings;
        d["frozen"] = st->frozen;
        d["sweeps"] = st->sweeps;
        return d;
      },
      "the last step's counts of the contact pass between flags (None with one flag or "
      "self_collision off; zeros when no two flags came near): candidate pairs, proximity "
      "contacts, crossings stopped short, vertices frozen by the fallback, sweeps");
  sim.def_property_readonly(
      "last_step_stats",
      [](const Simulation& s) {
        const IntegratorStats& st = s.last_step_stats();
        py::dict d;
        d["substeps"] = st.substeps;
        d["cg_iterations"] = st.cg_iterations;
        d["halvings"] = st.halvings;
        d["stable_step"] = st.stable_step;
        d["energy_halvings"] = st.energy_halvings;
        d["air_samples_outside"] = s.air_outside_last_step();
        const StepHalvings& h = s.last_step_halvings();
        d["halvings_total"] = h.total();
        d["halvings_energy"] = h.energy;
        d["halvings_strain"] = h.strain;
        d["halvings_piece_energy"] = h.piece_energy;
        d["halvings_cg"] = h.cg;
        return d;
      },
      "statistics of the last step. Its halvings, summed over all its pieces and redos (sum them "
      "over steps for a run's): halvings_total = halvings_energy + halvings_strain (the step "
      "redone in 2, 4, ... pieces because the check found energy no stage explains, or strain "
      "beyond the strain limit's promise) + halvings_piece_energy + halvings_cg (an implicit "
      "piece halved inside the integrator by its energy guard, or because CG did not converge). "
      "Of the last piece only: substeps, cg_iterations, halvings (the integrator's), stable_step; "
      "energy_halvings is the last piece's guard halvings plus the step's redo levels (any cause; "
      "docs/energy.md)");
  sim.def_property_readonly(
      "fluid", [](Simulation& s) { return s.fluid(); }, py::return_value_policy::reference_internal,
      "the air grid (flagsim.Fluid) when the scene uses one (air.model 'grid'), else None; "
      "stats['samples_outside'] counts masses that sampled it from outside its domain");
  sim.def_property_readonly(
      "pole_force", [](const Simulation& s) { return vec3_to_tuple(s.pole_force()); },
      "(fx, fy, fz) N, the force the flag exerted on its pins in the last step (the pole's "
      "reaction, from the flag's momentum: sum m g + (drag + eq. 5 force impulse - change of "
      "momentum) / dt; contact with the pole cylinder not included); zeros before any step");
  sim.def_property_readonly(
      "pole_force_mean", [](const Simulation& s) { return vec3_to_tuple(s.pole_force_mean()); },
      "(fx, fy, fz) N, pole_force averaged over the simulated time since construction or the "
      "last reset_pole_force_mean() (impulse / time)");
  sim.def("reset_pole_force_mean", &Simulation::reset_pole_force_mean,
          "Start pole_force_mean afresh from now (e.g. after the transient).");
  sim.def_property_readonly(
      "pole_impulse", [](const Simulation& s) { return vec3_to_tuple(s.pole_impulse()); },
      "(jx, jy, jz) N s, the pins' impulse since construction (never reset): the mean force "
      "between two moments is its change over the time between them");
  sim.def(
      "air_velocity",
      [](const Simulation& s, const py::object& points) {
        const DoubleArray pts = double_array("points", points);
        if (pts.ndim() != 2 || pts.shape(1) != 3)
          throw InvalidArgument("points should have shape (M, 3), got " +
                                std::string(py::str(pts.attr("shape"))));
        MatX3 p = Eigen::Map<const MatX3>(pts.data(), pts.shape(0), 3);
        MatX3 out;
        s.air_velocity(p, out);
        return out;
      },
      py::arg("points"), "(M, 3) air velocity at world points (M, 3) at the current time, m/s");
}

void bind_scene(py::module_& m) {
  bind_solids(m);
  bind_air_params(m);
  bind_flag_spec(m);
  bind_scene_class(m);
  bind_simulation(m);
}

}  // namespace flagsim::bindings

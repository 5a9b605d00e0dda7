#include "scene/scene.h"

#include <algorithm>
#include <cmath>

#include "common/errors.h"
#include "fluid/solids.h"

namespace flagsim {

void AirParams::validate(const std::string& p) const {
  wind.validate(p + ".wind");
  check_nonnegative(p + ".density", density);
  turbulence.validate(p + ".turbulence");  // used by "uniform" too
  if (model == AirModel::kGrid) FluidParams::validate(p);
}

ObstacleParams AirParams::pole_solid(const PoleParams& pole) {
  ObstacleParams o;
  o.shape = ObstacleShape::kCylinder;
  o.axis = Vec3(0, 1, 0);
  o.radius = pole.radius;
  o.length = pole.height;
  o.center = pole.base + Vec3(0, 0.5 * pole.height, 0);
  o.slip = Slip::kNoSlip;
  return o;
}

void SolidParams::validate(const std::string& p) const {
  ObstacleParams::validate(p);
  check_length(p + ".thickness", thickness);
  check_nonnegative(p + ".friction", friction);
  motion.validate(p + ".motion");
  if (air && !motion.empty())
    fail_param(p + ".air",
               "false for a keyframed solid (the air's solids are static; a moving solid is "
               "cloth-only)",
               "true");
}

std::vector<FlagSpec> Scene::flags() const {
  std::vector<FlagSpec> out{FlagSpec{flag, drag, integrator, flapping, pole}};
  out.insert(out.end(), more_flags.begin(), more_flags.end());
  return out;
}

void Scene::set_flags(const std::vector<FlagSpec>& flags) {
  if (flags.empty()) fail_param("flags", "at least one flag", "an empty list");
  flag = flags[0].flag;
  drag = flags[0].drag;
  integrator = flags[0].integrator;
  flapping = flags[0].flapping;
  pole = flags[0].pole;
  more_flags.assign(flags.begin() + 1, flags.end());
}

Scene Scene::flag_scene(int i) const {
  if (i < 0 || i >= num_flags())
    fail_param("flag", "an index in [0, " + std::to_string(num_flags()) + ")", i);
  Scene s = *this;
  s.more_flags.clear();
  if (i > 0) s.set_flags({more_flags[std::size_t(i) - 1]});
  return s;
}

namespace {
// The name of flag `f`'s section: "flag", "pole", ... alone; "flags[2]", "flags[2].pole", ...
// in a scene with several flags.
struct FlagSections {
  int index;  // -1: the scene has one flag
  std::string operator()(const std::string& section) const {
    if (index < 0) return section;
    const std::string f = "flags[" + std::to_string(index) + "]";
    return section == "flag" ? f : f + "." + section;
  }
};

void validate_flag(const FlagSpec& f, const SelfCollisionParams& self_collision,
                   const FlagSections& name) {
  f.flag.validate(name("flag"));
  f.drag.validate(name("drag"));
  f.integrator.validate(name("integrator"));
  // A strain beyond max_strain raises: at or below the strain limit's promise, so could a step
  // the limit keeps within it.
  const IntegratorParams& in = f.integrator;
  if (in.strain_limit > 0 && !(in.max_strain > in.strain_limit + kStrainLimitSlack))
    fail_param(name("integrator") + ".max_strain",
               "> " + name("integrator") + ".strain_limit + " + detail::to_text(kStrainLimitSlack) +
                   " = " + detail::to_text(in.strain_limit + kStrainLimitSlack) +
                   " (the strain the limit promises)",
               in.max_strain);
  f.flapping.validate(name("flapping"));
  if (self_collision.enabled) {
    // A thickness beyond the rest gap would have the flat flag collide with itself.
    const FlagParams& p = f.flag;
    const double dx = p.width / (p.cols - 1), dy = p.height / (p.rows - 1);
    const double gap = dx * dy / std::hypot(dx, dy);  // vertex to the diagonal of a neighbour cell
    if (!(self_collision.thickness < gap))
      fail_param("self_collision.thickness",
                 "< " + detail::to_text(gap) +
                     " m (the rest distance from a vertex to the nearest triangle it is not part "
                     "of" +
                     (name.index < 0 ? std::string() : " in " + name("flag")) + ")",
                 self_collision.thickness);
  }
  f.pole.validate(name("pole"));
}
}  // namespace

void Scene::validate() const {
  self_collision.validate("self_collision");
  const std::vector<FlagSpec> all = flags();
  for (std::size_t i = 0; i < all.size(); ++i)
    validate_flag(all[i], self_collision, FlagSections{all.size() > 1 ? int(i) : -1});
  air.validate("air");
  bool any_pole = false;
  for (const FlagSpec& f : all) any_pole = any_pole || f.pole.enabled;
  if (air.pole_obstacle && !(air.model == AirModel::kGrid && any_pole))
    fail_param("air.pole_obstacle",
               "false unless air.model is \"grid\" and pole.enabled is true (the pole is a solid "
               "of the air grid)",
               "true");
  if (air.two_way() && air.model != AirModel::kGrid)
    fail_param("air.coupling",
               "\"one_way\" unless air.model is \"grid\" (two-way coupling pushes the air grid)",
               "\"" + std::string(name_of(air.coupling)) + "\"");
  for (size_t i = 0; i < solids.size(); ++i) {
    solids[i].validate("solids[" + std::to_string(i) + "]");
    solids[i].validate_mesh("solids[" + std::to_string(i) + "]");
  }
  for (const FlagSpec& f : all)
    if (air.pole_obstacle && !f.flag.pin_motion.empty())
      fail_param("air.pole_obstacle",
                 "false with a keyframed flag.pin_motion (the air's solids are static)", "true");
  if (air.model == AirModel::kGrid) {
    AirParams with_pole = air;
    if (air.pole_obstacle)
      for (const FlagSpec& f : all)
        if (f.pole.enabled) with_pole.obstacles.push_back(AirParams::pole_solid(f.pole));
    for (const SolidParams& s : solids)
      if (s.air) with_pole.obstacles.push_back(s);
    with_pole.validate_combination("air");
  }
  check_finite_vec("gravity", gravity);
  check_positive("dt", dt);
}

Scene Scene::paper() {
  Scene s;
  s.name = "paper";
  s.flag.rows = 8;
  s.flag.cols = 11;
  s.flag.height = 0.54;
  s.flag.width = 0.81;
  s.dt = 0.01;
  // Air (§2, §5): Stable Fluids on 16^3 cells of 0.125 m, x in [-0.5, 1.5], y and z in [-1, 1]
  // around the flag (x in [0.055, 0.865], y in [-0.54, 0], z = 0). A periodic mean flow of
  // 1.5 m/s along +x plus a household fan (§4.1) upstream at mid-height blowing up to 2.5 m/s:
  // about 2 m/s at the flag, faster mid-height than at the edges, so the grid is needed.
  s.air.model = AirModel::kGrid;
  s.air.wind = WindSchedule(Vec3(1.5, 0.0, 0.0));
  s.air.resolution = {16, 16, 16};
  s.air.cell_size = 0.125;
  s.air.origin = Vec3(-0.5, -1.0, -1.0);
  s.air.boundary = Boundary::kPeriodic;
#ifdef FLAGSIM_HAVE_FFTW
  s.air.pressure = Pressure::kFft;
#else
  s.air.pressure = Pressure::kPcg;
#endif
  FanParams fan;
  fan.shape = FanShape::kSphere;
  fan.center = Vec3(-0.3, -0.27, 0.0);
  fan.radius = 0.3;
  fan.direction = Vec3(1.0, 0.0, 0.0);
  fan.force_density = 20.0;
  fan.max_speed = 2.5;
  s.air.fans = {fan};
  // Paper §4.2: one-way coupling cannot make the flag flap, so eq. 5 displaces it along its
  // normals; 0.03 m per m/s of air at the pole gives waves of a few cm at the paper's 2 m/s.
  s.flapping.mode = FlapMode::kDisplace;
  s.flapping.amplitude = 0.03;
  // Not flat to the last digit (docs/design.md "Still air"): with the wind and fans off the
  // scene is mirror-symmetric about the flag's plane, and a perfectly flat flag would stick out
  // sideways forever; 0.1 mm of seeded offset lets it fall and hang along its pole.
  s.flag.imperfection = 1e-4;
  return s;
}

Scene Scene::banner() {
  Scene s;
  s.name = "banner";
  s.flag.rows = 8;
  s.flag.cols = 6;
  s.flag.width = 0.5;
  s.flag.height = 0.7;
  s.flag.origin = Vec3(-0.25, 0.0, 0.0);
  s.flag.pin = Pin::kTop;
  s.pole.enabled = false;
  s.air.wind = WindSchedule(Vec3(0.0, 0.0, 3.0));
  return s;
}

Scene Scene::flapping_demo() {
  Scene s;
  s.name = "flapping_demo";
  s.flag.rows = 16;
  s.flag.cols = 24;
  s.air.model = AirModel::kUniform;
  s.air.wind = WindSchedule(Vec3(2.0, 0.0, 0.0));
  s.air.density = 0.0;               // no drag stage: the wind only sets u_p of eq. 5
  s.gravity = Vec3(9.81, 0.0, 0.0);  // every mass pulled along +x
  s.flapping.mode = FlapMode::kDisplace;
  s.flapping.amplitude = 0.01;
  s.flapping.l_max = 0.2;
  s.flapping.speed = 1.0;
  s.flapping.parabola = 1.0;
  s.flapping.frequency = 3.0;
  return s;
}

Scene Scene::pole_wake() {
  Scene s = paper();
  s.name = "pole_wake";
  // The paper's flag in a tunnel around it whose cells resolve the pole: 8 across its 0.11 m
  // (kWakeCellsAcross), 1.5 x 0.9 x 0.7 m (109 x 65 x 51 cells), inflow 2 m/s along +x.
  const double h = 2 * s.pole.radius / kWakeCellsAcross;
  s.air.boundary = Boundary::kTunnel;
  s.air.pressure = Pressure::kMultigrid;
  s.air.advection = Advection::kMacCormack;
  s.air.cell_size = h;
  s.air.origin = Vec3(-0.3, -0.75, -0.35);
  s.air.resolution = {int(std::lround(1.5 / h)), int(std::lround(0.9 / h)),
                      int(std::lround(0.7 / h))};
  s.air.wind = WindSchedule(Vec3(2.0, 0.0, 0.0));
  s.air.fans.clear();
  s.air.pole_obstacle = true;
  // No painted waves: whatever moves the flag out of its plane comes from the pole's wake.
  s.flapping.mode = FlapMode::kOff;
  return s;
}

Scene Scene::large() {
  Scene s = paper();
  s.name = "large";
  // The same box, fan and flag, meshed 4x finer in the air (64^3 cells of 3.125 cm, 0.8 cell per
  // step at the fan's 2.5 m/s) and 64 x 64 masses on the flag.
  const double paper_spacing =
      std::min(s.flag.width / (s.flag.cols - 1), s.flag.height / (s.flag.rows - 1));
  s.air.resolution = {64, 64, 64};
  s.air.cell_size = 0.125 / 4;
  s.flag.rows = s.flag.cols = 64;
  // Self-collision with the contact thickness at the paper's ratio to the spacing (0.005 m on
  // 77 mm), as the bench's cloth meshed finer (docs/design.md "Benchmark workloads").
  s.self_collision.enabled = true;
  s.self_collision.thickness *=
      std::min(s.flag.width / (s.flag.cols - 1), s.flag.height / (s.flag.rows - 1)) / paper_spacing;
  return s;
}

Scene Scene::emergent() {
  Scene s = paper();
  s.name = "emergent";
  // A periodic box of 2 x 1.25 x 1 m around the flag in cells of 1/16 m (32 x 20 x 16), the pole
  // a solid of the air (multigrid pressure: fft has no solids). The pole is 1.8 cells across:
  // the air flows around it, its vortices are not resolved. What sets the cell size is the cost
  // of the grid's curl noise (docs/coupling.md): at 1/32 m (the pole 3.5 cells across) a step
  // took 170 ms against ~25 here, most of it the noise.
  const double h = 1.0 / 16.0;
  s.air.boundary = Boundary::kPeriodic;
  s.air.pressure = Pressure::kMultigrid;
  s.air.cell_size = h;
  s.air.origin = Vec3(-0.5, -1.0, -0.5);
  s.air.resolution = {32, 20, 16};
  s.air.wind = WindSchedule(Vec3(5.0, 0.0, 0.0));
  s.air.fans.clear();
  s.air.pole_obstacle = true;
  s.air.coupling = Coupling::kTwoWay;
  // Eddies of about half the flag's height, changing twice a second, 1.5 m/s on a 5 m/s wind.
  s.air.turbulence.intensity.keys = {{0.0, 1.5}};
  s.air.turbulence.length_scale.keys = {{0.0, 0.4}};
  s.air.turbulence.evolution.keys = {{0.0, 2.0}};
  // No painted waves: whatever moves the flag out of its plane comes from the air.
  s.flapping.mode = FlapMode::kOff;
  return s;
}

Scene Scene::boat() {
  Scene s;
  s.name = "boat";
  s.flag.rows = 12;
  s.flag.cols = 18;
  s.flag.width = 0.9;
  s.flag.height = 0.6;
  s.flag.origin = Vec3(0.055, 0.0, 0.0);
  s.flag.imperfection = 1e-3;
  // The mast stands on the deck at y = -2.5 m; the boat rolls +-12 degrees about its length (the
  // x axis, downwind) with a 4 s period and pitches +-5 degrees about z with a 3 s period. The two
  // are sampled every 0.125 s over their common 12 s period (piecewise linear: 2 % of the peak
  // angular velocity lost at the turning points), then played again (repeat).
  MotionSchedule& m = s.flag.pin_motion;
  m.pivot = Vec3(0.0, -2.5, 0.0);
  m.repeat = true;
  constexpr double kPi = 3.14159265358979323846;
  for (int k = 0; k <= 96; ++k) {
    const double t = 0.125 * k;
    MotionKey key;
    key.time = t;
    key.rotation = Vec3(12.0 * std::sin(2 * kPi * t / 4.0), 0.0, 5.0 * std::sin(2 * kPi * t / 3.0));
    key.translation = Vec3(0.0, 0.15 * std::sin(2 * kPi * t / 3.0), 0.0);  // heave
    m.keys.push_back(key);
  }
  s.air.model = AirModel::kUniform;
  s.air.wind = WindSchedule(Vec3(6.0, 0.0, 0.0));
  s.air.turbulence.intensity.keys = {{0.0, 0.8}};
  s.drag.model = DragModel::kTriangle;
  s.flapping.mode = FlapMode::kOff;
  s.dt = 0.01;
  return s;
}

std::vector<std::pair<std::string, std::string>> builtin_scenes() {
  return {
      {"paper",
       "Okamoto et al. §5: 8 x 11 flag on a pole, 16^3 air grid, about 2 m/s from a fan, dt = 0.01 "
       "s"},
      {"banner", "a banner hanging from its top edge in a steady 3 m/s horizontal wind"},
      {"flapping_demo",
       "Okamoto et al. §4.3 (Fig. 6): eq. 5 flapping alone, no air solver, no "
       "gravity, every mass pulled along +x"},
      {"pole_wake",
       "the paper's flag behind its pole as a solid of the air: a 2 m/s tunnel whose cells "
       "resolve the pole (8 across), eq. 5 off"},
      {"large",
       "the paper scene meshed finer: 64 x 64 flag with self-collision and eq. 5 in a 64^3 air "
       "grid (same box and fan), dt = 0.01 s"},
      {"emergent",
       "a flag that flaps with eq. 5 off: two-way coupling, curl-noise turbulence, the pole a "
       "solid of the air"},
      {"boat",
       "a flag on the mast of a boat rolling and pitching in a 6 m/s wind (flag.pin_motion "
       "moves the pole and the pins)"},
  };
}

Scene builtin_scene(const std::string& name) {
  if (name == "paper") return Scene::paper();
  if (name == "banner") return Scene::banner();
  if (name == "flapping_demo") return Scene::flapping_demo();
  if (name == "pole_wake") return Scene::pole_wake();
  if (name == "large") return Scene::large();
  if (name == "emergent") return Scene::emergent();
  if (name == "boat") return Scene::boat();
  std::string known;
  for (const auto& [n, d] : builtin_scenes()) known += (known.empty() ? "" : ", ") + n;
  throw InvalidArgument("unknown scene '" + name + "'; built-in scenes are: " + known);
}

}  // namespace flagsim

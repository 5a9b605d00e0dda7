#include "scene/scene.h"

#include "common/errors.h"

namespace flagsim {

void AirParams::validate(const std::string& p) const {
  if (model != "none" && model != "uniform" && model != "grid")
    fail_param(p + ".model", "one of 'none', 'uniform', 'grid'", "'" + model + "'");
  wind.validate(p + ".wind");
  check_nonnegative(p + ".density", density);
  if (model == "grid") FluidParams::validate(p);
}

void Scene::validate() const {
  flag.validate("flag");
  air.validate("air");
  drag.validate("drag");
  integrator.validate("integrator");
  flapping.validate("flapping");
  self_collision.validate("self_collision");
  pole.validate("pole");
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
  s.air.model = "uniform";
  s.air.wind = WindSchedule(Vec3(2.0, 0.0, 0.0));
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
  s.flag.pin = "top";
  s.pole.enabled = false;
  s.air.wind = WindSchedule(Vec3(0.0, 0.0, 3.0));
  return s;
}

std::vector<std::pair<std::string, std::string>> builtin_scenes() {
  return {
      {"paper", "Okamoto et al. §5: 8 x 11 flag on a pole in about 2 m/s of air, dt = 0.01 s"},
      {"banner", "a banner hanging from its top edge in a steady 3 m/s horizontal wind"},
  };
}

Scene builtin_scene(const std::string& name) {
  if (name == "paper") return Scene::paper();
  if (name == "banner") return Scene::banner();
  std::string known;
  for (const auto& [n, d] : builtin_scenes()) known += (known.empty() ? "" : ", ") + n;
  throw InvalidArgument("unknown scene '" + name + "'; built-in scenes are: " + known);
}

}  // namespace flagsim

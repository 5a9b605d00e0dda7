// A scene: everything a Simulation needs, as plain validated structs (SI units).
#pragma once
#include <string>
#include <utility>
#include <vector>

#include "cloth/params.h"
#include "collision/params.h"
#include "flapping/params.h"
#include "fluid/params.h"

namespace flagsim {

enum class AirModel { kNone, kUniform, kGrid };
template <>
struct EnumNames<AirModel> {
  static constexpr std::array<const char*, 3> names{"none", "uniform", "grid"};
};

/// The air the flag feels. model "none": no air at all (no drag stage); "uniform": the wind
/// schedule everywhere, analytic (no grid is built); "grid": Stable Fluids on the grid described
/// by the FluidParams fields, with `wind` as its mean flow (periodic) or inflow (tunnel).
struct AirParams : FluidParams {
  AirModel model = AirModel::kUniform;
  /// The scene's pole is a no-slip solid of the air too (a capped cylinder as pole.* gives it),
  /// so the air flows around it and sheds its wake. Needs model "grid" and an enabled pole.
  bool pole_obstacle = false;
  /// With model "grid" and flagsim on two threads or more (set_num_threads), the air's step for
  /// the next step runs on a thread of its own beside the cloth's step (one-way coupling: the air
  /// never reads the flag), each with its loops on one thread; the same bits as the serial order
  /// (docs/design.md "Air and cloth side by side"). false: one after the other, each with every
  /// thread in its loops (better when one side dominates, e.g. a large grid and a small flag).
  bool pipeline = true;
  /// The pole as an obstacle of the air (pole.radius, height, base; axis +y; no-slip).
  static ObstacleParams pole_solid(const PoleParams& pole);
  AirParams() { wind = WindSchedule(Vec3(2.0, 0.0, 0.0)); }
  void validate(const std::string& prefix = "air") const;
};

/// One flag of a scene with several (TOML [[flags]]): its cloth and fabric, pins, pole, drag,
/// flapping and integrator. The flags of a scene share its air, gravity, dt and self_collision.
struct FlagSpec {
  FlagParams flag;
  DragParams drag;
  IntegratorParams integrator;
  FlappingParams flapping;
  PoleParams pole;
};

struct Scene {
  std::string name = "custom";
  FlagParams flag;
  AirParams air;
  DragParams drag;
  IntegratorParams integrator;
  FlappingParams flapping;
  SelfCollisionParams self_collision;
  PoleParams pole;
  Vec3 gravity{0.0, -9.81, 0.0};  ///< m/s^2
  double dt = 0.01;               ///< s, one Simulation step
  /// Flags 1, 2, ... of a scene with several; flag 0 is the fields flag, drag, integrator,
  /// flapping and pole above (so a one-flag scene is exactly what it always was).
  std::vector<FlagSpec> more_flags;

  /// Every flag, flag 0 first (copies).
  std::vector<FlagSpec> flags() const;
  /// Replace every flag: flags[0] into the fields above, the rest into more_flags (>= 1 flag).
  void set_flags(const std::vector<FlagSpec>& flags);
  int num_flags() const { return 1 + int(more_flags.size()); }
  /// Flag i alone: this scene with flag i's parts in the fields above and no more_flags.
  Scene flag_scene(int i) const;

  /// Throws InvalidArgument naming the first bad parameter ("flag.rows should be >= 2, got 1";
  /// with several flags "flags[2].width ..." and "flags[2].pole.radius ...").
  void validate() const;

  /// Paper §5: flag of 8 x 11 masses, 0.54 m tall, dt = 0.01 s, air about 2 m/s along +x on a
  /// 16^3 Stable Fluids grid, made non-uniform by a fan region upstream of the flag.
  static Scene paper();
  /// A banner hanging from its top edge in a horizontal wind along +z (equilibrium-angle check).
  static Scene banner();
  /// Paper §4.3, Fig. 6: the flapping alone. No air solver and no drag (a 2 m/s uniform wind of
  /// zero density only sets u_p), no gravity; instead every mass is pulled along +x (a uniform
  /// 9.81 m/s^2 field along the flag); eq. 5 "displace" on a 16 x 24 flag on its pole.
  static Scene flapping_demo();
  /// The paper's flag behind its pole, the pole a solid of the air (air.pole_obstacle): a tunnel
  /// at 2 m/s whose cells resolve the pole (kWakeCellsAcross across), eq. 5 off (issue 23).
  static Scene pole_wake();
  /// The paper scene meshed finer, what real time at a detailed size means: a 64 x 64 flag with
  /// self-collision (contact thickness at the paper's ratio to the spacing) and eq. 5 in a 64^3
  /// air grid over the same box with the same fan, dt = 0.01 s (real time: 100 steps/s).
  static Scene large();
};

/// Built-in scenes: (name, one-line description), in display order.
std::vector<std::pair<std::string, std::string>> builtin_scenes();
/// The built-in scene `name`; InvalidArgument listing the known names otherwise.
Scene builtin_scene(const std::string& name);

}  // namespace flagsim

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

/// one_way: the air pushes the flag and never feels it (the paper); two_way: the drag each mass
/// receives in a step goes back into the air grid with the opposite sign in that step's air step;
/// two_way_lagged: the same reaction, taken by the next step's air step instead, so that the air
/// can step beside the cloth (air.pipeline): a partitioned scheme one step further behind, not the
/// bits of two_way (docs/coupling.md "Two-way beside the cloth").
enum class Coupling { kOneWay, kTwoWay, kTwoWayLagged };
template <>
struct EnumNames<Coupling> {
  static constexpr std::array<const char*, 3> names{"one_way", "two_way", "two_way_lagged"};
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
  /// never reads the flag; "two_way_lagged": it takes the reaction of the step before), each with
  /// its loops on one thread; the same bits as the serial order (docs/design.md "Air and cloth
  /// side by side"). false: one after the other, each with every thread in its loops (better when
  /// one side dominates, e.g. a large grid and a small flag). "two_way" is never pipelined.
  bool pipeline = true;
  /// "two_way": the flag's drag reaction is spread back into the grid at every step, with the
  /// weights the sampling uses, so air plus flag conserve momentum; "two_way_lagged": the same,
  /// a step later (the air beside the cloth). Needs model "grid".
  Coupling coupling = Coupling::kOneWay;
  /// Any two-way scheme: the flag's drag goes back into the grid.
  bool two_way() const { return coupling != Coupling::kOneWay; }
  /// The pole as an obstacle of the air (pole.radius, height, base; axis +y; no-slip).
  static ObstacleParams pole_solid(const PoleParams& pole);
  AirParams() { wind = WindSchedule(Vec3(2.0, 0.0, 0.0)); }
  void validate(const std::string& prefix = "air") const;
};

/// A solid of the scene: one description for the air (its cells solid, as air.obstacles) and the
/// cloth (collided with, csrc/collision/solids.h). A keyframed solid (motion) is cloth-only: the
/// air's solids are static.
struct SolidParams : ObstacleParams {
  bool air = true;           ///< a solid of the air grid (air.model "grid"; static only)
  bool cloth = true;         ///< the flag collides with it
  double thickness = 0.005;  ///< m, the distance the flag's vertices keep from its surface
  double friction = 0.3;     ///< Coulomb coefficient of the cloth's contact
  MotionSchedule motion;     ///< keyframed rigid motion (cloth only); empty = at rest
  void validate(const std::string& prefix) const;
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
  std::vector<SolidParams> solids;  ///< TOML [[solids]], every flag collides with them
  Vec3 gravity{0.0, -9.81, 0.0};    ///< m/s^2
  double dt = 0.01;                 ///< s, one Simulation step
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
  /// A flag that flaps with eq. 5 off (issue 24): two-way coupling, curl-noise turbulence and
  /// the pole as a solid of the air, on a periodic grid around the paper's flag.
  static Scene emergent();
  /// A flag on the mast of a boat rolling and pitching in a 6 m/s wind: flag.pin_motion moves the
  /// pole and the pins together (roll about the boat's length, pitch across it, at the deck).
  static Scene boat();
};

/// Built-in scenes: (name, one-line description), in display order.
std::vector<std::pair<std::string, std::string>> builtin_scenes();
/// The built-in scene `name`; InvalidArgument listing the known names otherwise.
Scene builtin_scene(const std::string& name);

}  // namespace flagsim

// Solids in the air: static obstacles as solid cells, the tunnel's walls and inflow profile, the
// conditions they put on the velocity, the viscous step beside them and the forces on them.
//
// A cell is solid when its centre lies inside an obstacle (the first that contains it owns it).
// Faces of each velocity component then fall into three kinds:
//   open:   neither neighbouring cell solid, an unknown of the air;
//   held:   exactly one neighbouring cell solid: the solid's surface, normal velocity 0;
//   inside: both neighbouring cells solid: velocity 0 (no-slip) or ignored (free-slip).
// Held and inside faces are 0 after every stage that writes the field, so no flux crosses a solid
// face (to round-off: it is exactly 0), and the pressure solve sees a solid cell as no unknown
// with zero-flux faces to it (Neumann), csrc/fluid/poisson.h.
//
// No-slip puts the wall halfway between the last open node and its mirror inside the solid:
// the viscous term reads the mirror as -u (Bridson 2nd ed. §8.2), a free-slip wall as +u.
#pragma once
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "fluid/grid.h"
#include "fluid/params.h"

namespace flagsim {

/// Cells across a solid below which the air cannot resolve the wake it sheds (measured on the
/// cylinder of flagsim study accuracy: docs/accuracy.md); a thinner solid gets a warning.
constexpr double kWakeCellsAcross = 8;

/// kDomain: a node the tunnel holds (the inflow face, the walls' normal velocity), which keeps the
/// value the boundary stage writes.
enum class FaceKind : uint8_t { kOpen = 0, kHeld = 1, kInside = 2, kDomain = 3 };

/// Which cells and faces are solid, which obstacle owns them, and the walls; built once per set of
/// obstacles (allocation only in build). Without obstacles and no-slip walls nothing is allocated
/// (owner, solid and face stay empty).
struct SolidMap {
  GridGeometry geo;
  std::vector<uint16_t> owner;                  ///< per cell: 0 = air, 1 + obstacle index
  AlignedVector<uint8_t> solid;                 ///< per cell: 1 = solid (the pressure solve's mask)
  std::array<AlignedVector<uint8_t>, 3> face;   ///< per node of each component: FaceKind
  std::array<std::vector<uint32_t>, 3> closed;  ///< held and inside nodes of each component
  std::vector<Slip> slip;                       ///< per obstacle
  std::vector<long> cell_count;                 ///< per obstacle: solid cells it owns
  /// Tunnel walls: slip of side hi (0 = min, 1 = max) of axis d (only d = 1, 2 are walls).
  Slip wall[3][2] = {{Slip::kFreeSlip, Slip::kFreeSlip},
                     {Slip::kFreeSlip, Slip::kFreeSlip},
                     {Slip::kFreeSlip, Slip::kFreeSlip}};
  bool any_solid = false;    ///< at least one solid cell
  bool any_no_slip = false;  ///< a no-slip wall or obstacle: the viscous step reads ghosts

  void build(const GridGeometry& g, const FluidParams& p);
  /// Owner of cell (i, j, k), wrapping periodic axes; 0 (air) outside a bounded grid.
  uint16_t cell_owner(int i, int j, int k) const;
  /// Human-readable warnings: obstacles thinner than kWakeCellsAcross cells, or covering none.
  std::vector<std::string> warnings(const std::vector<ObstacleParams>& obstacles) const;
};

/// Sets every held and inside node to 0. No allocation.
template <class T>
void enforce_solids(const SolidMap& map, MacGrid<T>& u);

/// set_mean_flow over the air: shifts each component's open nodes so that their mean is
/// target[c] (the closed ones stay 0). Periodic grids with solids.
template <class T>
void set_air_mean_flow(const SolidMap& map, const Vec3& target, MacGrid<T>& u);

/// Per (j, k) of the x-min face: the inflow's shape factor, mean 1 (all 1 for "uniform"; for
/// "parabolic", 6 s (1 - s) averaged over each cell across every axis whose walls are both
/// no-slip, so the discrete flux equals the uniform one exactly). ny * nz values.
std::vector<double> inflow_weights(const GridGeometry& g, const FluidParams& p);

/// The inflow's shape factor at a point (cell units, p = (x - origin) / h): the parabola at its
/// y and z (clamped to the walls), 1 for "uniform".
struct InflowShape {
  bool parabolic[3] = {false, false, false};
  int n[3] = {1, 1, 1};
  double at(const double p[3]) const {
    double w = 1;
    for (int d = 1; d < 3; ++d)
      if (parabolic[d]) {
        double s = p[d] / n[d];
        s = s < 0 ? 0 : (s > 1 ? 1 : s);
        w *= 6 * s * (1 - s);
      }
    return w;
  }
};
InflowShape inflow_shape(const GridGeometry& g, const FluidParams& p);

/// Explicit viscous step beside walls and solids: u <- u + nu dt lap u on open nodes, with
/// substeps so that nu dt_sub / h^2 <= 0.15 (explicit diffusion is stable below 1/6 in 3-D).
/// Neighbour rules: open and held nodes by their values (held ones hold the wall's velocity);
/// inside nodes and beyond a y or z wall by the mirror (-u no-slip, +u free-slip); beyond the x
/// ends zero-gradient. Held, inside and domain nodes keep their values. scratch: u's geometry.
/// Returns the substep count. No allocation. The map must hold solids or no-slip walls (without
/// them nothing is built, and the implicit solves serve).
template <class T>
int diffuse_explicit(const SolidMap& map, double nu_dt, MacGrid<T>& u, MacGrid<T>& scratch);

/// The force the air exerts on obstacle `index` (N): pressure rho phi / dt on each face between
/// one of its cells and an air cell (extrapolated to the face from the two air cells beyond it:
/// a linear pressure gives Archimedes' force exactly), plus, when the obstacle is no-slip, the
/// viscous shear rho nu u_t / (h / 2) on each open tangential node whose mirror lies inside it.
/// phi: the last projection's potential dt p / rho (nx*ny*nz, m^2/s).
template <class T>
Vec3 obstacle_force(const SolidMap& map, int index, const MacGrid<T>& u, const T* phi, double dt,
                    double rho, double nu);

}  // namespace flagsim

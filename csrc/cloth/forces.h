// Cloth force kernels (paper §3): gravity, drag (eq. 3 and two named alternatives), springs and
// spring damping (eq. 4), and their Jacobians for the implicit integrator (Baraff-Witkin 1998).
// All forces are ADDED to `f` (N x 3, N). x, v, u_air are (N x 3): positions m, velocities m/s,
// air velocity at each mass m/s.
#pragma once
#include <vector>

#include "cloth/params.h"
#include "cloth/topology.h"
#include "common/types.h"

namespace flagsim {

/// f_i += m_i g.
void add_gravity(const ClothTopology& topo, const Vec3& g, MatX3& f);

/// Spring (k_s unit(p2-p1) dl) and damping (k_d (v2 - v1)) forces, eq. 4, gathered per vertex.
void add_spring_forces(const ClothTopology& topo, const MatX3& x, const MatX3& v, MatX3& f);

/// Drag, by drag.model: "paper" eq. 3 with S = the vertex's lumped rest area, "relative",
/// "triangle" (current triangle area and normal; each vertex takes a third). rho in kg/m^3.
void add_drag(const ClothTopology& topo, const DragParams& drag, double rho, const MatX3& x,
              const MatX3& v, const MatX3& u_air, MatX3& f);

/// A symmetric 3x3 block a I + e e^T in 4 doubles.
struct SpringBlock {
  double a = 0;
  Vec3 e = Vec3::Zero();
  Vec3 apply(const Vec3& p) const { return a * p + e * e.dot(p); }
  Mat3 matrix() const { return a * Mat3::Identity() + e * e.transpose(); }
};

/// Per spring s = (i, j): K_s = d f_i / d x_j = k [(1 - L/l)(I - d d^T) + d d^T], d = unit(x_j -
/// x_i), l = |x_j - x_i| (Baraff-Witkin 1998 §5), as the block k (1 - L/l) I + k (L/l) d d^T (e =
/// sqrt(k L/l) d). d f_i/d x_i = -K_s. With `clamp_compression`, the factor (1 - L/l) is clamped at
/// 0 so every K_s is positive semi-definite (Choi-Ko 2002), which keeps the implicit system SPD
/// (the solver's form); without, it is the exact Jacobian. Writes K (S).
void spring_position_jacobians(const ClothTopology& topo, const MatX3& x, bool clamp_compression,
                               std::vector<SpringBlock>& K);

/// out = (d f / d x) p with the compact K (N x 3).
void apply_position_jacobian(const ClothTopology& topo, const std::vector<SpringBlock>& K,
                             const MatX3& p, MatX3& out);

/// Velocity Jacobians of drag. Per-vertex models ("paper", "relative"): Dv[i] = -d f_i / d v_i
/// (positive semi-definite). For "paper" the stabilised form c S ((|v| + |u|) I + v v^T/|v|) is
/// used (see forces.cpp); pass u = 0 to get the exact Jacobian. "triangle": Jw[t] = d F_t / d w (w
/// = mean air - mean vertex velocity of triangle t), and d f_i / d v_m = -Jw[t] / 9 for i, m in t.
/// Resizes Dv (N) and Jw (T or 0).
void drag_velocity_jacobians(const ClothTopology& topo, const DragParams& drag, double rho,
                             const MatX3& x, const MatX3& v, const MatX3& u_air,
                             std::vector<Mat3>& Dv, std::vector<Mat3>& Jw);

/// out = (d f / d v) p: spring damping and drag.
void apply_velocity_jacobian(const ClothTopology& topo, const std::vector<Mat3>& Dv,
                             const std::vector<Mat3>& Jw, const MatX3& p, MatX3& out);

/// Largest stable step of symplectic Euler for the current state: h = 2 / (g + sqrt(g^2 + l)),
/// with l a Gershgorin bound on the largest eigenvalue of M^-1 K and g on half that of M^-1 C
/// (springs, spring damping and drag slope), from the damped oscillator's stability condition
/// l h^2 + 2 g h < 4. Returns +inf when nothing constrains the step.
double stable_step_estimate(const ClothTopology& topo, const DragParams& drag, double rho,
                            bool has_drag, const MatX3& x, const MatX3& v, const MatX3& u_air);

struct ClothEnergy {
  double kinetic = 0;                                          ///< J
  double gravity = 0;                                          ///< J, -sum m g.x
  double spring = 0;                                           ///< J, sum 1/2 k (l - L)^2
  double total() const { return kinetic + gravity + spring; }  ///< J
};
/// Each sum runs over fixed chunks of vertices or springs (the mesh sets them, never the thread
/// count), their partial sums added in chunk order: the same bits on any thread count.
ClothEnergy cloth_energy(const ClothTopology& topo, const Vec3& g, const MatX3& x, const MatX3& v);
/// kinetic + gravity + spring of cloth_energy, J: the energy the ledger balances
/// (scene/simulation.h, EnergyLedger).
double total_energy(const ClothTopology& topo, const Vec3& g, const MatX3& x, const MatX3& v);

/// Largest spring strain (l - L) / L and the first spring index where it occurs (springs with
/// L > 0); 0 (index -1) when none is above 0. A NaN strain is returned as NaN (its first spring).
double max_strain(const ClothTopology& topo, const MatX3& x, Index* worst_spring = nullptr);
/// cloth_energy(topo, g, x, v) and, into strain, max_strain(topo, x, worst_spring) of the same
/// positions in one pass over the springs: the same bits as the two calls.
ClothEnergy cloth_energy_and_max_strain(const ClothTopology& topo, const Vec3& g, const MatX3& x,
                                        const MatX3& v, double& strain,
                                        Index* worst_spring = nullptr);

}  // namespace flagsim

#include "flapping/flap_stage.h"

#include <limits>

namespace flagsim {

FlapStage::FlapStage(const ClothTopology& topo, const FlappingParams& p)
    : p_(p), noise_(p.seed), xy_(topo.uv) {  // x = u (0 at the pole edge), y = v
  const Index N = topo.num_vertices();
  L_.resize(N);
  for (Index i = 0; i < N; ++i)
    L_[i] = topo.pinned(i)               ? 0.0
            : topo.tether_anchor[i] >= 0 ? topo.tether_length[i]
                                         : std::numeric_limits<double>::infinity();
  z_.setZero(N);
  applied_.setZero(N);
  start_.setZero(N);
  before_.setZero(N);
  after_.setZero(N);
}

// The change of z over the piece, dz, as a drift dz n / h that the integrator adds to the
// positions (ForceSet::drift): the springs answer the displaced cloth inside the solve, while
// damping and drag see only the cloth's own velocity. Moving the positions after the solve
// instead stored whatever the wave stretched in the springs: at k_s = 1e6 N/m, 5e4 J in a 66 g
// flag (docs/energy.md).
void FlapStage::drift(const ClothTopology& topo, const MatX3& n, double u_p, double t1, double h,
                      MatX3& drift) {
  flapping_displacement(noise_, xy_, L_, u_p, t1, p_, z_);
  for (Index i = 0; i < topo.num_vertices(); ++i)
    drift.row(i) =
        topo.pinned(i) ? Vec3::Zero().transpose() : (((z_[i] - applied_[i]) / h) * n.row(i)).eval();
}

void FlapStage::force(const ClothTopology& topo, const MatX3& n, double u_p, double t1, double h,
                      MatX3& force) {
  flapping_displacement(noise_, xy_, L_, u_p, t1, p_, z_);
  flapping_displacement(noise_, xy_, L_, u_p, t1 - h, p_, before_);
  flapping_displacement(noise_, xy_, L_, u_p, t1 + h, p_, after_);
  for (Index i = 0; i < topo.num_vertices(); ++i) {
    const double a = (after_[i] - 2 * z_[i] + before_[i]) / (h * h);
    force.row(i) =
        topo.pinned(i) ? Vec3::Zero().transpose() : ((topo.mass[i] * a) * n.row(i)).eval();
  }
}

void FlapStage::displace(const MatX3& x, const MatX3& n, double u_p, double t, MatX3& render_x) {
  flapping_displacement(noise_, xy_, L_, u_p, t, p_, z_);
  for (Index i = 0; i < x.rows(); ++i) render_x.row(i) = x.row(i) + z_[i] * n.row(i);
}

MatX3 FlapStage::pole_edge_points(const ClothTopology& topo) {
  MatX3 p(topo.rows, 3);
  for (int r = 0; r < topo.rows; ++r) p.row(r) = topo.rest_positions.row(r * topo.cols);
  return p;
}

}  // namespace flagsim

// Curl-noise turbulence (Bridson, Hourihan, Nordenstam, SIGGRAPH 2007): u = curl psi, psi three
// channels of 3-D gradient noise (Perlin 2002's quintic fade and 12 edge gradients, picked by a
// counter-based hash instead of a permutation table), evolving in time by blending noise slices,
// and ramped to 0 near solids (Bridson's eq. 3 ramp of the distance) so that no air flows into a
// solid. Evaluated analytically at points (the uniform wind), or as a discrete curl of psi on the
// edges of a MAC grid (exactly divergence-free to round-off: the divergence of a discrete curl
// telescopes). Parameters: TurbulenceParams (fluid/params.h).
#pragma once
#include <array>
#include <cstdint>
#include <vector>

#include "common/types.h"
#include "fluid/grid.h"
#include "fluid/params.h"

namespace flagsim {

/// Signed distance (m) from x to the obstacle's surface (negative inside) and its gradient (unit).
double obstacle_distance(const ObstacleParams& o, const Vec3& x, Vec3* gradient);

/// Bridson 2007's ramp: 15/8 r - 10/8 r^3 + 3/8 r^5 on [0, 1], 0 below, 1 above; its derivative.
double noise_ramp(double r, double* derivative);

/// The two noise slices psi blends, at the edges of one grid, kept from step to step (owned by
/// the grid's solver, filled by CurlNoise::potential_on_edges). psi_c = A L [(1 - b) n_{c,k} +
/// b n_{c,k+1}](x / L) alpha(x): the slices n change only when k = floor(phase) or L does (for
/// a constant L once every 1 / evolution seconds; a step then evaluates one slice, or none,
/// where it evaluated two), the ramp alpha only when the solids do; within a slice a step is a
/// blend of stored values. Same bits as evaluating both slices every step.
struct EdgeNoise {
  /// Size the arrays for the edges of geo (the ramp's only with solids) and forget the slices.
  /// Allocates only when the sizes change (construction, new solids), never inside a step.
  void reset(const GridGeometry& geo, bool ramped);

  bool valid = false;  ///< n0, n1 hold slices `slice`, `slice + 1` at length `length`
  bool ramp_ready = false;
  std::int64_t slice = 0;
  double length = 0;  ///< m, L of x / L
  // per edge of axis a, edge_shape(geo, a): n_{a,k}(x / L), n_{a,k+1}(x / L) and alpha(x)
  std::array<AlignedVector<double>, 3> n0, n1, ramp;
};

class CurlNoise {
 public:
  /// `solids`: where psi ramps to 0 (copied). Parameters validated by the caller.
  CurlNoise(const TurbulenceParams& params, std::vector<ObstacleParams> solids);

  bool enabled() const { return enabled_; }
  /// Whether psi ramps to 0 near solids (then the grid keeps alpha per edge, EdgeNoise::ramp).
  bool ramped() const { return !solids_.empty(); }
  /// Velocity u = curl psi at x (m) and time t (s), m/s; zero when disabled.
  Vec3 velocity(const Vec3& x, double t) const;
  /// Component `axis` of the ramped potential psi at x and t, m^2/s.
  double potential(int axis, const Vec3& x, double t) const;
  /// psi at the edges of `geo` at time t into edge arrays psi[a] (edge_shape(geo, a)), from the
  /// noise slices kept in `slices` (reset for geo and these solids; updated when t needs others).
  template <class T>
  void potential_on_edges(const GridGeometry& geo, double t, EdgeNoise& slices,
                          std::array<AlignedVector<T>, 3>& psi) const;

 private:
  struct Frame {  // the schedules at one time
    double intensity, length, phase;
  };
  Frame frame(double t) const;
  /// Unramped psi (3 channels, m^2/s) and its Jacobian J(c, d) = d psi_c / d x_d at x.
  void raw(const Vec3& x, const Frame& f, Vec3& psi, Mat3* jacobian) const;
  /// Evaluates the ramp and the slices `slices` lacks for slice k and length L.
  void update_slices(const GridGeometry& geo, std::int64_t k, double length,
                     EdgeNoise& slices) const;
  /// Ramp factor alpha(x) and its gradient.
  double ramp(const Vec3& x, Vec3* gradient) const;

  TurbulenceParams p_;
  std::vector<ObstacleParams> solids_;
  bool enabled_ = false;
};

/// Shape of the edge array of axis a (edges along a): n[a] cells along a, and the nodes of the
/// other two axes (n + 1, or n when periodic).
Shape3 edge_shape(const GridGeometry& geo, int a);
/// World position of edge (i, j, k) of axis a: its midpoint.
Vec3 edge_position(const GridGeometry& geo, int a, int i, int j, int k);

/// u += curl (psi1 - psi0) on every face of u (discrete curl over the face's four edges, /h).
template <class T>
void add_discrete_curl(const std::array<AlignedVector<T>, 3>& psi1,
                       const std::array<AlignedVector<T>, 3>& psi0, MacGrid<T>& u);

}  // namespace flagsim

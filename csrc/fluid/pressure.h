// Pressure projection and viscosity on the MAC grid (Stam 1999 §2.3-2.4; Stam 2001 for the
// periodic FFT form; Bridson 2nd ed. ch. 5 for the bounded form).
//
// With phi = dt p / rho (m^2/s), projection is u <- u - grad phi where lap phi = div u, using the
// MAC operators: div at cells, grad at faces, lap = div grad (7 points). Boundaries of the
// bounded (tunnel) grid: the x-min (inflow) face and the y and z walls hold their normal velocity
// (Neumann for phi), the x-max face is open with p = 0 in the ghost cell beyond (Dirichlet).
#pragma once
#include <complex>
#include <memory>

#include "fluid/grid.h"
#include "fluid/poisson.h"

namespace flagsim {

/// Cell divergence of the face field (1/s). div: nx*ny*nz, C order, each (i, j) row of nz values
/// starting row_stride values after the previous one (0: nz, contiguous). scale != 0: div =
/// T(scale * T(div u)) in the same pass, the bits of scaling it afterwards (the pressure solve's
/// right-hand side -h^2 div u, unit m).
template <class T>
void divergence(const MacGrid<T>& u, T* div, int row_stride = 0, double scale = 0);

/// K-operator of the pressure solve for this grid (periodic, or the tunnel conditions above).
Laplace7 pressure_operator(const GridGeometry& geo);

/// Operator of the implicit diffusion of component c: periodic, or for the tunnel grid the held
/// faces (inflow, wall normals) fixed and zero-gradient elsewhere.
Laplace7 diffusion_operator(const GridGeometry& geo, int c);

/// u <- u - grad phi on every face that is not held (phi: nx*ny*nz, m^2/s, rows row_stride
/// values apart as in divergence).
template <class T>
void subtract_gradient(const T* phi, MacGrid<T>& u, int row_stride = 0);

/// subtract_gradient on a periodic grid (every face), fused with the step's finiteness check:
/// returns true when every new value is finite.
template <class T>
bool subtract_gradient_periodic(const T* phi, int row_stride, MacGrid<T>& u);

/// Tunnel boundary values: u = inflow.x (times weights[j * nz + k], the inflow profile, when
/// weights is not null) on the x-min face, 0 normal velocity on the y and z walls.
template <class T>
void apply_tunnel_boundary(const Vec3& inflow, const double* weights, MacGrid<T>& u);

/// Adds (target - mean) to each component of a periodic grid, so its k = 0 mode is `target`.
template <class T>
void set_mean_flow(const Vec3& target, MacGrid<T>& u);

/// Periodic projection (and spectral implicit diffusion) with FFTW: the discrete Poisson problem
/// is diagonal in Fourier space, eigenvalues lambda(k) = sum_d (2 cos(2 pi k_d / n_d) - 2) / h^2,
/// so dividing by them solves it to round-off. Plans are made once at construction (FFTW_ESTIMATE:
/// deterministic), buffers allocated once. Throws MissingFeature when built without FFTW.
template <class T>
class FftProjector {
 public:
  explicit FftProjector(const GridGeometry& geo);
  ~FftProjector();
  FftProjector(const FftProjector&) = delete;
  FftProjector& operator=(const FftProjector&) = delete;

  /// u <- P u (no diffusion): one r2c of div u, divide, one c2r, subtract the gradient. The
  /// transforms run in place in the first spectrum's buffer (div u, then the potential, in rows
  /// padded to 2 (nz/2 + 1) values: 14 % faster than out of place at 128^3). The k = 0 mode is
  /// untouched. Returns true when every new value is finite (checked as the gradient is
  /// subtracted), false when one is not.
  bool project(MacGrid<T>& u);
  /// u <- P (I - nu dt lap)^-1 u, all in Fourier space (3 r2c + 3 c2r). When mean != nullptr the
  /// k = 0 mode is set to *mean (m/s), otherwise left as it is. Returns true when the new u is
  /// certainly finite (its modes, checked in the spectral pass, are bounded far below overflow);
  /// false says nothing either way: the caller checks u itself.
  bool diffuse_and_project(MacGrid<T>& u, double nu_dt, const Vec3* mean);
  /// Room for nx*ny*nz values in rows of nz, `stride` (set, >= nz) apart: the first spectrum's
  /// buffer, free between projections (the fluid's divergence readouts use it).
  T* scratch(int& stride) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace flagsim

// Paper eq. 5: the noise-driven flapping wave, evaluated per vertex.
//
//   z = u_p A(L) f_n( k (x - v t - a (1 - y) y) )                                 (paper eq. 5)
//
// times a fade-in over the first `ramp` seconds (flapping_fade_in; ramp = 0: none).
//
// Normalisation (paper §4.2 leaves it open): x and y are the vertex's rest texture coordinates,
//   x = distance along the flag away from the pole / flag length   (0 at the pole edge, 1 at the
//   fly) y = distance across the flag / flag height                      (0 and 1 at the top and
//   bottom)
// so y (1 - y) peaks (1/4) mid-edge and the wave front x = v t + a (1 - y) y + const is a parabola
// leading at the middle of the pole edge, as observed in paper §4.1. v is in flag lengths per
// second, a in flag lengths, k = frequency is noise lattice cells per flag length, f_n =
// Perlin1D(seed). The ramp A(L) (paper: "rises with L, constant once L >= L_max") is the C1
// smoothstep
//   A(L) = amplitude * S(min(L / l_max, 1)),  S(u) = 3u^2 - 2u^3,
// so pinned vertices (L = 0) do not move and A has no kink at L = l_max.
// z is along the vertex normal, in metres: amplitude is metres per m/s of u_p.
#pragma once
#include "common/types.h"
#include "flapping/params.h"
#include "flapping/perlin.h"

namespace flagsim {

/// A(L), m per m/s. L: distance to the nearest pinned vertex, m (>= 0).
double flapping_ramp(double L, const FlappingParams& p);

/// The fade-in S(min(t / ramp, 1)) (1 when ramp = 0) that multiplies z: a flat flag at t = 0
/// grows its wave over `ramp` seconds. The paper starts at full amplitude; a start from the flat
/// rest shape in one step is a jump of up to amplitude x u_p, which stiff springs answer with
/// energy far beyond the wave's own (docs/energy.md).
double flapping_fade_in(double t, const FlappingParams& p);

/// Eq. 5 for every vertex.
/// noise  the f_n of the scene (Perlin1D(p.seed), built once)
/// xy     N x 2 normalised (x, y) per vertex, see above
/// L      N distances to the nearest pinned vertex, m
/// u_p    representative air speed around the pole, m/s
/// t      time, s
/// z      N out: displacement along the normal, m (resized only if its size differs)
void flapping_displacement(const Perlin1D& noise, const MatX2& xy, const VecX& L, double u_p,
                           double t, const FlappingParams& p, VecX& z);

}  // namespace flagsim

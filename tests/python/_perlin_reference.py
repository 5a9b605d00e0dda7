"""The noise and eq. 5 written out from their definitions (csrc/flapping/perlin.h, flapping.h),
independently of flagsim, for the tests to compare against."""

import numpy as np

MASK64 = (1 << 64) - 1


def reference_permutation(seed):
    """perlin_permutation() as documented in csrc/flapping/perlin.h: Fisher-Yates driven by
    splitmix64 whose state starts at the seed."""
    perm = list(range(256))
    state = seed
    for k in range(255, 0, -1):
        state = (state + 0x9E3779B97F4A7C15) & MASK64
        z = state
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK64
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK64
        z ^= z >> 31
        j = z % (k + 1)
        perm[k], perm[j] = perm[j], perm[k]
    return perm


def reference_noise(x, seed):
    perm = reference_permutation(seed)

    def grad(i):
        h = perm[i % 256]
        return (-1.0 if h & 1 else 1.0) * (1.0 - 0.25 * ((h >> 1) & 3))

    out = []
    for xi in np.ravel(x):
        i = int(np.floor(xi))
        f = xi - i
        s = f * f * f * (f * (f * 6 - 15) + 10)
        out.append(2 * ((1 - s) * grad(i) * f + s * grad(i + 1) * (f - 1)))
    return np.array(out).reshape(np.shape(x))


def reference_ramp(L, amplitude, l_max):
    """A(L) of flapping.h: amplitude * S(min(L / l_max, 1)), S(u) = 3u^2 - 2u^3."""
    u = np.minimum(np.asarray(L, dtype=float) / l_max, 1.0)
    return amplitude * (3 * u**2 - 2 * u**3)


def reference_eq5(x, y, L, u_p, t, p):
    """Paper eq. 5 per vertex with a FlappingParams-like p."""
    phase = p.frequency * (x - p.speed * t - p.parabola * (1 - y) * y)
    u = min(t / p.ramp, 1.0) if p.ramp > 0 else 1.0  # the fade-in, a smoothstep in time
    fade = u * u * (3 - 2 * u)
    return fade * u_p * reference_ramp(L, p.amplitude, p.l_max) * reference_noise(phase, p.seed)

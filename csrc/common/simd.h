// Short vectors for the few kernels written out by hand (periodic advection, the spectral
// projection): GCC and Clang generic vectors, 16 bytes on any target (SSE2 on x86-64, NEON on
// arm64) and 32 bytes inside functions compiled for AVX, chosen once at run time
// (vector_bytes()). Other compilers get the kernels' scalar loops.
//
// A kernel is one template over the lane type, instantiated for scalars, 16-byte vectors and, in
// a FLAGSIM_TARGET_AVX function, 32-byte vectors. AVX without FMA cannot contract a * b + c, so
// every width does the same operations per lane and gives the same bits (tests compare widths).
#pragma once
#include <cstring>
#include <type_traits>

namespace flagsim {

#if defined(__GNUC__)
// GCC notes that a 32-byte vector passed by value outside AVX code would change the ABI. The
// helpers here are always inlined into FLAGSIM_TARGET_AVX functions, so no call crosses that line.
#pragma GCC diagnostic ignored "-Wpsabi"
#define FLAGSIM_HAVE_VECTORS 1
#define FLAGSIM_INLINE inline __attribute__((always_inline))
// A lambda always inlined into its caller (a lambda does not inherit the caller's target("avx")):
// [&](int k) FLAGSIM_INLINE_LAMBDA { ... }.
#define FLAGSIM_INLINE_LAMBDA __attribute__((always_inline))
#if defined(__x86_64__) || defined(__i386__)
#define FLAGSIM_HAVE_AVX_DISPATCH 1
#define FLAGSIM_TARGET_AVX __attribute__((target("avx")))
#endif

template <class T>
struct Lanes16 {
  static constexpr int W = 16 / int(sizeof(T));
  typedef T V __attribute__((vector_size(16)));
};
template <class T>
struct Lanes32 {
  static constexpr int W = 32 / int(sizeof(T));
  typedef T V __attribute__((vector_size(32)));
};
#else
#define FLAGSIM_INLINE inline
#define FLAGSIM_INLINE_LAMBDA
#endif

/// The narrow lane type a kernel runs on without AVX: 16-byte vectors of T where the compiler has
/// generic vectors, else void (the kernels' scalar loops).
#ifdef FLAGSIM_HAVE_VECTORS
template <class T>
using NarrowLanes = Lanes16<T>;
#else
template <class T>
using NarrowLanes = void;
#endif

/// *p as a scalar S == T, or the vector S of T loaded (unaligned) from p.
template <class S, class T>
FLAGSIM_INLINE S load_lanes(const T* p) {
  if constexpr (std::is_same<S, T>::value) {
    return *p;
  } else {
    S v;
    std::memcpy(&v, p, sizeof(S));
    return v;
  }
}

template <class S, class T>
FLAGSIM_INLINE void store_lanes(T* p, const S& v) {
  if constexpr (std::is_same<S, T>::value)
    *p = v;
  else
    std::memcpy(p, &v, sizeof(S));
}

/// The vector width (bytes) the hand-written kernels use: 32 where the CPU has AVX (x86-64,
/// GCC/Clang), else 16 (0 without generic vectors). force > 0 caps it until called with 0 (tests
/// compare the widths); the default argument only reads it.
int vector_bytes(int force = -1);

}  // namespace flagsim

// Short vectors for the few kernels written out by hand (periodic advection, the spectral
// projection): GCC and Clang generic vectors, 16 bytes on any target (SSE2 on x86-64, NEON on
// arm64) and 32 bytes inside functions compiled for AVX, chosen once at run time
// (vector_bytes()). Other compilers get the kernels' scalar loops.
//
// A kernel is one template over the lane type, instantiated for scalars, 16-byte vectors and, in
// a FLAGSIM_TARGET_AVX function, 32-byte vectors; on_widest_lanes below picks the width once and
// also makes the row length of 16^3 and 32^3 grids a compile-time constant. AVX without FMA cannot
// contract a * b + c, so every width does the same operations per lane and gives the same bits
// (tests compare widths).
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

/// What on_widest_lanes compiles a kernel for: lanes L (Lanes32 or Lanes16 of some type, or void:
/// the kernel's scalar loops) of W values (1 for void), rows of N values (0: read at run time).
template <class Lanes, int Row = 0>
struct CompiledFor {
  using L = Lanes;
  static constexpr int N = Row;
  static constexpr int W = [] {
    if constexpr (std::is_void<Lanes>::value)
      return 1;
    else
      return Lanes::W;
  }();
};

namespace simd_detail {
template <class K, class F, class R, class... A>
R run(const void* f, A... a) {
  return (*static_cast<const F*>(f))(K{}, a...);
}
#ifdef FLAGSIM_HAVE_AVX_DISPATCH
template <class K, class F, class R, class... A>
FLAGSIM_TARGET_AVX R run_avx(const void* f, A... a) {
  return (*static_cast<const F*>(f))(K{}, a...);
}
#endif
}  // namespace simd_detail

template <class Signature>
struct LaneKernel;

/// A kernel bound to the widest lanes this CPU has (on_widest_lanes): calling it with a... runs
/// f(CompiledFor<L, N>{}, a...) in a function compiled for those lanes. It holds f's address, as
/// a function_ref does: f must outlive it.
template <class R, class... A>
struct LaneKernel<R(A...)> {
  R (*fn)(const void*, A...) = nullptr;
  const void* f = nullptr;
  FLAGSIM_INLINE R operator()(A... a) const { return fn(f, a...); }

  template <class T, bool kRows, class F>
  static LaneKernel bind(const F& f, int rows) {
    LaneKernel k{&simd_detail::run<CompiledFor<NarrowLanes<T>>, F, R, A...>, &f};
#ifdef FLAGSIM_HAVE_AVX_DISPATCH
    if (vector_bytes() == 32) {
      using L = Lanes32<T>;
      k.fn = &simd_detail::run_avx<CompiledFor<L>, F, R, A...>;
      if constexpr (kRows) {
        if (rows == 16) k.fn = &simd_detail::run_avx<CompiledFor<L, 16>, F, R, A...>;
        if (rows == 32) k.fn = &simd_detail::run_avx<CompiledFor<L, 32>, F, R, A...>;
      }
    }
#else
    (void)rows;
#endif
    return k;
  }
};

/// Kernel f with the signature R(A...) after its first argument, bound once to the widest lanes
/// of T this CPU has: L = Lanes32<T> in a FLAGSIM_TARGET_AVX function where vector_bytes() is 32,
/// else NarrowLanes<T>. f: a generic lambda marked FLAGSIM_INLINE_LAMBDA (or a functor whose call
/// operator is always inlined), so that it becomes AVX code by inlining, with all it calls on
/// vectors FLAGSIM_INLINE. Given rows (the length of f's rows), N is rows where that is 16 or 32
/// on 32-byte lanes (the 16^3 and 32^3 grids: a row's vectors unrolled, its set-up shorter),
/// else 0; without, N is 0.
template <class T, class Signature, class F>
LaneKernel<Signature> on_widest_lanes(const F& f) {
  return LaneKernel<Signature>::template bind<T, false>(f, 0);
}
template <class T, class Signature, class F>
LaneKernel<Signature> on_widest_lanes(const F& f, int rows) {
  return LaneKernel<Signature>::template bind<T, true>(f, rows);
}

}  // namespace flagsim

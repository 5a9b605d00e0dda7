#include "common/simd.h"

namespace flagsim {

int vector_bytes(int force) {
  static const int chosen = [] {
#ifdef FLAGSIM_HAVE_AVX_DISPATCH
    __builtin_cpu_init();
    if (__builtin_cpu_supports("avx")) return 32;  // libgcc also checks the OS saves YMM state
#endif
#ifdef FLAGSIM_HAVE_VECTORS
    return 16;
#else
    return 0;
#endif
  }();
  static int cap = 0;  // set by tests only, before the kernels run
  if (force >= 0) cap = force;
  return cap > 0 && cap < chosen ? cap : chosen;
}

}  // namespace flagsim

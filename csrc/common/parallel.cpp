#include "common/parallel.h"

#include "common/errors.h"
#ifdef _OPENMP
#include <omp.h>
#endif

namespace flagsim {

int num_threads() {
#ifdef _OPENMP
  return omp_get_max_threads();
#else
  return 1;
#endif
}

void set_num_threads(int n) {
  if (n < 1) fail_param("threads", ">= 1", n);
#ifdef _OPENMP
  omp_set_num_threads(n);
#endif
}

bool has_openmp() {
#ifdef _OPENMP
  return true;
#else
  return false;
#endif
}

}  // namespace flagsim

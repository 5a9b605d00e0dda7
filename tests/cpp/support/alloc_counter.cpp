// Replaces the allocator of the whole test binary with counting versions that count only while
// a CountAllocations scope is alive, so other tests are unaffected. Two levels are replaced:
//  - global operator new / delete (every variant), which C++ containers and std::string use;
//  - on glibc, malloc / calloc / realloc / memalign / posix_memalign / aligned_alloc, forwarding
//    to glibc's __libc_* entry points. Eigen's dynamic matrices (and so its temporaries) allocate
//    with std::malloc through Eigen::internal::aligned_malloc, never with operator new, so a
//    counter that replaced operator new alone would miss exactly the allocations that matter.
// Under AddressSanitizer the sanitizer owns both levels: nothing is replaced, and
// allocation_counting_available() is false (tests then skip with that reason).
#include "alloc_counter.h"

#include <atomic>
#include <cstddef>
#include <cstdlib>
#include <new>

#if defined(__SANITIZE_ADDRESS__)
#define FLAGSIM_COUNT_ALLOCATIONS 0
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define FLAGSIM_COUNT_ALLOCATIONS 0
#endif
#endif
#ifndef FLAGSIM_COUNT_ALLOCATIONS
#define FLAGSIM_COUNT_ALLOCATIONS 1
#endif

namespace {
std::atomic<int> g_armed{0};  // CountAllocations scopes alive
std::atomic<long> g_allocations{0};

inline void note_allocation() {
  if (g_armed.load(std::memory_order_relaxed) > 0) g_allocations.fetch_add(1, std::memory_order_relaxed);
}
}  // namespace

#if FLAGSIM_COUNT_ALLOCATIONS

#if defined(__GLIBC__)
// Counting malloc family. operator new below calls std::malloc, so with these in place every
// operator new is counted here once (not twice).
extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
void* __libc_memalign(std::size_t, std::size_t);

void* malloc(std::size_t n) {
  note_allocation();
  return __libc_malloc(n);
}
void* calloc(std::size_t count, std::size_t n) {
  note_allocation();
  return __libc_calloc(count, n);
}
void* realloc(void* p, std::size_t n) {
  note_allocation();
  return __libc_realloc(p, n);
}
void* memalign(std::size_t alignment, std::size_t n) {
  note_allocation();
  return __libc_memalign(alignment, n);
}
void* aligned_alloc(std::size_t alignment, std::size_t n) {
  note_allocation();
  return __libc_memalign(alignment, n);
}
int posix_memalign(void** out, std::size_t alignment, std::size_t n) {
  note_allocation();
  if (alignment < sizeof(void*) || (alignment & (alignment - 1)) != 0) return 22;  // EINVAL
  void* p = __libc_memalign(alignment, n);
  if (!p) return 12;  // ENOMEM
  *out = p;
  return 0;
}
}  // extern "C"
#define FLAGSIM_NOTE_NEW()
#else
#define FLAGSIM_NOTE_NEW() note_allocation()
#endif

namespace {
void* counted_new(std::size_t n) {
  FLAGSIM_NOTE_NEW();
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void* counted_new_aligned(std::size_t n, std::align_val_t a) {
  FLAGSIM_NOTE_NEW();
  const std::size_t al = static_cast<std::size_t>(a);
  void* p = nullptr;
  if (posix_memalign(&p, al < sizeof(void*) ? sizeof(void*) : al, n ? n : 1) != 0) throw std::bad_alloc();
  return p;
}
}  // namespace

void* operator new(std::size_t n) { return counted_new(n); }
void* operator new[](std::size_t n) { return counted_new(n); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return counted_new(n);
  } catch (...) {
    return nullptr;
  }
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return counted_new(n);
  } catch (...) {
    return nullptr;
  }
}
void* operator new(std::size_t n, std::align_val_t a) { return counted_new_aligned(n, a); }
void* operator new[](std::size_t n, std::align_val_t a) { return counted_new_aligned(n, a); }
void* operator new(std::size_t n, std::align_val_t a, const std::nothrow_t&) noexcept {
  try {
    return counted_new_aligned(n, a);
  } catch (...) {
    return nullptr;
  }
}
void* operator new[](std::size_t n, std::align_val_t a, const std::nothrow_t&) noexcept {
  try {
    return counted_new_aligned(n, a);
  } catch (...) {
    return nullptr;
  }
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t, const std::nothrow_t&) noexcept { std::free(p); }

#endif  // FLAGSIM_COUNT_ALLOCATIONS

namespace flagsim::testing {
bool allocation_counting_available() { return FLAGSIM_COUNT_ALLOCATIONS != 0; }
long allocation_count() { return g_allocations.load(); }
CountAllocations::CountAllocations() : start_(allocation_count()) { g_armed.fetch_add(1); }
CountAllocations::~CountAllocations() { g_armed.fetch_sub(1); }
}  // namespace flagsim::testing

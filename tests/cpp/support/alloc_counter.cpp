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

#if FLAGSIM_COUNT_ALLOCATIONS && defined(__GLIBC__)
#define FLAGSIM_COUNT_C_ALLOCATIONS 1
#else
#define FLAGSIM_COUNT_C_ALLOCATIONS 0
#endif

namespace {
std::atomic<long> g_count{0};
std::atomic<int> g_enabled{0};

inline void note() {
  if (g_enabled.load(std::memory_order_relaxed)) g_count.fetch_add(1, std::memory_order_relaxed);
}
}  // namespace

#if FLAGSIM_COUNT_C_ALLOCATIONS
// glibc's own entry points: the C allocation functions below forward to them, so the memory is
// glibc's and its free() releases it.
extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
void* __libc_memalign(std::size_t, std::size_t);

void* malloc(std::size_t n) {
  note();
  return __libc_malloc(n);
}
void* calloc(std::size_t count, std::size_t n) {
  note();
  return __libc_calloc(count, n);
}
void* realloc(void* p, std::size_t n) {
  note();
  return __libc_realloc(p, n);
}
void* memalign(std::size_t alignment, std::size_t n) {
  note();
  return __libc_memalign(alignment, n);
}
void* aligned_alloc(std::size_t alignment, std::size_t n) {
  note();
  return __libc_memalign(alignment, n);
}
int posix_memalign(void** out, std::size_t alignment, std::size_t n) {
  note();
  if (alignment < sizeof(void*) || (alignment & (alignment - 1)) != 0) return 22;  // EINVAL
  void* p = __libc_memalign(alignment, n);
  if (!p) return 12;  // ENOMEM
  *out = p;
  return 0;
}
}  // extern "C"
#endif

#if FLAGSIM_COUNT_ALLOCATIONS
namespace {
// With the C functions counted, operator new is counted there (once), through std::malloc.
inline void note_new() {
  if (!FLAGSIM_COUNT_C_ALLOCATIONS) note();
}
void* counted_alloc(std::size_t n) {
  note_new();
  void* p = std::malloc(n == 0 ? 1 : n);
  if (!p) throw std::bad_alloc();
  return p;
}
void* counted_aligned_alloc(std::size_t n, std::align_val_t a) {
  note_new();
  const std::size_t al = static_cast<std::size_t>(a);
  void* p = std::aligned_alloc(al, ((n + al - 1) / al) * al);
  if (!p) throw std::bad_alloc();
  return p;
}
template <class F>
void* or_null(F&& f) noexcept {
  try {
    return f();
  } catch (...) {
    return nullptr;
  }
}
}  // namespace

void* operator new(std::size_t n) { return counted_alloc(n); }
void* operator new[](std::size_t n) { return counted_alloc(n); }
void* operator new(std::size_t n, std::align_val_t a) { return counted_aligned_alloc(n, a); }
void* operator new[](std::size_t n, std::align_val_t a) { return counted_aligned_alloc(n, a); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  return or_null([&] { return counted_alloc(n); });
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  return or_null([&] { return counted_alloc(n); });
}
void* operator new(std::size_t n, std::align_val_t a, const std::nothrow_t&) noexcept {
  return or_null([&] { return counted_aligned_alloc(n, a); });
}
void* operator new[](std::size_t n, std::align_val_t a, const std::nothrow_t&) noexcept {
  return or_null([&] { return counted_aligned_alloc(n, a); });
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
long allocation_count() { return g_count.load(); }
bool allocation_counting_available() { return FLAGSIM_COUNT_ALLOCATIONS != 0; }
bool counts_c_allocations() { return FLAGSIM_COUNT_C_ALLOCATIONS != 0; }
CountAllocations::CountAllocations() : start_(allocation_count()) { g_enabled.fetch_add(1); }
CountAllocations::~CountAllocations() { g_enabled.fetch_sub(1); }
}  // namespace flagsim::testing

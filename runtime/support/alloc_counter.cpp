#include "alloc_counter.hpp"

#include <cerrno>
#include <cstddef>
#include <new>

// glibc's own implementations, which the replacements below forward to.
extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
void* __libc_memalign(std::size_t, std::size_t);
void __libc_free(void*);
}

// A static link (NAO_STATIC, the robot build) cannot define malloc itself: libc.a's malloc.o,
// which holds __libc_malloc, defines it too. There the C functions are __wrap_<name> and the
// linker routes every call of <name> to them (-Wl,--wrap=<name>, runtime/CMakeLists.txt).
#if NAO_ALLOC_COUNTER_WRAP
#define NAO_ALLOC_C_NAME(name) __wrap_##name
#else
#define NAO_ALLOC_C_NAME(name) name
#endif

namespace {
// Plain thread-local integers: reading them allocates nothing and needs no constructor.
thread_local int t_armed = 0;
thread_local std::int64_t t_count = 0;
thread_local nao::ThreadAllocations* t_sink = nullptr;

inline void note() {
  if (t_armed) ++t_count;
  if (t_sink != nullptr) t_sink->count.fetch_add(1, std::memory_order_relaxed);
}

void* newImpl(std::size_t n) {
  note();
  void* p = __libc_malloc(n == 0 ? 1 : n);
  if (!p) throw std::bad_alloc();
  return p;
}

void* newAlignedImpl(std::size_t n, std::size_t align) {
  note();
  void* p = __libc_memalign(align, n == 0 ? 1 : n);
  if (!p) throw std::bad_alloc();
  return p;
}
}  // namespace

extern "C" {
void* NAO_ALLOC_C_NAME(malloc)(std::size_t n) {
  note();
  return __libc_malloc(n);
}
void* NAO_ALLOC_C_NAME(calloc)(std::size_t n, std::size_t size) {
  note();
  return __libc_calloc(n, size);
}
void* NAO_ALLOC_C_NAME(realloc)(void* p, std::size_t n) {
  note();
  return __libc_realloc(p, n);
}
void* NAO_ALLOC_C_NAME(memalign)(std::size_t align, std::size_t n) {
  note();
  return __libc_memalign(align, n);
}
void* NAO_ALLOC_C_NAME(aligned_alloc)(std::size_t align, std::size_t n) {
  note();
  return __libc_memalign(align, n);
}
int NAO_ALLOC_C_NAME(posix_memalign)(void** out, std::size_t align, std::size_t n) {
  note();
  void* p = __libc_memalign(align, n);
  if (!p) return ENOMEM;
  *out = p;
  return 0;
}
void NAO_ALLOC_C_NAME(free)(void* p) { __libc_free(p); }
}

void* operator new(std::size_t n) { return newImpl(n); }
void* operator new[](std::size_t n) { return newImpl(n); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  note();
  return __libc_malloc(n == 0 ? 1 : n);
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  note();
  return __libc_malloc(n == 0 ? 1 : n);
}
void* operator new(std::size_t n, std::align_val_t a) { return newAlignedImpl(n, static_cast<std::size_t>(a)); }
void* operator new[](std::size_t n, std::align_val_t a) { return newAlignedImpl(n, static_cast<std::size_t>(a)); }
void operator delete(void* p) noexcept { __libc_free(p); }
void operator delete[](void* p) noexcept { __libc_free(p); }
void operator delete(void* p, std::size_t) noexcept { __libc_free(p); }
void operator delete[](void* p, std::size_t) noexcept { __libc_free(p); }
void operator delete(void* p, std::align_val_t) noexcept { __libc_free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { __libc_free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { __libc_free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { __libc_free(p); }

namespace nao {

CountAllocations::CountAllocations() : start_(t_count) { ++t_armed; }
CountAllocations::~CountAllocations() { --t_armed; }
std::int64_t CountAllocations::count() const { return t_count - start_; }
void countThreadAllocationsInto(ThreadAllocations* sink) { t_sink = sink; }

}  // namespace nao

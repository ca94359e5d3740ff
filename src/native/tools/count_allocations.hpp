// Counting allocator for the C++-only drivers (driver.cpp, weighted_driver.cpp): g_allocs
// counts heap allocations, so a driver can check that a solver allocates nothing per call
// after the first. Include it in exactly one translation unit of a driver.
//
// With QPCOORD_COUNT_MALLOC defined before the include (driver.cpp), it counts at the C level
// (malloc, calloc, realloc and the aligned forms, forwarded to glibc's __libc_* functions):
// Eigen's dense storage allocates through std::malloc (internal::aligned_malloc), which a
// counting operator new never sees — e.g. Eigen 3.4's BDCSVD::compute makes 4-80 heap
// allocations per call, and a product whose left factor is a strided (row-major input) block
// copies it to a heap temporary; an operator-new count reported both as 0. operator new
// (libstdc++'s) calls malloc, so std::vector and friends are counted too. glibc only.
//
// Without it (weighted_driver.cpp) only the global operator new is counted, which misses
// Eigen's allocations: with the malloc count, weighted_driver's refactor mode shows 3
// allocations per call.
#pragma once

#ifdef QPCOORD_COUNT_MALLOC
#include <cstddef>
#include <cstdlib>

extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
void* __libc_memalign(std::size_t, std::size_t);
void __libc_free(void*);
}

static long long g_allocs = 0;

extern "C" {
void* malloc(std::size_t n) {
  ++g_allocs;
  return __libc_malloc(n);
}
void* calloc(std::size_t k, std::size_t n) {
  ++g_allocs;
  return __libc_calloc(k, n);
}
void* realloc(void* p, std::size_t n) {
  ++g_allocs;
  return __libc_realloc(p, n);
}
void* memalign(std::size_t a, std::size_t n) {
  ++g_allocs;
  return __libc_memalign(a, n);
}
void* aligned_alloc(std::size_t a, std::size_t n) {
  ++g_allocs;
  return __libc_memalign(a, n);
}
int posix_memalign(void** p, std::size_t a, std::size_t n) {
  ++g_allocs;
  *p = __libc_memalign(a, n);
  return *p ? 0 : 12;  // ENOMEM
}
void free(void* p) { __libc_free(p); }
}

#else  // count the global operator new only

#include <cstdlib>
#include <new>

static long long g_allocs = 0;
void* operator new(std::size_t n) {
  ++g_allocs;
  void* p = std::malloc(n ? n : 1);
  if (!p) throw std::bad_alloc();
  return p;
}
void* operator new[](std::size_t n) {
  ++g_allocs;
  void* p = std::malloc(n ? n : 1);
  if (!p) throw std::bad_alloc();
  return p;
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }

#endif

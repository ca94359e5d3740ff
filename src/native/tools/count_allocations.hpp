// Counting replacements of the global operator new/delete for the C++-only drivers
// (driver.cpp, weighted_driver.cpp): g_allocs counts every heap allocation, so a driver can
// check that a solver allocates nothing per call after the first. Include it in exactly one
// translation unit of a driver.
#pragma once

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

// Which x86-64 ISA levels the running CPU and OS support: the loader (qpcoord/core/native.py)
// asks the baseline module (qpcoord._native, compiled for plain x86-64) before it imports a
// variant compiled for a higher level (qpcoord._native_x86_64_v3), which would die of SIGILL
// on an older CPU.
//
// The levels are those of the x86-64 psABI (what GCC's and Clang's -march=x86-64-vN assume):
//   v2: CMPXCHG16B, LAHF/SAHF, POPCNT, SSE3, SSSE3, SSE4.1, SSE4.2;
//   v3: v2 + AVX, AVX2, BMI1, BMI2, F16C, FMA, LZCNT, MOVBE, XSAVE, and the OS saving the
//       SSE and AVX state (XCR0 bits 1, 2, read with XGETBV once CPUID says OSXSAVE);
//   v4: v3 + AVX512F, AVX512BW, AVX512CD, AVX512DQ, AVX512VL, and the OS saving the opmask
//       and ZMM state (XCR0 bits 5, 6, 7).
// Read with CPUID and XGETBV directly (GCC/Clang <cpuid.h>), so the OS check does not depend on
// what a compiler's __builtin_cpu_supports covers. Elsewhere (not x86-64, or another compiler)
// only the baseline is reported.
#pragma once

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <cpuid.h>
#define QPCOORD_HAVE_CPUID 1
#endif

namespace qpcoord {

/// The highest x86-64 ISA level (1 = baseline, 2, 3, 4) this CPU and OS support.
inline int x86_64_level() {
#ifdef QPCOORD_HAVE_CPUID
  unsigned a = 0, b = 0, c = 0, d = 0;
  if (__get_cpuid_max(0, nullptr) < 7) return 1;
  __cpuid_count(1, 0, a, b, c, d);
  const unsigned c1 = c;
  __cpuid_count(7, 0, a, b, c, d);
  const unsigned b7 = b;
  unsigned c81 = 0;
  if (__get_cpuid_max(0x80000000u, nullptr) >= 0x80000001u) {
    __cpuid(0x80000001u, a, b, c, d);
    c81 = c;
  }
  auto bit = [](unsigned reg, int i) { return ((reg >> i) & 1u) != 0; };
  // v2: SSE3 0, SSSE3 9, CX16 13, SSE4.1 19, SSE4.2 20, POPCNT 23 (leaf 1 ecx); LAHF 0 (ext.)
  const bool v2 = bit(c1, 0) && bit(c1, 9) && bit(c1, 13) && bit(c1, 19) && bit(c1, 20) &&
                  bit(c1, 23) && bit(c81, 0);
  if (!v2) return 1;
  // v3: FMA 12, MOVBE 22, XSAVE 26, OSXSAVE 27, AVX 28, F16C 29 (leaf 1 ecx); BMI1 3, AVX2 5,
  // BMI2 8 (leaf 7 ebx); LZCNT 5 (ext. ecx)
  const bool cpu3 = bit(c1, 12) && bit(c1, 22) && bit(c1, 26) && bit(c1, 27) && bit(c1, 28) &&
                    bit(c1, 29) && bit(b7, 3) && bit(b7, 5) && bit(b7, 8) && bit(c81, 5);
  if (!cpu3) return 2;
  unsigned xlo = 0, xhi = 0;
  __asm__ volatile("xgetbv" : "=a"(xlo), "=d"(xhi) : "c"(0u));  // XCR0 (OSXSAVE checked)
  if ((xlo & 0x6u) != 0x6u) return 2;  // the OS does not save the SSE and AVX state
  // v4: AVX512F 16, AVX512DQ 17, AVX512CD 28, AVX512BW 30, AVX512VL 31 (leaf 7 ebx)
  const bool cpu4 = bit(b7, 16) && bit(b7, 17) && bit(b7, 28) && bit(b7, 30) && bit(b7, 31);
  if (!cpu4 || (xlo & 0xe0u) != 0xe0u) return 3;
  return 4;
#else
  return 1;
#endif
}

}  // namespace qpcoord

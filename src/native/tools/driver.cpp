// Profiling / allocation driver of the native core, without Python (built only by hand or by
// tests/core/test_native_allocation.py): reads problems written by dump_problems.py, solves every step
// warm (as Stack.solve does), repeats, and reports the time per solve and the heap
// allocations (a counting malloc: tools/count_allocations.hpp) made by the solves after the
// first pass.
//
//   g++ -O2 -g -std=c++17 -DNDEBUG -I<eigen3> -Isrc/native src/native/tools/driver.cpp
//       src/native/hierarchy.cpp -o /tmp/driver
//   /tmp/driver FILE.bin [repeats] [cold|warm] [XOUT.bin]
//
// The x86-64-v3 build (qpcoord._native_x86_64_v3, which the loader picks on an AVX2/FMA CPU):
// the same command with -march=x86-64-v3 (e.g. -o /tmp/driver_v3); compare the two binaries
// alternated on the same files (the v3 build's FMA rounds otherwise: x equal to ~1e-12, not
// bit for bit). valgrind's callgrind runs both (it emulates AVX2 and FMA, not AVX-512).
//
// Prints the mean, median, p90 and p99 per solve; with XOUT.bin, writes every solve's x
// (float64, n per solve, in order) to compare two builds.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <new>
#include <string>
#include <vector>

#include "hierarchy.hpp"

#define QPCOORD_COUNT_MALLOC  // count malloc (Eigen allocates there), not only operator new
#include "tools/count_allocations.hpp"
#include "tools/dump_file.hpp"

// Under valgrind --tool=callgrind --collect-atstart=no, only the second pass is counted (the
// warm re-solve: the first pass allocates and fills the per-stage buffers).
#if defined(__has_include)
#if __has_include(<valgrind/callgrind.h>)
#include <valgrind/callgrind.h>
#define QPCOORD_DRIVER_COLLECT() CALLGRIND_TOGGLE_COLLECT
#endif
#endif
#ifndef QPCOORD_DRIVER_COLLECT
#define QPCOORD_DRIVER_COLLECT() (void)0
#endif

using namespace qpcoord;
using RowMap = Eigen::Map<const Mat, 0, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>>;
using VecMap = Eigen::Map<const Vec>;

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: driver FILE.bin [repeats] [cold]\n");
    return 2;
  }
  const int repeats = argc > 2 ? std::atoi(argv[2]) : 20;
  const bool cold = argc > 3 && argv[3][0] == 'c';
  tools::DumpFile dump;  // the dump's reader, shared with benchmarks/lexls/lexls_driver.cpp
  if (!dump.read(argv[1])) return 2;
  std::FILE* xout = argc > 4 ? std::fopen(argv[4], "wb") : nullptr;
  const int n = dump.n, blocks = dump.blocks, steps = dump.steps;
  const bool has_bounds = dump.has_bounds;
  const double damping = dump.damping;
  const std::vector<int>& meq = dump.meq;
  const std::vector<int>& min = dump.min;
  const int me = dump.me, mi = dump.mi;
  const int L = blocks - 1;
  const size_t per = dump.per;
  const std::vector<double>& data = dump.data;
  Hierarchy h(n, meq, min, has_bounds, damping);
  Vec x(n), res(L), detail(8);
  Mat stats(L + 2, 3);
  long long allocs_after_first = 0;
  double seconds = 0.0;
  std::vector<double> each;
  each.reserve(size_t(repeats) * steps);
  long long iters = 0, hits = 0, closed = 0;
  Mat per_stage = Mat::Zero(L + 2, 3);  // summed stats: iterations, warm hits, closed forms
  long long seeded = 0, qr_forms = 0;
  // QPCOORD_DRIVER_STEPS=1: print each solve's time, iterations and QR closed forms (stderr)
  const bool each_step = std::getenv("QPCOORD_DRIVER_STEPS") != nullptr;
  for (int rep = 0; rep < repeats; ++rep) {
    for (int s = 0; s < steps; ++s) {
      const double* p = data.data() + per * s;
      RowMap Aeq(p, me, n, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>(1, n));
      p += size_t(me) * n;
      VecMap beq(p, me);
      p += me;
      RowMap C(p, mi, n, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>(1, n));
      p += size_t(mi) * n;
      VecMap lo(p, mi), hi(p + mi, mi), sw(p + 2 * mi, mi);
      p += 3 * mi;
      VecMap lb(p, n), ub(p + n, n);
      if (rep == 1 && s == 0) QPCOORD_DRIVER_COLLECT();  // on: the second pass starts
      const long long a0 = g_allocs;
      const auto t0 = std::chrono::steady_clock::now();
      const bool warm = !cold && (rep || s);
      const double no_limit = std::numeric_limits<double>::infinity();
      const int code =
          h.solve(Aeq, beq, C, lo, hi, sw, lb, ub, warm, no_limit, x, res, stats, detail);
      const auto t1 = std::chrono::steady_clock::now();
      const double dt = std::chrono::duration<double>(t1 - t0).count();
      seconds += dt;
      each.push_back(dt);
      if (xout) std::fwrite(x.data(), sizeof(double), size_t(n), xout);
      if (rep > 0) allocs_after_first += g_allocs - a0;
      if (rep == 1 && s == steps - 1) QPCOORD_DRIVER_COLLECT();  // off: it ended
      if (code) {
        std::fprintf(stderr, "step %d: status %d\n", s, code);
        return 1;
      }
      iters += static_cast<long long>(stats.col(0).sum());
      hits += static_cast<long long>(stats.col(1).sum());
      closed += static_cast<long long>(stats.col(2).sum());
      per_stage += stats;
      seeded += static_cast<long long>(detail(7));
      qr_forms += h.stats().qr_closed_forms;
      if (each_step)
        std::fprintf(stderr, "pass %d step %d: %.1f us, iterations %.0f, QR closed forms %d\n",
                     rep, s, 1e6 * dt, stats.col(0).sum(), h.stats().qr_closed_forms);
    }
  }
  if (xout) std::fclose(xout);
  const double solves = double(repeats) * steps;
  std::sort(each.begin(), each.end());
  auto pct = [&](double q) { return 1e6 * each[size_t(q * double(each.size() - 1))]; };
  std::printf("median %.2f us  p90 %.2f us  p99 %.2f us  ", pct(0.5), pct(0.9), pct(0.99));
  std::printf("solves %.0f  mean %.2f us  iters/solve %.2f  warm hits/solve %.2f  "
              "closed forms/solve %.2f  allocations after the first pass %lld\n",
              solves, 1e6 * seconds / solves, iters / solves, hits / solves, closed / solves,
              allocs_after_first);
  // per stage (hard, levels..., min-norm): iterations, warm hits, closed forms per solve
  std::printf("per stage (iters/hits/closed per solve):");
  for (int b = 0; b < L + 2; ++b)
    std::printf(" [%d] %.2f/%.2f/%.2f", b, per_stage(b, 0) / solves, per_stage(b, 1) / solves,
                per_stage(b, 2) / solves);
  std::printf("  seeded stages/solve %.2f  QR closed forms/solve %.2f\n", double(seeded) / solves,
              double(qr_forms) / solves);
  return 0;
}

// The reader of the problem dumps written by tools/dump_problems.py, shared by the native
// engine's driver (tools/driver.cpp) and the LexLS driver (benchmarks/lexls/lexls_driver.cpp).
// Header-only, standard C++17 (no Eigen: each driver maps the arrays with its own types).
//
// Format (little-endian, 8 bytes per entry): int64 n, int64 blocks (the hard block, then the
// levels), int64 has_bounds, float64 damping, int64 steps, int64 meq[blocks],
// int64 min[blocks], then per step the stacked arrays of every block: Aeq (me x n, row-major),
// beq (me), C (mi x n, row-major), lo, hi, sw (mi each), lb, ub (n each), with me and mi the
// sums of meq and min.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <vector>

namespace qpcoord {
namespace tools {

/// One step's arrays inside DumpFile::data (pointers into it; row-major matrices).
struct DumpStep {
  const double* Aeq;  // me x n
  const double* beq;  // me
  const double* C;    // mi x n
  const double* lo;   // mi
  const double* hi;   // mi
  const double* sw;   // mi: sqrt weights of the inequality rows
  const double* lb;   // n
  const double* ub;   // n
};

/// A dump file read whole: its header and every step's stacked arrays.
struct DumpFile {
  int n = 0;
  int blocks = 0;  // the hard block, then the levels
  bool has_bounds = false;
  double damping = 0.0;
  int steps = 0;
  std::vector<int> meq, min;  // rows per block
  int me = 0, mi = 0;         // their sums
  std::size_t per = 0;        // doubles per step
  std::vector<double> data;   // steps x per

  /// Reads `path`; false (with a message on stderr) if it cannot be opened or is short.
  bool read(const char* path) {
    std::ifstream f(path, std::ios::binary);
    if (!f) {
      std::fprintf(stderr, "cannot open %s\n", path);
      return false;
    }
    auto rd_i = [&]() {
      std::int64_t v = 0;
      f.read(reinterpret_cast<char*>(&v), 8);
      return static_cast<int>(v);
    };
    n = rd_i();
    blocks = rd_i();
    has_bounds = rd_i() != 0;
    f.read(reinterpret_cast<char*>(&damping), 8);
    steps = rd_i();
    if (!f || n < 0 || blocks < 0 || steps < 0) {
      std::fprintf(stderr, "short file\n");
      return false;
    }
    meq.assign(blocks, 0);
    min.assign(blocks, 0);
    me = mi = 0;
    for (auto& v : meq) me += (v = rd_i());
    for (auto& v : min) mi += (v = rd_i());
    per = std::size_t(me) * n + me + std::size_t(mi) * n + 3 * std::size_t(mi) +
          2 * std::size_t(n);
    data.assign(per * steps, 0.0);
    f.read(reinterpret_cast<char*>(data.data()), std::streamsize(data.size() * 8));
    if (!f) {
      std::fprintf(stderr, "short file\n");
      return false;
    }
    return true;
  }

  /// The arrays of step `s` (0 <= s < steps).
  DumpStep step(int s) const {
    const double* p = data.data() + per * std::size_t(s);
    DumpStep d;
    d.Aeq = p;
    d.beq = d.Aeq + std::size_t(me) * n;
    d.C = d.beq + me;
    d.lo = d.C + std::size_t(mi) * n;
    d.hi = d.lo + mi;
    d.sw = d.hi + mi;
    d.lb = d.sw + mi;
    d.ub = d.lb + n;
    return d;
  }
};

}  // namespace tools
}  // namespace qpcoord

// LexLS (jrl-umi3218/lexls, C++, header-only, BSD-2) on the problems dumped for the native
// engine's driver (src/native/tools/dump_problems.py; read by src/native/tools/dump_file.hpp,
// the driver's reader too): the fastest published strict-hierarchy solver, run on this
// machine rather than quoted from its paper. Not built by pip or CI: LexLS is not on PyPI;
// benchmarks/lexls/bench.py builds it and the native driver and prints the table.
//
//   git clone https://github.com/jrl-umi3218/lexls /tmp/lexls   (only include/ is needed)
//   g++ -O2 -std=c++17 -DNDEBUG -I<eigen3> -I/tmp/lexls/include \
//       benchmarks/lexls/lexls_driver.cpp -o /tmp/lexls_driver
//   /tmp/lexls_driver FILE.bin [repeats] [cold|warm] [XOUT.bin]
//
// Each level of the dump (the hard block, then the levels) is one LexLS GENERAL_OBJECTIVE:
// equality rows as bl = bu = b, inequality rows scaled by their sqrt weight sw (the violation
// sw·viol is what qpcoord's level value squares). The bounds, when the dump has them, are
// LexLS's SIMPLE_BOUNDS_OBJECTIVE (its first objective, as LexLS requires; an infinite side
// is written as ±1e30). LexLS treats the bounds and the hard block as objectives of highest
// priority: the same lexicographic problem when they can be met, which they can here.
// "warm": each step starts from the previous step's x (set_x0) and its final working set
// (api_activate of every active inequality), LexLS's hot start; "cold": from scratch.
// The time per solve includes setData (LexLS copies the data into its own storage each step;
// qpcoord's driver reads the stacked arrays in place). Prints median / p90 / p99 per solve
// and the factorisations per solve; with XOUT.bin writes every solve's x (float64).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <vector>

#include <lexls/lexlsi.h>

#include "../../src/native/tools/dump_file.hpp"

using LexLS::Index;
using Mat = Eigen::MatrixXd;
using Vec = Eigen::VectorXd;
using RowMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: lexls_driver FILE.bin [repeats] [cold|warm] [XOUT.bin]\n");
    return 2;
  }
  const int repeats = argc > 2 ? std::atoi(argv[2]) : 10;
  const bool cold = argc > 3 && argv[3][0] == 'c';
  std::FILE* xout = argc > 4 ? std::fopen(argv[4], "wb") : nullptr;
  qpcoord::tools::DumpFile dump;  // the reader of src/native/tools/driver.cpp too
  if (!dump.read(argv[1])) return 2;
  const int n = dump.n, blocks = dump.blocks, steps = dump.steps;
  const bool has_bounds = dump.has_bounds;
  const std::vector<int>& meq = dump.meq;
  const std::vector<int>& min = dump.min;
  // objectives: [simple bounds], then every non-empty block
  std::vector<Index> dims;
  std::vector<LexLS::ObjectiveType> types;
  std::vector<int> block_of;  // block index of each general objective
  if (has_bounds) {
    dims.push_back(n);
    types.push_back(LexLS::SIMPLE_BOUNDS_OBJECTIVE);
  }
  for (int b = 0; b < blocks; ++b)
    if (meq[b] + min[b] > 0) {
      dims.push_back(meq[b] + min[b]);
      types.push_back(LexLS::GENERAL_OBJECTIVE);
      block_of.push_back(b);
    }
  const Index nobj = Index(dims.size());
  LexLS::internal::LexLSI solver(n, nobj, dims.data(), types.data());
  LexLS::ParametersLexLSI prm;
  prm.setDefaults();
  prm.max_number_of_factorizations = 1000;
  solver.setParameters(prm);
  std::vector<Index> var_index(n);
  for (int j = 0; j < n; ++j) var_index[j] = j;
  std::vector<Mat> obj_data(nobj);
  for (Index k = 0; k < nobj; ++k)
    obj_data[k] = Mat::Zero(dims[k], types[k] == LexLS::SIMPLE_BOUNDS_OBJECTIVE ? 2 : n + 2);
  std::vector<std::vector<LexLS::ConstraintActivationType>> active(nobj);
  Vec x_prev = Vec::Zero(n);
  bool have_prev = false;
  std::vector<double> each;
  long long factorizations = 0, failures = 0;
  const double big = 1e30;
  for (int rep = 0; rep < repeats; ++rep) {
    for (int s = 0; s < steps; ++s) {
      const qpcoord::tools::DumpStep ds = dump.step(s);
      const auto t0 = std::chrono::steady_clock::now();
      solver.reset();
      // the stacked arrays: Aeq, beq, C, lo, hi, sw, lb, ub
      const double *Aeq = ds.Aeq, *beq = ds.beq, *C = ds.C, *lo = ds.lo, *hi = ds.hi, *sw = ds.sw;
      const double *lb = ds.lb, *ub = ds.ub;
      Index k = 0;
      if (has_bounds) {
        Mat& d = obj_data[0];
        for (int j = 0; j < n; ++j) {
          d(j, 0) = std::max(lb[j], -big);
          d(j, 1) = std::min(ub[j], big);
        }
        solver.setData(0, var_index.data(), d);
        k = 1;
      }
      int re = 0, ri = 0;  // first rows of block b in Aeq / C
      int g = 0;
      for (int b = 0; b < blocks; ++b) {
        if (g < int(block_of.size()) && block_of[g] == b) {
          Mat& d = obj_data[k];
          for (int i = 0; i < meq[b]; ++i) {
            for (int j = 0; j < n; ++j) d(i, j) = Aeq[size_t(re + i) * n + j];
            d(i, n) = d(i, n + 1) = beq[re + i];
          }
          for (int i = 0; i < min[b]; ++i) {
            const double w = sw[ri + i];
            for (int j = 0; j < n; ++j) d(meq[b] + i, j) = w * C[size_t(ri + i) * n + j];
            d(meq[b] + i, n) = std::max(w * lo[ri + i], -big);
            d(meq[b] + i, n + 1) = std::min(w * hi[ri + i], big);
          }
          solver.setData(k, d);
          ++k;
          ++g;
        }
        re += meq[b];
        ri += min[b];
      }
      if (!cold && have_prev) {
        solver.set_x0(x_prev);
        for (Index o = 0; o < nobj; ++o)
          for (Index c = 0; c < Index(active[o].size()); ++c)
            if (active[o][c] == LexLS::CTR_ACTIVE_LB || active[o][c] == LexLS::CTR_ACTIVE_UB)
              solver.api_activate(o, c, active[o][c]);
      }
      const LexLS::TerminationStatus st = solver.solve();
      const double dt =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      each.push_back(dt);
      if (st != LexLS::PROBLEM_SOLVED && st != LexLS::PROBLEM_SOLVED_CYCLING_HANDLING)
        ++failures;
      factorizations += solver.getFactorizationsCount();
      x_prev = solver.get_x();
      have_prev = true;
      for (Index o = 0; o < nobj; ++o) solver.getActiveCtr(o, active[o]);
      if (xout) std::fwrite(x_prev.data(), sizeof(double), size_t(n), xout);
    }
  }
  if (xout) std::fclose(xout);
  std::sort(each.begin(), each.end());
  auto pct = [&](double q) { return 1e6 * each[size_t(q * double(each.size() - 1))]; };
  std::printf("median %.2f us  p90 %.2f us  p99 %.2f us  solves %zu  factorizations/solve %.2f"
              "  not solved %lld\n",
              pct(0.5), pct(0.9), pct(0.99), each.size(),
              double(factorizations) / double(each.size()), failures);
  return failures ? 1 : 0;
}

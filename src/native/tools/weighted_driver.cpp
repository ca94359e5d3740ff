// Allocation and timing driver of the native weighted QP (src/native/weighted.*), without
// Python: a random stack (hard equalities and inequalities, bounds, levels of equalities and
// soft inequalities), 2 000 steps with moving right-hand sides; counts the heap allocations
// (malloc and operator new: tools/count_allocations.hpp) of the solves after the first,
// with the factor kept (refactor = false, PersistentQP's step) and rebuilt every call
// (refactor = true, a changed matrix).
//
//   g++ -O2 -std=c++17 -DNDEBUG -DQPCOORD_NO_BINDINGS -I<eigen3> -Isrc/native \
//       src/native/tools/weighted_driver.cpp src/native/weighted.cpp -o /tmp/wdriver
//   /tmp/wdriver [n] [singular]
// "singular": the levels' equality rows only in the first n/2 coordinates, so that H is
// singular and eps is added (the least-squares unconstrained optimum of weighted.hpp).
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <new>
#include <random>
#include <string>
#include <vector>

#include "weighted.hpp"

#define QPCOORD_COUNT_MALLOC  // count malloc (Eigen allocates there), not only operator new
#include "tools/count_allocations.hpp"

using Mat = Eigen::MatrixXd;
using Vec = Eigen::VectorXd;

int main(int argc, char** argv) {
  const int n = argc > 1 ? std::atoi(argv[1]) : 30;
  std::mt19937 gen(7);
  std::normal_distribution<double> N(0.0, 1.0);
  // blocks: hard (2 eq, 3 in), level 0 (6 eq, 8 in), level 1 (n/2 eq, 4 in), level 2 (n eq)
  const std::vector<int> meq = {2, 6, n / 2, n}, min = {3, 8, 4, 0};
  int me = 0, mi = 0;
  for (int v : meq) me += v;
  for (int v : min) mi += v;
  Mat Aeq(me, n), C(mi, n);
  for (int i = 0; i < me; ++i)
    for (int j = 0; j < n; ++j) Aeq(i, j) = N(gen);
  for (int i = 0; i < mi; ++i)
    for (int j = 0; j < n; ++j) C(i, j) = N(gen) / std::sqrt(double(n));
  Aeq.bottomRows(n).setIdentity();  // the last level: a posture
  const bool singular = argc > 2 && std::string(argv[2]) == "singular";
  if (singular) Aeq.block(meq[0], n / 2, me - meq[0], n - n / 2).setZero();
  Vec beq = Vec::Zero(me), lo(mi), hi(mi), sw = Vec::Ones(mi), lb(n), ub(n);
  for (int i = 0; i < mi; ++i) {
    lo(i) = -0.3 - 0.2 * std::abs(N(gen));
    hi(i) = 0.3 + 0.2 * std::abs(N(gen));
  }
  lb.setConstant(-1.0);
  ub.setConstant(1.0);
  qpcoord::Weighted w(n, meq, min, true, 1e-9, 1e-3);
  Vec x(n), res(3), detail(8), active(n + meq[0] + min[0] + 12);
  const int steps = 2000;
  for (int mode = 0; mode < 2; ++mode) {
    const bool refactor = mode == 1;
    long long allocs = 0, iters = 0, hits = 0, regularized = 0;
    double seconds = 0.0;
    for (int s = 0; s < steps; ++s) {
      for (int i = 0; i < meq[1]; ++i) beq(meq[0] + i) = 2.0 * std::sin(0.01 * s + i);
      for (int i = 0; i < meq[2]; ++i) beq(meq[0] + meq[1] + i) = std::cos(0.02 * s + i);
      const long long a0 = g_allocs;
      const auto t0 = std::chrono::steady_clock::now();
      const int code = w.solve(Aeq, beq, C, lo, hi, sw, lb, ub, true,
                               std::numeric_limits<double>::infinity(), refactor || s == 0, x,
                               res, detail, active);
      seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      if (s > 0) allocs += g_allocs - a0;
      if (code) {
        std::fprintf(stderr, "step %d: status %d\n", s, code);
        return 1;
      }
      iters += static_cast<long long>(detail(2));
      hits += static_cast<long long>(detail(5));
      regularized += static_cast<long long>(detail(6));
    }
    std::printf("n %d  refactor %d  solves %d  mean %.2f us  iterations/solve %.2f  "
                "warm hits/solve %.2f  regularised/solve %.2f  allocations after the first "
                "%lld\n",
                n, int(refactor), steps, 1e6 * seconds / steps, double(iters) / steps,
                double(hits) / steps, double(regularized) / steps, allocs);
  }
  return 0;
}

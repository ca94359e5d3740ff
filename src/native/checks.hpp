// qpcoord native engines: what the strict hierarchy (hierarchy.cpp) and the weighted QP
// (weighted.cpp) share -- the numerical rank rule, the final check of a returned x (as
// qpcoord.core.stack.Stack._check) and a level's value (as CompiledLevel.residual).
#pragma once

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>

namespace qpcoord {

/// CHECK_TOL (qpcoord.core.elimination): the final check of x and of the hard equalities,
/// relative to max(1, |bound|).
inline constexpr double kCheckTol = 1e-6;

/// lo widened by tol * max(1, |lo|) (an infinite lo stays infinite).
inline double widen_lo_by(double lo, double tol) { return lo - tol * std::max(1.0, std::abs(lo)); }
/// hi widened by tol * max(1, |hi|) (an infinite hi stays infinite).
inline double widen_hi_by(double hi, double tol) { return hi + tol * std::max(1.0, std::abs(hi)); }

/// Numerical rank of sorted singular values s of a rows x cols matrix, as
/// qpcoord.core.linalg.numerical_rank: s_i > max(rows, cols) * eps * max(s_0, scale).
inline int numerical_rank(const Eigen::VectorXd& s, int rows, int cols, double scale = 0.0) {
  if (s.size() == 0) return 0;
  const double ref = std::max(s(0), scale);
  if (ref == 0.0) return 0;
  const double tol = std::max(rows, cols) * std::numeric_limits<double>::epsilon() * ref;
  int rank = 0;
  for (Eigen::Index i = 0; i < s.size(); ++i)
    if (s(i) > tol) ++rank;
  return rank;
}

/// Row i of A dotted with x. A row stored contiguously (the stacked arrays are numpy's
/// C-ordered ones, seen column-major with outer stride 1) is read as one vector: Eigen then
/// vectorises the sum (else a strided loop); the sum's order, and so its rounding, differ.
template <class M, class V>
double row_dot(const M& A, Eigen::Index i, const V& x) {
  if (A.outerStride() == 1)
    return Eigen::Map<const Eigen::VectorXd>(A.data() + i * A.innerStride(), A.cols()).dot(x);
  return A.row(i).dot(x);
}

/// |row i of A|^2 (as row_dot: one vector where the row is contiguous).
template <class M>
double row_squared_norm(const M& A, Eigen::Index i) {
  if (A.outerStride() == 1)
    return Eigen::Map<const Eigen::VectorXd>(A.data() + i * A.innerStride(), A.cols()).squaredNorm();
  return A.row(i).squaredNorm();
}

/// Value of one level at x: sqrt of the squared equality residuals of rows [e0, e0 + me) of
/// (Aeq, beq) plus the squared weighted violations sw_i dist(C_i x, [lo_i, hi_i]) of rows
/// [i0, i0 + mi) of C. With `scale`, also the level's scale at x, the size of the rounding
/// of its value: |b| + |A|_F |x| over its rows (the equality rows' targets beq, the
/// inequality rows' bounds nearer to C_i x (0 if both are infinite), each weighted by sw_i,
/// and their matrix), from the same pass. The native end check compares a level's value with
/// its frozen one relative to max(1, value, scale): rounding of a level whose data is large
/// (targets ~1e5 on extreme Talos states) or whose x is (|x| ~ 1e7 past a direction
/// inverted up to 1/damping) is not a lost optimum.
template <class MA, class VB, class MC, class VL, class VX>
double level_value(const MA& Aeq, const VB& beq, int e0, int me, const MC& C, const VL& lo,
                   const VL& hi, const VL& sw, int i0, int mi, const VX& x,
                   double* scale = nullptr) {
  double total = 0.0, target = 0.0, matrix = 0.0;
  for (int i = e0; i < e0 + me; ++i) {
    const double v = row_dot(Aeq, i, x);
    const double d = v - beq(i);
    total += d * d;
    if (scale) {
      target += beq(i) * beq(i);
      matrix += row_squared_norm(Aeq, i);
    }
  }
  for (int i = i0; i < i0 + mi; ++i) {
    const double v = row_dot(C, i, x);
    const double gap = sw(i) * (v - std::min(std::max(v, lo(i)), hi(i)));
    total += gap * gap;
    if (scale) {
      const bool lower = std::isfinite(lo(i)) && (!std::isfinite(hi(i)) || v - lo(i) < hi(i) - v);
      const double b = lower ? lo(i) : (std::isfinite(hi(i)) ? hi(i) : 0.0);
      target += sw(i) * sw(i) * b * b;
      matrix += sw(i) * sw(i) * row_squared_norm(C, i);
    }
  }
  if (scale) *scale = std::sqrt(target) + std::sqrt(matrix) * x.norm();
  return std::sqrt(total);
}

/// The check of every returned x (Stack._check): the bounds (if has_bounds), the first me
/// rows of (Aeq, beq) as hard equalities, the first mi rows of C within [lo, hi], each to
/// kCheckTol. Returns 0 if x passes, else which check failed -- 1: bounds (where = the
/// index), 2: hard equalities (where = the residual norm), 3: hard inequalities (where = the
/// row).
template <class VX, class VLB, class MA, class VB, class MC, class VL>
int check_point(const VX& x, bool has_bounds, const VLB& lb, const VLB& ub, const MA& Aeq,
                const VB& beq, int me, const MC& C, const VL& lo, const VL& hi, int mi,
                double& where) {
  for (Eigen::Index j = 0; has_bounds && j < x.size(); ++j) {
    if (!(x(j) >= widen_lo_by(lb(j), kCheckTol) && x(j) <= widen_hi_by(ub(j), kCheckTol))) {
      where = static_cast<double>(j);
      return 1;
    }
  }
  if (me) {
    const double scale = std::max(1.0, beq.head(me).cwiseAbs().maxCoeff());
    double worst = 0.0, sq = 0.0;
    for (int i = 0; i < me; ++i) {
      const double d = row_dot(Aeq, i, x) - beq(i);
      worst = std::max(worst, std::abs(d));
      sq += d * d;
    }
    if (worst > kCheckTol * scale) {
      where = std::sqrt(sq);
      return 2;
    }
  }
  for (int i = 0; i < mi; ++i) {
    const double v = row_dot(C, i, x);
    if (!(v >= widen_lo_by(lo(i), kCheckTol) && v <= widen_hi_by(hi(i), kCheckTol))) {
      where = static_cast<double>(i);
      return 3;
    }
  }
  return 0;
}

}  // namespace qpcoord

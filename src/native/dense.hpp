// qpcoord native engine: a Householder QR with column pivoting on a preallocated buffer.
//
// The active set factorises a matrix of a different size at every iteration (the working
// set grows and shrinks by one row); Eigen's decompositions reallocate their storage whenever
// the size changes. This one works in a buffer sized once (max rows x max cols) through
// Eigen::Map views, so the per-call path does not touch the heap.
//
//   A P = Qf [R11 R12; 0 0],  Qf = H_0 H_1 ... H_{rank-1},  H_j = I - tau_j v_j v_j^T,
// with v_j(j) = 1 and v_j(j+1:) stored below the diagonal. The factorisation stops at the
// first pivot column whose norm is at most max(abs_tol, rel_tol * first pivot norm): that is
// the numerical rank (the pivoted diagonal of R approximates the singular values).
#pragma once

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <vector>

namespace qpcoord {

using Mat = Eigen::MatrixXd;
using Vec = Eigen::VectorXd;
using MapMat = Eigen::Map<Mat, 0, Eigen::OuterStride<>>;

class PivotedQR {
 public:
  /// Size the buffers once: no later call allocates for m <= max_rows, nc <= max_cols and
  /// matrices of at most max_right_rows rows given to apply_q_right.
  void reserve(int max_rows, int max_cols, int max_right_rows) {
    max_rows_ = std::max(max_rows, 1);
    max_cols_ = std::max(max_cols, 1);
    buf_.setZero(static_cast<Eigen::Index>(max_rows_) * max_cols_);
    tau_.setZero(max_cols_);
    norms_.setZero(max_cols_);
    perm_.assign(max_cols_, 0);
    work_.setZero(std::max({max_rows_, max_cols_, max_right_rows, 1}));
  }

  /// The m x nc matrix to fill before factor() (column-major view of the buffer).
  MapMat matrix(int m, int nc) {
    m_ = m;
    nc_ = nc;
    return MapMat(buf_.data(), m, nc, Eigen::OuterStride<>(std::max(m, 1)));
  }
  MapMat matrix() { return MapMat(buf_.data(), m_, nc_, Eigen::OuterStride<>(std::max(m_, 1))); }

  /// Factorise in place; returns the numerical rank.
  int factor(double abs_tol, double rel_tol) {
    abs_tol_ = abs_tol;
    rel_tol_ = rel_tol;
    MapMat A = matrix();
    const int steps = std::min(m_, nc_);
    for (int j = 0; j < nc_; ++j) perm_[j] = j;
    rank_ = 0;
    first_ = 0.0;
    for (int j = 0; j < steps; ++j) {
      // pivot: the remaining column of largest norm (recomputed: exact, no downdating)
      int p = j;
      double best = -1.0;
      for (int c = j; c < nc_; ++c) {
        const double v = A.col(c).segment(j, m_ - j).squaredNorm();
        norms_(c) = v;
        if (v > best) {
          best = v;
          p = c;
        }
      }
      const double pn = std::sqrt(std::max(best, 0.0));
      if (j == 0) first_ = pn;
      if (!(pn > abs_tol) || !(pn > rel_tol * first_) || pn == 0.0) break;
      if (p != j) {
        A.col(j).swap(A.col(p));
        std::swap(perm_[j], perm_[p]);
      }
      // Householder reflector of A(j:m, j)
      const double x0 = A(j, j);
      const double beta = (x0 >= 0.0) ? -pn : pn;
      const double v0 = x0 - beta;
      double tau = 0.0;
      if (v0 != 0.0) {
        A.col(j).segment(j + 1, m_ - j - 1) /= v0;
        tau = (beta - x0) / beta;
      }
      A(j, j) = beta;
      tau_(j) = tau;
      // apply to the trailing columns
      for (int c = j + 1; c < nc_; ++c) {
        auto ac = A.col(c).segment(j, m_ - j);
        const double w = ac(0) + A.col(j).segment(j + 1, m_ - j - 1).dot(ac.tail(m_ - j - 1));
        const double tw = tau * w;
        ac(0) -= tw;
        ac.tail(m_ - j - 1) -= tw * A.col(j).segment(j + 1, m_ - j - 1);
      }
      ++rank_;
    }
    return rank_;
  }

  int rank() const { return rank_; }
  int rows() const { return m_; }
  int cols() const { return nc_; }
  double first_pivot() const { return first_; }
  /// Column i of R (pivoted order) comes from column perm(i) of A.
  int perm(int i) const { return perm_[i]; }

  /// v <- Qf^T v (v: m).
  template <typename V>
  void apply_qt(V&& v) const {
    for (int j = 0; j < rank_; ++j) reflect(j, v);
  }
  /// v <- Qf v (v: m).
  template <typename V>
  void apply_q(V&& v) const {
    for (int j = rank_ - 1; j >= 0; --j) reflect(j, v);
  }
  /// B <- B Qf (B: p x m), through a workspace of p doubles.
  template <typename B>
  void apply_q_right(B&& b) {
    for (int j = 0; j < rank_; ++j) reflect_right(j, b);
  }
  /// B <- B H_j (one reflector, e.g. the one append() added: j = rank() - 1).
  template <typename B>
  void reflect_right(int j, B&& b) {
    const auto A = cmatrix();
    const int len = m_ - j - 1;
    auto w = work_.head(b.rows());
    w.noalias() = b.col(j);
    if (len > 0) w.noalias() += b.middleCols(j + 1, len) * A.col(j).segment(j + 1, len);
    w *= tau_(j);
    b.col(j) -= w;
    if (len > 0) b.middleCols(j + 1, len).noalias() -= w * A.col(j).segment(j + 1, len).transpose();
  }
  /// Append a column a (m entries) to a factorisation of full column rank: the reflectors
  /// so far are applied to it and one more reflector (no pivoting) zeroes it below the
  /// diagonal. False (nothing changed) if the factorisation is rank-deficient, full, or the
  /// new column is dependent to the factorisation's tolerance: then factor() again.
  template <typename A_>
  bool append(const A_& a) {
    if (rank_ != nc_ || nc_ >= max_cols_ || rank_ >= m_) return false;
    const int j = nc_;
    Eigen::Map<Vec> col(buf_.data() + static_cast<Eigen::Index>(j) * std::max(m_, 1), m_);
    col = a;
    for (int i = 0; i < rank_; ++i) reflect(i, col);
    const double pn = col.tail(m_ - j).norm();
    const double ref = (j == 0) ? pn : first_;
    if (!(pn > abs_tol_) || !(pn > rel_tol_ * ref) || pn == 0.0) return false;
    if (j == 0) first_ = pn;
    const double x0 = col(j);
    const double beta = (x0 >= 0.0) ? -pn : pn;
    const double v0 = x0 - beta;
    double tau = 0.0;
    if (v0 != 0.0) {
      col.segment(j + 1, m_ - j - 1) /= v0;
      tau = (beta - x0) / beta;
    }
    col(j) = beta;
    tau_(j) = tau;
    perm_[j] = j;
    ++nc_;
    ++rank_;
    return true;
  }

  /// The minimum-norm v with A^T v = b for the factorised A (m x nc, b: nc entries, out: m
  /// entries): A^T = P R^T Qf^T, so v = Qf [R11^-T (P^T b)(0:rank); 0] (b in A^T's range).
  template <typename B, typename V>
  void min_norm_transposed_solve(const B& b, V&& out) const {
    out.setZero();
    for (int i = 0; i < rank_; ++i) out(i) = b(perm_[i]);
    solve_rt(out);
    apply_q(out);
  }
  /// Solve R11 u = rhs(0:rank) in place (rhs: at least rank entries).
  template <typename V>
  void solve_r(V&& rhs) const {
    const auto A = cmatrix();
    A.topLeftCorner(rank_, rank_).template triangularView<Eigen::Upper>().solveInPlace(
        rhs.head(rank_));
  }
  /// Solve R11^T u = rhs(0:rank) in place.
  template <typename V>
  void solve_rt(V&& rhs) const {
    const auto A = cmatrix();
    A.topLeftCorner(rank_, rank_).transpose().template triangularView<Eigen::Lower>().solveInPlace(
        rhs.head(rank_));
  }

 private:
  Eigen::Map<const Mat, 0, Eigen::OuterStride<>> cmatrix() const {
    return Eigen::Map<const Mat, 0, Eigen::OuterStride<>>(buf_.data(), m_, nc_,
                                                          Eigen::OuterStride<>(std::max(m_, 1)));
  }
  template <typename V>
  void reflect(int j, V& v) const {
    const auto A = cmatrix();
    const int len = m_ - j - 1;
    double w = v(j);
    if (len > 0) w += A.col(j).segment(j + 1, len).dot(v.segment(j + 1, len));
    const double tw = tau_(j) * w;
    v(j) -= tw;
    if (len > 0) v.segment(j + 1, len) -= tw * A.col(j).segment(j + 1, len);
  }

  Vec buf_, tau_, norms_, work_;
  std::vector<int> perm_;
  int max_rows_ = 0, max_cols_ = 0, m_ = 0, nc_ = 0, rank_ = 0;
  double first_ = 0.0, abs_tol_ = 0.0, rel_tol_ = 0.0;
};

}  // namespace qpcoord

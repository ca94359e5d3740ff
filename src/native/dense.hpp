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
#include <limits>
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
    orig_.setZero(max_cols_);
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
    for (int j = 0; j < nc_; ++j) {
      perm_[j] = j;
      norms_(j) = A.col(j).norm();  // partial norms, downdated as rows are eliminated
      orig_(j) = norms_(j);
    }
    rank_ = 0;
    first_ = 0.0;
    const double tol3z = std::sqrt(std::numeric_limits<double>::epsilon());
    for (int j = 0; j < steps; ++j) {
      // pivot: the remaining column of largest (downdated) norm, as LAPACK's dlaqp2
      int p = j;
      double best = -1.0;
      for (int c = j; c < nc_; ++c) {
        if (norms_(c) > best) {
          best = norms_(c);
          p = c;
        }
      }
      if (p != j) {
        A.col(j).swap(A.col(p));
        std::swap(perm_[j], perm_[p]);
        std::swap(norms_(j), norms_(p));
        std::swap(orig_(j), orig_(p));
      }
      // the rank decision on the pivot's exact norm
      const double pn = A.col(j).segment(j, m_ - j).norm();
      if (j == 0) first_ = pn;
      if (!(pn > abs_tol) || !(pn > rel_tol * first_) || pn == 0.0) break;
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
      // apply to the trailing columns: H_j A(j:m, j+1:nc), v = [1; A(j+1:m, j)]
      const int len = m_ - j - 1;
      for (int c = j + 1; c < nc_; ++c) {
        auto ac = A.col(c).segment(j, m_ - j);
        const double w = ac(0) + A.col(j).segment(j + 1, len).dot(ac.tail(len));
        const double tw = tau * w;
        ac(0) -= tw;
        ac.tail(len) -= tw * A.col(j).segment(j + 1, len);
        downdate_norm(A, j, c, tol3z);
      }
      ++rank_;
    }
    return rank_;
  }

  int rank() const { return rank_; }
  int rows() const { return m_; }
  int cols() const { return nc_; }
  double first_pivot() const { return first_; }
  /// tau of reflector j (H_j = I - tau_j v_j v_j^T).
  double tau(int j) const { return tau_(j); }
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
  /// B <- B Qf (B: p x m), through a workspace of p doubles; in a build with FMA (kWyRight)
  /// and after reserve_wy, a B of at least kWyMinRows rows, at least kWyMinReflectors
  /// reflectors and at most m / 3 (the WY form's extra flops, about 4 p k^2 + m k^2 over the
  /// loop's 4 p m k, stay small beside the products' higher speed), by the compact WY form
  /// instead.
  template <typename B>
  void apply_q_right(B&& b) {
    if (kWyRight && wy_rows_ > 0 && rank_ >= kWyMinReflectors && 3 * rank_ <= m_ &&
        b.rows() >= kWyMinRows && b.rows() <= wy_rows_) {
      apply_q_right_wy(b);
      return;
    }
    for (int j = 0; j < rank_; ++j) reflect_right(j, b);
  }
  /// Buffers of the compact WY form (apply_q_right in a kWyRight build) for right-hand matrices
  /// of up to max_right_rows rows: no later call allocates.
  void reserve_wy(int max_right_rows) {
    wy_rows_ = std::max(max_right_rows, 1);
    wy_v_.setZero(max_rows_, max_cols_);
    wy_t_.setZero(max_cols_, max_cols_);
    wy_w_.setZero(wy_rows_, max_cols_);
    wy_w2_.setZero(wy_rows_, max_cols_);
  }
  /// B <- B Qf by the compact WY form (LAPACK's dlarft and dlarfb): Qf = H_0 ... H_{k-1}
  /// = I - V T V^T (V the unit lower trapezoidal reflectors, T upper triangular k x k), so
  /// B Qf = B - ((B V) T) V^T by matrix products (GEMM), where the loop above takes one
  /// matrix-vector product and one rank-one update per reflector. The same transform, its
  /// sums in another order. The Z of a wide level (88 x 86, 21 reflectors on the humanoid).
  template <typename B>
  void apply_q_right_wy(B&& b) {
    const int k = rank_, m = m_, p = static_cast<int>(b.rows());
    const auto A = cmatrix();
    auto V = wy_v_.topLeftCorner(m, k);
    for (int j = 0; j < k; ++j) {
      V.col(j).head(j).setZero();
      V(j, j) = 1.0;
      V.col(j).tail(m - j - 1) = A.col(j).tail(m - j - 1);
    }
    auto T = wy_t_.topLeftCorner(k, k);
    T.setZero();
    auto t = work_.head(k);
    for (int j = 0; j < k; ++j) {
      // T(0:j, j) = -tau_j T(0:j, 0:j) V(j:m, 0:j)^T v_j(j:m)  (v_j is zero above row j)
      if (j > 0) {
        t.head(j).noalias() = V.block(j, 0, m - j, j).transpose() * V.col(j).tail(m - j);
        for (int i = 0; i < j; ++i) {
          double s = 0.0;
          for (int l = i; l < j; ++l) s += T(i, l) * t(l);
          T(i, j) = -tau_(j) * s;
        }
      }
      T(j, j) = tau_(j);
    }
    auto W = wy_w_.topLeftCorner(p, k);
    auto W2 = wy_w2_.topLeftCorner(p, k);
    W.noalias() = b * V;
    W2.noalias() = W * T;
    b.noalias() -= W2 * V.transpose();
    ++wy_applications;
  }
  /// apply_q_right takes the compact WY form where it applies (see reserve_wy) in a build
  /// with FMA (the x86-64-v3 module), where its matrix products are faster than one
  /// reflector at a time; without FMA the loop is as fast and takes fewer instructions.
#if defined(__FMA__)
  static constexpr bool kWyRight = true;
#else
  static constexpr bool kWyRight = false;
#endif
  /// apply_q_right_wy only from this many reflectors on (fewer: the loop's overhead is lower)
  static constexpr int kWyMinReflectors = 16;
  /// ... and for a B of at least this many rows
  static constexpr int kWyMinRows = 24;
  /// apply_q_right calls that took the WY form since the counter was last reset (by its owner).
  int wy_applications = 0;
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
  /// Solve R11 X = B(0:rank, :) in place (B: at least rank rows).
  template <typename B>
  void solve_r_matrix(B&& b) const {
    const auto A = cmatrix();
    A.topLeftCorner(rank_, rank_).template triangularView<Eigen::Upper>().solveInPlace(
        b.topRows(rank_));
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
  /// Downdate the partial norm of column c by its entry A(j, c) just eliminated (LAPACK's
  /// dlaqp2); recompute it on cancellation.
  EIGEN_ALWAYS_INLINE void downdate_norm(MapMat& A, int j, int c, double tol3z) {
    if (norms_(c) == 0.0) return;
    double t = std::abs(A(j, c)) / norms_(c);
    t = std::max(0.0, (1.0 + t) * (1.0 - t));
    const double r = norms_(c) / orig_(c);
    if (t * r * r <= tol3z) {
      norms_(c) = A.col(c).segment(j + 1, m_ - j - 1).norm();
      orig_(c) = norms_(c);
    } else {
      norms_(c) *= std::sqrt(t);
    }
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

  Vec buf_, tau_, norms_, orig_, work_;
  Mat wy_v_, wy_t_, wy_w_, wy_w2_;  ///< compact WY buffers (reserve_wy)
  int wy_rows_ = 0;
  std::vector<int> perm_;
  int max_rows_ = 0, max_cols_ = 0, m_ = 0, nc_ = 0, rank_ = 0;
  double first_ = 0.0, abs_tol_ = 0.0, rel_tol_ = 0.0;
};

/// RZ factorisation of an upper trapezoidal T = [R11 R12] (rank x nc, R11 upper triangular;
/// LAPACK's xTZRZF): T = [R 0] Z, Z = H_0 H_1 ... H_{rank-1}, H_i = I - tau_i v_i v_i^T with
/// v_i(i) = 1 and v_i nonzero only at i and at rank..nc-1. Each H_i folds row i's R12 part
/// into its diagonal, from the last row up: about 4 rank^2 (nc - rank) flops, where the QR of
/// T^T takes about 2 nc rank^2. The minimum-norm solution of T u = b is u = Z^T [R^-1 b; 0],
/// and Z^T [I; 0] is an orthonormal basis of T's row space. T^T is stored (nc x rank,
/// column-major): row i of T, and v_i's tail, are contiguous. No heap use after reserve().
class TrapezoidRZ {
 public:
  void reserve(int max_rank, int max_cols) {
    max_rank_ = std::max(max_rank, 1);
    max_cols_ = std::max(max_cols, 1);
    buf_.setZero(static_cast<Eigen::Index>(max_rank_) * max_cols_);
    tau_.setZero(max_rank_);
  }
  /// T^T (nc x rank) to fill before factor(): its column i is row i of T from entry i down
  /// (the entries above are not read).
  MapMat matrix(int rank, int nc) {
    rank_ = rank;
    nc_ = nc;
    return MapMat(buf_.data(), nc, rank, Eigen::OuterStride<>(std::max(nc, 1)));
  }
  int rank() const { return rank_; }
  int cols() const { return nc_; }

  /// Factorise in place; false when R is singular (a zero diagonal).
  bool factor() {
    MapMat B(buf_.data(), nc_, rank_, Eigen::OuterStride<>(std::max(nc_, 1)));
    const int l = nc_ - rank_;
    for (int i = rank_ - 1; i >= 0; --i) {
      auto v = B.col(i).tail(l);
      const double alpha = B(i, i);
      const double xn2 = v.squaredNorm();
      if (xn2 == 0.0) {
        tau_(i) = 0.0;
        if (alpha == 0.0) return false;
        continue;
      }
      const double beta = -std::copysign(std::sqrt(alpha * alpha + xn2), alpha);
      const double tau = (beta - alpha) / beta;
      tau_(i) = tau;
      v /= (alpha - beta);
      B(i, i) = beta;
      // rows j < i of T (columns of B): r <- r H_i on entries i and rank..
      const double* vp = &B(rank_, i);
      for (int j = 0; j < i; ++j) {
        double* t = &B(rank_, j);
        double d = B(i, j);
        for (int q = 0; q < l; ++q) d += t[q] * vp[q];
        const double sj = tau * d;
        B(i, j) -= sj;
        for (int q = 0; q < l; ++q) t[q] -= sj * vp[q];
      }
    }
    return true;
  }
  /// v <- Z^T v = H_{rank-1} ... H_0 v (v: nc).
  template <typename V>
  void apply_zt(V&& x) const {
    const auto B = cmatrix();
    const int l = nc_ - rank_;
    for (int i = 0; i < rank_; ++i) {
      if (tau_(i) == 0.0) continue;
      // plain loops over the short tail (l = nc - rank entries): Eigen's dot on these
      // block types is the one PivotedQR::reflect uses, which GCC inlines there only while
      // it has a single caller
      const double* v = B.data() + static_cast<Eigen::Index>(i) * B.outerStride() + rank_;
      double d = x(i);
      for (int t = 0; t < l; ++t) d += v[t] * x(rank_ + t);
      const double s = tau_(i) * d;
      x(i) -= s;
      for (int t = 0; t < l; ++t) x(rank_ + t) -= s * v[t];
    }
  }
  /// The minimum-norm solution of T u = b (b: rank, u: nc).
  template <typename B_, typename V>
  void min_norm_solve(const B_& b, V&& u) const {
    const auto B = cmatrix();
    u.head(rank_) = b;
    u.tail(nc_ - rank_).setZero();
    // R w = b with R^T the lower triangle of B's top rank x rank block
    B.topRows(rank_).transpose().template triangularView<Eigen::Upper>().solveInPlace(
        u.head(rank_));
    apply_zt(u);
  }

 private:
  Eigen::Map<const Mat, 0, Eigen::OuterStride<>> cmatrix() const {
    return Eigen::Map<const Mat, 0, Eigen::OuterStride<>>(buf_.data(), nc_, rank_,
                                                           Eigen::OuterStride<>(std::max(nc_, 1)));
  }
  Vec buf_, tau_;
  int max_rank_ = 1, max_cols_ = 1, rank_ = 0, nc_ = 0;
};

/// The QR of the active set's working-set matrix G_w^T (k x kw) kept up to date as rows
/// enter (one Householder reflector appended) and leave (the column deleted from R and the
/// Hessenberg part restored by Givens rotations: a downdate, no refactorisation).
///
///   A P = Qf [R; 0],  Qf^T = S_m ... S_1,
/// with S_t the transforms in the order they were made: the reflectors of the pivoted
/// factorisation, then one reflector per appended column and a Givens rotation per row of R
/// restored after a deletion. R (rank x nc, upper triangular, full column rank after an
/// update) lives in its own buffer; the transform list has a fixed capacity (an update that
/// would overflow it returns false: the caller refactorises). No heap use after reserve().
class WorkingQR {
 public:
  void reserve(int max_rows, int max_cols, int max_right_rows) {
    max_rows_ = std::max(max_rows, 1);
    max_cols_ = std::max(max_cols, 1);
    base_.reserve(max_rows_, max_cols_, max_right_rows);
    // R: at most rank <= max_rows rows
    R_.setZero(static_cast<Eigen::Index>(max_rows_) * max_cols_);
    max_h_ = 2 * max_rows_ + 8;
    H_.setZero(static_cast<Eigen::Index>(max_rows_) * max_h_);
    htau_.setZero(max_h_);
    hpos_.assign(max_h_, 0);
    max_g_ = 8 * max_rows_ + 16;
    gc_.setZero(max_g_);
    gs_.setZero(max_g_);
    gi_.assign(max_g_, 0);
    seq_.reserve(max_h_ + max_g_);
    perm_.assign(max_cols_, 0);
    work_.setZero(std::max({max_rows_, max_cols_, max_right_rows, 1}));
  }

  /// The k x kw matrix to fill before factor().
  MapMat matrix(int k, int kw) { return base_.matrix(k, kw); }

  /// Pivoted Householder QR of matrix() (see PivotedQR::factor); returns the rank.
  int factor(double abs_tol, double rel_tol) {
    rank_ = base_.factor(abs_tol, rel_tol);
    m_ = base_.rows();
    nc_ = base_.cols();
    abs_tol_ = abs_tol;
    rel_tol_ = rel_tol;
    first_ = base_.first_pivot();
    const MapMat A = base_.matrix();
    // R: the first rank rows of the factorised matrix (upper triangle)
    for (int j = 0; j < nc_; ++j) {
      auto rc = rcol(j);
      const int top = std::min(j + 1, rank_);
      rc.head(top) = A.col(j).head(top);
      if (top < rank_) rc.segment(top, rank_ - top).setZero();
      perm_[j] = base_.perm(j);
    }
    // the reflectors, as full-length vectors (v(pos) = 1, zeros above)
    seq_.clear();
    nh_ = ng_ = 0;
    for (int j = 0; j < rank_; ++j) {
      auto v = hcol(nh_);
      v.head(j).setZero();
      v(j) = 1.0;
      v.segment(j + 1, m_ - j - 1) = A.col(j).segment(j + 1, m_ - j - 1);
      htau_(nh_) = base_.tau(j);
      hpos_[nh_] = j;
      seq_.push_back(nh_++);
    }
    return rank_;
  }

  int rank() const { return rank_; }
  int rows() const { return m_; }
  int cols() const { return nc_; }
  /// Column i of R comes from column perm(i) of A.
  int perm(int i) const { return perm_[i]; }

  /// v <- Qf^T v (v: m).
  template <typename V>
  void apply_qt(V&& v) const {
    for (const int t : seq_) {
      if (t >= 0)
        reflect(t, v);
      else
        rotate(-t - 1, v, false);
    }
  }
  /// v <- Qf v (v: m).
  template <typename V>
  void apply_q(V&& v) const {
    for (auto it = seq_.rbegin(); it != seq_.rend(); ++it) {
      if (*it >= 0)
        reflect(*it, v);
      else
        rotate(-*it - 1, v, true);
    }
  }
  /// B <- B Qf (B: p x m).
  template <typename B>
  void apply_q_right(B&& b) {
    for (const int t : seq_) right(t, b);
  }
  /// B <- B S_last^T (the transform the last append made).
  template <typename B>
  void apply_last_right(B&& b) {
    right(seq_.back(), b);
  }

  /// Append a column a (m entries) to a factorisation of full column rank: false (nothing
  /// changed) if it is rank-deficient, full, a is dependent to the factorisation's
  /// tolerance, or the transform list is full: then factor() again.
  template <typename A_>
  bool append(const A_& a) {
    if (rank_ != nc_ || nc_ >= max_cols_ || rank_ >= m_ || nh_ >= max_h_) return false;
    const int j = nc_;
    auto col = work_.head(m_);
    col = a;
    apply_qt(col);
    const double pn = col.tail(m_ - j).norm();
    const double ref = (j == 0) ? pn : first_;
    if (!(pn > abs_tol_) || !(pn > rel_tol_ * ref) || pn == 0.0) return false;
    if (j == 0) first_ = pn;
    const double x0 = col(j);
    const double beta = (x0 >= 0.0) ? -pn : pn;
    const double v0 = x0 - beta;
    auto v = hcol(nh_);
    v.head(j).setZero();
    v(j) = 1.0;
    double tau = 0.0;
    if (v0 != 0.0) {
      v.segment(j + 1, m_ - j - 1) = col.segment(j + 1, m_ - j - 1) / v0;
      tau = (beta - x0) / beta;
    } else {
      v.segment(j + 1, m_ - j - 1).setZero();
    }
    auto rc = rcol(j);
    rc.head(j) = col.head(j);
    rc(j) = beta;
    htau_(nh_) = tau;
    hpos_[nh_] = j;
    seq_.push_back(nh_++);
    perm_[j] = j;
    ++nc_;
    ++rank_;
    return true;
  }

  /// Delete column jcol of A (full column rank): its column of R goes, the Givens rotations
  /// that restore the triangle are recorded and applied to the columns of B (B <- B G^T,
  /// p x m: the objective in the QR's basis); columns of A after jcol shift left. False
  /// (nothing changed) when rank-deficient or the transform list is full: factor() again.
  template <typename B>
  bool remove(int jcol, B&& b) {
    if (rank_ != nc_ || jcol < 0 || jcol >= nc_) return false;
    int i0 = -1;
    for (int i = 0; i < nc_; ++i)
      if (perm_[i] == jcol) i0 = i;
    if (i0 < 0 || ng_ + (nc_ - 1 - i0) > max_g_) return false;
    // shift R's columns i0+1.. left (upper Hessenberg from column i0 on)
    for (int j = i0; j + 1 < nc_; ++j) {
      rcol(j).head(j + 2) = rcol(j + 1).head(j + 2);
      perm_[j] = perm_[j + 1];
    }
    --nc_;
    for (int j = 0; j < nc_; ++j)
      if (perm_[j] > jcol) --perm_[j];
    // Givens on rows (i, i+1) zero the subdiagonal R(i+1, i), i = i0 .. nc-1
    for (int i = i0; i < nc_; ++i) {
      const double a = R_(idx(i, i)), bb = R_(idx(i + 1, i));
      const double r = std::hypot(a, bb);
      double c = 1.0, s = 0.0;
      if (r != 0.0) {
        c = a / r;
        s = bb / r;
      }
      for (int j = i; j < nc_; ++j) {
        const double ri = R_(idx(i, j)), rn = R_(idx(i + 1, j));
        R_(idx(i, j)) = c * ri + s * rn;
        R_(idx(i + 1, j)) = -s * ri + c * rn;
      }
      R_(idx(i + 1, i)) = 0.0;
      gc_(ng_) = c;
      gs_(ng_) = s;
      gi_[ng_] = i;
      seq_.push_back(-(ng_++) - 1);
      right(seq_.back(), b);
    }
    rank_ = nc_;
    return true;
  }

  /// Solve R11 u = rhs(0:rank) in place.
  template <typename V>
  void solve_r(V&& rhs) const {
    rmat().topLeftCorner(rank_, rank_).template triangularView<Eigen::Upper>().solveInPlace(
        rhs.head(rank_));
  }
  /// Solve R11^T u = rhs(0:rank) in place.
  template <typename V>
  void solve_rt(V&& rhs) const {
    rmat().topLeftCorner(rank_, rank_).transpose().template triangularView<Eigen::Lower>()
        .solveInPlace(rhs.head(rank_));
  }

 private:
  Eigen::Index idx(int i, int j) const { return static_cast<Eigen::Index>(j) * max_rows_ + i; }
  Eigen::Map<Vec> rcol(int j) { return Eigen::Map<Vec>(R_.data() + idx(0, j), max_rows_); }
  Eigen::Map<const Mat, 0, Eigen::OuterStride<>> rmat() const {
    return Eigen::Map<const Mat, 0, Eigen::OuterStride<>>(R_.data(), max_rows_, max_cols_,
                                                          Eigen::OuterStride<>(max_rows_));
  }
  Eigen::Map<Vec> hcol(int t) {
    return Eigen::Map<Vec>(H_.data() + static_cast<Eigen::Index>(t) * max_rows_, m_);
  }
  Eigen::Map<const Vec> hcol(int t) const {
    return Eigen::Map<const Vec>(H_.data() + static_cast<Eigen::Index>(t) * max_rows_, m_);
  }
  template <typename V>
  void reflect(int t, V& v) const {
    const int p = hpos_[t], len = m_ - p;
    const auto h = hcol(t).segment(p, len);
    const double tw = htau_(t) * h.dot(v.segment(p, len));
    v.segment(p, len) -= tw * h;
  }
  template <typename V>
  void rotate(int g, V& v, bool transpose) const {
    const int i = gi_[g];
    const double c = gc_(g), s = transpose ? -gs_(g) : gs_(g);
    const double a = v(i), b = v(i + 1);
    v(i) = c * a + s * b;
    v(i + 1) = -s * a + c * b;
  }
  /// B <- B S_t^T: a reflector (symmetric) or the transpose of a rotation.
  template <typename B>
  void right(int t, B& b) {
    if (t >= 0) {
      const int p = hpos_[t], len = m_ - p;
      const auto h = hcol(t).segment(p, len);
      auto w = work_.head(b.rows());
      w.noalias() = b.middleCols(p, len) * h;
      w *= htau_(t);
      b.middleCols(p, len).noalias() -= w * h.transpose();
    } else {
      const int g = -t - 1, i = gi_[g];
      const double c = gc_(g), s = gs_(g);
      for (Eigen::Index r = 0; r < b.rows(); ++r) {
        const double x = b(r, i), y = b(r, i + 1);
        b(r, i) = c * x + s * y;
        b(r, i + 1) = -s * x + c * y;
      }
    }
  }

  PivotedQR base_;
  Vec R_, H_, htau_, gc_, gs_, work_;
  std::vector<int> hpos_, gi_, perm_, seq_;
  int max_rows_ = 0, max_cols_ = 0, max_h_ = 0, max_g_ = 0, nh_ = 0, ng_ = 0;
  int m_ = 0, nc_ = 0, rank_ = 0;
  double first_ = 0.0, abs_tol_ = 0.0, rel_tol_ = 0.0;
};

}  // namespace qpcoord

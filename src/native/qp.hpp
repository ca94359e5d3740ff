// qpcoord native engine: a dense Goldfarb-Idnani dual active-set QP solver (as quadprog),
// on preallocated buffers, with a warm start from a stored working set.
//
//   min 1/2 y^T H y + f^T y   s.t.   lo_i <= g_i^T y <= hi_i  (rows of G; +-inf: no side)
//
// H = L L^T is positive definite; the caller gives J0 = L^{-T} and the unconstrained optimum
// y_u = -H^{-1} f (the objective enters only through them). The method (Goldfarb & Idnani
// 1983, the algorithm of quadprog and eiquadprog) keeps a dual-feasible point: the optimum on a
// working set A with multipliers u >= 0; each iteration picks the most violated row, steps
// towards it (dropping rows whose multiplier reaches zero) and adds it. J = L^{-T} Q and the
// upper-triangular R with J^T N_A = [R; 0] are updated by Givens rotations (no refactoring).
//
// Warm start: the stored working set (one-sided row ids) is factored first; the optimum on it
// (y = y_u + J_1 R^{-T} (b_A - N_A^T y_u), u = R^{-1} R^{-T} (b_A - N_A^T y_u)) is a valid
// dual-feasible start when every u >= 0, and the iterations continue from there (a hit: no
// iteration when nothing is violated); else the solve starts cold from y_u.
//
// Row ids: c = 2 i (lower side g_i^T y >= lo_i) and c = 2 i + 1 (upper side -g_i^T y >= -hi_i).
#pragma once

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <vector>

namespace qpcoord {
namespace qp {

using Mat = Eigen::MatrixXd;
using Vec = Eigen::VectorXd;

enum Result : int {
  kSolved = 0,
  kInfeasible = 1,  ///< a violated row cannot be met (violation in `violation`, row in `row`)
  kMaxIter = 2,
  kTimeout = 3,
};

class DualActiveSet {
 public:
  /// Size the buffers once: no later solve allocates for nv <= max_vars, rows <= max_rows.
  void reserve(int max_vars, int max_rows) {
    J_.setZero(max_vars, max_vars);
    R_.setZero(max_vars, max_vars);
    d_.setZero(max_vars);
    z_.setZero(max_vars);
    r_.setZero(max_vars);
    u_.setZero(max_vars + 1);
    v_.setZero(max_vars);
    act_.assign(max_vars + 1, -1);
    state_.assign(2 * std::max(max_rows, 1), 0);
    stored_.reserve(max_vars + 1);
    stored_.clear();
  }

  /// Forget the stored working set (the next warm solve starts cold).
  void forget() {
    stored_.clear();
    kept_ = false;
  }
  /// J0 or the rows changed (a new set-up): the kept factors of the stored working set are
  /// stale; the next warm solve factors the stored set again.
  void invalidate() { kept_ = false; }

  int iterations = 0;      ///< iterations of the last solve (rows added or dropped)
  bool warm_hit = false;   ///< the stored working set was optimal (no iteration)
  bool warm_used = false;  ///< the stored working set gave the start
  double violation = 0.0;  ///< kInfeasible: the violation of the row that cannot be met
  int row = -1;            ///< kInfeasible: that row
  int active = 0;          ///< size of the final working set
  /// Final working set (one-sided ids c), valid after a solve.
  const std::vector<int>& working_set() const { return stored_; }

  /// Solve. G: rows x nv (any Eigen expression with .row()); tol_lo/tol_hi: the absolute
  /// violation each side may keep (the tolerance rule of the caller); first_tol_lo/hi: the
  /// tolerance of the first scan of a cold start (the unconstrained optimum's acceptance
  /// test). y: in y_u, out the optimum.
  template <typename GMat>
  int solve(int nv, const GMat& G, const Eigen::Ref<const Vec>& lo, const Eigen::Ref<const Vec>& hi,
            const Eigen::Ref<const Vec>& tol_lo, const Eigen::Ref<const Vec>& tol_hi,
            const Eigen::Ref<const Vec>& first_tol_lo, const Eigen::Ref<const Vec>& first_tol_hi,
            const Eigen::Ref<const Mat>& J0, Eigen::Ref<Vec> y, bool warm, int max_iter,
            bool has_deadline, std::chrono::steady_clock::time_point deadline) {
    const int m = static_cast<int>(lo.size());
    nv_ = nv;
    iterations = 0;
    warm_hit = false;
    warm_used = false;
    violation = 0.0;
    row = -1;
    auto J = J_.topLeftCorner(nv, nv);
    for (int c = 0; c < 2 * m; ++c) state_[c] = 0;  // 0 free, 1 active, 2 ignored
    iq_ = 0;
    bool first = true;
    bool kept_ok = kept_ && warm && nv == kept_nv_;
    for (int k = 0; kept_ok && k < static_cast<int>(stored_.size()); ++k) {
      const int c = stored_[k], i = c >> 1;
      if (i >= m || !std::isfinite((c & 1) ? hi(i) : lo(i))) kept_ok = false;
    }
    kept_ = false;
    if (kept_ok) {
      // the matrices are those of the last solve: J and R of its final working set are
      // still the factors of the stored set (only b moved), no refactoring
      iq_ = static_cast<int>(stored_.size());
      for (int k = 0; k < iq_; ++k) {
        act_[k] = stored_[k];
        state_[stored_[k]] = 1;
      }
    } else if (warm && !stored_.empty()) {
      // y_u is in y: factor the stored rows, then the optimum on them
      J = J0.topLeftCorner(nv, nv);
      double rnorm = 1.0;
      for (const int c : stored_) {
        const int i = c >> 1;
        if (i >= m || state_[c] || !std::isfinite((c & 1) ? hi(i) : lo(i))) continue;
        normal(G, c, nv);
        d_.head(nv).noalias() = J.transpose() * v_.head(nv);
        if (!add(rnorm)) continue;
        act_[iq_ - 1] = c;
        state_[c] = 1;
      }
    }
    {
      if (iq_ > 0) {
        // v = b_A - N_A^T y_u; R^T w = v; y = y_u + J_1 w; u = R^{-1} w
        auto w = r_.head(iq_);
        for (int k = 0; k < iq_; ++k) {
          const int c = act_[k], i = c >> 1;
          const double g = G.row(i).head(nv).dot(y);
          w(k) = (c & 1) ? (-hi(i) + g) : (lo(i) - g);
        }
        const auto Rk = R_.topLeftCorner(iq_, iq_);
        Rk.transpose().template triangularView<Eigen::Lower>().solveInPlace(w);
        y.noalias() += J.leftCols(iq_) * w;
        auto u = u_.head(iq_);
        u = w;
        Rk.template triangularView<Eigen::Upper>().solveInPlace(u);
        // a negative multiplier beyond rounding (relative to the largest one: with levels
        // weighted down to rho^k, the multipliers of a low level's rows are tiny, and an
        // absolute threshold would keep a row that the optimum releases)
        const double umax = u.cwiseAbs().maxCoeff();
        bool ok = y.allFinite() && u.allFinite();
        for (int k = 0; ok && k < iq_; ++k) {
          if (u(k) < -1e-12 * umax) ok = false;
          else if (u(k) < 0.0) u(k) = 0.0;
        }
        if (ok) {
          warm_used = true;
          first = false;
        } else {  // not dual feasible: cold (y back to y_u)
          y.noalias() -= J.leftCols(iq_) * w;
          for (int k = 0; k < iq_; ++k) state_[act_[k]] = 0;
          iq_ = 0;
        }
      }
    }
    if (iq_ == 0) J = J0.topLeftCorner(nv, nv);
    int status = kSolved;
    for (;;) {
      // the most violated row (relative to its tolerance)
      int ip = -1;
      double best = 0.0, s_ip = 0.0;
      for (int i = 0; i < m; ++i) {
        const bool flo = std::isfinite(lo(i)), fhi = std::isfinite(hi(i));
        if (!flo && !fhi) continue;
        const double g = G.row(i).head(nv).dot(y);
        if (flo && !state_[2 * i]) {
          const double s = lo(i) - g;  // > 0: violated
          const double tol = first ? first_tol_lo(i) : tol_lo(i);
          if (s > tol && s / std::max(tol, 1e-300) > best) {
            best = s / std::max(tol, 1e-300);
            ip = 2 * i;
            s_ip = -s;
          }
        }
        if (fhi && !state_[2 * i + 1]) {
          const double s = g - hi(i);
          const double tol = first ? first_tol_hi(i) : tol_hi(i);
          if (s > tol && s / std::max(tol, 1e-300) > best) {
            best = s / std::max(tol, 1e-300);
            ip = 2 * i + 1;
            s_ip = -s;
          }
        }
      }
      first = false;
      if (ip < 0) break;
      u_(iq_) = 0.0;
      normal(G, ip, nv);
      // s_ip = n_ip^T y - b_ip < 0 (the violation, negative)
      bool added = false;
      while (!added) {
        if (++iterations > max_iter) return finish(kMaxIter);
        if (has_deadline && std::chrono::steady_clock::now() >= deadline) return finish(kTimeout);
        d_.head(nv).noalias() = J.transpose() * v_.head(nv);
        // z = J_2 d_2 (the primal step), r = R^{-1} d_1 (the dual step)
        z_.head(nv).noalias() = J.rightCols(nv - iq_) * d_.segment(iq_, nv - iq_);
        auto r = r_.head(iq_);
        r = d_.head(iq_);
        R_.topLeftCorner(iq_, iq_).template triangularView<Eigen::Upper>().solveInPlace(r);
        double t1 = kInf;
        int l = -1;
        for (int k = 0; k < iq_; ++k) {
          if (r(k) > 0.0) {
            const double q = u_(k) / r(k);
            if (q < t1) {
              t1 = q;
              l = k;
            }
          }
        }
        const double zn = z_.head(nv).dot(v_.head(nv));  // = |d_2|^2 >= 0
        const double t2 = (zn > kTiny * d_.head(nv).squaredNorm())
                              ? -s_ip / zn
                              : kInf;
        const double t = std::min(t1, t2);
        if (!(t < kInf)) {
          // no step meets the row: infeasible, unless its violation is within the first
          // scan's tolerance (a set thinner than rounding: the row is left out)
          const int i = ip >> 1;
          if (-s_ip <= ((ip & 1) ? first_tol_hi(i) : first_tol_lo(i))) {
            state_[ip] = 2;
            break;
          }
          violation = -s_ip;
          row = ip >> 1;
          return finish(kInfeasible);
        }
        if (!(t2 < kInf)) {  // dual step only
          u_.head(iq_) -= t * r;
          u_(iq_) += t;
          drop(l);
          continue;
        }
        y.noalias() += t * z_.head(nv);
        u_.head(iq_) -= t * r;
        u_(iq_) += t;
        if (t == t2) {
          const double keep_u = u_(iq_);
          if (!add(1.0)) {  // rounding: the row is (numerically) met; ignore it
            state_[ip] = 2;
            break;
          }
          u_(iq_ - 1) = keep_u;
          act_[iq_ - 1] = ip;
          state_[ip] = 1;
          added = true;
        } else {
          drop(l);
          const int i = ip >> 1;
          const double g = G.row(i).head(nv).dot(y);
          s_ip = (ip & 1) ? (hi(i) - g) : (g - lo(i));
          if (s_ip >= 0.0) break;  // met by the dual step's move
        }
      }
    }
    return finish(status);
  }

 private:
  static constexpr double kInf = std::numeric_limits<double>::infinity();
  static constexpr double kTiny = 1e-20;  // |d_2|^2 / |d|^2 under it: z = 0

  int finish(int status) {
    stored_.clear();
    for (int k = 0; k < iq_; ++k) stored_.push_back(act_[k]);
    active = iq_;
    kept_ = status == kSolved;  // J, R: the factors of the stored set (for the next call)
    kept_nv_ = nv_;
    if (status == kSolved && iterations == 0 && warm_used) warm_hit = true;
    return status;
  }

  template <typename GMat>
  void normal(const GMat& G, int c, int nv) {
    const int i = c >> 1;
    if (c & 1)
      v_.head(nv) = -G.row(i).head(nv).transpose();
    else
      v_.head(nv) = G.row(i).head(nv).transpose();
  }

  /// Append the row whose J^T n is in d_: rotate d_(iq..nv-1) into d_(iq) (columns of J
  /// alike), R's new column = d_(0..iq). False (nothing appended) if the row depends on the
  /// working set's rows.
  bool add(double /*unused*/) {
    const int nv = nv_;
    auto J = J_.topLeftCorner(nv, nv);
    for (int j = nv - 1; j > iq_; --j) {
      const double a = d_(j - 1), b = d_(j);
      if (b == 0.0) continue;
      const double h = std::hypot(a, b);
      const double c = a / h, s = b / h;
      d_(j - 1) = h;
      d_(j) = 0.0;
      for (int k = 0; k < nv; ++k) {
        const double p = J(k, j - 1), q = J(k, j);
        J(k, j - 1) = c * p + s * q;
        J(k, j) = -s * p + c * q;
      }
    }
    if (iq_ >= nv) return false;
    const double scale = std::max(d_.head(iq_ + 1).cwiseAbs().maxCoeff(), 1e-300);
    if (std::abs(d_(iq_)) <= 1e-12 * scale) return false;
    R_.col(iq_).head(iq_ + 1) = d_.head(iq_ + 1);
    ++iq_;
    return true;
  }

  /// Remove the working-set row at position l; restore R's triangle by Givens rotations.
  void drop(int l) {
    const int nv = nv_;
    auto J = J_.topLeftCorner(nv, nv);
    state_[act_[l]] = 0;  // free again: it may come back
    for (int k = l; k < iq_ - 1; ++k) {
      act_[k] = act_[k + 1];
      u_(k) = u_(k + 1);
      R_.col(k).head(iq_) = R_.col(k + 1).head(iq_);
    }
    u_(iq_ - 1) = u_(iq_);  // the candidate's multiplier moves down
    --iq_;
    for (int j = l; j < iq_; ++j) {
      const double a = R_(j, j), b = R_(j + 1, j);
      if (b == 0.0) continue;
      const double h = std::hypot(a, b);
      const double c = a / h, s = b / h;
      R_(j, j) = h;
      R_(j + 1, j) = 0.0;
      for (int k = j + 1; k < iq_; ++k) {
        const double p = R_(j, k), q = R_(j + 1, k);
        R_(j, k) = c * p + s * q;
        R_(j + 1, k) = -s * p + c * q;
      }
      for (int k = 0; k < nv; ++k) {
        const double p = J(k, j), q = J(k, j + 1);
        J(k, j) = c * p + s * q;
        J(k, j + 1) = -s * p + c * q;
      }
    }
  }

  int nv_ = 0;
  int iq_ = 0;
  bool kept_ = false;
  int kept_nv_ = -1;
  Mat J_, R_;
  Vec d_, z_, r_, u_, v_;
  std::vector<int> act_;
  std::vector<char> state_;
  std::vector<int> stored_;
};

}  // namespace qp
}  // namespace qpcoord

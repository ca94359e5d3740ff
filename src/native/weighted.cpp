// qpcoord native engine: the weighted QP (weighted.hpp) and its nanobind binding.
#include "weighted.hpp"

#include "checks.hpp"

#ifndef QPCOORD_NO_BINDINGS  // defined by the C++-only tools (src/native/tools/)
#include <nanobind/eigen/dense.h>
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/vector.h>

#include "refresh.hpp"
#endif

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace qpcoord {

namespace {

using Mat = Eigen::MatrixXd;
using Vec = Eigen::VectorXd;

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kFeasTol = 1e-9;   // FEAS_TOL: the unconstrained optimum's acceptance, relative
constexpr double kQpTol = 1e-12;    // a row counts as violated in the active set, relative
constexpr double kSingular = 1e-14;  // methods/weighted.py _SINGULAR

inline double scale_of(double b) { return std::isfinite(b) ? std::max(1.0, std::abs(b)) : 1.0; }


/// Householder QR of W (m x k, m >= k) in place: R on and above the diagonal (R_jj = beta_j),
/// the vectors below it, their coefficients in tau (no allocation: work holds k entries).
/// Returns the smallest |R_jj|. The R of W, not the Cholesky of W^T W: a rank-deficient W
/// gives a diagonal entry at rounding of |W|, not of |W|^2.
double householder_qr(Eigen::Ref<Mat> W, Eigen::Ref<Vec> tau, Eigen::Ref<Vec> work) {
  const int m = static_cast<int>(W.rows()), k = static_cast<int>(W.cols());
  double dmin = kInf;
  for (int j = 0; j < k; ++j) {
    double beta = 0.0;
    W.col(j).tail(m - j).makeHouseholderInPlace(tau(j), beta);
    W(j, j) = beta;
    dmin = std::min(dmin, std::abs(beta));
    if (j + 1 < k)
      W.bottomRightCorner(m - j, k - j - 1)
          .applyHouseholderOnTheLeft(W.col(j).tail(m - j - 1), tau(j), work.data());
  }
  return dmin;
}

}  // namespace

Weighted::Weighted(int n, std::vector<int> meq, std::vector<int> min, bool has_bounds,
                   double regularization, double weight_ratio)
    : n_(n), meq_(std::move(meq)), min_(std::move(min)), has_bounds_(has_bounds),
      reg_(regularization), rho_(weight_ratio) {
  const int blocks = static_cast<int>(meq_.size());
  eq0_.assign(blocks, 0);
  in0_.assign(blocks, 0);
  int e = 0, c = 0;
  for (int b = 0; b < blocks; ++b) {
    eq0_[b] = e;
    in0_[b] = c;
    e += meq_[b];
    c += min_[b];
  }
  mes_ = e - (blocks ? meq_[0] : 0);
  ms_ = c - (blocks ? min_[0] : 0);
  rows_ = ms_ + (blocks ? min_[0] : 0) + (has_bounds_ ? n_ : 0);
  const int nv = n_ + ms_;
  const int me_h = blocks ? meq_[0] : 0;
  if (me_h) {
    Ah_.setZero(me_h, n_);
    svd_ = Eigen::JacobiSVD<Mat>(me_h, n_, Eigen::ComputeThinU | Eigen::ComputeFullV);
  }
  Z_.setZero(n_, n_);
  M_.setZero(std::max(mes_, 1), n_);
  beta_eq_.setZero(std::max(mes_, 1));
  beta_in_.setZero(std::max(ms_, 1));
  double beta = 1.0;
  for (int b = 1; b < blocks; ++b) {
    for (int i = 0; i < meq_[b]; ++i) beta_eq_(eq0_[b] - me_h + i) = beta;
    for (int i = 0; i < min_[b]; ++i) beta_in_(in0_[b] - min_[0] + i) = beta;
    beta *= rho_;
  }
  L_.setZero(n_, n_);
  J0_.setZero(std::max(nv, 1), std::max(nv, 1));
  G_.setZero(std::max(rows_, 1), std::max(nv, 1));
  xbar_.setZero(n_);
  x_.setZero(n_);
  y_.setZero(std::max(nv, 1));
  e_.setZero(std::max(e, 1));
  coef_.setZero(std::max(n_, 1));
  for (Vec* v : {&glo_, &ghi_, &tlo_, &thi_, &flo_, &fhi_}) v->setZero(std::max(rows_, 1));
  cx_.setZero(std::max(c, 1));
  qp_.reserve(std::max(nv, 1), std::max(rows_, 1));
  if (me_h) rows_buf_.setZero(std::max({mes_, ms_, min_[0], 1}), n_);
  Wq_.setZero(mes_ + std::max(n_, 1), n_);
  hh_.setZero(std::max(n_, 1));
  tau_.setZero(std::max(n_, 1));
  rhs_.setZero(mes_ + std::max(n_, 1));
}

int Weighted::setup(const MatC& Aeq, const MatC& C, const VecC& sw) {
  const int me_h = meq_[0], mi_h = min_[0];
  // elimination of the hard equalities: x = xbar + Z z
  if (me_h) {
    Ah_ = Aeq.topRows(me_h);
    svd_.compute(Ah_, Eigen::ComputeThinU | Eigen::ComputeFullV);
    rank_ = numerical_rank(svd_.singularValues(), me_h, n_);
    r_ = n_ - rank_;
    Z_.leftCols(r_) = svd_.matrixV().rightCols(r_);
  } else {
    rank_ = 0;
    r_ = n_;
    Z_.setIdentity();
  }
  const int r = r_;
  const int nv = r + ms_;
  // out = rows Z(:, 0:r) through a contiguous copy of rows: Eigen's product of a strided
  // (row-major) view makes a heap temporary on every call
  auto times_z = [&](const auto& rows, auto&& out) {
    auto buf = rows_buf_.topRows(rows.rows());
    buf = rows;
    out.noalias() = buf * Z_.leftCols(r);
  };
  // H = sum_k rho^k (A_k Z)^T (A_k Z) = W^T W is never formed: its factor L = R^T comes from
  // a Householder QR of W = diag(sqrt(rho^k)) M (H's Cholesky factor up to the signs of its
  // columns, without squaring W); hdiag: the x-space Hessian's largest diagonal entry
  double hdiag = 0.0;
  if (mes_) {
    const auto As = Aeq.middleRows(me_h, mes_);
    auto M = M_.topLeftCorner(mes_, r);
    if (me_h)
      times_z(As, M);
    else
      M = As;
    for (int j = 0; j < n_; ++j) {
      double d = 0.0;
      for (int i = 0; i < mes_; ++i) d += beta_eq_(i) * As(i, j) * As(i, j);
      hdiag = std::max(hdiag, d);
    }
  }
  // the Python rule (_SINGULAR): fewer weighted rows than r, or a diagonal entry^2 of the R
  // of W's QR at most 1e-14 of max diag H (the largest squared column norm of W)
  regularized_ = false;
  auto L = L_.topLeftCorner(r, r);
  bool singular = r && mes_ < r;
  if (r && !singular) {
    auto W = Wq_.topLeftCorner(mes_, r);
    for (int i = 0; i < mes_; ++i) W.row(i) = std::sqrt(beta_eq_(i)) * M_.row(i).head(r);
    double hmax = 1e-300;
    for (int j = 0; j < r; ++j) hmax = std::max(hmax, W.col(j).squaredNorm());
    const double d = householder_qr(W, tau_.head(r), hh_.head(r));
    singular = !(d * d > kSingular * hmax);  // NaN counts as singular
    if (!singular) L.template triangularView<Eigen::Lower>() = W.topRows(r).transpose();
  }
  if (singular) {
    // [W; sqrt(eps) I] factored: L for H + eps I, and the unconstrained optimum as its
    // least-squares solution (see Wq_)
    eps_ = reg_ * std::max(1.0, hdiag);
    regularized_ = true;
    auto Wa = Wq_.topLeftCorner(mes_ + r, r);
    Wa.setZero();
    for (int i = 0; i < mes_; ++i) Wa.row(i) = std::sqrt(beta_eq_(i)) * M_.row(i).head(r);
    Wa.bottomRows(r).diagonal().setConstant(std::sqrt(eps_));
    householder_qr(Wa, tau_.head(r), hh_.head(r));
    L.template triangularView<Eigen::Lower>() = Wa.topRows(r).transpose();
  }
  if (r && !(L.diagonal().cwiseAbs().minCoeff() > 0.0)) return kWNotConverged;
  // J0 = blockdiag(L^{-T}, 1 / (sqrt(rho^k) sw))
  auto J0 = J0_.topLeftCorner(nv, nv);
  J0.setZero();
  if (r) {
    J0.topLeftCorner(r, r).setIdentity();
    L.transpose().template triangularView<Eigen::Upper>().solveInPlace(J0.topLeftCorner(r, r));
  }
  const int in_soft = in0_.size() > 1 ? in0_[1] : 0;
  for (int s = 0; s < ms_; ++s) J0(r + s, r + s) = 1.0 / (std::sqrt(beta_in_(s)) * sw(in_soft + s));
  if (!J0.allFinite()) return kWNotConverged;
  // constraint rows in y = (z, w): soft rows [C Z, -e_s], hard inequalities [C Z, 0], bounds Z
  auto G = G_.topLeftCorner(rows_, nv);
  G.setZero();
  if (ms_) {
    if (me_h)
      times_z(C.middleRows(in_soft, ms_), G.topLeftCorner(ms_, r));
    else
      G.topLeftCorner(ms_, r) = C.middleRows(in_soft, ms_);
    for (int s = 0; s < ms_; ++s) G(s, r + s) = -1.0;
  }
  if (mi_h) {
    if (me_h)
      times_z(C.topRows(mi_h), G.block(ms_, 0, mi_h, r));
    else
      G.block(ms_, 0, mi_h, r) = C.topRows(mi_h);
  }
  if (has_bounds_) G.block(ms_ + mi_h, 0, n_, r) = Z_.leftCols(r);
  ready_ = true;
  return kWOk;
}

double Weighted::level_value(int k, const MatC& Aeq, const VecC& beq, const MatC& C,
                             const VecC& lo, const VecC& hi, const VecC& sw) const {
  const int b = k + 1;
  return qpcoord::level_value(Aeq, beq, eq0_[b], meq_[b], C, lo, hi, sw, in0_[b], min_[b], x_);
}

int Weighted::solve(const MatC& Aeq, const VecC& beq, const MatC& C, const VecC& lo,
                    const VecC& hi, const VecC& sw, const VecC& lb, const VecC& ub, bool warm,
                    double time_left, bool refactor, VecM x_out, VecM res_out, VecM detail,
                    VecM active) {
  const int Lv = num_levels();
  const int me = eq0_.back() + meq_.back();
  const int mi = in0_.back() + min_.back();
  const int me_h = meq_[0], mi_h = min_[0];
  if (Aeq.rows() != me || Aeq.cols() != n_ || beq.size() != me || C.rows() != mi ||
      C.cols() != n_ || lo.size() != mi || hi.size() != mi || sw.size() != mi ||
      lb.size() != n_ || ub.size() != n_ || x_out.size() != n_ || res_out.size() != Lv ||
      detail.size() < 8 || active.size() != n_ + me_h + mi_h + ms_)
    return kWBadInput;
  if (!Aeq.allFinite() || !beq.allFinite() || !C.allFinite() || !sw.allFinite() ||
      lo.hasNaN() || hi.hasNaN() || lb.hasNaN() || ub.hasNaN())
    return kWBadInput;
  for (int i = 0; i < mi; ++i)  // wrong-sided infinities; a zero weight has no slack cost
    if (lo(i) == kInf || hi(i) == -kInf || !(sw(i) > 0.0)) return kWBadInput;
  for (int j = 0; j < n_; ++j)
    if (lb(j) == kInf || ub(j) == -kInf) return kWBadInput;
  detail.setZero();
  active.setZero();
  const bool has_deadline = std::isfinite(time_left);
  const auto deadline = std::chrono::steady_clock::now() +
                        std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                            std::chrono::duration<double>(
                                has_deadline ? std::max(time_left, 0.0) : 0.0));
  if (refactor || !ready_) {
    qp_.invalidate();  // new J0 and rows: the stored set is factored again
    const int st = setup(Aeq, C, sw);
    if (st != kWOk) {
      ready_ = false;
      return st;
    }
  }
  const int r = r_;
  const int nv = r + ms_;
  // xbar: the hard equalities' minimum-norm least-squares solution (consistency checked)
  xbar_.setZero();
  if (me_h) {
    const auto b = beq.head(me_h);
    auto coef = coef_.head(rank_);
    coef.noalias() = svd_.matrixU().leftCols(rank_).transpose() * b;
    coef.array() /= svd_.singularValues().head(rank_).array();
    xbar_.noalias() = svd_.matrixV().leftCols(rank_) * coef;
    auto res = e_.head(me_h);
    res.noalias() = Aeq.topRows(me_h) * xbar_;
    res -= b;
    const double scale = std::max(1.0, b.cwiseAbs().maxCoeff());
    if (res.cwiseAbs().maxCoeff() > kCheckTol * scale) {
      detail(0) = res.norm();
      return kWInfeasibleEq;
    }
  }
  // the limits of the QP's rows, shifted by xbar, and their tolerances (of the true bounds)
  auto cx = cx_.head(mi);
  if (mi) cx.noalias() = C * xbar_;
  const int in_soft = in0_.size() > 1 ? in0_[1] : 0;
  auto put = [&](int row, double l, double u, double c) {
    glo_(row) = l - c;
    ghi_(row) = u - c;
    tlo_(row) = kQpTol * scale_of(l);
    thi_(row) = kQpTol * scale_of(u);
    flo_(row) = kFeasTol * scale_of(l);
    fhi_(row) = kFeasTol * scale_of(u);
  };
  for (int s = 0; s < ms_; ++s) put(s, lo(in_soft + s), hi(in_soft + s), cx(in_soft + s));
  for (int i = 0; i < mi_h; ++i) put(ms_ + i, lo(i), hi(i), cx(i));
  if (has_bounds_)
    for (int j = 0; j < n_; ++j) put(ms_ + mi_h + j, lb(j), ub(j), xbar_(j));
  if (r == 0) {
    // x is fixed by the hard equalities: feasible (FEAS_TOL) or infeasible, no QP
    for (int i = ms_; i < rows_; ++i) {
      if (!(0.0 >= glo_(i) - flo_(i) && 0.0 <= ghi_(i) + fhi_(i))) {
        detail(1) = kInf;
        return kWInfeasibleHard;
      }
    }
    x_ = xbar_;
  } else {
    // the soft equalities' targets e = be - A xbar (the linear term f = -M^T diag(beta) e
    // [+ eps Z^T xbar] is never formed: see below)
    if (mes_) {
      auto e = e_.head(mes_);
      e = beq.segment(me_h, mes_);
      if (me_h) e.noalias() -= Aeq.middleRows(me_h, mes_) * xbar_;
    }
    // the unconstrained optimum y_u (slacks 0)
    auto y = y_.head(nv);
    y.setZero();
    auto J0 = J0_.topLeftCorner(nv, nv);
    if (r) {
      // the unconstrained optimum as the least-squares solution of W z = sqrt(beta) e (with
      // eps: [W; sqrt(eps) I] z = [sqrt(beta) e; -sqrt(eps) Z^T xbar]) from W's QR, not
      // H^{-1} f: forming f and H costs ~eps_machine cond(H) in z, the QR eps_machine
      // cond(W) = eps_machine sqrt(cond(H)) (Talos weighted IK: cond(H) ~ 1e12)
      const int ma = mes_ + (regularized_ ? r : 0);
      auto rhs = rhs_.head(ma);
      if (mes_) rhs.head(mes_) = e_.head(mes_).cwiseProduct(beta_eq_.head(mes_).cwiseSqrt());
      if (regularized_) {
        if (me_h)
          rhs.tail(r).noalias() = -std::sqrt(eps_) * (Z_.leftCols(r).transpose() * xbar_);
        else
          rhs.tail(r).setZero();
      }
      const auto Wa = Wq_.topLeftCorner(ma, r);
      for (int j = 0; j < r; ++j)
        rhs.tail(ma - j).applyHouseholderOnTheLeft(Wa.col(j).tail(ma - j - 1), tau_(j),
                                                   hh_.data());
      auto yz = y.head(r);
      yz = rhs.head(r);
      Wa.topRows(r).template triangularView<Eigen::Upper>().solveInPlace(yz);
    }
    const int max_iter = 10 * (nv + rows_) + 100;
    const auto G = G_.topLeftCorner(rows_, nv);
    int st = qp_.solve(nv, G, glo_.head(rows_), ghi_.head(rows_), tlo_.head(rows_),
                       thi_.head(rows_), flo_.head(rows_), fhi_.head(rows_), J0, y, warm,
                       max_iter, has_deadline, deadline);
    detail(2) = qp_.iterations;
    if (st == qp::kInfeasible) {
      if (qp_.row < ms_) return kWNotConverged;  // a soft row always has its slack
      // relative to the row's bound (the library's max(1, |bound|) rule)
      detail(1) = qp_.violation / (flo_(qp_.row) / kFeasTol);
      return kWInfeasibleHard;
    }
    if (st == qp::kMaxIter) return kWNotConverged;
    if (st == qp::kTimeout) return kWTimeLimit;
    x_ = xbar_;
    x_.noalias() += Z_.leftCols(r) * y.head(r);
    detail(5) = qp_.warm_hit ? 1.0 : 0.0;
    detail(7) = qp_.active;
    for (const int c : qp_.working_set()) {
      const int i = c >> 1;
      const double side = (c & 1) ? 1.0 : -1.0;
      if (i < ms_)
        active(n_ + me_h + mi_h + i) = side;
      else if (i < ms_ + mi_h)
        active(n_ + me_h + (i - ms_)) = side;
      else
        active(i - ms_ - mi_h) = side;
    }
  }
  for (int i = 0; i < me_h; ++i) active(n_ + i) = 1.0;
  detail(6) = regularized_ ? 1.0 : 0.0;
  if (!x_.allFinite()) return kWNonFinite;
  // snapped into the bounds (the QP meets them to rounding), then the check of Stack._check
  if (has_bounds_) x_ = x_.cwiseMax(lb).cwiseMin(ub);
  double where = 0.0;
  if (const int failed =
          check_point(x_, has_bounds_, lb, ub, Aeq, beq, me_h, C, lo, hi, mi_h, where)) {
    detail(3) = failed;
    detail(4) = where;
    if (failed == 1) x_out = x_;  // the message shows the offending entry
    return kWCheckFailed;
  }
  for (int k = 0; k < Lv; ++k) res_out(k) = level_value(k, Aeq, beq, C, lo, hi, sw);
  x_out = x_;
  return kWOk;
}

#ifndef QPCOORD_NO_BINDINGS
// ---------------------------------------------------------------------------------------
// binding: the solver with its input and output arrays bound once (bind()); run() per step
namespace {

namespace nb = nanobind;
using Arr = nb::ndarray<double, nb::numpy, nb::c_contig, nb::device::cpu>;
using CMap = Eigen::Map<const Mat, 0, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>>;
using CVMap = Eigen::Map<const Vec>;
using MVMap = Eigen::Map<Vec>;

struct BoundWeighted : Weighted {
  using Weighted::Weighted;
  std::array<Arr, 12> a;  // Aeq beq C lo hi sw lb ub x res detail active
  bool bound = false;

  static CMap cmat(const Arr& m) {  // row-major (r, c) seen as a column-major r x c
    const auto r = static_cast<Eigen::Index>(m.shape(0)), c = static_cast<Eigen::Index>(m.shape(1));
    return CMap(m.data(), r, c, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>(1, c));
  }
  static CVMap cvec(const Arr& v) { return CVMap(v.data(), static_cast<Eigen::Index>(v.shape(0))); }
  static MVMap mvec(Arr& v) { return MVMap(v.data(), static_cast<Eigen::Index>(v.shape(0))); }

  int run(bool warm, double time_left, bool refactor) {
    if (!bound) return static_cast<int>(kWBadInput);
    return solve(cmat(a[0]), cvec(a[1]), cmat(a[2]), cvec(a[3]), cvec(a[4]), cvec(a[5]),
                 cvec(a[6]), cvec(a[7]), warm, time_left, refactor, mvec(a[8]), mvec(a[9]),
                 mvec(a[10]), mvec(a[11]));
  }

  /// The tasks' numbers copied into the bound arrays by refresh() (refresh.hpp, as the
  /// Hierarchy's step()): the compiled stack's refresh_stacked in one native pass.
  refresh::Stacked stacked;

  void set_tasks(nb::handle P, const std::vector<nb::object>& eq,
                 const std::vector<int64_t>& eq_rows, const std::vector<int64_t>& eq_first,
                 const std::vector<nb::object>& in, const std::vector<int64_t>& in_rows,
                 const std::vector<int64_t>& in_first) {
    if (!bound) throw nb::value_error("set_tasks: call bind first");
    const refresh::Stacked::Dest d =
        refresh::checked_dest(a, eq, eq_rows, eq_first, in, in_rows, in_first);
    const int64_t n = static_cast<int64_t>(a[0].shape(1));
    stacked.set(P, eq, eq_rows, eq_first, in, in_rows, in_first, n,
                static_cast<int64_t>(a[0].shape(0)), d);
  }
};

/// Cyclic garbage collection of a Weighted that holds its stack's tasks (set_tasks), as the
/// Hierarchy's (bindings.cpp): a task referring back to its stack makes a cycle through it.
int weighted_traverse(PyObject* self, visitproc visit, void* arg) {
  Py_VISIT(Py_TYPE(self));
  if (!nb::inst_ready(self)) return 0;
  return nb::inst_ptr<BoundWeighted>(self)->stacked.traverse(visit, arg);
}

int weighted_clear(PyObject* self) {
  nb::inst_ptr<BoundWeighted>(self)->stacked.clear();
  return 0;
}

PyType_Slot weighted_slots[] = {{Py_tp_traverse, reinterpret_cast<void*>(weighted_traverse)},
                                {Py_tp_clear, reinterpret_cast<void*>(weighted_clear)},
                                {0, nullptr}};

}  // namespace

void bind_weighted(nanobind::module_& m) {
  nb::class_<BoundWeighted>(m, "Weighted",
                            "The weighted QP of one stack structure (sizes fixed): "
                            "qpcoord.core.native_weighted.",
                            nb::type_slots(weighted_slots))
      .def(nb::init<int, std::vector<int>, std::vector<int>, bool, double, double>(),
           nb::arg("n"), nb::arg("meq"), nb::arg("min"), nb::arg("has_bounds"),
           nb::arg("regularization"), nb::arg("weight_ratio"))
      .def(
          "bind",
          [](BoundWeighted& w, Arr Aeq, Arr beq, Arr C, Arr lo, Arr hi, Arr sw, Arr lb, Arr ub,
             Arr x_out, Arr res_out, Arr detail, Arr active) {
            std::array<Arr, 12> a{Aeq, beq, C, lo, hi, sw, lb, ub, x_out, res_out, detail, active};
            static constexpr int kNdim[12] = {2, 1, 2, 1, 1, 1, 1, 1, 1, 1, 1, 1};
            for (int i = 0; i < 12; ++i)
              if (a[i].ndim() != static_cast<size_t>(kNdim[i]))
                throw nb::value_error("bind: wrong number of dimensions");
            w.a = a;
            w.bound = true;
          },
          nb::arg("Aeq"), nb::arg("beq"), nb::arg("C"), nb::arg("lo"), nb::arg("hi"),
          nb::arg("sw"), nb::arg("lb"), nb::arg("ub"), nb::arg("x_out"), nb::arg("res_out"),
          nb::arg("detail"), nb::arg("active"),
          "Keep these C-contiguous float64 arrays (inputs, then writable outputs) for run().")
      .def(
          "run",
          [](BoundWeighted& w, bool warm, double time_left, bool refactor) {
            try {
              return w.run(warm, time_left, refactor);
            } catch (const std::bad_alloc&) {
              return static_cast<int>(kWBadInput);
            }
          },
          nb::arg("warm"), nb::arg("time_left"), nb::arg("refactor"),
          "Solve on the bound arrays' current numbers; returns the status code (the "
          "Hierarchy's codes).")
      .def("set_tasks", &BoundWeighted::set_tasks, nb::arg("P"), nb::arg("eq"),
           nb::arg("eq_rows"), nb::arg("eq_first"), nb::arg("in_"), nb::arg("in_rows"),
           nb::arg("in_first"),
           "Bind the compiled stack P and its tasks (CompiledStack._task_rows) for refresh(); "
           "the bound input arrays must be P's stacked arrays.")
      .def(
          "refresh", [](const BoundWeighted& w) { return w.stacked.refresh(); },
          "Copy the tasks' current numbers and the box into the bound arrays (as "
          "CompiledStack.refresh_stacked); False (nothing raised): the data is not the common "
          "case, run the Python refresh.")
      .def_prop_ro(
          "fast_arrays", [](const BoundWeighted& w) { return w.stacked.fast(); },
          "Are numpy arrays read from their heads (else through the buffer protocol)?")
      .def("forget", &Weighted::forget, "Forget the stored working set.")
      .def_prop_ro("n", &Weighted::n)
      .def_prop_ro("num_levels", &Weighted::num_levels)
      .def_prop_ro("regularization", &Weighted::regularization)
      .def_prop_ro("weight_ratio", &Weighted::weight_ratio);
}
#endif  // QPCOORD_NO_BINDINGS

}  // namespace qpcoord

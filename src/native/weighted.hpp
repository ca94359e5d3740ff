// qpcoord native engine: the weighted QP of a stack (method="weighted"), one dense convex QP.
//
// Same problem and answer as qpcoord.core.methods.weighted (the Python engine):
//   min  sum_k rho^k (1/2 |Ae_k x - be_k|^2 + 1/2 |sw_k * w_k|^2)  [+ eps/2 |x|^2]
//   s.t. hard equalities, hard inequalities and bounds (hard), lo_k <= C_k x - w_k <= hi_k
// with rho = weight_ratio and w the slacks of the levels' inequality rows (soft). The hard
// equalities are eliminated (x = xbar + Z z, xbar their minimum-norm solution, Z an orthonormal
// basis of their null space, from an SVD with the rank rule of qpcoord.core.linalg); eps =
// regularization * max(1, max diag of the x-space Hessian) is added, centred on x = 0, only
// when the z-space Hessian H = W^T W is singular (W: the soft equality rows times Z, row-scaled
// by sqrt(rho^k)), so that the optimum is unique and both engines agree. The rule is
// methods/weighted.py's _SINGULAR: W has fewer rows than z has entries, or a diagonal entry^2
// of the R of a Householder QR of W (not the Cholesky of the formed H, whose pivots carry
// rounding ~sqrt(eps_machine) |W|) is at most 1e-14 of H's largest diagonal entry. H is never
// formed: L = R^T is its factor (of H + eps I: the R of [W; sqrt(eps) I]).
//
// The QP in y = (z, w) is solved by the dual active set of qp.hpp, whose factor J0 = L^{-T}
// and constraint rows are built once per set-up: a call with refactor = false (the matrices
// unchanged, e.g. PersistentQP) only recomputes xbar, the linear term and the limits, and
// starts from the previous call's working set. Every returned x is checked (bounds, hard rows:
// as Stack._check) and snapped into the bounds; nothing non-finite is accepted or returned.
#pragma once

#include <Eigen/Dense>
#include <chrono>
#include <vector>

#include "qp.hpp"

namespace nanobind {
class module_;
}

namespace qpcoord {

/// Status codes of Weighted::solve (the Hierarchy's codes of hierarchy.hpp, same values).
enum WeightedStatus : int {
  kWOk = 0,
  kWInfeasibleEq = 1,    ///< inconsistent hard equalities (detail[0]: residual norm)
  kWInfeasibleHard = 2,  ///< hard rows and bounds inconsistent (detail[1]: violation; inf:
                         ///< the hard equalities fix x and it violates them)
  kWNonFinite = 3,       ///< a non-finite result
  kWNotConverged = 4,    ///< iteration limit (or a Hessian that stays singular)
  kWBadInput = 5,        ///< wrong shapes or non-finite data
  kWTimeLimit = 6,       ///< the time limit passed
  kWCheckFailed = 7,     ///< the final x fails the check (detail[3]: kind, detail[4]: index)
};

/// The weighted QP of one stack structure (sizes fixed at construction).
class Weighted {
 public:
  using MatC = Eigen::Ref<const Eigen::MatrixXd, 0, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>>;
  using VecC = Eigen::Ref<const Eigen::VectorXd, 0, Eigen::InnerStride<>>;
  using VecM = Eigen::Ref<Eigen::VectorXd, 0, Eigen::InnerStride<>>;

  /// n variables; block 0 = hard constraints, block k+1 = level k; meq/min = rows per block.
  Weighted(int n, std::vector<int> meq, std::vector<int> min, bool has_bounds,
           double regularization, double weight_ratio);

  /// Solve with the current numbers (rows stacked block after block, hard first).
  /// refactor: rebuild the elimination, the Hessian's factor and the constraint rows (the
  /// first call always does); false reuses them (the matrices A, C, sw are unchanged).
  /// detail (8): [0] hard equality residual, [1] hard violation, [2] iterations, [3] check
  /// kind (1 bounds, 2 hard equalities, 3 hard inequalities), [4] its index or residual,
  /// [5] warm-start hit (0/1), [6] regularised (0/1), [7] size of the final working set.
  /// active (n + meq[0] + min[0] + soft rows): per row (bounds, hard equalities, hard
  /// inequalities, soft rows) -1 lower side active, +1 upper (hard equalities: +1), else 0.
  int solve(const MatC& Aeq, const VecC& beq, const MatC& C, const VecC& lo, const VecC& hi,
            const VecC& sw, const VecC& lb, const VecC& ub, bool warm, double time_left,
            bool refactor, VecM x_out, VecM res_out, VecM detail, VecM active);

  int n() const { return n_; }
  int num_levels() const { return static_cast<int>(meq_.size()) - 1; }
  double regularization() const { return reg_; }
  double weight_ratio() const { return rho_; }
  /// Forget the stored working set (the next solve starts cold).
  void forget() { qp_.forget(); }

 private:
  int setup(const MatC& Aeq, const MatC& C, const VecC& sw);
  double level_value(int k, const MatC& Aeq, const VecC& beq, const MatC& C, const VecC& lo,
                     const VecC& hi, const VecC& sw) const;

  int n_;
  std::vector<int> meq_, min_, eq0_, in0_;
  bool has_bounds_;
  double reg_, rho_;
  int ms_ = 0;     ///< soft inequality rows (all levels)
  int mes_ = 0;    ///< soft equality rows
  int rows_ = 0;   ///< constraint rows of the QP: soft, hard inequality, bounds
  bool ready_ = false;
  bool regularized_ = false;
  double eps_ = 0.0;

  int rank_ = 0;  ///< rank of the hard equalities
  int r_ = 0;     ///< n - rank
  Eigen::JacobiSVD<Eigen::MatrixXd> svd_;
  Eigen::MatrixXd Ah_;   ///< the hard equalities (SVD input)
  Eigen::MatrixXd Z_;    ///< n x r
  Eigen::MatrixXd M_;    ///< soft equality rows times Z (mes x r)
  /// contiguous copies of the rows multiplied by Z (the soft equalities, then the soft and
  /// hard inequalities): a product with a strided (row-major) view of the caller's arrays
  /// made a heap temporary on every refactor
  Eigen::MatrixXd rows_buf_;
  /// the weighted rows W (mes x r), QR-factored in place for the rank decision; when eps is
  /// added, [W; sqrt(eps) I] ((mes + r) x r) factored in place (Householder vectors below
  /// the diagonal, their coefficients in tau_): the unconstrained optimum is its least-squares
  /// solution, not H^{-1} f (forming H and f costs ~eps_machine |W|^2 / eps in z, 2e-7)
  Eigen::MatrixXd Wq_;
  Eigen::VectorXd hh_, tau_, rhs_;  ///< Householder workspace (n), coefficients (n), rhs
  Eigen::VectorXd beta_eq_, beta_in_;  ///< rho^k of each soft equality / inequality row
  Eigen::MatrixXd L_, J0_, G_;  ///< L = R^T of W's QR (H = L L^T), J0 = L^{-T}, rows
  Eigen::VectorXd xbar_, x_, y_, e_, coef_, glo_, ghi_, tlo_, thi_, flo_, fhi_, cx_;
  qp::DualActiveSet qp_;
};

/// Register Weighted (as qpcoord._native.Weighted) in the extension module.
void bind_weighted(nanobind::module_& m);

}  // namespace qpcoord

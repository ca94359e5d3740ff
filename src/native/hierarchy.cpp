// qpcoord native engine: dense exact strict-hierarchy least squares (implementation).
//
// One translation unit: the tolerances and helpers below, the parts of the solver by concern
// (hierarchy/*.hxx: workspace, caches, freeze, least_squares, warm_start, closed_form), then
// the stages -- hard phase, levels, minimum-norm step -- and solve().
#include "hierarchy.hpp"

#include "checks.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

namespace qpcoord {
namespace {

constexpr double kEps = std::numeric_limits<double>::epsilon();
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kFeasTol = 1e-9;       // FEAS_TOL: closed-form feasibility test, relative
constexpr double kInfeasTol = 1e-9;     // INFEAS_TOL: hard part violation, relative
constexpr double kAbsFloor = 1e-14;
constexpr double kWarmFeasTol = 1e-10;  // a working set's point must meet every row to this
// a level row (or combination of rows) whose projection on the remaining freedom is under this
// fraction of the row's norm is dependent on the frozen rows (rounding of the freeze)
constexpr double kMovableTol = 1e-9;
// tries of a zero-objective level's working set without its far rows before the whole set
// is stored (each adds the rows the last one's point violated)
constexpr int kPruneRounds = 3;
constexpr int kBlandAfter = 2;          // zero-length steps in a row before Bland's rule
constexpr double kRoundFactor = 16.0;   // rounding floor of a multiplier, in eps k |Q| |Q y|
constexpr double kQrMargin = 4.0;       // QR closed form: sigma_min bound over the SVD's floor
// up to this rank, the QR closed form's bound 1/|R11^-1|_F comes by a back substitution per
// column on its leading entries (above it, by Eigen's blocked triangular solve)
constexpr int kSmallRinvMax = 16;
// a level with a singular value under this fraction of the largest (or a damped one) is
// finished with exact_ (as qpcoord.core.methods.hierarchical.ILL_CONDITIONED)
constexpr double kIllConditioned = 1e-3;
// room for a cache key's sizes and flags, in bytes (KeyedCache: 3 ints per block part)
constexpr std::size_t kKeyHeader = 256;

inline double widen_lo(double lo) { return lo - kFeasTol * std::max(1.0, std::abs(lo)); }
inline double widen_hi(double hi) { return hi + kFeasTol * std::max(1.0, std::abs(hi)); }
inline bool in_box(double v, double lo, double hi) {
  return v >= widen_lo(lo) && v <= widen_hi(hi);
}
inline double finite_abs(double v) { return std::isfinite(v) ? std::abs(v) : 0.0; }

/// The ratio test of one row: the step length (>= 0; inf if it never blocks) at which a row
/// whose product with the step is gp and with the current point gy reaches its bound, the
/// bound's side in sd (+1 upper, -1 lower, 0 none); |gp| <= tiny does not block.
inline double bound_step(double gp, double gy, double lo, double hi, double tiny, int8_t& sd) {
  sd = 0;
  if (gp > tiny && std::isfinite(hi)) {
    sd = 1;
    return std::max((hi - gy) / gp, 0.0);
  }
  if (gp < -tiny && std::isfinite(lo)) {
    sd = -1;
    return std::max((lo - gy) / gp, 0.0);
  }
  return kInf;
}


}  // namespace

}  // namespace qpcoord

// the parts of the solver, by concern (one translation unit: the helpers above are theirs)
#include "hierarchy/workspace.hxx"
#include "hierarchy/caches.hxx"
#include "hierarchy/freeze.hxx"
#include "hierarchy/least_squares.hxx"
#include "hierarchy/warm_start.hxx"
#include "hierarchy/closed_form.hxx"
#include "hierarchy/level.hxx"

namespace qpcoord {

int Hierarchy::hard_phase(const CRef<Mat>& Aeq, const CRef<Vec>& beq, const CRef<Mat>& C,
                          const CRef<Vec>& lo, const CRef<Vec>& hi, MRef<Mat> stats,
                          MRef<Vec> detail, bool warm) {
  enter_stage(0);
  z_repeats_ = true;  // (the trial cache's gate in the hard phase; set again after it)
  x_.setZero();
  Z_.setIdentity();
  z_identity_ = true;
  r_ = n_;
  k_ = 0;
  kz_ = 0;
  const int me = meq_[0];
  if (me) {
    const auto A = Aeq.topRows(me);
    const auto b = beq.head(me);
    Mat& M = Ms_[0];
    M = A;
    auto& svd = svds_[0];
    svd.compute(M, Eigen::ComputeThinU | Eigen::ComputeFullV);
    const Vec& s = svd.singularValues();
    const int rank = numerical_rank(s, me, n_, 0.0);
    auto coef = ute_.head(rank);
    coef.noalias() = svd.matrixU().leftCols(rank).transpose() * b;
    coef.array() /= s.head(rank).array();
    x_.noalias() = svd.matrixV().leftCols(rank) * coef;
    auto res = e_.head(me);
    res.noalias() = A * x_;
    res -= b;
    const double scale = std::max(1.0, b.cwiseAbs().maxCoeff());
    if (res.cwiseAbs().maxCoeff() > kCheckTol * scale) {
      detail(0) = res.norm();
      return kInfeasibleEq;
    }
    r_ = n_ - rank;
    Z_.leftCols(r_) = svd.matrixV().rightCols(r_);
    z_identity_ = false;
  }
  // hard inequality rows with their true bounds, then: is x already feasible?
  const int mi = min_[0];
  for (int i = 0; i < mi; ++i) {
    if (!std::isfinite(lo(i)) && !std::isfinite(hi(i))) continue;
    Cin_.row(k_) = C.row(i);
    cin_norm_(k_) = -1.0;  // |Cin_.row(k_)| on first use (cin_norm)
    lin_(k_) = lo(i);
    uin_(k_) = hi(i);
    inid_[k_] = i;
    ++k_;
  }
  if (feasible(x_)) return kOk;
  if (me == 0 && k_ == 0 && has_bounds_) {
    // only the box: its point nearest x = 0 is feasible (a performance shortcut: phase 1
    // would find a zero-violation point by an active set over all n bounds; the levels and
    // the minimum-norm step do not depend on which feasible start they get)
    snap(x_);
    if (feasible(x_)) return kOk;
  }
  if (r_ == 0) {
    detail(1) = kInf;
    return kInfeasibleHard;
  }
  // phase 1: min sum of squared violations of the hard rows and bounds, in (z, w)
  const int nb = has_bounds_ ? n_ : 0;
  const int cols = r_ + k_ + nb;
  LsqProblem& P = P_;
  P.start(k_ + nb, cols);
  for (int i = 0; i < k_ + nb; ++i) P.Q(i, r_ + i) = 1.0;
  auto g = rowbuf_.head(cols);
  auto y = y_.head(cols);
  y.setZero();
  double worst_fixed = 0.0;
  for (int i = 0; i < k_; ++i) {
    const double v = Cin_.row(i).dot(x_);
    g.setZero();
    g.head(r_).noalias() = Z_.leftCols(r_).transpose() * Cin_.row(i).transpose();
    const double gap = std::max({lin_(i) - v, v - uin_(i), 0.0});
    if (g.head(r_).norm() <= 1e-12 * cin_norm(i)) {  // fixed by the hard equalities
      worst_fixed = std::max(
          worst_fixed, gap / std::max({1.0, finite_abs(lin_(i)), finite_abs(uin_(i))}));
      continue;
    }
    g(r_ + i) = -1.0;
    y(r_ + i) = (v > uin_(i)) ? v - uin_(i) : ((v < lin_(i)) ? v - lin_(i) : 0.0);
    P.add_row(g, lin_(i) - v, uin_(i) - v, inid_[i], cin_norm(i));
  }
  for (int j = 0; j < nb; ++j) {
    g.setZero();
    g.head(r_) = Z_.row(j).head(r_).transpose();
    const double v = x_(j);
    g(r_ + k_ + j) = -1.0;
    if (g.head(r_).norm() <= 1e-12) {
      const double gap = std::max({lb_(j) - v, v - ub_(j), 0.0});
      worst_fixed =
          std::max(worst_fixed, gap / std::max({1.0, finite_abs(lb_(j)), finite_abs(ub_(j))}));
      continue;
    }
    y(r_ + k_ + j) = (v > ub_(j)) ? v - ub_(j) : ((v < lb_(j)) ? v - lb_(j) : 0.0);
    P.add_row(g, lb_(j) - v, ub_(j) - v, capacity_ + j, 1.0);
  }
  if (worst_fixed > kInfeasTol) {
    detail(1) = worst_fixed;
    return kInfeasibleHard;
  }
  int iters = 0;
  bool hit = false;
  // (every row has its slack: a seed's z is the stored set's point, each slack the row's
  // violation there; the cold start is y as set above)
  const int st = warm_started_active_set(P, working_[0], warm, 0, 0, y, [](Eigen::Ref<Vec>) {},
                                         iters, hit);
  if (st != kOk) {
    detail(2) = 0;
    return st;
  }
  store_working_set(P, W_, working_[0]);
  stats(0, 0) = iters;
  stats(0, 1) = hit ? 1.0 : 0.0;
  x_.noalias() += Z_.leftCols(r_) * y.head(r_);
  // the violation left, relative to each row's scale
  double worst = 0.0;
  for (int i = 0; i < k_; ++i) {
    const double v = Cin_.row(i).dot(x_);
    const double gap = std::max({lin_(i) - v, v - uin_(i), 0.0});
    worst = std::max(worst,
                     gap / std::max({1.0, finite_abs(lin_(i)), finite_abs(uin_(i))}));
  }
  for (int j = 0; j < nb; ++j) {
    const double gap = std::max({lb_(j) - x_(j), x_(j) - ub_(j), 0.0});
    worst = std::max(worst, gap / std::max({1.0, finite_abs(lb_(j)), finite_abs(ub_(j))}));
  }
  if (worst > kInfeasTol) {
    detail(1) = worst;
    return kInfeasibleHard;
  }
  snap(x_);
  for (int i = 0; i < k_; ++i) {  // opened to the point's value (rounding)
    const double v = Cin_.row(i).dot(x_);
    lin_(i) = std::min(lin_(i), v);
    uin_(i) = std::max(uin_(i), v);
  }
  return kOk;
}

int Hierarchy::level(int k, const CRef<Mat>& Aeq, const CRef<Vec>& beq, const CRef<Mat>& C,
                     const CRef<Vec>& lo, const CRef<Vec>& hi, const CRef<Vec>& sw,
                     MRef<Mat> stats, bool warm) {
  const int stage = k + 1;
  const LevelRows d{Aeq, beq, C, lo, hi, sw, stage, meq_[stage], min_[stage], eq0_[stage],
                    in0_[stage]};
  const int mi = d.mi, i0 = d.i0;
  enter_stage(stage);
  cf_ = per_stage_ ? &cforms_[stage].value : &shared_cf_;
  if (r_ == 0) {  // no freedom left: the level's rows are inherited as they are
    inherit(C, lo, hi, i0, mi, nullptr);
    return kOk;
  }
  // ---- the damped closed form of the projected equalities M dz = e, M = A Z (M and its
  // factorisations from the closed-form cache when A, C and Z on entry are the last call's)
  const bool same_m = closed_form_lookup(stage, Aeq, d.e0, d.me, C, i0, mi);
  if (!same_m) cf_->svd_valid = false;
  const LevelForm form = level_closed_form(d, same_m);
  if (accept_closed_form(d, form)) {  // it meets every row: the level's optimum, frozen
    stats(stage, 2) = 1.0;
    return kOk;
  }
  // ---- else the exact active-set least squares in y = (z, w), w the moving rows' slacks.
  // The warm trial first on the level's own rows and its stored set's other rows alone, the
  // bounds and inherited rows it leaves out checked at its point (the support polygon's
  // level and the levels below it, their sets a polygon row among 38 bounds, did not build
  // them). A miss builds the whole problem and starts over from it.
  Working& ws = working_[stage];
  const Light light = (warm && ws.stored) ? light_trial(d, form, ws, y_) : Light::kRebuild;
  if (light == Light::kHit || light == Light::kHitStore) {
    if (light == Light::kHitStore) {  // the whole problem, W_ the set on it, for the store
      const int m = level_problem(d, form);
      map_working_set(P_, ws, W_);
      store_level_working_set(P_, y_.head(r_ + m), m, true, ws);
    }
    stats(stage, 0) = 0.0;
    stats(stage, 1) = 1.0;
    xold_.head(n_) = x_;
    x_.noalias() += Z_.leftCols(r_) * y_.head(r_);
    snap(x_);
    freeze_level(d, form, violated_rows(d));
    return kOk;
  }
  const int mv =
      (light == Light::kWhole) ? static_cast<int>(mov_.size()) : level_problem(d, form);
  LsqProblem& P = P_;
  const auto Zr = Z_.leftCols(r_);
  auto y = y_.head(r_ + mv);
  int iters = 0;
  bool hit = false;
  // the cold start: z = 0, each slack its row's violation at x
  auto cold = [&](Eigen::Ref<Vec> y0) {
    y0.setZero();
    for (int j = 0; j < mv; ++j) {
      const int row = i0 + mov_[j];
      const double v = C.row(row).dot(x_);
      y0(r_ + j) = (v > hi(row)) ? v - hi(row) : ((v < lo(row)) ? v - lo(row) : 0.0);
    }
  };
  const int st =
      warm_started_active_set(P, working_[stage], warm, P.rows - mv, mv, y, cold, iters, hit);
  if (st != kOk) return st;
  // an ill-conditioned or damped level: finished to rounding (a point optimal to
  // settings.kkt_tol can be far from the optimum along a direction of curvature s^2 or
  // tau^2, and is frozen)
  if (ill_conditioned(d, form)) {
    exact_ = true;
    const bool done = active_set(P, y, W_, iters);
    exact_ = false;
    if (!done) return timed_out_ ? kTimeLimit : kNotConverged;
  }
  // (the exact finish may leave the trial's set: then W_ is stored as after a miss)
  store_level_working_set(P, y, mv, hit && iters == 0, working_[stage]);
  stats(stage, 0) = iters;
  stats(stage, 1) = hit ? 1.0 : 0.0;
  xold_.head(n_) = x_;
  x_.noalias() += Zr * y.head(r_);
  snap(x_);
  // ---- the rows its optimum leaves violated; the freeze of its optimal set
  freeze_level(d, form, violated_rows(d));
  return kOk;
}

int Hierarchy::min_norm(MRef<Mat> stats, bool warm) {
  const int stage = static_cast<int>(meq_.size());
  enter_stage(stage);
  if (r_ == 0) return kOk;
  const auto Zr = Z_.leftCols(r_);
  auto zx = tmpr_.head(r_);
  zx.noalias() = Zr.transpose() * x_;
  auto xc = xc_.head(n_);
  xc = x_;
  xc.noalias() -= Zr * zx;
  if (feasible(xc)) {
    x_ = xc;
    snap(x_);
    stats(stage, 2) = 1.0;
    return kOk;
  }
  LsqProblem& P = P_;
  P.start(n_, r_);
  P.Q.topLeftCorner(n_, r_) = Zr;
  P.c.head(n_) = -x_;
  add_inherited_rows(P);
  add_bound_rows(P, stage);
  // Z^T Z = I: the least squares min |Z y + x| is the least-distance problem
  // min |y + Z^T x|^2 (+ const), stepped without the QR of the projected objective
  struct UnitQ {  // cleared on every return
    bool& flag;
    ~UnitQ() { flag = false; }
  } unit_q{unit_q_};
  unit_q_ = true;
  auto y = y_.head(r_);
  y.setZero();
  int iters = 0;
  bool hit = false;
  // (every row is without slack here; y = 0, the cold start, is feasible: x meets the
  // inherited rows and the bounds)
  const int st = warm_started_active_set(P, working_[stage], warm, P.rows, 0, y,
                                         [](Eigen::Ref<Vec> y0) { y0.setZero(); }, iters, hit);
  if (st != kOk) return st;
  store_working_set(P, W_, working_[stage]);
  stats(stage, 0) = iters;
  stats(stage, 1) = hit ? 1.0 : 0.0;
  x_.noalias() += Zr * y;
  snap(x_);
  return kOk;
}

double Hierarchy::level_value(int k, const CRef<Mat>& Aeq, const CRef<Vec>& beq,
                              const CRef<Mat>& C, const CRef<Vec>& lo, const CRef<Vec>& hi,
                              const CRef<Vec>& sw, const Vec& x, double* scale) const {
  const int b = k + 1;
  return qpcoord::level_value(Aeq, beq, eq0_[b], meq_[b], C, lo, hi, sw, in0_[b], min_[b], x,
                              scale);
}

int Hierarchy::check_input(const CRef<Mat>& Aeq, const CRef<Vec>& beq, const CRef<Mat>& C,
                           const CRef<Vec>& lo, const CRef<Vec>& hi, const CRef<Vec>& sw,
                           const CRef<Vec>& lb, const CRef<Vec>& ub, const MRef<Vec>& x_out,
                           const MRef<Vec>& res_out, const MRef<Mat>& stats,
                           const MRef<Vec>& detail) const {
  const int L = num_levels();
  const int me = eq0_.back() + meq_.back();
  const int mi = in0_.back() + min_.back();
  if (Aeq.rows() != me || Aeq.cols() != n_ || beq.size() != me || C.rows() != mi ||
      C.cols() != n_ || lo.size() != mi || hi.size() != mi || sw.size() != mi ||
      lb.size() != n_ || ub.size() != n_ || x_out.size() != n_ || res_out.size() != L ||
      stats.rows() != L + 2 || stats.cols() != 3 || detail.size() < 8)
    return kBadInput;
  if (!Aeq.allFinite() || !beq.allFinite() || !C.allFinite() || !sw.allFinite() ||
      lo.hasNaN() || hi.hasNaN() || lb.hasNaN() || ub.hasNaN())
    return kBadInput;
  for (int i = 0; i < mi; ++i)  // wrong-sided infinities
    if (lo(i) == kInf || hi(i) == -kInf) return kBadInput;
  for (int j = 0; j < n_; ++j)
    if (lb(j) == kInf || ub(j) == -kInf) return kBadInput;
  return kOk;
}

void Hierarchy::start_call(double time_left) {
  if (calls_ > 0 && !per_stage_) allocate_per_stage();  // (the second call: once)
  ++calls_;
  shared_cf_.mqr.wy_applications = 0;
  for (ClosedFormCache& f : cforms_) f.value.mqr.wy_applications = 0;
  fqr_.wy_applications = 0;
  timed_out_ = false;
  seeded_ = 0;
  stats_ = Stats();
  unit_q_ = false;
  ts_->k_valid = false;
  trial_ready_ = false;
  const double limit = std::min(time_left, settings.time_limit);
  has_deadline_ = std::isfinite(limit);
  if (has_deadline_)
    deadline_ = std::chrono::steady_clock::now() +
                std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                    std::chrono::duration<double>(std::max(limit, 0.0)));
}

int Hierarchy::certify(const CRef<Mat>& Aeq, const CRef<Vec>& beq, const CRef<Mat>& C,
                       const CRef<Vec>& lo, const CRef<Vec>& hi, const CRef<Vec>& sw,
                       MRef<Vec> x_out, MRef<Vec> res_out, MRef<Vec> detail) {
  if (!x_.allFinite()) return kNonFinite;
  // the check of every returned x (as Stack._check): bounds, hard equalities, hard rows
  double where = 0.0;
  if (const int failed = check_point(x_, has_bounds_, lb_, ub_, Aeq, beq, meq_[0], C, lo, hi,
                                     min_[0], where)) {
    detail(3) = failed;
    detail(4) = where;
    if (failed == 1) x_out = x_;  // the message shows the offending entry
    return kCheckFailed;
  }
  // each level keeps the value it was frozen with (lower levels move in its optimal set
  // only): the worst deviation, relative to max(1, the frozen value, the level's scale at x,
  // |b| + |A|_F |x|: the size of its rounding), is reported (Python: status "inaccurate")
  for (int k = 0; k < num_levels(); ++k) {
    double scale = 0.0;
    res_out(k) = level_value(k, Aeq, beq, C, lo, hi, sw, x_, &scale);
    const double dev =
        std::abs(res_out(k) - frozen_value_(k)) / std::max({1.0, frozen_value_(k), scale});
    if (dev > detail(5)) {
      detail(5) = dev;
      detail(6) = k;
    }
  }
  return kOk;
}

int Hierarchy::solve(const CRef<Mat>& Aeq, const CRef<Vec>& beq, const CRef<Mat>& C,
                     const CRef<Vec>& lo, const CRef<Vec>& hi, const CRef<Vec>& sw,
                     const CRef<Vec>& lb, const CRef<Vec>& ub, bool warm, double time_left,
                     MRef<Vec> x_out, MRef<Vec> res_out, MRef<Mat> stats, MRef<Vec> detail) {
  if (check_input(Aeq, beq, C, lo, hi, sw, lb, ub, x_out, res_out, stats, detail) != kOk)
    return kBadInput;
  stats.setZero();
  detail.setZero();
  start_call(time_left);
  lb_ = lb;
  ub_ = ub;
  // the hard phase: x meets the bounds and the hard rows, Z spans the hard equalities' null space
  int st = hard_phase(Aeq, beq, C, lo, hi, stats, detail, warm);
  z_repeats_ = true;  // (the freeze cache: the first freeze's lookup compares Z itself)
  if (st != kOk) return st;
  // the levels, in order: each moves x in Z's span to its optimum and freezes its optimal set
  const int L = num_levels();
  for (int k = 0; k < L; ++k) {
    st = level(k, Aeq, beq, C, lo, hi, sw, stats, warm);
    if (st != kOk) {
      detail(2) = k + 1;
      return st;
    }
    frozen_value_(k) = level_value(k, Aeq, beq, C, lo, hi, sw, x_);
  }
  // the point of least norm in the last optimal set
  st = min_norm(stats, warm);
  if (st != kOk) {
    detail(2) = L + 1;
    return st;
  }
  // the end check of x, each level's value and its deviation from its frozen value
  st = certify(Aeq, beq, C, lo, hi, sw, x_out, res_out, detail);
  if (st != kOk) return st;
  detail(7) = seeded_;
  stats_.wy_applications = fqr_.wy_applications + shared_cf_.mqr.wy_applications;
  for (const ClosedFormCache& f : cforms_) stats_.wy_applications += f.value.mqr.wy_applications;
  x_out = x_;
  return kOk;
}

}  // namespace qpcoord

// qpcoord native engine: dense exact strict-hierarchy least squares (implementation).
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
constexpr int kBlandAfter = 2;          // zero-length steps in a row before Bland's rule
constexpr double kRoundFactor = 16.0;   // rounding floor of a multiplier, in eps k |Q| |Q y|
constexpr double kQrMargin = 4.0;       // QR closed form: sigma_min bound over the SVD's floor
// up to this rank, the QR closed form's bound 1/|R11^-1|_F comes by a back substitution per
// column on its leading entries (above it, by Eigen's blocked triangular solve)
constexpr int kSmallRinvMax = 16;
// a level with a singular value under this fraction of the largest (or a damped one) is
// finished with exact_ (as qpcoord.core.methods.hierarchical.ILL_CONDITIONED)
constexpr double kIllConditioned = 1e-3;

inline double widen_lo(double lo) { return lo - kFeasTol * std::max(1.0, std::abs(lo)); }
inline double widen_hi(double hi) { return hi + kFeasTol * std::max(1.0, std::abs(hi)); }
inline bool in_box(double v, double lo, double hi) {
  return v >= widen_lo(lo) && v <= widen_hi(hi);
}
inline double finite_abs(double v) { return std::isfinite(v) ? std::abs(v) : 0.0; }

/// a and b (the same shape) equal bit for bit (0.0 and -0.0 differ: freeze_memo restores
/// outputs only for inputs that are the same bits)
template <typename A, typename B>
bool same_bits(const A& a, const B& b) {
  if (a.rows() == 0) return true;  // (no memcmp of empty, possibly null, data)
  for (Eigen::Index j = 0; j < a.cols(); ++j)
    if (std::memcmp(a.col(j).data(), b.col(j).data(), sizeof(double) * a.rows()) != 0)
      return false;
  return true;
}

/// freeze_memo's copy of a level's rows a (m x n, any strides): true when buf holds them bit
/// for bit in the layout `layout` names (1 rows, 2 columns contiguous in a, 3 neither: entry
/// by entry), else they are copied into buf (its first m n entries) in a's layout, layout set
/// and false returned. One memcmp for a block of C-ordered rows (numpy's stacked arrays).
template <typename R>
bool same_rows_or_copy(const R& a, Vec& buf, int& layout) {
  const Eigen::Index m = a.rows(), n = a.cols();
  if (m == 0 || n == 0) {
    const bool same = layout == 1;
    layout = 1;
    return same;
  }
  double* out = buf.data();
  if (a.outerStride() != 1 && a.innerStride() != 1) {  // entry by entry
    bool same = layout == 3;
    for (Eigen::Index j = 0; same && j < n; ++j)
      for (Eigen::Index i = 0; same && i < m; ++i) {
        const double v = a(i, j);
        same = std::memcmp(&v, out + j * m + i, sizeof v) == 0;
      }
    if (same) return true;
    for (Eigen::Index j = 0; j < n; ++j)
      for (Eigen::Index i = 0; i < m; ++i) out[j * m + i] = a(i, j);
    layout = 3;
    return false;
  }
  // runs of contiguous entries: the rows (1) or the columns (2); one run when they follow
  // each other
  const int now = (a.outerStride() == 1) ? 1 : 2;
  Eigen::Index runs = (now == 1) ? m : n, len = (now == 1) ? n : m;
  const Eigen::Index stride = (now == 1) ? a.innerStride() : a.outerStride();
  if (stride == len) {
    len *= runs;
    runs = 1;
  }
  const std::size_t bytes = sizeof(double) * len;
  bool same = layout == now;
  for (Eigen::Index k = 0; same && k < runs; ++k)
    same = std::memcmp(a.data() + k * stride, out + k * len, bytes) == 0;
  if (same) return true;
  for (Eigen::Index k = 0; k < runs; ++k) std::memcpy(out + k * len, a.data() + k * stride, bytes);
  layout = now;
  return false;
}

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

// ---------------------------------------------------------------------------------------
void LsqProblem::resize(int max_qrows, int max_grows, int max_cols) {
  Q.resize(max_qrows, max_cols);
  c.resize(max_qrows);
  G.resize(max_grows, max_cols);
  lo.resize(max_grows);
  hi.resize(max_grows);
  id.assign(max_grows, -1);
}

void LsqProblem::start(int qrows_, int cols_) {
  qrows = qrows_;
  cols = cols_;
  rows = 0;
  dropped2 = 0.0;
  zcols = slacks = slack_q0 = slack_g0 = 0;
  Q.topLeftCorner(qrows, cols).setZero();
  c.head(qrows).setZero();
}

double LsqProblem::add_row(const Eigen::Ref<const Vec>& g, double l, double u, int gid,
                           double ref_norm) {
  if (!std::isfinite(l) && !std::isfinite(u)) return 0.0;
  const double nrm = g.norm();
  if (!(nrm > 1e-12 * std::max(ref_norm, 1e-300))) return 0.0;  // cannot bind: constant row
  G.row(rows).head(cols) = g.transpose() / nrm;
  lo(rows) = l / nrm;
  hi(rows) = u / nrm;
  id[rows] = gid;
  ++rows;
  return nrm;
}

// ---------------------------------------------------------------------------------------
Hierarchy::Hierarchy(int n, std::vector<int> meq, std::vector<int> min, bool has_bounds,
                     double damping)
    : n_(n), meq_(std::move(meq)), min_(std::move(min)), has_bounds_(has_bounds),
      damping_(damping) {
  const int blocks = static_cast<int>(meq_.size());
  eq0_.assign(blocks, 0);
  in0_.assign(blocks, 0);
  int e = 0, c = 0, max_eq = 0, max_in = 0;
  for (int b = 0; b < blocks; ++b) {
    eq0_[b] = e;
    in0_[b] = c;
    e += meq_[b];
    c += min_[b];
    max_eq = std::max(max_eq, meq_[b]);
    max_in = std::max(max_in, min_[b]);
  }
  capacity_ = c;
  x_.resize(n);
  frozen_value_.setZero(std::max(blocks - 1, 1));
  Z_.resize(n, n);
  Cin_.resize(std::max(capacity_, 1), n);
  CinZ_.resize(std::max(capacity_, 1), std::max(n, 1));
  cinx_.resize(std::max(capacity_, 1));
  lin_.resize(std::max(capacity_, 1));
  cin_norm_.resize(std::max(capacity_, 1));
  uin_.resize(std::max(capacity_, 1));
  inid_.assign(std::max(capacity_, 1), -1);
  lb_.resize(n);
  ub_.resize(n);
  // largest stage: (z, w) with w over a level's rows, or the hard phase (slack per hard row
  // and per bound); Q holds equalities, damping rows and slack rows (or Z for the min norm)
  const int hard_cols = n + min_[0] + (has_bounds ? n : 0);
  const int max_cols = std::max({n + max_in, hard_cols, 1});
  const int max_qrows = std::max({max_eq + n + max_in, n, min_[0] + (has_bounds ? n : 0), 1});
  const int max_grows = capacity_ + (has_bounds ? n : 0) + max_in + 1;
  P_.resize(max_qrows, max_grows, max_cols);
  Pr_.resize(max_qrows, max_grows, std::max(n, 1));
  y_.setZero(max_cols);
  W_.assign(max_grows, 0);
  working_.resize(blocks + 1);
  for (auto& w : working_) {
    w.id.reserve(max_grows);
    w.side.reserve(max_grows);
  }
  // the first call's working-set and K factorisations, shared by its stages (the memos'
  // per-stage ones are allocated at the second call: a one-shot solve never pays for them)
  shared_trial_.reserve(max_cols, max_grows, max_qrows, false);
  ts_ = &shared_trial_;
  sqr_.reserve(max_cols, max_grows + max_qrows, 1);
  // (apply_q_right: Z, and the carried projection of up to capacity inherited rows)
  fqr_.reserve(std::max(n, 1), n + max_in + 1, std::max(n, capacity_));
  fqr_.reserve_wy(std::max(n, capacity_));
  const int big = std::max({max_cols, max_grows, max_qrows, n, max_eq, 1});
  for (Vec* v : {&res_, &dres_, &step_, &gvec_, &u_, &mu_, &gy_, &gp_, &tvec_, &rowbuf_, &zc_,
                 &tmpr_, &xc_, &xold_, &e_, &ute_})
    v->setZero(big);
  widx_.reserve(max_grows);
  mov_.reserve(std::max(max_in, 1));
  depn_.setZero(std::max(max_in, 1));
  gram_.setZero(std::max(std::min(max_in, n), 1), std::max(std::min(max_in, n), 1));
  keep_.assign(max_grows, 0);
  viol_.assign(std::max(max_in, 1), 0);
  Ms_.resize(blocks);
  for (int b = 0; b < blocks; ++b) Ms_[b].setZero(meq_[b], n);  // M = A Z in its left r columns
  svds_.resize(blocks);
  Ztmp_.setZero(n, n);
  Ab_.setZero(std::max(max_eq, 1), n);
  Cl_.setZero(std::max(max_in, 1), n);
  CZl_.setZero(std::max(max_in, 1), std::max(n, 1));
  shared_cf_.reserve(n, max_eq, capacity_);
  cf_ = &shared_cf_;
  rinv_.setZero(std::max(n, 1), std::max(n, 1));
  nsp_.setZero(std::max(n, 1), std::max(n, 1));
  cztmp_.setZero(std::max(capacity_, 1), std::max(n, 1));
}

void Hierarchy::TrialState::reserve(int cols, int grows, int qrows, bool keys) {
  wqr.reserve(cols, grows, qrows);
  kqr.reserve(qrows, cols, 1);
  cqr.reserve(cols, cols, 1);
  krz.reserve(cols, cols);
  kqr_t.reserve(cols, qrows, 1);
  Qt.setZero(qrows, cols);
  if (!keys) return;
  key_widx.reserve(grows);
  key_G.setZero(static_cast<Eigen::Index>(cols) * cols);  // kw <= k rows kept (trial_keep)
  key_Q.setZero(static_cast<Eigen::Index>(qrows) * cols);
}

void Hierarchy::ClosedForm::reserve(int n, int me, int capacity) {
  mqr.reserve(std::max({n, me, 1}), std::max({n, me, 1}), std::max({n, capacity, 1}));
  mqr.reserve_wy(std::max({n, capacity, 1}));
  tqr.reserve(std::max({n, me, 1}), std::max(n, 1), 1);
  trz.reserve(std::max(n, 1), std::max(n, 1));
}

void Hierarchy::allocate_per_stage() {
  // the first call's shared factorisations are not used again (freed first: a lower peak)
  shared_trial_ = TrialState();
  shared_cf_ = ClosedForm();
  const int n = n_, blocks = static_cast<int>(meq_.size());
  const int nb = has_bounds_ ? n : 0;
  // each stage's working-set and K factorisations (trial_memo), sized for its own problem:
  // a level's has at most n + min_[b] columns (z and its slacks), the inequality rows of the
  // blocks above (inherited), the bounds and its own rows, and meq_[b] + n + min_[b]
  // objective rows (equalities or their R, damping, slacks); the minimum-norm stage n columns
  // and n objective rows; the hard phase's phase 1 a slack column and an objective row per
  // hard inequality row and per bound
  trials_.resize(blocks + 1);
  int above = 0;  // inequality rows of the blocks above stage b
  for (int b = 0; b <= blocks; ++b) {
    int cols = n + min_[0] + nb, grows = min_[0] + nb + 1, qrows = min_[0] + nb;
    if (b > 0 && b < blocks) {
      cols = n + min_[b];
      grows = above + nb + min_[b] + 1;
      qrows = meq_[b] + n + min_[b];
    } else if (b == blocks) {
      cols = n;
      grows = capacity_ + nb + 1;
      qrows = n;
    }
    cols = std::max(cols, 1);
    qrows = std::max(qrows, 1);
    if (b < blocks) above += min_[b];
    trials_[b].reserve(cols, grows, qrows, true);
  }
  // each level's closed-form factorisations (closed_form_memo), sized for its equality rows
  cforms_.resize(blocks);
  for (int b = 0; b < blocks; ++b) cforms_[b].reserve(n, meq_[b], capacity_);
  // each level's memo entry and freeze (freeze_memo; not the hard phase's)
  memos_.resize(blocks);
  // each level's and the minimum-norm step's bound rows (bound_rows_memo)
  bound_memos_.resize(blocks + 1);
  for (int b = 1; has_bounds_ && b <= blocks; ++b) {
    BoundRowsMemo& m = bound_memos_[b];
    m.Z.setZero(n, n);
    m.G.setZero(n, n);
    m.nrm.setZero(n);
  }
  for (int b = 1; b < blocks; ++b) {
    FreezeMemo& f = memos_[b];
    f.Z_in.setZero(n, n);
    f.Z_out.setZero(n, n);
    f.CinZ_in.setZero(std::max(capacity_, 1), std::max(n, 1));
    f.CinZ_out.setZero(std::max(capacity_, 1), std::max(n, 1));
    f.A.setZero(static_cast<Eigen::Index>(meq_[b]) * n);
    f.C.setZero(static_cast<Eigen::Index>(min_[b]) * n);
    f.viol.assign(std::max(min_[b], 1), 0);
  }
  per_stage_ = true;
}

void Hierarchy::invalidate_caches() {
  for (FreezeMemo& f : memos_) {
    f.valid = f.pending = f.zm_valid = false;
    f.a_layout = f.c_layout = 0;  // the level's rows compare unequal: M = A Z recomputed
  }
  for (ClosedForm& f : cforms_) f.valid = f.svd_valid = false;
  for (TrialState& t : trials_) t.intact = false;
  for (BoundRowsMemo& m : bound_memos_) m.valid = false;
}

bool Hierarchy::feasible(const Eigen::Ref<const Vec>& x) {
  if (has_bounds_)
    for (int j = 0; j < n_; ++j)
      if (!in_box(x(j), lb_(j), ub_(j))) return false;
  if (k_ == 0) return true;
  // one product (Cin_ is column-major: a row's dot product would read it with a stride)
  auto cx = cinx_.head(k_);
  cx.noalias() = Cin_.topRows(k_) * x;
  for (int i = 0; i < k_; ++i)
    if (!in_box(cx(i), lin_(i), uin_(i))) return false;
  return true;
}

void Hierarchy::snap(Vec& x) const {
  if (has_bounds_) x = x.cwiseMax(lb_).cwiseMin(ub_);
}

void Hierarchy::inherit(const CRef<Mat>& C, const CRef<Vec>& lo, const CRef<Vec>& hi, int row0,
                        int m, const std::vector<char>* skip) {
  for (int i = 0; i < m; ++i) {
    if (skip && (*skip)[i]) continue;
    const int g = row0 + i;
    if (!std::isfinite(lo(g)) && !std::isfinite(hi(g))) continue;
    const double v = C.row(g).dot(x_);
    Cin_.row(k_) = C.row(g);
    cin_norm_(k_) = -1.0;  // |Cin_.row(k_)| on first use (cin_norm)
    lin_(k_) = std::min(lo(g), v);  // opened to the current value: may stay, never grow
    uin_(k_) = std::max(hi(g), v);
    inid_[k_] = g;
    ++k_;
  }
}

double Hierarchy::cin_norm(int i) {
  if (cin_norm_(i) < 0.0) cin_norm_(i) = Cin_.row(i).norm();
  return cin_norm_(i);
}

void Hierarchy::add_inherited_rows(LsqProblem& P) {
  if (k_ == 0) return;
  auto full = rowbuf_.head(P.cols);
  full.setZero();
  // every inherited row projected at once (one matrix product, not k_ vector products)
  auto CZ = CinZ_.topLeftCorner(k_, r_);
  // rows inherited since the last projection; the older ones were carried through every
  // change of Z since (carry_z)
  if (kz_ < k_ && z_identity_) {  // Cin I: the rows themselves
    CinZ_.block(kz_, 0, k_ - kz_, r_) = Cin_.middleRows(kz_, k_ - kz_);
    ++stats_.identity_products;
  } else if (kz_ < k_) {
    CinZ_.block(kz_, 0, k_ - kz_, r_).noalias() =
        Cin_.middleRows(kz_, k_ - kz_) * Z_.leftCols(r_);
  }
  kz_ = k_;
  auto cx = cinx_.head(k_);
  cx.noalias() = Cin_.topRows(k_) * x_;
  for (int i = 0; i < k_; ++i) {
    full.head(r_) = CZ.row(i).transpose();
    const double l = std::min(lin_(i) - cx(i), 0.0);
    const double u = std::max(uin_(i) - cx(i), 0.0);
    P.add_row(full, l, u, inid_[i], cin_norm(i));
  }
}

void Hierarchy::add_bound_rows(LsqProblem& P, int stage) {
  if (!has_bounds_) return;
  const int r0 = P.rows, cols = P.cols;
  // (the bound-rows cache: the rows depend on Z alone, their bounds on x too; no row is
  // skipped unless a variable has no finite bound, or Z a zero row)
  BoundRowsMemo* memo = memo_gate() ? &bound_memos_[stage] : nullptr;
  bool all_finite = memo != nullptr;  // (only the memo reads it: every variable has a side)
  for (int j = 0; j < n_ && all_finite; ++j)
    all_finite = std::isfinite(lb_(j)) || std::isfinite(ub_(j));
  if (all_finite && memo->valid && memo->r == r_ &&
      (r_ == 0 ||
       std::memcmp(memo->Z.data(), Z_.data(), sizeof(double) * n_ * r_) == 0)) {
    P.G.block(r0, 0, n_, r_) = memo->G.topLeftCorner(n_, r_);
    if (cols > r_) P.G.block(r0, r_, n_, cols - r_).setZero();
    for (int j = 0; j < n_; ++j) {  // (as add_row: the bound over the row's norm)
      P.lo(r0 + j) = std::min(lb_(j) - x_(j), 0.0) / memo->nrm(j);
      P.hi(r0 + j) = std::max(ub_(j) - x_(j), 0.0) / memo->nrm(j);
      P.id[r0 + j] = capacity_ + j;
    }
    P.rows += n_;
    ++stats_.bound_rows_memo_hits;
    return;
  }
  auto full = rowbuf_.head(cols);
  full.setZero();
  for (int j = 0; j < n_; ++j) {
    full.head(r_) = Z_.row(j).head(r_).transpose();
    const double l = std::min(lb_(j) - x_(j), 0.0);
    const double u = std::max(ub_(j) - x_(j), 0.0);
    const double nrm = P.add_row(full, l, u, capacity_ + j, 1.0);
    if (memo) memo->nrm(j) = nrm;
  }
  if (!memo) return;
  // stored when every row was kept (a skipped row shifts the others: not one block)
  memo->valid = (P.rows - r0 == n_);
  if (!memo->valid) return;
  memo->r = r_;
  memo->Z.leftCols(r_) = Z_.leftCols(r_);
  memo->G.topLeftCorner(n_, r_) = P.G.block(r0, 0, n_, r_);
}

void Hierarchy::carry_z(PivotedQR& qr, int rank) {
  if (kz_ == 0) return;
  // rank reflectors on kz x r (about 4 rank kz r flops) against one product with the new Z
  // when the rows are next needed (2 kz n (r - rank)): many reflectors, or few rows left,
  // and the projection is dropped, recomputed where a level needs it
  if (2 * rank * r_ > n_ * (r_ - rank)) {
    kz_ = 0;
    return;
  }
  // Cin Z <- Cin Z Qf, its first rank columns dropped: the projection of the rows inherited
  // so far onto the new Z, at the cost of the rank reflectors (not a product with Z)
  auto CZ = CinZ_.topLeftCorner(kz_, r_);
  qr.apply_q_right(CZ);
  for (int i = 0; i < r_ - rank; ++i) CinZ_.col(i).head(kz_) = CinZ_.col(rank + i).head(kz_);
}

void Hierarchy::freeze(double scale) {
  const int f = fqr_.cols();
  if (f == 0 || r_ == 0) return;
  // numerical rank as qpcoord.core.linalg.numerical_rank: relative to max(|F|_2, scale),
  // the first pivot (largest row norm of F) standing for |F|_2
  const MapMat Ft = fqr_.matrix();
  const double first = Ft.colwise().norm().maxCoeff();
  const double tol = std::max(f, r_) * kEps * std::max(first, scale);
  const int rank = fqr_.factor(tol, 0.0);
  if (rank == 0) return;
  auto Zr = Z_.leftCols(r_);
  z_identity_ = false;
  fqr_.apply_q_right(Zr);  // Z Qf: its last r - rank columns span Z null(F)
  carry_z(fqr_, rank);
  for (int i = 0; i < r_ - rank; ++i) Z_.col(i) = Z_.col(rank + i);
  r_ -= rank;
}

void Hierarchy::freeze_wide(int rank) {
  auto Zr = Z_.leftCols(r_);
  z_identity_ = false;
  cf_->mqr.apply_q_right(Zr);
  carry_z(cf_->mqr, rank);
  for (int i = 0; i < r_ - rank; ++i) Z_.col(i) = Z_.col(rank + i);
  r_ -= rank;
}

bool Hierarchy::memo_entry(int stage, const CRef<Mat>& Aeq, int e0, int me, const CRef<Mat>& C,
                           int i0, int mi) {
  if (!per_stage_) return false;  // (the first call: no memo allocated yet)
  FreezeMemo& f = memos_[stage];
  f.rows_same = f.z_same = false;
  if (!memo_gate()) {  // Z differs from the last call's (or no memo): nothing kept
    f.valid = f.zm_valid = false;
    return false;
  }
  // the level's rows first (a changed Jacobian differs at its first entries, the IK's every
  // call): when they changed, only they are kept -- Z is kept once they repeat
  const bool same_a = same_rows_or_copy(Aeq.middleRows(e0, me), f.A, f.a_layout);
  const bool same_c = same_rows_or_copy(C.middleRows(i0, mi), f.C, f.c_layout);
  f.rows_same = same_a && same_c;
  if (!f.rows_same) {
    f.valid = f.zm_valid = false;
    return false;
  }
  const auto Zr = Z_.leftCols(r_);
  f.z_same = f.zm_valid && f.r_in == r_ && f.zid_in == z_identity_ &&
             (r_ == 0 || std::memcmp(f.Z_in.data(), Zr.data(), sizeof(double) * n_ * r_) == 0);
  if (!f.z_same) {  // the stored freeze had another Z: Z kept for the next call
    f.valid = false;
    f.Z_in.leftCols(r_) = Zr;
    f.r_in = r_;
    f.zid_in = z_identity_;
    f.zm_valid = true;
  }
  return f.z_same;
}

bool Hierarchy::freeze_lookup(int stage, FreezeKind kind, int rank, int mi, bool with_viol) {
  FreezeMemo& f = memos_[stage];
  f.pending = false;
  if (!f.rows_same) return false;  // (memo_entry: the rows changed)
  // Z on entry is the last call's (z_same) and the stored freeze had it (valid): the rest
  const auto CZ = CinZ_.topLeftCorner(kz_, r_);
  bool hit = f.z_same && f.valid && f.kind == kind && f.rank == rank && f.kz_in == kz_;
  for (int i = 0; hit && with_viol && i < mi; ++i) hit = f.viol[i] == viol_[i];
  hit = hit && same_bits(f.CinZ_in.topLeftCorner(kz_, r_), CZ);
  if (hit) {
    Z_.leftCols(f.r_out) = f.Z_out.leftCols(f.r_out);
    r_ = f.r_out;
    z_identity_ = f.zid_out;
    kz_ = f.kz_out;
    CinZ_.topLeftCorner(kz_, r_) = f.CinZ_out.topLeftCorner(kz_, r_);
    if (kind == FreezeKind::kNullSpace) ++stats_.null_space_freezes;  // as freeze_null_space
    ++stats_.freeze_memo_hits;
    return true;
  }
  // the rows repeat (Z_in is this call's Z), the rest is taken: outputs by freeze_computed
  f.valid = false;
  f.pending = true;
  f.kind = kind;
  f.rank = rank;
  f.kz_in = kz_;
  for (int i = 0; i < mi; ++i) f.viol[i] = with_viol ? viol_[i] : 0;
  f.CinZ_in.topLeftCorner(kz_, r_) = CZ;
  return false;
}

void Hierarchy::freeze_computed(int stage) {
  // Z is not the previous call's any more (to rounding it may be, not bit for bit): the
  // lower levels' freezes have other inputs, and are not looked up in this call
  if (!memo_gate()) return;
  z_repeats_ = false;
  FreezeMemo& f = memos_[stage];
  if (!f.pending) return;
  f.pending = false;
  f.r_out = r_;
  f.kz_out = kz_;
  f.zid_out = z_identity_;
  f.Z_out.leftCols(r_) = Z_.leftCols(r_);
  f.CinZ_out.topLeftCorner(kz_, r_) = CinZ_.topLeftCorner(kz_, r_);
  f.valid = true;
}

void Hierarchy::freeze_null_space(int rank) {
  const int l = r_ - rank;
  auto N = nsp_.topLeftCorner(r_, l);
  auto q = u_.head(r_);
  for (int t = 0; t < l; ++t) {  // column t of N: Z_rz^T e_{rank+t} (or Qf e_{rank+t}), permuted
    q.setZero();
    q(rank + t) = 1.0;
    cf_->trz.apply_zt(q);
    for (int i = 0; i < r_; ++i) N(cf_->mqr.perm(i), t) = q(i);
  }
  auto Zn = Ztmp_.leftCols(l);
  Zn.noalias() = Z_.leftCols(r_) * N;
  Z_.leftCols(l) = Zn;
  z_identity_ = false;
  if (kz_ > 0) {
    auto CZ = cztmp_.topLeftCorner(kz_, l);
    CZ.noalias() = CinZ_.topLeftCorner(kz_, r_) * N;
    CinZ_.topLeftCorner(kz_, l) = CZ;
  }
  r_ = l;
  ++stats_.null_space_freezes;
}

// ---------------------------------------------------------------------------------------
void Hierarchy::factor_rows(const LsqProblem& P, const std::vector<int8_t>& W) {
  const int k = P.cols;
  ts_->k_valid = false;
  trial_ready_ = false;
  widx_.clear();
  for (int i = 0; i < P.rows; ++i)
    if (W[i]) widx_.push_back(i);
  const int kw = static_cast<int>(widx_.size());
  MapMat GwT = ts_->wqr.matrix(k, kw);
  for (int j = 0; j < kw; ++j) GwT.col(j) = P.G.row(widx_[j]).head(k).transpose();
  ts_->wqr.factor(0.0, std::max(k, kw) * kEps * 10.0);
}

void Hierarchy::factor_working(const LsqProblem& P, const std::vector<int8_t>& W) {
  finish_ready_ = false;
  ts_->intact = false;
  factor_rows(P, W);
  // with the slack step the projected objective is rarely needed: formed on first use
  qt_stale_ = true;
  if (P.slacks == 0 && !unit_q_) form_qt(P);
}

void Hierarchy::form_qt(const LsqProblem& P) {
  auto Qt = ts_->Qt.topLeftCorner(P.qrows, P.cols);
  Qt = P.Q.topLeftCorner(P.qrows, P.cols);
  ts_->wqr.apply_q_right(Qt);  // every transform of the working set's QR so far, in order
  qt_stale_ = false;
}

bool Hierarchy::trial_restore(const LsqProblem& P, const std::vector<int8_t>& W) {
  TrialState& t = *ts_;
  const int k = P.cols, qr = P.qrows;
  if (!t.intact || t.key_k != k || t.key_qrows != qr || t.key_unit_q != unit_q_ ||
      t.key_slacks[0] != P.slacks ||
      t.key_slacks[1] != P.zcols || t.key_slacks[2] != P.slack_q0 ||
      t.key_slacks[3] != P.slack_g0)
    return false;
  int kw = 0;
  const int kmax = static_cast<int>(t.key_widx.size());
  for (int i = 0; i < P.rows; ++i) {
    if (!W[i]) continue;
    if (kw >= kmax || t.key_widx[kw] != i) return false;
    ++kw;
  }
  if (kw != kmax) return false;
  const double* g = t.key_G.data();
  for (int j = 0; j < kw; ++j, g += k) {
    const auto row = P.G.row(t.key_widx[j]).head(k);
    for (int c = 0; c < k; ++c)
      if (std::memcmp(&g[c], &row.coeffRef(c), sizeof(double)) != 0) return false;
  }
  const double* q = t.key_Q.data();
  for (int c = 0; c < k && qr > 0; ++c, q += qr)
    if (std::memcmp(q, P.Q.col(c).data(), sizeof(double) * qr) != 0) return false;
  // the same factorisations as factor_trial's: its flags as it leaves them (K, when the
  // trial's ls_step made it, is still the factorisation of this trial's K: k_valid kept)
  widx_ = t.key_widx;
  finish_ready_ = false;
  trial_ready_ = false;
  qt_stale_ = t.key_qt_stale;
  ++stats_.trial_memo_hits;
  return true;
}

void Hierarchy::trial_keep(const LsqProblem& P) {
  TrialState& t = *ts_;
  const int k = P.cols, qr = P.qrows, kw = static_cast<int>(widx_.size());
  // (more working rows than columns, or a problem larger than the stage's key: not kept)
  if (static_cast<Eigen::Index>(kw) * k > t.key_G.size() ||
      static_cast<Eigen::Index>(qr) * k > t.key_Q.size()) {
    t.intact = false;
    return;
  }
  t.key_k = k;
  t.key_qrows = qr;
  t.key_unit_q = unit_q_;
  t.key_qt_stale = qt_stale_;
  t.key_slacks = {P.slacks, P.zcols, P.slack_q0, P.slack_g0};
  t.key_widx = widx_;
  double* g = t.key_G.data();
  for (int j = 0; j < kw; ++j, g += k)
    for (int c = 0; c < k; ++c) g[c] = P.G(widx_[j], c);
  double* q = t.key_Q.data();
  for (int c = 0; c < k && qr > 0; ++c, q += qr)
    std::memcpy(q, P.Q.col(c).data(), sizeof(double) * qr);
  t.intact = true;
}

void Hierarchy::factor_trial(const LsqProblem& P, const std::vector<int8_t>& W) {
  // (trial_memo: the stage's last trial had these rows and objective, its factorisations
  // untouched since: nothing to compute. Only above every computed freeze of the call:
  // below one, Z and with it every projected row differ from the last call's)
  const bool memo = per_stage_ && z_repeats_;
  if (memo && trial_restore(P, W)) return;
  factor_trial_computed(P, W);
  if (memo) trial_keep(P);
}

void Hierarchy::factor_trial_computed(const LsqProblem& P, const std::vector<int8_t>& W) {
  if (unit_q_) {  // (factor_working forms no Q Qf either)
    factor_working(P, W);
    return;
  }
  ts_->intact = false;
  const int k = P.cols;
  // not the active set's end any more: the exact finish must not reuse this factorisation
  finish_ready_ = false;
  // Qt holds only the null-space columns below (all ls_step reads); the active set starts
  // from factor_working, so no downdate or append reads the stale leading columns
  qt_stale_ = false;
  factor_rows(P, W);
  // (Q Qf)(i, :) = (Qf^T Q(i, :)^T)^T, row by row; only its columns rank.. (null(G_w)) are
  // kept: the least-squares step reads no other (none at a vertex of the working set)
  const int rho = ts_->wqr.rank(), nk = k - rho;
  if (nk == 0) return;
  auto v = rowbuf_.head(k);
  for (int i = 0; i < P.qrows; ++i) {
    v = P.Q.row(i).head(k).transpose();
    ts_->wqr.apply_qt(v);
    ts_->Qt.row(i).segment(rho, nk) = v.tail(nk).transpose();
  }
}

/// Form K = Q N (N = Qf(:, rank:), the working set's null space) and factorise it for
/// ls_step: k_mode kZero (K is rounding noise: the step is zero), kWide (a wide K of full
/// row rank: the QR of K^T in kqr_t) or kTall (the pivoted QR of K in kqr, rank k_rank;
/// rank-deficient: the RZ of [R11 R12] in krz, or its transpose's QR in cqr). Sets
/// k_valid; false when K is zero (all in the stage's TrialState).
/// Numerical rank of K as qpcoord.core.linalg.numerical_rank with the scale of Q before
/// projection: a K whose columns are rounding noise (the working set's rows span what Q can
/// change) is rank 0, not a full-rank matrix of size 1e-16.
bool Hierarchy::factor_k(const LsqProblem& P) {
  const int k = P.cols, qr = P.qrows, rho = ts_->wqr.rank(), nk = k - rho;
  if (qt_stale_) form_qt(P);
  const auto K = ts_->Qt.block(0, rho, qr, nk);
  const double kmax = K.colwise().norm().maxCoeff();
  const double tol = std::max(qr, nk) * kEps * std::max(kmax, qscale_);
  ts_->k_valid = true;
  ts_->k_mode = KMode::kZero;
  if (!(kmax > tol)) return false;
  // a wide K (more free directions than objective rows) of full row rank: K s = -res is
  // consistent and its minimum-norm solution comes from one QR of K^T (nk x qr), without
  // the QR of K and the second one of [R11 R12]^T below
  if (nk > qr) {
    ts_->kqr_t.matrix(nk, qr) = K.transpose();
    if (ts_->kqr_t.factor(tol, 0.0) == qr) {
      ts_->k_mode = KMode::kWide;
      return true;
    }
  }
  ts_->kqr.matrix(qr, nk) = K;
  const int rk = ts_->kqr.factor(tol, 0.0);
  ts_->k_mode = KMode::kTall;
  ts_->k_rank = rk;
  ts_->k_rz = false;
  if (rk > 0 && rk < nk) {
    const auto Kf = ts_->kqr.matrix();
    {
      MapMat T = ts_->krz.matrix(rk, nk);  // [R11 R12]^T (its upper triangle is not read)
      for (int i = 0; i < rk; ++i) T.col(i).tail(nk - i) = Kf.row(i).segment(i, nk - i).transpose();
      // R11 is nonsingular (its pivots are above tol); the QR of [R11 R12]^T stands in should
      // the RZ meet an exactly zero pivot all the same
      ts_->k_rz = ts_->krz.factor();
      if (ts_->k_rz) ++stats_.rz_factors;
    }
    if (!ts_->k_rz) {
      MapMat T = ts_->cqr.matrix(nk, rk);  // [R11 R12]^T
      T.setZero();
      for (int i = 0; i < rk; ++i)
        T.col(i).tail(nk - i) = Kf.row(i).segment(i, nk - i).transpose();
      ts_->cqr.factor(0.0, 0.0);
    }
  }
  return true;
}

/// The minimum-residual step in null(G_w) = span(Qf(:, rank:)): min ||Q (y + N s) - c||, by
/// slack_step or K's factorisation (factor_k, or the last one's on the same working set's
/// QR with reuse_k_qr).
void Hierarchy::ls_step(const LsqProblem& P, const Eigen::Ref<const Vec>& y,
                        Eigen::Ref<Vec> step) {
  const int k = P.cols, qr = P.qrows, rho = ts_->wqr.rank(), nk = k - rho;
  const auto Q = P.Q.topLeftCorner(qr, k);
  auto res = res_.head(qr);
  res.noalias() = Q * y;
  res -= P.c.head(qr);
  step.setZero();
  if (nk == 0 || qr == 0) return;
  if (unit_q_) {
    // Q^T Q = I: K = Q N has orthonormal columns (K^T K = N^T N = I, full column rank), so
    // the least squares min |K s + res| is s = -K^T res = -N^T g, g = Q^T res the gradient:
    // the step -N N^T g from the working set's QR alone (its columns rho.. span null(G_w))
    auto g = u_.head(k);
    g.noalias() = Q.transpose() * res;
    ts_->wqr.apply_qt(g);
    step.segment(rho, nk) = -g.segment(rho, nk);
    ts_->wqr.apply_q(step);
    ++stats_.least_distance_steps;
    return;
  }
  if (ts_->k_valid) {
    // the same working set's QR as the last step: the same K (a K^T or slack_step decided
    // by W and P alone: the same path), only the right-hand side changed
    ++stats_.k_qr_reuses;
  } else {
    ts_->k_valid = false;
    if (P.slacks > 0) {
      if (slack_step(P, step)) {
        ++stats_.slack_steps;
        return;
      }
      step.setZero();
    }
    if (!factor_k(P)) return;
  }
  auto rhs = tvec_.head(qr);
  rhs = -res;
  if (ts_->k_mode == KMode::kZero) return;
  if (ts_->k_mode == KMode::kWide) {
    auto s = u_.head(nk);
    ts_->kqr_t.min_norm_transposed_solve(rhs, s);
    step.segment(rho, nk) = s;
    ts_->wqr.apply_q(step);
    return;
  }
  const int rk = ts_->k_rank;
  ts_->kqr.apply_qt(rhs);
  // step = Qf [0; s]; K P = Qk [R11 R12; 0 0]: with full column rank s(perm(i)) = u(i),
  // u = R11^-1 (Qk^T (-res))(0:rk); rank-deficient K: the minimum-norm s (as a complete
  // orthogonal decomposition), u the min-norm solution of [R11 R12] u = (Qk^T (-res))(0:rk)
  if (rk == nk) {
    ts_->kqr.solve_r(rhs);
    for (int i = 0; i < rk; ++i) step(rho + ts_->kqr.perm(i)) = rhs(i);
  } else if (rk > 0) {
    auto u = u_.head(nk);
    if (ts_->k_rz)
      ts_->krz.min_norm_solve(rhs.head(rk), u);
    else
      ts_->cqr.min_norm_transposed_solve(rhs.head(rk), u);
    for (int i = 0; i < nk; ++i) step(rho + ts_->kqr.perm(i)) = u(i);
  }
  ts_->wqr.apply_q(step);
}

/// min |s| s.t. G_w s = 0, Q s = -res in y = (z, w). Every slack j appears in one objective
/// row alone (Q(q0 + j, zc + j) = sw_j != 0): the solutions all share s_j = -res_j / sw_j,
/// and their z part solves (in minimum norm: the slacks' part is fixed)
///   [G_w(:, z); Q(0:q0, z)] s_z = [-G_w(:, w) s_w; -res(0:q0)]
/// by one pivoted QR of its transpose (zc x (kw + q0)). With full row rank the system is
/// consistent: the projected least squares of ls_step has residual zero and this same
/// minimum-norm step.
bool Hierarchy::slack_step(const LsqProblem& P, Eigen::Ref<Vec> step) {
  const int zc = P.zcols, ns = P.slacks, q0 = P.slack_q0, g0 = P.slack_g0;
  const int kw = static_cast<int>(widx_.size()), mr = kw + q0;
  if (ts_->wqr.rank() < kw) return false;  // dependent working rows: the general path
  if (mr > zc) return false;  // more conditions than unknowns: no exact step in general
  const auto res = res_.head(P.qrows);
  const double stol = std::max(P.qrows, P.cols) * kEps * std::max(qscale_, 1e-300);
  for (int j = 0; j < ns; ++j) {
    const double sw = P.Q(q0 + j, zc + j);
    if (!(std::abs(sw) > stol)) return false;  // (near) zero weight: K is rank-deficient
    step(zc + j) = -res(q0 + j) / sw;
  }
  MapMat T = sqr_.matrix(zc, mr);
  auto b = tvec_.head(mr);
  for (int c = 0; c < kw; ++c) {
    const int i = widx_[c];
    T.col(c) = P.G.row(i).head(zc).transpose();
    b(c) = (i >= g0) ? -P.G(i, zc + i - g0) * step(zc + i - g0) : 0.0;
  }
  for (int r = 0; r < q0; ++r) T.col(kw + r) = P.Q.row(r).head(zc).transpose();
  b.tail(q0) = -res.head(q0);
  const double tmax = mr ? T.colwise().norm().maxCoeff() : 0.0;
  const double tol = std::max(zc, mr) * kEps * std::max(tmax, qscale_);
  if (mr && sqr_.factor(tol, 0.0) < mr) return false;
  auto v = u_.head(zc);
  if (mr)
    sqr_.min_norm_transposed_solve(b, v);
  else
    v.setZero();
  step.head(zc) = v;
  return true;
}

bool Hierarchy::multipliers_ok(const LsqProblem& P, const Eigen::Ref<const Vec>& y,
                               const std::vector<int8_t>& W, int* drop,
                               const std::vector<char>* keep, bool bland) {
  const int k = P.cols;
  const int kw = static_cast<int>(widx_.size());
  if (kw == 0) return true;
  const double tol = sign_tolerance(P, y, qscale_);
  const auto g = gvec_.head(k);
  // G_w^T u = g in least squares through the working set's QR; mu = sign * u
  auto u = u_.head(k);
  u = g;
  ts_->wqr.apply_qt(u);
  ts_->wqr.solve_r(u);
  auto mu = mu_.head(kw);
  mu.setZero();
  for (int i = 0; i < ts_->wqr.rank(); ++i) mu(ts_->wqr.perm(i)) = u(i);
  int jmin = -1;
  double mmin = kInf;
  for (int j = 0; j < kw; ++j) {
    const int i = widx_[j];
    if (W[i] == 2) continue;           // equalities are never dropped
    if (keep && (*keep)[i]) continue;  // re-blocked right after a drop: multiplier is zero
    const double v = (W[i] == 1) ? -mu(j) : mu(j);
    if (v >= -tol) continue;
    if (bland) {  // degenerate stretch: the lowest index with a negative multiplier
      if (jmin < 0 || i < jmin) jmin = i;
      continue;
    }
    if (v < mmin || (v == mmin && i < jmin)) {
      mmin = v;
      jmin = i;
    }
  }
  if (jmin < 0) return true;
  if (drop) *drop = jmin;
  return false;
}

double Hierarchy::sign_tolerance(const LsqProblem& P, const Eigen::Ref<const Vec>& y,
                                 double qn) {
  const int k = P.cols, qr = P.qrows;
  const auto Q = P.Q.topLeftCorner(qr, k);
  auto res = dres_.head(qr);
  res.noalias() = Q * y;
  res -= P.c.head(qr);
  auto g = gvec_.head(k);
  g.noalias() = Q.transpose() * res;
  // a multiplier counts as negative beyond the sign tolerance (relative to the gradient) and
  // beyond the rounding of the gradient itself (g = Q^T (Q y - c) in floating point)
  const double gref = std::max(g.cwiseAbs().maxCoeff(), 1e-300);
  const double round =
      kRoundFactor * kEps * k * qn * (qn * y.cwiseAbs().maxCoeff() + P.c_norm());
  return (exact_ ? 0.0 : settings.kkt_tol * gref) + round;
}

void Hierarchy::add_zero_blockers(const LsqProblem& P, std::vector<int8_t>& W,
                                  int dropped, double smax, double yscale, bool& current) {
  const int k = P.cols, qr = P.qrows, m = P.rows;
  // the ratio test's products gp = G step and gy = G y (y before its move of length zero)
  const auto gp = gp_.head(m);
  const auto gy = gy_.head(m);
  const double tiny = 1e-13 * smax;
  for (int i = 0; i < m; ++i) {
    if (W[i] || i == dropped) continue;  // (the dropped row: active_set's keep rule)
    int8_t sd;
    const double t = bound_step(gp(i), gy(i), P.lo(i), P.hi(i), tiny, sd);
    if (!(t * smax <= 1e-14 * yscale)) continue;  // active_set's `moved` test
    W[i] = sd;
    ++stats_.batch_rows;
    // (a failed append leaves the row in W: the next iteration refactorises)
    if (current && ts_->wqr.append(P.G.row(i).head(k).transpose())) {
      widx_.push_back(i);
      if (!qt_stale_) ts_->wqr.apply_last_right(ts_->Qt.topLeftCorner(qr, k));
    } else {
      current = false;
    }
  }
}

bool Hierarchy::active_set(const LsqProblem& P, Eigen::Ref<Vec> y, std::vector<int8_t>& W,
                           int& iters) {
  ts_->intact = false;  // (trial_memo: its updates change the stage's factorisations)
  const int k = P.cols;
  const int m = P.rows;
  const int qr = P.qrows;
  const auto Q = P.Q.topLeftCorner(qr, k);
  const auto c = P.c.head(qr);
  const double cn = P.c_norm();
  qscale_ = Q.norm();
  const int max_iter = settings.max_iter_factor * (m + k) + 10;
  auto step = step_.head(k);
  auto dres = dres_.head(qr);
  auto gy = gy_.head(m);
  auto gp = gp_.head(m);
  auto qy = e_.head(qr);
  // anti-cycling: a row dropped for a negative multiplier that blocks the very next step at
  // once had a multiplier that is zero to rounding; it is put back and kept ("keep") until
  // the point moves. After several steps of length zero in a row, Bland's rule (lowest
  // index) chooses the row to drop; ties in the ratio test go to the lowest index always.
  std::fill(keep_.begin(), keep_.begin() + m, 0);
  int last_drop = -1;
  int zero_steps = 0;
  bool dropped_since_move = false;  // a row left W since y last moved (tight_batch)
  // tight_batch on a cold start only (no one-sided row in the starting W): rows batched into
  // a seeded start's set end in the stored set more often than its steps would put them
  // there, and the next call's warm trial misses more (random50: +6 % instructions)
  bool batch_ok = true;
  for (int i = 0; i < m && batch_ok; ++i)
    if (W[i] == 1 || W[i] == -1) batch_ok = false;
  bool current = false;  // the working set's factorisation matches W (after an append)
  // the exact finish right after an optimal end: its first step is that end's last one
  bool reuse = exact_ && finish_ready_;
  finish_ready_ = false;
  // the exact finish right after a warm trial hit: W and y are the trial's, so is its
  // working set's QR (wqr, widx_) and K's factorisation; the trial kept only the
  // null-space columns of Q Qf (factor_trial): formed in full when an update needs them
  bool trial = exact_ && trial_ready_ && !reuse;
  trial_ready_ = false;
  // the current working set's sub-threshold step was taken (see `stationary` below)
  bool finished = false;
  for (int it = 0; it < max_iter; ++it) {
    if (out_of_time()) {
      timed_out_ = true;
      return false;
    }
    ++iters;
    if (reuse) {  // wqr, widx_, res_ and step_ are those of this W and y
      reuse = false;
    } else {
      if (trial) {
        trial = false;
        qt_stale_ = true;
      } else if (!current) {
        factor_working(P, W);
      }
      ls_step(P, y, step);  // res_ = Q y - c
    }
    current = false;
    const auto res = res_.head(qr);
    dres.noalias() = Q * step;
    const double gain = -(2.0 * res.dot(dres) + dres.squaredNorm());
    const double smax = step.cwiseAbs().maxCoeff();
    const double yscale = std::max(1.0, y.cwiseAbs().maxCoeff());
    // stationary on W: the step no longer decreases the objective measurably (relative to
    // its value, with a floor at rounding of the data's scale), or it is rounding itself
    qy = res + c;
    // (the rounding of res = Q y - c is relative to |Q| |y|, not to |Q y| ~ |c|, where y is
    // large and Q y cancels: a 30 x 8 level whose point sat at |y| ~ 650 gained ~1e-26 per
    // step of ~1e-10, rounding, without end -- tests/core/test_native_memo.py's seed 4857)
    const double qys = exact_ ? 0.0 : qscale_ * yscale;
    const double floor = 1e-28 * std::max({cn * cn, qy.squaredNorm(), qys * qys});
    // (exact_: a step is taken unless it is rounding: on a direction of curvature tau^2 a
    // step gaining 1e-19 of the objective can still move y by ~1)
    bool stationary = exact_ ? (gain <= floor || smax <= 8.0 * kEps * yscale)
                             : (gain <= 1e-15 * (res.squaredNorm() + P.dropped2) + floor ||
                                smax <= 1e-15 * yscale);
    // a step gaining under 1e-15 of a large objective that is no rounding is still taken,
    // once per working set (a level with residual 8.5 hid a 4.5e-8 step: the Talos step of
    // tests/core/test_talos_joint_limit_oracle.py; as polish.active_set_ls)
    if (stationary && !exact_ && !finished && smax > 8.0 * kEps * yscale) {
      stationary = false;
      finished = true;
    }
    if (stationary) {
      int drop = -1;
      if (multipliers_ok(P, y, W, &drop, &keep_, zero_steps > kBlandAfter)) {
        finish_ready_ = true;
        return true;
      }
      W[drop] = 0;
      last_drop = drop;
      dropped_since_move = true;
      finished = false;
      // the row leaves: downdate the working set's QR and Q Qf instead of refactorising
      const auto pos = std::find(widx_.begin(), widx_.end(), drop);
      if (pos != widx_.end() &&
          ts_->wqr.remove(static_cast<int>(pos - widx_.begin()),
                          ts_->Qt.topLeftCorner(qt_stale_ ? 0 : qr, k))) {
        widx_.erase(pos);
        ts_->k_valid = false;
        current = true;
        ++stats_.downdates;
      }
      continue;
    }
    // ratio test on the rows outside the working set (ties: the lowest index)
    double alpha = 1.0;
    int block = -1;
    int8_t side = 0;
    if (m) {
      gp.noalias() = P.G.topLeftCorner(m, k) * step;
      gy.noalias() = P.G.topLeftCorner(m, k) * y;
      const double tiny = 1e-13 * smax;
      for (int i = 0; i < m; ++i) {
        if (W[i]) continue;
        int8_t sd;
        const double t = bound_step(gp(i), gy(i), P.lo(i), P.hi(i), tiny, sd);
        if (t < alpha) {
          alpha = t;
          block = i;
          side = sd;
        }
      }
    }
    const bool moved = alpha * smax > 1e-14 * yscale;
    if (!moved && block >= 0 && block == last_drop) {
      W[block] = side;  // its multiplier was zero to rounding: back, and kept
      keep_[block] = 1;
      last_drop = -1;
      continue;
    }
    const int dropped = last_drop;
    last_drop = -1;
    if (moved) {
      std::fill(keep_.begin(), keep_.begin() + m, 0);
      zero_steps = 0;
      dropped_since_move = false;
    } else {
      ++zero_steps;
    }
    y += alpha * step;
    if (block >= 0) {
      finished = false;
      W[block] = side;
      // one row enters: update the working set's QR and Q Qf instead of refactorising
      if (ts_->wqr.append(P.G.row(block).head(k).transpose())) {
        widx_.push_back(block);
        ts_->k_valid = false;
        if (!qt_stale_) ts_->wqr.apply_last_right(ts_->Qt.topLeftCorner(qr, k));
        current = true;
      } else {
        current = false;
      }
      // tight_batch: the step is blocked at length zero; every other row that blocks it at
      // length zero enters too (y does not move: each would block the next step at once).
      // Not in Bland's regime once a row has left at this point (the drops and entries of a
      // degenerate stretch go by the lowest index there); rows that only enter cannot cycle
      if (batch_ok && !moved && (zero_steps <= kBlandAfter || !dropped_since_move))
        add_zero_blockers(P, W, dropped, smax, yscale, current);
    } else {
      current = true;  // W unchanged
    }
  }
  return exact_;  // the exact finish at its cap: y is feasible and no worse than its start
}

int Hierarchy::stored_set_point(const LsqProblem& P, const Working& ws, std::vector<int8_t>& W,
                                bool* consistent) {
  *consistent = false;
  if (!ws.stored) return 0;
  const int k = P.cols;
  const int found = map_working_set(P, ws, W);
  if (!found && !ws.id.empty()) return 0;
  qscale_ = P.Q.topLeftCorner(P.qrows, k).norm();
  factor_trial(P, W);
  auto yp = xc_.head(k);
  if (!working_set_point(P, W, yp, consistent)) return 0;
  auto step = step_.head(k);
  ls_step(P, yp, step);
  yp += step;
  trial_ready_ = true;  // wqr and K are those of W on P (the exact finish's start)
  return found;
}

bool Hierarchy::working_set_point(const LsqProblem& P, const std::vector<int8_t>& W,
                                  Eigen::Ref<Vec> y, bool* consistent) {
  const int k = P.cols, kw = static_cast<int>(widx_.size());
  auto t = tvec_.head(kw);
  for (int j = 0; j < kw; ++j) {
    const int i = widx_[j];
    t(j) = (W[i] == 1) ? P.hi(i) : P.lo(i);
    if (!std::isfinite(t(j))) return false;
  }
  // the point on the working set's rows: G_w y = t, y = Qf [R11^-T (P^T t)_(1:rank); 0]
  const int rho = ts_->wqr.rank();
  y.setZero();
  for (int i = 0; i < rho; ++i) y(i) = t(ts_->wqr.perm(i));
  ts_->wqr.solve_rt(y);
  ts_->wqr.apply_q(y);
  *consistent = true;
  if (kw) {
    const double tmax = std::max(1.0, t.cwiseAbs().maxCoeff());
    for (int j = 0; j < kw && *consistent; ++j)
      if (std::abs(P.G.row(widx_[j]).head(k).dot(y) - t(j)) > 1e-10 * tmax) *consistent = false;
  }
  return true;
}

int Hierarchy::map_working_set(const LsqProblem& P, const Working& ws, std::vector<int8_t>& W) {
  // the equality rows (lo = hi: hard or inherited rows fixed at their value) are in every
  // working set, as in the cold start: store_working_set keeps the one-sided rows only, and
  // a point on the stored rows alone is free to leave an equality row (issue 24: the
  // humanoid's box form missed on every call, its point off two inherited rows lo = hi = 0)
  for (int i = 0; i < P.rows; ++i) W[i] = (P.lo(i) == P.hi(i)) ? 2 : 0;
  int found = 0;
  for (size_t j = 0; j < ws.id.size(); ++j) {
    for (int i = 0; i < P.rows; ++i) {
      if (P.id[i] == ws.id[j]) {
        if (W[i] != 2) W[i] = ws.side[j];
        ++found;
        break;
      }
    }
  }
  return found;
}

int Hierarchy::reduced_set_point(const LsqProblem& P, int mv, const Working& ws,
                                 std::vector<int8_t>& W, bool* consistent) {
  *consistent = false;
  if (!ws.stored) return 0;
  const int k = P.cols, hard = P.rows - mv, zc = k - mv;
  const int found = map_working_set(P, ws, W);
  if (!found && !ws.id.empty()) return 0;
  // slack rows: row hard + j has its slack in column zc + j (G(i, zc + j) = -s_i < 0) and
  // the objective row q0 + j = sw_j there; the rows above q0 have no slack entries
  const int q0 = P.qrows - mv;
  int ns = 0;
  for (int j = 0; j < mv; ++j) {
    const int i = hard + j;
    if (!W[i]) continue;
    const double t = (W[i] == 1) ? P.hi(i) : P.lo(i);
    // a working row without weight leaves its slack free in the objective: its point is the
    // minimum norm over (z, w), which the reduced problem does not see (the full trial)
    if (!std::isfinite(t) || !(P.Q(q0 + j, zc + j) > 0.0)) return -1;
    ++ns;
  }
  LsqProblem& R = Pr_;
  R.start(q0 + ns, zc);
  R.Q.topLeftCorner(q0, zc) = P.Q.topLeftCorner(q0, zc);
  R.c.head(q0) = P.c.head(q0);
  // a working slack row at its bound t: w_j = (g_z z - t) / s, its objective term
  // (sw_j w_j)^2 = ((sw_j / s) (g_z z - t))^2: a row of the objective in z
  for (int j = 0, d = q0; j < mv; ++j) {
    const int i = hard + j;
    if (!W[i]) continue;
    const double t = (W[i] == 1) ? P.hi(i) : P.lo(i);
    const double f = P.Q(q0 + j, zc + j) / -P.G(i, zc + j);
    R.Q.row(d).head(zc) = f * P.G.row(i).head(zc);
    R.c(d++) = f * t;
  }
  // the rows without slack, where working (the others are not read)
  R.rows = hard;
  for (int i = 0; i < hard; ++i) {
    if (!W[i]) continue;
    R.G.row(i).head(zc) = P.G.row(i).head(zc);
    R.lo(i) = P.lo(i);
    R.hi(i) = P.hi(i);
  }
  qscale_ = R.Q.topLeftCorner(R.qrows, zc).norm();
  factor_trial(R, W);
  // z on the working rows without slack (minimum norm; R's rows and bounds there are P's),
  // then the least squares in their null space, as stored_set_point on the full problem
  auto yp = xc_.head(k);
  yp.setZero();
  auto zp = yp.head(zc);
  if (!working_set_point(R, W, zp, consistent)) return 0;
  auto step = step_.head(zc);
  ls_step(R, zp, step);
  zp += step;
  // the slacks: a working row's from its bound, the others' 0 (their least-squares value)
  for (int j = 0; j < mv; ++j) {
    const int i = hard + j;
    if (!W[i]) continue;
    const double tb = (W[i] == 1) ? P.hi(i) : P.lo(i);
    yp(zc + j) = (P.G.row(i).head(zc).dot(zp) - tb) / -P.G(i, zc + j);
  }
  return found;
}

bool Hierarchy::reduced_multipliers_ok(const LsqProblem& P, int mv,
                                       const Eigen::Ref<const Vec>& y,
                                       const std::vector<int8_t>& W) {
  const int k = P.cols, hard = P.rows - mv, zc = k - mv;
  // (P's own scale: qscale_ is the reduced problem's here)
  const double tol = sign_tolerance(P, y, P.Q.topLeftCorner(P.qrows, k).norm());
  const auto g = gvec_.head(k);
  auto sign_bad = [&](int i, double mu) {
    if (W[i] == 2) return false;
    return ((W[i] == 1) ? -mu : mu) < -tol;
  };
  // a working slack row's multiplier from its slack column alone (no other working row has
  // an entry there): mu G(i, zc + j) = g(zc + j); its z part leaves the rows without slack
  auto gz = u_.head(k);
  gz.setZero();
  gz.head(zc) = g.head(zc);
  for (int j = 0; j < mv; ++j) {
    const int i = hard + j;
    if (!W[i]) continue;
    const double mu = g(zc + j) / P.G(i, zc + j);
    if (sign_bad(i, mu)) return false;
    gz.head(zc) -= mu * P.G.row(i).head(zc).transpose();
  }
  // the rows without slack: G_h^T u = g_z - sum mu_s g_s in least squares (reduced_set_point's
  // QR of G_h^T in wqr, its rows in widx_)
  const int kw = static_cast<int>(widx_.size());
  if (kw == 0) return true;
  auto u = gz.head(zc);
  ts_->wqr.apply_qt(u);
  ts_->wqr.solve_r(u);
  auto mu = mu_.head(kw);
  mu.setZero();
  for (int i = 0; i < ts_->wqr.rank(); ++i) mu(ts_->wqr.perm(i)) = u(i);
  for (int j = 0; j < kw; ++j)
    if (sign_bad(widx_[j], mu(j))) return false;
  return true;
}

bool Hierarchy::try_working_set(const LsqProblem& P, const Working& ws, Eigen::Ref<Vec> y,
                                std::vector<int8_t>& W, int* found) {
  const int k = P.cols;
  *found = 0;
  trial_ready_ = false;
  if (!ws.stored) return false;
  bool consistent = false;
  // a level's slack rows (mv > 0): the trial in z alone, the working rows' slacks eliminated
  const int reduced =
      (slack_rows_ > 0) ? reduced_set_point(P, slack_rows_, ws, W, &consistent) : -1;
  if (reduced >= 0) ++stats_.reduced_trials;
  *found = (reduced >= 0) ? reduced : stored_set_point(P, ws, W, &consistent);
  if (*found != static_cast<int>(ws.id.size()) || !consistent) return false;
  auto yp = xc_.head(k);
  auto gy = gy_.head(P.rows);
  gy.noalias() = P.G.topLeftCorner(P.rows, k) * yp;
  for (int i = 0; i < P.rows; ++i) {
    const double sl = kWarmFeasTol * std::max(1.0, finite_abs(P.lo(i)));
    const double su = kWarmFeasTol * std::max(1.0, finite_abs(P.hi(i)));
    if (gy(i) < P.lo(i) - sl || gy(i) > P.hi(i) + su) return false;
  }
  if (reduced >= 0 ? !reduced_multipliers_ok(P, slack_rows_, yp, W)
                   : !multipliers_ok(P, yp, W, nullptr, nullptr, false))
    return false;
  y.head(k) = yp;
  return true;
}

bool Hierarchy::seed_working_set(const LsqProblem& P, const Working& ws, int hard_rows,
                                 int zcols, Eigen::Ref<Vec> y, std::vector<int8_t>& W) {
  const int k = P.cols, m = P.rows;
  (void)ws;  // its point is in xc_ already (try_working_set's stored_set_point)
  auto yp = xc_.head(k);
  if (!yp.allFinite()) return false;
  // ratio test from z = 0 towards z_p on the rows without slack (feasible at z = 0)
  const auto zp = yp.head(zcols);
  const double smax = zp.cwiseAbs().maxCoeff();
  const double tiny = 1e-13 * smax;
  double alpha = 1.0;
  int block = -1;
  int8_t side = 0;
  for (int i = 0; i < hard_rows; ++i) {
    const double gd = P.G.row(i).head(zcols).dot(zp);
    int8_t sd;
    const double a = bound_step(gd, 0.0, P.lo(i), P.hi(i), tiny, sd);  // from z = 0
    if (a < alpha) {
      alpha = a;
      block = i;
      side = sd;
    }
  }
  // alpha = 0 (blocked at once) is the cold start's point, with the stored rows tight there
  y.setZero();
  y.head(zcols) = alpha * zp;
  // each level row's slack: its violation at z (rows hard_rows.. have one slack column each)
  for (int i = hard_rows; i < m; ++i) {
    // its slack column: the next one (levels: one per row, in order), else the one nonzero
    // of the row past zcols (the hard phase skips the rows the equalities fix)
    int col = zcols + (i - hard_rows);
    if (col >= k || P.G(i, col) == 0.0) {
      col = -1;
      for (int c = zcols; c < k && col < 0; ++c)
        if (P.G(i, c) != 0.0) col = c;
      if (col < 0) continue;
    }
    const double a = -P.G(i, col);  // 1 / |row| > 0
    const double gz = P.G.row(i).head(zcols).dot(y.head(zcols));
    y(col) = (gz > P.hi(i)) ? (gz - P.hi(i)) / a : ((gz < P.lo(i)) ? (gz - P.lo(i)) / a : 0.0);
  }
  // the working set: equality rows, stored rows still tight, the blocking row
  auto gy = gy_.head(m);
  gy.noalias() = P.G.topLeftCorner(m, k) * y;
  for (int i = 0; i < m; ++i) {
    if (P.lo(i) == P.hi(i)) {
      W[i] = 2;
      continue;
    }
    if (!W[i]) continue;
    const double bound = (W[i] == 1) ? P.hi(i) : P.lo(i);
    if (std::abs(gy(i) - bound) > 1e-12 * std::max(1.0, std::abs(bound))) W[i] = 0;
  }
  if (block >= 0) W[block] = side;
  return true;
}

void Hierarchy::store_working_set(const LsqProblem& P, const std::vector<int8_t>& W,
                                  Working& ws) {
  ws.id.clear();
  ws.side.clear();
  ws.stored = true;
  for (int i = 0; i < P.rows; ++i) {
    if (W[i] == 1 || W[i] == -1) {
      ws.id.push_back(P.id[i]);
      ws.side.push_back(W[i]);
    }
  }
}

// ---------------------------------------------------------------------------------------
int Hierarchy::hard_phase(const CRef<Mat>& Aeq, const CRef<Vec>& beq, const CRef<Mat>& C,
                          const CRef<Vec>& lo, const CRef<Vec>& hi, MRef<Mat> stats,
                          MRef<Vec> detail, bool warm) {
  ts_ = stage_trial(0);
  z_repeats_ = true;  // (trial_memo's gate in the hard phase; set again after it)
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
  int found = 0;
  const bool hit = warm && try_working_set(P, working_[0], y, W_, &found);
  // on a miss: the stored set made feasible (every row has its slack: z = the set's point,
  // each slack the row's violation there)
  const bool seeded = !hit && warm && found > 0 &&
                      seed_working_set(P, working_[0], 0, r_, y, W_);
  if (seeded) ++seeded_;
  if (!hit) {
    if (!seeded) {
      std::fill(W_.begin(), W_.begin() + P.rows, 0);
      for (int i = 0; i < P.rows; ++i)
        if (P.lo(i) == P.hi(i)) W_[i] = 2;
    }
    if (!active_set(P, y, W_, iters)) {
      detail(2) = 0;
      return timed_out_ ? kTimeLimit : kNotConverged;
    }
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

int Hierarchy::qr_factor(const Eigen::Ref<const Mat>& M, double tol, double floor) {
  const int me = static_cast<int>(M.rows()), r = static_cast<int>(M.cols());
  const bool wide = me <= r;
  cf_->wide = wide;
  const int p = wide ? me : r;  // columns of the factorised matrix
  const int m = wide ? r : me;  // its rows
  if (wide)
    cf_->mqr.matrix(r, me) = M.transpose();
  else
    cf_->mqr.matrix(me, r) = M;
  // pivoted QR, every step (the full R: a tall level's compressed objective); the rank is
  // the first pivot of norm <= tol (|R(j, j)| is that pivot column's norm), as a
  // factorisation stopping there would give
  const int steps = cf_->mqr.factor(0.0, 0.0);
  const auto Af = cf_->mqr.matrix();
  int rank = 0;
  while (rank < steps && std::abs(Af(rank, rank)) > tol) ++rank;
  if (rank == 0) return -1;
  // the dropped block R22 (upper triangle of the trailing block; columns past `steps` were
  // not reduced): its norm bounds the singular values past the rank, which the SVD's rank
  // rule must drop as well
  if (rank < p) {
    double r22 = 0.0;
    for (int j = rank; j < p; ++j) {
      const int top = (j < steps) ? j + 1 : m;
      r22 += Af.col(j).segment(rank, top - rank).squaredNorm();
    }
    if (!(std::sqrt(r22) < tol)) return -1;
  }
  // sigma_rank(M) >= sigma_min(R11) >= 1 / |R11^-1|_F: well above the floor (damping
  // threshold, rank tolerance), every singular value up to the rank passes it and the SVD's
  // closed form is the plain minimum-norm least-squares solution
  auto Ri = rinv_.topLeftCorner(rank, rank);
  double inv = 0.0;
  if (rank <= kSmallRinvMax) {
    // column j of R11^-1 by back substitution on its j + 1 leading entries (the rest are
    // zero), summed into |R11^-1|_F^2: no blocked solve with an identity right-hand side
    double sum = 0.0;
    for (int j = 0; j < rank; ++j) {
      auto x = Ri.col(j).head(j + 1);
      x.setZero();
      x(j) = 1.0;
      for (int i = j; i >= 0; --i) {
        const double xi = x(i) / Af(i, i);
        x(i) = xi;
        for (int l = 0; l < i; ++l) x(l) -= xi * Af(l, i);
      }
      sum += x.squaredNorm();
    }
    inv = std::sqrt(sum);
    ++stats_.small_rinvs;
  } else {
    Ri.setIdentity();
    Af.topLeftCorner(rank, rank).triangularView<Eigen::Upper>().solveInPlace(Ri);
    inv = Ri.norm();
  }
  if (!(inv > 0.0) || !std::isfinite(inv) || !(1.0 / inv > kQrMargin * floor)) return -1;
  // a rank-deficient M: the RZ factorisation of [R11 R12] (tall) or the QR of
  // L = [R11^T; R12^T] (wide)
  if (!wide && rank < r) {
    MapMat T = cf_->trz.matrix(rank, r);  // [R11 R12]^T (its upper triangle is not read)
    for (int j = 0; j < rank; ++j)
      T.col(j).tail(r - j) = Af.row(j).segment(j, r - j).transpose();
    if (!cf_->trz.factor()) return -1;
    ++stats_.rz_factors;
  } else if (wide && rank < me) {
    MapMat L = cf_->tqr.matrix(me, rank);
    L.setZero();
    for (int j = 0; j < rank; ++j) L.col(j).tail(me - j) = Af.row(j).segment(j, me - j).transpose();
    if (cf_->tqr.factor(0.0, 0.0) < rank) return -1;
  }
  cf_->smin = 1.0 / inv;
  return rank;
}

int Hierarchy::qr_closed_form(const Eigen::Ref<const Mat>& M, const Eigen::Ref<const Vec>& e,
                              double tol, double floor, bool same_m, Eigen::Ref<Vec> dz) {
  ClosedForm& f = *cf_;
  const int me = static_cast<int>(M.rows()), r = static_cast<int>(M.cols());
  // (the closed-form cache: M bit for bit the one factorised at this level's last call --
  // A and Z are, and with A the tolerances, functions of |A|_F, r and the damping: its
  // factorisation, or its failure, is still in f)
  if (same_m && f.valid) {
    ++stats_.closed_form_memo_hits;
  } else {
    f.rank = qr_factor(M, tol, floor);
    f.valid = true;  // (the factorisation of the M now in Ms_ of the stage)
  }
  const int rank = f.rank;
  if (rank <= 0) return -1;
  const bool wide = f.wide;
  if (wide && rank == me) {  // M = P R^T Qf^T: the minimum-norm solution of M dz = e
    f.mqr.min_norm_transposed_solve(e, dz);
  } else if (!wide && rank == r) {  // M P = Qf R: dz = P R^-1 (Qf^T e)(0:r)
    auto u = ute_.head(me);
    u = e;
    f.mqr.apply_qt(u);
    f.mqr.solve_r(u);
    for (int i = 0; i < r; ++i) dz(f.mqr.perm(i)) = u(i);
  } else if (!wide) {
    // M P = Qf [R11 R12; 0 0] (R22 dropped): dz = P w, w the minimum-norm solution of
    // [R11 R12] w = (Qf^T e)(0:rank), by the RZ of [R11 R12]
    auto u = ute_.head(me);
    u = e;
    f.mqr.apply_qt(u);
    auto w = u_.head(r);
    f.trz.min_norm_solve(u.head(rank), w);
    for (int i = 0; i < r; ++i) dz(f.mqr.perm(i)) = w(i);
  } else {
    // M^T P = Qf [R11 R12; 0 0]: M = P L Qf1^T with L = [R11^T; R12^T] (me x rank, full
    // column rank); dz = Qf [v; 0], v the least-squares solution of L v = P^T e (QR of L)
    auto u = ute_.head(me);
    for (int i = 0; i < me; ++i) u(i) = e(f.mqr.perm(i));
    f.tqr.apply_qt(u);
    f.tqr.solve_r(u);
    dz.setZero();
    for (int i = 0; i < rank; ++i) dz(f.tqr.perm(i)) = u(i);
    f.mqr.apply_q(dz);
  }
  ++stats_.qr_closed_forms;
  return rank;
}

void Hierarchy::row_space_basis(const Svd& svd, bool by_qr, int rank,
                                Eigen::Ref<Mat, 0, Eigen::OuterStride<>> out) {
  const int r = static_cast<int>(out.rows());
  if (!by_qr) {
    if (rank == 0) return;  // no equality rows (no SVD computed): nothing to fill
    out = svd.matrixV().topLeftCorner(r, rank);  // [M 0]'s padding rows below r are zero
  } else if (cf_->wide) {  // M^T P = Qf R: Qf's first rank columns
    out.setZero();
    for (int i = 0; i < rank; ++i) {
      out(i, i) = 1.0;
      auto col = out.col(i);
      cf_->mqr.apply_q(col);
    }
  } else if (rank == r) {  // M has full column rank: the whole space
    out.setIdentity();
  } else {  // rows of [R11 R12] P^T: P times its RZ's row space, Z^T [I; 0]
    auto q = u_.head(r);
    for (int j = 0; j < rank; ++j) {
      q.setZero();
      q(j) = 1.0;
      cf_->trz.apply_zt(q);
      for (int i = 0; i < r; ++i) out(cf_->mqr.perm(i), j) = q(i);
    }
  }
}

int Hierarchy::level(int k, const CRef<Mat>& Aeq, const CRef<Vec>& beq, const CRef<Mat>& C,
                     const CRef<Vec>& lo, const CRef<Vec>& hi, const CRef<Vec>& sw,
                     MRef<Mat> stats, bool warm) {
  const int b = k + 1;
  const int me = meq_[b], mi = min_[b], e0 = eq0_[b], i0 = in0_[b];
  const int stage = b;
  ts_ = stage_trial(stage);
  cf_ = per_stage_ ? &cforms_[stage] : &shared_cf_;
  if (r_ == 0) {
    inherit(C, lo, hi, i0, mi, nullptr);
    return kOk;
  }
  // (the memos: A, C and Z on entry bit for bit the last call's -- M = A Z is then the one
  // in Ms_[stage], and its factorisations those the stage keeps)
  const bool same_m = memo_entry(stage, Aeq, e0, me, C, i0, mi);
  if (!same_m) cf_->svd_valid = false;
  const auto Zr = Z_.leftCols(r_);
  // ---- damped closed form of the projected equalities
  int rank = 0;
  double tau = 0.0;
  // M = A Z in the left r columns of the stage's me x n buffer: no reallocation when r
  // changes from call to call (e.g. as a level's active inequality rows change)
  auto M = Ms_[stage].leftCols(r_);
  auto& svd = svds_[stage];
  auto e = e_.head(me);
  auto xc = xc_.head(n_);
  xc = x_;
  bool by_qr = false;  // closed form from a QR of M (no damping can apply), no SVD
  double M_scale = 0.0;  // |A|_F of the level's equalities (>= s_0 of M)
  if (me) {
    const auto A = Aeq.middleRows(e0, me);
    if (z_identity_) {  // A I: the rows themselves
      M = A;
      ++stats_.identity_products;
    } else if (!same_m) {
      auto Ab = Ab_.topRows(me);
      Ab = A;  // contiguous: the product below makes no temporary
      M.noalias() = Ab * Zr;
    }
    e.noalias() = -A * x_;
    e += beq.segment(e0, me);
    const double scale = A.norm();
    M_scale = scale;
    // |M|_2 <= |M|_F <= |A|_F (Z orthonormal): the damping threshold and the rank tolerance
    // of the SVD, max(s_0, scale) = scale, are known before any factorisation
    tau = damping_ * scale;
    auto dz = tmpr_.head(r_);
    const double rank_tol = std::max(me, r_) * kEps * scale;
    // the QR closed form only where sigma_rank(M) is well above kMovableTol * scale too: no
    // direction of M can then be dependent on the frozen rows to within kMovableTol (the
    // SVD path's independent_rank considers none), which the QR path does not test (without
    // this floor, damping 0 solved rows dependent to 1e-10 exactly, x ~ 1e10, where the
    // Python engine leaves them to the lower levels: tests/core/test_native_damped.py)
    const double floor = std::max({tau, rank_tol, kMovableTol * scale});
    const int qr_rank = qr_closed_form(M, e, rank_tol, floor, same_m, dz);
    by_qr = qr_rank > 0;
    if (by_qr) {
      rank = qr_rank;
      xc.noalias() += Zr * dz;
    } else {
      // thin V: its first rank columns are all a level uses (the damped step, the damping
      // rows, the freeze); the null space of M comes from the freeze of V_rank
      // the SVD of [M 0] (me x n, zero columns padded to the stage's fixed width): the same
      // singular values and U; V's first rank columns are M's, padded with zero rows. A fixed
      // size keeps JacobiSVD's workspace (no allocation when r changes)
      if (!cf_->svd_valid) {  // (else the SVD of this M, the last call's)
        Ms_[stage].rightCols(n_ - r_).setZero();
        svd.compute(Ms_[stage], Eigen::ComputeThinU | Eigen::ComputeThinV);
        cf_->svd_valid = true;
      }
      const Vec& s = svd.singularValues();
      rank = numerical_rank(s, me, r_, scale);
      rank = independent_rank(svd, Aeq, e0, me, rank, scale);
      if (rank) {
        tau = damping_ * std::max(s(0), scale);
        auto ute = ute_.head(rank);
        ute.noalias() = svd.matrixU().leftCols(rank).transpose() * e;
        for (int i = 0; i < rank; ++i)
          ute(i) *= (s(i) >= tau) ? 1.0 / s(i) : s(i) / (tau * tau);
        dz.noalias() = svd.matrixV().topLeftCorner(r_, rank) * ute;
        xc.noalias() += Zr * dz;
      }
    }
  }
  bool ok = feasible(xc);
  if (ok)
    for (int i = 0; i < mi && ok; ++i) ok = in_box(row_dot(C, i0 + i, xc), lo(i0 + i), hi(i0 + i));
  if (ok) {
    x_ = xc;
    snap(x_);
    inherit(C, lo, hi, i0, mi, nullptr);
    if (by_qr && !cf_->wide && rank == r_) {  // M has full column rank: no freedom left
      r_ = 0;
      z_identity_ = false;
    } else if (rank) {
      // (freeze_memo: the same inputs as this level's last freeze: its outputs restored)
      const FreezeKind kind = (by_qr && cf_->wide) ? FreezeKind::kWide
                              : by_qr                ? FreezeKind::kNullSpace
                                                     : FreezeKind::kGeneral;
      if (!(memo_gate() && freeze_lookup(stage, kind, rank, mi, false))) {
        if (kind == FreezeKind::kWide) {  // wide: null(M) = span(Qf(:, rank:)) of M^T's QR
          freeze_wide(rank);
        } else if (kind == FreezeKind::kNullSpace) {  // Z <- Z P null([R11 R12])
          freeze_null_space(rank);
        } else {  // Z <- Z null(B^T), B an orthonormal basis of M's row space
          row_space_basis(svd, by_qr, rank, fqr_.matrix(r_, rank));
          freeze(1.0);
        }
        freeze_computed(stage);
      }
    }
    stats(stage, 2) = 1.0;
    return kOk;
  }
  // ---- exact active-set least squares in y = (z, w)
  mov_.clear();  // level rows z can move, with a finite side
  // the level's rows projected, C Z, by one product (rows copied contiguous first: no
  // temporary), used for the moving rows' test, their rows of P, the freeze of the violated
  // rows and the carried projection of the rows the level leaves to the next
  auto CZl = CZl_.topLeftCorner(mi, r_);
  if (mi) {
    auto Cl = Cl_.topRows(mi);
    Cl = C.middleRows(i0, mi);
    if (z_identity_) {  // C I: the rows themselves
      CZl = Cl;
      ++stats_.identity_products;
    } else {
      CZl.noalias() = Cl * Zr;
    }
  }
  for (int i = 0; i < mi; ++i) {
    const int g = i0 + i;
    if (!std::isfinite(lo(g)) && !std::isfinite(hi(g))) continue;
    const double cn = C.row(g).norm();
    if (CZl.row(i).norm() > kMovableTol * cn) {
      depn_(static_cast<int>(mov_.size())) = cn;  // the row's norm, for the drop below
      mov_.push_back(i);
    }
  }
  const int mv = static_cast<int>(mov_.size());
  if (mv > 1) drop_dependent_directions(CZl, mov_, depn_.head(mv));
  int ndamp = 0;
  static const Vec kNoSvd;  // empty: no equality rows, or the QR path (no SVD this call)
  const Vec& s = (me && !by_qr) ? svd.singularValues() : kNoSvd;
  if (!by_qr)
    for (int i = 0; i < rank; ++i)
      if (s(i) < tau) ++ndamp;
  const int cols = r_ + mv;
  LsqProblem& P = P_;
  // a tall level factorised by the QR (M P = Qm [R; 0]): its objective rows compressed to
  // R P^T and (Qm^T e)(0:r), exactly (an orthogonal transform; the rest of Qm^T e is
  // constant in y, kept in dropped2)
  // (the full QR may stop at a pivot column exactly zero: then the whole trailing block is
  // checked to be exactly zero, its rows of R are zero and the compression stays exact)
  bool full_r = by_qr && !cf_->wide && cf_->mqr.rank() == r_;
  if (by_qr && !cf_->wide && !full_r && cf_->mqr.rows() == me && cf_->mqr.cols() == r_) {
    const int t = cf_->mqr.rank();
    full_r = (cf_->mqr.matrix().bottomRightCorner(me - t, r_ - t).array() == 0.0).all();
    if (full_r) ++stats_.zero_tail_compressions;
  }
  const int qme = full_r ? r_ : me;
  P.start(qme + ndamp + mv, cols);
  if (qme < me) {
    const auto Af = cf_->mqr.matrix();
    for (int j = 0; j < r_; ++j) P.Q.col(cf_->mqr.perm(j)).head(j + 1) = Af.col(j).head(j + 1);
    auto u = ute_.head(me);
    u = e;
    cf_->mqr.apply_qt(u);
    P.c.head(r_) = u.head(r_);
    P.dropped2 = u.tail(me - r_).squaredNorm();
  } else if (me) {
    P.Q.topLeftCorner(me, r_) = M;
    P.c.head(me) = e;
  }
  {
    int d = qme;
    for (int i = 0; i < rank && ndamp; ++i)
      if (s(i) < tau)
        P.Q.row(d++).head(r_) = std::sqrt(tau * tau - s(i) * s(i)) * svd.matrixV().col(i).head(r_);
  }
  add_inherited_rows(P);
  add_bound_rows(P, stage);
  auto y = y_.head(cols);
  auto g = rowbuf_.head(cols);
  const int slack_g0 = P.rows;
  for (int j = 0; j < mv; ++j) {
    const int row = i0 + mov_[j];
    const double v = C.row(row).dot(x_);
    P.Q(qme + ndamp + j, r_ + j) = sw(row);
    g.setZero();
    g.head(r_) = CZl.row(mov_[j]).transpose();
    g(r_ + j) = -1.0;
    P.add_row(g, lo(row) - v, hi(row) - v, row, C.row(row).norm());
  }
  if (P.rows == slack_g0 + mv && P.qrows == qme + ndamp + mv) {  // every level row kept
    P.zcols = r_;
    P.slacks = mv;
    P.slack_q0 = qme + ndamp;
    P.slack_g0 = slack_g0;
  }
  int iters = 0;
  int found = 0;
  slack_rows_ = mv;
  const bool hit = warm && try_working_set(P, working_[stage], y, W_, &found);
  slack_rows_ = 0;
  const bool seeded =
      !hit && warm && found > 0 &&
      seed_working_set(P, working_[stage], P.rows - mv, r_, y, W_);
  if (seeded) {
    ++seeded_;
    if (!active_set(P, y, W_, iters)) return timed_out_ ? kTimeLimit : kNotConverged;
  } else if (!hit) {
    std::fill(W_.begin(), W_.begin() + P.rows, 0);
    for (int i = 0; i < P.rows; ++i)
      if (P.lo(i) == P.hi(i)) W_[i] = 2;
    y.setZero();
    for (int j = 0; j < mv; ++j) {
      const int row = i0 + mov_[j];
      const double v = C.row(row).dot(x_);
      y(r_ + j) = (v > hi(row)) ? v - hi(row) : ((v < lo(row)) ? v - lo(row) : 0.0);
    }
    if (!active_set(P, y, W_, iters)) return timed_out_ ? kTimeLimit : kNotConverged;
  }
  // an ill-conditioned or damped level: finished to rounding (a point optimal to settings.kkt_tol can
  // be far from the optimum along a direction of curvature s^2 or tau^2, and is frozen)
  if (me && rank &&
      (by_qr ? cf_->smin < kIllConditioned * M_scale
             : s(rank - 1) < std::max(tau, kIllConditioned * s(0)))) {
    exact_ = true;
    const bool done = active_set(P, y, W_, iters);
    exact_ = false;
    if (!done) return timed_out_ ? kTimeLimit : kNotConverged;
  }
  store_working_set(P, W_, working_[stage]);
  stats(stage, 0) = iters;
  stats(stage, 1) = hit ? 1.0 : 0.0;
  xold_.head(n_) = x_;
  x_.noalias() += Zr * y.head(r_);
  snap(x_);
  // ---- classify the level's rows on the new point; freeze
  std::fill(viol_.begin(), viol_.begin() + mi, 0);
  const double xscale =
      std::max(xold_.head(n_).cwiseAbs().maxCoeff(), x_.cwiseAbs().maxCoeff());
  int nviol = 0;
  for (int j = 0; j < mv; ++j) {
    const int i = mov_[j], row = i0 + i;
    const double v = C.row(row).dot(x_);
    const double gap = std::max(lo(row) - v, v - hi(row));
    const double scale = std::max({finite_abs(lo(row)), finite_abs(hi(row)),
                                   C.row(row).norm() * xscale});
    if (gap > settings.violation_tol * scale + kAbsFloor) {
      viol_[i] = 1;
      ++nviol;
    }
  }
  // the freeze: onto null([R11 R12]) from the closed form's own QR (a rank-deficient tall
  // M and no violated row), else F^T = [V_rank, Z^T C_violated^T] (r x f) factorised,
  // null(F) being what the level leaves free
  const bool by_null_space = nviol == 0 && rank && by_qr && !cf_->wide && rank < r_;
  // the level's equalities have rank r (M of full column rank) and no row is violated: F^T
  // would be an orthonormal basis of the whole space, null(F) = {0}
  const bool no_freedom = nviol == 0 && rank == r_;
  // a wide M factorised by the QR of M^T, no row violated: null(M) spans the last r - rank
  // columns of Qf, Z <- Z Qf by M^T's own reflectors (as a feasible closed form)
  const bool by_wide = !no_freedom && nviol == 0 && rank && by_qr && cf_->wide;
  const bool by_f = !by_null_space && !no_freedom && !by_wide;
  const int k_before = k_;
  inherit(C, lo, hi, i0, mi, &viol_);
  if (kz_ == k_before) {  // the inherited rows' projections, at hand
    for (int k = k_before; k < k_; ++k) CinZ_.row(k).head(r_) = CZl.row(inid_[k] - i0);
    kz_ = k_;
  }
  if (no_freedom) {  // what freeze() ends with for F of rank r (carry_z drops Cin Z)
    r_ = 0;
    kz_ = 0;
    z_identity_ = false;
    ++stats_.full_rank_freezes;
    return kOk;
  }
  if (by_wide) ++stats_.wide_freezes;
  // (freeze_memo: the same inputs as this level's last freeze: its outputs restored; the
  // violated rows are inputs of the general freeze only)
  const FreezeKind kind = by_null_space ? FreezeKind::kNullSpace
                          : by_wide     ? FreezeKind::kWide
                                        : FreezeKind::kGeneral;
  if (memo_gate() && freeze_lookup(stage, kind, rank, mi, by_f))
    return kOk;
  if (by_null_space) {
    freeze_null_space(rank);
  } else if (by_wide) {
    freeze_wide(rank);
  } else {
    // F^T = [B, (C_violated Z)^T], B an orthonormal basis of M's row space
    MapMat Ft = fqr_.matrix(r_, rank + nviol);
    row_space_basis(svd, by_qr, rank, Ft.leftCols(rank));
    int f = rank;
    double fro = 0.0;
    for (int i = 0; i < mi; ++i) {
      if (!viol_[i]) continue;
      Ft.col(f++) = CZl.row(i).transpose();
      fro += C.row(i0 + i).squaredNorm();
    }
    freeze(std::max(1.0, std::sqrt(fro)));
  }
  freeze_computed(stage);
  return kOk;
}

/// The rank of a level's M = A Z (its SVD in svds_ of the stage, numerical rank `rank`)
/// without the directions in which the level's rows are dependent on the frozen rows to
/// within kMovableTol: a left singular vector u_i with s_i <= kMovableTol |A^T u_i| is a
/// combination of the level's rows within kMovableTol of the frozen rows' span, rounding of
/// the freeze (the movable test of the inequality rows, drop_dependent_directions); it is
/// left to the lower levels as an exactly dependent one would be, not damped and frozen (the
/// Talos CoM level below the support polygon, which pins the CoM: 2 directions of ~1e-13
/// frozen, the posture level 23 % above its optimum). Only s_i <= kMovableTol * scale can
/// qualify (|A^T u_i| <= |A|_F = scale): no product otherwise.
int Hierarchy::independent_rank(const Svd& svd, const CRef<Mat>& Aeq, int e0, int me, int rank,
                                double scale) {
  const Vec& s = svd.singularValues();
  auto v = rowbuf_.head(n_);
  for (int i = 0; i < rank; ++i) {
    if (s(i) > kMovableTol * scale) continue;
    v.noalias() = Aeq.middleRows(e0, me).transpose() * svd.matrixU().col(i);
    if (s(i) <= kMovableTol * v.norm()) {
      ++stats_.dependent_drops;
      return i;
    }
  }
  return rank;
}

/// Rows rows[j] of R (their first r_ columns: projections C_i Z of rows of norm norms[j])
/// with every direction in which they are dependent to within kMovableTol of their own rows'
/// norms removed: each row is replaced by its projection on the span of the pivot rows of a
/// pivoted QR of the rows scaled by 1 / |C_i|, stopped at the first pivot whose distance to the
/// span of the previous ones is at most kMovableTol. The per-row movable test
/// (|C_i Z| > kMovableTol |C_i|, both engines) generalised to rows together: a row, or a
/// combination of rows, within kMovableTol of the frozen rows' span is rounding of the freeze
/// (the Talos support polygon, a function of the CoM and the feet: with the feet frozen by an
/// ill-conditioned level (condition 3e6, targets 1e5), its 6 projected rows have rank 2 plus
/// singular values ~1e-13; the active set stepped along them to y = 1e17 (level value 4.5
/// for 2e4) and did not converge on the next level: tests/data/talos_extreme_feet_{10,11}.npz).
/// Uses fqr_ (free until the level's freeze) and tmpr_.
void Hierarchy::drop_dependent_directions(Eigen::Ref<Mat> R, const std::vector<int>& rows,
                                          const Eigen::Ref<const Vec>& norms) {
  const int m = static_cast<int>(rows.size());
  if (m < 2 || r_ == 0) return;
  MapMat T = fqr_.matrix(r_, m);
  for (int j = 0; j < m; ++j) T.col(j) = R.row(rows[j]).head(r_).transpose() / norms(j);
  if (independent_by_gram(T)) {
    ++stats_.gram_screens;
    return;
  }
  const int rank = fqr_.factor(kMovableTol, 0.0);
  if (rank >= std::min(m, r_)) return;
  auto v = tmpr_.head(r_);
  for (int j = 0; j < m; ++j) {
    v = R.row(rows[j]).head(r_).transpose();
    fqr_.apply_qt(v);
    v.tail(r_ - rank).setZero();
    fqr_.apply_q(v);
    R.row(rows[j]).head(r_) = v.transpose();
  }
  ++stats_.dependent_drops;
}

/// True when the pivoted QR of T (r x m, columns of norm at most 1: projections of rows
/// scaled by their own norms) provably keeps min(m, r) pivots above kMovableTol, so that
/// drop_dependent_directions would change nothing: a Cholesky of G - delta I, G = T^T T
/// (m <= r) or T T^T (m > r), k = min(m, r), succeeds. Then lambda_min(G) > delta - err, err
/// the rounding of G and of the Cholesky (at most 16 (m + r) eps trace(G), trace(G) =
/// |T|_F^2), so sigma_k(T) > 2 sqrt(m) kMovableTol; every pivot of the QR is at least
/// sigma_k(T) / sqrt(m) (at step j, the largest remaining column of the projection P T off
/// the j - 1 chosen columns is at least |P T|_2 / sqrt(m) >= sigma_j(T) / sqrt(m)), twice the
/// tolerance. A failed Cholesky proves nothing (the QR decides). k^2 max(m, r) / 2 + k^3 / 6
/// multiply-adds in products where the QR takes about 2 m r k in matrix-vector steps (the
/// humanoid's 72 moving rows in 88 columns: 12 % of its instructions).
bool Hierarchy::independent_by_gram(const Eigen::Ref<const Mat>& T) {
  const int r = static_cast<int>(T.rows()), m = static_cast<int>(T.cols());
  const int k = std::min(m, r);
  if (k == 0 || k > gram_.rows()) return false;
  auto G = gram_.topLeftCorner(k, k);
  G.setZero();
  if (m <= r)
    G.selfadjointView<Eigen::Lower>().rankUpdate(T.transpose());
  else
    G.selfadjointView<Eigen::Lower>().rankUpdate(T);
  const double trace = G.trace();
  if (!std::isfinite(trace)) return false;
  const double need = 4.0 * m * kMovableTol * kMovableTol;
  const double delta = need + 16.0 * (m + r) * kEps * trace;
  G.diagonal().array() -= delta;
  // G = L L^T in the lower triangle, in place, a column of L at a time: L(j+1:, j) from one
  // product of L(j+1:, 0:j) with L(j, 0:j) (no allocation; fewer instructions than Eigen's
  // blocked LLT or the row-oriented form at these sizes: 72 x 72 on the humanoid)
  for (int j = 0; j < k; ++j) {
    const double d2 = G(j, j) - G.row(j).head(j).squaredNorm();
    if (!(d2 > 0.0)) return false;
    const double d = std::sqrt(d2);
    G(j, j) = d;
    const int below = k - j - 1;
    if (below > 0) {
      auto col = G.col(j).tail(below);
      if (j > 0) col.noalias() -= G.bottomLeftCorner(below, j) * G.row(j).head(j).transpose();
      col /= d;
    }
  }
  return true;
}

int Hierarchy::min_norm(MRef<Mat> stats, bool warm) {
  const int stage = static_cast<int>(meq_.size());
  ts_ = stage_trial(stage);
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
  int found = 0;
  const bool hit = warm && try_working_set(P, working_[stage], y, W_, &found);
  // on a miss: the stored set made feasible (every row is without slack here; y = 0 is
  // feasible: x meets the inherited rows and the bounds)
  const bool seeded =
      !hit && warm && found > 0 &&
      seed_working_set(P, working_[stage], P.rows, r_, y, W_);
  if (seeded) {
    ++seeded_;
    if (!active_set(P, y, W_, iters)) return timed_out_ ? kTimeLimit : kNotConverged;
  } else if (!hit) {
    std::fill(W_.begin(), W_.begin() + P.rows, 0);
    for (int i = 0; i < P.rows; ++i)
      if (P.lo(i) == P.hi(i)) W_[i] = 2;
    y.setZero();
    if (!active_set(P, y, W_, iters)) return timed_out_ ? kTimeLimit : kNotConverged;
  }
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

int Hierarchy::solve(const CRef<Mat>& Aeq, const CRef<Vec>& beq, const CRef<Mat>& C,
                     const CRef<Vec>& lo, const CRef<Vec>& hi, const CRef<Vec>& sw,
                     const CRef<Vec>& lb, const CRef<Vec>& ub, bool warm, double time_left,
                     MRef<Vec> x_out, MRef<Vec> res_out, MRef<Mat> stats, MRef<Vec> detail) {
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
  stats.setZero();
  detail.setZero();
  if (calls_ > 0 && !per_stage_) allocate_per_stage();  // (the second call: once)
  ++calls_;
  shared_cf_.mqr.wy_applications = 0;
  for (ClosedForm& f : cforms_) f.mqr.wy_applications = 0;
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
  lb_ = lb;
  ub_ = ub;
  int st = hard_phase(Aeq, beq, C, lo, hi, stats, detail, warm);
  z_repeats_ = true;  // (freeze_memo: the first freeze's lookup compares Z itself)
  if (st != kOk) return st;
  for (int k = 0; k < L; ++k) {
    st = level(k, Aeq, beq, C, lo, hi, sw, stats, warm);
    if (st != kOk) {
      detail(2) = k + 1;
      return st;
    }
    frozen_value_(k) = level_value(k, Aeq, beq, C, lo, hi, sw, x_);
  }
  st = min_norm(stats, warm);
  if (st != kOk) {
    detail(2) = L + 1;
    return st;
  }
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
  for (int k = 0; k < L; ++k) {
    double scale = 0.0;
    res_out(k) = level_value(k, Aeq, beq, C, lo, hi, sw, x_, &scale);
    const double dev =
        std::abs(res_out(k) - frozen_value_(k)) / std::max({1.0, frozen_value_(k), scale});
    if (dev > detail(5)) {
      detail(5) = dev;
      detail(6) = k;
    }
  }
  detail(7) = seeded_;
  stats_.wy_applications = fqr_.wy_applications + shared_cf_.mqr.wy_applications;
  for (const ClosedForm& f : cforms_) stats_.wy_applications += f.mqr.wy_applications;
  x_out = x_;
  return kOk;
}

}  // namespace qpcoord

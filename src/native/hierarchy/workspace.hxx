// qpcoord native engine, Hierarchy: the problem's data and workspace: LsqProblem, the constructor
// and the buffers, the inherited rows and the bounds as rows of a stage's problem.
// Part of hierarchy.cpp's translation unit (included there, after its helpers).
namespace qpcoord {

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
                           double ref_norm, double floor) {
  if (!std::isfinite(l) && !std::isfinite(u)) return 0.0;
  const double nrm = g.norm();
  if (!(nrm > floor * std::max(ref_norm, 1e-300))) return 0.0;  // cannot bind: constant row
  G.row(rows).head(cols) = g.transpose() / nrm;
  lo(rows) = l / nrm;
  hi(rows) = u / nrm;
  id[rows] = gid;
  ++rows;
  return nrm;
}

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
  Wp_.assign(max_grows, 0);
  working_.resize(blocks + 1);
  for (auto& w : working_) {
    w.id.reserve(max_grows);
    w.side.reserve(max_grows);
  }
  pruned_.id.reserve(max_grows);
  pruned_.side.reserve(max_grows);
  // the first call's working-set and K factorisations, shared by its stages (the memos'
  // per-stage ones are allocated at the second call: a one-shot solve never pays for them)
  shared_trial_.value.reserve(max_cols, max_grows, max_qrows);
  enter_stage(0);
  sqr_.reserve(max_cols, max_grows + max_qrows, 1);
  // (apply_q_right: Z, and the carried projection of up to capacity inherited rows)
  fqr_.reserve(std::max(n, 1), n + max_in + 1, std::max(n, capacity_));
  fqr_.reserve_wy(std::max(n, capacity_));
  const int big = std::max({max_cols, max_grows, max_qrows, n, max_eq, 1});
  for (Vec* v : {&res_, &dres_, &step_, &gvec_, &u_, &mu_, &gy_, &gp_, &tvec_, &rowbuf_, &zc_,
                 &tmpr_, &xc_, &xold_, &e_, &ute_})
    v->setZero(big);
  widx_.reserve(max_grows);
  bidx_.assign(std::max(n, 1), 0);
  brun_.assign(n + 1, 0);
  binv_.setZero(std::max(n, 1));
  bsq_.setZero(std::max(n, 1));
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

void Hierarchy::TrialState::reserve(int cols, int grows, int qrows) {
  wqr.reserve(cols, grows, qrows);
  kqr.reserve(qrows, cols, 1);
  cqr.reserve(cols, cols, 1);
  krz.reserve(cols, cols);
  kqr_t.reserve(cols, qrows, 1);
  bqr.reserve(cols, grows, 1);
  Qt.setZero(qrows, cols);
}

void Hierarchy::ClosedForm::reserve(int n, int me, int capacity) {
  mqr.reserve(std::max({n, me, 1}), std::max({n, me, 1}), std::max({n, capacity, 1}));
  mqr.reserve_wy(std::max({n, capacity, 1}));
  tqr.reserve(std::max({n, me, 1}), std::max(n, 1), 1);
  trz.reserve(std::max(n, 1), std::max(n, 1));
}

void Hierarchy::allocate_per_stage() {
  // the first call's shared factorisations are not used again (freed first: a lower peak)
  shared_trial_ = TrialCache();
  shared_cf_ = ClosedForm();
  const int n = n_, blocks = static_cast<int>(meq_.size());
  const int nb = has_bounds_ ? n : 0;
  // each stage's working-set and K factorisations (the trial cache), sized for its own problem:
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
    trials_[b].value.reserve(cols, grows, qrows);
    // its key: the sizes, up to grows working rows' indices and (kw <= k) cols x cols
    // entries of them, the objective (qrows x cols)
    trials_[b].reserve_key(kKeyHeader + sizeof(int) * grows +
                           sizeof(double) * (static_cast<std::size_t>(cols) * cols +
                                             static_cast<std::size_t>(qrows) * cols));
  }
  // each level's closed-form factorisations (the closed-form cache), sized for its equality rows
  cforms_.resize(blocks);
  // (its key: the level's rows A and C, and Z)
  for (int b = 1; b < blocks; ++b) {
    cforms_[b].value.reserve(n, meq_[b], capacity_);
    cforms_[b].reserve_key(kKeyHeader +
                           sizeof(double) * static_cast<std::size_t>(meq_[b] + min_[b] + n) * n);
  }
  // each level's freeze (the freeze cache; not the hard phase's); its key: the freeze's kind
  // and rank, the violated rows, Cin Z (up to capacity x n)
  freezes_.resize(blocks);
  freeze_pending_.assign(blocks, 0);
  for (int b = 1; b < blocks; ++b) {
    Frozen& f = freezes_[b].value;
    f.Z.setZero(n, n);
    f.CinZ.setZero(std::max(capacity_, 1), std::max(n, 1));
    freezes_[b].reserve_key(kKeyHeader + min_[b] +
                            sizeof(double) * static_cast<std::size_t>(capacity_) * n);
  }
  // each level's and the minimum-norm step's bound rows (the bound-rows cache); its key: Z
  bound_rows_.resize(blocks + 1);
  for (int b = 1; has_bounds_ && b <= blocks; ++b) {
    BoundRows& m = bound_rows_[b].value;
    m.G.setZero(n, n);
    m.nrm.setZero(n);
    bound_rows_[b].reserve_key(kKeyHeader + sizeof(double) * static_cast<std::size_t>(n) * n);
  }
  per_stage_ = true;
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

namespace {
/// id is one of ids (a stored working set's: a few rows, scanned)
inline bool holds_id(const std::vector<int>& ids, int id) {
  return std::find(ids.begin(), ids.end(), id) != ids.end();
}
}  // namespace

void Hierarchy::add_inherited_rows(LsqProblem& P, const Working* only) {
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
    const double l = std::min(lin_(i) - cx(i), 0.0);
    const double u = std::max(uin_(i) - cx(i), 0.0);
    if (only && l != u && !holds_id(only->id, inid_[i])) {
      ++left_out_;
      continue;
    }
    full.head(r_) = CZ.row(i).transpose();
    // a level's row whose projection is within kMovableTol of its norm lies in the frozen
    // rows' span to rounding of the freeze: constant, as for the level's own movable test
    // (its projection's direction is rounding: a half-space through x with that normal
    // decides the lower levels by rounding). The hard rows stay (the end check holds them)
    P.add_row(full, l, u, inid_[i], cin_norm(i), inid_[i] >= min_[0] ? kMovableTol : 1e-12);
  }
}

void Hierarchy::add_bound_rows(LsqProblem& P, int stage, const Working* only) {
  if (!has_bounds_) return;
  const int r0 = P.rows, cols = P.cols;
  if (only) {  // the set's rows and the fixed ones, as below (the cache neither read nor kept)
    auto full = rowbuf_.head(cols);
    full.setZero();
    for (int j = 0; j < n_; ++j) {
      const double l = std::min(lb_(j) - x_(j), 0.0);
      const double u = std::max(ub_(j) - x_(j), 0.0);
      if (l != u && !holds_id(only->id, capacity_ + j)) {
        ++left_out_;
        continue;
      }
      full.head(r_) = Z_.row(j).head(r_).transpose();
      P.add_row(full, l, u, capacity_ + j, 1.0);
    }
    return;
  }
  // (the bound-rows cache: the rows depend on Z alone, their bounds on x too; no row is
  // skipped unless a variable has no finite bound, or Z a zero row)
  BoundRowsCache* cache = memo_gate() ? &bound_rows_[stage] : nullptr;
  bool all_finite = cache != nullptr;  // (only the cache reads it: every variable has a side)
  for (int j = 0; j < n_ && all_finite; ++j)
    all_finite = std::isfinite(lb_(j)) || std::isfinite(ub_(j));
  if (cache) {
    cache->begin();
    cache->same_block(Z_.leftCols(r_));
  }
  if (all_finite && cache->hit(stats_)) {
    const BoundRows& m = cache->value;
    P.G.block(r0, 0, n_, r_) = m.G.topLeftCorner(n_, r_);
    if (cols > r_) P.G.block(r0, r_, n_, cols - r_).setZero();
    for (int j = 0; j < n_; ++j) {  // (as add_row: the bound over the row's norm)
      P.lo(r0 + j) = std::min(lb_(j) - x_(j), 0.0) / m.nrm(j);
      P.hi(r0 + j) = std::max(ub_(j) - x_(j), 0.0) / m.nrm(j);
      P.id[r0 + j] = capacity_ + j;
    }
    P.rows += n_;
    return;
  }
  // add_row's rows (ref_norm 1: a row of norm at most 1e-12 cannot bind) and bounds. The
  // rows' squared norms accumulate column by column and the scaled rows are written by
  // columns: Z is column-major, so every pass reads and writes contiguous memory (a row's own
  // norm and copy read Z with a stride of n, per row: 16k instructions a level on the Talos
  // polygon's three active levels, 38 x 26)
  auto sq = bsq_.head(n_);
  sq.setZero();
  for (int c = 0; c < r_; ++c) sq += Z_.col(c).head(n_).cwiseAbs2();
  int kept = 0;
  for (int j = 0; j < n_; ++j) {
    const double l = std::min(lb_(j) - x_(j), 0.0);
    const double u = std::max(ub_(j) - x_(j), 0.0);
    double nrm = 0.0;
    if (std::isfinite(l) || std::isfinite(u)) {
      nrm = std::sqrt(sq(j));
      if (!(nrm > 1e-12)) nrm = 0.0;  // cannot bind: constant row
    }
    if (cache) cache->value.nrm(j) = nrm;
    if (nrm == 0.0) continue;
    P.lo(r0 + kept) = l / nrm;
    P.hi(r0 + kept) = u / nrm;
    P.id[r0 + kept] = capacity_ + j;
    bidx_[kept] = j;
    binv_(kept++) = 1.0 / nrm;
  }
  // the kept rows as runs of consecutive variables (a free-flyer's unbounded base leaves one
  // run): each run of each column one scaled copy
  int runs = 0;
  for (int i = 0; i < kept; ++i)
    if (i == 0 || bidx_[i] != bidx_[i - 1] + 1) brun_[runs++] = i;
  brun_[runs] = kept;
  for (int c = 0; c < r_; ++c) {
    for (int b = 0; b < runs; ++b) {
      const int i0 = brun_[b], len = brun_[b + 1] - i0;
      P.G.col(c).segment(r0 + i0, len) =
          Z_.col(c).segment(bidx_[i0], len).cwiseProduct(binv_.segment(i0, len));
    }
  }
  if (cols > r_) P.G.block(r0, r_, kept, cols - r_).setZero();
  P.rows += kept;
  if (!cache) return;
  // stored when every row was kept (a skipped row shifts the others: not one block)
  if (P.rows - r0 != n_) {
    cache->drop();
    return;
  }
  cache->value.G.topLeftCorner(n_, r_) = P.G.block(r0, 0, n_, r_);
  cache->store();
}

}  // namespace qpcoord

// qpcoord native engine, Hierarchy: the active-set least squares on a working set: the working
// set's factorisations, the least-squares step, the multipliers and the active set.
// Part of hierarchy.cpp's translation unit (included there, after its helpers).
namespace qpcoord {

void Hierarchy::factor_rows(const LsqProblem& P, const std::vector<int8_t>& W) {
  const int k = P.cols;
  ts_->k_valid = false;
  ts_->range = false;
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
  tc_->drop();
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

void Hierarchy::factor_trial(const LsqProblem& P, const std::vector<int8_t>& W) {
  // (the trial cache: the stage's last trial had these rows and objective, its factorisations
  // untouched since: nothing to compute. Only above every computed freeze of the call:
  // below one, Z and with it every projected row differ from the last call's)
  const bool memo = memo_gate();
  if (memo && trial_lookup(P, W)) return;
  factor_trial_computed(P, W);
  if (memo) {
    ts_->qt_stale = qt_stale_;
    tc_->store();
  }
}

void Hierarchy::factor_trial_computed(const LsqProblem& P, const std::vector<int8_t>& W) {
  if (unit_q_) {  // (factor_working forms no Q Qf either)
    factor_working(P, W);
    return;
  }
  tc_->drop();
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
/// QR).
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
  tc_->drop();  // (the trial cache: its updates change the stage's factorisations)
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
  bool dropped_since_move = false;  // a row left W since y last moved
  // rows batched at a degenerate point on a cold start only (no one-sided row in the
  // starting W): rows batched into a seeded start's set end in the stored set more often
  // than its steps would put them there, and the next call's warm trial misses more
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
    // step of ~1e-10, rounding, without end -- tests/core/test_native_active_set.py's seed 4857)
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
      // the step is blocked at length zero; every other row that blocks it at
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

}  // namespace qpcoord

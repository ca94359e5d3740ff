// qpcoord native engine, Hierarchy: the warm start: a stage's stored working set tried, seeded from
// or replaced by the cold start, and stored.
// Part of hierarchy.cpp's translation unit (included there, after its helpers).
namespace qpcoord {

int Hierarchy::stored_set_point(const LsqProblem& P, const Working& ws, std::vector<int8_t>& W,
                                bool* consistent) {
  *consistent = false;
  if (!ws.stored) return 0;
  const int k = P.cols;
  const int found = map_working_set(P, ws, W);
  if (!found && !ws.id.empty()) return 0;
  qscale_ = P.Q.topLeftCorner(P.qrows, k).norm();
  auto yp = xc_.head(k);
  if (range_trial_) {
    const bool computed = factor_range_trial(P, W);
    if (ts_->range) {
      if (!working_set_point(P, W, yp, consistent)) return 0;
      range_step(P, yp);
      return found;
    }
    // (B rank-deficient: the general trial, its factorisations stored in place of these)
    if (computed) tc_->drop();
  }
  factor_trial(P, W);
  if (!working_set_point(P, W, yp, consistent)) return 0;
  auto step = step_.head(k);
  ls_step(P, yp, step);
  yp += step;
  trial_ready_ = true;  // wqr and K are those of W on P (the exact finish's start)
  return found;
}

bool Hierarchy::factor_range_trial(const LsqProblem& P, const std::vector<int8_t>& W) {
  // (the trial cache, as factor_trial's: its key holds range_trial_, so an entry is either
  // this function's or the general trial's for a B found rank-deficient here)
  const bool memo = memo_gate();
  if (memo && trial_lookup(P, W)) return false;
  tc_->drop();
  finish_ready_ = false;
  factor_rows(P, W);  // (ts_->range false)
  qt_stale_ = true;
  const int k = P.cols, kw = static_cast<int>(widx_.size());
  if (ts_->wqr.rank() == kw) {
    // B = Q^-T G_w^T = R^-T P^T G_w^T, Q = R P^T (level_problem's compressed objective, R
    // the closed form's upper triangle, of condition below 1 / kIllConditioned: range_trial_)
    const MapMat Rf = cf_->mqr.matrix();
    const auto R = Rf.topLeftCorner(k, k).triangularView<Eigen::Upper>();
    MapMat B = ts_->bqr.matrix(k, kw);
    for (int j = 0; j < kw; ++j) {
      auto b = B.col(j);
      for (int i = 0; i < k; ++i) b(i) = P.G(widx_[j], cf_->mqr.perm(i));
      R.transpose().solveInPlace(b);
    }
    ts_->range = kw == 0 || ts_->bqr.factor(0.0, std::max(k, kw) * kEps * 10.0) == kw;
  }
  if (memo) {
    ts_->qt_stale = qt_stale_;
    tc_->store();
  }
  return true;
}

void Hierarchy::range_step(const LsqProblem& P, Eigen::Ref<Vec> y) {
  const int k = P.cols, qr = P.qrows, kw = static_cast<int>(widx_.size());
  // min |Q (y + d) - c| over G_w d = 0: the KKT system's multipliers solve B lambda = -res
  // in least squares (res = Q y - c), and d = -Q^-1 (I - P_B) res
  const MapMat Rf = cf_->mqr.matrix();
  const auto R = Rf.topLeftCorner(k, k).triangularView<Eigen::Upper>();
  auto res = res_.head(qr);
  res.noalias() = P.Q.topLeftCorner(qr, k) * y;
  res -= P.c.head(qr);
  auto v = step_.head(k);
  v = res;
  if (kw) {
    ts_->bqr.apply_qt(v);
    v.head(kw).setZero();
    ts_->bqr.apply_q(v);
  }
  R.solveInPlace(v);
  auto d = u_.head(k);
  for (int i = 0; i < k; ++i) d(cf_->mqr.perm(i)) = -v(i);
  // d in null(G_w) to the rounding of the working rows' own QR, as the general trial's N s
  const int rho = ts_->wqr.rank();
  ts_->wqr.apply_qt(d);
  d.head(rho).setZero();
  ts_->wqr.apply_q(d);
  y += d;
  ++stats_.range_trials;
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
  // a point on the stored rows alone is free to leave an equality row (the humanoid's box
  // form would miss on every call, its point off two inherited rows lo = hi = 0)
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
  // (a feasible point of zero objective is optimal whatever the multipliers computed there:
  // at a zero gradient they are rounding, amplified by the conditioning of the working rows
  // -- two near-parallel inherited polygon rows gave +-5e-9 for a gradient of 3e-17)
  if (reduced >= 0 ? !reduced_multipliers_ok(P, slack_rows_, yp, W)
                   : !multipliers_ok(P, yp, W, nullptr, nullptr, false)) {
    if (!zero_objective(P, yp)) return false;
    ++stats_.zero_objective_hits;
  }
  y.head(k) = yp;
  return true;
}

Hierarchy::Light Hierarchy::light_trial(const LevelRows& d, const LevelForm& form,
                                        Working& ws, Eigen::Ref<Vec> y) {
  const int mv = level_problem(d, form, &ws);
  if (left_out_ == 0) return Light::kWhole;
  // (an ill-conditioned level's hit is finished by the active set: on the whole problem)
  if (ill_conditioned(d, form)) return Light::kRebuild;
  int found = 0;
  slack_rows_ = mv;
  const bool hit = try_working_set(P_, ws, y.head(r_ + mv), W_, &found);
  slack_rows_ = 0;
  if (!hit || !left_out_rows_feasible(ws, y.head(r_))) {
    // (the whole trial computes its own factorisations: of the same working rows and
    // objective, the trial cache would return these within the call)
    tc_->drop();
    return Light::kRebuild;
  }
  if (ws.verified) return Light::kHit;  // (store_level_working_set keeps it)
  // store_level_working_set after a hit: the set stored again (its rows are all in this P,
  // in the whole problem's order: the same set), unless it prunes it: its trials of the
  // pruned set need the whole problem
  if (prunes(P_, y.head(r_ + mv), mv)) return Light::kHitStore;
  store_working_set(P_, W_, ws);
  return Light::kHit;
}

bool Hierarchy::left_out_rows_feasible(const Working& ws, const Eigen::Ref<const Vec>& z) {
  // try_working_set's test of a row of P (g / |g|, bounds [l, u] / |g|) at z:
  // g z / |g| within kWarmFeasTol max(1, |l| / |g|) below l / |g|, and so above u / |g|;
  // a row inside [l, u] unscaled passes whatever |g|, which is computed for the others only
  auto outside = [](double v, double l, double u, double nrm) {
    const double sl = kWarmFeasTol * std::max(1.0, finite_abs(l / nrm));
    const double su = kWarmFeasTol * std::max(1.0, finite_abs(u / nrm));
    return v / nrm < l / nrm - sl || v / nrm > u / nrm + su;
  };
  if (has_bounds_) {
    auto dx = tvec_.head(n_);
    dx.noalias() = Z_.leftCols(r_) * z;
    for (int j = 0; j < n_; ++j) {
      const double l = std::min(lb_(j) - x_(j), 0.0);
      const double u = std::max(ub_(j) - x_(j), 0.0);
      if ((dx(j) >= l && dx(j) <= u) || l == u || holds_id(ws.id, capacity_ + j)) continue;
      const double nrm = Z_.row(j).head(r_).norm();
      if (!(nrm > 1e-12)) continue;  // (add_row's constant row: not in P)
      if (outside(dx(j), l, u, nrm)) return false;
    }
  }
  if (k_ == 0) return true;
  // (add_inherited_rows formed Cin Z and Cin x for every inherited row: kz_ = k_)
  auto cz = cztmp_.col(0).head(k_);
  cz.noalias() = CinZ_.topLeftCorner(k_, r_) * z;
  const auto cx = cinx_.head(k_);
  for (int i = 0; i < k_; ++i) {
    const double l = std::min(lin_(i) - cx(i), 0.0);
    const double u = std::max(uin_(i) - cx(i), 0.0);
    if ((cz(i) >= l && cz(i) <= u) || l == u || holds_id(ws.id, inid_[i])) continue;
    const double nrm = CinZ_.row(i).head(r_).norm();
    const double floor = inid_[i] >= min_[0] ? kMovableTol : 1e-12;
    if (!(nrm > floor * std::max(cin_norm(i), 1e-300))) continue;  // (not in P)
    if (outside(cz(i), l, u, nrm)) return false;
  }
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

template <typename ColdStart>
int Hierarchy::warm_started_active_set(const LsqProblem& P, const Working& ws, bool warm,
                                       int hard_rows, int slack_rows, Eigen::Ref<Vec> y,
                                       ColdStart cold_start, int& iters, bool& hit) {
  int found = 0;
  slack_rows_ = slack_rows;
  hit = warm && try_working_set(P, ws, y, W_, &found);
  slack_rows_ = 0;
  if (hit) return kOk;  // the stored set's point is the optimum: y and W_ set
  // a miss whose stored rows matched: the stored set made feasible
  if (warm && found > 0 && seed_working_set(P, ws, hard_rows, r_, y, W_)) {
    ++seeded_;
  } else {  // the cold start: only the equality rows (lo = hi) in the working set
    std::fill(W_.begin(), W_.begin() + P.rows, 0);
    for (int i = 0; i < P.rows; ++i)
      if (P.lo(i) == P.hi(i)) W_[i] = 2;
    cold_start(y);
  }
  if (!active_set(P, y, W_, iters)) return timed_out_ ? kTimeLimit : kNotConverged;
  return kOk;
}

bool Hierarchy::zero_objective(const LsqProblem& P, const Eigen::Ref<const Vec>& y) {
  // |Q y - c| (with the compressed rows' constant part) within the rounding of Q y - c itself,
  // as sign_tolerance's floor: the objective is >= 0, so its minimum is within that too
  const int k = P.cols, qr = P.qrows;
  const auto Q = P.Q.topLeftCorner(qr, k);
  auto res = dres_.head(qr);
  res.noalias() = Q * y;
  res -= P.c.head(qr);
  const double qn = Q.norm();
  const double round = kRoundFactor * kEps * k * qn * (qn * y.cwiseAbs().maxCoeff() + P.c_norm());
  return std::sqrt(res.squaredNorm() + P.dropped2) <= round;
}

bool Hierarchy::prunes(const LsqProblem& P, const Eigen::Ref<const Vec>& y, int level_rows) {
  // (a stored vertex of far rows is tried again at every later call while its point stays
  // feasible, however far the point moves from the level's start: on the humanoid's support
  // polygon, 24 joint speed bounds of an early large correction, |z| ~ 23 rad/s where the
  // polygon asked ~1e-5, a 26 x 24 QR per call and the levels below moving back off them)
  const int k = P.cols, first_own = P.rows - level_rows;
  const double tight = settings.violation_tol * std::max(1.0, y.head(k).cwiseAbs().maxCoeff());
  int far = 0;
  for (int i = 0; i < P.rows; ++i) {
    Wp_[i] = W_[i];
    if (i >= first_own || (W_[i] != 1 && W_[i] != -1)) continue;
    const double t = (W_[i] == 1) ? P.hi(i) : P.lo(i);
    if (!(std::abs(t) <= tight)) {
      Wp_[i] = 0;
      ++far;
    }
  }
  return far > 0 && zero_objective(P, y.head(k));
}

void Hierarchy::store_level_working_set(const LsqProblem& P, const Eigen::Ref<const Vec>& y,
                                        int level_rows, bool hit, Working& ws) {
  if (hit && ws.verified) return;  // (W_ is ws on P's rows)
  store_working_set(P, W_, ws);
  if (!prunes(P, y, level_rows)) return;
  const int k = P.cols;
  // the rest tried as the next call would (its point into xc_, scratch here; y and x stay
  // this call's), the rows its point violates added, up to kPruneRounds tries: stored when
  // one hits (a verification, not counted as a warm trial)
  const int trials = stats_.reduced_trials;
  bool verified = false;
  for (int attempt = 0; attempt < kPruneRounds && !verified; ++attempt) {
    store_working_set(P, Wp_, pruned_);
    int found = 0;
    slack_rows_ = level_rows;
    verified = try_working_set(P, pruned_, xc_.head(k), Wp_, &found);
    slack_rows_ = 0;
    if (verified || found != static_cast<int>(pruned_.id.size())) break;
    auto gy = gy_.head(P.rows);
    gy.noalias() = P.G.topLeftCorner(P.rows, k) * xc_.head(k);
    int back = 0;
    for (int i = 0; i < P.rows; ++i) {
      if (Wp_[i]) continue;
      if (gy(i) > P.hi(i) + kWarmFeasTol * std::max(1.0, finite_abs(P.hi(i)))) {
        Wp_[i] = 1;
      } else if (gy(i) < P.lo(i) - kWarmFeasTol * std::max(1.0, finite_abs(P.lo(i)))) {
        Wp_[i] = -1;
      } else {
        continue;
      }
      ++back;
    }
    if (back == 0) break;  // (a multiplier's sign: not the drop)
  }
  stats_.reduced_trials = trials;
  if (verified) {
    std::swap(ws.id, pruned_.id);  // (swapped buffers: no allocation)
    std::swap(ws.side, pruned_.side);
    ++stats_.pruned_working_sets;
  }
  ws.verified = true;  // (a failed verification is not repeated either, until a miss)
}

void Hierarchy::store_working_set(const LsqProblem& P, const std::vector<int8_t>& W,
                                  Working& ws) {
  ws.id.clear();
  ws.side.clear();
  ws.stored = true;
  ws.verified = false;
  for (int i = 0; i < P.rows; ++i) {
    if (W[i] == 1 || W[i] == -1) {
      ws.id.push_back(P.id[i]);
      ws.side.push_back(W[i]);
    }
  }
}

}  // namespace qpcoord

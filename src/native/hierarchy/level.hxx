// qpcoord native engine, Hierarchy: a level's parts -- its closed form, the test and freeze
// that accept it, its least-squares problem in y = (z, w) when the closed form is not
// feasible, the rows its optimum leaves violated, and the freeze of its optimal set.
// Part of hierarchy.cpp's translation unit (included there, after its helpers).
namespace qpcoord {

Hierarchy::LevelForm Hierarchy::level_closed_form(const LevelRows& d, bool same_m) {
  const CRef<Mat>& Aeq = d.Aeq;
  const CRef<Vec>& beq = d.beq;
  const int stage = d.stage, me = d.me, e0 = d.e0;
  const auto Zr = Z_.leftCols(r_);
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
    // Python engine leaves them to the lower levels: tests/core/test_native_damped_levels.py)
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
  if (!same_m) closed_form_store(stage);  // (M and its factorisations: of these inputs)
  return {rank, tau, M_scale, by_qr};
}

bool Hierarchy::accept_closed_form(const LevelRows& d, const LevelForm& form) {
  const CRef<Mat>& C = d.C;
  const CRef<Vec>& lo = d.lo;
  const CRef<Vec>& hi = d.hi;
  const int stage = d.stage, mi = d.mi, i0 = d.i0;
  const int rank = form.rank;
  const bool by_qr = form.by_qr;
  auto& svd = svds_[stage];
  auto xc = xc_.head(n_);
  bool ok = feasible(xc);
  if (ok)
    for (int i = 0; i < mi && ok; ++i) ok = in_box(row_dot(C, i0 + i, xc), lo(i0 + i), hi(i0 + i));
  if (!ok) return false;
  {
    x_ = xc;
    snap(x_);
    inherit(C, lo, hi, i0, mi, nullptr);
    if (by_qr && !cf_->wide && rank == r_) {  // M has full column rank: no freedom left
      r_ = 0;
      z_identity_ = false;
    } else if (rank) {
      // (the freeze cache: the same inputs as this level's last freeze: its outputs restored)
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
  }
  return true;
}

int Hierarchy::level_problem(const LevelRows& d, const LevelForm& form, const Working* only) {
  const CRef<Mat>& C = d.C;
  const CRef<Vec>& lo = d.lo;
  const CRef<Vec>& hi = d.hi;
  const CRef<Vec>& sw = d.sw;
  const int stage = d.stage, me = d.me, mi = d.mi, i0 = d.i0;
  const int rank = form.rank;
  const double tau = form.tau;
  const bool by_qr = form.by_qr;
  const auto Zr = Z_.leftCols(r_);
  auto M = Ms_[stage].leftCols(r_);
  auto& svd = svds_[stage];
  auto e = e_.head(me);
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
  // the moving rows' conditioning, scaled by their norms (ill_conditioned): one row's is its
  // own projection's share of its norm
  rows_pivot_ = 1.0;
  if (mv == 1) rows_pivot_ = CZl.row(mov_[0]).norm() / depn_(0);
  if (mv > 1) rows_pivot_ = drop_dependent_directions(CZl, mov_, depn_.head(mv));
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
  left_out_ = 0;
  add_inherited_rows(P, only);
  add_bound_rows(P, stage, only);
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
  // Q = R P^T of full rank and well-conditioned, nothing else in the objective: the warm
  // trial's least-squares step through R (factor_range_trial, range_step)
  range_trial_ = full_r && form.rank == r_ && cf_->mqr.rank() == r_ && mv == 0 &&
                 P.qrows == r_ && !ill_conditioned(d, form);
  if (P.rows == slack_g0 + mv && P.qrows == qme + ndamp + mv) {  // every level row kept
    P.zcols = r_;
    P.slacks = mv;
    P.slack_q0 = qme + ndamp;
    P.slack_g0 = slack_g0;
  }
  return mv;
}

bool Hierarchy::ill_conditioned(const LevelRows& d, const LevelForm& form) const {
  // moving rows with a combination within kIllConditioned of the frozen rows' span (a row
  // parallel to them to 1e-8: its violation falls by ~1e-8 of itself across the whole box,
  // and a multiplier under settings.kkt_tol stopped the active set short of the box, where
  // the lower levels are decided; the Python engine's rule too)
  if (rows_pivot_ < kIllConditioned) return true;
  if (!d.me || !form.rank) return false;
  if (form.by_qr) return cf_->smin < kIllConditioned * form.scale;
  const Vec& s = svds_[d.stage].singularValues();
  return s(form.rank - 1) < std::max(form.tau, kIllConditioned * s(0));
}

int Hierarchy::violated_rows(const LevelRows& d) {
  const CRef<Mat>& C = d.C;
  const CRef<Vec>& lo = d.lo;
  const CRef<Vec>& hi = d.hi;
  const int mi = d.mi, i0 = d.i0, mv = static_cast<int>(mov_.size());
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
  return nviol;
}

void Hierarchy::freeze_level(const LevelRows& d, const LevelForm& form, int nviol) {
  const CRef<Mat>& C = d.C;
  const CRef<Vec>& lo = d.lo;
  const CRef<Vec>& hi = d.hi;
  const int stage = d.stage, mi = d.mi, i0 = d.i0;
  const int rank = form.rank;
  const bool by_qr = form.by_qr;
  auto& svd = svds_[stage];
  auto CZl = CZl_.topLeftCorner(mi, r_);
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
    return;
  }
  if (by_wide) ++stats_.wide_freezes;
  // (the freeze cache: the same inputs as this level's last freeze: its outputs restored; the
  // violated rows are inputs of the general freeze only)
  const FreezeKind kind = by_null_space ? FreezeKind::kNullSpace
                          : by_wide     ? FreezeKind::kWide
                                        : FreezeKind::kGeneral;
  if (memo_gate() && freeze_lookup(stage, kind, rank, mi, by_f))
    return;
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
}

}  // namespace qpcoord

// qpcoord native engine, Hierarchy: a level's closed form by the pivoted QR of its projected
// equalities, and the row space it freezes.
// Part of hierarchy.cpp's translation unit (included there, after its helpers).
namespace qpcoord {

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
  if (!(same_m && f.factored)) {
    f.rank = qr_factor(M, tol, floor);
    f.factored = true;  // (the factorisation of the M now in Ms_ of the stage)
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

}  // namespace qpcoord

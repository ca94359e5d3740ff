// qpcoord native engine, Hierarchy: the freezes (Z <- Z null(F) in its three kinds, the carried
// projection Cin Z) and the tests of rows dependent on the frozen ones.
// Part of hierarchy.cpp's translation unit (included there, after its helpers).
namespace qpcoord {

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

/// The rank of a level's M = A Z (its SVD in svds_ of the stage, numerical rank `rank`)
/// without the directions in which the level's rows are dependent to within kMovableTol of
/// the rows they combine: a left singular vector u_i with
/// s_i <= kMovableTol sum_j |u_ij| |A_j| is a combination that only rounding keeps (each
/// row's projection carries an error proportional to its own norm, so a combination's to
/// sum_j |u_ij| |A_j|). It is left to the lower levels as an exactly dependent one would be,
/// not damped and frozen. Two cases: the combination lies in the frozen rows' span (the
/// Talos CoM level below the support polygon, which pins the CoM: 2 directions of ~1e-13
/// frozen would leave the posture level well above its optimum), or the level's own rows
/// nearly cancel (rows parallel to ~1e-10: the point kept along that direction is set by
/// gradients under the KKT tolerance and decides the levels below). The Python engine's
/// _independent_rank and the inequality rows' drop_dependent_directions use the same
/// measure. Only s_i <= kMovableTol * scale can qualify (sum_j |u_ij| |A_j| <= |A|_F = scale
/// for a unit u_i): no row norm is computed otherwise.
int Hierarchy::independent_rank(const Svd& svd, const CRef<Mat>& Aeq, int e0, int me, int rank,
                                double scale) {
  const Vec& s = svd.singularValues();
  for (int i = 0; i < rank; ++i) {
    if (s(i) > kMovableTol * scale) continue;
    double combined = 0.0;
    for (int j = 0; j < me; ++j)
      combined += std::abs(svd.matrixU()(j, i)) * Aeq.row(e0 + j).norm();
    if (s(i) <= kMovableTol * combined) {
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
/// Returns the last pivot kept (the level is ill-conditioned below kIllConditioned: see
/// ill_conditioned), 1 when the Gram screen proves every pivot at least kIllConditioned.
/// Uses fqr_ (free until the level's freeze) and tmpr_.
double Hierarchy::drop_dependent_directions(Eigen::Ref<Mat> R, const std::vector<int>& rows,
                                            const Eigen::Ref<const Vec>& norms) {
  const int m = static_cast<int>(rows.size());
  if (m < 2 || r_ == 0) return 1.0;
  MapMat T = fqr_.matrix(r_, m);
  for (int j = 0; j < m; ++j) T.col(j) = R.row(rows[j]).head(r_).transpose() / norms(j);
  if (independent_by_gram(T, kIllConditioned)) {
    ++stats_.gram_screens;
    return 1.0;
  }
  const int rank = fqr_.factor(kMovableTol, 0.0);
  const double last = rank ? std::abs(fqr_.matrix()(rank - 1, rank - 1)) : 0.0;
  if (rank >= std::min(m, r_)) return last;
  // row j's projection: norms(j) Qf [Qf^T t_j](0:rank), and the QR stopped at rank holds
  // Qf^T t_j's first rank entries in its column of pivoted order c (perm(c) = j): R's for a
  // pivot column (c < rank; the reflector below its diagonal), the reflected column's head
  // for the others. One application of Qf per row (Qf^T t_j is already there)
  auto v = tmpr_.head(r_);
  const MapMat F = fqr_.matrix();
  for (int c = 0; c < m; ++c) {
    const int j = fqr_.perm(c);
    const int top = std::min(c + 1, rank);
    v.setZero();
    v.head(top) = F.col(c).head(top);
    fqr_.apply_q(v);
    R.row(rows[j]).head(r_) = norms(j) * v.transpose();
  }
  ++stats_.dependent_drops;
  return last;
}

/// True when the pivoted QR of T (r x m, columns of norm at most 1: projections of rows
/// scaled by their own norms) provably keeps min(m, r) pivots of at least pivot_floor, so
/// that drop_dependent_directions would change nothing and the level is not ill-conditioned
/// by its rows: a Cholesky of G - delta I, G = T^T T (m <= r) or T T^T (m > r), k = min(m, r),
/// succeeds. Then lambda_min(G) > delta - err, err the rounding of G and of the Cholesky (at
/// most 16 (m + r) eps trace(G), trace(G) = |T|_F^2), so sigma_k(T) > sqrt(m) pivot_floor;
/// every pivot of the QR is at least sigma_k(T) / sqrt(m) (at step j, the largest remaining
/// column of the projection P T off the j - 1 chosen columns is at least |P T|_2 / sqrt(m) >=
/// sigma_j(T) / sqrt(m)). A failed Cholesky proves nothing (the QR decides). k^2 max(m, r) / 2
/// + k^3 / 6 multiply-adds in products where the QR takes about 2 m r k in matrix-vector steps
/// (the humanoid: 72 moving rows in 88 columns at its first level).
bool Hierarchy::independent_by_gram(const Eigen::Ref<const Mat>& T, double pivot_floor) {
  const int r = static_cast<int>(T.rows()), m = static_cast<int>(T.cols());
  const int k = std::min(m, r);
  if (k == 0 || k > gram_.rows()) return false;
  auto G = gram_.topLeftCorner(k, k);
  const double trace = T.squaredNorm();  // trace(G) = |T|_F^2 in either form
  if (!std::isfinite(trace)) return false;
  const double need = m * pivot_floor * pivot_floor;
  const double delta = need + 16.0 * (m + r) * kEps * trace;
  // G - delta I = L L^T in the lower triangle, a column of L at a time (left-looking): G's
  // column j is formed only when L reaches it, by one product, so a failure at column j costs
  // j + 1 columns of G (the Talos support polygon's 6 rows of rank 2 fail at the third; the
  // whole Gram by a rank update cost more than the QR that decides then). L(j+1:, j) comes
  // from one product of L(j+1:, 0:j) with L(j, 0:j) (no allocation)
  for (int j = 0; j < k; ++j) {
    auto gj = G.col(j).tail(k - j);
    if (m <= r)
      gj.noalias() = T.rightCols(k - j).transpose() * T.col(j);
    else
      gj.noalias() = T.middleRows(j, k - j) * T.row(j).transpose();
    const double d2 = gj(0) - delta - G.row(j).head(j).squaredNorm();
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

}  // namespace qpcoord

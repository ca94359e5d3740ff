// qpcoord native engine, Hierarchy: the caches of a re-solve whose matrices did not change (closed
// form, freeze, trial; the bound rows' in add_bound_rows): their entry test, lookups and stores.
// Part of hierarchy.cpp's translation unit (included there, after its helpers).
namespace qpcoord {

void Hierarchy::invalidate_caches() {
  for (FreezeMemo& f : memos_) {
    f.valid = f.pending = f.zm_valid = false;
    f.a_layout = f.c_layout = 0;  // the level's rows compare unequal: M = A Z recomputed
  }
  for (ClosedForm& f : cforms_) f.valid = f.svd_valid = false;
  for (TrialState& t : trials_) t.intact = false;
  for (BoundRowsMemo& m : bound_memos_) m.valid = false;
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

}  // namespace qpcoord

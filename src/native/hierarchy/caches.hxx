// qpcoord native engine, Hierarchy: the caches of a re-solve whose matrices did not change
// (closed form, freeze, trial; the bound rows' in add_bound_rows): what each one's key is,
// where it is looked up and stored. Each is a KeyedCache (keyed_cache.hpp).
// Part of hierarchy.cpp's translation unit (included there, after its helpers).
namespace qpcoord {

void Hierarchy::invalidate_caches() {
  for (FreezeCache& f : freezes_) f.forget();
  std::fill(freeze_pending_.begin(), freeze_pending_.end(), 0);
  for (ClosedFormCache& f : cforms_) f.forget();
  for (TrialCache& t : trials_) t.forget();
  for (BoundRowsCache& m : bound_rows_) m.forget();
}

bool Hierarchy::closed_form_lookup(int stage, const CRef<Mat>& Aeq, int e0, int me,
                                   const CRef<Mat>& C, int i0, int mi) {
  entry_rows_same_ = false;
  if (!per_stage_) return false;  // (the first call: no cache allocated yet)
  ClosedFormCache& f = cforms_[stage];
  if (!memo_gate()) {  // Z differs from the last call's: nothing kept
    f.drop();
    freezes_[stage].drop();
    return false;
  }
  f.begin();
  // the level's rows first: when they changed, only they are recorded -- Z is recorded
  // once they repeat
  const bool same_a = f.same_block(Aeq.middleRows(e0, me));
  const bool same_c = f.same_block(C.middleRows(i0, mi));
  entry_rows_same_ = same_a && same_c;
  if (!entry_rows_same_) {
    freezes_[stage].drop();
    return false;
  }
  f.same(r_);
  f.same(z_identity_ ? 1 : 0);
  f.same_block(Z_.leftCols(r_));
  // (a level without equality rows has no closed form to reuse: its entry serves the
  // freeze cache's test only, and is not counted)
  return me ? f.hit(stats_) : f.holds();
}

void Hierarchy::closed_form_store(int stage) {
  if (entry_rows_same_) cforms_[stage].store();
}

bool Hierarchy::freeze_lookup(int stage, FreezeKind kind, int rank, int mi, bool with_viol) {
  FreezeCache& f = freezes_[stage];
  freeze_pending_[stage] = 0;
  if (!entry_rows_same_) return false;  // (closed_form_lookup: the rows changed)
  f.begin();
  f.same(static_cast<int>(kind));
  f.same(rank);
  f.same(with_viol ? mi : -1);
  if (with_viol) f.same(viol_.data(), mi);
  f.same_block(CinZ_.topLeftCorner(kz_, r_));
  // the level's rows and Z on entry (its closed-form entry) and these inputs: the outputs
  if (cforms_[stage].holds() && f.hit(stats_)) {
    const Frozen& o = f.value;
    Z_.leftCols(o.r) = o.Z.leftCols(o.r);
    r_ = o.r;
    z_identity_ = o.zid;
    kz_ = o.kz;
    CinZ_.topLeftCorner(kz_, r_) = o.CinZ.topLeftCorner(kz_, r_);
    if (kind == FreezeKind::kNullSpace) ++stats_.null_space_freezes;  // as freeze_null_space
    return true;
  }
  freeze_pending_[stage] = 1;  // (the inputs recorded: the outputs by freeze_computed)
  return false;
}

void Hierarchy::freeze_computed(int stage) {
  // Z is not the previous call's any more (to rounding it may be, not bit for bit): the
  // lower levels' freezes have other inputs, and are not looked up in this call
  if (!memo_gate()) return;
  z_repeats_ = false;
  if (!freeze_pending_[stage]) return;
  freeze_pending_[stage] = 0;
  FreezeCache& f = freezes_[stage];
  Frozen& o = f.value;
  o.r = r_;
  o.kz = kz_;
  o.zid = z_identity_;
  o.Z.leftCols(r_) = Z_.leftCols(r_);
  o.CinZ.topLeftCorner(kz_, r_) = CinZ_.topLeftCorner(kz_, r_);
  f.store();
}

bool Hierarchy::trial_lookup(const LsqProblem& P, const std::vector<int8_t>& W) {
  TrialCache& t = *tc_;
  const int k = P.cols, qr = P.qrows;
  t.begin();
  const int sizes[8] = {k, qr, unit_q_ ? 1 : 0, P.slacks, P.zcols, P.slack_q0, P.slack_g0,
                        range_trial_ ? 1 : 0};
  t.same(sizes, sizeof sizes);
  // (factor_rows' widx_: W's rows in order)
  widx_.clear();
  for (int i = 0; i < P.rows; ++i)
    if (W[i]) widx_.push_back(i);
  t.same_rows(P.G, widx_, k);
  t.same_block(P.Q.topLeftCorner(qr, k));
  if (!t.hit(stats_)) return false;
  // the same factorisations as factor_trial's: its flags as it leaves them (K, when the
  // trial's ls_step made it, is still the factorisation of this trial's K: k_valid kept)
  finish_ready_ = false;
  trial_ready_ = false;
  qt_stale_ = ts_->qt_stale;
  return true;
}

}  // namespace qpcoord

// qpcoord native engine, IKStep: the task kernels -- each task kind's error, Jacobian and rows
// from the kernel's parameters (run_kernel: the one place a kind is evaluated), the support
// bands (run_band), the rows another module computes (run_rows) and the limits' box (box).
// Part of ik_step.cpp's translation unit (included there, after the IKStep class).
namespace qpcoord {
namespace {

bool IKStep::run_kernel(Kernel& k, const double* q, int64_t qs) {
  const double gain = k.gain;
  const int rows = k.rows;
  if (k.band >= 0) return run_band(k, bands_[k.band]);
  if (k.kind == kCollision) return run_rows(k);
  switch (k.kind) {
    case kPosition: {  // e = y - y*, J the frame's linear rows; b = dy*/dt - K e
      const Frame& f = frames_[k.frame];
      frame_jacobian(f);
      for (int r = 0; r < rows; ++r) {
        const int a = k.sel[r];
        k.err[r] = f.p[a] - k.target[r];
        const double e = gain * (k.target[r] - f.p[a]);
        write_row(k, r, Jt_.row(a), k.has_vel ? k.vel[r] + e : 0.0 + e);
      }
      return true;
    }
    case kFramePosition: {
      const Frame& f = frames_[k.frame];
      frame_jacobian(f);
      for (int r = 0; r < rows; ++r) {
        const int a = k.sel[r];
        k.err[r] = f.p[a] - k.target[a];
        double bv = -gain * k.err[r];
        if (k.has_vel) bv += k.vel[a];
        write_row(k, r, Jt_.row(a), bv);
      }
      return true;
    }
    case kPose:
    case kPoseSplit: {
      const Frame& f = frames_[k.frame];
      const Mat3 RE = k.Rinv * f.R;  // E = T*^-1 T
      const Vec3 pE = k.Rinv * f.p + k.pinv;
      frame_jacobian(f);
      // LOCAL Jacobian: R^T of both parts
      Jl_.setZero();
      const Mat3 Rt = f.R.transpose();
      for (int c : f.cols) {
        Jl_.col(c).head<3>() = Rt * Jt_.col(c).head<3>();
        Jl_.col(c).tail<3>() = Rt * Jt_.col(c).tail<3>();
      }
      Jt_.setZero();
      Vec6 e, ff = Vec6::Zero();
      if (k.kind == kPose) {  // e = log6(E), J = Jlog6(E) J_local
        e = spatial::log6(RE, pE);
        const Mat6 Jlog = spatial::jlog6(RE, pE);
        for (int c : f.cols) Jt_.col(c).noalias() = Jlog * Jl_.col(c);
        if (k.has_vel) {
          // Ad(E^-1) nu with E^-1 = (RE^T, -RE^T pE)
          const Mat3 Ri = RE.transpose();
          const Vec3 pi = -(Ri * pE);
          const Vec3 u(k.vel[0], k.vel[1], k.vel[2]), w(k.vel[3], k.vel[4], k.vel[5]);
          Vec6 tw;
          tw.tail<3>() = Ri * w;
          tw.head<3>() = Ri * u + pi.cross(tw.tail<3>());
          ff = Jlog * tw;
        }
      } else {  // "split": e = (E.translation, log3(E.rotation)), J = (R_E J_lin; Jlog3 J_ang)
        double theta;
        const Vec3 lw = spatial::log3(RE, theta);
        const Mat3 Jlog = spatial::jlog3(theta, lw);
        e.head<3>() = pE;
        e.tail<3>() = lw;
        for (int c : f.cols) {
          Jt_.col(c).head<3>() = RE * Jl_.col(c).head<3>();
          Jt_.col(c).tail<3>() = Jlog * Jl_.col(c).tail<3>();
        }
        if (k.has_vel) {
          const Vec3 u(k.vel[0], k.vel[1], k.vel[2]), w(k.vel[3], k.vel[4], k.vel[5]);
          ff.head<3>() = w.cross(pE) + u;
          ff.tail<3>() = Jlog * (RE.transpose() * w);
        }
      }
      write_error_rows(k, rows, gain, e, k.has_vel, ff);
      return true;
    }
    case kOrientation: {  // Rinv holds R*^T
      const Frame& f = frames_[k.frame];
      const Mat3 E = k.Rinv * f.R;
      double theta;
      const Vec3 e = spatial::log3(E, theta);
      const Mat3 Jlog = spatial::jlog3(theta, e);
      const Mat3 JR = Jlog * f.R.transpose();
      Jt_.setZero();
      for (int c : f.cols) Jt_.col(c).head<3>() = JR * Vec3(J_(3, c), J_(4, c), J_(5, c));
      Vec3 ff = Vec3::Zero();
      if (k.has_vel) ff = Jlog * (E.transpose() * Vec3(k.vel[0], k.vel[1], k.vel[2]));
      write_error_rows(k, rows, gain, e, k.has_vel, ff);
      return true;
    }
    case kCom: {
      for (int r = 0; r < rows; ++r) {
        const int a = k.sel[r];
        for (int c = 0; c < nv_; ++c) Jt_(0, c) = Jcom_(a, c);
        k.err[r] = com_[a] - k.target[a];
        double bv = -gain * k.err[r];
        if (k.has_vel) bv += k.vel[a];
        write_row(k, r, Jt_.row(0), bv);
      }
      return true;
    }
    case kPosture: {
      double* Aeq = out_[0].data() + static_cast<size_t>(k.row0) * nv_;
      double* beq = out_[1].data() + k.row0;
      // d = difference(q, q_ref) on the posture's joints (its plan), into row_ at their v
      // indices: q copied contiguous (integrate::difference's q0), q_ref read in place
      for (int i = 0; i < nq_; ++i) hold_[i] = q[i * qs];
      integrate::difference(k.qidx.data(), static_cast<int>(k.qidx.size() / 4), hold_.data(),
                            k.target.data(), 1, 1.0, row_.data());
      for (int r = 0; r < rows; ++r) {
        const int j = k.sel[r];
        const double s = k.sw[r];
        const double d = row_[j];
        const double bv = gain * d;
        k.err[r] = -d;
        // the task's A (the selection) is constant: the stacked row is rewritten
        for (int c = 0; c < nv_; ++c) Aeq[r * nv_ + c] = 0.0;
        Aeq[r * nv_ + j] = k.A(r, j) * s;
        k.b[r] = bv;
        beq[r] = bv * s;
      }
      return true;
    }
    case kRelativeFrame: {  // E = T*^-1 (oMr^-1 oMf), e = log6(E), J = Jlog6(E) (Jf - Ad Jr)
      const Frame& f = frames_[k.frame];
      const Frame& g = frames_[k.qidx[0]];
      const Mat3 Rrel = g.R.transpose() * f.R;
      const Vec3 prel = g.R.transpose() * (f.p - g.p);
      const Mat3 RE = k.Rinv * Rrel;
      const Vec3 pE = k.Rinv * prel + k.pinv;
      // Jf - Ad(fMr) Jr in LOCAL coordinates of f: the world-aligned motion at f's origin
      // of f's supporting joints less that of r's, rotated by Rf^T (shared joints cancel)
      Jl_.setZero();
      for (int c : f.cols) {
        const Vec3 w(J_(3, c), J_(4, c), J_(5, c));
        Jl_.col(c).head<3>() += Vec3(J_(0, c), J_(1, c), J_(2, c)) + w.cross(f.p);
        Jl_.col(c).tail<3>() += w;
      }
      for (int c : g.cols) {
        const Vec3 w(J_(3, c), J_(4, c), J_(5, c));
        Jl_.col(c).head<3>() -= Vec3(J_(0, c), J_(1, c), J_(2, c)) + w.cross(f.p);
        Jl_.col(c).tail<3>() -= w;
      }
      const Mat3 Rt = f.R.transpose();
      const Vec6 e = spatial::log6(RE, pE);
      const Mat6 Jlog = spatial::jlog6(RE, pE);
      for (int c = 0; c < nv_; ++c) {
        Vec6 local;
        local.head<3>() = Rt * Jl_.col(c).head<3>();
        local.tail<3>() = Rt * Jl_.col(c).tail<3>();
        Jt_.col(c).noalias() = Jlog * local;
      }
      write_error_rows(k, rows, gain, e, false, e);
      return true;
    }
    case kJointCoupling: {  // e = sum(r_i q_i) - offset, J = r_i at the joints' v indices
      const int n = static_cast<int>(k.qidx.size() / 2);
      double s = 0.0;
      Jt_.row(0).setZero();
      for (int i = 0; i < n; ++i) {
        s += k.target[i] * q[k.qidx[i] * qs];
        Jt_(0, k.qidx[n + i]) = k.target[i];
      }
      const double e = s - k.target[n];
      k.err[0] = e;
      write_row(k, 0, Jt_.row(0), -gain * e);
      return true;
    }
    case kDamping: {  // A = I, b = 0; q_hold = q
      diagonal_rows(k, 1.0, nullptr);
      for (int i = 0; i < nq_; ++i) k.hold[i] = q[i * qs];
      return true;
    }
    case kLowAcceleration: {  // A = I, b = v_prev (v coordinates); q_hold = q
      if (k.has_vel) {  // set_previous: for this step only
        for (int i = 0; i < nv_; ++i) k.vprev[i] = k.target[i];
        k.has_vel = false;
      } else if (std::isnan(k.hold[0])) {  // the first step: from rest
        for (int i = 0; i < nv_; ++i) k.vprev[i] = 0.0;
      } else {  // difference(q_hold, q) / dt, into row_ then v_prev
        for (int i = 0; i < nq_; ++i) hold_[i] = k.hold[i];
        integrate::difference(k.qidx.data(), static_cast<int>(k.qidx.size() / 4),
                              hold_.data(), q, qs, dt_, row_.data());
        for (int i = 0; i < nv_; ++i) k.vprev[i] = row_[i];
      }
      for (int r = 0; r < nv_; ++r) {
        row_[r] = k.vprev[r];
        if (!std::isfinite(row_[r])) return false;  // the task's refresh names it
      }
      diagonal_rows(k, 1.0, row_.data());
      for (int i = 0; i < nq_; ++i) k.hold[i] = q[i * qs];
      return true;
    }
    case kLMDamping:
      return run_damping(k);
    default:
      return false;
  }
}

template <class Src>
bool IKStep::put_row(const Kernel& k, int r, const Src& src, double l, double u) {
  if (std::isnan(l) || std::isnan(u) || l == kInf || u == -kInf || l > u) return false;
  if (mapped_) {
    row_.noalias() = M_.transpose() * src.transpose();
  } else {
    row_ = src.transpose();
  }
  if (!row_.allFinite()) return false;
  const size_t i = static_cast<size_t>(k.row0 + r);
  double* C = out_[2].data() + i * nv_;
  for (int j = 0; j < nv_; ++j) {
    k.A(r, j) = row_[j];
    C[j] = row_[j];
  }
  k.lower[r] = out_[3].data()[i] = l;
  k.upper[r] = out_[4].data()[i] = u;
  out_[5].data()[i] = k.sw[r];
  return true;
}

bool IKStep::run_damping(Kernel& k) {
  const Kernel& o = kernels_[k.owner];
  // sum(w e^2) of the owner (w = sqrt(w)^2: to rounding of the Python task's weight); a band:
  // its distance outside [lower, upper], read from its rows K (lower - e), K (upper - e)
  double e2 = 0.0;
  if (o.band >= 0) {
    for (int r = 0; r < o.rows; ++r) {
      const double out = std::max(o.lower[r], 0.0) - std::min(o.upper[r], 0.0);
      e2 += o.sw[r] * o.sw[r] * (out * out);
    }
    e2 /= o.gain * o.gain;
  } else {
    for (int r = 0; r < o.rows; ++r) e2 += o.sw[r] * o.sw[r] * (o.err[r] * o.err[r]);
  }
  double mu = k.lm * e2;
  if (!std::isfinite(mu)) return false;  // the owner's Python refresh names its data
  // below the floor the rows are zero, not tiny (LMDamping._refresh: rows of any positive
  // size would fix the level's null space around a met task)
  if (mu <= k.lm * k.floor_sq) mu = 0.0;
  diagonal_rows(k, std::sqrt(mu), nullptr);
  return true;
}

void IKStep::diagonal_rows(Kernel& k, double d, const double* b) {
  double* Aeq = out_[0].data() + static_cast<size_t>(k.row0) * nv_;
  double* beq = out_[1].data() + k.row0;
  for (int r = 0; r < nv_; ++r) {
    for (int c = 0; c < nv_; ++c) {
      k.A(r, c) = r == c ? d : 0.0;
      Aeq[static_cast<size_t>(r) * nv_ + c] = r == c ? d * k.sw[r] : 0.0;
    }
    const double bv = b ? b[r] : 0.0;
    k.b[r] = bv;
    k.err[r] = 0.0;
    beq[r] = bv * k.sw[r];
  }
}

bool IKStep::run_band(const Kernel& k, support::Band& b) {
  const int rows = k.rows;
  const double gain = k.gain;
  auto put = [&](int r, const auto& src, double l, double u) { return put_row(k, r, src, l, u); };
  if (k.kind == kPositionBand) {  // y the frame's position rows, C their Jacobian
    const Frame& f = frames_[k.frame];
    frame_jacobian(f);
    for (int r = 0; r < rows; ++r) {
      const int a = k.sel[r];
      // y is finite: +-inf - y stays +-inf
      if (!put(r, Jt_.row(a), gain * (b.lo[r] - f.p[a]), gain * (b.hi[r] - f.p[a])))
        return false;
    }
    return true;
  }
  const double c[3] = {com_[0], com_[1], com_[2]};  // data.com[0]
  if (k.kind == kComBand) {
    for (int a = 0; a < 3; ++a) {
      for (int j = 0; j < nv_; ++j) Jt_(0, j) = Jcom_(a, j);
      // c is finite: +-inf - c stays +-inf
      if (!put(a, Jt_.row(0), gain * (b.lo[a] - c[a]), gain * (b.hi[a] - c[a]))) return false;
    }
    return true;
  }
  const int nf = static_cast<int>(b.frames.size()), np = rows / nf;
  for (int f = 0; f < nf; ++f) {
    const Frame& fr = frames_[b.frames[f]];
    frame_jacobian(fr);
    for (int i = 0; i < np; ++i) {
      const int r = f * np + i;
      support::contact_point(fr.R, fr.p, b.points(i, 0), b.points(i, 1), b.points(i, 2), Jt_,
                             b.x[r], b.y[r], b.Jx.row(r), b.Jy.row(r));
    }
  }
  for (int j = 0; j < nv_; ++j) {
    Jt_(0, j) = Jcom_(0, j);
    Jt_(1, j) = Jcom_(1, j);
  }
  if (support::polygon_rows(b, c[0], c[1], Jt_.row(0), Jt_.row(1), gain, b.margin) < 3)
    return false;  // collinear contacts: the task's _refresh raises its message
  for (int r = 0; r < rows; ++r)
    if (!put(r, b.J.row(r), -kInf, b.ub[r])) return false;
  return true;
}

bool IKStep::run_rows(const Kernel& k) {
  const qpcoord_rows_kernel& e = *k.rows_kernel;
  if (e.update(e.ctx, k.gain, dt_) < 0) return false;
  for (int r = 0; r < k.rows; ++r) {
    const Eigen::Map<const Eigen::RowVectorXd> src(e.C + static_cast<size_t>(r) * nv_, nv_);
    if (!put_row(k, r, src, e.lower[r], kInf)) return false;
  }
  return true;
}

void IKStep::box(const double* q, int64_t qs) {
  bool first = true;
  for (const Limit& L : limits_) {
    for (int i = 0; i < nv_; ++i) {
      row_[i] = -kInf;
      hi2_[i] = kInf;
    }
    if (L.velocity) {
      for (int i = 0; i < nv_; ++i) {
        row_[i] = -L.upper[i];
        hi2_[i] = L.upper[i];
      }
    } else if (L.acceleration) {  // AccelerationLimits.box
      for (int i = 0; i < nv_; ++i) {
        const double step = L.amax[i] * dt_;
        row_[i] = L.v_prev[i] - step;
        hi2_[i] = L.v_prev[i] + step;
      }
      for (size_t n = 0; n < L.qi.size(); ++n) {
        const double qq = q[L.qi[n] * qs];
        const int v = L.vi[n];
        const double a = L.amax[v];
        hi2_[v] = std::min(hi2_[v], braking::speed(L.upper[n] - qq, a, dt_, L.gain));
        row_[v] = std::max(row_[v], -braking::speed(qq - L.lower[n], a, dt_, L.gain));
      }
      // cannot brake in time, or outside the limit: the end nearer to 0
      for (int i = 0; i < nv_; ++i)
        if (row_[i] > hi2_[i])
          row_[i] = hi2_[i] = std::abs(row_[i]) < std::abs(hi2_[i]) ? row_[i] : hi2_[i];
    } else {
      // JointLimits._step, in the Python engine's operations: the longest step toward a
      // limit at distance D, max(K D, D - (1 - K) b) with the band b = band_rate dt (K D
      // outside, D < 0; fmax: the inf K D where inf - inf is NaN)
      const double K = L.gain, dt = dt_;
      auto step = [K, dt](double D, double band_rate) {
        return std::fmax(K * D, D - (1.0 - K) * (band_rate * dt));
      };
      if (L.indexed) {
        for (size_t i = 0; i < L.qi.size(); ++i) {
          const double qq = q[L.qi[i] * qs];
          row_[L.vi[i]] = -step(qq - L.lower[i], L.band_rate[i]) / dt;
          hi2_[L.vi[i]] = step(L.upper[i] - qq, L.band_rate[i]) / dt;
        }
      } else {
        for (int i = 0; i < nv_; ++i) {
          row_[i] = -step(q[i * qs] - L.lower[i], L.band_rate[i]) / dt;
          hi2_[i] = step(L.upper[i] - q[i * qs], L.band_rate[i]) / dt;
        }
      }
    }
    for (int i = 0; i < nv_; ++i) {
      if (first) {
        lo_[i] = row_[i];
        hi_[i] = hi2_[i];
      } else {
        lo_[i] = std::max(lo_[i], row_[i]);
        hi_[i] = std::min(hi_[i], hi2_[i]);
      }
    }
    first = false;
  }
  // boxes that do not meet: the end nearer to 0 wins
  for (int i = 0; i < nv_; ++i)
    if (lo_[i] > hi_[i]) lo_[i] = hi_[i] = std::abs(lo_[i]) < std::abs(hi_[i]) ? lo_[i] : hi_[i];
}

}  // namespace
}  // namespace qpcoord

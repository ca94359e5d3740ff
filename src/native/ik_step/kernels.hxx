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
        double bv = -gain * (f.p[a] - k.target[a]);
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
        double bv = -gain * (com_[a] - k.target[a]);
        if (k.has_vel) bv += k.vel[a];
        write_row(k, r, Jt_.row(0), bv);
      }
      return true;
    }
    case kPosture: {
      double* Aeq = out_[0].data() + static_cast<size_t>(k.row0) * nv_;
      double* beq = out_[1].data() + k.row0;
      for (int r = 0; r < rows; ++r) {
        const int j = k.sel[r], iq = k.qidx[r];
        const double s = k.sw[r];
        const double bv = gain * (k.target[iq] - q[iq * qs]);
        // the task's A (the selection) is constant: the stacked row is rewritten
        for (int c = 0; c < nv_; ++c) Aeq[r * nv_ + c] = 0.0;
        Aeq[r * nv_ + j] = k.A(r, j) * s;
        k.b[r] = bv;
        beq[r] = bv * s;
      }
      return true;
    }
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

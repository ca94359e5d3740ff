// qpcoord native engine: the IK step's band kernels of ComBand and SupportPolygon
// (qpcoord/kinematics/frame_tasks.py), term by term as their Python _refresh:
//
//   ComBand         C = J_com (3 x nv),  lower = K (lo - c),  upper = K (hi - c)  (m/s)
//   SupportPolygon  per edge i of the counter-clockwise hull of the contact points' ground
//                   projections: e_i = n_i^T (c_xy - a_i) (m), C_i = de_i/dq (the motion of
//                   the CoM and of the edge's two vertices), lower = -inf,
//                   upper = K (-margin - e_i); the rows after the hull's h edges are 0 with
//                   bounds (-inf, inf).
//
// The hull is frame_tasks._hull (Andrew's monotone chain, stable sort on (x, y), a point kept
// only for a strictly positive turn): the same comparisons on the same doubles give the same
// vertices, so the contact points are computed in the Python order (no fused multiply-add:
// the extension is built without -mfma / -march=native). Everything is sized when the kernel
// is added: nothing here allocates per step.
#pragma once

#include <Eigen/Dense>
#include <cmath>
#include <limits>
#include <vector>

namespace qpcoord {
namespace support {

using RowMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

/// Per-kernel data of a band kernel (the IK step keeps one per ComBand / SupportPolygon):
/// its parameters (set by the step's setters) and the SupportPolygon's workspace.
struct Band {
  Eigen::Vector3d lo = Eigen::Vector3d::Zero(), hi = Eigen::Vector3d::Zero();  ///< ComBand faces
  RowMat points;                ///< SupportPolygon: contact points (k, 3), frame coordinates
  double margin = 0.0;          ///< SupportPolygon: margin (m)
  std::vector<int> frames;      ///< SupportPolygon: the step's frame slot of each contact frame
  // SupportPolygon workspace (rows = frames x k points)
  Eigen::VectorXd x, y;         ///< ground projection of every contact point (m)
  RowMat Jx, Jy;                ///< their Jacobians (rows, nv), pin coordinates
  std::vector<int> order, lower_chain, upper_chain, hull;
  Eigen::VectorXd e, ub;        ///< signed distances of the hull's edges, upper bounds
  RowMat J;                     ///< the rows (rows, nv), pin coordinates
  int edges = 0;                ///< h, the hull's edges at the last step

  void size(int rows, int nv, int points_per_frame) {
    points.setZero(points_per_frame, 3);
    x.setZero(rows);
    y.setZero(rows);
    Jx.setZero(rows, nv);
    Jy.setZero(rows, nv);
    order.resize(rows);
    lower_chain.resize(rows);
    upper_chain.resize(rows);
    hull.resize(2 * rows);
    e.setZero(rows);
    ub.setZero(rows);
    J.setZero(rows, nv);
  }
};

/// Contact point r of a frame at world placement (R, p), offset o (frame coordinates), and
/// the frame's world-aligned Jacobian at its origin Jt (6 x nv: linear rows 0-2, angular
/// 3-5): its ground projection (x, y) and their Jacobians,
/// d(p + R o)/dq = J_v - [R o]x J_w (rows x and y), as SupportPolygon._contacts.
template <class M3, class V3, class JT>
inline void contact_point(const M3& R, const V3& p, double ox, double oy, double oz,
                          const JT& Jt, double& x, double& y, Eigen::Ref<Eigen::RowVectorXd> Jx,
                          Eigen::Ref<Eigen::RowVectorXd> Jy) {
  // world offset r = R o, summed in numpy's elementwise order ((ox R0 + oy R1) + oz R2)
  const double rx = (ox * R(0, 0) + oy * R(0, 1)) + oz * R(0, 2);
  const double ry = (ox * R(1, 0) + oy * R(1, 1)) + oz * R(1, 2);
  const double rz = (ox * R(2, 0) + oy * R(2, 1)) + oz * R(2, 2);
  x = p[0] + rx;
  y = p[1] + ry;
  const Eigen::Index nv = Jx.size();
  for (Eigen::Index c = 0; c < nv; ++c) {
    Jx[c] = Jt(0, c) - (ry * Jt(5, c) - rz * Jt(4, c));
    Jy[c] = Jt(1, c) - (rz * Jt(3, c) - rx * Jt(5, c));
  }
}

/// The counter-clockwise convex hull of the n points (x, y) into hull (indices; returns h),
/// exactly frame_tasks._hull: stable sort on (x, y), the lower then the upper monotone chain,
/// each without its last point; collinear points are dropped (a turn must be > 0).
/// order, lo, up: workspaces of n ints; hull: 2n ints.
inline int convex_hull(const double* x, const double* y, int n, int* order, int* lo, int* up,
                       int* hull) {
  // stable insertion sort on (x, y) (std::stable_sort would allocate its buffer; n is small)
  for (int i = 0; i < n; ++i) {
    int j = i;
    while (j > 0) {
      const int o = order[j - 1];
      if (!(x[i] < x[o] || (x[i] == x[o] && y[i] < y[o]))) break;
      order[j] = o;
      --j;
    }
    order[j] = i;
  }
  auto chain = [x, y](const int* idx, int m, int step, int* out) {
    int len = 0;
    for (int t = 0; t < m; ++t) {
      const int i = idx[step > 0 ? t : m - 1 - t];
      const double px = x[i], py = y[i];
      while (len >= 2) {
        const int o = out[len - 2], a = out[len - 1];
        const double ox = x[o], oy = y[o], ax = x[a], ay = y[a];
        if ((ax - ox) * (py - oy) - (ay - oy) * (px - ox) > 0) break;
        --len;
      }
      out[len++] = i;
    }
    return len;
  };
  const int nl = chain(order, n, 1, lo);
  const int nu = chain(order, n, -1, up);
  int h = 0;
  for (int i = 0; i + 1 < nl; ++i) hull[h++] = lo[i];
  for (int i = 0; i + 1 < nu; ++i) hull[h++] = up[i];
  return h;
}

/// SupportPolygon's rows from the contact points (b.x, b.y, b.Jx, b.Jy filled), the CoM c
/// (its x, y) and its Jacobian rows Jc0, Jc1 (nv): b.J (rows, nv), b.e and b.ub
/// (K (-margin - e) on the h live rows, inf after), b.edges = h. Returns h (< 3: collinear
/// contact points, no polygon: the caller lets Python raise the task's message).
template <class B, class R0, class R1>
inline int polygon_rows(B& b, double cx, double cy, const R0& Jc0, const R1& Jc1, double gain,
                        double margin) {
  const int n = static_cast<int>(b.x.size());
  const Eigen::Index nv = b.J.cols();
  const int h = convex_hull(b.x.data(), b.y.data(), n, b.order.data(), b.lower_chain.data(),
                            b.upper_chain.data(), b.hull.data());
  b.edges = h;
  if (h < 3) return h;
  for (int i = 0; i < h; ++i) {
    const int ia = b.hull[i], ib = b.hull[(i + 1) % h];
    const double ax = b.x[ia], ay = b.y[ia];
    const double tx = b.x[ib] - ax, ty = b.y[ib] - ay;
    const double L = std::hypot(tx, ty);
    const double ux = tx / L, uy = ty / L;
    const double nx = uy, ny = -ux;  // outward normal of a counter-clockwise hull
    const double dx = cx - ax, dy = cy - ay;
    const double ei = nx * dx + ny * dy;
    // de = n^T (dc - da) + s (u_x dt_y - u_y dt_x), s = u^T (c - a) / L
    const double s = (ux * dx + uy * dy) / L;
    for (Eigen::Index c = 0; c < nv; ++c) {
      const double dtx = b.Jx(ib, c) - b.Jx(ia, c), dty = b.Jy(ib, c) - b.Jy(ia, c);
      b.J(i, c) = (nx * (Jc0[c] - b.Jx(ia, c)) + ny * (Jc1[c] - b.Jy(ia, c))) +
                  s * (ux * dty - uy * dtx);
    }
    b.e[i] = ei;
    b.ub[i] = gain * (-margin - ei);
  }
  for (int i = h; i < n; ++i) {
    b.J.row(i).setZero();
    b.e[i] = 0.0;
    b.ub[i] = std::numeric_limits<double>::infinity();
  }
  return h;
}

}  // namespace support
}  // namespace qpcoord

// qpcoord._collision: the collision rows kernel (kernel.hpp) for Python.
//
// Shapes arrive as plain data (kind, dimensions, a convex hull's vertices and triangles) and
// are rebuilt as coal shapes here; the robot's joint placements and Jacobian arrive as numpy
// views of its pinocchio.Data, kept alive by the kernel. Built only where coal's C++ library
// (the libcoal wheel) is found; qpcoord/kinematics/collision.py uses the Python rows
// otherwise. COAL_VERSION tells which coal it was built against: a different coal at run
// time is not used (its ABI may differ). CollisionKernel.entry() hands the kernel to the native
// IK step (qpcoord._native) as a plain C entry point (rows_kernel.h): the step then computes
// the rows itself, with no Python between them.
#include <coal/config.hh>
#include <coal/shape/convex.h>
#include <coal/shape/geometric_shapes.h>
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include <cmath>
#include <memory>
#include <string>

#include "../rows_kernel.h"
#include "kernel.hpp"

namespace nb = nanobind;
using namespace qpcoord::collision;

namespace {

using F1 = nb::ndarray<const double, nb::numpy, nb::ndim<1>, nb::device::cpu>;
using F2 = nb::ndarray<const double, nb::numpy, nb::ndim<2>, nb::device::cpu>;
using Out1 = nb::ndarray<double, nb::numpy, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Out2 = nb::ndarray<double, nb::numpy, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using Flags = nb::ndarray<std::uint8_t, nb::numpy, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Tri = nb::ndarray<const std::int64_t, nb::numpy, nb::shape<-1, 3>, nb::c_contig,
                        nb::device::cpu>;

/// A column-major (Fortran-ordered) rows x cols view's memory.
const double* column_major(const F2& a, size_t rows, size_t cols, const char* what) {
  if (a.shape(0) != rows || a.shape(1) != cols || a.stride(0) != 1 ||
      a.stride(1) != static_cast<int64_t>(rows))
    throw nb::value_error((std::string(what) + ": a column-major view of shape (" +
                           std::to_string(rows) + ", " + std::to_string(cols) + ") expected")
                              .c_str());
  return a.data();
}

/// A contiguous 3-vector view's memory.
const double* contiguous3(const F1& a, const char* what) {
  if (a.shape(0) != 3 || a.stride(0) != 1)
    throw nb::value_error((std::string(what) + ": a contiguous 3-vector expected").c_str());
  return a.data();
}

Mat3 mat3(const F2& a) {
  if (a.shape(0) != 3 || a.shape(1) != 3)
    throw nb::value_error("rotation: shape (3, 3) expected");
  Mat3 R;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) R(i, j) = a(i, j);
  return R;
}

Vec3 vec3(const F1& a, const char* what) {
  if (a.shape(0) != 3)
    throw nb::value_error((std::string(what) + ": shape (3,) expected").c_str());
  return Vec3(a(0), a(1), a(2));
}

/// The coal shape of `kind` with `dims` (sphere: r; box: x, y, z sides; capsule, cylinder,
/// cone: r, length; ellipsoid: radii; halfspace: n, d; convex: vertices + triangles).
std::shared_ptr<coal::CollisionGeometry> shape(const std::string& kind, const F1& dims,
                                               const F2& vertices, const Tri& triangles) {
  auto d = [&](size_t i) {
    if (i >= dims.shape(0))
      throw nb::value_error(("dims: too few numbers for a " + kind).c_str());
    return dims(i);
  };
  if (kind == "sphere") return std::make_shared<coal::Sphere>(d(0));
  if (kind == "box") return std::make_shared<coal::Box>(d(0), d(1), d(2));
  if (kind == "capsule") return std::make_shared<coal::Capsule>(d(0), d(1));
  if (kind == "cylinder") return std::make_shared<coal::Cylinder>(d(0), d(1));
  if (kind == "cone") return std::make_shared<coal::Cone>(d(0), d(1));
  if (kind == "ellipsoid") return std::make_shared<coal::Ellipsoid>(d(0), d(1), d(2));
  if (kind == "halfspace") return std::make_shared<coal::Halfspace>(coal::Vec3s(d(0), d(1), d(2)), d(3));
  if (kind == "convex") {
    if (vertices.shape(1) != 3 || vertices.shape(0) < 4)
      throw nb::value_error("vertices: shape (n >= 4, 3) expected");
    const auto nvert = static_cast<unsigned int>(vertices.shape(0));
    auto pts = std::make_shared<std::vector<coal::Vec3s>>(nvert);
    for (unsigned int i = 0; i < nvert; ++i)
      (*pts)[i] = coal::Vec3s(vertices(i, 0), vertices(i, 1), vertices(i, 2));
    const auto ntri = static_cast<unsigned int>(triangles.shape(0));
    auto tris = std::make_shared<std::vector<coal::Triangle>>(ntri);
    for (unsigned int i = 0; i < ntri; ++i) {
      for (int j = 0; j < 3; ++j)
        if (triangles(i, j) < 0 || triangles(i, j) >= nvert)
          throw nb::value_error("triangles: a vertex index out of range");
      (*tris)[i] = coal::Triangle(static_cast<coal::Triangle::index_type>(triangles(i, 0)),
                                  static_cast<coal::Triangle::index_type>(triangles(i, 1)),
                                  static_cast<coal::Triangle::index_type>(triangles(i, 2)));
    }
    return std::make_shared<coal::Convex<coal::Triangle>>(pts, nvert, tris, ntri);
  }
  throw nb::value_error(("kind: unknown shape " + kind).c_str());
}

/// The kernel with the Python objects whose memory it reads kept alive.
struct PyKernel {
  std::vector<nb::object> keep;
  std::unique_ptr<Kernel> kernel;
  int joints = 0, nv = 0;
};

/// The pointer of CollisionKernel.entry()'s capsule: the C struct, then the Python kernel
/// object it keeps alive (ctx points into it).
struct Entry {
  qpcoord_rows_kernel c;
  PyObject* owner;
};

/// rows_kernel.h's update: one Kernel::update at the effective gain. Never throws (a coal
/// exception: -1, the step then asks Python, whose update raises it).
int entry_update(void* ctx, double gain, double dt) {
  auto* kernel = static_cast<Kernel*>(ctx);
  if (!(dt > 0.0) || std::isnan(gain)) return -1;
  try {
    return kernel->update(kernel->effective_gain(gain, dt));
  } catch (...) {
    return -1;
  }
}

void entry_release(void* p) noexcept {
  auto* e = static_cast<Entry*>(p);
  Py_XDECREF(e->owner);  // a capsule's destructor runs with the GIL held
  delete e;
}

}  // namespace

NB_MODULE(_collision, m) {
  m.doc() = "qpcoord's native collision rows (src/native/collision)";
  m.attr("COAL_VERSION") = COAL_VERSION;

  nb::class_<PyKernel>(m, "CollisionKernel")
      .def(
          "__init__",
          [](PyKernel* self, std::vector<F2> rotations, std::vector<F1> translations, F2 J,
             double min_distance, double influence_distance) {
            new (self) PyKernel();
            if (rotations.size() != translations.size() || rotations.empty())
              throw nb::value_error("rotations, translations: one per joint");
            RobotView view;
            view.nv = static_cast<int>(J.shape(1));
            view.J = column_major(J, 6, static_cast<size_t>(view.nv), "J");
            for (size_t j = 0; j < rotations.size(); ++j) {
              view.rotation.push_back(column_major(rotations[j], 3, 3, "rotations"));
              view.translation.push_back(contiguous3(translations[j], "translations"));
            }
            for (auto& a : rotations) self->keep.push_back(nb::cast(a));
            for (auto& a : translations) self->keep.push_back(nb::cast(a));
            self->keep.push_back(nb::cast(J));
            self->joints = static_cast<int>(rotations.size());
            self->nv = view.nv;
            self->kernel.reset(new Kernel(std::move(view), {min_distance, influence_distance}));
          },
          nb::arg("rotations"), nb::arg("translations"), nb::arg("J"),
          nb::arg("min_distance"), nb::arg("influence_distance"))
      .def(
          "add_geometry",
          [](PyKernel& self, const std::string& kind, F1 dims, F2 vertices, Tri triangles,
             int joint, F2 rotation, F1 translation, F1 centre, double radius,
             std::vector<int> columns) {
            Geometry g;
            g.shape = shape(kind, dims, vertices, triangles);
            g.shape->computeLocalAABB();
            g.joint = joint;
            g.R = mat3(rotation);
            g.p = vec3(translation, "translation");
            g.centre = vec3(centre, "centre");
            g.radius = radius;
            if (joint < 0 || joint >= self.joints) throw nb::value_error("joint: out of range");
            g.moves.assign(static_cast<size_t>(self.nv), 0);
            for (int c : columns) {
              if (c < 0 || c >= self.nv) throw nb::value_error("columns: out of range");
              g.moves[static_cast<size_t>(c)] = 1;
            }
            return self.kernel->add_geometry(std::move(g));
          },
          nb::arg("kind"), nb::arg("dims"), nb::arg("vertices"), nb::arg("triangles"),
          nb::arg("joint"), nb::arg("rotation"), nb::arg("translation"), nb::arg("centre"),
          nb::arg("radius"), nb::arg("columns"))
      .def("add_pair",
           [](PyKernel& self, int a, int b) {
             const int n = self.kernel->geometries();
             if (a < 0 || b < 0 || a >= n || b >= n || a == b)
               throw nb::value_error("add_pair: geometry indices out of range");
             self.kernel->add_pair(a, b);
           })
      .def("set_placement",
           [](PyKernel& self, int g, F2 rotation, F1 translation, F1 centre) {
             if (g < 0 || g >= self.kernel->geometries())
               throw nb::value_error("set_placement: geometry index out of range");
             Geometry& G = self.kernel->geometry(g);
             G.R = mat3(rotation);
             G.p = vec3(translation, "translation");
             G.centre = vec3(centre, "centre");
           })
      .def("bind",
           [](PyKernel& self, Out2 C, Out1 lower, Out1 distance, Flags active) {
             const size_t m = static_cast<size_t>(self.kernel->pairs());
             if (C.shape(0) != m || C.shape(1) != static_cast<size_t>(self.nv) ||
                 lower.shape(0) != m || distance.shape(0) != m || active.shape(0) != m)
               throw nb::value_error("bind: arrays of one row per pair expected");
             self.keep.push_back(nb::cast(C));
             self.keep.push_back(nb::cast(lower));
             self.keep.push_back(nb::cast(distance));
             self.keep.push_back(nb::cast(active));
             self.kernel->bind({C.data(), lower.data(), distance.data(), active.data()});
           })
      .def("update", [](PyKernel& self, double gain) { return self.kernel->update(gain); },
           nb::arg("gain"))
      .def(
          "entry",
          [](PyKernel& self) {
            const Output& out = self.kernel->output();
            if (!out.C) throw nb::value_error("entry: bind the output arrays first");
            auto e = std::make_unique<Entry>(Entry{
                {self.kernel.get(), &entry_update, out.C, out.lower, self.kernel->pairs(),
                 self.nv},
                nullptr});
            nb::capsule capsule(e.get(), QPCOORD_ROWS_KERNEL_CAPSULE, &entry_release);
            e.release()->owner = nb::find(&self).inc_ref().ptr();
            return capsule;
          },
          "The kernel as a C entry point for the native IK step: a capsule named "
          "QPCOORD_ROWS_KERNEL_CAPSULE holding a qpcoord_rows_kernel (src/native/"
          "rows_kernel.h) whose update(ctx, gain, dt) is update(min(gain, (d_i - d_s) / dt)) "
          "into the bound C and lower; it keeps this kernel alive.");
}

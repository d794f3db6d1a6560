// module.cpp - the C++ side of the `isotouch` Python package (_isotouch): the exceptions and
// the shared point conversions; each binding file registers its part.
#include <cmath>
#include <cstdint>
#include <cstring>
#include <sstream>

#include "isotouch/engine/volume.h"
#include "isotouch/io/record.h"
#include "isotouch/io/scene.h"
#include "isotouch/python/common.h"
#include "isotouch/session/live_session.h"
#include "isotouch/version.h"

namespace isotouch::python {

core::Vec3 vec3_arg(const py::handle& seq, const char* what) {
  const auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(seq);
  if (!a || a.size() != 3) throw py::value_error(std::string(what) + ": must be 3 numbers (x, y, z)");
  const double* d = a.data();
  for (int i = 0; i < 3; ++i)
    if (!std::isfinite(d[i])) {
      std::ostringstream s;
      s << what << "[" << i << "] is " << d[i] << ": must be finite";
      throw py::value_error(s.str());
    }
  return {d[0], d[1], d[2]};
}

/// The exponent bits of a double: all set for an infinity or a NaN.
constexpr std::uint64_t kExponent = 0x7ff0000000000000ull;

PointsIn points_in(const py::handle& in, const char* what, bool finite) {
  PointsIn pts;
  pts.keep = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(in);
  if (!pts.keep || pts.keep.ndim() != 2 || pts.keep.shape(1) != 3)
    throw py::value_error(std::string(what) + ": must be an (N, 3) array of points [m]");
  pts.p = pts.keep.data();
  pts.n = std::size_t(pts.keep.shape(0));
  if (!finite) return pts;
  // All finite? One pass over the exponent bits (branch-free, vectorised), then the row at fault.
  std::uint64_t nonfinite = 0;
  for (std::size_t i = 0; i < 3 * pts.n; ++i) {
    std::uint64_t bits;
    std::memcpy(&bits, pts.p + i, sizeof bits);
    nonfinite |= std::uint64_t((bits & kExponent) == kExponent);
  }
  if (nonfinite)
    for (std::size_t k = 0; k < pts.n; ++k)
      if (!std::isfinite(pts.p[3 * k]) || !std::isfinite(pts.p[3 * k + 1]) || !std::isfinite(pts.p[3 * k + 2]))
        throw py::value_error(std::string(what) + ": row " + std::to_string(k) + " is not finite");
  return pts;
}

std::vector<core::Vec3> points_arg(const py::handle& in, const char* what) {
  const PointsIn pts = points_in(in, what);
  std::vector<core::Vec3> p(pts.n);
  for (std::size_t k = 0; k < pts.n; ++k) p[k] = pts.at(k);
  return p;
}

py::array_t<double> points_array(const std::vector<core::Vec3>& p) {
  py::array_t<double> a({py::ssize_t(p.size()), py::ssize_t(3)});
  double* d = a.mutable_data();
  for (std::size_t k = 0; k < p.size(); ++k) {
    d[3 * k] = p[k].x;
    d[3 * k + 1] = p[k].y;
    d[3 * k + 2] = p[k].z;
  }
  return a;
}

}  // namespace isotouch::python

PYBIND11_MODULE(_isotouch, m) {
  namespace py = pybind11;
  using namespace isotouch;
  m.doc() = "isotouch: haptic rendering of isosurfaces in volumes (C++ core; use the isotouch package)";
  m.attr("__version__") = kVersion;
  // The library's errors, each with the message the command line prints (file, field, value).
  static py::exception<std::runtime_error> error(m, "Error", PyExc_RuntimeError);
  static py::exception<engine::VolumeError> volume_error(m, "VolumeError", error.ptr());
  static py::exception<io::SceneError> scene_error(m, "SceneError", error.ptr());
  static py::exception<io::RecordingError> recording_error(m, "RecordingError", error.ptr());
  // LiveSession.stop(): the servo thread was left stuck in the renderer (force off).
  static py::exception<session::ServoAbandoned> servo_abandoned(m, "ServoAbandoned", error.ptr());
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const engine::VolumeError& e) {
      volume_error(e.what());
    } catch (const io::SceneError& e) {
      scene_error(e.what());
    } catch (const io::RecordingError& e) {
      recording_error(e.what());
    } catch (const session::ServoAbandoned& e) {
      servo_abandoned(e.what());
    }
  });
  python::bind_volume(m);
  python::bind_render(m);
  python::bind_engine(m);
  python::bind_scene(m);
  python::bind_live(m);
}

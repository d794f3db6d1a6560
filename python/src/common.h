// common.h - what the Python module's binding files share: numpy conversions of points and
// the registration functions each file defines.
#pragma once
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <array>
#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include "isotouch/core/vec3.h"

namespace isotouch::engine {
struct Volume;
}

namespace isotouch::python {
namespace py = pybind11;

/// A length-3 sequence of finite numbers as a Vec3. @throws ValueError naming `what`.
core::Vec3 vec3_arg(const py::handle& seq, const char* what);

/// An (N, 3) float64 C-contiguous array of finite points (any array convertible to it: lists,
/// float32). @throws ValueError naming `what`, the shape or the first non-finite row.
std::vector<core::Vec3> points_arg(const py::handle& a, const char* what);

/// (N, 3) points read where they lie: the caller's float64 C-contiguous buffer (no copy), or
/// a converted copy that `keep` holds. With `finite`, checked finite like points_arg.
struct PointsIn {
  py::array_t<double> keep;
  const double* p = nullptr;
  std::size_t n = 0;
  core::Vec3 at(std::size_t k) const { return {p[3 * k], p[3 * k + 1], p[3 * k + 2]}; }
};
PointsIn points_in(const py::handle& a, const char* what, bool finite = true);

/// The names of volumes made in Python (run::kInMemoryPrefix: no file, never resolved against
/// the working folder): a numpy array's, and an isotouch.Volume's that has none.
inline constexpr const char* kNumpyVolumeName = "memory:numpy array";
inline constexpr const char* kInMemoryVolumeName = "memory:volume from Python";

/// A Volume from a numpy array (isotouch.Volume's constructor): axes 'zyx' or 'xyz', spacing
/// and origin in `unit` ("m" or "mm"), direction None or 3x3. @throws ValueError naming the
/// argument; warns isotouch.UnitsWarning where a value looks like the other unit.
std::shared_ptr<engine::Volume> volume_from_numpy(const py::array& array, const py::handle& spacing,
                                                  const py::handle& origin, const py::object& direction,
                                                  const std::string& axes, const std::string& unit);

/// Points as an (N, 3) float64 array.
py::array_t<double> points_array(const std::vector<core::Vec3>& p);

/// dims (nx, ny, nz), spacing [m] and origin [m] of a bound class with a core::Grid `grid`.
template <class Class>
Class& def_grid_properties(Class& c, const char* origin_doc) {
  using T = typename Class::type;
  c.def_property_readonly("dims", [](const T& x) {
    return py::make_tuple(x.grid.dims[0], x.grid.dims[1], x.grid.dims[2]);
  }, "(nx, ny, nz) voxels");
  c.def_property_readonly("spacing", [](const T& x) {
    return py::make_tuple(x.grid.spacing_m.x, x.grid.spacing_m.y, x.grid.spacing_m.z);
  }, "(sx, sy, sz) [m]");
  c.def_property_readonly("origin", [](const T& x) {
    return py::make_tuple(x.grid.origin_m.x, x.grid.origin_m.y, x.grid.origin_m.z);
  }, origin_doc);
  return c;
}

void bind_volume(py::module_& m);
void bind_render(py::module_& m);
void bind_engine(py::module_& m);
void bind_scene(py::module_& m);
void bind_live(py::module_& m);

}  // namespace isotouch::python

// volume_py.cpp - isotouch.Volume (engine::Volume) and isotouch.load_volume.
#include <cmath>
#include <memory>
#include <sstream>

#include "isotouch/engine/volume.h"
#include "isotouch/io/record.h"
#include "isotouch/io/vdb_io.h"
#include "isotouch/io/volume_io.h"
#include "isotouch/python/common.h"

namespace isotouch::python {
namespace {

/// isotouch.UnitsWarning: a spacing or origin that looks like the other unit (m vs mm).
PyObject* units_warning() {
  static PyObject* w = PyErr_NewExceptionWithDoc(
      "isotouch.UnitsWarning",
      "a spacing or origin that looks like millimetres given as metres, or the reverse", PyExc_UserWarning, nullptr);
  return w;
}

using VolumePtr = std::shared_ptr<engine::Volume>;

std::array<double, 3> finite3(const py::handle& seq, const char* what, bool positive, const std::string& unit) {
  const core::Vec3 v = vec3_arg(seq, what);
  const std::array<double, 3> a{v.x, v.y, v.z};
  for (int i = 0; i < 3; ++i)
    if (positive && !(a[i] > 0)) {
      std::ostringstream s;
      s << what << "[" << i << "] is " << a[i] << ": must be finite and > 0 [" << unit << "]";
      throw py::value_error(s.str());
    }
  return a;
}

std::array<double, 9> direction_arg(const py::object& d) {
  std::array<double, 9> out{1, 0, 0, 0, 1, 0, 0, 0, 1};
  if (d.is_none()) return out;
  const auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(d);
  if (!a || a.ndim() != 2 || a.shape(0) != 3 || a.shape(1) != 3)
    throw py::value_error("direction: must be a 3x3 matrix (column a: the physical direction of index axis a)");
  for (int i = 0; i < 9; ++i) out[std::size_t(i)] = a.data()[i];
  return out;
}

/// The array as (nz, ny, nx), x fastest in memory, whatever `axes` says it is indexed by:
/// 'zyx' (array[z, y, x], SimpleITK's order) as given, C-contiguous; 'xyz' (array[x, y, z],
/// nibabel's order) transposed, copied only when it is not F-contiguous. No stride check can
/// tell an (nx, ny, nz) array from an (nz, ny, nx) one: the caller says which.
py::array zyx_array(const py::array& array, const std::string& axes) {
  if (!array.dtype().is(py::dtype::of<float>()))
    throw py::value_error("array: dtype " + std::string(py::str(array.dtype())) +
                          ", must be float32 (convert with array.astype(numpy.float32))");
  if (array.ndim() != 3)
    throw py::value_error("array: " + std::to_string(array.ndim()) + " dimensions, must be 3 (axes='" + axes + "')");
  if (axes == "xyz")
    return py::module_::import("numpy").attr("ascontiguousarray")(array.attr("transpose")());
  if (axes != "zyx")
    throw py::value_error("axes: '" + axes + "', must be 'zyx' (array[z, y, x], SimpleITK's order) or 'xyz' "
                          "(array[x, y, z], nibabel's order)");
  if (!(array.flags() & py::array::c_style))
    throw py::value_error("array: not C-contiguous (x fastest); an array indexed [x, y, z] (nibabel's "
                          "get_fdata()) takes axes='xyz', an (nz, ny, nx) one numpy.ascontiguousarray(array)");
  return array;
}

/// A Python warning of `category` (raises when warnings are errors).
void warn(PyObject* category, const std::string& text) {
  if (PyErr_WarnEx(category, text.c_str(), 1) != 0) throw py::error_already_set();
}

std::string triple(const std::array<double, 3>& a) {
  std::ostringstream s;
  s << "(" << a[0] << ", " << a[1] << ", " << a[2] << ")";
  return s.str();
}

/// Warns (UnitsWarning) where spacing or origin, given in `unit` ("m" or "mm"), look like the
/// other unit: in metres a voxel over 50 mm or an origin over 2 m from the scanner's centre
/// (millimetres given as metres); in millimetres every voxel under 10 um (metres given as mm).
void warn_units(const std::array<double, 3>& sp, const std::array<double, 3>& org, const std::string& unit) {
  const auto any = [](const std::array<double, 3>& a, auto f) { return f(a[0]) || f(a[1]) || f(a[2]); };
  if (unit == "m") {
    if (any(sp, [](double x) { return x > 0.05; }))
      warn(units_warning(), "spacing " + triple(sp) + " m: a voxel over 50 mm looks like millimetres given as "
                            "metres; Volume.from_mm(array, spacing_mm, origin_mm) takes millimetres");
    if (any(org, [](double x) { return std::abs(x) > 2.0; }))
      warn(units_warning(), "origin " + triple(org) + " m: over 2 m from the scanner's centre looks like "
                            "millimetres given as metres; Volume.from_mm(array, spacing_mm, origin_mm) takes millimetres");
  } else if (sp[0] < 0.01 && sp[1] < 0.01 && sp[2] < 0.01) {
    warn(units_warning(), "spacing_mm " + triple(sp) + " mm: voxels under 10 um look like metres given as "
                          "millimetres; Volume(array, spacing, origin) takes metres");
  }
}

std::array<double, 3> scaled(std::array<double, 3> a, double k) {
  for (double& x : a) x *= k;
  return a;
}


/// The voxels as an (nz, ny, nx) float32 view; `owner` keeps the volume alive.
py::array voxel_view(engine::Volume& v, py::handle owner) {
  const auto& d = v.grid.dims;
  const py::ssize_t f = sizeof(float);
  return py::array_t<float>({py::ssize_t(d[2]), py::ssize_t(d[1]), py::ssize_t(d[0])},
                            {f * d[1] * d[0], f * d[0], f}, v.voxels.data(), owner);
}

py::array_t<double> map_points(const py::handle& pts, core::Vec3 (*f)(const engine::Volume&, const core::Vec3&),
                               const engine::Volume& v) {
  std::vector<core::Vec3> p = points_arg(pts, "points");
  for (core::Vec3& x : p) x = f(v, x);
  return points_array(p);
}

}  // namespace

/// Checks the array, spacing, origin and direction like a file's header, then copies the voxels.
/// spacing and origin in `unit` ("m" or "mm").
VolumePtr volume_from_numpy(const py::array& given, const py::handle& spacing, const py::handle& origin,
                            const py::object& direction, const std::string& axes, const std::string& unit) {
  const py::array array = zyx_array(given, axes);
  auto v = std::make_shared<engine::Volume>();
  const std::array<double, 3> sp_in = finite3(spacing, unit == "m" ? "spacing" : "spacing_mm", true, unit);
  const std::array<double, 3> org_in = finite3(origin, unit == "m" ? "origin" : "origin_mm", false, unit);
  warn_units(sp_in, org_in, unit);
  const double to_m = unit == "m" ? 1.0 : 1e-3;
  const std::array<double, 3> sp = scaled(sp_in, to_m), org = scaled(org_in, to_m);
  v->grid.dims = {int(array.shape(2)), int(array.shape(1)), int(array.shape(0))};
  v->grid.spacing_m = {sp[0], sp[1], sp[2]};
  v->grid.origin_m = {org[0], org[1], org[2]};
  v->direction = direction_arg(direction);
  v->path = kNumpyVolumeName;  // no file: named in scenes and errors as in memory
  v->reader = "numpy";
  v->component_type = "float";
  try {  // the limits every file meets (dims, extent, origin, memory; direction orthonormal)
    const std::array<std::uint64_t, 3> dims{std::uint64_t(array.shape(2)), std::uint64_t(array.shape(1)),
                                            std::uint64_t(array.shape(0))};
    io::check_volume_limits("numpy array", dims, {sp[0] * 1e3, sp[1] * 1e3, sp[2] * 1e3},
                            {org[0] * 1e3, org[1] * 1e3, org[2] * 1e3}, 4, "float", {"shape", "spacing", "origin", ""});
    io::check_direction("numpy array", v->direction, "direction");
  } catch (const engine::VolumeError& e) {
    throw py::value_error(e.what());
  }
  v->direction_is_identity = v->direction == std::array<double, 9>{1, 0, 0, 0, 1, 0, 0, 0, 1};
  const float* src = static_cast<const float*>(array.data());
  v->voxels.assign(src, src + v->grid.voxel_count());
  v->update_stats();
  return v;
}

void bind_volume(py::module_& m) {
  py::class_<engine::Volume, VolumePtr> volume(m, "Volume", R"(A scalar volume on a regular grid (float voxels, x fastest).

Volume(array, spacing, origin=(0, 0, 0), direction=None, axes='zyx'): from a float32 numpy
array (copied once): axes='zyx' an (nz, ny, nx) C-contiguous array indexed [z, y, x]
(SimpleITK's order, x fastest); axes='xyz' an (nx, ny, nz) array indexed [x, y, z] (nibabel's
order; F-ordered, any other order copied). The two orders give the same volume; an array given
in the other order than `axes` says has its axes swapped (no check can see that: say which).
spacing (sx, sy, sz) [m], finite and > 0; origin
(x, y, z) [m], the physical position of voxel (0, 0, 0); direction 3x3, column a the physical
unit direction of index axis a (identity if None). A bad array, spacing, origin or direction
raises ValueError naming it. Volume.from_mm takes spacing and origin in millimetres (the
imaging convention); a metre value that looks like millimetres (a voxel over 50 mm, an origin
over 2 m) raises isotouch.UnitsWarning.

Frames: index (x, y, z) continuous voxel coordinates; grid-world [m] = origin + spacing *
index (what renderers and strokes use); physical [m] = origin + D (spacing * index).)");
  def_grid_properties(volume, "(x, y, z) of voxel (0, 0, 0) [m], physical and grid-world")
      .def(py::init([](const py::array& a, const py::handle& sp, const py::handle& org, const py::object& dir,
                       const std::string& axes) { return volume_from_numpy(a, sp, org, dir, axes, "m"); }),
           py::arg("array"), py::arg("spacing"),
           py::arg("origin") = py::make_tuple(0.0, 0.0, 0.0), py::arg("direction") = py::none(),
           py::arg("axes") = "zyx")
      .def_static("from_mm", [](const py::array& a, const py::handle& sp, const py::handle& org, const py::object& dir,
                                const std::string& axes) { return volume_from_numpy(a, sp, org, dir, axes, "mm"); },
                  py::arg("array"), py::arg("spacing_mm"), py::arg("origin_mm") = py::make_tuple(0.0, 0.0, 0.0),
                  py::arg("direction") = py::none(), py::arg("axes") = "zyx",
                  "Volume(...) with spacing and origin in millimetres, as SimpleITK, nibabel and 3D Slicer give "
                  "them (UnitsWarning where every voxel is under 10 um: metres given as mm)")
      .def_property_readonly("spacing_mm", [](const engine::Volume& v) {
        return py::make_tuple(v.grid.spacing_m.x * 1e3, v.grid.spacing_m.y * 1e3, v.grid.spacing_m.z * 1e3);
      }, "(sx, sy, sz) [mm]")
      .def_property_readonly("origin_mm", [](const engine::Volume& v) {
        return py::make_tuple(v.grid.origin_m.x * 1e3, v.grid.origin_m.y * 1e3, v.grid.origin_m.z * 1e3);
      }, "(x, y, z) of voxel (0, 0, 0) [mm]")
      .def_property_readonly(
          "array", [](py::object self) { return voxel_view(self.cast<engine::Volume&>(), self); },
          "The voxels without a copy: (nz, ny, nx) float32, C-contiguous, x fastest, in the file's "
          "units. Writes go into the volume (call update_stats() after).")
      .def_property_readonly("shape", [](const engine::Volume& v) {
        return py::make_tuple(v.grid.dims[2], v.grid.dims[1], v.grid.dims[0]);
      }, "(nz, ny, nx)")
      .def_property_readonly("direction", [](const engine::Volume& v) {
        py::array_t<double> d({3, 3});
        std::copy(v.direction.begin(), v.direction.end(), d.mutable_data());
        return d;
      }, "3x3 direction matrix D (row-major; column a: physical direction of index axis a)")
      .def_readonly("path", &engine::Volume::path)
      .def_readonly("reader", &engine::Volume::reader)
      .def_readonly("component_type", &engine::Volume::component_type, "the on-disk voxel type")
      .def_readonly("min_value", &engine::Volume::min_value)
      .def_readonly("max_value", &engine::Volume::max_value)
      .def_property_readonly("orientation", &engine::Volume::orientation, "three-letter code, e.g. 'LPS'")
      .def("update_stats", &engine::Volume::update_stats, "recompute min/max after writing through .array")
      .def("crc32", [](const engine::Volume& v) { return io::volume_crc32(v); },
           "CRC-32 of dims, spacing, origin, direction and voxels (what a recording checks)")
      .def("to_physical", [](const engine::Volume& v, const py::handle& p) {
        return map_points(p, [](const engine::Volume& vv, const core::Vec3& x) { return vv.to_physical(x); }, v);
      }, py::arg("points"), "(N, 3) grid-world [m] -> physical [m]")
      .def("to_grid", [](const engine::Volume& v, const py::handle& p) {
        return map_points(p, [](const engine::Volume& vv, const core::Vec3& x) { return vv.to_grid(x); }, v);
      }, py::arg("points"), "(N, 3) physical [m] -> grid-world [m]")
      .def("index_to_world", [](const engine::Volume& v, const py::handle& p) {
        return map_points(p, [](const engine::Volume& vv, const core::Vec3& x) { return vv.grid.to_world(x); }, v);
      }, py::arg("points"), "(N, 3) continuous index (x, y, z) -> grid-world [m]")
      .def("save", [](const engine::Volume& v, const std::string& path) {
        py::gil_scoped_release nogil;
        io::save_any_volume(v, path);
      }, py::arg("path"), "write .mhd/.nrrd/.nii(.gz)/.vdb (atomic replace)")
      .def("__repr__", [](const engine::Volume& v) {
        std::ostringstream s;
        s << "<isotouch.Volume " << v.grid.dims[0] << "x" << v.grid.dims[1] << "x" << v.grid.dims[2] << " spacing ("
          << v.grid.spacing_m.x << ", " << v.grid.spacing_m.y << ", " << v.grid.spacing_m.z << ") m from " << v.path
          << ">";
        return s.str();
      });

  m.attr("UnitsWarning") = py::reinterpret_borrow<py::object>(units_warning());
  m.def("load_volume", [](const std::string& path) {
    py::gil_scoped_release nogil;
    return std::make_shared<engine::Volume>(io::load_any_volume(path));
  }, py::arg("path"), R"(Load a volume as `isotouch run` does: MetaImage (.mhd/.mha), NRRD
(.nrrd/.nhdr), NIfTI (.nii/.nii.gz), a DICOM series folder or OpenVDB (.vdb). Spacing and
origin in metres. Raises VolumeError with the CLI's message (file, field, value).)");
}

}  // namespace isotouch::python

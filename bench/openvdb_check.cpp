// openvdb_check.cpp - OpenVDB's central-difference gradient, an independent reference for
// the gradient pass (`isotouch check --all`). The only translation unit that includes
// OpenVDB (built with ISOTOUCH_HAVE_OPENVDB when find_package(OpenVDB) succeeds).
#include <chrono>

#include "isotouch/bench/pass_check.h"

#ifdef ISOTOUCH_HAVE_OPENVDB
#include <openvdb/math/Maps.h>
#include <openvdb/math/Operators.h>
#include <openvdb/openvdb.h>
#endif

namespace isotouch::bench {

OpenVdbGradient openvdb_gradient(const engine::Volume& vol) {
  OpenVdbGradient r;
#ifdef ISOTOUCH_HAVE_OPENVDB
  const auto t0 = std::chrono::steady_clock::now();
  openvdb::initialize();
  r.available = true;
  r.version = openvdb::getLibraryVersionString();
  const auto& g = vol.grid;
  const auto& d = g.dims;
  // Every voxel is set (active), so no value comes from the background: interior voxels
  // read only real neighbours.
  openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(0.0f);
  {
    auto acc = grid->getAccessor();
    for (int z = 0; z < d[2]; ++z)
      for (int y = 0; y < d[1]; ++y)
        for (int x = 0; x < d[0]; ++x) acc.setValue(openvdb::Coord(x, y, z), vol.voxels[g.index(x, y, z)]);
  }
  // World units = the spacing in metres per axis: the gradient comes out in value/m.
  const openvdb::math::ScaleMap map(openvdb::Vec3d(g.spacing_m.x, g.spacing_m.y, g.spacing_m.z));
  const auto acc = grid->getConstAccessor();
  for (int z = 1; z + 1 < d[2]; ++z)
    for (int y = 1; y + 1 < d[1]; ++y)
      for (int x = 1; x + 1 < d[0]; ++x) {
        const openvdb::Vec3s v =
            openvdb::math::Gradient<openvdb::math::ScaleMap, openvdb::math::CD_2ND>::result(
                map, acc, openvdb::Coord(x, y, z));
        r.g.insert(r.g.end(), {v[0], v[1], v[2]});
        r.voxel.push_back(g.index(x, y, z));
      }
  r.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
#else
  (void)vol;
#endif
  return r;
}

}  // namespace isotouch::bench

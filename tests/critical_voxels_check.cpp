// critical_voxels_check SCENE SAVED: compares a saved (sculpted) volume with the scene's volume
// as loaded, voxel by voxel, over the scene's labels. Prints one line:
//   critical_changed N next_to_critical_changed M changed K
// N: critical voxels whose value differs; M: non-critical voxels with a critical face
// neighbour whose value differs (the brush reached the structure); K: all that differ.
// With SEG (the edited label map saved beside it, a .seg.nrrd), also reads SEG's segments by
// the scene's material names (materials::load_label_volume) and compares each voxel's label
// with the scene's label map, a voxel inside the scene's isosurface before and not in SAVED
// expected 0 (removed); appends:
//   labels_removed R labels_wrong W
// R: voxels of a material expected 0; W: voxels whose label in SEG is not the expected one.
// Exit 1 if the files cannot be read or the grids differ.
#include <cstdio>
#include <cstring>
#include <exception>

#include "isotouch/io/scene.h"
#include "isotouch/io/volume_io.h"
#include "isotouch/materials/label_volume.h"
#include "isotouch/run/picture.h"

int main(int argc, char** argv) {
  if (argc != 3 && argc != 4) {
    std::fprintf(stderr, "usage: critical_voxels_check SCENE SAVED [SEG]\n");
    return 2;
  }
  try {
    using namespace isotouch;
    const io::Scene scene = io::load_scene(argv[1]);
    const engine::Volume before = run::load_scene_volume(scene);
    const engine::Volume after = io::load_volume(argv[2]);
    const materials::LabelVolume lv = materials::load_label_volume(scene.materials, before);
    if (after.grid.dims != before.grid.dims) {
      std::fprintf(stderr, "%s: dims differ from the scene's volume\n", argv[2]);
      return 1;
    }
    auto critical = [&](int x, int y, int z) {
      const std::uint8_t id = lv.at(x, y, z);
      return id != 0 && lv.materials[id - 1u].critical;
    };
    const auto& d = before.grid.dims;
    long crit = 0, next = 0, changed = 0;
    for (int z = 0; z < d[2]; ++z)
      for (int y = 0; y < d[1]; ++y)
        for (int x = 0; x < d[0]; ++x) {
          const std::size_t i = before.grid.index(x, y, z);
          if (std::memcmp(&before.voxels[i], &after.voxels[i], sizeof(float)) == 0) continue;
          ++changed;
          if (critical(x, y, z)) {
            ++crit;
            continue;
          }
          const int n[6][3] = {{x - 1, y, z}, {x + 1, y, z}, {x, y - 1, z}, {x, y + 1, z}, {x, y, z - 1}, {x, y, z + 1}};
          for (const auto& q : n)
            if (q[0] >= 0 && q[1] >= 0 && q[2] >= 0 && q[0] < d[0] && q[1] < d[1] && q[2] < d[2] && critical(q[0], q[1], q[2])) {
              ++next;
              break;
            }
        }
    std::printf("critical_changed %ld next_to_critical_changed %ld changed %ld", crit, next, changed);
    if (argc == 4) {
      materials::MaterialsSpec spec;
      spec.present = true;
      spec.labels_path = argv[3];
      for (const materials::Material& m : scene.materials.list) {
        materials::Material by_name;
        by_name.name = m.name;
        spec.list.push_back(by_name);
      }
      const materials::LabelVolume seg = materials::load_label_volume(spec, before);
      const core::Isosurface iso{scene.hri.tau, scene.hri.inside};
      long removed = 0, wrong = 0;
      for (std::size_t i = 0; i < lv.ids.size(); ++i) {
        const bool gone = iso.contains(before.voxels[i]) && !iso.contains(after.voxels[i]);
        const std::uint8_t want = gone ? 0 : lv.ids[i];
        removed += gone && lv.ids[i] != 0 ? 1 : 0;
        wrong += seg.ids[i] != want ? 1 : 0;
      }
      std::printf(" labels_removed %ld labels_wrong %ld", removed, wrong);
    }
    std::printf("\n");
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "critical_voxels_check: %s\n", e.what());
    return 1;
  }
}

// bench_material_fetch - what a material label costs the servo tick and the snapshot, the
// two ways it could reach the servo (docs/architecture.md, "How a material reaches the
// servo"), measured side by side with today's tick on bench table1's strokes (a
// micro-benchmark, not a test):
//   channel  one label byte per stored sample in the bricked snapshot, read through the
//            value's own brick table entry (same slot, a parallel byte pool; uniform bricks
//            a tile label);
//   field    a second bricked field of labels with its own brick table (its active bricks
//            are those where the label changes, whatever the isovalue does).
// Per tick: today's HRI tick, then the label at the VHIP (the nearest voxel: the material
// the proxy touches) read each way. Labels: three classes from the scan's own values,
// outside (not inside tau), inside below the median of the inside values, inside above it
// (a material boundary inside the object, as bone under soft tissue).
// Bytes: per brick, and for the whole snapshot of each scene.
// Options: kUsage below (--help).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <string>
#include <vector>

#include "isotouch/core/brick_field.h"
#include "isotouch/core/field_view.h"
#include "isotouch/eval/sweep.h"
#include "isotouch/servo/hri.h"

using namespace isotouch;

namespace {

const char* kUsage =
    "Usage: bench_material_fetch [SCENE...] [--reps N]\n"
    "  SCENE: sphere, knot, head, chest (default: head, chest)\n"
    "  --reps N   alternated rounds (median; default 21)\n";

/// Labels of a bricked layout: a table (one entry per brick), a byte pool (729 per slot)
/// and a tile label per uniform brick; entries as BrickStore's (slot * 729 | kUniform | tile).
struct LabelBricks {
  const std::uint32_t* table = nullptr;
  std::vector<std::uint32_t> own_table;  ///< the second field's table (empty: the value's)
  std::vector<std::uint8_t> pool, tiles;
  std::array<int, 3> dims{};
  std::size_t nbx = 0, nbxy = 0;

  /// The label of the voxel nearest `idx` (index frame), clamped to the grid.
  std::uint8_t at(const core::Vec3& idx) const {
    int v[3];
    for (int a = 0; a < 3; ++a) v[a] = std::clamp(int(std::lround(idx[a])), 0, dims[std::size_t(a)] - 1);
    const std::uint32_t e = table[std::size_t(v[2] >> 3) * nbxy + std::size_t(v[1] >> 3) * nbx + std::size_t(v[0] >> 3)];
    if (e & core::BrickStore::kUniform) return tiles[e & ~core::BrickStore::kUniform];
    return pool[e + std::uint32_t((v[0] & 7) + 9 * (v[1] & 7) + 81 * (v[2] & 7))];
  }
};

/// Fills a brick's 9^3 labels (beyond the grid: 0) from the dense labels; true if they differ.
bool brick_labels(const core::Grid& g, std::size_t id, const std::vector<std::uint8_t>& dense, std::uint8_t* out) {
  const auto b = core::brick_coords(id, core::brick_counts(g));
  bool mixed = false;
  for (int k = 0; k < 9; ++k)
    for (int j = 0; j < 9; ++j)
      for (int i = 0; i < 9; ++i) {
        const int x = 8 * b[0] + i, y = 8 * b[1] + j, z = 8 * b[2] + k;
        const bool in = x < g.dims[0] && y < g.dims[1] && z < g.dims[2];
        const std::uint8_t l =
            in ? dense[(std::size_t(z) * std::size_t(g.dims[1]) + std::size_t(y)) * std::size_t(g.dims[0]) + std::size_t(x)]
               : out[0];
        out[i + 9 * j + 81 * k] = l;
        mixed |= l != out[0];
      }
  return mixed;
}

/// The channel: labels for the value store's slots and tiles, through its table. Bricks
/// uniform in value but mixed in label are counted in `promoted` (the channel would have to
/// store them as active bricks; here their tile label is the brick's first voxel's).
LabelBricks channel_labels(const core::SampleField& f, const std::vector<std::uint8_t>& dense, std::size_t& promoted) {
  const core::BrickStore& s = *f.bricks;
  LabelBricks lb;
  lb.table = s.table.data();
  lb.dims = f.grid.dims;
  lb.nbx = std::size_t(s.bricks[0]);
  lb.nbxy = lb.nbx * std::size_t(s.bricks[1]);
  lb.pool.assign((s.table.size() - s.tiles.size()) * core::kBrickSamples, 0);
  lb.tiles.assign(s.tiles.size(), 0);
  promoted = 0;
  std::uint8_t tmp[core::kBrickSamples];
  for (std::size_t id = 0; id < s.table.size(); ++id) {
    const std::uint32_t e = s.table[id];
    const bool mixed = brick_labels(f.grid, id, dense, tmp);
    if (e & core::BrickStore::kUniform) {
      lb.tiles[e & ~core::BrickStore::kUniform] = tmp[0];
      promoted += mixed;
    } else {
      std::memcpy(&lb.pool[e], tmp, sizeof tmp);
    }
  }
  return lb;
}

/// The second field: its own table; active where the labels differ within the 9^3 brick.
LabelBricks field_labels(const core::Grid& g, const std::vector<std::uint8_t>& dense) {
  LabelBricks lb;
  const auto nb = core::brick_counts(g);
  lb.dims = g.dims;
  lb.nbx = std::size_t(nb[0]);
  lb.nbxy = lb.nbx * std::size_t(nb[1]);
  lb.own_table.resize(lb.nbxy * std::size_t(nb[2]));
  std::uint8_t tmp[core::kBrickSamples];
  for (std::size_t id = 0; id < lb.own_table.size(); ++id) {
    if (brick_labels(g, id, dense, tmp)) {
      lb.own_table[id] = std::uint32_t(lb.pool.size());
      lb.pool.insert(lb.pool.end(), tmp, tmp + core::kBrickSamples);
    } else {
      lb.own_table[id] = core::BrickStore::kUniform | std::uint32_t(lb.tiles.size());
      lb.tiles.push_back(tmp[0]);
    }
  }
  lb.table = lb.own_table.data();
  return lb;
}

/// Today's renderer, then the label at the VHIP read from `labels` (null: none read).
class Labelled final : public servo::Renderer {
 public:
  Labelled(servo::HriRenderer& hri, const LabelBricks* labels) : hri_(hri), labels_(labels) {}
  const char* name() const override { return "HRI+label"; }
  void reset() override { hri_.reset(); }
  servo::HriTick tick(const core::FieldView& f, const core::Vec3& hip, double dt) override {
    servo::HriTick t = hri_.tick(f, hip, dt);
    if (labels_) sum_ += labels_->at(f.grid().to_index(t.vhip_m));
    return t;
  }
  std::uint64_t sum() const { return sum_; }

 private:
  servo::HriRenderer& hri_;
  const LabelBricks* labels_;
  std::uint64_t sum_ = 0;
};

/// Three classes from the values: 0 outside, 1 inside below the inside median, 2 above.
std::vector<std::uint8_t> three_classes(const std::vector<float>& v, const core::Isosurface& iso) {
  std::vector<float> in;
  for (float x : v)
    if (iso.contains(x)) in.push_back(x);
  float mid = 0;
  if (!in.empty()) {
    std::nth_element(in.begin(), in.begin() + std::ptrdiff_t(in.size() / 2), in.end());
    mid = in[in.size() / 2];
  }
  std::vector<std::uint8_t> out(v.size());
  for (std::size_t i = 0; i < v.size(); ++i)
    out[i] = !iso.contains(v[i]) ? 0 : (iso.excess(v[i]) < iso.excess(mid) ? 1 : 2);
  return out;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

void run_scene(const std::string& name, int reps) {
  std::ostringstream quiet;
  const eval::SweepScene s = eval::prepare_sweep_scene(name, nullptr, quiet);
  if (s.field->bricks) throw std::runtime_error(name + ": the sweep's field is bricked; the bench needs its dense values");
  const core::Isosurface iso{s.tau, s.inside};
  std::vector<float> values(s.field->samples.size());
  for (std::size_t i = 0; i < values.size(); ++i) values[i] = s.field->samples[i].value;
  const std::vector<std::uint8_t> dense = three_classes(values, iso);
  const core::SampleField bricked = core::make_bricked_field(core::bricked_input_from_dense(*s.field, iso),
                                                             core::SampleFormat::kFp32);
  std::size_t promoted = 0;
  const LabelBricks channel = channel_labels(bricked, dense, promoted);
  const LabelBricks second = field_labels(bricked.grid, dense);

  servo::HriParams hp = eval::reference_params(s);
  hp.plane_update_period = 5;
  hp.intersection = servo::Intersection::kLinear;
  hp.normal = servo::NormalSource::kCentral;
  servo::HriRenderer hri(hp);
  Labelled none(hri, nullptr), via_channel(hri, &channel), via_field(hri, &second);
  std::vector<double> t0, t1, t2;
  for (int r = 0; r < reps; ++r) {  // alternated rounds: drift and frequency changes hit all three
    t0.push_back(eval::median_ns_per_tick(none, s, bricked, r == 0 ? 2 : 0, 1));
    t1.push_back(eval::median_ns_per_tick(via_channel, s, bricked, r == 0 ? 2 : 0, 1));
    t2.push_back(eval::median_ns_per_tick(via_field, s, bricked, r == 0 ? 2 : 0, 1));
  }
  const double a = median(t0), b = median(t1), c = median(t2);
  std::printf("%-6s %5zu ticks: HRI today %6.1f ns | + label, channel %6.1f ns (x%.3f) | + label, second field "
              "%6.1f ns (x%.3f)   [label sums %llu %llu]\n",
              s.name.c_str(), s.hip.size(), a, b, b / a, c, c / a, (unsigned long long)via_channel.sum(),
              (unsigned long long)via_field.sum());

  const core::BrickStore& st = *bricked.bricks;
  const std::size_t bricks = st.table.size(), active = bricks - st.tiles.size(), label_active = second.pool.size() / 729;
  const double today = double(core::snapshot_bytes(bricked));
  // Channel: +1 B per stored sample, +1 B per tile; value-uniform bricks with mixed labels
  // become active (729 x 16 B + 729 B) for per-voxel labels.
  const double ch = today + double(active) * 729 + double(st.tiles.size()) + double(promoted) * (729 * 17 - 16 - 1);
  // Second field: its own table (4 B per brick), 729 B per label-mixed brick, 1 B per tile.
  const double sf = today + 4.0 * double(bricks) + double(label_active) * 729 + double(second.tiles.size());
  std::printf("%-6s bricks %zu: iso-active %zu, label-mixed %zu (of which value-uniform %zu); snapshot today %.2f MB, "
              "with a label channel %.2f MB (x%.3f), with a second label field %.2f MB (x%.3f)\n",
              s.name.c_str(), bricks, active, label_active, promoted, today / 1e6, ch / 1e6, ch / today, sf / 1e6,
              sf / today);
}

}  // namespace

int main(int argc, char** argv) try {
  std::vector<std::string> scenes;
  int reps = 21;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--reps") && i + 1 < argc) {
      reps = std::atoi(argv[++i]);
      if (reps < 1 || reps > 10000) {
        std::fprintf(stderr, "bench_material_fetch: --reps needs a count from 1 to 10000, got '%s'\n%s", argv[i], kUsage);
        return 2;
      }
    } else if (!std::strcmp(argv[i], "--help") || !std::strcmp(argv[i], "-h")) {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (argv[i][0] == '-') {
      std::fprintf(stderr, "bench_material_fetch: unknown option, or a missing value: %s\n%s", argv[i], kUsage);
      return 2;
    } else {
      scenes.push_back(argv[i]);
    }
  }
  if (scenes.empty()) scenes = {"head", "chest"};
  std::printf("bytes per active brick: fp32 samples %d B, compact %d B; a label byte per sample adds %d B (+%.2f %% "
              "fp32, +%.2f %% compact); a uniform brick's tile 16 B + 1 B\n",
              729 * 16, 729 * 8, 729, 100.0 / 16, 100.0 / 8);
  for (const std::string& n : scenes) run_scene(n, reps);
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "bench_material_fetch: %s\n", e.what());
  return 1;
}

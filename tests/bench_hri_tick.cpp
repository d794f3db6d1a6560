// bench_hri_tick - HRI's tick against Avila and Sobierajski's on bench table1's strokes, one
// renderer at a time (a micro-benchmark, not a test): the table1 configuration (n = 5, linear
// p, central-difference N), alternated rounds, median ns per tick, and the stroke's mix of
// ticks (free, contact, plane updates, free ticks that read no sample), and the harness's own
// cost per tick (a renderer that reads nothing: the FieldView made per tick and the virtual
// call, paid by both).
// With --by-kind: HRI's ticks timed one by one (rdtsc, the null renderer's cycles
// subtracted; latency, not throughput), mean cycles per kind of tick: free, contact with
// no update, plane update, and Avila's tick on the same HIPs (a pass of its own: ticks of
// the two interleaved one by one shared the branch predictor and L1 and each paid for the other).
// Options: kUsage below (--help).
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <x86intrin.h>

#include "isotouch/servo/baselines.h"
#include "isotouch/servo/hri.h"
#include "isotouch/eval/sweep.h"
#include "isotouch/engine/vk_context.h"

using namespace isotouch;

namespace {
/// The harness's own cost: a renderer that reads nothing and returns zero force.
class NullRenderer final : public servo::Renderer {
 public:
  const char* name() const override { return "null"; }
  void reset() override {}
  servo::HriTick tick(const core::FieldView&, const core::Vec3& hip, double) override {
    servo::HriTick t;
    t.vhip_m = hip;
    return t;
  }
};

const char* kUsage =
    "Usage: bench_hri_tick [SCENE...] [--reps N] [--n N] [--only hri|avila] [--by-kind] [--vk]\n"
    "  SCENE: sphere, knot, head, chest (default: all four)\n"
    "  --reps N     alternated rounds (median; default 21)\n"
    "  --n N        HRI's plane update period (default 5, as bench table1)\n"
    "  --only R     time one renderer only (for callgrind)\n"
    "  --by-kind    HRI's ticks timed one by one: TSC cycles per kind of tick\n"
    "  --vk         samples from the Vulkan device, as bench table1 takes them\n";

/// A positive count from argv[i + 1]; exits with the usage on a missing or bad value.
int count_arg(int argc, char** argv, int& i) {
  char* end = nullptr;
  const long v = i + 1 < argc ? std::strtol(argv[i + 1], &end, 10) : 0;
  if (i + 1 >= argc || end == argv[i + 1] || *end != '\0' || v < 1 || v > 1000000) {
    std::fprintf(stderr, "bench_hri_tick: %s needs a count from 1 to 1000000, got '%s'\n%s", argv[i],
                 i + 1 < argc ? argv[i + 1] : "", kUsage);
    std::exit(2);
  }
  ++i;
  return int(v);
}
}  // namespace

int main(int argc, char** argv) try {
  std::vector<std::string> scenes;
  int reps = 21;
  std::string only;
  int n = 5;
  bool by_kind = false;
  bool use_vk = false;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--reps")) reps = count_arg(argc, argv, i);
    else if (!std::strcmp(argv[i], "--n")) n = count_arg(argc, argv, i);
    else if (!std::strcmp(argv[i], "--only") && i + 1 < argc &&
             (!std::strcmp(argv[i + 1], "hri") || !std::strcmp(argv[i + 1], "avila")))
      only = argv[++i];
    else if (!std::strcmp(argv[i], "--by-kind")) by_kind = true;
    else if (!std::strcmp(argv[i], "--vk")) use_vk = true;
    else if (!std::strcmp(argv[i], "--help") || !std::strcmp(argv[i], "-h")) {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (argv[i][0] == '-') {
      std::fprintf(stderr, "bench_hri_tick: unknown option, or a missing or bad value: %s\n%s", argv[i], kUsage);
      return 2;
    } else {
      scenes.push_back(argv[i]);
    }
  }
  if (scenes.empty()) scenes = {"sphere", "knot", "head", "chest"};
  std::unique_ptr<engine::VulkanContext> ctx;
  if (use_vk) {
    auto c = engine::VulkanContext::create();
    if (!c) {
      std::fprintf(stderr, "bench_hri_tick: --vk: no Vulkan device\n");
      return 1;
    }
    ctx = std::move(*c.value);
  }
  for (const std::string& name : scenes) {
    std::ostringstream quiet;
    const eval::SweepScene s = eval::prepare_sweep_scene(name, ctx.get(), quiet);
    servo::HriParams hp = eval::reference_params(s);
    hp.plane_update_period = n;
    hp.intersection = servo::Intersection::kLinear;
    hp.normal = servo::NormalSource::kCentral;
    servo::BaselineParams bp;
    bp.tau = s.tau;
    bp.inside = s.inside;
    bp.stiffness_n_per_m = s.stiffness_n_per_m;
    bp.force_limit_n = 1e3;
    servo::HriRenderer hri(hp);
    servo::AvilaRenderer avila(bp);
    std::size_t contact = 0, updates = 0;
    hri.reset();
    const std::uint64_t skipped0 = hri.reads_skipped();
    for (const core::Vec3& h : s.hip) {
      const servo::HriTick t = hri.tick(*s.field, h, 0.0);
      contact += t.contact;
      updates += t.plane_update;
    }
    const std::uint64_t skipped = hri.reads_skipped() - skipped0;
    NullRenderer null_r;
    std::vector<double> th, ta, tn;
    for (int r = 0; r < reps; ++r) {
      if (only != "avila") th.push_back(eval::median_ns_per_tick(hri, s, r == 0 ? 2 : 0, 1));
      if (only != "hri") ta.push_back(eval::median_ns_per_tick(avila, s, r == 0 ? 2 : 0, 1));
      if (only.empty()) tn.push_back(eval::median_ns_per_tick(null_r, s, r == 0 ? 2 : 0, 1));
    }
    auto med = [](std::vector<double> v) {
      if (v.empty()) return 0.0;
      std::sort(v.begin(), v.end());
      return v[v.size() / 2];
    };
    if (by_kind) {
      // Cycles per tick by kind, the median over reps of each kind's mean.
      NullRenderer nr;
      std::vector<double> kc[4];
      const char* kinds[4] = {"free", "contact", "update", "avila"};
      for (int r = 0; r < reps; ++r) {
        double sum[4] = {0, 0, 0, 0}, cnt[4] = {0, 0, 0, 0}, null_sum = 0;
        for (const core::Vec3& h : s.hip) {
          const core::FieldView v(*s.field);
          const unsigned long long t0 = __rdtsc();
          const servo::HriTick t = nr.tick(v, h, 0.0);
          null_sum += double(__rdtsc() - t0) + 0 * t.force_n.x;
        }
        const double null_c = null_sum / double(s.hip.size());
        hri.reset();
        avila.reset();
        for (const core::Vec3& h : s.hip) {
          const core::FieldView v(*s.field);
          unsigned long long t0 = __rdtsc();
          const servo::HriTick t = hri.tick(v, h, 0.0);
          const double c = double(__rdtsc() - t0) - null_c;
          const int k = t.plane_update ? 2 : t.contact ? 1 : 0;
          sum[k] += c;
          cnt[k] += 1;
        }
        // Avila in a loop of its own: interleaved tick by tick, the two renderers would
        // share one branch predictor and one L1 and each would pay for the other.
        for (const core::Vec3& h : s.hip) {
          const core::FieldView v(*s.field);
          const unsigned long long t0 = __rdtsc();
          const servo::HriTick ta2 = avila.tick(v, h, 0.0);
          sum[3] += double(__rdtsc() - t0) - null_c + 0 * ta2.force_n.x;
          cnt[3] += 1;
        }
        for (int k = 0; k < 4; ++k) kc[k].push_back(cnt[k] > 0 ? sum[k] / cnt[k] : 0.0);
      }
      std::printf("%-7s by kind [TSC cycles per tick, harness subtracted]:", s.name.c_str());
      for (int k = 0; k < 4; ++k) std::printf(" %s %.0f", kinds[k], med(kc[k]));
      std::printf("\n");
    }
    const double h = med(th), a = med(ta), z = med(tn);
    std::printf("%-7s %5zu ticks (contact %5zu, updates %4zu, free ticks with no read %4llu): HRI %6.1f ns, Avila "
                "%6.1f ns, HRI/Avila %.3f; harness alone %.1f ns\n",
                s.name.c_str(), s.hip.size(), contact, updates, (unsigned long long)skipped, h, a, a > 0 ? h / a : 0.0,
                z);
  }
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "bench_hri_tick: %s\n", e.what());
  return 1;
}

#include "isotouch/run/scene_setup.h"
#include <algorithm>
#include <cstdlib>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>
#include "isotouch/session/brush.h"
#include "isotouch/run/engine_run.h"
#include "isotouch/run/names.h"
#include "isotouch/engine/parallel.h"
#include "isotouch/run/run_report.h"
#include "isotouch/run/scene_script.h"
#include "isotouch/eval/shapes.h"
#include "isotouch/materials/label_volume.h"
#include "isotouch/materials/critical_distance.h"
#include "isotouch/session/material_cut.h"
#include "isotouch/engine/passes.h"
#include "isotouch/engine/vk_context.h"
#include "isotouch/core/brick_field.h"
#include "isotouch/sim/headless.h"
#include "isotouch/engine/synthetic.h"
#include "isotouch/run/text.h"

namespace isotouch::run {
namespace fs = std::filesystem;

bool is_cpu_device(const std::string& device) { return device == kCpuDevice; }

namespace {

session::BrushKind brush_kind(const std::string& k) {
  if (k == "add") return session::BrushKind::kAdd;
  if (k == "carve") return session::BrushKind::kCarve;
  if (k == "smooth") return session::BrushKind::kSmooth;
  return session::BrushKind::kDrill;
}

// Every brush of the scene through session::validate, before anything runs.
void check_scene_brushes(const Scene& scene, const engine::Volume& vol) {
  const core::Isosurface iso{scene.hri.tau, scene.hri.inside};
  const session::BrushTargets def = session::default_targets(vol, iso);
  const double dt = scene.edits.every_ticks / scene.hri.rate_hz;
  auto check = [&](const BrushSpec& b, const std::string& field) {
    const std::string why = session::validate(make_brush(b, def, vol.grid.centre_m(), dt, 0.0));
    if (!why.empty()) throw SceneError(scene.file + ": field '" + field + "': " + why);
  };
  check(scene.edits.brush, "edits.brush");
  for (const TimedEdit& t : scene.edits.timeline)
    if (t.kind != "undo" && t.kind != "redo") check(t.brush, "edits.timeline[" + std::to_string(t.index) + "]");
}

}  // namespace

double drill_rate(const BrushSpec& b, const session::BrushTargets& t) {
  if (!(b.removal_per_n_s >= 0)) return b.rate;
  return b.removal_per_n_s * std::abs(double(t.material) - double(t.empty));
}

session::Brush make_brush(const BrushSpec& b, const session::BrushTargets& defaults, const Vec3& centre_m,
                         double dt_s, double force_n) {
  session::Brush e;
  e.kind = brush_kind(b.kind);
  e.centre_m = centre_m;
  e.radius_m = b.radius_mm * 1e-3;
  e.strength = b.strength;
  e.falloff = b.falloff;
  e.targets = defaults;
  if (b.has_material) e.targets.material = float(b.material);
  if (b.has_empty) e.targets.empty = float(b.empty);
  if (b.density_scale > 0) e.targets.density_scale = float(b.density_scale);
  e.force_threshold_n = b.force_threshold_n;
  e.rate = drill_rate(b, e.targets);
  e.dt_s = dt_s;
  e.force_n = force_n;
  return e;
}


io::Recording recording_header(const Scene& scene, const SceneSetup& setup) {
  Recording rec;
  rec.scene_path = fs::absolute(scene.file).string();
  std::ifstream in(scene.file, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  rec.scene_text = text.str();
  rec.rate_hz = setup.hri.rate_hz;
  rec.volume_crc32 = volume_crc32(setup.volume);
  return rec;
}

double tool_brush_margin_m(const engine::Volume& vol) {
  const auto& sp = vol.grid.spacing_m;
  return 0.5 * std::max({sp.x, sp.y, sp.z});
}

io::BrushSpec brush_at_tool(const Scene& scene, const engine::Volume& vol, const io::BrushSpec& b) {
  if (!(scene.hri.tool_radius_m > 0)) return b;
  io::BrushSpec t = b;
  t.radius_mm = 1e3 * (scene.hri.tool_radius_m + tool_brush_margin_m(vol));
  return t;
}

std::vector<engine::PassDesc> scene_passes(const Scene& scene) {
  std::vector<engine::PassDesc> out;
  for (const PassSpec& p : scene.engine.passes) {
    if (p.kind == "gaussian") out.push_back(engine::PassDesc::gaussian(p.sigma_mm));
    else if (p.kind == "closing") out.push_back(engine::PassDesc::closing(p.radius_mm));
    else if (p.kind == "gradient") out.push_back(engine::PassDesc::gradient());
    else if (p.kind == "brick_minmax") out.push_back(engine::PassDesc::brick_minmax(p.halo));
    else throw SceneError(scene.file + ": field 'engine.passes': unknown pass \"" + p.kind + "\"");
  }
  if (const std::string e = engine::validate_passes(out); !e.empty())
    throw SceneError(scene.file + ": field 'engine.passes': " + e);
  return out;
}

core::SampleFormat scene_sample_format(const Scene& scene) {
  if (scene.engine.samples == "fp16") return core::SampleFormat::kFp16;
  if (scene.engine.samples == "unorm16") return core::SampleFormat::kUnorm16;
  if (scene.engine.samples == "fp32") return core::SampleFormat::kFp32;
  throw SceneError(scene.file + ": field 'engine.samples': unknown format \"" + scene.engine.samples + "\"");
}

SceneSetup::SceneSetup() = default;
SceneSetup::SceneSetup(SceneSetup&&) noexcept = default;
SceneSetup& SceneSetup::operator=(SceneSetup&&) noexcept = default;
SceneSetup::~SceneSetup() = default;

long edit_tick(double t_s, double rate_hz) { return std::max(0L, long(std::ceil(t_s * rate_hz - 1e-9))); }

namespace {

// 1. Volume in: the scene's file or synthetic shape.
engine::Volume load_volume(const Scene& scene, std::ostream& log) {
  if (!scene.volume_path.empty()) {
    log << "volume   " << scene.volume_path << "\n";
    return load_any_volume(scene.volume_path);
  }
  if (scene.synthetic.kind == "sphere")
    return engine::make_sphere(scene.synthetic.dims, scene.synthetic.spacing_m, scene.synthetic.radius_vox);
  return std::move(eval::make_synthetic_scene(scene.synthetic.kind).volume);
}

// 1a. The volume's figures into m; a volume without finite voxels, or an isovalue outside
// their range, has no isosurface.
void check_volume(const Scene& scene, SceneSetup& s, std::ostream& log) {
  RunMetrics& m = s.metrics;
  const engine::Volume& vol = s.volume;
  m.volume_path = vol.path;
  m.dims = vol.grid.dims;
  m.spacing_m = vol.grid.spacing_m;
  m.orientation = vol.orientation();
  m.direction = vol.direction;
  m.nan_voxels = vol.nan_voxels;
  m.inf_voxels = vol.inf_voxels;
  const bool any_finite = vol.finite_voxels > 0;
  log << "         " << vol.grid.dims[0] << " x " << vol.grid.dims[1] << " x " << vol.grid.dims[2]
      << " voxels, spacing " << fmt(vol.grid.spacing_m.x * 1e3) << " x " << fmt(vol.grid.spacing_m.y * 1e3)
      << " x " << fmt(vol.grid.spacing_m.z * 1e3) << " mm, " << vol.component_type << " via " << vol.reader
      << ", " << value_range_text(vol, m) << "\n"
      << "         orientation " << m.orientation << " (direction " << direction_text(vol.direction)
      << "); points below and in trace.csv are physical (ITK's LPS frame, origin + D (spacing * index))\n";
  if (!any_finite)
    throw std::runtime_error(scene.file + ": volume " + vol.path + " has no finite voxels (" +
                             std::to_string(m.nan_voxels) + " NaN, " + std::to_string(m.inf_voxels) +
                             " Inf): there is no isosurface");
  if (!(scene.hri.tau > vol.min_value && scene.hri.tau < vol.max_value))
    throw std::runtime_error(scene.file + ": field 'isovalue': " + fmt(scene.hri.tau) +
                             " is outside the finite data range [" + fmt(vol.min_value) + ", " +
                             fmt(vol.max_value) + "] of " + vol.path + ": there is no isosurface");
}

}  // namespace

std::shared_ptr<const session::MaterialCut> material_cut(const materials::LabelVolume& lv) {
  auto cut = std::make_shared<session::MaterialCut>();
  cut->ids = lv.ids;
  for (const materials::Material& m : lv.materials) cut->table.push_back({m.rate, m.density_scale, m.critical});
  return cut;
}

namespace {
// The drill's cut and the critical structures' distance field from the labels.
void make_cut(const materials::LabelVolume& lv, SceneSetup& s) {
  s.cut = material_cut(lv);
  for (std::size_t i = 0; i < lv.materials.size(); ++i) {
    const materials::Material& m = lv.materials[i];
    if (!m.critical) continue;
    std::vector<bool> only(lv.materials.size() + 1, false);
    only[i + 1] = true;
    s.critical.push_back({m.name, std::uint8_t(i + 1), m.margin_mm * 1e-3,
                          std::make_shared<const materials::CriticalDistance>(s.volume.grid, lv.ids, only)});
  }
}

// 1b. The scene's materials read onto the volume's grid and logged, so that a bad label map
// stops the run here with its error. The drill cuts per material (make_cut); the servo and
// the pictures do not use them yet (docs/architecture.md, "How a material reaches the servo").
void load_materials(const Scene& scene, SceneSetup& s, std::ostream& log) {
  if (!scene.materials.present) return;
  s.labels = std::make_shared<const materials::LabelVolume>(materials::load_label_volume(scene.materials, s.volume));
  const materials::LabelVolume& lv = *s.labels;
  make_cut(lv, s);
  log << "materials " << lv.materials.size() << " from " << lv.source << ":";
  for (std::size_t i = 0; i < lv.materials.size(); ++i)
    log << (i ? ", " : " ") << lv.materials[i].name << " " << lv.voxels[i + 1] << " voxels"
        << (lv.materials[i].critical ? " (critical)" : "");
  log << "; " << lv.voxels[0] << " voxels unlabelled (the drill cuts per material";
  if (!s.critical.empty()) log << ", never the critical ones";
  if (!s.critical.empty() && scene.edits.present)  // the margin warning watches the edits only (run::EditDriver)
    for (std::size_t i = 0; i < s.critical.size(); ++i)
      log << (i ? ", " : ", warning within ") << fmt(s.critical[i].margin_m * 1e3, 4) << " mm of " << s.critical[i].name;
  log << "; the servo does not feel materials yet)\n";
  for (const std::string& n : lv.notes) log << "         note: " << n << "\n";
}

// The Vulkan context of opt.device into s.vk, or none: the CPU backend when it is asked for,
// or when no device was asked for and none opens (the reason is logged). A device asked for
// by name that does not open is an error.
void open_device(const RunOptions& opt, SceneSetup& s, std::ostream& log) {
  RunMetrics& m = s.metrics;
  s.device = opt.device;
  const char* env = std::getenv("ISOTOUCH_DEVICE");
  const std::string asked = !opt.device.empty() ? opt.device : (env ? env : "");
  std::string why;
  if (is_cpu_device(asked)) {
    why = "device " + asked + " asked for";
  } else {
    engine::ContextOptions co;
    co.device = opt.device;
    auto ctx = engine::VulkanContext::create(co);
    if (!ctx && !asked.empty()) throw std::runtime_error("Vulkan: " + ctx.error);
    if (ctx) {
      s.vk = std::move(*ctx.value);
      m.gpu_device = s.vk->info().name;
      m.gpu_device_type = s.vk->info().type;
      log << "device   " << m.gpu_device << " (" << m.gpu_device_type << ", " << s.vk->info().driver << ")\n";
      return;
    }
    why = "no Vulkan device (" + ctx.error + ")";
  }
  s.device = kCpuDevice;
  m.cpu_backend = true;
  const unsigned threads = engine::hardware_threads();
  m.gpu_device = "CPU backend";
  m.gpu_device_type = std::to_string(threads) + " thread(s)";
  log << "device   none: " << why << "; the CPU backend: the engine chain on " << threads
      << " thread(s), the brushes and pictures by the one-thread CPU references (the same bits as on lavapipe)\n";
}

// 2. Engine: the scene's passes on the GPU (dense or sparse), the CPU reference beside it;
// the snapshot the servo reads first, the truth the error is measured against, the live
// field's options.
void run_engine_step(const Scene& scene, const RunOptions& opt, SceneSetup& s, std::ostream& log) {
  RunMetrics& m = s.metrics;
  const engine::Volume& vol = s.volume;
  open_device(opt, s, log);
  const EngineRun er = run_engine(scene, vol, s.vk.get(), opt, m, log);
  s.first = er.published;
  // What the surface error is measured against, and the script is cast on: the dense fp32
  // samples of the same passes (CPU reference). For a dense or bricked fp32 snapshot its
  // isosurface is the published one (the bricks hold the same samples wherever a cell
  // can straddle tau); for compact samples it is the surface before rounding.
  s.truth = er.truth;
  s.live.passes = scene_passes(scene);
  s.live.iso = core::Isosurface{scene.hri.tau, scene.hri.inside};
  s.live.background = float(s.live.iso.outside_value(vol.min_value, vol.max_value));  // as run_engine
  s.live.format = scene_sample_format(scene);
}

// 4. Edits: the brushes (GPU), the undo history and the live field over a copy of the volume.
void make_edit_session(const Scene& scene, SceneSetup& s, std::ostream& log) {
  if (!scene.edits.present) return;
  check_scene_brushes(scene, s.volume);
  s.session = std::make_unique<EditSession>(engine::Volume(s.volume), s.vk.get(), s.live, scene.edits.history_limit_mib);
  if (s.cut) s.session->sculptor().set_material_cut(s.cut);
  s.first = s.session->current();
  log << "edits    " << scene.edits.timeline.size() << " timeline entries, " << scene.edits.button_down.size()
      << " button press(es), brushes on the " << (s.session->sculptor().on_gpu() ? "GPU" : "CPU")
      << " (" << s.session->sculptor().describe_path() << ")"
      << ", undo limit " << fmt(scene.edits.history_limit_mib) << " MiB; first snapshot version "
      << s.first->version << " (LiveField, " << s.live.passes.size() << " pass(es))\n";
  log << "live     " << s.session->live().describe() << "\n";
}

}  // namespace

SceneSetup setup_scene(const Scene& scene, const RunOptions& opt, std::ostream& log) {
  (void)scene_passes(scene);  // a bad pass list fails before the volume is read
  (void)scene_sample_format(scene);
  return setup_scene(scene, load_volume(scene, log), opt, log);
}

SceneSetup setup_scene(const Scene& scene, engine::Volume volume, const RunOptions& opt, std::ostream& log) {
  SceneSetup s;
  (void)scene_passes(scene);
  (void)scene_sample_format(scene);
  s.volume = std::move(volume);
  check_volume(scene, s, log);
  load_materials(scene, s, log);
  run_engine_step(scene, opt, s, log);
  // 3. Script, servo parameters, workspace.
  s.hri = scene.hri;
  // An edit stands for every_ticks of cutting: its force step is eased over that time.
  s.hri.edit_period_s = scene.edits.every_ticks / scene.hri.rate_hz;
  s.script = scene_script(scene, *s.truth, s.hri, s.metrics, log);
  s.world_T_device.scale = scene.workspace_scale;
  s.world_T_device.translation_m = s.volume.grid.centre_m();
  make_edit_session(scene, s, log);
  const engine::Volume& vol = s.volume;
  const Vec3 contact_phys = vol.to_physical(s.script.contact_point_m);
  const Vec3 normal_phys = vol.direction_apply(s.script.contact_normal);
  log << "script   contact at (" << fmt(contact_phys.x * 1e3, 4) << ", " << fmt(contact_phys.y * 1e3, 4) << ", "
      << fmt(contact_phys.z * 1e3, 4) << ") mm (physical, LPS), normal (" << fmt(normal_phys.x, 3) << ", "
      << fmt(normal_phys.y, 3) << ", " << fmt(normal_phys.z, 3) << "), " << fmt(s.script.duration_s, 3) << " s at "
      << fmt(s.hri.rate_hz) << " Hz\n";
  return s;
}

}  // namespace isotouch::run

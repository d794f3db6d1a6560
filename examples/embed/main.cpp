// isotouch-embed: a program that uses isotouch as a library, through isotouch/isotouch.h only.
// Loads a CT volume, feels its bone (isovalue 1150) with a simulated device whose hand
// presses on the skull from the patient's left, carves once where the probe touches, and
// prints the force before and after the carve; with RECORDING, the session is recorded there
// (every tick and the edit, io/record.h) and read back.
//   isotouch-embed VOLUME [ISOVALUE [RECORDING]]
// Exit status: 0 done; 1 an error (its message names the file and the value); 2 bad
// arguments; 3 the probe never touched the surface.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>

#include "isotouch/isotouch.h"

namespace it = isotouch;

namespace {

void print_force(const char* what, const it::session::Observed& o) {
  std::printf("%-8s at tick %ld: |F| = %.4f N, F = (%.4f, %.4f, %.4f) N, VHIP (%.2f, %.2f, %.2f) mm, snapshot %llu\n",
              what, o.tick, it::core::norm(o.force_n), o.force_n.x, o.force_n.y, o.force_n.z, o.vhip_m.x * 1e3,
              o.vhip_m.y * 1e3, o.vhip_m.z * 1e3, static_cast<unsigned long long>(o.version));
}

int run(const std::string& path, double isovalue, const std::string& recording) {
  // 1. The volume and the engine's first snapshot (CPU engine: no Vulkan device needed).
  it::engine::Volume volume = it::load_volume(path);
  const auto& d = volume.grid.dims;
  std::printf("volume   %s: %d x %d x %d voxels, values %.0f to %.0f (isotouch %s)\n", path.c_str(), int(d[0]),
              int(d[1]), int(d[2]), double(volume.min_value), double(volume.max_value), it::kVersion);
  const it::session::LiveFieldOptions field = it::field_options(volume, isovalue);
  const it::session::BrushTargets targets = it::session::default_targets(volume, field.iso);
  it::servo::WorkspaceTransform world_T_device;  // the device frame centred on the volume
  world_T_device.translation_m = volume.grid.centre_m();
  const std::uint32_t crc = it::io::volume_crc32(volume);
  std::unique_ptr<it::session::EditSession> edits = it::make_edit_session(std::move(volume), field);
  it::servo::TripleBuffer<it::core::SampleField> buffer;
  buffer.publish(edits->current());

  // 2. The renderer and a simulated hand: from outside the head's left side, along -x.
  it::servo::HriRenderer renderer(it::hri_params(isovalue));
  it::sim::ScriptParams hand;
  hand.ray_origin_frac = {1.2, 0.5, 0.12};
  hand.ray_direction = {-1, 0, 0};
  hand.stroke_direction = {0, 1, 0};
  auto device = std::make_unique<it::SimulatedHand>(*edits->current(), it::hri_params(isovalue), hand, world_T_device);

  // 3. The live session: servo thread at 1 kHz, edit thread.
  it::session::LiveSessionConfig config = it::polite_config(1000.0, world_T_device);
  config.record_path = recording;  // "" = none
  config.record_header.rate_hz = 1000.0;
  config.record_header.volume_crc32 = crc;
  it::session::LiveSession live(*edits, buffer, renderer, device->io, config);
  live.start();
  const auto pressing = [](const it::session::Observed& o) { return o.contact && it::core::norm(o.force_n) > 0.5; };
  const double press_s = device->script.t_stroke + 1.0;  // the hand is pressed in by the stroke's start
  if (!it::wait_until(live, pressing, press_s)) {
    it::session::stop_or_end_process(live, "isotouch-embed");
    std::fprintf(stderr, "isotouch-embed: %s: no contact within %.1f s (isovalue %g)\n", path.c_str(), press_s, isovalue);
    return 3;
  }
  const it::session::Observed before = live.observe();
  print_force("contact", before);

  // 4. One carve at the probe's surface point; wait for a tick that reads its snapshot.
  live.submit(it::carve_at(before.vhip_m, 4e-3, 2000.0, targets));
  const bool read = it::wait_until(live, [&](const it::session::Observed& o) { return o.version > before.version; }, 5.0);
  const it::session::Observed after = live.observe();
  print_force("carved", after);
  it::session::stop_or_end_process(live, "isotouch-embed");
  const it::session::LiveStats s = live.stats();
  std::printf("session  %ld ticks, %ld missed deadlines, %ld faults; %ld edits applied, %ld snapshots published\n",
              s.ticks, s.missed_deadlines, s.faults, s.edits_applied, s.publications);
  if (!recording.empty()) {
    const it::io::Recording rec = it::io::load_recording(recording);
    std::printf("recorded %s: %zu ticks, %zu edits\n", recording.c_str(), rec.ticks.size(), rec.edits.size());
  }
  if (!read || s.edits_applied != 1) {
    std::fprintf(stderr, "isotouch-embed: the carve was not felt (%ld edits applied, %ld refused)\n", s.edits_applied,
                 s.edits_refused);
    return 1;
  }
  return s.faults > 0 ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || argc > 4) {
    std::fprintf(stderr, "usage: isotouch-embed VOLUME [ISOVALUE [RECORDING]]   "
                         "(e.g. data/ct-head-headsq/headsq_64x64x93_int16.mhd 1150 session.rec)\n");
    return 2;
  }
  char* end = nullptr;
  const double isovalue = argc >= 3 ? std::strtod(argv[2], &end) : 1150.0;
  if (!std::isfinite(isovalue) || (argc >= 3 && (end == argv[2] || *end != '\0'))) {
    std::fprintf(stderr, "isotouch-embed: ISOVALUE must be a finite number, got \"%s\"\n", argv[2]);
    return 2;
  }
  try {
    return run(argv[1], isovalue, argc == 4 ? argv[3] : "");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "isotouch-embed: %s\n", e.what());
    return 1;
  }
}

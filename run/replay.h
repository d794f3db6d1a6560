// replay.h - what `isotouch replay FILE` runs: plays a recording back (io/record.h) and checks
// the forces, the VHIPs and the snapshot versions each tick read.
//
// The replay rebuilds the recorded scene's pipeline with run::setup_scene from the scene text
// the recording carries (volume, engine, HriParams, the EditSession and its first snapshot;
// the recording's edit_session where it has one), then for each recorded tick k, in
// the headless run's order (sim/headless.cpp, session/edit_session.h's determinism rule):
// acquire the newest snapshot, HriRenderer::tick(field, recorded HIP) at the nominal
// period, compare the force, the VHIP and the snapshot's version with the recorded ones bit
// for bit (format 1 recordings: the force only), then apply tick k's
// recorded edits through the EditSession, publishing into the buffer tick k + 1 reads.
// The simulated device is not used: the HIP is the recorded one.
#pragma once
#include <iosfwd>
#include <stdexcept>
#include <string>

#include "isotouch/io/record.h"

namespace isotouch::run {

/// A recording that cannot be replayed as recorded: the scene text it carries is refused, the
/// volume's voxels differ from the recorded checksum, the rate differs, edits without an edit pipeline, an edit the pipeline refuses. what()
/// names the file and the reason. (`replay` exits 2.)
struct ReplayInputError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct ReplayOptions {
  std::string out_dir;      ///< if set: trace.csv of the replay written there (atomic)
  std::string device;       ///< Vulkan device choice (ContextOptions::device)
  bool progress = true;     ///< a line per 10 % on stderr
  std::string name = "recording";  ///< the recording's file name, for messages
  /// A relative io::Recording::scene_path is resolved against this folder (the recording's:
  /// committed regression recordings name their scene relative to themselves).
  std::string recording_dir;
};

struct ReplayResult {
  long ticks = 0;           ///< ticks replayed
  long edits = 0;           ///< edit events applied
  long publications = 0;    ///< snapshots published by the edits
  long differing_ticks = 0; ///< ticks whose force, VHIP or snapshot version differs from the recorded one in any bit
  double max_df_n = 0;      ///< max over ticks of |F_replay - F_recorded| [N]
  long first_diff_tick = -1;        ///< first differing tick, -1 if none
  double first_diff_t_s = 0;        ///< its time [s]
  core::Vec3 first_recorded_n, first_replayed_n;  ///< both forces there [N]
  std::string first_diff_what;      ///< what differed there: "force", "VHIP", "snapshot version" (joined by ", ")
  core::Vec3 first_recorded_vhip_m, first_replayed_vhip_m;
  std::uint64_t first_recorded_version = 0, first_replayed_version = 0;
  /// A cut recording (no end record): trailing ticks not compared, from the first one that
  /// read a snapshot no recorded edit reaches (its edit was written after the cut).
  long cut_ticks = 0;
  bool identical() const { return differing_ticks == 0; }
};

/// Replays `rec` (see the file comment). Log lines go to `log`.
/// @throws ReplayInputError (refused scene text, another volume, ...), engine errors, std::runtime_error.
ReplayResult replay_recording(const io::Recording& rec, const ReplayOptions& options, std::ostream& log);

/// The verdict line of a replay: "IDENTICAL: ..." or "DIFFERENT: k of n ticks differ; first at
/// tick ... (what, both values)"; `rec_format` is the recording's format (1: forces only).
std::string replay_verdict(const ReplayResult& result, int rec_format);

}  // namespace isotouch::run

// pass_desc.h - what a scene asks of the engine: the pass list (PassDesc), its check, the
// outputs of a chain, and the chain's one-thread CPU reference (run_chain_cpu). No Vulkan:
// the CPU references, the live field and the ThreadSanitizer build use this alone; the GPU
// chain that runs the same list is PassChain (passes.h).
#pragma once
#include "isotouch/engine/core_names.h"
#include <atomic>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "isotouch/engine/cpu_filters.h"
#include "isotouch/core/sample_field.h"
#include "isotouch/engine/volume.h"

namespace isotouch::engine {

enum class PassKind { Gaussian, Closing, Gradient, BrickMinMax };
const char* pass_name(PassKind kind);

struct PassDesc {
  PassKind kind = PassKind::Gradient;
  double sigma_mm = 0;   ///< Gaussian: standard deviation [mm], > 0
  double radius_mm = 0;  ///< Closing: structuring element half-width [mm], >= 0
  int halo = 1;          ///< BrickMinMax: voxels added on each side of a brick, 0..8

  static PassDesc gaussian(double sigma_mm) { return {PassKind::Gaussian, sigma_mm, 0, 1}; }
  static PassDesc closing(double radius_mm) { return {PassKind::Closing, 0, radius_mm, 1}; }
  static PassDesc gradient() { return {PassKind::Gradient, 0, 0, 1}; }
  static PassDesc brick_minmax(int halo = 1) { return {PassKind::BrickMinMax, 0, 0, halo}; }
  /// "gaussian(sigma 1 mm)", "closing(radius 2 mm)", "gradient", "brick_minmax(halo 1)".
  std::string label() const;
};

/// Checks a pass list: non-empty, parameters in range, gradient/brick_minmax at most once.
/// @return empty string if valid, else the reason (names the pass index and value).
std::string validate_passes(const std::vector<PassDesc>& passes);

struct PassTiming {
  std::string label;     ///< PassDesc::label()
  double ms = -1;        ///< GPU: device time from timestamps (-1 if none); CPU: wall time
  int dispatches = 0;    ///< GPU dispatches (one per axis per slab); 0 on the CPU
};

/// What a chain produced. Only the outputs the list asks for are present.
struct ChainOutput {
  std::optional<std::vector<float>> field;     ///< field after the last filter, if any filter ran
  std::optional<core::SampleField> samples;   ///< gradient output
  std::optional<BrickRanges> bricks;           ///< brick_minmax output
  std::vector<PassTiming> passes;              ///< one per PassDesc, in order
  double upload_ms = 0;       ///< host memcpy into staging
  double submit_wall_ms = 0;  ///< submit to fence, wall clock (GPU); total (CPU)
  double download_ms = 0;     ///< host memcpy out of readback buffers
  bool gpu_timestamps = false;
};

/// The CPU reference of a chain, same outputs; PassTiming::ms is wall time. One thread by
/// default (the reference); `threads` > 1 is the multi-threaded CPU backend (where no Vulkan
/// device exists): every pass's rows split among that many threads, bit for bit the same.
/// `cancel` (may be null), read between passes and between a filter's axis sweeps: once
/// set, the run stops there and throws ChainCancelled (a caller's Ctrl-C, within one sweep).
/// @throws std::invalid_argument if validate_passes() fails; ChainCancelled.
ChainOutput run_chain_cpu(const Volume& volume, const std::vector<PassDesc>& passes, unsigned threads = 1,
                          const std::atomic<bool>* cancel = nullptr);

/// run_chain_cpu stopped by its cancel flag; nothing was returned.
struct ChainCancelled : std::runtime_error {
  using std::runtime_error::runtime_error;
};

}  // namespace isotouch::engine

// engine_run.h - the scene's engine passes as `isotouch run` runs them: the GPU chain
// (dense or sparse; or the CPU backend without Vulkan) that computes the published snapshot, the one-thread CPU reference
// beside it, and the figures comparing the two.
#pragma once
#include <iosfwd>
#include <memory>

#include "isotouch/run/run_metrics.h"
#include "isotouch/core/sample_field.h"
#include "isotouch/io/scene.h"
#include "isotouch/run/scene_setup.h"
#include "isotouch/engine/vk_context.h"
#include "isotouch/engine/volume.h"

namespace isotouch::run {

struct EngineRun {
  std::shared_ptr<core::SampleField> published;    ///< what the servo reads (version 1, background set)
  std::shared_ptr<const core::SampleField> truth;  ///< dense fp32 samples of the same passes
};

/// Runs the scene's passes (engine.mode dense or sparse, engine.samples) on `vk`, or on the
/// CPU backend (every hardware thread) when `vk` is null, and the one-thread CPU reference;
/// fills the engine figures of `m` (the gpu_* ones hold the engine's, either way) and logs them.
/// @throws std::runtime_error (Vulkan, a chain that returned nothing), SceneError (the scene's passes).
EngineRun run_engine(const io::Scene& scene, const engine::Volume& vol, engine::VulkanContext* vk,
                     const RunOptions& opt, RunMetrics& m, std::ostream& log);

}  // namespace isotouch::run

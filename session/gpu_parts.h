// gpu_parts.h - session::GpuParts: what a Vulkan device gives the session library (the GPU
// brush engine, the live field's GPU recompute), handed in by whoever builds the session.
//
// The session library (isotouch::session, and isotouch::live above it) holds no Vulkan code:
// the GPU brush (brush.cpp) and the live field's GPU filter (live_gpu.cpp) are in
// isotouch::session_gpu, which links the Vulkan engine. The session reaches them only through
// the two factories here, which the converting constructor from an engine::VulkanContext*
// fills in the caller's own code: a program that passes a device links session_gpu (or fails
// to link, naming make_gpu_brush_engine), and one that passes none (nullptr, the default)
// links neither Vulkan nor the GPU code. Without Vulkan (ISOTOUCH_BUILD_ENGINE=OFF)
// session_gpu holds the stand-ins that say so (brush_engine_none.cpp, live_gpu_none.cpp).
#pragma once
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "isotouch/engine/pass_desc.h"
#include "isotouch/engine/result.h"
#include "isotouch/engine/volume.h"

namespace isotouch::engine {
class VulkanContext;
}

namespace isotouch::session {

class BrushEngine;
class LiveGpuFilter;

/// The GPU brush engine on `vol` (BrushEngine::create). In isotouch::session_gpu.
engine::Result<std::unique_ptr<BrushEngine>> make_gpu_brush_engine(engine::VulkanContext& ctx,
                                                                   const engine::Volume& vol,
                                                                   std::uint64_t max_binding_bytes);
/// The live field's GPU filter (live_gpu.h). In isotouch::session_gpu.
engine::Result<std::unique_ptr<LiveGpuFilter>> make_live_gpu_filter(engine::VulkanContext& ctx,
                                                                     const engine::Volume& vol,
                                                                     const std::vector<engine::PassDesc>& passes);

/// A Vulkan device and the GPU parts the session builds on it; empty (no device): the CPU
/// brushes and the live field's CPU recompute. Converts from an engine::VulkanContext*
/// (null: empty), so the session's constructors take a context as before.
struct GpuParts {
  using BrushEngineFactory = engine::Result<std::unique_ptr<BrushEngine>> (*)(engine::VulkanContext&,
                                                                              const engine::Volume&, std::uint64_t);
  using LiveFilterFactory = engine::Result<std::unique_ptr<LiveGpuFilter>> (*)(
      engine::VulkanContext&, const engine::Volume&, const std::vector<engine::PassDesc>&);

  engine::VulkanContext* ctx = nullptr;      ///< not owned; null: no device
  BrushEngineFactory brush_engine = nullptr;  ///< set with ctx
  LiveFilterFactory live_filter = nullptr;    ///< set with ctx

  GpuParts() = default;
  GpuParts(std::nullptr_t) {}  // NOLINT(google-explicit-constructor): a null context, as before
  GpuParts(engine::VulkanContext* c)  // NOLINT(google-explicit-constructor): a context, as before
      : ctx(c), brush_engine(c ? &make_gpu_brush_engine : nullptr), live_filter(c ? &make_live_gpu_filter : nullptr) {}
  explicit operator bool() const { return ctx != nullptr; }
};

}  // namespace isotouch::session

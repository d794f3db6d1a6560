// brush_engine_none.cpp - BrushEngine in a build without Vulkan (the ThreadSanitizer preset):
// it cannot be created, so a Sculptor runs every brush on the CPU reference.
#include <stdexcept>
#include <string>

#include "isotouch/session/brush.h"

namespace isotouch::session {

struct BrushEngine::Impl {
  core::Grid grid;
};

BrushEngine::BrushEngine(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
BrushEngine::~BrushEngine() = default;

engine::Result<std::unique_ptr<BrushEngine>> BrushEngine::create(engine::VulkanContext&, const engine::Volume& vol,
                                                                 std::uint64_t) {
  return engine::Result<std::unique_ptr<BrushEngine>>::fail(vol.path +
                                                            ": this build of isotouch has no Vulkan: no GPU brushes");
}

engine::Result<std::unique_ptr<BrushEngine>> make_gpu_brush_engine(engine::VulkanContext& ctx,
                                                                   const engine::Volume& vol,
                                                                   std::uint64_t max_binding_bytes) {
  return BrushEngine::create(ctx, vol, max_binding_bytes);
}

namespace {
[[noreturn]] void no_vulkan() { throw std::logic_error("BrushEngine: this build of isotouch has no Vulkan"); }
}  // namespace

BrushResult BrushEngine::apply(const Brush&, engine::Volume*) { no_vulkan(); }
void BrushEngine::upload_bricks(const engine::Volume&, const std::vector<std::uint32_t>&) { no_vulkan(); }
std::vector<float> BrushEngine::download_all() { no_vulkan(); }
const core::Grid& BrushEngine::grid() const { return impl_->grid; }
const std::string& BrushEngine::device_type() const {
  static const std::string none = "none";
  return none;
}

}  // namespace isotouch::session

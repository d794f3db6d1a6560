// live_gpu.cpp - the live field's GPU recompute on engine::SparseFilter (session/live_gpu.h).
#include "isotouch/session/live_gpu.h"

#include "isotouch/engine/sparse_chain.h"

namespace isotouch::session {

namespace {
class SparseFilterGpu final : public LiveGpuFilter {
 public:
  explicit SparseFilterGpu(std::unique_ptr<engine::SparseFilter> f) : f_(std::move(f)) {}
  void set_bricks(const float* voxels, const std::vector<std::uint32_t>& bricks) noexcept override {
    f_->set_bricks(voxels, bricks);
  }
  const float* filter(const std::vector<std::uint32_t>& candidates, double& submit_ms) override {
    const engine::SparseFilter::Output o = f_->filter(candidates);
    submit_ms = o.submit_wall_ms;
    return o.field;
  }
  std::string describe() const override { return f_->describe(); }

 private:
  std::unique_ptr<engine::SparseFilter> f_;
};
}  // namespace

engine::Result<std::unique_ptr<LiveGpuFilter>> make_live_gpu_filter(engine::VulkanContext& ctx,
                                                                     const engine::Volume& vol,
                                                                     const std::vector<engine::PassDesc>& passes) {
  using R = engine::Result<std::unique_ptr<LiveGpuFilter>>;
  auto r = engine::SparseFilter::create(ctx, vol, passes);
  if (!r) return R::fail(r.error);
  return R::ok(std::make_unique<SparseFilterGpu>(std::move(*r.value)));
}

}  // namespace isotouch::session

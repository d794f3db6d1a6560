// live_field.cpp - STUB (lead): every update() is a full run_sparse_cpu. The live-field
// helper replaces this with the brick-by-brick update described in live_field.h.
#include "live_field.h"

#include <chrono>
#include <mutex>
#include <stdexcept>

#include "sparse_chain.h"

namespace isotouch::engine {

struct LiveField::Impl {
  LiveFieldOptions opt;
  std::shared_ptr<const core::SampleField> cur;
  std::uint64_t version = 0;
  std::size_t total_bricks = 0;
};

LiveField::LiveField(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
LiveField::~LiveField() = default;

namespace {
std::shared_ptr<const core::SampleField> full(const Volume& vol, const LiveFieldOptions& o, std::uint64_t version) {
  SparseOutput out = run_sparse_cpu(vol, o.passes, o.iso, o.background, o.format);
  out.field.version = version;
  return std::make_shared<const core::SampleField>(std::move(out.field));
}
}  // namespace

std::unique_ptr<LiveField> LiveField::create(const Volume& vol, const LiveFieldOptions& options) {
  const std::string why = sparse::validate(options.passes);
  if (!why.empty()) throw std::invalid_argument("live field: " + why);
  auto impl = std::make_unique<Impl>();
  impl->opt = options;
  impl->version = 1;
  impl->cur = full(vol, options, 1);
  impl->total_bricks = impl->cur->bricks ? impl->cur->bricks->total_bricks() : 0;
  return std::unique_ptr<LiveField>(new LiveField(std::move(impl)));
}

std::shared_ptr<const core::SampleField> LiveField::update(const Volume& vol, const std::vector<std::uint32_t>& dirty,
                                                           LiveUpdateStats* stats) {
  const auto t0 = std::chrono::steady_clock::now();
  for (std::uint32_t id : dirty)
    if (id >= impl_->total_bricks)
      throw std::out_of_range("live field: dirty brick id " + std::to_string(id) + " of " +
                              std::to_string(impl_->total_bricks) + " bricks");
  impl_->cur = full(vol, impl_->opt, ++impl_->version);
  if (stats) {
    *stats = {};
    stats->dirty = dirty.size();
    stats->recomputed = impl_->total_bricks;
    stats->active = impl_->cur->bricks ? impl_->cur->bricks->active_bricks() : 0;
    stats->total_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    stats->recompute_ms = stats->total_ms;
    stats->version = impl_->version;
  }
  return impl_->cur;
}

std::shared_ptr<const core::SampleField> LiveField::current() const { return impl_->cur; }
const LiveFieldOptions& LiveField::options() const { return impl_->opt; }
std::uint64_t LiveField::pool_bytes() const { return 0; }

}  // namespace isotouch::engine

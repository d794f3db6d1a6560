// sparse_chain.cpp - the sparse GPU engine (issue 8 item 4). STUB: run() throws until the
// real implementation lands; create()/describe() already work so callers can link.
#include "sparse_chain.h"

#include <sstream>
#include <stdexcept>

namespace isotouch::engine {

struct SparseChain::Impl {
  VulkanContext& ctx;
  std::vector<PassDesc> passes;
  Impl(VulkanContext& c, std::vector<PassDesc> p) : ctx(c), passes(std::move(p)) {}
};

SparseChain::SparseChain(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
SparseChain::~SparseChain() = default;

Result<std::unique_ptr<SparseChain>> SparseChain::create(VulkanContext& ctx, std::vector<PassDesc> passes) {
  using R = Result<std::unique_ptr<SparseChain>>;
  if (std::string e = validate_passes(passes); !e.empty()) return R::fail("sparse chain: " + e);
  return R::ok(std::unique_ptr<SparseChain>(new SparseChain(std::make_unique<Impl>(ctx, std::move(passes)))));
}

SparseOutput SparseChain::run(const Volume& volume, const core::Isosurface&, float, core::SampleFormat,
                              std::uint64_t) {
  throw VolumeError(volume.path + ": sparse chain: not implemented yet");
}

std::string SparseChain::describe() const {
  std::ostringstream s;
  s << "sparse chain (stub):";
  for (const PassDesc& p : impl_->passes) s << ' ' << p.label();
  return s.str();
}

}  // namespace isotouch::engine

// pool_recycler.cpp - see pool_recycler.h.
#include "isotouch/engine/pool_recycler.h"

#include <utility>

#ifdef __linux__
#include <sys/mman.h>
#endif

namespace isotouch::engine {

namespace {
void advise_huge_pages(void* p, std::size_t bytes) {
#ifdef __linux__
  constexpr std::uintptr_t kHuge = std::uintptr_t(2) << 20;
  const std::uintptr_t b = (reinterpret_cast<std::uintptr_t>(p) + kHuge - 1) & ~(kHuge - 1);
  const std::uintptr_t e = (reinterpret_cast<std::uintptr_t>(p) + bytes) & ~(kHuge - 1);
  if (e > b) (void)madvise(reinterpret_cast<void*>(b), e - b, MADV_HUGEPAGE);
#else
  (void)p;
  (void)bytes;
#endif
}
}  // namespace

core::SamplePool fresh_pool(std::size_t n) {
  core::SamplePool p;
  p.reserve(n);
  advise_huge_pages(p.data(), p.capacity() * sizeof(core::Sample));
  p.resize(n);  // default-initialised: no write, the pages are first touched by the filler
  return p;
}

core::SamplePool PoolRecycler::take(std::size_t n) {
  core::SamplePool p, dropped;
  {
    const std::lock_guard<std::mutex> lock(m_);
    if (n > 0 && kept_.capacity() >= n && kept_.capacity() / 2 <= n) {
      p = std::move(kept_);
      ++reuses_;
      kept_ = core::SamplePool();
    } else if (kept_.capacity() < n) {
      dropped = std::move(kept_);  // too small: freed below, before the new one is made
      kept_ = core::SamplePool();
    }
    // More than twice as large: kept for a later large run; a small snapshot never pins it.
  }
  dropped = core::SamplePool();
  if (p.capacity() == 0) return fresh_pool(n);
  p.clear();
  p.resize(n);  // within capacity: no reallocation, no write
  return p;
}

void PoolRecycler::give_back(core::SamplePool&& pool) noexcept {
  core::SamplePool smaller = std::move(pool);
  try {
    const std::lock_guard<std::mutex> lock(m_);
    if (smaller.capacity() > kept_.capacity()) std::swap(smaller, kept_);
  } catch (...) {
    // The lock failed: the buffer is freed as it would be without a recycler.
  }
  // `smaller` (the buffer not kept) is freed here, outside the lock.
}

std::uint64_t PoolRecycler::retained_bytes() const {
  const std::lock_guard<std::mutex> lock(m_);
  return std::uint64_t(kept_.capacity()) * sizeof(core::Sample);
}

std::uint64_t PoolRecycler::reuses() const {
  const std::lock_guard<std::mutex> lock(m_);
  return reuses_;
}

}  // namespace isotouch::engine

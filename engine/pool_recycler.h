// pool_recycler.h - brick-pool buffers kept from one publication to the next.
//
// A sparse run publishes its active bricks' samples in a fresh fp32 pool (tens of MB on
// the chest CT). Written for the first time, every page of it is a page fault and a page
// the kernel zeroes first: on llvmpipe's machine that was a third of a chest run's time.
// A chain that publishes again (a run per isovalue, a benchmark's repetitions) takes the
// buffer of a snapshot nobody holds any more instead: same capacity, pages resident.
#pragma once
#include "isotouch/engine/core_names.h"
#include <cstddef>
#include <cstdint>
#include <mutex>

#include "isotouch/core/brick_field.h"

namespace isotouch::engine {

/// Keeps ONE retained buffer, the largest handed back (a second one is freed), so what it
/// holds beyond the live snapshots is at most the largest pool it published. Thread-safe:
/// give_back runs on whichever thread drops a snapshot, take on the publishing thread.
class PoolRecycler final : public core::PoolSink {
 public:
  /// A pool of `n` samples, unwritten (core::SamplePool): the retained buffer where its
  /// capacity holds `n` and is at most twice `n` (a small snapshot never pins a large
  /// buffer: that one stays retained), else a new one (transparent huge pages advised).
  core::SamplePool take(std::size_t n);
  void give_back(core::SamplePool&& pool) noexcept override;
  /// Bytes of the retained buffer's capacity (0 when none): memory held for no snapshot.
  std::uint64_t retained_bytes() const;
  /// take() calls served from a retained buffer.
  std::uint64_t reuses() const;

 private:
  mutable std::mutex m_;
  core::SamplePool kept_;
  std::uint64_t reuses_ = 0;
};

/// A new pool of `n` samples, unwritten, its buffer advised for transparent huge pages (a
/// fault per 2 MiB instead of per 4 KiB where the kernel offers them; advice only).
core::SamplePool fresh_pool(std::size_t n);

}  // namespace isotouch::engine

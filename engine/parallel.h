// parallel.h - the host's threads for the engine's CPU work: row loops split in contiguous
// parts, one std::thread each (no pool: the parts are long, a few ms and more).
#pragma once
#include <cstddef>
#include <functional>

namespace isotouch::engine {

/// Runs body(begin, end) over [0, n) split in at most `threads` contiguous parts, each on
/// its own thread (the last on the calling one); part sizes are multiples of `grain` (the
/// last one excepted). The first exception a part throws is rethrown after all have ended.
void parallel_for(std::size_t n, unsigned threads, std::size_t grain,
                  const std::function<void(std::size_t, std::size_t)>& body);
/// The hardware's threads (std::thread::hardware_concurrency), 1 .. 8.
unsigned hardware_threads();
/// Threads worth starting for `voxels` voxels of work: one per kMinVoxelsPerThread, at most
/// hardware_threads() and at most `wanted` (starting a thread costs tens of microseconds,
/// milliseconds on a loaded machine: small volumes stay on the calling thread).
inline constexpr unsigned long long kMinVoxelsPerThread = 1ull << 19;
unsigned threads_for(unsigned long long voxels, unsigned wanted);

}  // namespace isotouch::engine

#include "isotouch/engine/parallel.h"

#include <algorithm>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace isotouch::engine {

void parallel_for(std::size_t n, unsigned threads, std::size_t grain,
                  const std::function<void(std::size_t, std::size_t)>& body) {
  grain = std::max<std::size_t>(grain, 1);
  const std::size_t parts = std::max<std::size_t>(1, std::min<std::size_t>(threads, (n + grain - 1) / grain));
  if (parts <= 1) {
    if (n) body(0, n);
    return;
  }
  const std::size_t per = (n / grain + parts - 1) / parts * grain;
  std::vector<std::thread> pool;
  std::exception_ptr error;
  std::mutex m;
  auto run = [&](std::size_t b, std::size_t e) {
    try {
      body(b, e);
    } catch (...) {
      std::lock_guard<std::mutex> lock(m);
      if (!error) error = std::current_exception();
    }
  };
  std::size_t b = 0;
  for (std::size_t p = 0; p + 1 < parts && b + per < n; ++p, b += per) pool.emplace_back(run, b, b + per);
  run(b, n);
  for (std::thread& t : pool) t.join();
  if (error) std::rethrow_exception(error);
}

unsigned hardware_threads() { return std::clamp(std::thread::hardware_concurrency(), 1u, 8u); }

unsigned threads_for(unsigned long long voxels, unsigned wanted) {
  const unsigned long long by_work = std::max(1ull, voxels / kMinVoxelsPerThread);
  return unsigned(std::min<unsigned long long>({by_work, std::max(1u, wanted), 8ull}));
}

}  // namespace isotouch::engine

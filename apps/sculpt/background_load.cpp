#include "isotouch/apps/sculpt/background_load.h"

#include <atomic>
#include <thread>
#include <utility>

#include "isotouch/apps/sculpt/app.h"

namespace isotouch::sculpt {

namespace {
std::atomic<int> g_loads_running{0};
}

int loads_running() { return g_loads_running.load(); }

void BackgroundLoad::start(std::function<std::shared_ptr<Carried>()> work) {
  g_loads_running.fetch_add(1);
  std::thread([st = st_, work = std::move(work)] {
    std::shared_ptr<Carried> value;
    std::exception_ptr error;
    try {
      value = work();
    } catch (...) {
      error = std::current_exception();
    }
    {
      std::lock_guard<std::mutex> lock(st->mu);
      st->value = std::move(value);
      st->error = error;
      st->done = true;
    }
    st->cv.notify_all();
    g_loads_running.fetch_sub(1);
  }).detach();
}

}  // namespace isotouch::sculpt

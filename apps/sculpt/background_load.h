// background_load.h - a dropped file loading on a detached thread of its own (apps/sculpt).
//
// The sculpting window opens a dropped volume or scene without stopping its frames: the file
// is read on a thread of its own, and the session polls for the result. A session that ends
// while it runs (the window closed, the isovalue changed) abandons it instead of waiting for
// it (a reader may block as long as its file system does); its result is then dropped when it
// comes. loads_running() (app.h) counts those threads, so that the process can exit without
// running static destructors under one.
#pragma once
#include <chrono>
#include <condition_variable>
#include <exception>
#include <functional>
#include <memory>
#include <mutex>
#include <utility>

namespace isotouch::sculpt {

struct Carried;  // app.cpp: what a new session takes over

/// `work` run on a detached thread; the session polls ready() and takes get().
class BackgroundLoad {
 public:
  explicit BackgroundLoad(std::function<std::shared_ptr<Carried>()> work) : st_(std::make_shared<State>()) {
    start(std::move(work));
  }
  bool ready() const {
    std::lock_guard<std::mutex> lock(st_->mu);
    return st_->done;
  }
  void wait() const {
    std::unique_lock<std::mutex> lock(st_->mu);
    st_->cv.wait(lock, [&] { return st_->done; });
  }
  /// Waits at most `seconds`; true if it is done.
  bool wait_for(double seconds) const {
    std::unique_lock<std::mutex> lock(st_->mu);
    return st_->cv.wait_for(lock, std::chrono::duration<double>(seconds), [&] { return st_->done; });
  }
  /// The loaded volume (after ready()); rethrows what the load threw.
  std::shared_ptr<Carried> get() const {
    std::lock_guard<std::mutex> lock(st_->mu);
    if (st_->error) std::rethrow_exception(st_->error);
    return st_->value;
  }

 private:
  struct State {
    mutable std::mutex mu;
    std::condition_variable cv;
    bool done = false;
    std::shared_ptr<Carried> value;
    std::exception_ptr error;
  };
  void start(std::function<std::shared_ptr<Carried>()> work);
  std::shared_ptr<State> st_;
};

}  // namespace isotouch::sculpt

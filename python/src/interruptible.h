// interruptible.h - a long C++ call from Python that Ctrl-C can stop: the work runs on a worker
// thread while the calling thread (GIL released between looks) checks for signals.
#pragma once
#include <atomic>
#include <chrono>
#include <future>
#include <utility>

#include "isotouch/python/common.h"

namespace isotouch::python {

/// Runs `work(cancel)` on a worker thread and returns its result; every 50 ms the calling
/// thread looks for signals. On Ctrl-C (a handler that raises) it sets `cancel`, waits for
/// the worker (which must look at the flag between its steps and return early), drops what
/// the worker returned or threw, and raises the signal's exception (KeyboardInterrupt). The
/// worker's own exceptions otherwise reach the caller as they are. The GIL is held only
/// while signals are looked at: `work` must not touch Python objects.
template <class Work>
auto run_interruptible(Work&& work) {
  std::atomic<bool> cancel{false};
  auto done = std::async(std::launch::async, [&] { return work(static_cast<const std::atomic<bool>&>(cancel)); });
  for (;;) {
    {
      py::gil_scoped_release nogil;
      if (done.wait_for(std::chrono::milliseconds(50)) == std::future_status::ready) break;
    }
    if (PyErr_CheckSignals() != 0) {
      cancel = true;
      {
        py::gil_scoped_release nogil;
        done.wait();
      }
      throw py::error_already_set();
    }
  }
  return done.get();
}

}  // namespace isotouch::python

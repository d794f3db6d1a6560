#include "isotouch/service/outbox.h"

#include <chrono>
#include <utility>

namespace isotouch::service {

Outbox::Outbox(std::shared_ptr<Connection> conn, std::size_t max_queued_bytes,
               std::function<void(const std::string&)> on_drop)
    : conn_(std::move(conn)), max_bytes_(max_queued_bytes), on_drop_(std::move(on_drop)) {
  thread_ = std::thread([this] { run(); });
}

Outbox::~Outbox() { close(); }

void Outbox::drop(const std::string& why) {
  if (drop_once_.exchange(true)) return;
  conn_->shutdown();
  if (on_drop_ && !why.empty()) on_drop_(why);
  {
    std::lock_guard<std::mutex> lock(mu_);  // flush() returns once the drop was said
    dropped_ = true;
    queue_.clear();
    queued_bytes_ = 0;
  }
  cv_.notify_all();
}

bool Outbox::push(Bytes bytes) {
  std::string why;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (closed_ || dropped_ || !conn_->alive()) return false;
    if (!queue_.empty() && queued_bytes_ + bytes->size() > max_bytes_) {
      why = "not reading: " + std::to_string(queued_bytes_ + bytes->size()) + " bytes would wait for it, past the " +
            std::to_string(max_bytes_) + " its queue holds";
    } else {
      queued_bytes_ += bytes->size();
      queue_.push_back(std::move(bytes));
    }
  }
  if (!why.empty()) {
    drop(why);
    return false;
  }
  cv_.notify_all();
  return true;
}

bool Outbox::flush(int timeout_ms) {
  std::unique_lock<std::mutex> lock(mu_);
  cv_.wait_for(lock, std::chrono::milliseconds(timeout_ms),
               [&] { return closed_ || dropped_ || (queue_.empty() && !sending_); });
  return queue_.empty() && !sending_;
}

void Outbox::close() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    closed_ = true;
    queue_.clear();
    queued_bytes_ = 0;
  }
  cv_.notify_all();
  if (thread_.joinable() && thread_.get_id() != std::this_thread::get_id()) thread_.join();
}

long Outbox::sent() const {
  std::lock_guard<std::mutex> lock(mu_);
  return sent_;
}

void Outbox::run() {
  for (;;) {
    Bytes next;
    {
      std::unique_lock<std::mutex> lock(mu_);
      cv_.wait(lock, [&] { return closed_ || dropped_ || !queue_.empty(); });
      if (closed_ || dropped_) return;
      next = std::move(queue_.front());
      queue_.pop_front();
      queued_bytes_ -= next->size();
      sending_ = true;
    }
    const bool was_alive = conn_->alive();
    const bool ok = conn_->send(next->data(), next->size(), false);
    if (!ok)  // before the message is done with: flush() returns after the drop
      drop(was_alive ? "a message of " + std::to_string(next->size()) +
                           " bytes not taken within its deadline, or the connection gone"
                     : "");  // gone before: said where it was shut
    {
      std::lock_guard<std::mutex> lock(mu_);
      sending_ = false;
      if (ok) ++sent_;
    }
    cv_.notify_all();
    if (!ok) return;
  }
}

}  // namespace isotouch::service

// socket_link.h - a ReportLink over a Unix-domain SOCK_SEQPACKET socket: the same report
// bytes as over USB, to isotouch-devemu (one message = one report).
#pragma once
#include "isotouch/servo/core_names.h"
#include <string>

#include "isotouch/servo/report_device.h"

namespace isotouch::servo {

/// Connects to `path`. A feature report is asked for with a one-byte message holding its
/// ID; the answer is the next message that starts with that ID (input reports in between
/// are skipped).
class SocketLink final : public ReportLink {
 public:
  explicit SocketLink(std::string path) : path_(std::move(path)) {}
  ~SocketLink() override { close(); }
  std::string name() const override { return "emu:" + path_; }
  std::string open() override;
  void close() override;
  int read(std::span<std::uint8_t> buf, int timeout_ms) override;
  /// poll() on the socket: the kernel's, safe beside a send().
  bool wait_readable(int timeout_ms) override;
  bool write(std::span<const std::uint8_t> report) override;
  int get_feature(std::uint8_t id, std::span<std::uint8_t> buf) override;

 private:
  std::string path_;
  int fd_ = -1;
};

}  // namespace isotouch::servo

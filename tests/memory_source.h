// memory_source.h - bytes from a buffer, as a client sent them, for the igtl message reader
// (service::read_message) in the tests: one read at a time, its end an "end of buffer".
#pragma once
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "isotouch/service/igtl_message.h"

namespace isotouch::test {

class MemorySource final : public service::ByteSource {
 public:
  explicit MemorySource(std::vector<std::uint8_t> b) : b_(std::move(b)) {}
  std::size_t read(void* dst, std::size_t n, bool) override {
    const std::size_t k = std::min(n, b_.size() - at_);
    std::memcpy(dst, b_.data() + at_, k);
    at_ += k;
    return k;
  }
  std::string why() const override { return "end of buffer"; }

 private:
  std::vector<std::uint8_t> b_;
  std::size_t at_ = 0;
};

}  // namespace isotouch::test

// result.h - engine::Result: set-up that can legitimately fail (no device, missing layer,
// too large a volume) returns a value or the reason the caller reports. No Vulkan here, so
// code built without Vulkan (session/, the ThreadSanitizer preset) can name it.
#pragma once
#include <optional>
#include <string>
#include <utility>

namespace isotouch::engine {

/// Tier-2 errors: set-up that can legitimately fail (no device, missing layer) returns
/// a Result with a reason the caller reports.
template <class T>
struct Result {
  std::optional<T> value;
  std::string error;
  explicit operator bool() const { return value.has_value(); }
  static Result ok(T v) { return {std::move(v), {}}; }
  static Result fail(std::string why) { return {std::nullopt, std::move(why)}; }
};

}  // namespace isotouch::engine

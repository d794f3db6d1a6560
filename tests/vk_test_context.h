// vk_test_context.h - the one Vulkan context every GPU test file uses.
// Validation layer and its synchronization validation on; a missing layer is a failure,
// not a skip (CI installs vulkan-validationlayers). Tests check
// validation_messages() == 0 after their GPU work.
#pragma once
#include <stdexcept>
#include <string>

#include "isotouch/engine/vk_context.h"

namespace isotouch::test {

/// The process-wide validated context (created on first use).
/// @throws std::runtime_error if no Vulkan device with the validation layer exists.
inline engine::VulkanContext& validated_vk() {
  static auto ctx = [] {
    engine::ContextOptions o;
    o.validation = true;
    o.synchronization_validation = true;
    auto r = engine::VulkanContext::create(o);
    if (!r)
      throw std::runtime_error("no Vulkan device with the validation layer (Debian: vulkan-validationlayers): " +
                               r.error);
    return std::move(*r.value);
  }();
  return *ctx;
}

}  // namespace isotouch::test

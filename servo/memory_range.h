// memory_range.h - a range of this process's memory, as the servo locks it.
#pragma once
#include <cstddef>

namespace isotouch::servo {

/// [data, data + bytes) of this process's memory.
struct MemoryRange {
  const void* data = nullptr;
  std::size_t bytes = 0;
};

}  // namespace isotouch::servo

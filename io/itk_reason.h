// itk_reason.h - the reason in an ITK or teem exception's message, for the loaders' errors.
#pragma once
#include <string>

namespace isotouch::io {

/// The last, most specific line of an ITK or teem message, without the
/// "ITK ERROR: Class(0x...): " prefix and its source location; an unknown component type is
/// named as an unsupported voxel type. Defined in volume_io.cpp.
std::string itk_reason(std::string msg);

}  // namespace isotouch::io

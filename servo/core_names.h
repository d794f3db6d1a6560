#pragma once
// The core vocabulary that servo/ names without a prefix (core/vocabulary.h), taken in by
// servo/ itself: core's headers put nothing into other namespaces.
#include "isotouch/core/vocabulary.h"

namespace isotouch::servo {
using namespace core::vocabulary;
}  // namespace isotouch::servo

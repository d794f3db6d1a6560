#pragma once
// The core vocabulary that engine/ names without a prefix (core/vocabulary.h), taken in by
// engine/ itself: core's headers put nothing into other namespaces.
#include "isotouch/core/vocabulary.h"

namespace isotouch::engine {
using namespace core::vocabulary;
}  // namespace isotouch::engine

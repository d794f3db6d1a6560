#pragma once
// The core types and helpers that other folders may name without the core:: prefix, in one
// list. Nothing is put into another namespace here: a folder opts in with
// `using namespace core::vocabulary;` in its own *_names.h, so the choice stays with it.
#include "isotouch/core/brick_field.h"
#include "isotouch/core/field_view.h"
#include "isotouch/core/isosurface.h"
#include "isotouch/core/sample_field.h"
#include "isotouch/core/vec3.h"

namespace isotouch::core::vocabulary {
using core::Vec3;
using core::Grid;
using core::Sample;
using core::SampleField;
using core::FieldView;
using core::FieldValue;
using core::InsideIs;
using core::Isosurface;
using core::SampleFormat;
using core::CompactSample;
using core::BrickDecode;
using core::BrickStore;
using core::BrickedInput;
using core::BrickUsage;
using core::kBrickSize;
using core::kBrickStored;
using core::kBrickSamples;
using core::kUnormNaN;
using core::kUnormMax;
using core::iso_excess;
using core::float_to_half;
using core::half_to_float;
using core::unorm16_to_float;
}  // namespace isotouch::core::vocabulary

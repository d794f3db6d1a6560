#pragma once
// The core vocabulary that servo/ names without a prefix. Declared here, by servo/ for itself:
// core's headers put nothing into other namespaces.
#include "brick_field.h"
#include "field_view.h"
#include "isosurface.h"
#include "sample_field.h"
#include "vec3.h"

namespace isotouch::servo {
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
}  // namespace isotouch::servo

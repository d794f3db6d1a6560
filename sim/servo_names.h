#pragma once
// The core vocabulary (core/vocabulary.h) and the servo names that sim/ uses without a
// prefix, declared by sim/ for itself.
#include "isotouch/servo/baselines.h"
#include "isotouch/servo/device_io.h"
#include "isotouch/servo/hri.h"
#include "isotouch/servo/passivity.h"
#include "isotouch/servo/renderer.h"
#include "isotouch/servo/sampling.h"
#include "isotouch/servo/servo_thread.h"
#include "isotouch/servo/triple_buffer.h"
#include "isotouch/servo/workspace.h"

namespace isotouch::sim {
using namespace core::vocabulary;
using servo::AvilaRenderer;
using servo::BaselineParams;
using servo::BlezekRenderer;
using servo::HapticDeviceIO;
using servo::HriParams;
using servo::HriRenderer;
using servo::HriTick;
using servo::Intersection;
using servo::NormalSource;
using servo::PassivityController;
using servo::RenderTick;
using servo::Renderer;
using servo::ServoThread;
using servo::ServoThreadConfig;
using servo::SurfaceFriction;
using servo::ToolPlane;
using servo::TripleBuffer;
using servo::Variant;
using servo::VirtualPlane;
using servo::WorkspaceTransform;
using servo::central_difference_gradient;
using servo::sample_trilinear;
using servo::sample_value;
using servo::trilinear_field_gradient;
}  // namespace isotouch::sim

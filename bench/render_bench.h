// render_bench.h - `isotouch bench render`: ms per frame of the ray caster on the head and
// chest CTs, with and without empty-space skipping, and whether both give the same images.
#pragma once
#include <string>

namespace isotouch::bench {

/// Renders `frames` timed frames (after one warm-up) of size x size pixels of scenes/head.json
/// and scenes/chest.json from the default camera, skipping on and off alternating, on the
/// Vulkan device `device` ("" = the default choice); prints a markdown table and verdicts
/// computed from it to stdout. @return 0; throws std::runtime_error if Vulkan is unavailable.
int run_bench_render(int size, int frames, const std::string& device);

}  // namespace isotouch::bench

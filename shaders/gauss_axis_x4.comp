#version 450
// One axis of the separable Gaussian over the whole volume, the dense chain's form where the
// field is one binding, rows hold whole quads and every radius <= ISOTOUCH_FUSED_MAX_RADIUS
// (engine/passes.cpp; else filter_x4.comp by z-slab): four voxels of an x-row per invocation,
// the source read as quads (RGBA32F texel buffer: one fetch per quad), one vec4 store, 64x1x1
// workgroups over a (ceil(QX / 64), NY, NZ) grid, the size, axis, radius and weights
// specialization constants (no push constants, no buffer of weights).
// The x axis reads the whole quads either side of its own (one fetch each; process CPU time
// on the chest, loaded 2-core EPYC: 19.3-20.3 ms for the three passes against 20.2-21.8 ms
// with the 2R neighbours fetched as single floats through an R32F view).
// The float operations are engine/cpu_filters.cpp's in its order: taps k = -R .. R summed
// from 0 upward, each product and sum `precise` (bit for bit). Border: clamp to edge.
// Bindings: 0 the source (vec4 view), 1 the destination (vec4 per quad).
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_DENSE_WG, local_size_y = 1, local_size_z = 1) in;
layout(constant_id = 0) const int NX = 4;
layout(constant_id = 1) const int NY = 1;
layout(constant_id = 2) const int NZ = 1;
layout(constant_id = 3) const int AXIS = 0;
layout(constant_id = 4) const int R = 0;
layout(constant_id = 5) const float W0 = 0.0;
layout(constant_id = 6) const float W1 = 0.0;
layout(constant_id = 7) const float W2 = 0.0;
layout(constant_id = 8) const float W3 = 0.0;
layout(constant_id = 9) const float W4 = 0.0;
layout(constant_id = 10) const float W5 = 0.0;
layout(constant_id = 11) const float W6 = 0.0;
layout(constant_id = 12) const float W7 = 0.0;
layout(constant_id = 13) const float W8 = 0.0;
const int QX = NX / 4;
const int N = AXIS == 0 ? NX : (AXIS == 1 ? NY : NZ);
const int STRIDE = AXIS == 1 ? QX : QX * NY;  // quads between neighbours along y or z

float w(int k) {
  switch (k) {
    case 0: return W0;
    case 1: return W1;
    case 2: return W2;
    case 3: return W3;
    case 4: return W4;
    case 5: return W5;
    case 6: return W6;
    case 7: return W7;
  }
  return W8;
}

layout(set = 0, binding = 0) uniform samplerBuffer src;
layout(std430, set = 0, binding = 1) writeonly buffer Dst { vec4 dst[]; };

// The x axis: a[4 + j] is voxel 4 q + j for j = -4 .. 7 (those the taps read), clamped into
// the row (past the row's ends the quad either side stands for voxel 0 or NX - 1 in every lane).
vec4 filter_x(int idx, int q) {
  const vec4 cur = texelFetch(src, idx);
  const vec4 prev = q > 0 ? texelFetch(src, idx - 1) : vec4(cur.x);
  const vec4 next = q + 1 < QX ? texelFetch(src, idx + 1) : vec4(cur.w);
  const float a[12] = float[12](prev.x, prev.y, prev.z, prev.w, cur.x, cur.y, cur.z, cur.w, next.x, next.y,
                                next.z, next.w);
  vec4 o;
  [[unroll]] for (int j = 0; j < 4; ++j) {
    precise float acc = 0.0;
    [[unroll]] for (int k = -R; k <= R; ++k) {
      precise float t = w(k + R) * a[4 + j + k];
      acc = acc + t;
    }
    o[j] = acc;
  }
  return o;
}

void main() {
  const ivec3 g = ivec3(gl_GlobalInvocationID);
  if (g.x >= QX) return;
  const int idx = (g.z * NY + g.y) * QX + g.x;
  if (AXIS == 0) {
    dst[idx] = filter_x(idx, g.x);
  } else {
    const int i = AXIS == 1 ? g.y : g.z;
    const int line = idx - i * STRIDE;
    precise vec4 acc = vec4(0.0);
    [[unroll]] for (int k = -R; k <= R; ++k) {
      precise vec4 t = w(k + R) * texelFetch(src, line + clamp(i + k, 0, N - 1) * STRIDE);
      acc = acc + t;
    }
    dst[idx] = acc;
  }
}

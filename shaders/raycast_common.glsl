// raycast_common.glsl - what the ray caster's passes share: bindings, the
// trilinear field, the march, the refinement, shading and the overlay primitives.
// Included by raycast_tiles.comp, raycast_march.comp, raycast_shade.comp and
// raycast_overlay.comp; every pass (raycast_args.comp too) binds the same ISOTOUCH_RAYCAST_BINDINGS bindings (one descriptor layout, engine/raycast.cpp; 16 is the overlay's alone).
//
// Field: the trilinear interpolation of the float voxels (voxel centres at integer index,
// every voxel outside the grid reads `background`), i.e. the value field the servo feels
// (core::FieldView). Inside = inside_sign * (value - tau) > 0; NaN is outside.
//
// Ray: p(t) = eye + t dir in grid-world [m] (dir unit), marched in index space
// p_idx(t) = e + t d with e = (eye - origin) * inv_sp, d = dir * inv_sp, t in metres.
// Samples on one lattice t_k = min(t0 + k h, t1), h = step_vox / |d| (index-space step
// `step_vox` voxels), over [t0, t1] = the ray inside the box [-1, n] (the one-voxel band
// where the border voxels blend with the background) and, with the clip flag, inside
// the kept half-space dot(n, p) + d <= 0. The first inside sample t_k is refined by 6
// bisections of [t_{k-1}, t_k] and one secant step (bracket h / 64: 0.008 voxel at
// h = 0.5 voxel). A ray that starts inside (at the clip plane) hits there: the cut face.
//
// Empty-space skipping (march_skip): the same lattice samples, but a sample whose
// trilinear cell is inactive (no corner can be inside: binding 2, built on the host) is
// not evaluated (one byte load instead of 8 voxel loads), and from an inactive cell at
// chessboard distance D from the nearest active cell the march jumps to the first sample
// past the box of cells within D - 1 of it. A skipped sample is outside either way, so
// skipping on and off give the same image. On a SIMD CPU device every lane of a vector runs
// each iteration of a loop until all are done; march_skip's first loop (byte loads only)
// runs every lane's jumps to its first active cell, the second one evaluates the field
// where a cell is active and jumps where it is not. llvmpipe
// ends every loop of an invocation after 65535 trips in all (per 8-lane vector): a march
// stopped that way says so, and the shade pass finishes it (a new dispatch, a new budget).
//
// The CPU reference (engine/raycast_cpu.cpp) does the same float operations in the same
// order; `precise` forbids FMA contraction here, -ffp-contract=off there.
//
// Quads (binding 12, QUADS): the voxels again, 4 per texel (R32G32B32A32_SFLOAT): texel b
// holds the corners (x, y), (x + 1, y), (x, y + 1), (x + 1, y + 1) of plane z for every base
// corner b = (x, y, z) in [-1, n] per axis (the cells' layout; background outside the grid),
// so a trilinear sample reads 2 texels instead of 8 (on llvmpipe a fetch of 4 floats costs
// about what a fetch of one does: tests/bench_raycast_floor.cpp), the refinement's block 12
// instead of 27 and the normal's faces 5 instead of 12. The same floats in the same order:
// the picture is the one the 1-float path draws. Left out (QUADS false) where they would not
// fit one texel binding or the memory budget (engine/raycast.cpp).
//
// Passes (one command buffer; engine/raycast.cpp): llvmpipe runs an `if` by masking, not by
// branching, so a pass costs its whole straight-line code for every vector of 8
// invocations, taken or not. Code only some pixels need therefore runs in its own pass
// over only those pixels (the host first fills image and depth with the background, -1),
// unless nearly every vector needs it: the march's pixels are those of tiles where a hit
// can be, and shading them in the march (once per vector that has a hit) costs less than
// a pass of its own, which built every hit's ray again (chest, 1024x768: 9 of 10 marched
// pixels hit; bench_raycast_frames, march + shade 26.0-26.8 against 30.0-31.4 ms a frame):
//   tiles   (skipping; the tiles of the march's pixels): per tile of pixels, a ray
//            parameter before which none of its rays' samples can be inside (cone stepping),
//            and the list of the tiles where one can be; args turns their count into the
//            march's indirect dispatch (one workgroup per listed tile);
//   march   (the pixels the box can project to): the ray and its march (skipping: from its
//            tile's start), then, for a hit, refinement, normal and shading (shade_hit):
//            writes colour and depth. A ray whose march llvmpipe's loop budget stopped is
//            appended to the hit list instead;
//   args    (one invocation) : the hit list's count -> the indirect dispatch size of shade;
//   shade   (listed pixels: in practice none) : finishes those rays' march, then shade_hit;
//   overlay (every pixel, only when there are primitives): HIP, VHIP, disc, arrows.

// Binding 0 is a uniform buffer (std140 = std430 for a struct of 4-byte scalars whose size
// is a multiple of 16): one scalar load per use on llvmpipe, where a storage load is a gather.
layout(std140, set = 0, binding = 0) uniform ParamsBuf { RaycastParams P; };
// Bindings 1 and 2 are uniform texel buffers (R32_SFLOAT, texelFetch): on llvmpipe a texel
// fetch is one vector gather, a storage-buffer load a per-lane loop with a bounds check.
layout(set = 0, binding = 1) uniform samplerBuffer vals;    // voxel values, x fastest (VALS4: 4 per texel)
layout(set = 0, binding = 2) uniform samplerBuffer cdist;   // 4 trilinear cells per float, 6 bits each
// The grid's size as specialization constants (one pipeline per field): the voxel and cell
// index arithmetic folds to constant multiplies. Scalars only: glslang turns a float() of a
// specialization constant into a conversion that Vulkan's SPIR-V does not allow, and the
// validation layer's spirv-opt folds vector expressions of them (ivec3(NX, NY, NZ) - 1)
// into invalid SPIR-V for some sizes (45 x 40 x 43).
layout(constant_id = 1) const int NX = 1;
layout(constant_id = 2) const int NY = 1;
layout(constant_id = 3) const int NZ = 1;
layout(constant_id = 4) const bool QUADS = false;
// VALS4: binding 1 is viewed as R32G32B32A32_SFLOAT, voxels 4k .. 4k + 3 in texel k, so one
// texel binding holds 4 maxTexelBufferElements voxels (2^29 on lavapipe: a 512 x 512 x 600
// CT's 1.6e8 voxels do not fit 2^27 single-float texels). The same floats: the same picture;
// on llvmpipe a fetch of 4 floats costs about what a fetch of one does. Set by the host only
// where the voxels do not fit one single-float binding (engine/raycast.cpp).
layout(constant_id = 7) const bool VALS4 = false;
// ISOTOUCH_COUNT_FETCHES (the march and shade passes compiled a second time, *_count_spv.h):
// they count their invocation's texel fetches (voxel(), quad(), cell_dist()) and, per
// subgroup (a vector of lanes on llvmpipe), the lanes of the fetches it made with at least
// one lane active (elected lane), and add them to the counter buffer
// (RayCaster::set_count_fetches: the floor of isotouch-sculpt --bench). Without it
// COUNT_FETCH() is empty: the drawing passes' SPIR-V is the one without counting.
#ifdef ISOTOUCH_COUNT_FETCHES
uint g_fetches = 0u, g_vector_fetches = 0u;
// The fetches of shade_hit (refinement and normal), counted as the shade's in the march.
uint g_shade_fetches = 0u, g_shade_vector_fetches = 0u, g_shaded = 0u;
void count_fetch() {
  ++g_fetches;
  if (subgroupElect()) g_vector_fetches += gl_SubgroupSize;  // every lane's slot of the vector's fetch
}
#define COUNT_FETCH() count_fetch()
#else
#define COUNT_FETCH()
#endif
layout(set = 0, binding = 12) uniform samplerBuffer quads;  // 4 voxels per texel (see above)
// Binding 3: the primitives, a uniform texel buffer viewed as R32G32B32A32_UINT, 4 texels per
// RaycastPrim (its 16 words in order, prim_at): the overlay pass reads every primitive at
// every pixel, and on llvmpipe a storage-buffer load is a per-lane loop with a bounds check
// (its loads were half of the pass's time), a texel fetch one gather.
layout(set = 0, binding = 3) uniform usamplerBuffer prim_texels;
RaycastPrim prim_at(uint i) {
  int t = int(4u * i);
  uvec4 a = texelFetch(prim_texels, t), b = texelFetch(prim_texels, t + 1);
  uvec4 c = texelFetch(prim_texels, t + 2), d = texelFetch(prim_texels, t + 3);
  RaycastPrim q;
  q.kind = a.x;
  q.r0 = uintBitsToFloat(a.y);
  q.alpha = uintBitsToFloat(a.z);
  q.pad0 = uintBitsToFloat(a.w);
  q.ax = uintBitsToFloat(b.x);
  q.ay = uintBitsToFloat(b.y);
  q.az = uintBitsToFloat(b.z);
  q.cr = uintBitsToFloat(b.w);
  q.bx = uintBitsToFloat(c.x);
  q.by = uintBitsToFloat(c.y);
  q.bz = uintBitsToFloat(c.z);
  q.cg = uintBitsToFloat(c.w);
  q.pad1 = uintBitsToFloat(d.x);
  q.pad2 = uintBitsToFloat(d.y);
  q.pad3 = uintBitsToFloat(d.z);
  q.cb = uintBitsToFloat(d.w);
  return q;
}
layout(std430, set = 0, binding = 4) buffer Image { uint image[]; };      // RGBA8 (or BGRA8) per pixel
layout(std430, set = 0, binding = 5) buffer Depth { float depth[]; };     // t [m] of the hit, -1: none
layout(std430, set = 0, binding = 6) buffer LinR { float lin_r[]; };      // linear colour per hit pixel
layout(std430, set = 0, binding = 7) buffer LinG { float lin_g[]; };      //   (the overlay pass blends
layout(std430, set = 0, binding = 8) buffer LinB { float lin_b[]; };      //   into it)
layout(std430, set = 0, binding = 9) buffer Hits { uint hits[]; };        // hit pixels, in no order
layout(std430, set = 0, binding = 10) buffer HitK { uint hit_k[]; };      // per listed pixel: k | redo << 30 (| cap << 31)
#ifdef ISOTOUCH_COUNT_FETCHES
// After ctr: the texel fetches the march and the shade passes' invocations made, then the
// lanes of the fetches their vectors (subgroups) made with at least one lane taking part (a
// vector's fetch costs all its lanes' slots).
layout(std430, set = 0, binding = 11) buffer Counter {
  RaycastCounter ctr;
  uint fetches_march, fetches_shade, vector_fetches_march, vector_fetches_shade;
  uint shaded;  // pixels shade_hit wrote
};
#else
layout(std430, set = 0, binding = 11) buffer Counter { RaycastCounter ctr; };
#endif
layout(std430, set = 0, binding = 13) buffer TileT { float tile_t[]; };  // per tile: raycast_tiles.comp
layout(std430, set = 0, binding = 14) buffer TileCounter { RaycastCounter tctr; };  // listed tiles
layout(std430, set = 0, binding = 15) buffer TileList { uint tile_list[]; };      // ty << 16 | tx
layout(push_constant) uniform Push { RaycastPush pc; };

#define kInf uintBitsToFloat(0x7f800000u)

// Per-invocation copies of the parameters the inner loops read.
float g_bg, g_tau, g_sign;
vec3 g_inv_d;     // 1 / d per axis (exit planes: (plane - e) * inv)

// The memory seam: the only function that reads voxel memory. A bricked snapshot
// (core/brick_field.h) replaces the body with one brick-table lookup + pool read.
// Branch-free: the index is clamped into the grid and the background selected after.
float voxel(ivec3 i) {
  bool outside = any(lessThan(i, ivec3(0))) || i.x >= NX || i.y >= NY || i.z >= NZ;
  int cx = clamp(i.x, 0, NX - 1), cy = clamp(i.y, 0, NY - 1), cz = clamp(i.z, 0, NZ - 1);
  int k = (cz * NY + cy) * NX + cx;
  float v;
  COUNT_FETCH();
  if (VALS4) {
    vec4 t = texelFetch(vals, k >> 2);
    int c = k & 3;
    v = c == 0 ? t.x : c == 1 ? t.y : c == 2 ? t.z : t.w;
  } else {
    v = texelFetch(vals, k).x;
  }
  return outside ? g_bg : v;
}

// The quad of base corner b (components: (x, y), (x + 1, y), (x, y + 1), (x + 1, y + 1) of
// plane b.z). A base corner outside [-1, n] on some axis has every corner outside the grid:
// the background. Branch-free, as voxel().
vec4 quad(ivec3 b) {
  bool outside = any(lessThan(b, ivec3(-1))) || b.x > NX || b.y > NY || b.z > NZ;
  int cx = clamp(b.x, -1, NX) + 1, cy = clamp(b.y, -1, NY) + 1, cz = clamp(b.z, -1, NZ) + 1;
  COUNT_FETCH();
  vec4 q = texelFetch(quads, (cz * (NY + 2) + cy) * (NX + 2) + cx);
  return outside ? vec4(g_bg) : q;
}

float lerp1(float a, float b, float t) {
  precise float r = a + t * (b - a);
  return r;
}

// Trilinear interpolation of a cell's 8 corners v<z><y><x> at fractions f: lerps along x,
// then y, then z (FieldView's order).
float trilerp(float v000, float v001, float v010, float v011, float v100, float v101, float v110,
              float v111, vec3 f) {  // v<z><y><x>
  float c00 = lerp1(v000, v001, f.x);
  float c10 = lerp1(v010, v011, f.x);
  float c01 = lerp1(v100, v101, f.x);
  float c11 = lerp1(v110, v111, f.x);
  return lerp1(lerp1(c00, c10, f.y), lerp1(c01, c11, f.y), f.z);
}

// Trilinear value at a continuous index (FieldView's lerp order: x, then y, then z).
float field(vec3 p) {
  vec3 fl = floor(p);
  ivec3 i = ivec3(fl);
  precise vec3 f = p - fl;
  if (QUADS) {
    vec4 a = quad(i), b = quad(i + ivec3(0, 0, 1));
    return trilerp(a.x, a.y, a.z, a.w, b.x, b.y, b.z, b.w, f);
  }
  return trilerp(voxel(i), voxel(i + ivec3(1, 0, 0)), voxel(i + ivec3(0, 1, 0)), voxel(i + ivec3(1, 1, 0)),
                 voxel(i + ivec3(0, 0, 1)), voxel(i + ivec3(1, 0, 1)), voxel(i + ivec3(0, 1, 1)),
                 voxel(i + ivec3(1, 1, 1)), f);
}

float excess(float v) {
  precise float e = g_sign * (v - g_tau);
  return e;
}

vec3 ray_point(vec3 e, vec3 d, float t) {
  precise vec3 p = e + t * d;
  return p;
}

bool inside_at(vec3 e, vec3 d, float t) { return excess(field(ray_point(e, d, t))) > 0.0; }

float lattice_t(float t0, float t1, float h, int k) {
  precise float t = t0 + float(k) * h;
  return min(t, t1);
}

// refine() reads the field from the 3x3x3 voxels around its bracket, loaded once: the
// bracket [t_{k-1}, t_k] is one lattice step (at most ISOTOUCH_RAYCAST_MAX_STEP < 1 voxel
// in index space, so its points' floors span at most 2 cells per axis: ray_point is
// monotonic in t). field_block(p) picks p's 8 corners out of the 27 by selects (no memory
// access: on llvmpipe every voxel() is a per-lane gather) and lerps them in field()'s order:
// the same value as field(p).
ivec3 g_b;  // lower corner of the block [index]
float g_v000, g_v001, g_v002, g_v010, g_v011, g_v012, g_v020, g_v021, g_v022, g_v100, g_v101, g_v102, g_v110, g_v111, g_v112, g_v120, g_v121, g_v122, g_v200, g_v201, g_v202, g_v210, g_v211, g_v212, g_v220, g_v221, g_v222;
void load_block(ivec3 b) {
  g_b = b;
  if (QUADS) {  // per plane, the quads at (0, 0), (1, 0), (0, 1), (1, 1) cover its 3 x 3 voxels
    vec4 a = quad(b), c = quad(b + ivec3(1, 0, 0)), d = quad(b + ivec3(0, 1, 0)), e = quad(b + ivec3(1, 1, 0));
    g_v000 = a.x; g_v001 = a.y; g_v002 = c.y; g_v010 = a.z; g_v011 = a.w; g_v012 = c.w; g_v020 = d.z; g_v021 = d.w; g_v022 = e.w;
    a = quad(b + ivec3(0, 0, 1)); c = quad(b + ivec3(1, 0, 1)); d = quad(b + ivec3(0, 1, 1)); e = quad(b + ivec3(1, 1, 1));
    g_v100 = a.x; g_v101 = a.y; g_v102 = c.y; g_v110 = a.z; g_v111 = a.w; g_v112 = c.w; g_v120 = d.z; g_v121 = d.w; g_v122 = e.w;
    a = quad(b + ivec3(0, 0, 2)); c = quad(b + ivec3(1, 0, 2)); d = quad(b + ivec3(0, 1, 2)); e = quad(b + ivec3(1, 1, 2));
    g_v200 = a.x; g_v201 = a.y; g_v202 = c.y; g_v210 = a.z; g_v211 = a.w; g_v212 = c.w; g_v220 = d.z; g_v221 = d.w; g_v222 = e.w;
    return;
  }
  g_v000 = voxel(b + ivec3(0, 0, 0));
  g_v001 = voxel(b + ivec3(1, 0, 0));
  g_v002 = voxel(b + ivec3(2, 0, 0));
  g_v010 = voxel(b + ivec3(0, 1, 0));
  g_v011 = voxel(b + ivec3(1, 1, 0));
  g_v012 = voxel(b + ivec3(2, 1, 0));
  g_v020 = voxel(b + ivec3(0, 2, 0));
  g_v021 = voxel(b + ivec3(1, 2, 0));
  g_v022 = voxel(b + ivec3(2, 2, 0));
  g_v100 = voxel(b + ivec3(0, 0, 1));
  g_v101 = voxel(b + ivec3(1, 0, 1));
  g_v102 = voxel(b + ivec3(2, 0, 1));
  g_v110 = voxel(b + ivec3(0, 1, 1));
  g_v111 = voxel(b + ivec3(1, 1, 1));
  g_v112 = voxel(b + ivec3(2, 1, 1));
  g_v120 = voxel(b + ivec3(0, 2, 1));
  g_v121 = voxel(b + ivec3(1, 2, 1));
  g_v122 = voxel(b + ivec3(2, 2, 1));
  g_v200 = voxel(b + ivec3(0, 0, 2));
  g_v201 = voxel(b + ivec3(1, 0, 2));
  g_v202 = voxel(b + ivec3(2, 0, 2));
  g_v210 = voxel(b + ivec3(0, 1, 2));
  g_v211 = voxel(b + ivec3(1, 1, 2));
  g_v212 = voxel(b + ivec3(2, 1, 2));
  g_v220 = voxel(b + ivec3(0, 2, 2));
  g_v221 = voxel(b + ivec3(1, 2, 2));
  g_v222 = voxel(b + ivec3(2, 2, 2));
}
float field_block(vec3 p) {
  vec3 fl = floor(p);
  ivec3 o = clamp(ivec3(fl) - g_b, ivec3(0), ivec3(1));  // 0 or 1 (the clamp only guards)
  precise vec3 f = p - fl;
  bool ox = o.x == 1, oy = o.y == 1, oz = o.z == 1;
  float x000 = ox ? g_v001 : g_v000;
  float x001 = ox ? g_v002 : g_v001;
  float x010 = ox ? g_v011 : g_v010;
  float x011 = ox ? g_v012 : g_v011;
  float x020 = ox ? g_v021 : g_v020;
  float x021 = ox ? g_v022 : g_v021;
  float x100 = ox ? g_v101 : g_v100;
  float x101 = ox ? g_v102 : g_v101;
  float x110 = ox ? g_v111 : g_v110;
  float x111 = ox ? g_v112 : g_v111;
  float x120 = ox ? g_v121 : g_v120;
  float x121 = ox ? g_v122 : g_v121;
  float x200 = ox ? g_v201 : g_v200;
  float x201 = ox ? g_v202 : g_v201;
  float x210 = ox ? g_v211 : g_v210;
  float x211 = ox ? g_v212 : g_v211;
  float x220 = ox ? g_v221 : g_v220;
  float x221 = ox ? g_v222 : g_v221;
  float y000 = oy ? x010 : x000;
  float y001 = oy ? x011 : x001;
  float y010 = oy ? x020 : x010;
  float y011 = oy ? x021 : x011;
  float y100 = oy ? x110 : x100;
  float y101 = oy ? x111 : x101;
  float y110 = oy ? x120 : x110;
  float y111 = oy ? x121 : x111;
  float y200 = oy ? x210 : x200;
  float y201 = oy ? x211 : x201;
  float y210 = oy ? x220 : x210;
  float y211 = oy ? x221 : x211;
  float v000 = oz ? y100 : y000;
  float v001 = oz ? y101 : y001;
  float v010 = oz ? y110 : y010;
  float v011 = oz ? y111 : y011;
  float v100 = oz ? y200 : y100;
  float v101 = oz ? y201 : y101;
  float v110 = oz ? y210 : y110;
  float v111 = oz ? y211 : y111;
  return trilerp(v000, v001, v010, v011, v100, v101, v110, v111, f);
}

// [ta, tb]: ta outside, tb inside, one lattice step. The excess at both ends, 6 bisections
// keeping the excess at the bracket's ends (bracket h / 64: 0.008 voxel at h = 0.5 voxel),
// then the secant point of the last bracket: 8 evaluations of the field on the block of 27
// voxels around the bracket.
float refine(vec3 e, vec3 d, float ta, float tb) {
  load_block(min(ivec3(floor(ray_point(e, d, ta))), ivec3(floor(ray_point(e, d, tb)))));
  float ea = excess(field_block(ray_point(e, d, ta)));
  float eb = excess(field_block(ray_point(e, d, tb)));
  for (int i = 0; i < ISOTOUCH_RAYCAST_BISECTIONS; ++i) {
    precise float tm = 0.5 * (ta + tb);
    float em = excess(field_block(ray_point(e, d, tm)));
    if (em > 0.0) {
      tb = tm;
      eb = em;
    } else {
      ta = tm;
      ea = em;
    }
  }
  precise float t = 0.5 * (ta + tb);
  if (ea <= 0.0 && eb > 0.0) {
    precise float frac = -ea / (eb - ea);
    t = ta + (tb - ta) * frac;
  }
  // Within the bracket even where the float sum rounds past tb: surface_normal_block relies
  // on the hit's cell lying in the block.
  return clamp(t, ta, tb);
}

// The plain march: the first inside lattice sample k in [0, K] (march_from: in [k0, K]),
// or -1 if none. One flat loop: at most K + 1 trips, within llvmpipe's budget. The caller
// refines in a later pass (on a SIMD device a refine inside the loop would run once per
// iteration in which some lane hits, not once per vector).
int march_from(vec3 e, vec3 d, float t0, float t1, float h, int k0, int K) {
  for (int k = k0; k <= K; ++k)
    if (inside_at(e, d, lattice_t(t0, t1, h, k))) return k;
  return -1;
}
int march(vec3 e, vec3 d, float t0, float t1, float h, int K) { return march_from(e, d, t0, t1, h, 0, K); }

// Chessboard distance [cells] from trilinear cell c (lower corner, in [-1, n] per axis) to
// the nearest active cell, 0: active (binding 2, built on the host: engine/raycast.cpp).
// The index is clamped into the cells (a caller's select may evaluate it for any c).
uint cell_dist(ivec3 c) {
  int sx = clamp(c.x + 1, 0, NX + 1), sy = clamp(c.y + 1, 0, NY + 1), sz = clamp(c.z + 1, 0, NZ + 1);
  int i = (sz * (NY + 2) + sy) * (NX + 2) + sx;
  COUNT_FETCH();
  uint w = uint(texelFetch(cdist, i >> 2).x);  // an integer below 2^24, exact in float
  return (w >> (6u * uint(i & 3))) & 63u;
}

// The march with empty-space skipping: the same lattice samples k in [0, K] as march(), in
// order. At sample k the byte D of its cell (floor of the same point field() reads)
// decides: D = 0 (active): field() as in march(); D >= 1: no cell within D - 1 cells of it
// is active, so every sample inside the box of cells [c - D + 1, c + D - 1] is outside; the
// march goes on at the first sample at or past the box's exit plane on the ray's side,
// drawn in by `eps` voxels [index space] (the rounding of the lattice, of ray_point, of the
// exit and of the step count: the coordinates along the ray only move toward the exit:
// float + and * are monotonic). Sample k is skipped too (its cell cannot be inside). k
// grows by at least 1 per iteration: at most K + 1 iterations per loop. Returns as march():
// a skipped sample is outside either way. The caller may start at k > 0 and end at K below
// march()'s where the samples left out lie outside the active cells' box.
//
// Cell index: cell_dist() clamps it into the cells [-1, n]. A sample outside them (only by
// the rounding of a point on the sampling box's face) is then read as the nearest face
// cell c': if the background is inside, every face cell is active (D = 0: the field says
// background, as field() there does); otherwise the cells past the range are inactive
// background and the box of cells within D - 1 of the sample's own cell lies within the box
// around c' or past the range: the jump stays safe.
//
// Two loops (on llvmpipe a vector of 8 lanes runs each loop trip until all its lanes are
// done): first the jumps up to each lane's first active cell (every lane approaches at
// once), then one loop that per trip either jumps or evaluates the field, so a lane that
// meets inactive cells again (a grazing ray, a speck of noise) no longer holds the others'
// evaluations up for an inner loop of its own (as a loop nested in the evaluations did).

// The sample after the box of cells within D - 1 (D >= 1) of sample k's cell (lower corner
// fl): the first at or past its exit plane, at least k + 1; K + 1 past the ray's end.
int jump_past(vec3 e, vec3 d, float t0, float inv_h, int k, int K, float eps, vec3 fl, uint D) {
  precise float r = float(D) - eps;
  precise vec3 hi = fl + r;          // exit plane of a ray going up an axis
  precise vec3 lo = fl - (r - 1.0);  // and going down
  vec3 plane = mix(lo, hi, greaterThan(d, vec3(0.0)));
  precise vec3 tp = (plane - e) * g_inv_d;
  tp = mix(tp, vec3(kInf), equal(d, vec3(0.0)));
  float t_exit = min(min(tp.x, tp.y), tp.z);
  // (times 1 / h: at most an ulp from the quotient, i.e. a sample 1e-7 k h short of the
  // plane counts as past it; the plane is drawn in by eps >= 1/32 voxel, far more)
  precise float kr = (t_exit - t0) * inv_h;
  return max(k + 1, int(min(ceil(kr), float(K + 1))));
}

int march_skip(vec3 e, vec3 d, float t0, float t1, float h, int k, int K, float eps) {
  precise float inv_h = 1.0 / h;
  // Jumps up to the first active cell.
  while (true) {
    vec3 p = ray_point(e, d, lattice_t(t0, t1, h, k));
    vec3 fl = floor(p);
    uint D = cell_dist(ivec3(fl));
    if (D == 0u) break;
    k = jump_past(e, d, t0, inv_h, k, K, eps, fl, D);
    if (k > K) return -1;
  }
  // From there, sample by sample in active cells, jumps across inactive ones. (Where
  // llvmpipe's loop budget stopped the first loop, this one goes on from that sample.)
  while (k <= K) {
    vec3 p = ray_point(e, d, lattice_t(t0, t1, h, k));
    vec3 fl = floor(p);
    uint D = cell_dist(ivec3(fl));
    if (D == 0u) {
      if (excess(field(p)) > 0.0) return k;
      ++k;
    } else {
      k = jump_past(e, d, t0, inv_h, k, K, eps, fl, D);
    }
  }
  // The loop ends with k <= K only when llvmpipe's loop budget ran out (65535 trips per
  // invocation and vector; the two loops together can take up to 2 (K + 1) trips): the
  // samples before k are outside, the rest unknown. -(k + 2): the caller finishes the ray
  // from k with the plain march.
  return k <= K ? -(k + 2) : -1;
}

// Ray against the box [lo, hi] per axis (index space): [tmin, tmax], empty if tmin > tmax.
vec2 box_interval_of(vec3 e, vec3 d, vec3 lo, vec3 hi) {
  float tmin = 0.0, tmax = kInf;
  for (int a = 0; a < 3; ++a) {
    if (d[a] == 0.0) {
      if (e[a] < lo[a] || e[a] > hi[a]) return vec2(1.0, 0.0);
      continue;
    }
    precise float ta = (lo[a] - e[a]) / d[a];
    precise float tb = (hi[a] - e[a]) / d[a];
    tmin = max(tmin, min(ta, tb));
    tmax = min(tmax, max(ta, tb));
  }
  return vec2(tmin, tmax);
}
// Ray against the volume's box [-1, n] per axis.
vec2 box_interval(vec3 e, vec3 d) {
  return box_interval_of(e, d, vec3(-1.0), vec3(float(P.nx), float(P.ny), float(P.nz)));
}

vec3 dot_safe_normalize(vec3 v) {
  precise float l2 = v.x * v.x + v.y * v.y + v.z * v.z;
  precise vec3 r = v / sqrt(l2);
  return r;
}


// Outward unit normal from central differences (one voxel) of the trilinear field, in
// grid-world (index derivative times 1 / spacing): per axis, the trilinear interpolation at
// p's fractions of the cells one voxel up and down (= field(p +- e_a) but for rounding;
// the CPU reference's surface_normal). The six share 32 voxels around p's cell; p's cell
// lies in refine()'s block (the hit is in the bracket), so 20 of them are picked out of the
// block by selects and only the 12 of the three faces outside it are loaded (per axis, the
// face at -1 or +2 from p's cell, whichever the block lacks).
vec3 surface_normal_block(vec3 p) {
  vec3 fl = floor(p);
  ivec3 c = ivec3(fl);
  precise vec3 f = p - fl;
  ivec3 oc = clamp(c - g_b, ivec3(0), ivec3(1));  // 0 or 1 per axis (the clamp only guards)
  bool bx = oc.x == 1, by = oc.y == 1, bz = oc.z == 1;
  float fx00, fx01, fx10, fx11, fy00, fy01, fy10, fy11, fz00, fz01, fz10, fz11;
  if (QUADS) {  // the x face: 2 quads (components x, z); the y face: 2 (x, y); the z face: 1
    int xf = bx ? 2 : -1, yf = by ? 2 : -1, zf = bz ? 2 : -1;
    vec4 a = quad(c + ivec3(xf, 0, 0)), b = quad(c + ivec3(xf, 0, 1));
    fx00 = a.x; fx10 = a.z; fx01 = b.x; fx11 = b.z;
    a = quad(c + ivec3(0, yf, 0));
    b = quad(c + ivec3(0, yf, 1));
    fy00 = a.x; fy10 = a.y; fy01 = b.x; fy11 = b.y;
    a = quad(c + ivec3(0, 0, zf));
    fz00 = a.x; fz10 = a.y; fz01 = a.z; fz11 = a.w;
  } else {
    fx00 = voxel(c + ivec3((bx ? 2 : -1), 0, 0));
    fx01 = voxel(c + ivec3((bx ? 2 : -1), 0, 1));
    fx10 = voxel(c + ivec3((bx ? 2 : -1), 1, 0));
    fx11 = voxel(c + ivec3((bx ? 2 : -1), 1, 1));
    fy00 = voxel(c + ivec3(0, (by ? 2 : -1), 0));
    fy01 = voxel(c + ivec3(0, (by ? 2 : -1), 1));
    fy10 = voxel(c + ivec3(1, (by ? 2 : -1), 0));
    fy11 = voxel(c + ivec3(1, (by ? 2 : -1), 1));
    fz00 = voxel(c + ivec3(0, 0, (bz ? 2 : -1)));
    fz01 = voxel(c + ivec3(0, 1, (bz ? 2 : -1)));
    fz10 = voxel(c + ivec3(1, 0, (bz ? 2 : -1)));
    fz11 = voxel(c + ivec3(1, 1, (bz ? 2 : -1)));
  }
  float wm100 = bz ? (by ? (bx ? g_v011 : g_v010) : (bx ? g_v001 : g_v000)) : (by ? (bx ? fz00 : fz00) : (bx ? fz00 : fz00));
  float wm101 = bz ? (by ? (bx ? g_v012 : g_v011) : (bx ? g_v002 : g_v001)) : (by ? (bx ? fz10 : fz10) : (bx ? fz10 : fz10));
  float wm110 = bz ? (by ? (bx ? g_v021 : g_v020) : (bx ? g_v011 : g_v010)) : (by ? (bx ? fz01 : fz01) : (bx ? fz01 : fz01));
  float wm111 = bz ? (by ? (bx ? g_v022 : g_v021) : (bx ? g_v012 : g_v011)) : (by ? (bx ? fz11 : fz11) : (bx ? fz11 : fz11));
  float w0m10 = bz ? (by ? (bx ? g_v101 : g_v100) : (bx ? fy00 : fy00)) : (by ? (bx ? g_v001 : g_v000) : (bx ? fy00 : fy00));
  float w0m11 = bz ? (by ? (bx ? g_v102 : g_v101) : (bx ? fy10 : fy10)) : (by ? (bx ? g_v002 : g_v001) : (bx ? fy10 : fy10));
  float w00m1 = bz ? (by ? (bx ? g_v110 : fx00) : (bx ? g_v100 : fx00)) : (by ? (bx ? g_v010 : fx00) : (bx ? g_v000 : fx00));
  float w000 = bz ? (by ? (bx ? g_v111 : g_v110) : (bx ? g_v101 : g_v100)) : (by ? (bx ? g_v011 : g_v010) : (bx ? g_v001 : g_v000));
  float w001 = bz ? (by ? (bx ? g_v112 : g_v111) : (bx ? g_v102 : g_v101)) : (by ? (bx ? g_v012 : g_v011) : (bx ? g_v002 : g_v001));
  float w002 = bz ? (by ? (bx ? fx00 : g_v112) : (bx ? fx00 : g_v102)) : (by ? (bx ? fx00 : g_v012) : (bx ? fx00 : g_v002));
  float w01m1 = bz ? (by ? (bx ? g_v120 : fx10) : (bx ? g_v110 : fx10)) : (by ? (bx ? g_v020 : fx10) : (bx ? g_v010 : fx10));
  float w010 = bz ? (by ? (bx ? g_v121 : g_v120) : (bx ? g_v111 : g_v110)) : (by ? (bx ? g_v021 : g_v020) : (bx ? g_v011 : g_v010));
  float w011 = bz ? (by ? (bx ? g_v122 : g_v121) : (bx ? g_v112 : g_v111)) : (by ? (bx ? g_v022 : g_v021) : (bx ? g_v012 : g_v011));
  float w012 = bz ? (by ? (bx ? fx10 : g_v122) : (bx ? fx10 : g_v112)) : (by ? (bx ? fx10 : g_v022) : (bx ? fx10 : g_v012));
  float w020 = bz ? (by ? (bx ? fy00 : fy00) : (bx ? g_v121 : g_v120)) : (by ? (bx ? fy00 : fy00) : (bx ? g_v021 : g_v020));
  float w021 = bz ? (by ? (bx ? fy10 : fy10) : (bx ? g_v122 : g_v121)) : (by ? (bx ? fy10 : fy10) : (bx ? g_v022 : g_v021));
  float w1m10 = bz ? (by ? (bx ? g_v201 : g_v200) : (bx ? fy01 : fy01)) : (by ? (bx ? g_v101 : g_v100) : (bx ? fy01 : fy01));
  float w1m11 = bz ? (by ? (bx ? g_v202 : g_v201) : (bx ? fy11 : fy11)) : (by ? (bx ? g_v102 : g_v101) : (bx ? fy11 : fy11));
  float w10m1 = bz ? (by ? (bx ? g_v210 : fx01) : (bx ? g_v200 : fx01)) : (by ? (bx ? g_v110 : fx01) : (bx ? g_v100 : fx01));
  float w100 = bz ? (by ? (bx ? g_v211 : g_v210) : (bx ? g_v201 : g_v200)) : (by ? (bx ? g_v111 : g_v110) : (bx ? g_v101 : g_v100));
  float w101 = bz ? (by ? (bx ? g_v212 : g_v211) : (bx ? g_v202 : g_v201)) : (by ? (bx ? g_v112 : g_v111) : (bx ? g_v102 : g_v101));
  float w102 = bz ? (by ? (bx ? fx01 : g_v212) : (bx ? fx01 : g_v202)) : (by ? (bx ? fx01 : g_v112) : (bx ? fx01 : g_v102));
  float w11m1 = bz ? (by ? (bx ? g_v220 : fx11) : (bx ? g_v210 : fx11)) : (by ? (bx ? g_v120 : fx11) : (bx ? g_v110 : fx11));
  float w110 = bz ? (by ? (bx ? g_v221 : g_v220) : (bx ? g_v211 : g_v210)) : (by ? (bx ? g_v121 : g_v120) : (bx ? g_v111 : g_v110));
  float w111 = bz ? (by ? (bx ? g_v222 : g_v221) : (bx ? g_v212 : g_v211)) : (by ? (bx ? g_v122 : g_v121) : (bx ? g_v112 : g_v111));
  float w112 = bz ? (by ? (bx ? fx11 : g_v222) : (bx ? fx11 : g_v212)) : (by ? (bx ? fx11 : g_v122) : (bx ? fx11 : g_v112));
  float w120 = bz ? (by ? (bx ? fy01 : fy01) : (bx ? g_v221 : g_v220)) : (by ? (bx ? fy01 : fy01) : (bx ? g_v121 : g_v120));
  float w121 = bz ? (by ? (bx ? fy11 : fy11) : (bx ? g_v222 : g_v221)) : (by ? (bx ? fy11 : fy11) : (bx ? g_v122 : g_v121));
  float w200 = bz ? (by ? (bx ? fz00 : fz00) : (bx ? fz00 : fz00)) : (by ? (bx ? g_v211 : g_v210) : (bx ? g_v201 : g_v200));
  float w201 = bz ? (by ? (bx ? fz10 : fz10) : (bx ? fz10 : fz10)) : (by ? (bx ? g_v212 : g_v211) : (bx ? g_v202 : g_v201));
  float w210 = bz ? (by ? (bx ? fz01 : fz01) : (bx ? fz01 : fz01)) : (by ? (bx ? g_v221 : g_v220) : (bx ? g_v211 : g_v210));
  float w211 = bz ? (by ? (bx ? fz11 : fz11) : (bx ? fz11 : fz11)) : (by ? (bx ? g_v222 : g_v221) : (bx ? g_v212 : g_v211));
  precise vec3 g;
  g.x = (trilerp(w001, w002, w011, w012, w101, w102, w111, w112, f) -
         trilerp(w00m1, w000, w01m1, w010, w10m1, w100, w11m1, w110, f)) * 0.5;
  g.y = (trilerp(w010, w011, w020, w021, w110, w111, w120, w121, f) -
         trilerp(w0m10, w0m11, w000, w001, w1m10, w1m11, w100, w101, f)) * 0.5;
  g.z = (trilerp(w100, w101, w110, w111, w200, w201, w210, w211, f) -
         trilerp(wm100, wm101, wm110, wm111, w000, w001, w010, w011, f)) * 0.5;
  precise vec3 gw = g * vec3(P.inv_sp_x, P.inv_sp_y, P.inv_sp_z) * (-P.inside_sign);
  precise float l2 = gw.x * gw.x + gw.y * gw.y + gw.z * gw.z;
  if (!(l2 > 0.0)) return vec3(0.0);
  return dot_safe_normalize(gw);
}

// Headlight from the upper left of the camera; two-sided; Lambert + ambient + specular;
// sqrt as display gamma.
vec3 shade(vec3 albedo, vec3 n, vec3 dir) {
  vec3 fwd = vec3(P.fwd_x, P.fwd_y, P.fwd_z), up = vec3(P.up_x, P.up_y, P.up_z);
  vec3 right = vec3(P.right_x, P.right_y, P.right_z);
  precise vec3 lsum = -fwd + 0.5 * up - 0.35 * right;
  vec3 l = dot_safe_normalize(lsum);
  precise float facing = n.x * dir.x + n.y * dir.y + n.z * dir.z;
  vec3 nn = facing > 0.0 ? -n : n;
  precise float lam = max(nn.x * l.x + nn.y * l.y + nn.z * l.z, 0.0);
  precise vec3 hv = l - dir;
  vec3 hn = dot_safe_normalize(hv);
  precise float sp = max(nn.x * hn.x + nn.y * hn.y + nn.z * hn.z, 0.0);
  sp = sp * sp;
  sp = sp * sp;
  sp = sp * sp;
  sp = sp * sp;
  sp = sp * sp;  // ^32
  precise vec3 c = albedo * (0.18 + 0.82 * lam) + vec3(0.25 * sp);
  return c;
}

// R, G, B, A from the low byte; B, G, R, A with the BGRA flag (a swapchain's order).
uint pack_rgba(vec3 c) {
  vec3 g = sqrt(clamp(c, 0.0, 1.0));
  uvec3 u = uvec3(g * 255.0 + 0.5);
  bool bgra = (pc.flags & ISOTOUCH_RAYCAST_BGRA) != 0u;
  return (bgra ? u.b : u.r) | (u.g << 8) | ((bgra ? u.r : u.b) << 16) | (255u << 24);
}

// Primitive intersection in a local frame: origin moved along the ray to the point
// nearest the primitive's centre, lengths divided by the radius (well conditioned in
// float at millimetre sizes and metre distances). Returns (t [m], unit normal) or t < 0.
// `kind` stands for q.kind: a constant there (the overlay's stage pipelines, one per kind) leaves
// only that kind's code (on llvmpipe every arm of an `if` runs, masked).
vec4 intersect_prim_as(RaycastPrim q, vec3 ro, vec3 rd, uint kind) {
  vec3 a = vec3(q.ax, q.ay, q.az), b = vec3(q.bx, q.by, q.bz);
  bool two_points = kind == ISOTOUCH_RAYCAST_PRIM_CAPSULE || kind == ISOTOUCH_RAYCAST_PRIM_CONE;
  precise vec3 centre = two_points ? 0.5 * (a + b) : a;
  precise vec3 oc = centre - ro;
  precise float tc = oc.x * rd.x + oc.y * rd.y + oc.z * rd.z;
  precise vec3 ro2 = ro + tc * rd;
  float s = q.r0;
  precise vec3 al = (a - ro2) / s;
  precise vec3 bl = two_points ? (b - ro2) / s : b;
  precise vec3 cl = (centre - ro2) / s;
  precise float bound = two_points ? 0.5 * length(bl - al) + 1.0 : 1.0;
  if (dot(cl, cl) > bound * bound) return vec4(-1.0);
  precise float tl = -1.0;
  precise vec3 n = vec3(0.0);
  if (kind == ISOTOUCH_RAYCAST_PRIM_SPHERE) {
    precise float bb = -dot(al, rd);
    precise float c = dot(al, al) - 1.0;
    precise float h = bb * bb - c;
    if (h < 0.0) return vec4(-1.0);
    tl = -bb - sqrt(h);
    n = tl * rd - al;
  } else if (kind == ISOTOUCH_RAYCAST_PRIM_DISC) {
    precise float den = dot(rd, bl);
    if (abs(den) < 1e-6) return vec4(-1.0);
    tl = dot(al, bl) / den;
    precise vec3 r = tl * rd - al;
    if (dot(r, r) > 1.0) return vec4(-1.0);
    n = bl;
  } else if (kind == ISOTOUCH_RAYCAST_PRIM_CAPSULE) {
    precise vec3 ba = bl - al, oa = -al;
    precise float baba = dot(ba, ba), bard = dot(ba, rd), baoa = dot(ba, oa);
    precise float rdoa = dot(rd, oa), oaoa = dot(oa, oa);
    precise float qa = baba - bard * bard;
    precise float qb = baba * rdoa - baoa * bard;
    precise float qc = baba * oaoa - baoa * baoa - baba;
    precise float h = qb * qb - qa * qc;
    if (h < 0.0) return vec4(-1.0);
    tl = qa > 0.0 ? (-qb - sqrt(h)) / qa : -1.0;
    precise float y = baoa + tl * bard;
    if (!(qa > 0.0) || y <= 0.0 || y >= baba) {
      precise vec3 o2 = y <= 0.0 ? oa : -bl;
      precise float b2 = dot(rd, o2);
      precise float c2 = dot(o2, o2) - 1.0;
      precise float h2 = b2 * b2 - c2;
      if (h2 <= 0.0) return vec4(-1.0);
      tl = -b2 - sqrt(h2);
    }
    precise vec3 p = tl * rd;
    precise float u = clamp(dot(p - al, ba) / baba, 0.0, 1.0);
    n = p - (al + u * ba);
  } else if (kind == ISOTOUCH_RAYCAST_PRIM_CONE) {
    // Capped cone, radius 1 at a, 0 at b (the apex); the base disc closes it.
    precise vec3 ba = bl - al, oa = -al, ob = -bl;
    precise float m0 = dot(ba, ba), m1 = dot(oa, ba), m2 = dot(rd, ba), m3 = dot(rd, oa);
    precise float m5 = dot(oa, oa);
    bool done = false;
    if (m1 < 0.0) {
      precise vec3 w = oa * m2 - rd * m1;
      if (dot(w, w) < m2 * m2) {
        tl = -m1 / m2;
        n = -ba;
        done = true;
      }
    }
    if (!done) {
      precise float hy = m0 + 1.0;
      precise float k2 = m0 * m0 - m2 * m2 * hy;
      precise float k1 = m0 * m0 * m3 - m1 * m2 * hy + m0 * m2;
      precise float k0 = m0 * m0 * m5 - m1 * m1 * hy + m0 * (2.0 * m1 - m0);
      precise float h = k1 * k1 - k2 * k0;
      if (h < 0.0 || k2 == 0.0) return vec4(-1.0);
      tl = (-k1 - sqrt(h)) / k2;
      precise float y = m1 + tl * m2;
      if (y < 0.0 || y > m0) return vec4(-1.0);
      n = m0 * (m0 * (oa + tl * rd) + ba) - ba * hy * y;
    }
  } else {
    return vec4(-1.0);
  }
  precise float t = tc + tl * s;
  if (!(t > 0.0)) return vec4(-1.0);
  return vec4(t, dot_safe_normalize(n));
}
vec4 intersect_prim(RaycastPrim q, vec3 ro, vec3 rd) { return intersect_prim_as(q, ro, rd, q.kind); }

void init_globals() {
  g_bg = P.background;
  g_tau = P.tau;
  g_sign = P.inside_sign;
}

// One pixel's ray: unit direction `dir` and eye in grid-world [m]; e, d in index space;
// [t0, t1] its part in the box and the kept half-space (t0 > t1: none); cap_entry: t0 is on
// the clip plane; h the lattice step [m]; K the last lattice sample.
struct Ray {
  vec3 eye, dir, e, d;
  float t0, t1, h, dl;
  int K;
  bool cap_entry;
};

Ray make_ray(uvec2 px) {
  Ray r;
  r.eye = vec3(P.eye_x, P.eye_y, P.eye_z);
  vec3 fwd = vec3(P.fwd_x, P.fwd_y, P.fwd_z), right = vec3(P.right_x, P.right_y, P.right_z);
  vec3 up = vec3(P.up_x, P.up_y, P.up_z);
  precise float sx = (float(px.x) + 0.5) - 0.5 * float(P.width);
  precise float sy = 0.5 * float(P.height) - (float(px.y) + 0.5);
  precise vec3 dsum = fwd * P.focal_px + right * sx + up * sy;
  r.dir = dot_safe_normalize(dsum);
  vec3 inv_sp = vec3(P.inv_sp_x, P.inv_sp_y, P.inv_sp_z);
  precise vec3 e = (r.eye - vec3(P.origin_x, P.origin_y, P.origin_z)) * inv_sp;
  precise vec3 d = r.dir * inv_sp;
  r.e = e;
  r.d = d;

  // The ray's interval in the box and the kept half-space.
  vec2 ti = box_interval(e, d);
  r.t0 = ti.x;
  r.t1 = ti.y;
  r.cap_entry = false;
  if ((pc.flags & ISOTOUCH_RAYCAST_CLIP) != 0u) {
    vec3 cn = vec3(P.clip_nx, P.clip_ny, P.clip_nz);
    precise float g0 = cn.x * r.eye.x + cn.y * r.eye.y + cn.z * r.eye.z + P.clip_d;
    precise float gd = cn.x * r.dir.x + cn.y * r.dir.y + cn.z * r.dir.z;
    if (gd == 0.0) {
      if (g0 > 0.0) r.t1 = -1.0;
    } else {
      precise float tp = -g0 / gd;
      if (gd > 0.0) r.t1 = min(r.t1, tp);
      else if (tp >= r.t0) {
        r.t0 = tp;
        r.cap_entry = true;
      }
    }
  }
  precise float dl = sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
  r.dl = dl;
  precise float h = P.step_vox / dl;
  r.h = h;
  // The host bounds the samples per ray (make_params); the min only guards the loops.
  r.K = int(min(ceil((r.t1 - r.t0) / h), float(ISOTOUCH_RAYCAST_MAX_SAMPLES)));
  return r;
}

// Refines the hit at lattice sample k of ray r in the bracket [t_{k-1}, t_k] (sample 0:
// t0, no refinement), shades it and writes pixel pix's colour and depth (and its linear
// colour with write_linear: the overlay pass blends into it). The cut face (cap: sample 0
// on the clip plane) is flat: the clip plane's normal, cap colour.
void shade_hit(Ray r, uint pix, int k, bool cap, bool write_linear) {
#ifdef ISOTOUCH_COUNT_FETCHES
  uint before = g_fetches, before_lanes = g_vector_fetches;
#endif
  // Sample 0 has no bracket: refine() of [t0, t0] returns t0 (and loads the block around it,
  // which the normal reads). Unconditional: on llvmpipe an `if` would not skip it anyway.
  float ta = k > 0 ? lattice_t(r.t0, r.t1, r.h, k - 1) : r.t0;
  float tb = k > 0 ? lattice_t(r.t0, r.t1, r.h, k) : r.t0;
  float t_hit = refine(r.e, r.d, ta, tb);
  // One shade() of whichever normal applies (on llvmpipe both arms of an `if` run, so two
  // calls would cost two).
  vec3 n = surface_normal_block(ray_point(r.e, r.d, t_hit));  // the block holds the hit's cell
  vec3 albedo = vec3(P.surf_r, P.surf_g, P.surf_b);
  if (cap) {
    n = vec3(P.clip_nx, P.clip_ny, P.clip_nz);
    albedo = vec3(P.cap_r, P.cap_g, P.cap_b);
  }
  vec3 colour = shade(albedo, n, r.dir);
  depth[pix] = t_hit;
  if (write_linear) {
    lin_r[pix] = colour.r;
    lin_g[pix] = colour.g;
    lin_b[pix] = colour.b;
  }
  image[pix] = pack_rgba(colour);
#ifdef ISOTOUCH_COUNT_FETCHES
  g_shade_fetches += g_fetches - before;
  g_shade_vector_fetches += g_vector_fetches - before_lanes;
  ++g_shaded;
#endif
}

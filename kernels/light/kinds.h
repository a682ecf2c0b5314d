// The kinds of light source: one list, shared by the scene (src/scene/scene.h's Light is a
// LightShape) and the kernels. Each kind keeps all of its own code in one file,
// light/kinds/<name>.h, as LightKindOps<kind>: how a point or direction on it is drawn
// from a shading point and with what density, which side of it emits, its power and its
// bounds for the light BVH. light/dispatch.h runs a kernel over the kinds a batch of lanes
// holds, as bsdf/material.h's for_each_local does for the BSDFs; docs/DESIGN.md ("Adding a
// light kind") lists the steps of a new one.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>

#include "lanes/vec.h"

namespace tuile {

enum class LightKind : int32_t {
  triangle = 0,       // p0, p0 + e1, p0 + e2
  parallelogram = 1,  // p0 + u e1 + v e2, u, v in [0, 1]
  sphere = 2,         // centre p0, radius in e1.x
  point = 3,          // position p0, intensity in the radiance
  spot = 4,           // position p0, axis e1 (unit), cos of the cone's falloff start / end in e2.x / e2.y
  distant = 5,        // towards the light is e1 (unit), irradiance in the radiance
  infinite = 6,       // the sky: radiance from every direction at infinity; its frame's axes e1 (x), e2 (y), p0 (z)
};
inline constexpr int light_kind_count = 7;

// Which kinds of source a pipeline can meet (wave/features.h), as bits: the code of the
// other kinds is removed at compile time. Each kind belongs to one group (kind_area: it
// has a surface and a density; kind_delta: it is sampled by a single direction; kind_sky:
// a density over the directions at infinity, found by the rays that escape the scene).
// kind_rects (with kind_area alone): every source is a rectangle, so the light stages run
// Urena's map without dispatching on the kind of source (the same values as kind_area).
// kind_finite: every group but the sky (the pipelines of scenes without one).
inline constexpr unsigned kind_area = 1, kind_delta = 2, kind_rects = 4, kind_sky = 8;
inline constexpr unsigned kind_finite = kind_area | kind_delta, kind_all = kind_area | kind_delta | kind_sky;

struct LightKindInfo {
  const char* name;
  unsigned group;    // kind_area, kind_delta or kind_sky
  bool planar;       // emits from a plane, on the side of cross(e1, e2) unless two-sided
  bool at_infinity;  // its directions come from infinitely far away (no position)
};
inline constexpr LightKindInfo light_kind_info[light_kind_count] = {
    {"triangle", kind_area, true, false}, {"parallelogram", kind_area, true, false}, {"sphere", kind_area, false, false},
    {"point", kind_delta, false, false},  {"spot", kind_delta, false, false},         {"distant", kind_delta, false, true},
    {"infinite", kind_sky, false, true},
};
constexpr const LightKindInfo& kind_info(LightKind k) { return light_kind_info[static_cast<int>(k)]; }
constexpr bool is_delta(LightKind k) { return kind_info(k).group == kind_delta; }
constexpr bool is_planar(LightKind k) { return kind_info(k).planar; }
// A light at infinity with a density over directions: seen by rays that leave the scene.
constexpr bool is_sky(LightKind k) { return kind_info(k).group == kind_sky; }

// A source's shape as the scene states it (its radiance and where it came from are the
// scene's: Light in src/scene/scene.h).
struct LightShape {
  LightKind type = LightKind::point;
  vec3f p0{0, 0, 0}, e1{0, 0, 0}, e2{0, 0, 0};
  bool two_sided = false;
  float area = 0;  // of the emitting surface (0 for delta lights)
};

// What the light BVH (src/render/light_bvh.cpp) needs of a source: a box around it, the
// cone of its emitting normals (axis w, spread cos_o, emission spread cos_e beyond it) and
// its power phi (with the largest channel of its radiance, as pbrt-v4's LightBounds).
struct LightBounds {
  vec3f lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
  vec3f w{0, 0, 1};
  double cos_o = 1, cos_e = 0, phi = 0;
  bool two_sided = false;
  void grow(const vec3f& q) {
    lo = {std::min(lo.x, q.x), std::min(lo.y, q.y), std::min(lo.z, q.z)};
    hi = {std::max(hi.x, q.x), std::max(hi.y, q.y), std::max(hi.z, q.z)};
  }
};

// Each kind's code; the specialisations are in light/kinds/<name>.h.
template <LightKind K> struct LightKindOps;

}  // namespace tuile

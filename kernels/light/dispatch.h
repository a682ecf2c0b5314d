// Running light code over the kinds of source a batch of lanes holds, as the BSDFs'
// for_each_local does (bsdf/material.h): for_each_light_kind calls f(ops, mask) once for
// each kind present among the lanes (ops: its LightKindOps, mask: its lanes). The masks of
// two kinds are disjoint, so what f merges with sel() does not depend on the order.
// with_light_kind does the same for one scalar source (scene set-up, the light BVH).
#pragma once
#include <utility>

#include "light/kinds/distant.h"
#include "light/kinds/infinite.h"
#include "light/kinds/parallelogram.h"
#include "light/kinds/point.h"
#include "light/kinds/sphere.h"
#include "light/kinds/spot.h"
#include "light/kinds/triangle.h"

namespace tuile {

template <class T> inline mask_t<T> kind_is(const i32_t<T>& type, LightKind k) {
  return type_is<T>(type, static_cast<int32_t>(k));
}

// The kinds with a surface among the groups of Kinds (and the rectangle-only flag).
constexpr unsigned area_kinds(unsigned kinds) { return kinds & (kind_area | kind_rects); }

template <unsigned Kinds, LightKind K, class T, class F> inline void visit_light_kind(const i32_t<T>& type, F& f) {
  if constexpr ((kind_info(K).group & Kinds) != 0) {
    const mask_t<T> m = kind_is<T>(type, K);
    if (any(m)) f(LightKindOps<K>{}, m);
  }
}

// The lanes' kinds are g.type. Kinds: the groups a pipeline can meet (kind_area,
// kind_delta, kind_sky); with kind_rects every source is a rectangle and f runs once, with
// RectangleLight over every lane (no test of the kind).
template <unsigned Kinds, class T, class F> inline void for_each_light_kind(const LightGeom<T>& g, F&& f) {
  if constexpr ((Kinds & kind_rects) != 0) {
    f(RectangleLight{}, mask_t<T>(true));
  } else {
    [&]<int... K>(std::integer_sequence<int, K...>) {
      (visit_light_kind<Kinds, static_cast<LightKind>(K), T>(g.type, f), ...);
    }(std::make_integer_sequence<int, light_kind_count>{});
  }
}

// for_each_light_kind for the code the planar kinds share (PlanarLight: which side emits,
// the cosine at the source, the normal at a point): triangles and parallelograms run once,
// together, as PlanarLight (the same expressions, so the same bits), then each other kind.
template <unsigned Kinds, class T, class F> inline void for_each_light_shape(const LightGeom<T>& g, F&& f) {
  if constexpr ((Kinds & kind_rects) != 0) {
    f(RectangleLight{}, mask_t<T>(true));
  } else {
    if constexpr ((Kinds & kind_area) != 0) {
      const mask_t<T> planar = kind_is<T>(g.type, LightKind::triangle) || kind_is<T>(g.type, LightKind::parallelogram);
      if (any(planar)) f(PlanarLight{}, planar);
      visit_light_kind<Kinds, LightKind::sphere, T>(g.type, f);
    }
    visit_light_kind<Kinds, LightKind::point, T>(g.type, f);
    visit_light_kind<Kinds, LightKind::spot, T>(g.type, f);
    visit_light_kind<Kinds, LightKind::distant, T>(g.type, f);
    visit_light_kind<Kinds, LightKind::infinite, T>(g.type, f);
  }
}
static_assert(light_kind_count == 7, "for_each_light_shape names every kind");

// Each kind's code agrees with the list about what it is.
template <int... K> constexpr bool kinds_agree(std::integer_sequence<int, K...>) {
  return ((LightKindOps<static_cast<LightKind>(K)>::planar == kind_info(static_cast<LightKind>(K)).planar &&
           LightKindOps<static_cast<LightKind>(K)>::at_infinity == kind_info(static_cast<LightKind>(K)).at_infinity &&
           LightKindOps<static_cast<LightKind>(K)>::kind == static_cast<LightKind>(K)) &&
          ...);
}
static_assert(kinds_agree(std::make_integer_sequence<int, light_kind_count>{}), "light/kinds.h and LightKindOps disagree");

// f(LightKindOps<k>{}) for one source's kind k.
template <class F> inline decltype(auto) with_light_kind(LightKind k, F&& f) {
  switch (k) {
    case LightKind::triangle: return f(LightKindOps<LightKind::triangle>{});
    case LightKind::parallelogram: return f(LightKindOps<LightKind::parallelogram>{});
    case LightKind::sphere: return f(LightKindOps<LightKind::sphere>{});
    case LightKind::point: return f(LightKindOps<LightKind::point>{});
    case LightKind::spot: return f(LightKindOps<LightKind::spot>{});
    case LightKind::distant: return f(LightKindOps<LightKind::distant>{});
    case LightKind::infinite: break;
  }
  return f(LightKindOps<LightKind::infinite>{});
}
static_assert(light_kind_count == 7, "with_light_kind names every kind");

// A source's power (lum: its radiance's luminance; scene_radius: of the scene's bounding
// sphere, for sources at infinity).
inline float light_power(const LightShape& l, float lum, float scene_radius) {
  return with_light_kind(l.type, [&](auto ops) { return ops.power(l, lum, scene_radius); });
}
// A source's bounds for the light BVH (L: the largest channel of its radiance); false for
// a source the tree leaves out (at infinity, or degenerate).
inline bool light_bounds(const LightShape& l, double L, LightBounds& b) {
  return with_light_kind(l.type, [&](auto ops) { return ops.bounds(l, L, b); });
}

// Whether a ray from o travelling along d sees the emitting side of light l (read from the
// table): one-sided planar sources emit on the side of their normal, spheres outwards (a ray
// starting inside a sphere light sees no emission, as in pbrt-v4). Spheres: false when no
// source is a sphere (the planar test alone, the same answer).
template <class T, bool Spheres = true, int Tier = tier_gather>
inline mask_t<T> light_front_lanes(const LightView& L, const i32_t<T>& l, const Vec3<T>& o, const Vec3<T>& d) {
  if constexpr (Tier == tier_gather && !std::is_same_v<T, float>) {  // permutes of small and medium tables
    if (L.tier == tier_small) return light_front_lanes<T, Spheres, tier_small>(L, l, o, d);
    if (L.tier == tier_medium) return light_front_lanes<T, Spheres, tier_medium>(L, l, o, d);
  }
  auto front = PlanarLight::faces(d, Vec3<T>{lget<Tier>(L.nx, l), lget<Tier>(L.ny, l), lget<Tier>(L.nz, l)});
  if (L.any_two_sided) front = front || lget<Tier>(L.two_sided, l) > T(0.f);
  if constexpr (!Spheres) return front;
  const Vec3<T> c = o - Vec3<T>{lget<Tier>(L.p0x, l), lget<Tier>(L.p0y, l), lget<Tier>(L.p0z, l)};
  const auto sphere = f_mask_from_i(lget<Tier>(L.type, l) == i32_t<T>(static_cast<int32_t>(LightKind::sphere)));
  return sel_mask(sphere, LightKindOps<LightKind::sphere>::seen_from_outside(c, lget<Tier>(L.e1x, l)), front);
}
inline bool light_front(const LightView& L, int32_t l, float ox, float oy, float oz, float dx, float dy, float dz) {
  return light_front_lanes<float>(L, l, {ox, oy, oz}, {dx, dy, dz});
}

}  // namespace tuile

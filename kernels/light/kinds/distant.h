// Distant sources (towards the light is the unit e1; irradiance E in the radiance): one
// direction from everywhere, at infinity. pbrt-v4's power, pi r^2 E over the disc of the
// scene's bounding sphere; not in the light BVH (its pickers give it its power's share).
#pragma once
#include "light/kinds/common.h"

namespace tuile {

template <> struct LightKindOps<LightKind::distant> {
  static constexpr LightKind kind = LightKind::distant;
  static constexpr bool planar = false, at_infinity = true;
  // the distance of a point at infinity, as far as a ray can go
  static constexpr float infinite_distance = 3.0e38f;
  template <class T> static DeltaSample<T> sample_delta(const LightGeom<T>& g, const Vec3<T>&) {
    DeltaSample<T> s;
    s.wi = g.e1;
    s.dist = T(infinite_distance);
    s.scale = T(1.f);
    s.valid = mask_t<T>(true);
    return s;
  }
  template <class T> static Vec3<T> endpoint_normal(const LightGeom<T>&, const Vec3<T>&, const Vec3<T>&) {
    return Vec3<T>(T(0.f), T(0.f), T(0.f));
  }
  static float power(const LightShape&, float lum, float scene_radius) {
    return 3.14159265f * scene_radius * scene_radius * lum;
  }
  static bool bounds(const LightShape&, double, LightBounds&) { return false; }
};

}  // namespace tuile

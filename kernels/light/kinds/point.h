// Point sources (position p0, intensity I in the radiance): the one direction to p0, with
// the intensity falling off as 1/d^2 (pbrt-v4's PointLight). power 4 pi I.
#pragma once
#include "light/kinds/common.h"

namespace tuile {

struct PositionalLight {
  static constexpr bool planar = false, at_infinity = false;
  // The direction from x to the source's position, its distance and 1/d^2.
  template <class T> static DeltaSample<T> towards(const LightGeom<T>& g, const Vec3<T>& x) {
    DeltaSample<T> s;
    const Vec3<T> dp = g.p0 - x;
    const T d2 = length_sq(dp);
    const T dd = sqrt(d2);
    s.wi = dp * (T(1.f) / sel(dd > T(0.f), dd, T(1.f)));
    s.dist = dd;
    s.scale = T(1.f) / max(d2, T(1e-30f));
    s.valid = dd > T(0.f);
    return s;
  }
  // the shadow ray ends at the position itself: no offset
  template <class T> static Vec3<T> endpoint_normal(const LightGeom<T>&, const Vec3<T>&, const Vec3<T>&) {
    return Vec3<T>(T(0.f), T(0.f), T(0.f));
  }
  // in the light BVH: a point with emission in every direction
  static bool point_bounds(const LightShape& l, LightBounds& b) {
    b.grow(l.p0);
    b.cos_o = -1;
    b.cos_e = 0;
    return true;
  }
};

template <> struct LightKindOps<LightKind::point> : PositionalLight {
  static constexpr LightKind kind = LightKind::point;
  template <class T> static DeltaSample<T> sample_delta(const LightGeom<T>& g, const Vec3<T>& x) { return towards(g, x); }
  static float power(const LightShape&, float lum, float) { return 4.f * 3.14159265f * lum; }
  static bool bounds(const LightShape& l, double L, LightBounds& b) {
    point_bounds(l, b);
    b.phi = 4 * light_pi * L;
    return true;
  }
};

}  // namespace tuile

// Spot sources (position p0, unit axis e1, the cosines of the falloff's start and of the
// cone's edge in e2.x and e2.y): a point source whose intensity falls off by pbrt-v4's
// smoothstep between the two cosines.
#pragma once
#include "light/kinds/point.h"

namespace tuile {

template <> struct LightKindOps<LightKind::spot> : PositionalLight {
  static constexpr LightKind kind = LightKind::spot;
  template <class T> static DeltaSample<T> sample_delta(const LightGeom<T>& g, const Vec3<T>& x) {
    DeltaSample<T> s = towards(g, x);
    // pbrt-v4's falloff: smoothstep between cos(total) and cos(falloff start)
    const T cos_t = -dot(s.wi, g.e1);
    const T c0 = g.e2.y, c1 = g.e2.x;
    T t = (cos_t - c0) / max(c1 - c0, T(1e-12f));
    t = min(T(1.f), max(T(0.f), t));
    s.scale = s.scale * t * t * (T(3.f) - T(2.f) * t);
    return s;
  }
  // 2 pi I (1 - (cos_start + cos_end) / 2), pbrt-v4's
  static float power(const LightShape& l, float lum, float) {
    return 2.f * 3.14159265f * lum * (1.f - 0.5f * (l.e2.x + l.e2.y));
  }
  static bool bounds(const LightShape& l, double L, LightBounds& b) {
    b.grow(l.p0);
    b.w = l.e1;
    const double cs = std::clamp(double(l.e2.x), -1.0, 1.0), ce = std::clamp(double(l.e2.y), -1.0, 1.0);
    b.cos_o = cs;
    b.cos_e = std::cos(std::acos(ce) - std::acos(cs));
    b.phi = 4 * light_pi * L;  // pbrt-v4's (an overestimate, as its comment says)
    return true;
  }
};

}  // namespace tuile

// The sky (LightSource "infinite"): radiance arriving from every direction at infinity.
// Today a constant radiance (the table's), drawn uniformly over the sphere of directions
// with density 1 / (4 pi); an environment map is the same kind with a direction-dependent
// radiance and density (its own sample_direction, pdf_direction and radiance). It has no
// surface that a ray can hit: a ray that leaves the scene sees it (wave/escaped.h, which
// weights it against the density below). Power: pbrt-v4's 4 pi * pi r^2 L over the disc
// of the scene's bounding sphere; not in the light BVH (its pickers give it its power's
// share, as a distant source's).
#pragma once
#include "light/kinds/common.h"
#include "sample/sampling.h"

namespace tuile {

// A direction drawn towards a light at infinity and its density in solid angle.
template <class T> struct SkySample {
  Vec3<T> wi;
  T pdf;
};

template <> struct LightKindOps<LightKind::infinite> {
  static constexpr LightKind kind = LightKind::infinite;
  static constexpr bool planar = false, at_infinity = true;
  template <class T> static SkySample<T> sample_direction(const LightGeom<T>&, const T& u1, const T& u2) {
    return {sample_uniform_sphere(u1, u2), T(inv_4pi_f)};
  }
  // The density sample_direction gives the direction wi.
  template <class T> static T pdf_direction(const LightGeom<T>&, const Vec3<T>&) { return T(inv_4pi_f); }
  // the shadow ray goes as far as a ray can: no end point to offset
  template <class T> static Vec3<T> endpoint_normal(const LightGeom<T>&, const Vec3<T>&, const Vec3<T>&) {
    return Vec3<T>(T(0.f), T(0.f), T(0.f));
  }
  static float power(const LightShape&, float lum, float scene_radius) {
    return 4.f * 3.14159265f * 3.14159265f * scene_radius * scene_radius * lum;
  }
  static bool bounds(const LightShape&, double, LightBounds&) { return false; }
};

}  // namespace tuile

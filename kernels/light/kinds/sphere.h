// Sphere sources (centre p0, radius e1.x, emitting outwards): directions uniform in the
// cone the sphere subtends from x (pbrt-v4's Sphere::Sample with a reference point), points
// uniform by area where x is inside or the cone is degenerate. A ray starting inside sees
// no emission, as in pbrt-v4.
#pragma once
#include "light/kinds/common.h"

namespace tuile {

template <> struct LightKindOps<LightKind::sphere> {
  static constexpr LightKind kind = LightKind::sphere;
  static constexpr bool planar = false, at_infinity = false;

  template <class T> static T radius(const LightGeom<T>& g) { return g.e1.x; }
  template <class T> static SolidAngleSample<T> sample_solid_angle(const LightGeom<T>& g, const Vec3<T>& x, T u1, T u2) {
    SolidAngleSample<T> s;
    T pdf;
    s.ok = sample_sphere_cone(x, g.p0, radius(g), u1, u2, s.dir, pdf);
    s.omega = sphere_cone_solid_angle(x, g.p0, radius(g));
    s.safe = s.omega > T(0.f);
    // the nearer root along dir, computed stably
    const Vec3<T> oc = x - g.p0;
    const T bq = dot(oc, s.dir);
    const T cq = length_sq(oc) - g.e1.x * g.e1.x;
    const T disc = max(T(0.f), bq * bq - cq);
    s.t = cq / max(-bq + sqrt(disc), T(1e-30f));
    return s;
  }
  template <class T> static SolidAngle<T> solid_angle(const LightGeom<T>& g, const Vec3<T>& x) {
    const T omega = sphere_cone_solid_angle(x, g.p0, radius(g));
    return {omega, omega > T(0.f)};
  }
  template <class T> static Vec3<T> area_point(const LightGeom<T>& g, T u1, T u2) {
    return sample_sphere_area(g.p0, radius(g), u1, u2);
  }
  // the cosine at y = x + wi dist from the outward normal
  template <class T> static T emit_cos(const LightGeom<T>& g, const Vec3<T>& x, const Vec3<T>& wi, T dist) {
    const Vec3<T> y = x + wi * dist;
    return -dot(wi, (y - g.p0)) / max(g.e1.x, T(1e-30f));
  }
  template <class T> static mask_t<T> lit_from(const LightGeom<T>&, const Vec3<T>&) { return mask_t<T>(true); }
  // A ray from o sees the outside (c: o minus the centre, r: the radius).
  template <class T> static mask_t<T> seen_from_outside(const Vec3<T>& c, const T& r) { return dot(c, c) > r * r; }
  // the outward normal at y; a point at the centre of a tiny sphere falls back to -wi
  template <class T> static Vec3<T> endpoint_normal(const LightGeom<T>& g, const Vec3<T>& y, const Vec3<T>& wi) {
    const Vec3<T> rel = y - g.p0;
    const T rl = length(rel);
    const auto good = rl > T(0.f) && is_finite(rl);
    return sel(good, rel * (T(1.f) / sel(good, rl, T(1.f))), -wi);
  }
  static float power(const LightShape& l, float lum, float) { return lum * 3.14159265f * l.area; }
  static bool bounds(const LightShape& l, double L, LightBounds& b) {
    const float r = l.e1.x;
    b.grow(l.p0 - vec3f{r, r, r});
    b.grow(l.p0 + vec3f{r, r, r});
    b.cos_o = -1;
    b.cos_e = 0;
    b.phi = L * 4 * light_pi * double(r) * r * light_pi;
    return true;
  }
};

}  // namespace tuile

// Triangle sources (p0, p0 + e1, p0 + e2; emitting on the side of cross(e1, e2) unless
// two-sided): Arvo's spherical triangle for directions uniform in their solid angle,
// barycentric points uniform by area.
#pragma once
#include "light/kinds/common.h"

namespace tuile {

template <> struct LightKindOps<LightKind::triangle> : PlanarLight {
  static constexpr LightKind kind = LightKind::triangle;

  template <class T> static SolidAngleSample<T> sample_solid_angle(const LightGeom<T>& g, const Vec3<T>& x, T u1, T u2) {
    SolidAngleSample<T> s;
    const SphericalTriangle<T> st = spherical_triangle_setup(x, g.p0, g.p0 + g.e1, g.p0 + g.e2);
    T pdf;
    s.ok = sample_spherical_triangle(st, u1, u2, s.dir, pdf);
    s.omega = st.omega;
    s.safe = solid_angle_safe(g, x, s.omega, 1.f / 3.f);
    s.t = plane_distance(g, x, s.dir);
    return s;
  }
  template <class T> static SolidAngle<T> solid_angle(const LightGeom<T>& g, const Vec3<T>& x) {
    const T omega = spherical_triangle_solid_angle(x, g.p0, g.p0 + g.e1, g.p0 + g.e2);
    return {omega, solid_angle_safe(g, x, omega, 1.f / 3.f)};
  }
  template <class T> static Vec3<T> area_point(const LightGeom<T>& g, T u1, T u2) {
    T b1, b2;
    sample_triangle_area(u1, u2, b1, b2);
    return g.p0 + g.e1 * b1 + g.e2 * b2;
  }
  static float power(const LightShape& l, float lum, float) { return PlanarLight::power(l, lum); }
  static bool bounds(const LightShape& l, double L, LightBounds& b) {
    const vec3f corners[3] = {l.p0, l.p0 + l.e1, l.p0 + l.e2};
    return PlanarLight::bounds(l, L, corners, b);
  }
};

}  // namespace tuile

// Parallelogram sources (p0 + u e1 + v e2, u, v in [0, 1]; emitting on the side of
// cross(e1, e2) unless two-sided). Those with orthogonal edges (LightGeom::rect, from
// light_geom_derive) are rectangles, sampled by Urena et al.'s spherical rectangle map from
// their unit edges and lengths (RectangleLight; pipelines whose sources are all rectangles
// use it alone); the others by the spherical parallelogram map (sample/spherical.h).
#pragma once
#include "light/kinds/common.h"

namespace tuile {

// A rectangle: the frame of its map (its centre at ((x0 + x1) / 2, (y0 + y1) / 2, z0) from
// x, its plane at distance |z0|) decides the fallback rule; Omega is 0 where the setup
// failed, so such lanes fall back too. Rectangles stay in solid angle up to the hemisphere:
// Urena's map stays accurate there, while area sampling of a source that fills the
// hemisphere has enormous variance (tests/test_stress.cpp near-light cases).
struct RectangleLight : PlanarLight {
  static constexpr LightKind kind = LightKind::parallelogram;
  template <class T> static mask_t<T> safe(const SphericalRectangle<T>& r) {
    const T xc = (r.x0 + r.x1) * T(0.5f), yc = (r.y0 + r.y1) * T(0.5f), z2 = r.z0 * r.z0;
    const T rr = T(grazing_plane_ratio * grazing_plane_ratio);
    const auto grazing = z2 < rr * mul_add(xc, xc, mul_add(yc, yc, z2)) && r.omega < T(grazing_max_omega);
    return r.omega >= T(min_sa_sample_omega) && r.omega < T(6.2831853f) && !grazing;
  }
  template <class T> static SphericalRectangle<T> setup(const LightGeom<T>& g, const Vec3<T>& x) {
    return spherical_rectangle_setup_unit(x, g.p0, g.ex, g.ey, g.len1, g.len2);
  }
  template <class T> static SolidAngleSample<T> sample_solid_angle(const LightGeom<T>& g, const Vec3<T>& x, T u1, T u2) {
    SolidAngleSample<T> s;
    const SphericalRectangle<T> r = setup(g, x);
    s.ok = sample_spherical_rectangle(r, u1, u2, s.dir, s.t);
    s.omega = r.omega;
    s.safe = safe(r);
    return s;
  }
  template <class T> static SolidAngle<T> solid_angle(const LightGeom<T>& g, const Vec3<T>& x) {
    const SphericalRectangle<T> r = setup(g, x);
    return {r.omega, safe(r)};
  }
  // uniform by area, from the unit edges and lengths (what rectangle pipelines read)
  template <class T> static Vec3<T> area_point(const LightGeom<T>& g, T u1, T u2) {
    return g.p0 + g.ex * (g.len1 * u1) + g.ey * (g.len2 * u2);
  }
};

template <> struct LightKindOps<LightKind::parallelogram> : PlanarLight {
  static constexpr LightKind kind = LightKind::parallelogram;

  template <class T> static SolidAngleSample<T> sample_solid_angle(const LightGeom<T>& g, const Vec3<T>& x, T u1, T u2) {
    const auto rect = g.rect > T(0.5f);
    SolidAngleSample<T> s;
    s.dir = Vec3<T>(T(0.f), T(0.f), T(1.f));
    s.t = s.omega = T(0.f);
    s.ok = s.safe = T(0.f) > T(1.f);
    if (any(rect)) {
      const SolidAngleSample<T> r = RectangleLight::sample_solid_angle(g, x, u1, u2);
      s.dir = sel(rect, r.dir, s.dir);
      s.t = sel(rect, r.t, s.t);
      s.omega = sel(rect, r.omega, s.omega);
      s.ok = sel_mask(rect, r.ok, s.ok);
      s.safe = sel_mask(rect, r.safe, s.safe);
    }
    if (!all(rect)) {
      Vec3<T> dir;
      T pdf;
      const auto ok = sample_spherical_parallelogram(x, g.p0, g.e1, g.e2, u1, u2, dir, pdf);
      const T omega = sel(pdf > T(0.f), T(1.f) / sel(pdf > T(0.f), pdf, T(1.f)), T(0.f));
      s.dir = sel(rect, s.dir, dir);
      s.omega = sel(rect, s.omega, omega);
      s.ok = sel_mask(rect, s.ok, ok);
      s.safe = sel_mask(rect, s.safe, solid_angle_safe(g, x, omega, 0.5f));
      s.t = sel(rect, s.t, plane_distance(g, x, dir));
    }
    return s;
  }
  template <class T> static SolidAngle<T> solid_angle(const LightGeom<T>& g, const Vec3<T>& x) {
    const auto rect = g.rect > T(0.5f);
    SolidAngle<T> a{T(0.f), T(0.f) > T(1.f)};
    if (any(rect)) {
      const SolidAngle<T> r = RectangleLight::solid_angle(g, x);
      a.omega = sel(rect, r.omega, a.omega);
      a.safe = sel_mask(rect, r.safe, a.safe);
    }
    if (!all(rect)) {
      const T omega = spherical_parallelogram_solid_angle(x, g.p0, g.e1, g.e2);
      a.omega = sel(rect, a.omega, omega);
      a.safe = sel_mask(rect, a.safe, solid_angle_safe(g, x, omega, 0.5f));
    }
    return a;
  }
  template <class T> static Vec3<T> area_point(const LightGeom<T>& g, T u1, T u2) {
    return sel(g.rect > T(0.5f), RectangleLight::area_point(g, u1, u2), g.p0 + g.e1 * u1 + g.e2 * u2);
  }
  static float power(const LightShape& l, float lum, float) { return PlanarLight::power(l, lum); }
  static bool bounds(const LightShape& l, double L, LightBounds& b) {
    const vec3f corners[4] = {l.p0, l.p0 + l.e1, l.p0 + l.e2, l.p0 + l.e1 + l.e2};
    return PlanarLight::bounds(l, L, corners, b);
  }
};

}  // namespace tuile

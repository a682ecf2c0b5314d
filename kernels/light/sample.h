// Light sampling, the two halves every estimator needs:
//   sample_light_point: a point/direction on source s seen from x, with its density in
//                       solid angle at x (area sampling converted by d^2 / cos, or
//                       uniform in the subtended solid angle);
//   pdf_light_point_sa: the same density for a direction that reached source s another
//                       way (a BSDF-sampled ray), for MIS.
// Both use the same fallback rule (solid angle only where it is numerically safe), so
// the pdf always belongs to the strategy that would have produced the sample.
// Source: Veach's thesis §9 (direct lighting), Arvo 1995, Ureña et al. 2013, pbrt-v4's
// shapes for the cone of a sphere.
#pragma once
#include "light/table.h"

namespace tuile {

// The fallback rule, the same for sampling and for pdf evaluation: spheres always use
// their cone; triangles and non-rectangular parallelograms the solid angle within
// [min_sa_sample_omega, max_sa_sample_omega]; rectangles from the minimum up to the
// hemisphere (Urena's map stays accurate there, while area sampling of a source that
// fills the hemisphere has enormous variance; tests/test_stress.cpp near-light cases).
// Planar sources seen nearly edge-on (x within grazing_plane_ratio of the source's plane,
// relative to its distance to the centre) also fall back: the spherical maps lose their
// precision there (measured: +1.2% bias for a 1 x 1 source 1 mm above the floor seen
// from 1-2 m, tests/test_stress.cpp NearlyCoplanarSource), as Cycles also does.
// Only thin, small spherical polygons are affected: a large source next to x (which it
// also sees edge-on from its centre) is sampled well by the spherical map.
inline constexpr float grazing_plane_ratio = 0.02f;
inline constexpr float grazing_max_omega = 0.05f;

// The rule for triangles, non-rectangular parallelograms and spheres (false for
// rectangles: rect_solid_angle_safe decides for them, from their map's setup).
template <class T> inline mask_t<T> use_solid_angle(const LightGeom<T>& g, const Vec3<T>& x, T omega) {
  const auto is_tri = type_is<T>(g.type, lt_triangle);
  const auto is_par = type_is<T>(g.type, lt_parallelogram);
  const auto is_sph = type_is<T>(g.type, lt_sphere);
  const auto rect = is_par && g.rect > T(0.5f);
  const Vec3<T> to_c = g.p0 + (g.e1 + g.e2) * T(sel(is_tri, T(1.f / 3.f), T(0.5f))) - x;
  // |to_c . n| < ratio |to_c|, squared (no square root)
  const T h = dot(to_c, g.n);
  const T r = T(grazing_plane_ratio);
  const auto grazing = h * h < r * r * length_sq(to_c) && omega < T(grazing_max_omega);
  return ((is_tri || (is_par && !rect)) && solid_angle_sampling_safe(omega) && !grazing) || (is_sph && omega > T(0.f));
}

// The rule for a rectangle, in the frame of its map: the centre is at ((x0 + x1) / 2,
// (y0 + y1) / 2, z0) from x and the plane at distance |z0|. Omega is 0 where the setup
// failed, so such lanes fall back too.
template <class T> inline mask_t<T> rect_solid_angle_safe(const SphericalRectangle<T>& r) {
  const T xc = (r.x0 + r.x1) * T(0.5f), yc = (r.y0 + r.y1) * T(0.5f), z2 = r.z0 * r.z0;
  const T rr = T(grazing_plane_ratio * grazing_plane_ratio);
  const auto grazing = z2 < rr * mul_add(xc, xc, mul_add(yc, yc, z2)) && r.omega < T(grazing_max_omega);
  return r.omega >= T(min_sa_sample_omega) && r.omega < T(6.2831853f) && !grazing;
}

// Solid angle a triangle/parallelogram/sphere source subtends from x (0 where x is
// behind a one-sided source, where it emits nothing towards x). Rectangles use their
// constants (the same setup the sampler uses, so both see the same Omega to the bit).
template <class T>
inline T light_solid_angle(const LightGeom<T>& g, const Vec3<T>& x, mask_t<T>* rect_safe = nullptr) {
  const auto is_tri = type_is<T>(g.type, lt_triangle);
  const auto is_par = type_is<T>(g.type, lt_parallelogram);
  const auto is_sph = type_is<T>(g.type, lt_sphere);
  const auto rect = is_par && g.rect > T(0.5f);
  const auto skew = is_par && !rect;
  T omega(0.f);
  if (any(is_tri)) omega = sel(is_tri, spherical_triangle_solid_angle(x, g.p0, g.p0 + g.e1, g.p0 + g.e2), omega);
  if (any(rect)) {
    const SphericalRectangle<T> r = spherical_rectangle_setup_unit(x, g.p0, g.ex, g.ey, g.len1, g.len2);
    omega = sel(rect, r.omega, omega);
    if (rect_safe) *rect_safe = rect_solid_angle_safe(r);
  }
  if (any(skew)) omega = sel(skew, spherical_parallelogram_solid_angle(x, g.p0, g.e1, g.e2), omega);
  if (any(is_sph)) omega = sel(is_sph, sphere_cone_solid_angle(x, g.p0, g.e1.x), omega);
  return omega;
}

// Density in solid angle at x of reaching the source at distance dist along wi when the
// point is drawn uniformly by area: d^2 / (cos theta_y A); 0 from behind a one-sided source.
template <class T> inline T pdf_area_as_solid_angle(const LightGeom<T>& g, const Vec3<T>& x, const Vec3<T>& wi, T dist) {
  const T cos_y_signed = -dot(wi, g.n);
  const T cos_y = sel(g.two_sided > T(0.f), abs(cos_y_signed), cos_y_signed);
  const auto is_sph = type_is<T>(g.type, lt_sphere);
  // sphere: cos at y from its outward normal
  T cos_eff = cos_y;
  if (any(is_sph)) {
    const Vec3<T> y = x + wi * dist;
    cos_eff = sel(is_sph, -dot(wi, (y - g.p0)) / max(g.e1.x, T(1e-30f)), cos_y);
  }
  return sel(cos_eff > T(0.f), dist * dist / (cos_eff * g.area), T(0.f));
}

// Density in solid angle of a direction from x reaching the source at point y (distance
// d, unit direction wi) under the chosen point strategy, not including the pick pdf.
// omega: the solid angle of the source from x (light_solid_angle), needed only in
// solid-angle mode.
template <class T>
inline T pdf_light_point_sa(LightPoint mode, const LightGeom<T>& g, const Vec3<T>& x, const Vec3<T>& wi, T dist,
                            T omega, const mask_t<T>& rect_safe) {
  if (mode == LightPoint::area) return finite_or_zero(pdf_area_as_solid_angle(g, x, wi, dist));
  const auto rect = type_is<T>(g.type, lt_parallelogram) && g.rect > T(0.5f);
  const auto safe = sel_mask(rect, rect_safe, use_solid_angle(g, x, omega));
  T pdf = sel(omega > T(0.f), T(1.f) / sel(omega > T(0.f), omega, T(1.f)), T(0.f));
  if (!all(safe)) pdf = sel(safe, pdf, pdf_area_as_solid_angle(g, x, wi, dist));
  return finite_or_zero(pdf);
}

template <class T>
inline T pdf_light_point_sa(LightPoint mode, const LightGeom<T>& g, const Vec3<T>& x, const Vec3<T>& wi, T dist) {
  mask_t<T> rect_safe = T(0.f) > T(1.f);
  const T omega = mode == LightPoint::area ? T(0.f) : light_solid_angle(g, x, &rect_safe);
  return pdf_light_point_sa(mode, g, x, wi, dist, omega, rect_safe);
}

// pdf_light_point_sa where every lane's source is a rectangle (the same values).
template <class T>
inline T pdf_rectangle_point_sa(LightPoint mode, const LightGeom<T>& g, const Vec3<T>& x, const Vec3<T>& wi, T dist) {
  if (mode == LightPoint::area) return finite_or_zero(pdf_area_as_solid_angle(g, x, wi, dist));
  const SphericalRectangle<T> r = spherical_rectangle_setup_unit(x, g.p0, g.ex, g.ey, g.len1, g.len2);
  const T omega = r.omega;
  const auto safe = rect_solid_angle_safe(r);
  T pdf = sel(omega > T(0.f), T(1.f) / sel(omega > T(0.f), omega, T(1.f)), T(0.f));
  if (!all(safe)) pdf = sel(safe, pdf, pdf_area_as_solid_angle(g, x, wi, dist));
  return finite_or_zero(pdf);
}

// A sampled point on a source. wi is the unit direction from x, dist the distance
// (infinite for distant lights), pdf_sa its density (0 for delta lights, which are
// flagged by is_delta), emitted radiance or intensity factor in scale (1/d^2 for point
// lights, spot falloff / d^2 for spots, 1 otherwise).
template <class T> struct LightPointSample {
  Vec3<T> wi;
  T dist, pdf_sa, scale;
  mask_t<T> valid, is_delta;
};

// The lanes of by_area take the point y drawn by area: its direction and distance from x
// and its density converted to solid angle (both light-point samplers end this way).
template <class T>
inline void take_area_point(const LightGeom<T>& g, const Vec3<T>& x, const Vec3<T>& y, const mask_t<T>& by_area,
                            Vec3<T>& wi, T& dist, T& pdf, mask_t<T>& valid) {
  const Vec3<T> d = y - x;
  const T da = sqrt(length_sq(d));
  const Vec3<T> wa = d * (T(1.f) / sel(da > T(0.f), da, T(1.f)));
  wi = sel(by_area, wa, wi);
  dist = sel(by_area, da, dist);
  pdf = sel(by_area, pdf_area_as_solid_angle(g, x, wa, da), pdf);
  valid = sel_mask(by_area, da > T(0.f), valid);
}

// A point uniform by area on a rectangle, from its unit edges and lengths (what rectangle
// pipelines read; the general pipeline draws rectangles' points the same way).
template <class T> inline Vec3<T> rectangle_area_point(const LightGeom<T>& g, T u1, T u2) {
  return g.p0 + g.ex * (g.len1 * u1) + g.ey * (g.len2 * u2);
}

// sample_light_point where every lane's source is a rectangle: the same steps and values
// without the dispatch on the kind of source.
template <class T>
inline LightPointSample<T> sample_rectangle_point(LightPoint mode, const LightGeom<T>& g, const Vec3<T>& x, T u1,
                                                  T u2) {
  LightPointSample<T> s;
  s.is_delta = T(0.f) > T(1.f);
  s.scale = T(1.f);
  Vec3<T> wi(T(0.f), T(0.f), T(1.f));
  T dist(0.f), pdf(0.f);
  auto valid = s.is_delta, use_sa = s.is_delta;
  if (mode == LightPoint::solid_angle) {
    const SphericalRectangle<T> r =
        spherical_rectangle_setup_unit(x, g.p0, g.ex, g.ey, g.len1, g.len2);
    Vec3<T> dir;
    T t_sa;
    const auto ok = sample_spherical_rectangle(r, u1, u2, dir, t_sa);
    use_sa = rect_solid_angle_safe(r);
    wi = sel(use_sa, dir, wi);
    dist = sel(use_sa, t_sa, dist);
    pdf = sel(use_sa && r.omega > T(0.f), T(1.f) / sel(r.omega > T(0.f), r.omega, T(1.f)), pdf);
    valid = use_sa && ok && t_sa > T(0.f);
  }
  const auto by_area = !use_sa;
  if (any(by_area)) {
    take_area_point(g, x, rectangle_area_point(g, u1, u2), by_area, wi, dist, pdf, valid);
  }
  s.wi = wi;
  s.dist = dist;
  s.pdf_sa = finite_or_zero(pdf);
  s.valid = valid && s.pdf_sa > T(0.f) && is_finite(dist);
  return s;
}

// In solid-angle mode the spherical maps run first: their Omega decides (use_solid_angle)
// which lanes keep them, and only the lanes that fall back draw a point by area. The pdf
// is always the one of the strategy that produced the sample, as pdf_light_point_sa
// evaluates it.
template <unsigned Kinds = kind_all, class T>
inline LightPointSample<T> sample_light_point(LightPoint mode, const LightGeom<T>& g, const Vec3<T>& x, T u1,
                                              T u2) {
  if constexpr ((Kinds & kind_rects) != 0) return sample_rectangle_point(mode, g, x, u1, u2);
  LightPointSample<T> s;
  const auto is_tri = type_is<T>(g.type, lt_triangle);
  const auto is_par = type_is<T>(g.type, lt_parallelogram);
  const auto is_sph = type_is<T>(g.type, lt_sphere);
  const auto is_pt = type_is<T>(g.type, lt_point);
  const auto is_spot = type_is<T>(g.type, lt_spot);
  const auto is_dist = type_is<T>(g.type, lt_distant);
  s.is_delta = is_pt || is_spot || is_dist;
  s.scale = T(1.f);

  Vec3<T> wi(T(0.f), T(0.f), T(1.f));
  T dist(0.f), pdf(0.f);
  auto valid = T(0.f) > T(1.f);
  if constexpr ((Kinds & kind_area) != 0) {
    const auto is_area = is_tri || is_par || is_sph;
    auto use_sa = valid;
    if (mode == LightPoint::solid_angle && any(is_area)) {
      const auto rect = is_par && g.rect > T(0.5f);
      const auto skew = is_par && !rect;
      Vec3<T> dir = wi;
      T omega(0.f), t_sa(0.f);
      auto ok = valid, rect_safe = valid;
      if (any(rect)) {
        const SphericalRectangle<T> r =
            spherical_rectangle_setup_unit(x, g.p0, g.ex, g.ey, g.len1, g.len2);
        Vec3<T> dr;
        T tr;
        const auto m = sample_spherical_rectangle(r, u1, u2, dr, tr);
        dir = sel(rect, dr, dir);
        t_sa = sel(rect, tr, t_sa);
        omega = sel(rect, r.omega, omega);
        ok = sel_mask(rect, m, ok);
        rect_safe = rect_solid_angle_safe(r);
      }
      if (any(is_tri)) {
        const SphericalTriangle<T> st = spherical_triangle_setup(x, g.p0, g.p0 + g.e1, g.p0 + g.e2);
        Vec3<T> dt;
        T pt;
        const auto m = sample_spherical_triangle(st, u1, u2, dt, pt);
        dir = sel(is_tri, dt, dir);
        omega = sel(is_tri, st.omega, omega);
        ok = sel_mask(is_tri, m, ok);
      }
      if (any(skew)) {
        Vec3<T> dp;
        T pp;
        const auto m = sample_spherical_parallelogram(x, g.p0, g.e1, g.e2, u1, u2, dp, pp);
        dir = sel(skew, dp, dir);
        omega = sel(skew, sel(pp > T(0.f), T(1.f) / sel(pp > T(0.f), pp, T(1.f)), T(0.f)), omega);
        ok = sel_mask(skew, m, ok);
      }
      if (any(is_sph)) {
        Vec3<T> ds;
        T ps;
        const auto m = sample_sphere_cone(x, g.p0, g.e1.x, u1, u2, ds, ps);
        dir = sel(is_sph, ds, dir);
        omega = sel(is_sph, sphere_cone_solid_angle(x, g.p0, g.e1.x), omega);
        ok = sel_mask(is_sph, m, ok);
      }
      use_sa = is_area && sel_mask(rect, rect_safe, use_solid_angle(g, x, omega));
      // distance along dir to the source's plane (triangles, skew parallelograms) or
      // sphere; rectangles know it already
      if (any(use_sa && !rect)) {
        const T denom = dot(dir, g.n);
        const T t_plane = dot(g.p0 - x, g.n) / sel(abs(denom) > T(0.f), denom, T(1.f));
        T t_other = t_plane;
        if (any(is_sph)) {
          const Vec3<T> oc = x - g.p0;
          const T bq = dot(oc, dir);
          const T cq = length_sq(oc) - g.e1.x * g.e1.x;
          const T disc = max(T(0.f), bq * bq - cq);
          // nearer root, computed stably
          t_other = sel(is_sph, cq / max(-bq + sqrt(disc), T(1e-30f)), t_plane);
        }
        t_sa = sel(rect, t_sa, t_other);
      }
      wi = sel(use_sa, dir, wi);
      dist = sel(use_sa, t_sa, dist);
      pdf = sel(use_sa && omega > T(0.f), T(1.f) / sel(omega > T(0.f), omega, T(1.f)), pdf);
      valid = use_sa && ok && t_sa > T(0.f);
    }
    // area sampling: a point y on the surface, for area mode and the lanes that fall back
    const auto by_area = is_area && !use_sa;
    if (any(by_area)) {
      Vec3<T> y = g.p0;
      if (any(is_tri)) {
        T b1, b2;
        sample_triangle_area(u1, u2, b1, b2);
        y = sel(is_tri, g.p0 + g.e1 * b1 + g.e2 * b2, y);
      }
      if (any(is_par)) y = sel(is_par, sel(g.rect > T(0.5f), rectangle_area_point(g, u1, u2), g.p0 + g.e1 * u1 + g.e2 * u2), y);
      if (any(is_sph)) y = sel(is_sph, sample_sphere_area(g.p0, g.e1.x, u1, u2), y);
      take_area_point(g, x, y, by_area, wi, dist, pdf, valid);
    }
  }

  if constexpr ((Kinds & kind_delta) != 0) {
  if (any(is_pt || is_spot)) {
    const Vec3<T> dp = g.p0 - x;
    const T d2 = length_sq(dp);
    const T dd = sqrt(d2);
    const Vec3<T> w = dp * (T(1.f) / sel(dd > T(0.f), dd, T(1.f)));
    const auto m = is_pt || is_spot;
    wi = sel(m, w, wi);
    dist = sel(m, dd, dist);
    T sc = T(1.f) / max(d2, T(1e-30f));
    if (any(is_spot)) {
      // pbrt-v4 spot falloff: smoothstep between cos(total) and cos(falloff start)
      const T cos_t = -dot(w, g.e1);
      const T c0 = g.e2.y, c1 = g.e2.x;
      T t = (cos_t - c0) / max(c1 - c0, T(1e-12f));
      t = min(T(1.f), max(T(0.f), t));
      sc = sel(is_spot, sc * t * t * (T(3.f) - T(2.f) * t), sc);
    }
    s.scale = sel(m, sc, s.scale);
    valid = sel_mask(m, dd > T(0.f), valid);
  }
  if (any(is_dist)) {
    wi = sel(is_dist, g.e1, wi);
    dist = sel(is_dist, T(3.0e38f), dist);
    valid = sel_mask(is_dist, mask_t<T>(true), valid);
  }
  }
  s.wi = wi;
  s.dist = dist;
  s.pdf_sa = sel(s.is_delta, T(0.f), finite_or_zero(pdf));
  s.valid = valid && (s.is_delta || s.pdf_sa > T(0.f)) && is_finite(dist);
  return s;
}

}  // namespace tuile

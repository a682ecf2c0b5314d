// Light sampling, the two halves every estimator needs:
//   sample_light_point: a point/direction on source s seen from x, with its density in
//                       solid angle at x (area sampling converted by d^2 / cos, or
//                       uniform in the subtended solid angle);
//   pdf_light_point_sa: the same density for a direction that reached source s another
//                       way (a BSDF-sampled ray), for MIS.
// Both use the same fallback rule (solid angle only where it is numerically safe: each
// kind's own, light/kinds/), so the pdf always belongs to the strategy that would have
// produced the sample. The kinds' code is in light/kinds/<name>.h; this file combines it.
// Source: Veach's thesis §9 (direct lighting), Arvo 1995, Ureña et al. 2013, pbrt-v4's
// shapes for the cone of a sphere.
#pragma once
#include "light/dispatch.h"

namespace tuile {

// Density in solid angle at x of reaching the source at distance dist along wi when the
// point is drawn uniformly by area: d^2 / (cos theta_y A), with the cosine at the source
// from its kind (emit_cos); 0 from behind a one-sided source and for delta sources.
template <unsigned Kinds = kind_all, class T>
inline T pdf_area_as_solid_angle(const LightGeom<T>& g, const Vec3<T>& x, const Vec3<T>& wi, T dist) {
  T cos_y(0.f);
  for_each_light_shape<area_kinds(Kinds)>(g, [&](auto ops, const mask_t<T>& m) {
    cos_y = sel(m, ops.emit_cos(g, x, wi, dist), cos_y);
  });
  return sel(cos_y > T(0.f), dist * dist / (cos_y * g.area), T(0.f));
}

// Density in solid angle of a direction from x reaching the source at point y (distance
// d, unit direction wi) under the chosen point strategy, not including the pick pdf: in
// solid-angle mode 1 / Omega where the kind's fallback rule keeps the spherical map, the
// area density elsewhere (the strategy that would have produced the sample).
template <unsigned Kinds = kind_all, class T>
inline T pdf_light_point_sa(LightPoint mode, const LightGeom<T>& g, const Vec3<T>& x, const Vec3<T>& wi, T dist) {
  if (mode == LightPoint::area) return finite_or_zero(pdf_area_as_solid_angle<Kinds>(g, x, wi, dist));
  T omega(0.f);
  mask_t<T> safe = T(0.f) > T(1.f);
  for_each_light_kind<area_kinds(Kinds)>(g, [&](auto ops, const mask_t<T>& m) {
    const SolidAngle<T> a = ops.solid_angle(g, x);
    omega = sel(m, a.omega, omega);
    safe = sel_mask(m, a.safe, safe);
  });
  T pdf = sel(omega > T(0.f), T(1.f) / sel(omega > T(0.f), omega, T(1.f)), T(0.f));
  if (!all(safe)) pdf = sel(safe, pdf, pdf_area_as_solid_angle<Kinds>(g, x, wi, dist));
  return finite_or_zero(pdf);
}

// The density of the direction wi towards a light at infinity under its own sampling
// (sample_light_point), not including the pick pdf: what a ray that escaped the scene
// along wi is weighted against (wave/escaped.h). 0 for every other kind.
template <unsigned Kinds = kind_all, class T> inline T pdf_sky_direction(const LightGeom<T>& g, const Vec3<T>& wi) {
  T pdf(0.f);
  for_each_light_kind<Kinds & kind_sky>(g, [&](auto ops, const mask_t<T>& m) { pdf = sel(m, ops.pdf_direction(g, wi), pdf); });
  return finite_or_zero(pdf);
}

// Solid angle a source subtends from x, as the density uses it (0 for delta sources).
template <unsigned Kinds = kind_all, class T> inline T light_solid_angle(const LightGeom<T>& g, const Vec3<T>& x) {
  T omega(0.f);
  for_each_light_kind<area_kinds(Kinds)>(g, [&](auto ops, const mask_t<T>& m) {
    omega = sel(m, ops.solid_angle(g, x).omega, omega);
  });
  return omega;
}

// A sampled point on a source. wi is the unit direction from x, dist the distance
// (infinite for distant lights), pdf_sa its density (0 for delta lights, which are
// flagged by is_delta), emitted radiance or intensity factor in scale (1/d^2 for point
// lights, spot falloff / d^2 for spots, 1 otherwise).
template <class T> struct LightPointSample {
  Vec3<T> wi;
  T dist, pdf_sa, scale;
  mask_t<T> valid, is_delta;
  i32_t<T> sky_texel;  // a sky with a map: the texel drawn (its radiance's factor); -1 otherwise
};

// The lanes of by_area take the point y drawn by area: its direction and distance from x
// and its density converted to solid angle.
template <unsigned Kinds, class T>
inline void take_area_point(const LightGeom<T>& g, const Vec3<T>& x, const Vec3<T>& y, const mask_t<T>& by_area,
                            Vec3<T>& wi, T& dist, T& pdf, mask_t<T>& valid) {
  const Vec3<T> d = y - x;
  const T da = sqrt(length_sq(d));
  const Vec3<T> wa = d * (T(1.f) / sel(da > T(0.f), da, T(1.f)));
  wi = sel(by_area, wa, wi);
  dist = sel(by_area, da, dist);
  pdf = sel(by_area, pdf_area_as_solid_angle<Kinds>(g, x, wa, da), pdf);
  valid = sel_mask(by_area, da > T(0.f), valid);
}

// A point (or direction) on each lane's source seen from x. In solid-angle mode the
// spherical maps run first: each kind's fallback rule (its SolidAngleSample's safe) decides
// which lanes keep them, and only the lanes that fall back draw a point by area. The pdf is
// always the one of the strategy that produced the sample, as pdf_light_point_sa evaluates
// it (pdf_sky_direction for the sky, whatever the mode). Delta sources give their one
// direction.
template <unsigned Kinds = kind_all, class T>
inline LightPointSample<T> sample_light_point(LightPoint mode, const LightGeom<T>& g, const Vec3<T>& x, T u1,
                                              T u2) {
  LightPointSample<T> s;
  s.is_delta = T(0.f) > T(1.f);
  s.scale = T(1.f);
  s.sky_texel = i32_t<T>(-1);
  Vec3<T> wi(T(0.f), T(0.f), T(1.f));
  T dist(0.f), pdf(0.f);
  auto valid = s.is_delta;
  if constexpr (area_kinds(Kinds) != 0) {
    auto use_sa = valid;
    if (mode == LightPoint::solid_angle) {
      for_each_light_kind<area_kinds(Kinds)>(g, [&](auto ops, const mask_t<T>& m) {
        const SolidAngleSample<T> a = ops.sample_solid_angle(g, x, u1, u2);
        const auto take = m && a.safe;
        wi = sel(take, a.dir, wi);
        dist = sel(take, a.t, dist);
        pdf = sel(take && a.omega > T(0.f), T(1.f) / sel(a.omega > T(0.f), a.omega, T(1.f)), pdf);
        valid = sel_mask(take, a.ok && a.t > T(0.f), valid);
        use_sa = use_sa || take;
      });
    }
    // area sampling: a point y on the surface, for area mode and the lanes that fall back
    Vec3<T> y = g.p0;
    auto by_area = s.is_delta;
    for_each_light_kind<area_kinds(Kinds)>(g, [&](auto ops, const mask_t<T>& m) {
      const auto mine = m && !use_sa;
      if (any(mine)) {
        y = sel(mine, ops.area_point(g, u1, u2), y);
        by_area = by_area || mine;
      }
    });
    if (any(by_area)) take_area_point<Kinds>(g, x, y, by_area, wi, dist, pdf, valid);
  }
  if constexpr ((Kinds & kind_sky) != 0) {  // a direction at infinity, with its density
    for_each_light_kind<kind_sky>(g, [&](auto ops, const mask_t<T>& m) {
      const SkySample<T> d = ops.sample_direction(g, u1, u2);
      wi = sel(m, d.wi, wi);
      dist = sel(m, T(LightKindOps<LightKind::distant>::infinite_distance), dist);
      pdf = sel(m, d.pdf, pdf);
      valid = sel_mask(m, d.pdf > T(0.f), valid);
      s.sky_texel = sel(i_mask_from_f(m), d.texel, s.sky_texel);
    });
  }
  if constexpr ((Kinds & kind_delta) != 0) {
    for_each_light_kind<kind_delta>(g, [&](auto ops, const mask_t<T>& m) {
      const DeltaSample<T> d = ops.sample_delta(g, x);
      wi = sel(m, d.wi, wi);
      dist = sel(m, d.dist, dist);
      s.scale = sel(m, d.scale, s.scale);
      valid = sel_mask(m, d.valid, valid);
      s.is_delta = s.is_delta || m;
    });
  }
  s.wi = wi;
  s.dist = dist;
  s.pdf_sa = sel(s.is_delta, T(0.f), finite_or_zero(pdf));
  s.valid = valid && (s.is_delta || s.pdf_sa > T(0.f)) && is_finite(dist);
  return s;
}

}  // namespace tuile

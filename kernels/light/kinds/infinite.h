// The sky (LightSource "infinite"): radiance arriving from every direction at infinity,
// the table's radiance times, for a sky with an environment map, the map's texel along the
// direction (light/sky_map.h: pbrt-v4's equal-area octahedral square in the light's frame
// e1, e2, n; nearest texel). A constant sky is drawn uniformly over the sphere of
// directions (density 1 / (4 pi)); a map by its texels' distribution (pdf_uv / (4 pi)),
// the compensated one where LightGeom::sky_dist asks for it, and then a constant sky is
// left to the BSDF technique (density 0, as pbrt-v4's UniformInfiniteLight under MIS:
// cosine-weighted BSDF samples already cover it without variance from the direction).
// It has no surface that a ray can hit: a ray that leaves the scene sees it
// (wave/escaped.h, which weights it against pdf_direction). Power: what the disc of the
// scene's bounding sphere (radius r) receives from it facing it, pi r^2 times the
// irradiance pi L (L: the radiance, a map's mean texel in it), as a distant source's
// pi r^2 L: so a sky and a distant source of the same irradiance weigh the same. (pbrt-v4
// takes 4 pi * pi r^2 L, the flux into the whole sphere, four times as much: measured on
// two sun-and-sky interiors, a sky given that share starves the sun, which only light
// sampling reaches, while BSDF samples also find the sky: bench/results.md.) Under MIS
// the power picker takes only the part of the sky its light samples draw (render/views.h:
// SkyMap::compensated_share of a map, none of a constant sky). Not in the light BVH (its
// pickers give it its power's share, as a distant source's).
// Table fields: p0.x the map's index in LightView::sky_maps (-1: constant), e1, e2, n the
// light frame's x, y, z axes in the world (orthonormal). The sky's functions are out of
// line (TUILE_OUT_OF_LINE): the flattened stages call them once per batch.
#pragma once
#include "light/kinds/common.h"
#include "light/sky_map.h"
#include "sample/sampling.h"

namespace tuile {

// A direction drawn towards a light at infinity, its density in solid angle and, for a sky
// with a map, the texel it came from (-1 otherwise).
template <class T> struct SkySample {
  Vec3<T> wi;
  T pdf;
  i32_t<T> texel;
};

template <> struct LightKindOps<LightKind::infinite> {
  static constexpr LightKind kind = LightKind::infinite;
  static constexpr bool planar = false, at_infinity = true;

  // f(map, lanes) for each environment map among the lanes (the lanes of a constant sky
  // take none).
  template <class T, class F> static void for_each_map(const LightGeom<T>& g, F&& f) {
    if (g.sky_map_count == 0) return;
    const auto in = g.p0.x >= T(0.f) && g.p0.x < T(static_cast<float>(g.sky_map_count));
    const i32_t<T> mi = to_i32(sel(in, g.p0.x, T(-1.f)));
    for (int32_t k = 0; k < g.sky_map_count; ++k) {
      const mask_t<T> m = f_mask_from_i(mi == i32_t<T>(k));
      if (any(m)) f(g.sky_maps[k], m);
    }
  }
  // A constant sky's density: uniform, or none where the compensated distributions are asked for.
  static float constant_pdf(int dist) { return dist == sky_dist_compensated ? 0.f : inv_4pi_f; }

  template <class T> TUILE_OUT_OF_LINE static SkySample<T> sample_direction(const LightGeom<T>& g, const T& u1, const T& u2) {
    SkySample<T> s{sample_uniform_sphere(u1, u2), T(constant_pdf(g.sky_dist)), i32_t<T>(-1)};
    for_each_map(g, [&](const SkyMapView& map, const mask_t<T>& m) {
      const SkyMapSample<T> ms = sample_sky_map(map, g.sky_dist, u1, u2);
      const Vec3<T> w = from_sky_frame(equal_area_square_to_sphere(ms.pu, ms.pv), g.e1, g.e2, g.n);
      s.wi = sel(m, w, s.wi);
      s.pdf = sel(m, ms.pdf_uv * T(inv_4pi_f), s.pdf);
      s.texel = sel(i_mask_from_f(m), ms.texel, s.texel);
    });
    return s;
  }
  // The texel of each map lane along the world direction wi (-1 for constant skies).
  template <class T> TUILE_OUT_OF_LINE static i32_t<T> texel_along(const LightGeom<T>& g, const Vec3<T>& wi) {
    i32_t<T> texel(-1);
    for_each_map(g, [&](const SkyMapView& map, const mask_t<T>& m) {
      T pu, pv;
      equal_area_sphere_to_square(to_sky_frame(wi, g.e1, g.e2, g.n), pu, pv);
      texel = sel(i_mask_from_f(m), sky_texel(map.res, pu, pv), texel);
    });
    return texel;
  }
  // The density sample_direction gives the direction wi.
  template <class T> TUILE_OUT_OF_LINE static T pdf_direction(const LightGeom<T>& g, const Vec3<T>& wi) {
    T pdf(constant_pdf(g.sky_dist));
    for_each_map(g, [&](const SkyMapView& map, const mask_t<T>& m) {
      T pu, pv;
      equal_area_sphere_to_square(to_sky_frame(wi, g.e1, g.e2, g.n), pu, pv);
      pdf = sel(m, sky_map_pdf_uv<T>(map, g.sky_dist, sky_texel(map.res, pu, pv)) * T(inv_4pi_f), pdf);
    });
    return pdf;
  }
  // The radiance (r, gr, b: the table's on entry) times the texel of the map lanes (texel
  // from sample_direction or texel_along; lanes with texel -1 keep theirs).
  template <class T> TUILE_OUT_OF_LINE static void apply_texel(const LightGeom<T>& g, const i32_t<T>& texel, T& r, T& gr, T& b) {
    for_each_map(g, [&](const SkyMapView& map, const mask_t<T>& in_map) {
      const auto mi = i_mask_from_f(in_map) && texel >= i32_t<T>(0);
      const mask_t<T> m = f_mask_from_i(mi);
      const i32_t<T> t = sel(mi, texel, i32_t<T>(0));
      r = sel(m, r * gather(map.r, t), r);
      gr = sel(m, gr * gather(map.g, t), gr);
      b = sel(m, b * gather(map.b, t), b);
    });
  }
  // the shadow ray goes as far as a ray can: no end point to offset
  template <class T> static Vec3<T> endpoint_normal(const LightGeom<T>&, const Vec3<T>&, const Vec3<T>&) {
    return Vec3<T>(T(0.f), T(0.f), T(0.f));
  }
  // lum: the luminance of the table's radiance times the map's mean texel
  static float power(const LightShape&, float lum, float scene_radius) {
    return 3.14159265f * 3.14159265f * scene_radius * scene_radius * lum;
  }
  static bool bounds(const LightShape&, double, LightBounds&) { return false; }
};

}  // namespace tuile

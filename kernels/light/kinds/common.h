// What the light kinds' code shares: the results their samplers return, and the rules of
// planar sources (triangles and parallelograms: one side emits, the fallback near the
// source's plane, the distance along a direction to the plane, the bounds).
#pragma once
#include <algorithm>
#include <cmath>

#include "light/kinds.h"
#include "light/table.h"

namespace tuile {

// Double precision pi, for the scalar power and bounds of the light BVH.
inline constexpr double light_pi = 3.14159265358979323846;

// A direction drawn uniformly in the solid angle a source subtends from x: the direction,
// the distance to the source along it, the solid angle (as the sampler computed it), and
// whether the map succeeded (ok) and is accurate enough to be used (safe: the fallback
// rule; the other lanes draw a point by area instead).
template <class T> struct SolidAngleSample {
  Vec3<T> dir;
  T t, omega;
  mask_t<T> ok, safe;
};

// The solid angle of a source from x and the fallback rule for it: the density of a
// direction that reached the source another way (a BSDF ray) uses it.
template <class T> struct SolidAngle {
  T omega;
  mask_t<T> safe;
};

// A delta source's one direction from x: unit wi, the distance (3e38 at infinity), the
// factor of its intensity towards x (1/d^2, a spot's falloff), and whether it is defined.
template <class T> struct DeltaSample {
  Vec3<T> wi;
  T dist, scale;
  mask_t<T> valid;
};

// The fallback rule of solid-angle sampling (the same for sampling and for the density):
// triangles and non-rectangular parallelograms use the spherical maps for a solid angle
// within [min_sa_sample_omega, max_sa_sample_omega] (sampling.h), except where they are
// seen nearly edge-on: x within grazing_plane_ratio of the source's plane, relative to its
// distance to the centre, and a solid angle below grazing_max_omega. The maps lose their
// precision there (measured: +1.2% bias for a 1 x 1 source 1 mm above the floor seen from
// 1-2 m, tests/test_stress.cpp NearlyCoplanarSource), as Cycles also finds. Only thin,
// small spherical polygons are affected: a large source next to x (which it also sees
// edge-on from its centre) is sampled well by the spherical map. Rectangles apply the rule
// in their map's frame (RectangleLight); spheres always use their cone.
inline constexpr float grazing_plane_ratio = 0.02f;
inline constexpr float grazing_max_omega = 0.05f;

struct PlanarLight {
  static constexpr bool planar = true, at_infinity = false;
  // centre_weight: 1/3 for a triangle's centroid, 1/2 for a parallelogram's centre
  template <class T>
  static mask_t<T> solid_angle_safe(const LightGeom<T>& g, const Vec3<T>& x, T omega, float centre_weight) {
    const Vec3<T> to_c = g.p0 + (g.e1 + g.e2) * T(centre_weight) - x;
    // |to_c . n| < ratio |to_c|, squared (no square root)
    const T h = dot(to_c, g.n);
    const T r = T(grazing_plane_ratio);
    const auto grazing = h * h < r * r * length_sq(to_c) && omega < T(grazing_max_omega);
    return solid_angle_sampling_safe(omega) && !grazing;
  }
  // Distance from x along dir to the source's plane.
  template <class T> static T plane_distance(const LightGeom<T>& g, const Vec3<T>& x, const Vec3<T>& dir) {
    const T denom = dot(dir, g.n);
    return dot(g.p0 - x, g.n) / sel(abs(denom) > T(0.f), denom, T(1.f));
  }
  // The cosine at the source of the direction wi arriving there (negative: its back).
  template <class T> static T emit_cos(const LightGeom<T>& g, const Vec3<T>& wi) {
    const T cos_y_signed = -dot(wi, g.n);
    return sel(g.two_sided > T(0.f), abs(cos_y_signed), cos_y_signed);
  }
  template <class T> static T emit_cos(const LightGeom<T>& g, const Vec3<T>&, const Vec3<T>& wi, T) { return emit_cos(g, wi); }
  // x is on the side the source emits to.
  template <class T> static mask_t<T> lit_from(const LightGeom<T>& g, const Vec3<T>& x) {
    return g.two_sided > T(0.f) || dot(x - g.p0, g.n) > T(0.f);
  }
  // A ray along d meets the side the normal n is on (a one-sided source's emitting side).
  template <class T> static mask_t<T> faces(const Vec3<T>& d, const Vec3<T>& n) { return dot(d, n) < T(0.f); }
  // The normal at the sampled point facing the shading point (the shadow ray's end is
  // offset along it).
  template <class T> static Vec3<T> endpoint_normal(const LightGeom<T>& g, const Vec3<T>&, const Vec3<T>& wi) {
    return sel(dot(g.n, wi) > T(0.f), -g.n, g.n);
  }
  // One-sided sources emit pi L A, two-sided ones twice that (lum: the radiance's luminance).
  static float power(const LightShape& l, float lum) { return lum * 3.14159265f * l.area * (l.two_sided ? 2.f : 1.f); }
  // The bounds of the corners given and the normal cone of the plane (cos_o = 1: one
  // normal; cos_e = cos(pi / 2): emission over the hemisphere).
  template <size_t N> static bool bounds(const LightShape& l, double L, const vec3f (&corners)[N], LightBounds& b) {
    for (const vec3f& q : corners) b.grow(q);
    const vec3f c = cross(l.e1, l.e2);
    const double n[3] = {c.x, c.y, c.z}, len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (!(len > 0)) return false;
    b.w = {static_cast<float>(n[0] / len), static_cast<float>(n[1] / len), static_cast<float>(n[2] / len)};
    b.cos_o = 1;
    b.cos_e = 0;
    b.two_sided = l.two_sided;
    b.phi = L * l.area * light_pi * (l.two_sided ? 2 : 1);
    return true;
  }
};

}  // namespace tuile

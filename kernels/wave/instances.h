// Instances (pbrt-v4's ObjectInstance, traced by Embree as instances of one BVH per
// object): a hit of instance i is of a shape whose rows (GeomView) hold it in its object's
// space. The hit stages compute the point there and place it in the world
// (surface_hits.h); the scalar passes that read a shape's vertices (shading normals, bump
// mapping, hair's fibers) place those first. Reads GeomView::inst_m, inst_inv.
#pragma once
#include <cmath>

#include "lanes/vec.h"
#include "wave/tile.h"

namespace tuile {

// The lanes of packet p from lane l whose hit is of an instance (GeomView::has_instances):
// which (the instance's index, -1 elsewhere), and 12 times it, where its matrices start.
template <class T> struct InstanceLanes {
  mask_t<T> on = mask_t<T>(false);
  i32_t<T> index = i32_t<T>(-1), m12 = i32_t<T>(0);
};
template <class T>
inline InstanceLanes<T> instance_lanes(const RayHit16& p, int l, const mask_t<T>& hit) {
  InstanceLanes<T> in;
  const i32_t<T> id = load_i32<T>(reinterpret_cast<const int32_t*>(p.instID[0] + l));  // invalid_id reads as -1
  in.on = hit && f_mask_from_i(id >= i32_t<T>(0));
  in.index = sel(i_mask_from_f(in.on), id, i32_t<T>(-1));
  in.m12 = max(in.index, i32_t<T>(0)) * i32_t<T>(12);
  return in;
}
// Row r of a 3x4 matrix per lane (M: 12 floats per instance, from m12), applied to a point
// (w = 1) or a vector (w = 0); and the transpose of its linear part applied to a vector.
template <class T> inline T instance_row(const float* M, const i32_t<T>& m12, int r, const Vec3<T>& v, bool point) {
  const T a = gather(M + 4 * r, m12), b = gather(M + 4 * r + 1, m12), c = gather(M + 4 * r + 2, m12);
  T out = a * v.x + b * v.y + c * v.z;
  if (point) out = out + gather(M + 4 * r + 3, m12);
  return out;
}
template <class T> inline Vec3<T> instance_apply(const float* M, const i32_t<T>& m12, const Vec3<T>& v, bool point) {
  return {instance_row<T>(M, m12, 0, v, point), instance_row<T>(M, m12, 1, v, point), instance_row<T>(M, m12, 2, v, point)};
}
template <class T> inline Vec3<T> instance_apply_transposed(const float* M, const i32_t<T>& m12, const Vec3<T>& v) {
  Vec3<T> out(T(0.f), T(0.f), T(0.f));
  for (int r = 0; r < 3; ++r) {
    const T vr = r == 0 ? v.x : r == 1 ? v.y : v.z;
    out = out + Vec3<T>(gather(M + 4 * r, m12), gather(M + 4 * r + 1, m12), gather(M + 4 * r + 2, m12)) * vr;
  }
  return out;
}
// A hit normal of an instance in world space: Embree's Ng is the object's (pbrt-v4 turns
// normals by the inverse transpose, which keeps their side: the outside stays the row's
// geom_side). A flat curve's Ng is its tangent, a vector: turned by the matrix itself.
template <class T>
inline Vec3<T> instance_normal(const GeomView& G, const InstanceLanes<T>& in, const i32_t<T>& geom, const Vec3<T>& ng) {
  Vec3<T> n = instance_apply_transposed<T>(G.inst_inv, in.m12, ng);
  const i32_t<T> kind = gather(G.geom_kind, max(geom, i32_t<T>(0)));
  const auto flat = in.on && f_mask_from_i(kind == i32_t<T>(static_cast<int32_t>(GeomKind::flat_curve)));
  if (any(flat)) n = sel(flat, instance_apply<T>(G.inst_m, in.m12, ng, false), n);
  return sel(in.on, n, ng);
}

// Scalar: a point of instance i's object placed in the world, and a normal (by the inverse
// transpose, unit again; a zero normal stays zero).
inline vec3f instance_point(const GeomView& G, int32_t i, const vec3f& p) {
  const float* M = G.inst_m + 12 * static_cast<size_t>(i);
  return {M[0] * p.x + M[1] * p.y + M[2] * p.z + M[3], M[4] * p.x + M[5] * p.y + M[6] * p.z + M[7],
          M[8] * p.x + M[9] * p.y + M[10] * p.z + M[11]};
}
inline vec3f instance_normal(const GeomView& G, int32_t i, const vec3f& n) {
  const float* A = G.inst_inv + 12 * static_cast<size_t>(i);
  const vec3f w{A[0] * n.x + A[4] * n.y + A[8] * n.z, A[1] * n.x + A[5] * n.y + A[9] * n.z,
                A[2] * n.x + A[6] * n.y + A[10] * n.z};
  const float l2 = dot(w, w);
  return l2 > 0.f && std::isfinite(l2) ? w * (1.f / std::sqrt(l2)) : vec3f{0.f, 0.f, 0.f};
}
// The scale of lengths under instance i (the cube root of its determinant's magnitude:
// a curve's width placed in the world, as pbrt-v4's flattening would scale it)
inline float instance_scale(const GeomView& G, int32_t i) {
  const float* M = G.inst_m + 12 * static_cast<size_t>(i);
  const float det = M[0] * (M[5] * M[10] - M[6] * M[9]) - M[1] * (M[4] * M[10] - M[6] * M[8]) + M[2] * (M[4] * M[9] - M[5] * M[8]);
  return std::cbrt(std::fabs(det));
}
// Whether instance i mirrors (a negative determinant): a triangle's winding, placed in the
// world, then turns the other way round its outside.
inline bool instance_mirrors(const GeomView& G, int32_t i) {
  const float* M = G.inst_m + 12 * static_cast<size_t>(i);
  return M[0] * (M[5] * M[10] - M[6] * M[9]) - M[1] * (M[4] * M[10] - M[6] * M[8]) + M[2] * (M[4] * M[9] - M[5] * M[8]) < 0.f;
}

}  // namespace tuile

// A light BVH (Conty Estevez & Kulla 2018; the importance and cone bounds of pbrt-v4's
// BVHLightSampler): a binary tree over the sources whose nodes bound their sources'
// positions (a sphere around the node's box), emitted power phi and normals (a cone of
// axis w and half-angle theta_o, emitting up to theta_e beyond it). A pick descends it with
// one uniform number, choosing each child with probability proportional to its importance
// for the shading point x and normal n (power over clamped squared distance, times the
// cosine bounds of the emitter's and the receiver's orientation), and remapping the number
// into the chosen child's share. The pmf of a given source walks the same nodes along its
// bit trail (the root-to-leaf path, bit d: the second child at depth d) and multiplies the
// same ratios, bit for bit the pick's.
// Distant sources are not in the tree: with S_inf of them, one is picked uniformly with
// probability S_inf / (S_inf + 1) (pbrt-v4; 1 when the tree is empty) and the tree gets
// the rest.
// Lane-generic: T = float is the reference; every batch lane computes its bits (correctly
// rounded square roots and divisions only).
// Not wired into the stages yet: sample_lights and the emitter-hit weights still take the
// alias picker (the queue must first keep each entry's normal for pmf's context).
#pragma once
#include <cstdint>

#include "light/pick.h"

namespace tuile {

// The nodes are quantized (pbrt-v4's CompactLightBounds), 28 bytes each in seven 32-bit
// arrays, so that a batch reads a node with seven 32-bit gathers:
// - box: per axis one word, the low 16 bits the minimum and the high 16 bits the maximum
//   as steps of the tree's grid (lo + q step, the sources' bounding box cut in 65535
//   steps), rounded outwards so that the decoded box holds the node's sources;
// - axis: the cone's axis as an octahedral vector, 16 bits per coordinate;
// - cone: bits 0-14 cos theta_o, bits 15-29 cos theta_e, both as steps of 2 / 32767 from
//   -1 and rounded down (the cone only widens; theta_o is also widened by the axis's
//   encoding error), and bit 30 set where a two-sided emitter is inside;
// - phi (float) and child (int32): an inner node's second child (the first is the next
//   node), or -1 - light for a leaf.
// Per light, its bit trail: bits 0-61 of trail_lo | trail_hi << 32 (the tree is at most 62
// levels deep); a source outside the tree has bit 63 set, and bit 62 too if it is a
// distant source (else it is never picked: no power).
struct LightBvhView {
  int32_t nodes = 0;         // 0: no source in the tree
  int32_t distant = 0;       // distant sources, picked apart from the tree
  const int32_t* distant_light = nullptr;  // their light indices
  float p_distant = 0;       // the probability of picking one of them (then 1 / distant each)
  float grid_lo[3] = {0, 0, 0}, grid_step[3] = {0, 0, 0};  // the box grid: lo + q step
  const uint32_t *box_x = nullptr, *box_y = nullptr, *box_z = nullptr;
  const uint32_t *axis = nullptr, *cone = nullptr;
  const float* phi = nullptr;
  const int32_t* child = nullptr;
  const uint32_t *trail_lo = nullptr, *trail_hi = nullptr;
};

inline constexpr uint32_t light_bvh_outside = 0x80000000u;  // trail_hi: not in the tree
inline constexpr uint32_t light_bvh_distant = 0x40000000u;  // with it: a distant source
inline constexpr int light_bvh_max_depth = 62;
inline constexpr float light_bvh_oct_step = 2.f / 65535.f, light_bvh_cos_step = 2.f / 32767.f;
inline constexpr uint32_t light_bvh_two_sided = 1u << 30;

// The decodings: the build calls them (T = float) to check that what it stores decodes to
// bounds that hold the exact ones.
// A grid coordinate: lo + q step.
template <class T, class I> inline T light_bvh_grid(float lo, float step, const I& q) noexcept {
  return T(lo) + to_f32(q) * T(step);
}
// A 15-bit cosine: -1 + q 2 / 32767.
template <class T, class I> inline T light_bvh_cos(const I& q) noexcept {
  return to_f32(q) * T(light_bvh_cos_step) - T(1.f);
}
// The octahedral vector (u, v 16 bits each: word = u | v << 16) as a unit vector: the
// point of the octahedron |x| + |y| + |z| = 1 (the lower half folded over the upper one's
// corners), normalized.
template <class T, class I> inline Vec3<T> light_bvh_axis(const I& word) noexcept {
  const T x = to_f32(word & I(0xffff)) * T(light_bvh_oct_step) - T(1.f);
  const T y = to_f32((word >> 16) & I(0xffff)) * T(light_bvh_oct_step) - T(1.f);
  const T ax = abs(x), ay = abs(y);
  const T z = T(1.f) - ax - ay;
  const auto lower = z < T(0.f);
  const T xf = sel(lower, (T(1.f) - ay) * sel(x >= T(0.f), T(1.f), T(-1.f)), x);
  const T yf = sel(lower, (T(1.f) - ax) * sel(y >= T(0.f), T(1.f), T(-1.f)), y);
  const Vec3<T> v{xf, yf, z};
  return v / sqrt(dot(v, v));
}
// The bounding sphere of a box: its centre, and a radius that holds the box's corners
// despite the roundings (each of the few operations below errs by at most 2^-24 of its
// result; 2^-20 covers them all).
template <class T> inline void light_bvh_sphere(const Vec3<T>& lo, const Vec3<T>& hi, Vec3<T>& c, T& r) noexcept {
  c = (lo + hi) * T(0.5f);
  const Vec3<T> e{max(hi.x - c.x, c.x - lo.x), max(hi.y - c.y, c.y - lo.y), max(hi.z - c.z, c.z - lo.z)};
  r = sqrt(dot(e, e)) * T(1.f + 0x1p-20f);
}

// pbrt-v4's cos(max(0, a - b)) from the cosines and sines of a and b.
template <class T> inline T cos_sub_clamped(const T& sin_a, const T& cos_a, const T& sin_b, const T& cos_b) noexcept {
  return sel(cos_a > cos_b, T(1.f), cos_a * cos_b + sin_a * sin_b);
}
template <class T> inline T sin_sub_clamped(const T& sin_a, const T& cos_a, const T& sin_b, const T& cos_b) noexcept {
  return sel(cos_a > cos_b, T(0.f), sin_a * cos_b - cos_a * sin_b);
}
template <class T> inline T sin_from_cos(const T& c) noexcept { return sqrt(max(T(0.f), T(1.f) - c * c)); }

// The importance of node k for the shading point x with normal n (n = 0: no receiver
// orientation): phi cos(theta') / max(d^2, r) times cos(theta'_i), where theta' bounds the
// angle between the cone and the direction to x, and theta'_i the one between n and the
// node's directions, both widened by the angle the bounding sphere of the node's decoded
// box subtends at x (the whole sphere when x is inside it); 0 where theta' passes theta_e.
template <class T, class I> inline T light_bvh_importance(const LightBvhView& B, const I& k, const Vec3<T>& x,
                                                         const Vec3<T>& n) noexcept {
  const I bx = gather(reinterpret_cast<const int32_t*>(B.box_x), k);
  const I by = gather(reinterpret_cast<const int32_t*>(B.box_y), k);
  const I bz = gather(reinterpret_cast<const int32_t*>(B.box_z), k);
  const I m16(0xffff);
  const Vec3<T> lo{light_bvh_grid<T>(B.grid_lo[0], B.grid_step[0], bx & m16),
                   light_bvh_grid<T>(B.grid_lo[1], B.grid_step[1], by & m16),
                   light_bvh_grid<T>(B.grid_lo[2], B.grid_step[2], bz & m16)};
  const Vec3<T> hi{light_bvh_grid<T>(B.grid_lo[0], B.grid_step[0], (bx >> 16) & m16),
                   light_bvh_grid<T>(B.grid_lo[1], B.grid_step[1], (by >> 16) & m16),
                   light_bvh_grid<T>(B.grid_lo[2], B.grid_step[2], (bz >> 16) & m16)};
  Vec3<T> c;
  T r;
  light_bvh_sphere(lo, hi, c, r);
  const Vec3<T> w = light_bvh_axis<T>(gather(reinterpret_cast<const int32_t*>(B.axis), k));
  const I cone = gather(reinterpret_cast<const int32_t*>(B.cone), k);
  const T cos_o = light_bvh_cos<T>(cone & I(0x7fff)), cos_e = light_bvh_cos<T>((cone >> 15) & I(0x7fff));
  const auto two_sided = f_mask_from_i((cone & I(static_cast<int32_t>(light_bvh_two_sided))) != I(0));
  const T phi = gather(B.phi, k);
  const Vec3<T> d = x - c;
  const T d2 = dot(d, d);
  const T inv_d = sel(d2 > T(0.f), T(1.f) / sqrt(sel(d2 > T(0.f), d2, T(1.f))), T(0.f));
  const Vec3<T> wi = d * inv_d;  // from the node towards x (0 at the centre)
  T cos_w = dot(w, wi);
  cos_w = sel(two_sided, abs(cos_w), cos_w);
  const T sin_w = sin_from_cos(cos_w);
  const auto inside = d2 < r * r;
  const T sin2_b = sel(inside, T(1.f), min(T(1.f), (r * r) / sel(d2 > T(0.f), d2, T(1.f))));
  const T cos_b = sel(inside, T(-1.f), sqrt(T(1.f) - sin2_b));
  const T sin_b = sel(inside, T(0.f), sqrt(sin2_b));
  const T sin_o = sin_from_cos(cos_o);
  const T cos_x = cos_sub_clamped(sin_w, cos_w, sin_o, cos_o);
  const T sin_x = sin_sub_clamped(sin_w, cos_w, sin_o, cos_o);
  const T cos_p = cos_sub_clamped(sin_x, cos_x, sin_b, cos_b);
  T importance = phi * cos_p / max(d2, r);
  const T cos_i = abs(dot(wi, n));
  const T cos_pi = cos_sub_clamped(sin_from_cos(cos_i), cos_i, sin_b, cos_b);
  const auto oriented = dot(n, n) > T(0.f);
  importance = sel(oriented, importance * cos_pi, importance);
  return sel(cos_p <= cos_e, T(0.f), max(importance, T(0.f)));
}

// The light BVH as a picker (pick.h's interface).
struct BvhPicker {
  static constexpr bool reads_context = true;
  const LightBvhView& B;

  // One step down from inner node `node`: the children's importances and the chosen one's
  // probability (i_chosen / (i0 + i1); 0 where both are 0).
  template <class T> struct Step {
    i32_t<T> next;
    T p;
  };

  template <int Tier, class T> PickedLight<T> pick(const PickContext<T>& ctx, const T& u_in) const noexcept {
    using I = i32_t<T>;
    T u = u_in;
    const T p_tree = T(1.f - B.p_distant);
    PickedLight<T> out{I(0), T(0.f)};
    // the distant sources: the first p_distant of u
    auto distant = u < T(B.p_distant);
    if (B.distant > 0) {
      const T ud = u / T(B.p_distant);
      const I j = min(to_i32(ud * T(static_cast<float>(B.distant))), I(B.distant - 1));
      out.light = sel(i_mask_from_f(distant), gather(B.distant_light, max(j, I(0))), out.light);
      out.pmf = sel(distant, T(B.p_distant / static_cast<float>(B.distant)), out.pmf);
      u = sel(distant, u, min((u - T(B.p_distant)) / p_tree, T(0x1.fffffep-1f)));
    }
    if (B.nodes == 0) return out;
    I node(0);
    T pmf(1.f);
    auto live = !distant;
    for (int depth = 0; depth < light_bvh_max_depth; ++depth) {
      const I second = gather(B.child, node);
      const auto inner = live && f_mask_from_i(second >= I(0));
      if (!any(inner)) break;
      const I c0 = node + I(1), c1 = max(second, I(0));
      const T i0 = light_bvh_importance(B, c0, ctx.x, ctx.n), i1 = light_bvh_importance(B, c1, ctx.x, ctx.n);
      const T total = i0 + i1;
      const T p0 = sel(total > T(0.f), i0 / sel(total > T(0.f), total, T(1.f)), T(0.f));
      const auto go1 = u >= p0;
      const T p = sel(total > T(0.f), sel(go1, i1, i0) / sel(total > T(0.f), total, T(1.f)), T(0.f));
      // the remapped number stays below 1 (its share of [0, 1) scaled back up)
      const T un = sel(go1, (u - p0) / sel(p0 < T(1.f), T(1.f) - p0, T(1.f)), u / sel(p0 > T(0.f), p0, T(1.f)));
      u = sel(inner, min(un, T(0x1.fffffep-1f)), u);
      pmf = sel(inner, pmf * p, pmf);
      live = live && !(inner && total <= T(0.f));
      node = sel(i_mask_from_f(inner), sel(i_mask_from_f(go1), c1, c0), node);
    }
    // a tree of one source: its own importance decides whether it is picked
    if (B.nodes == 1) pmf = sel(light_bvh_importance(B, I(0), ctx.x, ctx.n) > T(0.f), pmf, T(0.f));
    const I leaf = gather(B.child, node);
    const auto picked = live && pmf > T(0.f);
    out.light = sel(i_mask_from_f(picked), I(-1) - leaf, out.light);
    out.pmf = sel(picked, pmf * p_tree, out.pmf);
    return out;
  }

  // The probability pick gives light idx at ctx (0 for a source never picked).
  template <int Tier, class T, class I> T pmf(const PickContext<T>& ctx, const I& idx_in) const noexcept {
    using IT = i32_t<T>;
    const IT idx = IT(idx_in);
    const IT lo = gather(reinterpret_cast<const int32_t*>(B.trail_lo), idx);
    const IT hi = gather(reinterpret_cast<const int32_t*>(B.trail_hi), idx);
    const IT marks = hi & IT(static_cast<int32_t>(light_bvh_outside | light_bvh_distant));
    const auto distant = f_mask_from_i(marks == IT(static_cast<int32_t>(light_bvh_outside | light_bvh_distant)));
    T out = sel(distant, T(B.distant > 0 ? B.p_distant / static_cast<float>(B.distant) : 0.f), T(0.f));
    if (B.nodes == 0) return out;
    const auto in_tree = f_mask_from_i(marks == IT(0));
    if (!any(in_tree)) return out;
    IT node(0);
    T pmf(1.f);
    auto live = in_tree;
    for (int depth = 0; depth < light_bvh_max_depth; ++depth) {
      const IT second = gather(B.child, node);
      const auto inner = live && f_mask_from_i(second >= IT(0));
      if (!any(inner)) break;
      const IT c0 = node + IT(1), c1 = max(second, IT(0));
      const T i0 = light_bvh_importance(B, c0, ctx.x, ctx.n), i1 = light_bvh_importance(B, c1, ctx.x, ctx.n);
      const T total = i0 + i1;
      const IT word = depth < 32 ? lo : hi;
      const auto go1 = f_mask_from_i(((word >> (depth & 31)) & IT(1)) != IT(0));
      const T p = sel(total > T(0.f), sel(go1, i1, i0) / sel(total > T(0.f), total, T(1.f)), T(0.f));
      pmf = sel(inner, pmf * p, pmf);
      node = sel(i_mask_from_f(inner), sel(i_mask_from_f(go1), c1, c0), node);
    }
    if (B.nodes == 1) pmf = sel(light_bvh_importance(B, IT(0), ctx.x, ctx.n) > T(0.f), pmf, T(0.f));
    return sel(in_tree, pmf * T(1.f - B.p_distant), out);
  }
};

}  // namespace tuile

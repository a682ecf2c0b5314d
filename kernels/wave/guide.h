// Path guiding (--guide, Estimator::guide): a learned distribution of the light that
// arrives at each region of the scene, mixed with BSDF sampling at the points whose
// surface is diffuse (Lambert). After Müller, Gross & Novák 2017 ("Practical Path
// Guiding"): a binary tree over space, refined where many path vertices fall, whose leaves
// hold a distribution over directions, each an adaptive quadtree on the equal-area
// octahedral square (light/sky_map.h: the square maps to the sphere with a constant
// Jacobian of 4 pi, so a density over the square is a density over solid angle times
// 4 pi). A quadtree node holds its four quadrants' shares of its light; it was split where
// it held more than a set share of the distribution's light, so its cells are fine where
// the light is and coarse where it is not. Sampling descends it choosing quadrants by
// their shares (a column, then a row within it), the density is the product of 4 x share
// along the descent; the descents gather per lane and run to the deepest lane's leaf, so
// every lane gives the scalar reference's bits.
// src/render/guide.cpp learns the trees from the paths of earlier samples.
//
// The estimator stays unbiased whatever was learned: a guided point draws its direction
// from the guide with probability alpha, else from its BSDF, and every density the
// techniques compare (the BSDF sample's throughput f cos / p, the MIS weights of the light
// samples and of the emitters and sky the BSDF samples reach) is the mixture's
//   p(wi) = alpha p_guide(wi) + (1 - alpha) p_bsdf(wi)
// (a delta lobe of the BSDF keeps its delta, drawn with probability (1 - alpha) times its
// own). A point is guided where its material is diffuse and its leaf
// learned a distribution; the same test decides in the BSDF and the light stages, so both
// see the same density.
#pragma once
#include <cstdint>

#include "bsdf/bsdf.h"
#include "light/sky_map.h"
#include "wave/tile.h"
#include "wave/views.h"

namespace tuile {

// Each leaf learns one distribution per class of surface orientation: the axis its normal
// (facing the viewer) is closest to, and that axis's sign. A leaf that holds a floor and
// a wall keeps their light apart.
inline constexpr int guide_classes = 6;
// A directional quadtree is at most this deep (cells of 1/4096 of the square's side; a
// sample's two numbers give up about one bit each per level, so 12 levels leave them 12).
inline constexpr int guide_quad_depth = 12;

// The guide as the kernels read it (src/render/guide.h builds it).
struct GuideView {
  int32_t depth = 0;              // the tree's depth (descent steps)
  const int32_t* child = nullptr; // per node: >= 0 the first of its two children; -1 a leaf
  const int32_t* leaf_dist = nullptr;  // per node, guide_classes distributions (-1: none learned)
  const int32_t* axis = nullptr;  // per node: the split axis
  const float* split = nullptr;   // per node: the split plane (a point on it goes to the second child)
  // the directional quadtrees: distribution d's root is quad node root[d]; per quad node,
  // quad_child >= 0 the first of its four children (quadrants u-low v-low, u-high v-low,
  // u-low v-high, u-high v-high), -1 a leaf; quad_share the four quadrants' shares of the
  // node's light (they sum to 1; inner nodes only)
  const int32_t* root = nullptr;
  const int32_t* quad_child = nullptr;
  const float* quad_share = nullptr;
  int32_t quad_depth = 0;         // the deepest quadtree's depth (descent steps)
  float alpha = 0.5f;             // the probability of drawing from the guide at a guided point
};

// The class of the normal n (guide_classes).
template <class T> inline i32_t<T> guide_class(const Vec3<T>& n) {
  const T ax = abs(n.x), ay = abs(n.y), az = abs(n.z);
  const auto xm = ax >= ay && ax >= az, ym = !xm && ay >= az;
  const T c = sel(xm, sel(n.x < T(0.f), T(1.f), T(0.f)),
                  sel(ym, sel(n.y < T(0.f), T(3.f), T(2.f)), sel(n.z < T(0.f), T(5.f), T(4.f))));
  return to_i32(c);
}

// The distribution of the leaf holding x for a point of normal n (-1: none learned).
template <class T> inline i32_t<T> guide_dist(const GuideView& g, const Vec3<T>& x, const Vec3<T>& n) {
  i32_t<T> node(0);
  for (int32_t s = 0; s < g.depth; ++s) {
    const i32_t<T> c = gather(g.child, node);
    const auto inner = c >= i32_t<T>(0);
    if (!any(f_mask_from_i(inner))) break;
    const i32_t<T> ax = gather(g.axis, node);
    const T sp = gather(g.split, node);
    const T coord = sel(f_mask_from_i(ax == i32_t<T>(0)), x.x, sel(f_mask_from_i(ax == i32_t<T>(1)), x.y, x.z));
    const i32_t<T> right = sel(i_mask_from_f(coord >= sp), i32_t<T>(1), i32_t<T>(0));
    node = sel(inner, c + right, node);
  }
  return gather(g.leaf_dist, node * i32_t<T>(guide_classes) + guide_class(n));
}

// The guide's density (solid angle) of the unit direction d in distribution dist (>= 0).
template <class T> inline T guide_pdf(const GuideView& g, const i32_t<T>& dist, const Vec3<T>& d) {
  T u, v;
  equal_area_sphere_to_square(d, u, v);
  i32_t<T> node = gather(g.root, dist);
  T p(1.f / (4.f * pi_f));
  for (int32_t s = 0; s < g.quad_depth; ++s) {
    const i32_t<T> c = gather(g.quad_child, node);
    const auto inner = f_mask_from_i(c >= i32_t<T>(0));
    if (!any(inner)) break;
    const auto hu = u >= T(0.5f), hv = v >= T(0.5f);
    const i32_t<T> q = to_i32(sel(hu, T(1.f), T(0.f)) + sel(hv, T(2.f), T(0.f)));
    const T share = gather(g.quad_share, sel(i_mask_from_f(inner), node, i32_t<T>(0)) * i32_t<T>(4) + q);
    p = sel(inner, p * (T(4.f) * share), p);
    u = sel(inner, T(2.f) * u - sel(hu, T(1.f), T(0.f)), u);
    v = sel(inner, T(2.f) * v - sel(hv, T(1.f), T(0.f)), v);
    node = sel(i_mask_from_f(inner), c + q, node);
  }
  return p;
}

// A direction drawn from distribution dist (>= 0) by (u1, u2).
template <class T> inline Vec3<T> guide_sample(const GuideView& g, const i32_t<T>& dist, const T& u1, const T& u2) {
  const T one_minus = T(0x1.fffffep-1f);
  T a = u1, b = u2, ou(0.f), ov(0.f), size(1.f);
  i32_t<T> node = gather(g.root, dist);
  for (int32_t s = 0; s < g.quad_depth; ++s) {
    const i32_t<T> c = gather(g.quad_child, node);
    const auto inner = f_mask_from_i(c >= i32_t<T>(0));
    if (!any(inner)) break;
    const i32_t<T> base = sel(i_mask_from_f(inner), node, i32_t<T>(0)) * i32_t<T>(4);
    const T s0 = gather(g.quad_share, base), s1 = gather(g.quad_share, base + i32_t<T>(1));
    const T s2 = gather(g.quad_share, base + i32_t<T>(2)), s3 = gather(g.quad_share, base + i32_t<T>(3));
    // the column (u) by its two quadrants' shares, then the row (v) within it
    const T left = s0 + s2;
    const auto hu = a >= left;
    const T au = sel(hu, (a - left) / sel(left < T(1.f), T(1.f) - left, T(1.f)), a / sel(left > T(0.f), left, T(1.f)));
    const T lo = sel(hu, s1, s0), hi = sel(hu, s3, s2), col = lo + hi;
    const T plo = lo / sel(col > T(0.f), col, T(1.f));
    const auto hv = b >= plo;
    const T bv = sel(hv, (b - plo) / sel(plo < T(1.f), T(1.f) - plo, T(1.f)), b / sel(plo > T(0.f), plo, T(1.f)));
    const T half = T(0.5f) * size;
    ou = sel(inner, ou + sel(hu, half, T(0.f)), ou);
    ov = sel(inner, ov + sel(hv, half, T(0.f)), ov);
    size = sel(inner, half, size);
    a = sel(inner, min(max(au, T(0.f)), one_minus), a);
    b = sel(inner, min(max(bv, T(0.f)), one_minus), b);
    const i32_t<T> q = to_i32(sel(hu, T(1.f), T(0.f)) + sel(hv, T(2.f), T(0.f)));
    node = sel(i_mask_from_f(inner), c + q, node);
  }
  return equal_area_square_to_sphere(ou + a * size, ov + b * size);
}

// Whether a material kind is guided: diffuse surfaces (a coated diffuse's glossy or mirror
// coat, sampled half as often, lost more than the guide gained: bench/results.md).
template <class T> inline mask_t<T> guided_kind(const i32_t<T>& kind) {
  return f_mask_from_i(kind == i32_t<T>(static_cast<int32_t>(MaterialKind::diffuse)));
}

// --guide: the share alpha of the guide at shading points [k, k + width) (0 where the point
// is not guided: its material, or its leaf learned nothing), and each lane's distribution
// (0 where none, so that it can be gathered from).
template <class T, unsigned Bsdfs>
inline T guide_share(const GeomView& G, const ShadingPoints& P, int k, const Vec3<T>& x, i32_t<T>& dist) {
  const Vec3<T> n = load3<T>(P.nx + k, P.ny + k, P.nz + k);
  const i32_t<T> d = guide_dist(*G.guide, x, n);
  auto m = f_mask_from_i(d >= i32_t<T>(0));
  if constexpr (Bsdfs != bsdf_diffuse) m = m && guided_kind<T>(gather(G.mat_kind, load_i32<T>(P.mat + k)));
  dist = sel(d >= i32_t<T>(0), d, i32_t<T>(0));
  return sel(m, T(G.guide->alpha), T(0.f));
}

// --guide: the density of the mixture alpha guide + (1 - alpha) BSDF of direction wi,
// whose BSDF density is pdf_b.
template <class T>
inline T guide_mixture_pdf(const GeomView& G, const T& alpha, const i32_t<T>& dist, const Vec3<T>& wi, const T& pdf_b) {
  if (!any(alpha > T(0.f))) return pdf_b;
  return sel(alpha > T(0.f), alpha * guide_pdf(*G.guide, dist, wi) + (T(1.f) - alpha) * pdf_b, pdf_b);
}

}  // namespace tuile

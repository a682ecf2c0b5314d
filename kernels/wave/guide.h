// Path guiding (--guide, Estimator::guide): a learned distribution of the light that
// arrives at each region of the scene, mixed with BSDF sampling at the points whose
// surface is diffuse (Lambert) and with phase-function sampling at points inside a medium. After Müller, Gross & Novák 2017 ("Practical Path
// Guiding"): a binary tree over space, refined where many path vertices fall, whose leaves
// hold a distribution over directions. Here the directional part is a fixed grid of
// guide_res x guide_res cells on the equal-area octahedral square (light/sky_map.h: the
// square maps to the sphere with a constant Jacobian of 4 pi, so a density over cells is a
// density over solid angle divided by 4 pi), sampled like an environment map (rows by
// their marginal, then a column; inversion with gathers, the same bits in every lane).
// src/render/guide.cpp learns the tree and the cells from the paths of earlier samples.
//
// The estimator stays unbiased whatever was learned: a guided point draws its direction
// from the guide with probability alpha, else from its BSDF, and every density the
// techniques compare (the BSDF sample's throughput f cos / p, the MIS weights of the light
// samples and of the emitters and sky the BSDF samples reach) is the mixture's
//   p(wi) = alpha p_guide(wi) + (1 - alpha) p_bsdf(wi)
// (a delta lobe of the BSDF keeps its delta, drawn with probability (1 - alpha) times its
// own). A point is guided where its material is diffuse, or it is in a medium, and its leaf
// learned a distribution for its class; the same test decides in the BSDF and the light stages, so both
// see the same density.
#pragma once
#include <cstdint>

#include "bsdf/bsdf.h"
#include "light/sky_map.h"
#include "wave/tile.h"
#include "wave/views.h"

namespace tuile {

inline constexpr int guide_res = 16;                       // cells per side of the square
inline constexpr int guide_cells = guide_res * guide_res;  // per distribution
// Each leaf learns one distribution per class of point: for a surface, the axis its normal
// (facing the viewer) is closest to, and that axis's sign (a leaf that holds a floor and a
// wall keeps their light apart); a point inside a participating medium (its phase
// function's, which has no side) is the last class, guide_medium_class.
inline constexpr int guide_classes = 7;
inline constexpr int guide_medium_class = 6;

// The guide as the kernels read it (src/render/guide.h builds it).
struct GuideView {
  int32_t depth = 0;              // the tree's depth (descent steps)
  const int32_t* child = nullptr; // per node: >= 0 the first of its two children; -1 a leaf
  const int32_t* leaf_dist = nullptr;  // per node, guide_classes distributions (-1: none learned)
  const int32_t* axis = nullptr;  // per node: the split axis
  const float* split = nullptr;   // per node: the split plane (a point on it goes to the second child)
  const float* func = nullptr;    // per distribution, guide_cells densities over the unit square (mean 1)
  const float* cond_cdf = nullptr;  // per distribution, guide_res rows of guide_res + 1 values
  const float* marg_cdf = nullptr;  // per distribution, guide_res + 1 values over the rows
  float alpha = 0.5f;             // the probability of drawing from the guide at a guided point
};

// The class of a surface point of normal n (guide_classes).
template <class T> inline i32_t<T> guide_class(const Vec3<T>& n) {
  const T ax = abs(n.x), ay = abs(n.y), az = abs(n.z);
  const auto xm = ax >= ay && ax >= az, ym = !xm && ay >= az;
  const T c = sel(xm, sel(n.x < T(0.f), T(1.f), T(0.f)),
                  sel(ym, sel(n.y < T(0.f), T(3.f), T(2.f)), sel(n.z < T(0.f), T(5.f), T(4.f))));
  return to_i32(c);
}

// The distribution of the leaf holding x for a point of class cls (-1: none learned).
template <class T> inline i32_t<T> guide_dist(const GuideView& g, const Vec3<T>& x, const i32_t<T>& cls) {
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
  return gather(g.leaf_dist, node * i32_t<T>(guide_classes) + cls);
}
// ... for a surface point of normal n.
template <class T> inline i32_t<T> guide_dist(const GuideView& g, const Vec3<T>& x, const Vec3<T>& n) {
  return guide_dist(g, x, guide_class(n));
}

// The guide's density (solid angle) of the unit direction d in distribution dist (>= 0).
template <class T> inline T guide_pdf(const GuideView& g, const i32_t<T>& dist, const Vec3<T>& d) {
  T pu, pv;
  equal_area_sphere_to_square(d, pu, pv);
  const i32_t<T> cell = sky_texel<T>(guide_res, pu, pv);
  return gather(g.func, dist * i32_t<T>(guide_cells) + cell) * T(1.f / (4.f * pi_f));
}

// A direction drawn from distribution dist (>= 0) by (u1, u2), and its density.
template <class T> inline Vec3<T> guide_sample(const GuideView& g, const i32_t<T>& dist, const T& u1, const T& u2) {
  constexpr int32_t n = guide_res;
  const T one_minus = T(0x1.fffffep-1f);
  const i32_t<T> mbase = dist * i32_t<T>(n + 1);
  const i32_t<T> row = find_interval<T>(g.marg_cdf, n, mbase, u2);
  const T c0 = gather(g.marg_cdf, mbase + row), c1 = gather(g.marg_cdf, mbase + row + i32_t<T>(1));
  const T dv = min(max((u2 - c0) / sel(c1 > c0, c1 - c0, T(1.f)), T(0.f)), one_minus);
  const i32_t<T> base = (dist * i32_t<T>(n) + row) * i32_t<T>(n + 1);
  const i32_t<T> col = find_interval<T>(g.cond_cdf, n, base, u1);
  const T k0 = gather(g.cond_cdf, base + col), k1 = gather(g.cond_cdf, base + col + i32_t<T>(1));
  const T du = min(max((u1 - k0) / sel(k1 > k0, k1 - k0, T(1.f)), T(0.f)), one_minus);
  const T fn = T(static_cast<float>(n));
  return equal_area_square_to_sphere((to_f32(col) + du) / fn, (to_f32(row) + dv) / fn);
}

// Whether a material kind is guided: diffuse surfaces (a coated diffuse's glossy or mirror
// coat, sampled half as often, lost more than the guide gained: bench/results.md) and
// points inside a medium (the phase function's: volume path guiding, where the light a
// medium point sees comes through a lens or a gap, as a volumetric caustic's does).
template <class T> inline mask_t<T> guided_kind(const i32_t<T>& kind) {
  return f_mask_from_i(kind == i32_t<T>(static_cast<int32_t>(MaterialKind::diffuse)) ||
                       kind == i32_t<T>(static_cast<int32_t>(MaterialKind::phase)));
}

// --guide: the share alpha of the guide at shading points [k, k + width) (0 where the point
// is not guided: its material, or its leaf learned nothing), and each lane's distribution
// (0 where none, so that it can be gathered from).
template <class T, unsigned Bsdfs>
inline T guide_share(const GeomView& G, const ShadingPoints& P, int k, const Vec3<T>& x, i32_t<T>& dist) {
  const Vec3<T> n = load3<T>(P.nx + k, P.ny + k, P.nz + k);
  i32_t<T> cls = guide_class(n);
  auto m = mask_t<T>(true);
  if constexpr (Bsdfs != bsdf_diffuse) {
    const i32_t<T> kind = gather(G.mat_kind, load_i32<T>(P.mat + k));
    m = guided_kind<T>(kind);
    if constexpr ((Bsdfs & bsdf_phase) != 0)
      cls = sel(kind == i32_t<T>(static_cast<int32_t>(MaterialKind::phase)), i32_t<T>(guide_medium_class), cls);
  }
  const i32_t<T> d = guide_dist(*G.guide, x, cls);
  m = m && f_mask_from_i(d >= i32_t<T>(0));
  dist = sel(d >= i32_t<T>(0), d, i32_t<T>(0));
  return sel(m, T(G.guide->alpha), T(0.f));
}

// --guide: each shading point's share and distribution (guide_share) into
// ShadingPoints::guide_alpha and guide_dist, once a vertex, before its light and BSDF stages
// read them (the descent of the guide's tree is the costly part).
template <unsigned Bsdfs> inline void guide_points(const GeomView& G, TileBuffers& tb) {
  const int padded = packet_padded(tb.points.count);
  for_lane_batches<vfloat2>(0, padded, [&](auto lane, int k) {
    using T = typename decltype(lane)::type;
    i32_t<T> dist;
    const T alpha = guide_share<T, Bsdfs>(G, tb.points, k, load3<T>(tb.points.px + k, tb.points.py + k, tb.points.pz + k), dist);
    store(tb.points.guide_alpha + k, alpha);
    store(tb.points.guide_dist + k, dist);
  });
}

// --guide: the density of the mixture alpha guide + (1 - alpha) BSDF of direction wi,
// whose BSDF density is pdf_b.
template <class T>
inline T guide_mixture_pdf(const GeomView& G, const T& alpha, const i32_t<T>& dist, const Vec3<T>& wi, const T& pdf_b) {
  if (!any(alpha > T(0.f))) return pdf_b;
  return sel(alpha > T(0.f), alpha * guide_pdf(*G.guide, dist, wi) + (T(1.f) - alpha) * pdf_b, pdf_b);
}

}  // namespace tuile

// Environment maps (LightSource "infinite" with an image): pbrt-v4's one layout, the
// equal-area octahedral square (Clarberg 2008; pbrt-v4's EqualAreaSquareToSphere and
// EqualAreaSphereToSquare): the unit square maps onto the sphere of directions with a
// constant Jacobian of 4 pi, centre +z of the light's frame, texels looked up nearest.
// Because the map preserves area, a piecewise-constant density over the texels is a
// piecewise-constant density over solid angle: pdf(w) = pdf_uv(texel of w) / (4 pi).
//
// Sampling: a piecewise-constant 2-D distribution over the texels (rows by their marginal,
// then a column in the row: pbrt-v4's PiecewiseConstant2D), found by a binary search with
// gathers that starts from the CDFs' cut points (the same bits in every lane and the scalar
// reference, and the same interval as a search of the whole CDF).
// Each map has two distributions, built by src/scene/sky_map.cpp:
//   full:        the texels' mean channel (pbrt-v4's GetSamplingDistribution);
//   compensated: max(value - mean, 0) (Karlik et al. 2019, "MIS compensation"; pbrt-v4's
//                compensatedDistribution), all ones where that leaves nothing. It leaves
//                the directions darker than the mean to the BSDF technique, so it is used
//                only where BSDF sampling also covers every direction (MIS, and RIS with
//                BSDF candidates: LightView::sky_dist).
// Reads: the map's texels (R G B and the compensated distribution's weight, four floats a
// texel, row-major, top row first) and distribution tables.
#pragma once
#include <bit>
#include <cstdint>

#include "lanes/lane_math.h"
#include "lanes/vec.h"

namespace tuile {

inline constexpr int sky_dist_full = 0, sky_dist_compensated = 1;
// The largest map, texels a side (`tuile envmap --resolution`'s too): its lookups index four
// floats a texel in 32 bits.
inline constexpr int32_t sky_map_max_res = 16384;

// One piecewise-constant distribution over a map's res x res texels.
struct SkyDistView {
  const float* func = nullptr;      // res * res weights, row-major (>= 0, not all zero), texel i's at func[i * stride]
  int32_t stride = 1;               // (4 where they sit beside the texels' radiance: SkyMapView::texels)
  const float* cond_cdf = nullptr;  // res rows of res + 1 values: 0 ... 1 within the row
  const float* marg_cdf = nullptr;  // res + 1 values over the rows: 0 ... 1
  // cut points (a guide table, Chen and Asau 1974) of each row's CDF and of the marginal:
  // cuts + 1 per CDF, the j-th the largest i < res with cdf[i] <= j / cuts (cuts a power
  // of two), so the interval of u lies between those of floor(u cuts) and the next
  const int32_t* cond_cut = nullptr;  // res rows of cuts + 1
  const int32_t* marg_cut = nullptr;  // cuts + 1
  int32_t cuts = 1;
  float inv_mean = 0;               // 1 / the mean of func: func * inv_mean is the density over the unit square
};

// A map as the kernels read it.
struct SkyMapView {
  int32_t res = 0;
  const float* texels = nullptr;  // res * res texels, row-major, top row first: r, g, b and a weight each
  SkyDistView dist[2];                                    // sky_dist_full, sky_dist_compensated
};

// |mag| with the sign of s (s < 0: negative).
template <class T> inline T sign_of(const T& mag, const T& s) { return sel(s < T(0.f), -mag, mag); }

// The direction of the point p of the unit square (pbrt-v4's EqualAreaSquareToSphere).
template <class T> inline Vec3<T> equal_area_square_to_sphere(const T& px, const T& py) {
  const T u = T(2.f) * px - T(1.f), v = T(2.f) * py - T(1.f);
  const T up = abs(u), vp = abs(v);
  const T sd = T(1.f) - (up + vp);  // signed distance to the diagonal: > 0 in the +z half
  const T r = T(1.f) - abs(sd);
  const auto pole = r == T(0.f);
  const T phi = sel(pole, T(1.f), (vp - up) / sel(pole, T(1.f), r) + T(1.f)) * T(pi_f / 4.f);
  const T z = sign_of(T(1.f) - r * r, sd);
  T s, c;
  lane_math::sincos(phi, s, c);
  const T k = r * sqrt(max(T(2.f) - r * r, T(0.f)));
  return {sign_of(c, u) * k, sign_of(s, v) * k, z};
}

// The point of the unit square of the unit direction d (pbrt-v4's EqualAreaSphereToSquare).
template <class T> inline void equal_area_sphere_to_square(const Vec3<T>& d, T& pu, T& pv) {
  const T x = abs(d.x), y = abs(d.y), z = abs(d.z);
  const T r = sqrt(max(T(1.f) - z, T(0.f)));
  // the angle in the octant's quarter, as a fraction of a quarter turn
  T phi = lane_math::atan2(min(x, y), max(x, y)) * T(2.f / pi_f);
  phi = sel(x < y, T(1.f) - phi, phi);
  const T v = phi * r, u = r - v;
  const auto south = d.z < T(0.f);  // the -z half folds onto the corners
  const T us = sel(south, T(1.f) - v, u), vs = sel(south, T(1.f) - u, v);
  pu = (sign_of(us, d.x) + T(1.f)) * T(0.5f);
  pv = (sign_of(vs, d.y) + T(1.f)) * T(0.5f);
}

// The texel (row-major index) holding the point (pu, pv) of the square, nearest lookup: the
// texel whose cell contains it (the closed edge 1 belongs to the last texel). Any input,
// NaN included, gives a texel of the map (the clamp compares, so NaN goes to 0).
template <class T> inline i32_t<T> sky_texel(int32_t res, const T& pu, const T& pv) {
  const T n = T(static_cast<float>(res)), last = T(static_cast<float>(res - 1));
  const T x = pu * n, y = pv * n;
  const i32_t<T> ix = to_i32(sel(x > T(0.f), sel(x < last, x, last), T(0.f)));
  const i32_t<T> iy = to_i32(sel(y > T(0.f), sel(y < last, y, last), T(0.f)));
  return iy * i32_t<T>(res) + ix;
}

// The largest i in [0, n) with cdf[base + i] <= u (cdf non-decreasing, cdf[base] <= u):
// a binary search of fixed length, one gather per step.
template <class T> inline i32_t<T> find_interval(const float* cdf, int32_t n, const i32_t<T>& base, const T& u) {
  i32_t<T> i(0);
  for (int32_t step = static_cast<int32_t>(std::bit_floor(static_cast<uint32_t>(n))); step > 0; step >>= 1) {
    const i32_t<T> cand = i + i32_t<T>(step);
    const auto in = cand <= i32_t<T>(n - 1);
    const auto le = i_mask_from_f(gather(cdf, base + sel(in, cand, i32_t<T>(0))) <= u);
    i = sel(in && le, cand, i);
  }
  return i;
}

// The same interval from the cut points (cut: the CDF's cuts + 1 entries, cuts a power of
// two): the search starts between the cuts around u, within a few values where the CDF is
// smooth, instead of log2(n) steps whose first ones miss the cache. The same i for every u
// in [0, 1): with j = floor(u cuts) (exact), cdf[cut[j]] <= j / cuts <= u, and the answer's
// cdf <= u < (j + 1) / cuts puts it at or below cut[j + 1].
template <class T>
inline i32_t<T> find_interval_cut(const float* cdf, const i32_t<T>& base, const int32_t* cut, const i32_t<T>& cut_base, int32_t cuts,
                                  const T& u) {
  i32_t<T> j = to_i32(u * T(static_cast<float>(cuts)));
  j = sel(j < i32_t<T>(0), i32_t<T>(0), sel(j > i32_t<T>(cuts - 1), i32_t<T>(cuts - 1), j));
  i32_t<T> lo = gather(cut, cut_base + j), hi = gather(cut, cut_base + j + i32_t<T>(1));
  for (auto open = lo < hi; any(open); open = lo < hi) {
    const i32_t<T> mid = lo + ((hi - lo + i32_t<T>(1)) >> 1);
    const auto le = open && i_mask_from_f(gather(cdf, base + sel(open, mid, lo)) <= u);
    hi = sel(open && !le, mid - i32_t<T>(1), hi);
    lo = sel(le, mid, lo);
  }
  return lo;
}

// A point of the unit square drawn from a map's distribution: the point, its texel and the
// density over the square (func * inv_mean of that texel).
template <class T> struct SkyMapSample {
  T pu, pv, pdf_uv;
  i32_t<T> texel;
};

// u2 picks the row by the marginal, u1 the column within it; the offsets inside the texel
// keep the numbers' stratification (inversion, not an alias table).
template <class T> inline SkyMapSample<T> sample_sky_map(const SkyMapView& m, int dist, const T& u1, const T& u2) {
  const SkyDistView& d = m.dist[dist];
  const int32_t n = m.res;
  const T one_minus = T(0x1.fffffep-1f);
  const i32_t<T> row = find_interval_cut<T>(d.marg_cdf, i32_t<T>(0), d.marg_cut, i32_t<T>(0), d.cuts, u2);
  const T c0 = gather(d.marg_cdf, row), c1 = gather(d.marg_cdf, row + i32_t<T>(1));
  const T dv = min(max((u2 - c0) / sel(c1 > c0, c1 - c0, T(1.f)), T(0.f)), one_minus);
  const i32_t<T> base = row * i32_t<T>(n + 1);
  const i32_t<T> col = find_interval_cut<T>(d.cond_cdf, base, d.cond_cut, row * i32_t<T>(d.cuts + 1), d.cuts, u1);
  const T k0 = gather(d.cond_cdf, base + col), k1 = gather(d.cond_cdf, base + col + i32_t<T>(1));
  const T du = min(max((u1 - k0) / sel(k1 > k0, k1 - k0, T(1.f)), T(0.f)), one_minus);
  SkyMapSample<T> s;
  const T fn = T(static_cast<float>(n));
  s.pu = (to_f32(col) + du) / fn;
  s.pv = (to_f32(row) + dv) / fn;
  s.texel = row * i32_t<T>(n) + col;
  s.pdf_uv = gather(d.func, s.texel * i32_t<T>(d.stride)) * T(d.inv_mean);
  return s;
}

// The density over the square of the texel's cell under the distribution.
template <class T> inline T sky_map_pdf_uv(const SkyMapView& m, int dist, const i32_t<T>& texel) {
  const SkyDistView& d = m.dist[dist];
  return gather(d.func, texel * i32_t<T>(d.stride)) * T(d.inv_mean);
}

// Direction d (world) in the light's frame (orthonormal axes ex, ey, ez), and back.
template <class T> inline Vec3<T> to_sky_frame(const Vec3<T>& d, const Vec3<T>& ex, const Vec3<T>& ey, const Vec3<T>& ez) {
  return {dot(d, ex), dot(d, ey), dot(d, ez)};
}
template <class T>
inline Vec3<T> from_sky_frame(const Vec3<T>& w, const Vec3<T>& ex, const Vec3<T>& ey, const Vec3<T>& ez) {
  return {mul_add(ex.x, w.x, mul_add(ey.x, w.y, ez.x * w.z)), mul_add(ex.y, w.x, mul_add(ey.y, w.y, ez.y * w.z)),
          mul_add(ex.z, w.x, mul_add(ey.z, w.y, ez.z * w.z))};
}

}  // namespace tuile

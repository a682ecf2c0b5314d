// Stage 6, accumulate: one sample of every pixel of the tile into the tile's double sums
// (camera-visible emission plus the shading point's sum, its square, the BSDF MIS weight AOV, largest sample luminance). A sample
// with a non-finite channel counts as rejected and adds 0. run_tile zeroes the sums at
// tile start and adds them into the Film once, after the tile's last sample.
// Reads the tile radiance (and wsum/wcnt with the AOV); writes the tile sums,
// rejected_camera.
#pragma once
#include <bit>

#include "tile.h"

namespace tuile {

template <class T> inline T luminance(T r, T g, T b) { return T(0.2126f) * r + T(0.7152f) * g + T(0.0722f) * b; }

using vdouble = xsimd::batch<double>;
static_assert(2 * vdouble::size == vfloat::size, "a float batch converts to two double batches");

// Adds the lanes of v, converted to double, to dst (add_sq_f64: and their squares to sq).
inline void add_f64(double* dst, float v) noexcept { *dst += static_cast<double>(v); }
inline void add_sq_f64(double* dst, double* sq, float v) noexcept {
  const double x = v;
  *dst += x;
  *sq += x * x;
}
inline void to_f64(const vfloat& v, vdouble& lo, vdouble& hi) noexcept {
#if defined(__AVX512F__)
  lo = _mm512_cvtps_pd(_mm512_castps512_ps256(v));
  hi = _mm512_cvtps_pd(_mm256_castpd_ps(_mm512_extractf64x4_pd(_mm512_castps_pd(v), 1)));
#elif defined(__AVX__)
  lo = _mm256_cvtps_pd(_mm256_castps256_ps128(v));
  hi = _mm256_cvtps_pd(_mm256_extractf128_ps(v, 1));
#else
  lo = _mm_cvtps_pd(v);
  hi = _mm_cvtps_pd(_mm_movehl_ps(v, v));
#endif
}
inline void add_f64(double* dst, const vfloat& v) noexcept {
  vdouble lo, hi;
  to_f64(v, lo, hi);
  (vdouble::load_aligned(dst) + lo).store_aligned(dst);
  (vdouble::load_aligned(dst + vdouble::size) + hi).store_aligned(dst + vdouble::size);
}
inline void add_sq_f64(double* dst, double* sq, const vfloat& v) noexcept {
  vdouble lo, hi;
  to_f64(v, lo, hi);
  (vdouble::load_aligned(dst) + lo).store_aligned(dst);
  (vdouble::load_aligned(dst + vdouble::size) + hi).store_aligned(dst + vdouble::size);
  (vdouble::load_aligned(sq) + lo * lo).store_aligned(sq);
  (vdouble::load_aligned(sq + vdouble::size) + hi * hi).store_aligned(sq + vdouble::size);
}

// Lanes [i, i + width) of the tile; lanes from `lanes` on are padding (never counted).
template <class T> TUILE_FLATTEN inline void accumulate_lanes(TileBuffers& tb, int i, int lanes, bool aov) {
  T r = load<T>(tb.Lr + i), g = load<T>(tb.Lg + i), b = load<T>(tb.Lb + i);
  // plus what the techniques added to the lanes' shading points: camera_hits compacted
  // them in lane order, so an expand reads them back
  const uint32_t shaded = lane_bits(f_mask_from_i(load_i32<T>(tb.shade_of + i) >= i32_t<T>(0)));
  // A batch without shading points and without emission (camera rays that all missed):
  // it would add +0 to every sum and leave every maximum, so it is skipped, with the same
  // bits. (Lanes without a shading point have no MIS weight either; tested all the same.)
  if (!shaded && !any((r != T(0.f)) || (g != T(0.f)) || (b != T(0.f))) &&
      !(aov && any((load<T>(tb.wsum + i) != T(0.f)) || (load<T>(tb.wcnt + i) != T(0.f)))))
    return;
  if (shaded) {
    const int32_t first = tb.shade_of[i + std::countr_zero(shaded)];
    r = r + expand_load<T>(tb.Sr + first, shaded);
    g = g + expand_load<T>(tb.Sg + first, shaded);
    b = b + expand_load<T>(tb.Sb + first, shaded);
  }
  const auto finite = is_finite(r) && is_finite(g) && is_finite(b);
  const auto live = f_mask_from_i(i32_t<T>(i) + lane_iota_i32<T>() < i32_t<T>(lanes));
  tb.rejected_camera += static_cast<uint64_t>(std::popcount(lane_bits(live && !finite)));
  r = sel(finite, r, T(0.f));
  g = sel(finite, g, T(0.f));
  b = sel(finite, b, T(0.f));
  add_sq_f64(tb.acc_r + i, tb.acc_rr + i, r);
  add_sq_f64(tb.acc_g + i, tb.acc_gg + i, g);
  add_sq_f64(tb.acc_b + i, tb.acc_bb + i, b);
  if (aov) {  // no AOV requested: none computed
    add_f64(tb.acc_w + i, load<T>(tb.wsum + i));
    add_f64(tb.acc_wc + i, load<T>(tb.wcnt + i));
  }
  const T y = luminance(r, g, b);
  const T m = load<T>(tb.acc_max + i);
  store(tb.acc_max + i, sel(y > m, y, m));
}

// Zeroes the tile sums of lanes [0, lanes) padded to a whole packet.
inline void clear_tile_sums(TileBuffers& tb, int lanes) {
  const int padded = (lanes + packet_width - 1) / packet_width * packet_width;
  for (double* a : {tb.acc_r, tb.acc_g, tb.acc_b, tb.acc_rr, tb.acc_gg, tb.acc_bb, tb.acc_w, tb.acc_wc})
    std::fill_n(a, padded, 0.0);
  std::fill_n(tb.acc_max, padded, 0.f);
}

// One sample of every pixel of the tile. T = float is the scalar reference.
template <class T = vfloat> inline void accumulate_samples(TileBuffers& tb, int lanes, bool aov) {
  const int padded = (lanes + packet_width - 1) / packet_width * packet_width;
  for (int i = 0; i < padded; i += lane_traits<T>::width) accumulate_lanes<T>(tb, i, lanes, aov);
}

}  // namespace tuile

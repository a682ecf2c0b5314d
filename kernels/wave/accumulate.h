// Stage 6, accumulate: one sample of every pixel of the tile into the tile's double sums
// (camera-visible emission plus the shading point's sum, its square, the BSDF MIS weight AOV, largest sample luminance). A sample
// with a non-finite channel counts as rejected and adds 0. run_tile zeroes the sums at
// tile start and adds them into the Film once, after the tile's last sample.
// Reads the tile radiance (and wsum/wcnt with the AOV; the pixel filter's weights fw where
// lanes.weighted); writes the tile sums, rejected_camera.
// A weighted filter (mitchell, sinc) makes some samples negative: the sums and squares take
// them as they are, the largest sample luminance stays the largest (>= 0), and a tile's
// double sums are never -0 (they start at +0, and x + -x = +0), which stream_tile_to_film
// relies on.
#pragma once
#include <bit>

#include "wave/tile.h"

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
// Weighted: multiply the sample by the pixel filter's weight (lanes.fw).
template <class T, bool Weighted = false>
TUILE_FLATTEN inline void accumulate_lanes(TileBuffers& tb, int i, int lanes, bool aov) {
  T r = load<T>(tb.lanes.Lr + i), g = load<T>(tb.lanes.Lg + i), b = load<T>(tb.lanes.Lb + i);
  // plus what the techniques added to the lanes' shading points: camera_hits compacted
  // them in lane order, so an expand reads them back
  const uint32_t shaded = lane_bits(f_mask_from_i(load_i32<T>(tb.lanes.shade_of + i) >= i32_t<T>(0)));
  // A batch without shading points and without emission (camera rays that all missed):
  // it would add +0 to every sum and leave every maximum, so it is skipped, with the same
  // bits. (Lanes without a shading point have no MIS weight either; tested all the same.)
  if (!shaded && !any((r != T(0.f)) || (g != T(0.f)) || (b != T(0.f))) &&
      !(aov && any((load<T>(tb.lanes.wsum + i) != T(0.f)) || (load<T>(tb.lanes.wcnt + i) != T(0.f)))))
    return;
  if (shaded) {
    const int32_t first = tb.lanes.shade_of[i + std::countr_zero(shaded)];
    r = r + expand_load<T>(tb.radiance.r + first, shaded);
    g = g + expand_load<T>(tb.radiance.g + first, shaded);
    b = b + expand_load<T>(tb.radiance.b + first, shaded);
  }
  if constexpr (Weighted) {
    const T w = load<T>(tb.lanes.fw + i);
    r = r * w;
    g = g * w;
    b = b * w;
  }
  const auto finite = is_finite(r) && is_finite(g) && is_finite(b);
  const auto live = f_mask_from_i(i32_t<T>(i) + lane_iota_i32<T>() < i32_t<T>(lanes));
  tb.stats.rejected_camera += static_cast<uint64_t>(std::popcount(lane_bits(live && !finite)));
  r = sel(finite, r, T(0.f));
  g = sel(finite, g, T(0.f));
  b = sel(finite, b, T(0.f));
  add_sq_f64(tb.sums.r + i, tb.sums.rr + i, r);
  add_sq_f64(tb.sums.g + i, tb.sums.gg + i, g);
  add_sq_f64(tb.sums.b + i, tb.sums.bb + i, b);
  if (aov) {  // no AOV requested: none computed
    add_f64(tb.sums.w + i, load<T>(tb.lanes.wsum + i));
    add_f64(tb.sums.wc + i, load<T>(tb.lanes.wcnt + i));
  }
  const T y = luminance(r, g, b);
  const T m = load<T>(tb.sums.max + i);
  store(tb.sums.max + i, sel(y > m, y, m));
}

// The film's per-pixel sums: RGB interleaved (3 per pixel) for the sums and their squares,
// one per pixel for the weight AOV and the largest sample; width pixels per row.
struct FilmSums {
  double *sum, *sum_sq, *w_sum, *w_cnt;
  float* max_sample;
  size_t width;
};

// Adds the tile's sums of lanes [0, lanes) into their pixels (tb.lanes.pixel).
inline void add_tile_to_film(const TileBuffers& tb, int lanes, const FilmSums& f, bool aov) noexcept {
  for (int i = 0; i < lanes; ++i) {
    const size_t pix = tb.lanes.pixel[i];
    double* sp = f.sum + 3 * pix;
    double* sq = f.sum_sq + 3 * pix;
    sp[0] += tb.sums.r[i];
    sp[1] += tb.sums.g[i];
    sp[2] += tb.sums.b[i];
    sq[0] += tb.sums.rr[i];
    sq[1] += tb.sums.gg[i];
    sq[2] += tb.sums.bb[i];
    if (aov) {
      f.w_sum[pix] += tb.sums.w[i];
      f.w_cnt[pix] += tb.sums.wc[i];
    }
    if (tb.sums.max[i] > f.max_sample[pix]) f.max_sample[pix] = tb.sums.max[i];
  }
}

// Whether stream_tile_to_film can write a tile: AVX-512, a tile 16 pixels wide whose
// lanes are 4x4 blocks, rows of whole cache lines (x0 and the film's width multiples of 16,
// the arrays on 64-byte boundaries).
inline bool can_stream_tile(int x0, int tw, int th, const FilmSums& f) noexcept {
#if defined(__AVX512F__)
  auto lines = [](const void* p) { return (reinterpret_cast<uintptr_t>(p) & 63u) == 0; };
  return packet_width == 16 && tw == 16 && th % 4 == 0 && x0 % 16 == 0 && f.width % 16 == 0 && lines(f.sum) &&
         lines(f.sum_sq) && lines(f.w_sum) && lines(f.w_cnt) && lines(f.max_sample);
#else
  (void)x0, (void)tw, (void)th, (void)f;
  return false;
#endif
}

// The tile's sums written into a film that holds zeros (no samples yet): what adding them
// gives (0 + s = s, as no sum is -0, negative sums of a filter's negative lobes included;
// the largest sample likewise), row by row with streaming stores of whole cache lines, so the film's lines are neither read nor kept in
// the caches. The RGB sums are interleaved by two permutes per output vector.
inline void stream_tile_to_film(const TileBuffers& tb, int x0, int y0, int th, const FilmSums& f, bool aov) noexcept {
#if defined(__AVX512F__)
  const __m512i rg0 = _mm512_setr_epi64(0, 8, 0, 1, 9, 0, 2, 10), b0 = _mm512_setr_epi64(0, 1, 8, 3, 4, 9, 6, 7);
  const __m512i rg1 = _mm512_setr_epi64(0, 3, 11, 0, 4, 12, 0, 5), b1 = _mm512_setr_epi64(10, 1, 2, 11, 4, 5, 12, 7);
  const __m512i rg2 = _mm512_setr_epi64(13, 0, 6, 14, 0, 7, 15, 0), b2 = _mm512_setr_epi64(0, 13, 2, 3, 14, 5, 6, 15);
  for (int r = 0; r < th; ++r) {
    // row r's pixels 4 b .. 4 b + 3 are lanes l0 + 16 b .. + 3 (4x4 blocks of 16 lanes)
    const int l0 = (r / 4) * 64 + (r % 4) * 4;
    const size_t p = static_cast<size_t>(y0 + r) * f.width + static_cast<size_t>(x0);
    auto half = [&](const double* a, int h) {  // pixels 8 h .. 8 h + 7 of the row
      const double* s = a + l0 + 32 * h;
      return _mm512_insertf64x4(_mm512_castpd256_pd512(_mm256_load_pd(s)), _mm256_load_pd(s + 16), 1);
    };
    auto put_rgb = [&](double* dst, const double* ra, const double* ga, const double* ba) {
      for (int h = 0; h < 2; ++h) {
        const __m512d R = half(ra, h), G = half(ga, h), B = half(ba, h);
        double* d = dst + 3 * (p + 8 * static_cast<size_t>(h));
        _mm512_stream_pd(d, _mm512_permutex2var_pd(_mm512_permutex2var_pd(R, rg0, G), b0, B));
        _mm512_stream_pd(d + 8, _mm512_permutex2var_pd(_mm512_permutex2var_pd(R, rg1, G), b1, B));
        _mm512_stream_pd(d + 16, _mm512_permutex2var_pd(_mm512_permutex2var_pd(R, rg2, G), b2, B));
      }
    };
    put_rgb(f.sum, tb.sums.r, tb.sums.g, tb.sums.b);
    put_rgb(f.sum_sq, tb.sums.rr, tb.sums.gg, tb.sums.bb);
    if (aov)
      for (int h = 0; h < 2; ++h) {
        _mm512_stream_pd(f.w_sum + p + 8 * h, half(tb.sums.w, h));
        _mm512_stream_pd(f.w_cnt + p + 8 * h, half(tb.sums.wc, h));
      }
    __m512 m = _mm512_castps128_ps512(_mm_load_ps(tb.sums.max + l0));
    m = _mm512_insertf32x4(m, _mm_load_ps(tb.sums.max + l0 + 16), 1);
    m = _mm512_insertf32x4(m, _mm_load_ps(tb.sums.max + l0 + 32), 2);
    m = _mm512_insertf32x4(m, _mm_load_ps(tb.sums.max + l0 + 48), 3);
    _mm512_stream_ps(f.max_sample + p, m);
  }
  _mm_sfence();  // the streaming stores are weakly ordered: complete them before the tile ends
#else
  (void)tb, (void)x0, (void)y0, (void)th, (void)f, (void)aov;
#endif
}

// Zeroes the tile sums of lanes [0, lanes) padded to a whole packet.
inline void clear_tile_sums(TileBuffers& tb, int lanes) {
  const int padded = packet_padded(lanes);
  for (double* a : {tb.sums.r, tb.sums.g, tb.sums.b, tb.sums.rr, tb.sums.gg, tb.sums.bb, tb.sums.w, tb.sums.wc})
    std::fill_n(a, padded, 0.0);
  std::fill_n(tb.sums.max, padded, 0.f);
}

// One sample of every pixel of the tile. T = float is the scalar reference.
template <class T = vfloat> inline void accumulate_samples(TileBuffers& tb, int lanes, bool aov) {
  const int padded = packet_padded(lanes);
  if (tb.lanes.weighted)
    for (int i = 0; i < padded; i += lane_traits<T>::width) accumulate_lanes<T, true>(tb, i, lanes, aov);
  else
    for (int i = 0; i < padded; i += lane_traits<T>::width) accumulate_lanes<T>(tb, i, lanes, aov);
}

}  // namespace tuile

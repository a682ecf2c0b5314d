// Pixel filters by filter importance sampling (pbrt-v4, section 5.4.3; Ernst et al. 2006,
// "Filter importance sampling"): a camera sample's position in its pixel is drawn with a
// density that follows the filter, and the sample carries the weight f / pdf, so that the
// pixel's plain mean of N weighted samples estimates  ∫ f(p) L(p) dp / ∫ f(p) dp.
//
// sample_filter maps (u0, u1) in [0, 1)^2 to the sample's offset from the pixel's corner
// (the pixel spans [0, 1)^2; its centre is (0.5, 0.5)) and a weight:
//   box       uniform over the square of half-width r (exactly: offset = (0.5 - r) + 2 r u,
//             which for the default r = 0.5 is u itself, today's camera samples bit for bit);
//             weight 1.
//   triangle  the tent (r - |x|)(r - |y|), inverted per axis (pbrt-v4's SampleTent); weight 1.
//   gaussian, mitchell, sinc (Lanczos): separable, f(x, y) = f1(x) f1(y). Each axis is
//             sampled from a piecewise-constant density over [-r, r] whose 128 cells hold
//             probability 1/128 each: cell k is [X_k, X_k+1], X_k the k/128 quantile of |f1|
//             (tabulated once per render, src/render/filter_table.cpp), so the density is the
//             mean of |f1| over the cell over ∫|f1|. Sampling is a table lookup, with no search:
//             k = floor(128 u), x = X_k + (128 u - k) (X_k+1 - X_k), exact in float up to the
//             last product. (pbrt-v4's FilterSampler tabulates |f| at 32 points per unit of
//             radius and searches the CDF; its binary search of gathers cost 20 ns a sample
//             here.) The weight is f1(x) f1(y) / (pdf(x) pdf(y) ∫f1 ∫f1), f1 evaluated
//             exactly at the sample, so that E[weight] = 1 and E[weight g] = ∫ f g / ∫ f with
//             no tabulation bias; a cell's weights stay within max |f1| / mean |f1| over the
//             cell. Mitchell and sinc weights are negative in the negative lobes.
// The weight-1 filters (box, triangle) skip the weight altogether (FilterView::weighted).
// Lane-generic: T = float (the scalar reference) or vfloat, bit-identical.
#pragma once
#include <bit>
#include <cstdint>

#include "lanes/lane_math.h"

namespace tuile {

enum class FilterKind : int32_t { box = 0, triangle = 1, gaussian = 2, mitchell = 3, sinc = 4 };
inline constexpr const char* filter_kind_names[] = {"box", "triangle", "gaussian", "mitchell", "sinc"};

// A filter as a scene file or the command line gives it (pbrt-v4's PixelFilter parameters).
struct FilterParams {
  FilterKind kind = FilterKind::box;
  float xradius = 0.5f, yradius = 0.5f;
  float sigma = 0.5f;            // gaussian
  float b = 1.f / 3.f, c = 1.f / 3.f;  // mitchell
  float tau = 3.f;               // sinc: the number of lobes of the window
  bool operator==(const FilterParams&) const = default;
};

// pbrt-v4's defaults for each filter (filters.cpp, the Create functions).
constexpr FilterParams default_filter(FilterKind k) {
  FilterParams p;
  p.kind = k;
  const float r = k == FilterKind::box ? 0.5f : k == FilterKind::gaussian ? 1.5f : k == FilterKind::sinc ? 4.f : 2.f;
  p.xradius = p.yradius = r;
  return p;
}

// One axis of a tabulated filter: filter_cells cells of equal probability over [-r, r],
// cell k from x0[k] to x0[k] + dx[k]; scale[k] = 1 / (pdf_k ∫f1) with the density
// pdf_k = 1 / (filter_cells dx[k]).
inline constexpr int filter_cells = medium_table_size;  // 128: lookup_medium, not gathers
struct FilterAxis {
  const float* x0 = nullptr;
  const float* dx = nullptr;
  const float* scale = nullptr;
  float r = 0.5f;
  float t_scale = 0.f;     // gaussian: 1 / (2 sigma^2); mitchell: 2 / r; sinc: 1 / tau
  float f_at_r = 0.f;      // gaussian: exp(-r^2 / (2 sigma^2)), subtracted
};

// The filter as generate reads it (CameraView::filter). Default: the box of radius 0.5.
struct FilterView {
  FilterKind kind = FilterKind::box;
  float box_a[2] = {0.f, 0.f}, box_b[2] = {1.f, 1.f};  // box: offset = a + b u per axis
  float coef[7] = {};  // mitchell: (|t| <= 1) c0 t^3 + c1 t^2 + c2, (|t| <= 2) c3 t^3 + c4 t^2 + c5 t + c6
  FilterAxis axis[2];
  // whether samples carry a weight other than 1
  bool weighted() const noexcept { return kind != FilterKind::box && kind != FilterKind::triangle; }
};


// The one-dimensional factor f1 of a separable tabulated filter on axis a, at x (any x;
// 0 outside [-r, r]). Unnormalised (the weight divides by its integral).
template <class T> inline T filter_value_1d(const FilterView& f, const FilterAxis& a, T x) noexcept {
  const T ax = abs(x);
  const auto inside = ax <= T(a.r);
  if (f.kind == FilterKind::gaussian) {
    const T g = lane_math::exp_nonpositive(-(x * x) * T(a.t_scale)) - T(a.f_at_r);
    return sel(inside, max(g, T(0.f)), T(0.f));
  }
  if (f.kind == FilterKind::mitchell) {
    const T t = ax * T(a.t_scale), t2 = t * t, t3 = t2 * t;
    const T near = (T(f.coef[0]) * t3 + T(f.coef[1]) * t2) + T(f.coef[2]);
    const T far = ((T(f.coef[3]) * t3 + T(f.coef[4]) * t2) + T(f.coef[5]) * t) + T(f.coef[6]);
    return sel(t <= T(1.f), near, sel(t <= T(2.f), far, T(0.f)));
  }
  if (f.kind == FilterKind::sinc) {  // sinc(x) sinc(x / tau), sinc(x) = sin(pi x) / (pi x)
    auto sinc = [](T v) {
      T s, c;
      lane_math::sincos_2pi(v * T(0.5f), s, c);  // sin(pi v), reduced exactly in turns
      const auto zero = v == T(0.f);
      return sel(zero, T(1.f), s / sel(zero, T(1.f), T(pi_f) * v));
    };
    return sel(inside, sinc(x) * sinc(x * T(a.t_scale)), T(0.f));
  }
  return sel(inside, T(1.f), T(0.f));  // box (not tabulated in practice)
}

// Samples one tabulated axis: returns x in [-r, r], sets w = f1(x) / (pdf(x) ∫f1).
template <class T> inline T sample_filter_axis(const FilterView& f, const FilterAxis& a, T u, T& w) noexcept {
  const T um = u * T(static_cast<float>(filter_cells));  // exact (a power of two); < 128 as u < 1
  const T kf = floor(um);
  const T t = um - kf;  // exact
  const i32_t<T> k = to_i32(kf);
  const T x = lookup_medium(a.x0, k) + t * lookup_medium(a.dx, k);
  w = filter_value_1d(f, a, x) * lookup_medium(a.scale, k);
  return x;
}

// The sample's offset from its pixel's corner (ox, oy) and its weight (1 for box and
// triangle, where callers skip it).
template <class T> inline void sample_filter(const FilterView& f, T u0, T u1, T& ox, T& oy, T& w) noexcept {
  if (f.kind == FilterKind::box) {
    ox = T(f.box_a[0]) + T(f.box_b[0]) * u0;  // r = 0.5: 0 + 1 u = u exactly
    oy = T(f.box_a[1]) + T(f.box_b[1]) * u1;
    w = T(1.f);
  } else if (f.kind == FilterKind::triangle) {
    auto tent = [](T u, float r) {  // u < 1/2: -r (1 - sqrt(2u)), else r (1 - sqrt(2 - 2u)) (both exact arguments)
      const auto lo = u < T(0.5f);
      const T s = sqrt(sel(lo, T(2.f) * u, T(2.f) - T(2.f) * u));
      const T x = T(r) * (T(1.f) - s);
      return T(0.5f) + sel(lo, -x, x);
    };
    ox = tent(u0, f.axis[0].r);
    oy = tent(u1, f.axis[1].r);
    w = T(1.f);
  } else {
    T wx, wy;
    ox = T(0.5f) + sample_filter_axis(f, f.axis[0], u0, wx);
    oy = T(0.5f) + sample_filter_axis(f, f.axis[1], u1, wy);
    w = wx * wy;
  }
}

// The filter's value at an offset (dx, dy) from the pixel centre (unnormalised; for tests
// and the tables): the separable product, box and triangle included.
inline double filter_value(const FilterView& f, double dx, double dy) {
  auto one = [&](const FilterAxis& a, double x) -> double {
    if (f.kind == FilterKind::box) return std::abs(x) <= a.r ? 1.0 : 0.0;
    if (f.kind == FilterKind::triangle) return std::max(0.0, static_cast<double>(a.r) - std::abs(x));
    return filter_value_1d<float>(f, a, static_cast<float>(x));
  };
  return one(f.axis[0], dx) * one(f.axis[1], dy);
}

}  // namespace tuile

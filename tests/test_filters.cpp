// Pixel filters by filter importance sampling (kernels/sample/filter.h, src/render/filter_table.cpp):
// - the default box maps u to the pixel corner plus u, bit for bit (today's camera samples);
// - the offsets follow the sampling density (chi-square at significance 0.1%, fixed seeds):
//   |f| itself for box and triangle, the tabulated density of equal-probability cells for the
//   tabulated filters (whose weights then make the estimate exact, tested next);
// - the weights average 1, and E[w g(offset)] = ∫ f g / ∫ f for test functions g, within 5
//   standard errors of the sample mean (a false alarm with probability ~6e-7 per check for
//   normal errors; the seeds are fixed, so a pass is a pass for good);
// - every SIMD lane equals the scalar reference bit for bit;
// - the scene file's PixelFilter reaches the render: an image of a step edge (an emitter
//   filling half the view) matches the filter's integral over the edge, per column.
// Each chi-square uses 2e5 samples; the whole file runs in well under a second (Release).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include "render/filter_table.h"
#include "render_util.h"
#include "sample/filter.h"
#include "scene/pbrt.h"
#include "chi2.h"

using tuile::test::Chi2;
using tuile::test::chi2_test;

namespace tuile {
namespace {

struct Rng {
  std::mt19937_64 g;
  explicit Rng(uint64_t seed) : g(seed) {}
  float uf() { return static_cast<float>(g() >> 40) * 0x1p-24f; }  // [0, 1), the samplers' grid
};


// The one-dimensional factor of the filter on axis d (separable filters: f = f1(x) f1(y)).
double f1(const FilterView& v, int d, double x) {
  return d == 0 ? filter_value(v, x, 0) / filter_value(v, 0, 0) : filter_value(v, 0, x) / filter_value(v, 0, 0);
}
// ∫_a^b g(x) f1(x) dx by Simpson's rule with n intervals (n even).
double integrate(const std::function<double(double)>& g, double a, double b, int n = 20000) {
  const double h = (b - a) / n;
  double s = 0;
  for (int k = 0; k <= n; ++k) s += (k == 0 || k == n ? 1 : k % 2 ? 4 : 2) * g(a + h * k);
  return s * h / 3;
}

// The probability the sampler puts in [a, b] on axis d: |f1| normalised for box and
// triangle; the table's piecewise-constant density for the tabulated filters.
double axis_probability(const FilterView& v, int d, double a, double b) {
  const FilterAxis& ax = v.axis[d];
  if (!v.weighted()) {
    const double r = ax.r;
    a = std::max(a, -r), b = std::min(b, r);
    if (b <= a) return 0;
    if (v.kind == FilterKind::box) return (b - a) / (2 * r);
    auto cdf = [&](double x) { return x <= 0 ? 0.5 * (r + x) * (r + x) / (r * r) : 1 - 0.5 * (r - x) * (r - x) / (r * r); };
    return cdf(b) - cdf(a);
  }
  double p = 0;
  for (int k = 0; k < filter_cells; ++k) {
    const double lo = ax.x0[k], hi = lo + ax.dx[k];
    const double o = std::min(b, hi) - std::max(a, lo);
    if (o > 0) p += o / ax.dx[k] / filter_cells;
  }
  return p;
}

struct Case {
  const char* name;
  FilterParams p;
};
std::vector<Case> cases() {
  FilterParams tri_aniso = default_filter(FilterKind::triangle);
  tri_aniso.xradius = 1.f;
  tri_aniso.yradius = 2.5f;
  FilterParams box_wide = default_filter(FilterKind::box);
  box_wide.xradius = 1.5f;
  FilterParams gauss = default_filter(FilterKind::gaussian);
  gauss.sigma = 0.3f;
  gauss.yradius = 1.f;
  FilterParams mitchell_sharp = default_filter(FilterKind::mitchell);
  mitchell_sharp.b = 0.f;
  mitchell_sharp.c = 0.5f;  // Catmull-Rom: deeper negative lobes
  return {{"box", default_filter(FilterKind::box)},
          {"box_wide", box_wide},
          {"triangle", default_filter(FilterKind::triangle)},
          {"triangle_aniso", tri_aniso},
          {"gaussian", default_filter(FilterKind::gaussian)},
          {"gaussian_narrow", gauss},
          {"mitchell", default_filter(FilterKind::mitchell)},
          {"catmull_rom", mitchell_sharp},
          {"sinc", default_filter(FilterKind::sinc)}};
}

TEST(Filters, DefaultBoxIsTheCornerPlusU) {
  std::vector<float> storage;
  const FilterView v = build_filter(FilterParams{}, storage);
  EXPECT_EQ(v.kind, FilterKind::box);
  EXPECT_FALSE(v.weighted());
  const FilterView d;  // CameraView's default (the built-in scenes, tests without a filter)
  Rng rng(1);
  for (int i = 0; i < 100000; ++i) {
    const float u0 = i < 2 ? (i ? 0x1.fffffep-1f : 0.f) : rng.uf(), u1 = rng.uf();
    for (const FilterView* f : {&v, &d}) {
      float ox, oy, w;
      sample_filter(*f, u0, u1, ox, oy, w);
      ASSERT_EQ(std::bit_cast<uint32_t>(ox), std::bit_cast<uint32_t>(u0));
      ASSERT_EQ(std::bit_cast<uint32_t>(oy), std::bit_cast<uint32_t>(u1));
      ASSERT_EQ(w, 1.f);
    }
  }
}

TEST(Filters, OffsetsFollowTheSamplingDensity) {
  for (const Case& c : cases()) {
    std::vector<float> storage;
    const FilterView v = build_filter(c.p, storage);
    constexpr int n = 200000, cells = 20;
    const double rx = c.p.xradius, ry = c.p.yradius;
    std::vector<double> obs(cells * cells, 0.0), expd(cells * cells, 0.0);
    Rng rng(7);
    for (int i = 0; i < n; ++i) {
      float ox, oy, w;
      sample_filter(v, rng.uf(), rng.uf(), ox, oy, w);
      const double x = ox - 0.5, y = oy - 0.5;
      ASSERT_LE(std::abs(x), rx * (1 + 1e-6)) << c.name;
      ASSERT_LE(std::abs(y), ry * (1 + 1e-6)) << c.name;
      const int ix = std::clamp(static_cast<int>((x + rx) / (2 * rx) * cells), 0, cells - 1);
      const int iy = std::clamp(static_cast<int>((y + ry) / (2 * ry) * cells), 0, cells - 1);
      obs[iy * cells + ix] += 1;
    }
    for (int iy = 0; iy < cells; ++iy)
      for (int ix = 0; ix < cells; ++ix) {
        const double px = axis_probability(v, 0, -rx + 2 * rx * ix / cells, -rx + 2 * rx * (ix + 1) / cells);
        const double py = axis_probability(v, 1, -ry + 2 * ry * iy / cells, -ry + 2 * ry * (iy + 1) / cells);
        expd[iy * cells + ix] = n * px * py;
      }
    const Chi2 r = chi2_test(obs, expd);
    EXPECT_GE(r.p, 1e-3) << c.name << ": chi2 " << r.chi2 << " dof " << r.dof;
    EXPECT_GE(r.dof, 100) << c.name;
  }
}

// The tabulated density is close to |f| (it is |f| averaged over cells of probability
// 1/128): the weights' spread stays small where f does not change sign.
TEST(Filters, TabulatedDensityFollowsTheFilter) {
  for (FilterKind k : {FilterKind::gaussian, FilterKind::mitchell}) {
    std::vector<float> storage;
    const FilterView v = build_filter(default_filter(k), storage);
    Rng rng(3);
    double lo = 1e30, hi = -1e30;
    for (int i = 0; i < 100000; ++i) {
      float ox, oy, w;
      sample_filter(v, rng.uf(), 0.5f, ox, oy, w);
      if (std::abs(f1(v, 0, ox - 0.5)) < 0.2 * f1(v, 0, 0)) continue;  // the tails and lobes
      lo = std::min(lo, double(std::abs(w))), hi = std::max(hi, double(std::abs(w)));
    }
    EXPECT_LT(hi / lo, 1.5) << filter_kind_names[static_cast<int>(k)];
  }
}

TEST(Filters, WeightedEstimatesAreTheFilteredIntegrals) {
  for (const Case& c : cases()) {
    std::vector<float> storage;
    const FilterView v = build_filter(c.p, storage);
    const double rx = c.p.xradius, ry = c.p.yradius;
    // separable test functions g(x, y) = gx(x) gy(y); reference ∫ f1 gx / ∫ f1 times the same in y
    struct G {
      std::function<double(double)> gx, gy;
    };
    const std::vector<G> gs = {{[](double) { return 1.0; }, [](double) { return 1.0; }},
                               {[](double x) { return x * x; }, [](double y) { return 1.0 + y; }},
                               {[](double x) { return x > 0.3 ? 1.0 : 0.0; }, [](double y) { return y < 0.2 ? 1.0 : 0.0; }},
                               {[](double x) { return std::cos(2 * x); }, [](double y) { return std::exp(y); }}};
    constexpr int n = 400000;
    std::vector<double> sum(gs.size(), 0.0), sq(gs.size(), 0.0);
    Rng rng(11);
    for (int i = 0; i < n; ++i) {
      float ox, oy, w;
      sample_filter(v, rng.uf(), rng.uf(), ox, oy, w);
      ASSERT_TRUE(std::isfinite(w));
      if (!v.weighted()) {
        ASSERT_EQ(w, 1.f);
      }
      for (size_t j = 0; j < gs.size(); ++j) {
        const double s = w * gs[j].gx(ox - 0.5) * gs[j].gy(oy - 0.5);
        sum[j] += s;
        sq[j] += s * s;
      }
    }
    for (size_t j = 0; j < gs.size(); ++j) {
      auto ratio = [&](int d, double r, const std::function<double(double)>& g) {
        const int kinks = 4000;  // Simpson over pieces, the step of g at 0.3 / 0.2 on a piece boundary
        auto prod = [&](double x) { return f1(v, d, x) * g(x); };
        auto piece = [&](double a, double b) { return b > a ? integrate(prod, a, b, kinks) : 0.0; };
        const double cut = d == 0 ? 0.3 : 0.2;
        const double num = piece(-r, std::clamp(cut, -r, r)) + piece(std::clamp(cut, -r, r), r);
        const double den = integrate([&](double x) { return f1(v, d, x); }, -r, r, kinks);
        return num / den;
      };
      const double ref = ratio(0, rx, gs[j].gx) * ratio(1, ry, gs[j].gy);
      const double mean = sum[j] / n, var = std::max(0.0, sq[j] / n - mean * mean);
      const double se = std::sqrt(var / n);
      if (!v.weighted() && j == 0) {
        EXPECT_EQ(mean, 1.0) << c.name;
      }
      EXPECT_NEAR(mean, ref, 5 * se + 1e-6) << c.name << " g" << j << " se " << se;
    }
  }
}

TEST(Filters, LanesEqualTheScalarReference) {
  for (const Case& c : cases()) {
    std::vector<float> storage;
    const FilterView v = build_filter(c.p, storage);
    Rng rng(5);
    alignas(64) float u0[simd_width], u1[simd_width], ox[simd_width], oy[simd_width], w[simd_width];
    for (int rep = 0; rep < 4000; ++rep) {
      for (int l = 0; l < simd_width; ++l) u0[l] = rng.uf(), u1[l] = rng.uf();
      if (rep == 0) u0[0] = 0.f, u1[0] = 0x1.fffffep-1f, u0[1] = 0.5f, u1[1] = 0.5f;
      vfloat vx, vy, vw;
      sample_filter(v, vfloat::load_aligned(u0), vfloat::load_aligned(u1), vx, vy, vw);
      vx.store_aligned(ox), vy.store_aligned(oy), vw.store_aligned(w);
      for (int l = 0; l < simd_width; ++l) {
        float sx, sy, sw;
        sample_filter(v, u0[l], u1[l], sx, sy, sw);
        ASSERT_EQ(std::bit_cast<uint32_t>(sx), std::bit_cast<uint32_t>(ox[l])) << c.name;
        ASSERT_EQ(std::bit_cast<uint32_t>(sy), std::bit_cast<uint32_t>(oy[l])) << c.name;
        ASSERT_EQ(std::bit_cast<uint32_t>(sw), std::bit_cast<uint32_t>(w[l])) << c.name;
      }
    }
  }
}

// The kernels' one exp (the Gaussian filter, the coated BSDFs' slab): within 1e-6 of libm's
// over its whole domain, 0 below it, and every SIMD lane the scalar's bits.
TEST(LaneMath, ExpNonpositiveMatchesLibm) {
  for (double x = -87; x <= 0; x += 0.0137) {
    const float e = lane_math::exp_nonpositive(static_cast<float>(x));
    const double ref = std::exp(static_cast<double>(static_cast<float>(x)));
    EXPECT_NEAR(e, ref, 1e-6 * ref) << x;
  }
  EXPECT_EQ(lane_math::exp_nonpositive(-87.5f), 0.f);
  EXPECT_EQ(lane_math::exp_nonpositive(0.f), 1.f);
  alignas(64) float xs[simd_width], out[simd_width];
  for (int k = 0; k < 64; ++k) {
    for (int l = 0; l < simd_width; ++l) xs[l] = -0.37f * static_cast<float>(k * simd_width + l) / simd_width;
    lane_math::exp_nonpositive(vfloat::load_aligned(xs)).store_aligned(out);
    for (int l = 0; l < simd_width; ++l)
      ASSERT_EQ(std::bit_cast<uint32_t>(out[l]), std::bit_cast<uint32_t>(lane_math::exp_nonpositive(xs[l]))) << xs[l];
  }
}

TEST(Filters, SceneFileParametersAndErrors) {
  auto load = [](const std::string& text) { return load_pbrt_string(text, "f.pbrt", "/tmp"); };
  Scene s = load("PixelFilter \"mitchell\" \"float xradius\" 1.5 \"float B\" 0 \"float C\" 0.5\nWorldBegin\n");
  EXPECT_EQ(s.file_filter.kind, FilterKind::mitchell);
  EXPECT_EQ(s.file_filter.xradius, 1.5f);
  EXPECT_EQ(s.file_filter.yradius, 2.f);  // pbrt-v4's default
  EXPECT_EQ(s.file_filter.b, 0.f);
  EXPECT_EQ(s.file_filter.c, 0.5f);
  EXPECT_TRUE(s.warnings.empty());
  s = load("PixelFilter \"gaussian\"\nWorldBegin\n");
  EXPECT_EQ(s.file_filter, default_filter(FilterKind::gaussian));
  EXPECT_EQ(s.file_filter.xradius, 1.5f);
  EXPECT_EQ(s.file_filter.sigma, 0.5f);
  s = load("WorldBegin\n");
  EXPECT_EQ(s.file_filter, FilterParams{});
  auto error = [&](const std::string& text) {
    try {
      load(text);
    } catch (const SceneError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error("\nPixelFilter \"gaussian\" \"float sigma\" -1\nWorldBegin\n").find("f.pbrt:2:"), std::string::npos);
  EXPECT_NE(error("PixelFilter \"gaussian\" \"float sigma\" -1\nWorldBegin\n").find("sigma"), std::string::npos);
  EXPECT_NE(error("PixelFilter \"box\" \"float xradius\" 0\nWorldBegin\n").find("f.pbrt:1:"), std::string::npos);
  EXPECT_NE(error("PixelFilter \"lanczos\"\nWorldBegin\n").find("f.pbrt:1:"), std::string::npos);
  RenderOptions o;
  o.filter.yradius = NAN;
  EXPECT_THROW(validate(o), std::invalid_argument);
}

// A step edge: an emitter filling the half x > 0 of the view (raster x > 12 or < 12 by the
// camera's handedness), nothing else. Every sample is L or 0 before its weight, so column c
// is L times the filter's mass beyond the edge: P(c + 0.5 + X > 12) for the filter's offset X.
TEST(Filters, SceneFilterReachesTheRender) {
  auto edge_scene = [](const std::string& filter) {
    return load_pbrt_string("LookAt 0 0 0  0 0 1  0 1 0\nCamera \"perspective\" \"float fov\" 10\n"
                            "Film \"rgb\" \"integer xresolution\" 24 \"integer yresolution\" 4\n" + filter +
                                "\nWorldBegin\nAttributeBegin\nAreaLightSource \"diffuse\" \"rgb L\" [1 1 1] \"bool twosided\" true\n"
                                "Shape \"trianglemesh\" \"point3 P\" [0 -50 5  50 -50 5  50 50 5  0 50 5] "
                                "\"integer indices\" [0 1 2 0 2 3]\nAttributeEnd\n",
                            "edge.pbrt", "/tmp");
  };
  double L = 0;  // the emitter's radiance: every sample of the box's bright columns
  for (const char* filter : {"PixelFilter \"box\"", "PixelFilter \"triangle\"", "PixelFilter \"mitchell\"",
                             "PixelFilter \"gaussian\" \"float sigma\" 0.6"}) {
    Scene s = edge_scene(filter);
    finalize_scene(s);  // the light table (load_pbrt_string leaves it to load_scene)
    RenderOptions o;
    o.filter = s.file_filter;
    o.est.spp = 256;
    o.threads = 1;
    const test::RenderResult res = test::render_scene(s, o);
    std::vector<float> storage;
    const FilterView v = build_filter(o.filter, storage);
    const double r = o.filter.xradius;
    const int W = 24, H = 4;
    const std::vector<float> var = res.film.variance_of_mean();
    auto col = [&](int x, double& se) {
      double m = 0, vs = 0;
      for (int y = 0; y < H; ++y) m += res.mean[3 * (y * W + x)], vs += var[3 * (y * W + x)];
      se = std::sqrt(vs) / H;
      return m / H;
    };
    double se0, se1;
    const double left = col(0, se0), right = col(W - 1, se1);
    ASSERT_TRUE((left == 0) != (right == 0)) << filter << ": " << left << " " << right;
    if (o.filter.kind == FilterKind::box) L = std::max(left, right);  // (weighted filters: L times the mean weight)
    const bool emitter_right = right > 0;
    const double den = integrate([&](double x) { return f1(v, 0, x); }, -r, r);
    for (int x = 0; x < W; ++x) {
      const double d = 12 - (x + 0.5);  // the edge's offset from the pixel centre
      const double dd = std::clamp(emitter_right ? d : -d, -r, r);
      // the mass beyond the edge, on the emitter's side
      const double mass = emitter_right ? integrate([&](double t) { return f1(v, 0, t); }, dd, r) / den
                                        : integrate([&](double t) { return f1(v, 0, -t); }, dd, r) / den;
      double se;
      const double got = col(x, se);
      EXPECT_NEAR(got, L * mass, 5 * se + 2e-3 * L) << filter << " column " << x;
    }
    // the triangle reaches 1.5 pixels past the edge, the box does not
    double se = 0;
    const int past = emitter_right ? 10 : 13;  // centre 1.5 from the edge, on the dark side
    if (o.filter.kind == FilterKind::box) {
      EXPECT_EQ(col(past, se), 0.0);
    }
    if (o.filter.kind == FilterKind::triangle) {
      EXPECT_NEAR(col(past, se), L * 0.5 * 0.25 / 4, 5 * se + 1e-3);
    }
    if (o.filter.kind == FilterKind::mitchell) {
      EXPECT_LT(col(past, se), 0.0);  // the negative lobe
    }
  }
}

}  // namespace
}  // namespace tuile

// Tests for kernels/sampling.h and kernels/polygon_irradiance.h.
// Shape of pbrt-v4's sampling_test and Mitsuba's test_warp: every pdf integrates to one,
// every sampler's histogram matches its pdf integrated over the cells (chi-square at 0.1%),
// solid-angle samplers hit their source uniformly with 1/pdf = the closed-form solid angle,
// and every SIMD lane equals the scalar reference bit for bit.
// GCC 12's AVX-512 intrinsics trip -Wuninitialized on _mm512_undefined_ps (GCC bug 105593,
// fixed in 13); silence it for the intrinsic headers only, before anything includes them.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <immintrin.h>
#pragma GCC diagnostic pop
#endif
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <functional>
#include <limits>
#include <random>
#include <vector>

#include "light/polygon_irradiance.h"
#include "lanes/twin.h"
#include "sample/spherical.h"
#include "chi2.h"

using namespace tuile;
using tuile::test::Chi2;
using tuile::test::chi2_test;

namespace {

constexpr double kPi = 3.14159265358979323846;

// ---- small double geometry for references -------------------------------------------
struct D3 {
  double x = 0, y = 0, z = 0;
};
D3 operator+(D3 a, D3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
D3 operator-(D3 a, D3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
D3 operator*(D3 a, double s) { return {a.x * s, a.y * s, a.z * s}; }
double dot(D3 a, D3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
D3 cross(D3 a, D3 b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
double len(D3 a) { return std::sqrt(dot(a, a)); }
D3 unit(D3 a) { return a * (1.0 / len(a)); }
D3 to_d(const vec3f& v) { return {v.x, v.y, v.z}; }
vec3f to_f(D3 v) { return {float(v.x), float(v.y), float(v.z)}; }

// Solid angle of a triangle seen from o (Van Oosterom & Strackee, double).
double tri_omega(D3 o, D3 p0, D3 p1, D3 p2) {
  const D3 a = p0 - o, b = p1 - o, c = p2 - o;
  const double la = len(a), lb = len(b), lc = len(c);
  const double num = std::fabs(dot(a, cross(p1 - p0, p2 - p0)));
  const double den = la * lb * lc + dot(a, b) * lc + dot(a, c) * lb + dot(b, c) * la;
  return 2.0 * std::atan2(num, den);
}
double para_omega(D3 o, D3 p0, D3 e1, D3 e2) {
  return tri_omega(o, p0, p0 + e1, p0 + e1 + e2) + tri_omega(o, p0, p0 + e1 + e2, p0 + e2);
}
double cone_omega(D3 o, D3 c, double r) {
  const double d2 = dot(c - o, c - o);
  const double s2 = r * r / d2;
  return 2.0 * kPi * s2 / (1.0 + std::sqrt(1.0 - s2));
}

// Ray from o along d against the plane p0 + s e1 + t e2: (s, t) of the hit; false if
// parallel or behind.
bool plane_coords(D3 o, D3 d, D3 p0, D3 e1, D3 e2, double& s, double& t) {
  const D3 n = cross(e1, e2);
  const double dn = dot(d, n);
  if (dn == 0.0) return false;
  const double h = dot(p0 - o, n) / dn;
  if (!(h > 0.0)) return false;
  const D3 v = o + d * h - p0;
  const double d00 = dot(e1, e1), d01 = dot(e1, e2), d11 = dot(e2, e2);
  const double d20 = dot(v, e1), d21 = dot(v, e2);
  const double den = d00 * d11 - d01 * d01;
  s = (d11 * d20 - d01 * d21) / den;
  t = (d00 * d21 - d01 * d20) / den;
  return true;
}
bool hits_triangle(D3 o, D3 d, D3 p0, D3 p1, D3 p2, double tol) {
  double s, t;
  if (!plane_coords(o, d, p0, p1 - p0, p2 - p0, s, t)) return false;
  return s >= -tol && t >= -tol && s + t <= 1.0 + tol;
}
bool hits_parallelogram(D3 o, D3 d, D3 p0, D3 e1, D3 e2, double tol) {
  double s, t;
  if (!plane_coords(o, d, p0, e1, e2, s, t)) return false;
  return s >= -tol && t >= -tol && s <= 1.0 + tol && t <= 1.0 + tol;
}
bool hits_sphere(D3 o, D3 d, D3 c, double r, double tol) {
  const D3 oc = c - o;
  const double along = dot(oc, unit(d));
  if (along <= 0.0) return false;
  const double perp2 = dot(oc, oc) - along * along;
  return perp2 <= r * r * (1.0 + tol) * (1.0 + tol);
}

// ---- random numbers --------------------------------------------------------------------
struct Rng {
  std::mt19937_64 g;
  explicit Rng(uint64_t seed) : g(seed) {}
  float uf() { return float(g() >> 40) * 0x1p-24f; }  // [0, 1)
  double ud() { return double(g() >> 11) * 0x1p-53; }
};

// ---- chi-square ------------------------------------------------------------------------
// (tests/chi2.h: chi2_test)
constexpr double kSignificance = 1e-3;

#define EXPECT_CHI2(res)                                                                            \
  do {                                                                                              \
    const Chi2 r_ = (res);                                                                          \
    EXPECT_GE(r_.p, kSignificance) << "chi2 " << r_.chi2 << " dof " << r_.dof << " p " << r_.p; \
    EXPECT_GE(r_.dof, 10);                                                                          \
  } while (0)

// Histogram of directions over the sphere in cells of (cos theta, phi), each of equal solid
// angle, against the pdf integrated over each cell by a sub-grid midpoint rule: 8 x 8 points,
// refined to 96 x 96 in cells where the pdf varies (edges of a source) and their neighbours.
Chi2 chi2_directions(const std::function<D3(float, float)>& sample, const std::function<double(D3)>& pdf, int n,
                     uint64_t seed, int nz = 32, int nphi = 64) {
  std::vector<double> obs(size_t(nz) * nphi, 0.0), expd(size_t(nz) * nphi, 0.0);
  Rng rng(seed);
  for (int i = 0; i < n; ++i) {
    const D3 d = unit(sample(rng.uf(), rng.uf()));
    const double z = std::clamp(d.z, -1.0, 1.0);
    const double phi = std::atan2(d.y, d.x);
    const int iz = std::clamp(int((z + 1.0) * 0.5 * nz), 0, nz - 1);
    const int ip = std::clamp(int((phi + kPi) / (2 * kPi) * nphi), 0, nphi - 1);
    obs[size_t(iz) * nphi + ip] += 1;
  }
  const double dz = 2.0 / nz, dphi = 2 * kPi / nphi;
  auto cell = [&](int iz, int ip, int sub, double& lo, double& hi) {
    double sum = 0;
    lo = std::numeric_limits<double>::infinity();
    hi = -lo;
    for (int a = 0; a < sub; ++a)
      for (int b = 0; b < sub; ++b) {
        const double z = -1.0 + dz * (iz + (a + 0.5) / sub);
        const double phi = -kPi + dphi * (ip + (b + 0.5) / sub);
        const double r = std::sqrt(std::max(0.0, 1 - z * z));
        const double v = pdf({r * std::cos(phi), r * std::sin(phi), z});
        sum += v;
        lo = std::min(lo, v);
        hi = std::max(hi, v);
      }
    return n * sum * dz * dphi / (sub * sub);
  };
  std::vector<char> refine(size_t(nz) * nphi, 0);
  for (int iz = 0; iz < nz; ++iz)
    for (int ip = 0; ip < nphi; ++ip) {
      double lo, hi;
      expd[size_t(iz) * nphi + ip] = cell(iz, ip, 8, lo, hi);
      if (hi > lo)
        for (int a = -1; a <= 1; ++a)
          for (int b = -1; b <= 1; ++b)
            if (iz + a >= 0 && iz + a < nz) refine[size_t(iz + a) * nphi + size_t((ip + b + nphi) % nphi)] = 1;
    }
  for (int iz = 0; iz < nz; ++iz)
    for (int ip = 0; ip < nphi; ++ip)
      if (refine[size_t(iz) * nphi + ip]) {
        double lo, hi;
        expd[size_t(iz) * nphi + ip] = cell(iz, ip, 96, lo, hi);
      }
  return chi2_test(obs, expd);
}

// Integral of a direction pdf over the sphere (midpoint rule in (cos theta, phi)).
double integrate_sphere(const std::function<double(D3)>& pdf, int nz = 600, int nphi = 1200) {
  double sum = 0;
  for (int iz = 0; iz < nz; ++iz) {
    const double z = -1.0 + 2.0 * (iz + 0.5) / nz;
    const double r = std::sqrt(1 - z * z);
    for (int ip = 0; ip < nphi; ++ip) {
      const double phi = 2 * kPi * (ip + 0.5) / nphi;
      sum += pdf({r * std::cos(phi), r * std::sin(phi), z});
    }
  }
  return sum * (2.0 / nz) * (2 * kPi / nphi);
}

// ---- test geometry -----------------------------------------------------------------------
// A parallelogram (or rectangle if skew == 0) of size s x 0.7 s centred at distance dist
// along a fixed oblique direction from the origin, tilted with respect to the view.
struct Para {
  D3 p0, e1, e2;
};
// The default direction is near the equator of the (cos theta, phi) histograms, away from
// their poles where the cells are thin wedges.
Para make_para(double s, double dist, double skew = 0.0, D3 dir = {0.8, -0.5, 0.15}) {
  const D3 c = unit(dir) * dist;
  const D3 n = unit(unit(dir) * -1.0 + D3{0.2, -0.1, 0.25});  // facing roughly back to the origin, tilted
  const D3 u = unit(cross(n, D3{0.3, 1.0, 0.1}));
  const D3 v = cross(n, u);
  Para p;
  p.e1 = u * s;
  p.e2 = (v + u * skew) * (0.7 * s);
  p.p0 = c - p.e1 * 0.5 - p.e2 * 0.5;
  return p;
}
struct Tri {
  D3 a, b, c;
};
Tri make_tri(double s, double dist, D3 dir = {0.8, -0.5, 0.15}) {
  const Para p = make_para(s, dist, 0.35, dir);
  return {p.p0, p.p0 + p.e1, p.p0 + p.e1 * 0.2 + p.e2};
}
// Round the geometry to float and back, so double references see the float inputs.
Para rounded(Para p) { return {to_d(to_f(p.p0)), to_d(to_f(p.e1)), to_d(to_f(p.e2))}; }
Tri rounded(Tri t) { return {to_d(to_f(t.a)), to_d(to_f(t.b)), to_d(to_f(t.c))}; }

const D3 kOrigin{0, 0, 0};

}  // namespace

// =========================================================================================
// Elementary functions
TEST(LaneMath, AgainstLibm) {
  double max_sc = 0, max_at = 0, max_as = 0;
  for (int i = -20000; i <= 20000; ++i) {
    const float x = float(i) * 3e-4f;  // [-6, 6]
    float s, c;
    lane_math::sincos(x, s, c);
    max_sc = std::max({max_sc, std::fabs(s - std::sin(double(x))), std::fabs(c - std::cos(double(x)))});
    float s2, c2;
    lane_math::sincos_2pi(x, s2, c2);
    max_sc = std::max({max_sc, std::fabs(s2 - std::sin(2 * kPi * x)), std::fabs(c2 - std::cos(2 * kPi * x))});
    const float y = float(i % 173) * 0.05f - 4.f;
    const double at = std::atan2(double(y), double(x));
    max_at = std::max(max_at, std::fabs(lane_math::atan2(y, x) - at) / std::max(std::fabs(at), 1e-30));
    const float t = float(i) / 20000.f;
    const double as = std::asin(double(t));
    if (t != 0) max_as = std::max(max_as, std::fabs(lane_math::asin(t) - as) / std::fabs(as));
  }
  EXPECT_LT(max_sc, 4e-7);  // absolute, about 3 ulps of 1
  EXPECT_LT(max_at, 5e-7);  // relative, about 4 ulps
  EXPECT_LT(max_as, 5e-7);
  // tiny arguments keep their relative precision
  EXPECT_NEAR(lane_math::atan2(1e-30f, 1.f), 1e-30f, 1e-37f);
  EXPECT_NEAR(lane_math::asin(1e-20f), 1e-20f, 1e-27f);
  EXPECT_EQ(lane_math::atan2(0.f, 0.f), 0.f);
}

// =========================================================================================
// 1. Cosine hemisphere
TEST(CosineHemisphere, PdfIntegratesToOne) {
  const double I = integrate_sphere([](D3 d) { return double(pdf_cosine_hemisphere(float(d.z))); });
  EXPECT_NEAR(I, 1.0, 1e-4);
}

TEST(CosineHemisphere, ChiSquare) {
  auto sample = [](float u1, float u2) { return to_d(sample_cosine_hemisphere(u1, u2)); };
  auto pdf = [](D3 d) { return std::max(d.z, 0.0) / kPi; };
  EXPECT_CHI2(chi2_directions(sample, pdf, 1000000, 1));
}

TEST(CosineHemisphere, UnitAndUpper) {
  Rng rng(2);
  for (int i = 0; i < 100000; ++i) {
    const vec3f d = sample_cosine_hemisphere(rng.uf(), rng.uf());
    ASSERT_NEAR(length(d), 1.f, 3e-7f);
    ASSERT_GE(d.z, 0.f);
  }
  for (float u1 : {0.f, 0.5f, 0x1.fffffep-1f})
    for (float u2 : {0.f, 0.5f, 0x1.fffffep-1f}) {
      const vec3f d = sample_cosine_hemisphere(u1, u2);
      EXPECT_TRUE(std::isfinite(d.x) && std::isfinite(d.y) && std::isfinite(d.z));
    }
  EXPECT_EQ(pdf_cosine_hemisphere(-0.5f), 0.f);
}

// =========================================================================================
// 2. Triangle by area
TEST(TriangleArea, ChiSquareOnSubTriangles) {
  // n^2 congruent sub-triangles of the unit triangle, each of equal area.
  const int n = 16, N = 1000000;
  std::vector<double> obs(size_t(n) * n, 0.0), expd(size_t(n) * n, double(N) / (n * n));
  Rng rng(3);
  for (int i = 0; i < N; ++i) {
    float b1, b2;
    sample_triangle_area(rng.uf(), rng.uf(), b1, b2);
    ASSERT_GE(b1, 0.f);
    ASSERT_GE(b2, 0.f);
    ASSERT_LE(b1 + b2, 1.f);
    const double s = b1 * n, t = b2 * n;
    const int i1 = std::min(int(s), n - 1), i2 = std::min(int(t), n - 1 - i1);
    const bool upper = (s - i1) + (t - i2) > 1.0;
    // cells in row i1: 2 (n - i1) - 1 triangles; index them densely
    int base = 0;
    for (int r = 0; r < i1; ++r) base += 2 * (n - r) - 1;
    obs[size_t(base + 2 * i2 + (upper ? 1 : 0))] += 1;
  }
  EXPECT_CHI2(chi2_test(obs, expd));
  EXPECT_FLOAT_EQ(pdf_triangle_area(vec3f(2, 0, 0), vec3f(0, 3, 0)), 1.f / 3.f);
}

// =========================================================================================
// 3. Spherical triangles
//
// Error analysis of the float solid angles against the double references, in roundings of
// u = 2^-24 relative. No bound below depends on which bits a processor's reciprocal
// estimates return: an estimate enters only through rcp_nr / rsqrt_nr, within 3 ulps of the
// exact value for any |e| <= 2^-13 (kernels/simd.h), and these checks also run with the
// estimates perturbed by +-2^-14 and with exact IEEE division (tuile_precision_tests_*).
// - Triangle (Van Oosterom & Strackee, tan(Omega/2) = |det| / (1 + a.b + a.c + b.c), det =
//   a . (eb / lb x ec / lc) from the edges eb, ec): the edges are exact for small triangles
//   (Sterbenz) or one rounding; 1 / lb and 1 / lc two roundings each after the length's
//   four; the cross product two per component (relative to |cross|, for triangles that are
//   not slivers); the dot product with the unit a three, plus a's own five, amplified by
//   1 / cos of the angle between a and the normal (under 2 for the triangles here); the
//   denominator (about 4, all terms positive) six; the one-division atan2 about four ulps
//   (tested above). About 20 u in all, 1.2e-6, whatever the size: tolerance 2e-6.
// - Parallelogram with skewed edges: the sum of two such triangles (both positive): 2e-6.
// - Sphere cone: 2 pi sin^2 / (1 + cos) with sin^2 = r^2 / |d|^2: about eight roundings and
//   a square root whose error is halved: tolerance 2e-6 (1e-6 where the radius is exact).
// - Rectangle (Urena): S = a01 + a23, two atan2 of O(1) arguments whose absolute error is a
//   few u times the angles themselves; where both angles have one sign (the source straight
//   ahead) that is relative to S, but where the rectangle is off to one side the two nearly
//   cancel and the absolute error, about 1e-9 sr for the sources at distance 1 here, becomes
//   a relative 1e-5 at min_sa_sample_omega. Below it the renderer samples such sources by
//   area (the pdf then needs no Omega), and the tests only ask for a finite Omega >= 0.
TEST(SphericalTriangle, SolidAngleMatchesClosedForm) {
  // octant: pi/2 exactly
  EXPECT_NEAR(spherical_triangle_solid_angle(vec3f(0, 0, 0), vec3f(1, 0, 0), vec3f(0, 1, 0), vec3f(0, 0, 1)),
              float(kPi / 2), 2e-7);
  for (double s : {1e-4, 1e-3, 1e-2, 0.1, 1.0, 10.0})
    for (double dist : {0.5, 3.0, 1e3}) {
      const Tri t = rounded(make_tri(s, dist));
      const double ref = tri_omega(kOrigin, t.a, t.b, t.c);
      const float om = spherical_triangle_solid_angle(vec3f(0, 0, 0), to_f(t.a), to_f(t.b), to_f(t.c));
      EXPECT_NEAR(om / ref, 1.0, 2e-6) << "size " << s << " dist " << dist << " omega " << ref;  // analysis above
    }
}

TEST(SphericalTriangle, PdfIntegratesAndChiSquare) {
  const Tri t = rounded(make_tri(1.2, 1.5));
  const vec3f x(0, 0, 0), a = to_f(t.a), b = to_f(t.b), c = to_f(t.c);
  const double omega = tri_omega(kOrigin, t.a, t.b, t.c);
  const float pdf = pdf_spherical_triangle_sa(x, a, b, c);
  auto pdf_dir = [&](D3 d) { return hits_triangle(kOrigin, d, t.a, t.b, t.c, 0.0) ? double(pdf) : 0.0; };
  EXPECT_NEAR(integrate_sphere(pdf_dir), 1.0, 2e-3) << "omega " << omega;
  EXPECT_NEAR(1.0 / pdf, omega, 1e-6 * omega);
  auto sample = [&](float u1, float u2) {
    vec3f d;
    float p;
    EXPECT_TRUE(sample_spherical_triangle(x, a, b, c, u1, u2, d, p));
    return to_d(d);
  };
  auto pdf_ref = [&](D3 d) { return hits_triangle(kOrigin, d, t.a, t.b, t.c, 0.0) ? 1.0 / omega : 0.0; };
  EXPECT_CHI2(chi2_directions(sample, pdf_ref, 400000, 4));
}

// Uniform density over the source: cells are n^2 sub-triangles of the source, expected
// counts proportional to their exact (double) solid angles. Every direction must hit.
static Chi2 triangle_uniformity(const Tri& t, int N, uint64_t seed, double hit_tol, int n = 12) {
  const vec3f x(0, 0, 0), fa = to_f(t.a), fb = to_f(t.b), fc = to_f(t.c);
  const D3 e1 = t.b - t.a, e2 = t.c - t.a;
  std::vector<double> obs(size_t(n) * n, 0.0), expd(size_t(n) * n, 0.0);
  const double omega = tri_omega(kOrigin, t.a, t.b, t.c);
  int k = 0;
  for (int i1 = 0; i1 < n; ++i1)
    for (int i2 = 0; i2 < n - i1; ++i2) {
      const D3 q = t.a + e1 * (double(i1) / n) + e2 * (double(i2) / n);
      const D3 f1 = e1 * (1.0 / n), f2 = e2 * (1.0 / n);
      expd[size_t(k++)] = N * tri_omega(kOrigin, q, q + f1, q + f2) / omega;
      if (i2 < n - i1 - 1) expd[size_t(k++)] = N * tri_omega(kOrigin, q + f1, q + f1 + f2, q + f2) / omega;
    }
  Rng rng(seed);
  float pdf_fn = pdf_spherical_triangle_sa(x, fa, fb, fc);
  for (int i = 0; i < N; ++i) {
    vec3f d;
    float pdf;
    const bool ok = sample_spherical_triangle(x, fa, fb, fc, rng.uf(), rng.uf(), d, pdf);
    EXPECT_TRUE(ok);
    EXPECT_EQ(pdf, pdf_fn);
    double s, tt;
    const bool hit = plane_coords(kOrigin, to_d(d), t.a, e1, e2, s, tt) && s >= -hit_tol && tt >= -hit_tol &&
                     s + tt <= 1 + hit_tol;
    EXPECT_TRUE(hit) << "s " << s << " t " << tt;
    if (!hit) return Chi2{};
    s = std::clamp(s, 0.0, 1.0) * n;
    tt = std::clamp(tt, 0.0, 1.0) * n;
    const int i1 = std::min(int(s), n - 1), i2 = std::max(0, std::min(int(tt), n - 1 - i1));
    const bool upper = (s - i1) + (tt - i2) > 1.0 && i2 < n - i1 - 1;
    int base = 0;
    for (int r = 0; r < i1; ++r) base += 2 * (n - r) - 1;
    obs[size_t(base + 2 * i2 + (upper ? 1 : 0))] += 1;
  }
  return chi2_test(obs, expd);
}

TEST(SphericalTriangle, UniformOverSourceAndHits) {
  EXPECT_CHI2(triangle_uniformity(rounded(make_tri(1.0, 1.2)), 400000, 5, 1e-5));       // ~0.25 sr
  EXPECT_CHI2(triangle_uniformity(rounded(make_tri(0.02, 1.0)), 400000, 6, 1e-4));      // ~1.5e-4 sr
  EXPECT_CHI2(triangle_uniformity(rounded(make_tri(20.0, 0.9)), 400000, 7, 1e-5));      // large
  // x close to the plane of a large triangle: near the hemisphere.
  Tri big{{-50, -50, 0.05}, {100, -50, 0.05}, {-50, 100, 0.05}};
  big = rounded(big);
  const float om = spherical_triangle_solid_angle(vec3f(0, 0, 0), to_f(big.a), to_f(big.b), to_f(big.c));
  EXPECT_GT(om, 6.0f);
  EXPECT_CHI2(triangle_uniformity(big, 400000, 8, 1e-5));
}

TEST(SphericalTriangle, OrientationAndVertexOrderInvariant) {
  const Tri t = rounded(make_tri(0.8, 1.1));
  const vec3f x(0, 0, 0), a = to_f(t.a), b = to_f(t.b), c = to_f(t.c);
  const float o1 = spherical_triangle_solid_angle(x, a, b, c);
  EXPECT_FLOAT_EQ(o1, spherical_triangle_solid_angle(x, a, c, b));
  EXPECT_FLOAT_EQ(o1, spherical_triangle_solid_angle(x, b, c, a));
  // End points of the map: u1 = 1, u2 = 1 lands on C, u2 = 0 on B.
  vec3f d;
  float p;
  sample_spherical_triangle(x, a, b, c, 1.f, 1.f, d, p);
  EXPECT_NEAR(dot(d, normalize(c)), 1.f, 1e-6f);
  sample_spherical_triangle(x, a, b, c, 0.3f, 0.f, d, p);
  EXPECT_NEAR(dot(d, normalize(b)), 1.f, 1e-6f);
  sample_spherical_triangle(x, a, b, c, 0.f, 1.f, d, p);
  EXPECT_NEAR(dot(d, normalize(a)), 1.f, 1e-6f);
}

// =========================================================================================
// 4. Spherical rectangles and parallelograms
TEST(SphericalRectangle, SolidAngleMatchesClosedForm) {
  for (double s : {1e-2, 0.1, 1.0, 10.0})
    for (double dist : {0.5, 3.0}) {
      const Para p = rounded(make_para(s, dist));
      const double ref = para_omega(kOrigin, p.p0, p.e1, p.e2);
      const float om = spherical_rectangle_solid_angle(vec3f(0, 0, 0), to_f(p.p0), to_f(p.e1), to_f(p.e2));
      // Urena's S cancels for small rectangles off to one side (section 3's analysis):
      // accurate to 1e-5 above min_sa_sample_omega, to 1e-3 below (sampled by area there).
      EXPECT_NEAR(om / ref, 1.0, ref >= min_sa_sample_omega ? 1e-5 : 1e-3)
          << "size " << s << " dist " << dist << " omega " << ref;
      EXPECT_EQ(om, parallelogram_solid_angle(vec3f(0, 0, 0), to_f(p.p0), to_f(p.e1), to_f(p.e2)));
    }
}

// Uniform density over the source in a (s, t) grid of the parallelogram, expected counts from
// the exact solid angle of each cell; every direction must hit.
template <class Sampler>
static Chi2 para_uniformity(const Para& p, Sampler sampler, int N, uint64_t seed, double hit_tol, int n = 20) {
  const vec3f x(0, 0, 0);
  std::vector<double> obs(size_t(n) * n, 0.0), expd(size_t(n) * n, 0.0);
  const double omega = para_omega(kOrigin, p.p0, p.e1, p.e2);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      expd[size_t(i) * n + j] =
          N * para_omega(kOrigin, p.p0 + p.e1 * (double(i) / n) + p.e2 * (double(j) / n), p.e1 * (1.0 / n),
                         p.e2 * (1.0 / n)) /
          omega;
  Rng rng(seed);
  const float pdf_fn = pdf_parallelogram_sa(x, to_f(p.p0), to_f(p.e1), to_f(p.e2));
  for (int k = 0; k < N; ++k) {
    vec3f d;
    float pdf;
    const bool ok = sampler(x, to_f(p.p0), to_f(p.e1), to_f(p.e2), rng.uf(), rng.uf(), d, pdf);
    EXPECT_TRUE(ok);
    EXPECT_EQ(pdf, pdf_fn);
    double s, t;
    const bool hit = plane_coords(kOrigin, to_d(d), p.p0, p.e1, p.e2, s, t) && s >= -hit_tol && t >= -hit_tol &&
                     s <= 1 + hit_tol && t <= 1 + hit_tol;
    EXPECT_TRUE(hit) << "s " << s << " t " << t;
    if (!hit) return Chi2{};
    const int i = std::clamp(int(s * n), 0, n - 1), j = std::clamp(int(t * n), 0, n - 1);
    obs[size_t(i) * n + j] += 1;
  }
  return chi2_test(obs, expd);
}

static bool rect_sampler(const vec3f& x, const vec3f& p0, const vec3f& e1, const vec3f& e2, float u1, float u2,
                         vec3f& d, float& pdf) {
  return sample_spherical_rectangle(x, p0, e1, e2, u1, u2, d, pdf);
}
static bool para_sampler(const vec3f& x, const vec3f& p0, const vec3f& e1, const vec3f& e2, float u1, float u2,
                         vec3f& d, float& pdf) {
  return sample_parallelogram_sa(x, p0, e1, e2, u1, u2, d, pdf);
}

TEST(SphericalRectangle, UniformOverSourceAndHits) {
  EXPECT_TRUE(parallelogram_is_rectangle(to_f(make_para(1, 1).e1), to_f(make_para(1, 1).e2)));
  EXPECT_CHI2(para_uniformity(rounded(make_para(1.0, 1.2)), rect_sampler, 400000, 9, 1e-5));
  EXPECT_CHI2(para_uniformity(rounded(make_para(0.015, 1.0)), rect_sampler, 400000, 10, 1e-4));  // ~1.5e-4 sr
  EXPECT_CHI2(para_uniformity(rounded(make_para(30.0, 0.5)), rect_sampler, 400000, 11, 1e-5));   // ~5.5 sr
}

TEST(SphericalRectangle, PdfIntegratesAndChiSquare) {
  const Para p = rounded(make_para(1.0, 1.3));
  const vec3f x(0, 0, 0);
  const double omega = para_omega(kOrigin, p.p0, p.e1, p.e2);
  const float pdf = pdf_parallelogram_sa(x, to_f(p.p0), to_f(p.e1), to_f(p.e2));
  auto pdf_dir = [&](D3 d) { return hits_parallelogram(kOrigin, d, p.p0, p.e1, p.e2, 0.0) ? double(pdf) : 0.0; };
  EXPECT_NEAR(integrate_sphere(pdf_dir), 1.0, 2e-3);
  auto sample = [&](float u1, float u2) {
    vec3f d;
    float pp;
    EXPECT_TRUE(sample_parallelogram_sa(x, to_f(p.p0), to_f(p.e1), to_f(p.e2), u1, u2, d, pp));
    return to_d(d);
  };
  auto pdf_ref = [&](D3 d) { return hits_parallelogram(kOrigin, d, p.p0, p.e1, p.e2, 0.0) ? 1.0 / omega : 0.0; };
  EXPECT_CHI2(chi2_directions(sample, pdf_ref, 400000, 12));
}

TEST(SphericalParallelogram, UniformOverSourceAndHits) {
  const Para p = rounded(make_para(1.0, 1.2, 0.6));
  EXPECT_FALSE(parallelogram_is_rectangle(to_f(p.e1), to_f(p.e2)));
  const double ref = para_omega(kOrigin, p.p0, p.e1, p.e2);
  EXPECT_NEAR(parallelogram_solid_angle(vec3f(0, 0, 0), to_f(p.p0), to_f(p.e1), to_f(p.e2)) / ref, 1.0, 2e-6);
  EXPECT_CHI2(para_uniformity(p, para_sampler, 400000, 13, 1e-5));
  EXPECT_CHI2(para_uniformity(rounded(make_para(0.015, 1.0, 0.6)), para_sampler, 400000, 14, 1e-4));
  // and the pdf integrates to one over the sphere
  const float pdf = pdf_parallelogram_sa(vec3f(0, 0, 0), to_f(p.p0), to_f(p.e1), to_f(p.e2));
  EXPECT_NEAR(integrate_sphere([&](D3 d) {
                return hits_parallelogram(kOrigin, d, p.p0, p.e1, p.e2, 0.0) ? double(pdf) : 0.0;
              }),
              1.0, 2e-3);
}

// =========================================================================================
// 5. Spheres
TEST(SphereCone, SolidAngleChiSquareAndHits) {
  const D3 c{1.5, -0.3, 0.4};  // near the histogram's equator
  const double r = 0.6;
  const vec3f x(0, 0, 0), fc = to_f(c);
  const double omega = cone_omega(kOrigin, c, r);
  EXPECT_NEAR(sphere_cone_solid_angle(x, fc, float(r)) / omega, 1.0, 1e-6);
  const float pdf = pdf_sphere_cone(x, fc, float(r));
  EXPECT_NEAR(integrate_sphere([&](D3 d) { return hits_sphere(kOrigin, d, c, r, 0.0) ? double(pdf) : 0.0; }), 1.0,
              2e-3);
  Rng rng(15);
  for (int i = 0; i < 200000; ++i) {
    vec3f d;
    float p;
    ASSERT_TRUE(sample_sphere_cone(x, fc, float(r), rng.uf(), rng.uf(), d, p));
    ASSERT_EQ(p, pdf);
    ASSERT_TRUE(hits_sphere(kOrigin, to_d(d), c, r, 1e-6));
  }
  auto sample = [&](float u1, float u2) {
    vec3f d;
    float p;
    sample_sphere_cone(x, fc, float(r), u1, u2, d, p);
    return to_d(d);
  };
  auto pdf_ref = [&](D3 d) { return hits_sphere(kOrigin, d, c, r, 0.0) ? 1.0 / omega : 0.0; };
  EXPECT_CHI2(chi2_directions(sample, pdf_ref, 400000, 16));
}

TEST(SphereCone, UniformInConeSmallAndInside) {
  // (1 - cos theta, phi) cells around the axis: equal solid angles. A small far sphere.
  const D3 c{1e3, 2e3, -3e3};
  const double r = 1.0;
  const D3 w = unit(c);
  D3 t = unit(cross(w, D3{0, 0, 1})), b = cross(w, t);
  const double omc_max = cone_omega(kOrigin, c, r) / (2 * kPi);
  const int n1 = 16, n2 = 32, N = 400000;
  std::vector<double> obs(size_t(n1) * n2, 0.0), expd(size_t(n1) * n2, double(N) / (n1 * n2));
  Rng rng(17);
  for (int i = 0; i < N; ++i) {
    vec3f d;
    float p;
    ASSERT_TRUE(sample_sphere_cone(vec3f(0, 0, 0), to_f(c), float(r), rng.uf(), rng.uf(), d, p));
    const D3 dd = unit(to_d(d));
    const double z = dot(dd, w);
    const double omc = dot(dd - w, dd - w) * 0.5;  // 1 - cos theta, stable
    (void)z;
    const double phi = std::atan2(dot(dd, b), dot(dd, t));
    const int i1 = std::clamp(int(omc / omc_max * n1), 0, n1 - 1);
    const int i2 = std::clamp(int((phi + kPi) / (2 * kPi) * n2), 0, n2 - 1);
    obs[size_t(i1) * n2 + i2] += 1;
    ASSERT_TRUE(hits_sphere(kOrigin, dd, c, r, 1e-3));
  }
  EXPECT_CHI2(chi2_test(obs, expd));
  // inside: invalid, finite, pdf 0
  vec3f d;
  float p;
  EXPECT_FALSE(sample_sphere_cone(vec3f(0, 0, 0), vec3f(0.1f, 0, 0), 1.f, 0.3f, 0.6f, d, p));
  EXPECT_EQ(p, 0.f);
  EXPECT_TRUE(std::isfinite(d.x) && std::isfinite(d.y) && std::isfinite(d.z));
  EXPECT_EQ(pdf_sphere_cone(vec3f(0, 0, 0), vec3f(0.1f, 0, 0), 1.f), 0.f);
}

TEST(SphereArea, ChiSquareAndOnSurface) {
  const vec3f c(1, 2, 3);
  const float r = 2.f;
  EXPECT_FLOAT_EQ(pdf_sphere_area(r), float(1.0 / (4 * kPi * 4)));
  auto sample = [&](float u1, float u2) {
    const vec3f p = sample_sphere_area(c, r, u1, u2);
    return (to_d(p) - to_d(c)) * (1.0 / r);
  };
  Rng rng(18);
  for (int i = 0; i < 100000; ++i) {
    const vec3f p = sample_sphere_area(c, r, rng.uf(), rng.uf());
    ASSERT_NEAR(len(to_d(p) - to_d(c)), r, 2e-6);
  }
  EXPECT_CHI2(chi2_directions(sample, [](D3) { return 1.0 / (4 * kPi); }, 1000000, 19));
}

// =========================================================================================
// 6. Extremes and the fallback rule
TEST(FallbackRule, ExactThresholds) {
  EXPECT_TRUE(solid_angle_sampling_safe(min_sa_sample_omega));
  EXPECT_FALSE(solid_angle_sampling_safe(std::nextafter(min_sa_sample_omega, 0.f)));
  EXPECT_TRUE(solid_angle_sampling_safe(max_sa_sample_omega));
  EXPECT_FALSE(solid_angle_sampling_safe(std::nextafter(max_sa_sample_omega, 10.f)));
  EXPECT_FALSE(solid_angle_sampling_safe(0.f));
  alignas(64) float v[simd_width];
  for (int i = 0; i < simd_width; ++i)
    v[i] = (i % 4 == 0)   ? min_sa_sample_omega
           : (i % 4 == 1) ? std::nextafter(min_sa_sample_omega, 0.f)
           : (i % 4 == 2) ? max_sa_sample_omega
                          : std::nextafter(max_sa_sample_omega, 10.f);
  const vmask m = solid_angle_sampling_safe(vfloat::load_aligned(v));
  alignas(64) float mf[simd_width];
  sel(m, vfloat(1.f), vfloat(0.f)).store_aligned(mf);
  for (int i = 0; i < simd_width; ++i) EXPECT_EQ(mf[i] != 0.f, solid_angle_sampling_safe(v[i])) << i;
}

TEST(Extremes, TinyAndHemisphericalSourcesStayFinite) {
  const vec3f x(0, 0, 0);
  // ~1e-10 sr: triangle, rectangle, parallelogram, sphere.
  const Tri t = rounded(make_tri(1.4e-5, 1.0));
  const Para pr = rounded(make_para(1.2e-5, 1.0));
  const Para pp = rounded(make_para(1.2e-5, 1.0, 0.5));
  const vec3f sc(3, -2, 4);
  const float srad = float(std::sqrt(1e-10 / kPi) * 5.385);
  const float om_t = spherical_triangle_solid_angle(x, to_f(t.a), to_f(t.b), to_f(t.c));
  const float om_r = parallelogram_solid_angle(x, to_f(pr.p0), to_f(pr.e1), to_f(pr.e2));
  const float om_p = parallelogram_solid_angle(x, to_f(pp.p0), to_f(pp.e1), to_f(pp.e2));
  const float om_s = sphere_cone_solid_angle(x, sc, srad);
  // Urena's rectangle loses its solid angle to cancellation here (it may report 0: invalid);
  // the triangle-based and cone solid angles stay accurate.
  // Its absolute error stays below ~1e-6 sr (a few ulps of the O(1) angles it sums).
  EXPECT_TRUE(std::isfinite(om_r) && om_r >= 0.f && om_r < 1e-6f);
  for (float om : {om_t, om_r, om_p, om_s}) EXPECT_FALSE(solid_angle_sampling_safe(om));  // sampled by area
  for (float om : {om_t, om_p, om_s}) EXPECT_LT(om, 3e-10f);
  for (float om : {om_t, om_p, om_s}) EXPECT_GT(om, 3e-11f);
  // references on the float vertices the kernels see (p0 + e1 etc. rounded to float)
  const vec3f q0 = to_f(pp.p0), q1 = q0 + to_f(pp.e1), q2 = q1 + to_f(pp.e2), q3 = q0 + to_f(pp.e2);
  const double ref_p = tri_omega(kOrigin, to_d(q0), to_d(q1), to_d(q2)) + tri_omega(kOrigin, to_d(q0), to_d(q2), to_d(q3));
  // Van Oosterom & Strackee's relative error does not grow as the source shrinks (section
  // 3's analysis): the same 2e-6 as for sources of 1 sr.
  EXPECT_NEAR(om_t / tri_omega(kOrigin, t.a, t.b, t.c), 1.0, 2e-6);
  EXPECT_NEAR(om_p / ref_p, 1.0, 2e-6);
  EXPECT_NEAR(om_s / cone_omega(kOrigin, to_d(sc), srad), 1.0, 2e-6);
  Rng rng(20);
  for (int i = 0; i < 20000; ++i) {
    const float u1 = rng.uf(), u2 = rng.uf();
    vec3f d;
    float p;
    // Still usable: finite, valid, and on the source up to float direction precision
    // (6e-8 rad against a source 1e-5 rad across).
    ASSERT_TRUE(sample_spherical_triangle(x, to_f(t.a), to_f(t.b), to_f(t.c), u1, u2, d, p));
    ASSERT_TRUE(std::isfinite(p) && p > 0);
    ASSERT_TRUE(hits_triangle(kOrigin, to_d(d), t.a, t.b, t.c, 2e-2));
    ASSERT_TRUE(sample_parallelogram_sa(x, to_f(pp.p0), to_f(pp.e1), to_f(pp.e2), u1, u2, d, p));
    ASSERT_TRUE(std::isfinite(p) && p > 0);
    ASSERT_TRUE(hits_parallelogram(kOrigin, to_d(d), pp.p0, pp.e1, pp.e2, 2e-2));
    const bool ok = sample_parallelogram_sa(x, to_f(pr.p0), to_f(pr.e1), to_f(pr.e2), u1, u2, d, p);
    ASSERT_TRUE(std::isfinite(d.x) && std::isfinite(d.y) && std::isfinite(d.z) && std::isfinite(p));
    if (ok) {
      ASSERT_TRUE(hits_parallelogram(kOrigin, to_d(d), pr.p0, pr.e1, pr.e2, 0.5));
    }
    ASSERT_TRUE(sample_sphere_cone(x, sc, srad, u1, u2, d, p));
    ASSERT_TRUE(std::isfinite(p) && p > 0);
    ASSERT_TRUE(hits_sphere(kOrigin, to_d(d), to_d(sc), srad, 1e-2));
  }
  // Near-hemispherical: receiver 1e-3 above a huge rectangle / triangle / next to a sphere.
  const vec3f hp0(-1e3f, -1e3f, 1e-3f), he1(2e3f, 0, 0), he2(0, 2e3f, 0);
  const float om_h = parallelogram_solid_angle(x, hp0, he1, he2);
  EXPECT_GT(om_h, 6.27f);
  EXPECT_LE(om_h, 6.2832f);
  EXPECT_FALSE(solid_angle_sampling_safe(om_h));
  const float om_ht = spherical_triangle_solid_angle(x, hp0, hp0 + he1 * 2.f, hp0 + he2 * 2.f);
  EXPECT_GT(om_ht, 6.27f);
  EXPECT_FALSE(solid_angle_sampling_safe(om_ht));
  const float om_hs = sphere_cone_solid_angle(x, vec3f(0, 0, 1.000001f), 1.f);
  EXPECT_GT(om_hs, 6.25f);
  EXPECT_FALSE(solid_angle_sampling_safe(om_hs));
  for (int i = 0; i < 20000; ++i) {
    const float u1 = rng.uf(), u2 = rng.uf();
    vec3f d;
    float p;
    sample_parallelogram_sa(x, hp0, he1, he2, u1, u2, d, p);
    ASSERT_TRUE(std::isfinite(d.x) && std::isfinite(d.y) && std::isfinite(d.z) && std::isfinite(p));
    sample_spherical_triangle(x, hp0, hp0 + he1 * 2.f, hp0 + he2 * 2.f, u1, u2, d, p);
    ASSERT_TRUE(std::isfinite(d.x) && std::isfinite(d.y) && std::isfinite(d.z) && std::isfinite(p));
    ASSERT_TRUE(sample_sphere_cone(x, vec3f(0, 0, 1.000001f), 1.f, u1, u2, d, p));
    ASSERT_TRUE(std::isfinite(d.x) && std::isfinite(d.y) && std::isfinite(d.z) && std::isfinite(p));
  }
  // Degenerate inputs: x in the plane, zero edges, zero radius, NaN-free outputs and pdf 0.
  vec3f d;
  float p;
  EXPECT_FALSE(sample_parallelogram_sa(x, vec3f(1, 1, 0), vec3f(1, 0, 0), vec3f(0, 1, 0), 0.5f, 0.5f, d, p));
  EXPECT_EQ(p, 0.f);
  EXPECT_FALSE(sample_parallelogram_sa(x, vec3f(1, 1, 1), vec3f(0, 0, 0), vec3f(0, 1, 0), 0.5f, 0.5f, d, p));
  EXPECT_FALSE(sample_spherical_triangle(x, vec3f(1, 0, 1), vec3f(1, 0, 1), vec3f(0, 1, 1), 0.5f, 0.5f, d, p));
  EXPECT_FALSE(sample_spherical_triangle(x, vec3f(1, 0, 0), vec3f(2, 1, 0), vec3f(0, 1, 0), 0.5f, 0.5f, d, p));
  EXPECT_FALSE(sample_sphere_cone(x, vec3f(1, 0, 0), 0.f, 0.5f, 0.5f, d, p));
  EXPECT_TRUE(std::isfinite(d.x) && std::isfinite(d.y) && std::isfinite(d.z));
  EXPECT_EQ(pdf_parallelogram_sa(x, vec3f(1, 1, 0), vec3f(1, 0, 0), vec3f(0, 1, 0)), 0.f);
}

// =========================================================================================
// Threshold measurement: the float maps against double-precision textbook versions of the
// same maps (Urena's rectangle, Arvo's triangle) at decreasing solid angles. The error of a
// sample is the distance between the two points on the source, over the source's size.
namespace {

D3 ref_urena(D3 o, D3 p0, D3 e1, D3 e2, double u1, double u2, double& S) {
  const double lx = len(e1), ly = len(e2);
  const D3 ex = e1 * (1 / lx), ey = e2 * (1 / ly);
  D3 ez = cross(ex, ey);
  const D3 d = p0 - o;
  double z0 = dot(d, ez);
  if (z0 > 0) {
    z0 = -z0;
    ez = ez * -1.0;
  }
  const double x0 = dot(d, ex), y0 = dot(d, ey), x1 = x0 + lx, y1 = y0 + ly;
  const D3 v00{x0, y0, z0}, v01{x0, y1, z0}, v10{x1, y0, z0}, v11{x1, y1, z0};
  const D3 n0 = unit(cross(v00, v10)), n1 = unit(cross(v10, v11)), n2 = unit(cross(v11, v01)),
           n3 = unit(cross(v01, v00));
  const double g0 = std::acos(-dot(n0, n1)), g1 = std::acos(-dot(n1, n2)), g2 = std::acos(-dot(n2, n3)),
               g3 = std::acos(-dot(n3, n0));
  const double b0 = n0.z, b1 = n2.z, k = 2 * kPi - g2 - g3;
  S = g0 + g1 - k;
  const double au = u1 * S + k;
  const double fu = (std::cos(au) * b0 - b1) / std::sin(au);
  double cu = std::copysign(1.0, fu) / std::sqrt(fu * fu + b0 * b0);
  cu = std::clamp(cu, -1.0, 1.0);
  const double xu = std::clamp(-(cu * z0) / std::sqrt(1 - cu * cu), x0, x1);
  const double dd = std::sqrt(xu * xu + z0 * z0);
  const double h0 = y0 / std::sqrt(dd * dd + y0 * y0), h1 = y1 / std::sqrt(dd * dd + y1 * y1);
  const double hv = h0 + u2 * (h1 - h0), hv2 = hv * hv;
  const double yv = hv2 < 1 - 1e-12 ? hv * dd / std::sqrt(1 - hv2) : y1;
  return ex * xu + ey * yv + ez * z0;
}

D3 ref_arvo(D3 o, D3 pa, D3 pb, D3 pc, double u1, double u2) {
  const D3 A = unit(pa - o), B = unit(pb - o), C = unit(pc - o);
  auto angle = [](D3 v, D3 p, D3 q) {  // angle at v between arcs to p and q
    return std::acos(std::clamp(dot(unit(cross(v, p)), unit(cross(v, q))), -1.0, 1.0));
  };
  const double alpha = angle(A, B, C), beta = angle(B, C, A), gamma = angle(C, A, B);
  const double area = alpha + beta + gamma - kPi;
  const double ah = u1 * area;
  const double s = std::sin(ah - alpha), t = std::cos(ah - alpha);
  const double u = t - std::cos(alpha), v = s + std::sin(alpha) * dot(A, B);
  double q = ((v * t - u * s) * std::cos(alpha) - v) / ((v * s + u * t) * std::sin(alpha));
  q = std::clamp(q, -1.0, 1.0);
  const D3 ch = A * q + unit(C - A * dot(C, A)) * std::sqrt(1 - q * q);
  const double z = 1 - u2 * (1 - dot(ch, B));
  return B * z + unit(ch - B * dot(ch, B)) * std::sqrt(std::max(0.0, 1 - z * z));
}

struct MapError {
  double pdf_rel = 0, pos_max = 0, pos_mean = 0;
};

MapError rect_map_error(double s) {
  const Para p = rounded(make_para(s, 1.0));
  const double omega = para_omega(kOrigin, p.p0, p.e1, p.e2);
  const double size = len(p.e1);
  MapError e;
  const int n = 48;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      const float u1 = (i + 0.5f) / n, u2 = (j + 0.5f) / n;
      vec3f d;
      float pdf;
      sample_spherical_rectangle(vec3f(0, 0, 0), to_f(p.p0), to_f(p.e1), to_f(p.e2), u1, u2, d, pdf);
      double S;
      const D3 q = ref_urena(kOrigin, p.p0, p.e1, p.e2, u1, u2, S);
      double s1 = 0, t1 = 0, s2 = 0, t2 = 0;
      if (!plane_coords(kOrigin, to_d(d), p.p0, p.e1, p.e2, s1, t1) || !plane_coords(kOrigin, q, p.p0, p.e1, p.e2, s2, t2)) {
        e.pos_max = INFINITY;  // a direction that misses the source's plane fails the caller's bound
        continue;
      }
      const double err = len(p.e1 * (s1 - s2) + p.e2 * (t1 - t2)) / size;
      e.pos_max = std::max(e.pos_max, err);
      e.pos_mean += err / (n * n);
      e.pdf_rel = std::max(e.pdf_rel, std::fabs(1.0 / (pdf * omega) - 1.0));
    }
  return e;
}

MapError tri_map_error(double s) {
  const Tri t = rounded(make_tri(s, 1.0));
  const double omega = tri_omega(kOrigin, t.a, t.b, t.c);
  const double size = len(t.b - t.a);
  MapError e;
  const int n = 48;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      const float u1 = (i + 0.5f) / n, u2 = (j + 0.5f) / n;
      vec3f d;
      float pdf;
      sample_spherical_triangle(vec3f(0, 0, 0), to_f(t.a), to_f(t.b), to_f(t.c), u1, u2, d, pdf);
      const D3 q = ref_arvo(kOrigin, t.a, t.b, t.c, u1, u2);
      double s1 = 0, t1 = 0, s2 = 0, t2 = 0;
      const D3 e1 = t.b - t.a, e2 = t.c - t.a;
      if (!plane_coords(kOrigin, to_d(d), t.a, e1, e2, s1, t1) || !plane_coords(kOrigin, q, t.a, e1, e2, s2, t2)) {
        e.pos_max = INFINITY;  // a direction that misses the source's plane fails the caller's bound
        continue;
      }
      const double err = len(e1 * (s1 - s2) + e2 * (t1 - t2)) / size;
      e.pos_max = std::max(e.pos_max, err);
      e.pos_mean += err / (n * n);
      e.pdf_rel = std::max(e.pdf_rel, std::fabs(1.0 / (pdf * omega) - 1.0));
    }
  return e;
}

}  // namespace

TEST(SolidAngleThresholds, FloatMapsAgainstDoubleReference) {
  std::printf("  %-10s %-10s | %-28s | %-28s\n", "omega~", "", "rectangle pdf/posmax/posmean",
              "triangle pdf/posmax/posmean");
  for (double om : {1.0, 1e-1, 1e-2, 1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 1e-6, 1e-7, 1e-8}) {
    const double s_rect = std::sqrt(om / 0.7 / 0.80), s_tri = std::sqrt(om / 0.35 / 0.85);
    const MapError r = rect_map_error(s_rect), t = tri_map_error(s_tri);
    std::printf("  %-10.0e %-10s | %8.1e %8.1e %8.1e   | %8.1e %8.1e %8.1e\n", om, "", r.pdf_rel, r.pos_max,
                r.pos_mean, t.pdf_rel, t.pos_max, t.pos_mean);
    if (om >= min_sa_sample_omega) {
      // Above the threshold both maps are accurate to well under a thousandth of the source.
      EXPECT_LT(r.pdf_rel, 1e-4) << om;
      EXPECT_LT(r.pos_max, 1e-3) << om;
      EXPECT_LT(t.pdf_rel, 1e-4) << om;
      EXPECT_LT(t.pos_max, 1e-3) << om;
    }
  }
}

// =========================================================================================
// SIMD lanes equal the scalar reference, bit for bit.
namespace {

constexpr int W = simd_width;
constexpr int kIn = 16, kOut = 8;
struct LaneData {
  alignas(64) float in[kIn][W];
  alignas(64) float out[kOut][W];
};

template <class T, class F> void run_lanes(F&& f, const LaneData& src, LaneData& dst, int i) {
  T in[kIn];
  for (int k = 0; k < kIn; ++k) in[k] = load<T>(&src.in[k][i]);
  T out[kOut];
  for (int k = 0; k < kOut; ++k) out[k] = T(0.f);
  f(in, out);
  for (int k = 0; k < kOut; ++k) store(&dst.out[k][i], out[k]);
}

// Whether this translation unit was compiled with a*b+c fused into fma (GCC's default
// -ffp-contract=fast for C++): then the compiler may fuse differently in the scalar and SIMD
// instantiations, and lanes can differ from the scalar reference by a few ulps. Built with
// -ffp-contract=off (recommended for the project) every lane must be bit-identical.
__attribute__((noinline)) float probe_mul_add(float a, float b, float c) { return a * b + c; }
bool compiler_fuses_mul_add() {
  volatile float a = 1.f + 0x1p-12f;
  return probe_mul_add(a, a, -(1.f + 0x1p-11f)) != 0.f;  // exact product needs 25 bits
}

// f(in, out) is a generic lambda over T. gen fills the inputs of one lane.
template <class F, class G> void expect_lanes_equal(F&& f, G&& gen, const char* name, float fused_tol = 2e-6f) {
  LaneData src{}, scalar{}, simd{};
  Rng rng(1234);
  for (int i = 0; i < W; ++i) {
    float v[kIn] = {};
    gen(rng, i, v);
    for (int k = 0; k < kIn; ++k) src.in[k][i] = v[k];
  }
  for (int i = 0; i < W; ++i) run_lanes<float>(f, src, scalar, i);
  run_lanes<vfloat>(f, src, simd, 0);
  const bool fused = compiler_fuses_mul_add();
  for (int k = 0; k < kOut; ++k)
    for (int i = 0; i < W; ++i) {
      const float a = scalar.out[k][i], b = simd.out[k][i];
      if (!fused)
        EXPECT_EQ(std::memcmp(&a, &b, sizeof(float)), 0)
            << name << " output " << k << " lane " << i << ": scalar " << a << " simd " << b;
      else  // measured: at most 4e-7 relative here; allow 2e-6 (more where stated)
        EXPECT_LE(std::fabs(a - b), fused_tol * std::max(1.f, std::fabs(a)))
            << name << " output " << k << " lane " << i << ": scalar " << a << " simd " << b;
    }
}

template <class T> Vec3<T> v3(const T* p) { return {p[0], p[1], p[2]}; }
template <class T> void put3(T* o, const Vec3<T>& v) {
  o[0] = v.x;
  o[1] = v.y;
  o[2] = v.z;
}
template <class T, class M> T mask_f(const M& m) { return sel(m, T(1.f), T(0.f)); }

// Lane inputs: x, three points or p0/e1/e2, u1, u2, radius; a few lanes degenerate.
void gen_geometry(Rng& r, int lane, float* v) {
  for (int k = 0; k < 3; ++k) v[k] = r.uf() * 2 - 1;                  // x
  for (int k = 3; k < 12; ++k) v[k] = r.uf() * 4 - 2;                 // a, b, c (or p0, e1, e2)
  v[2] -= 3.f;                                                        // x below the sources
  v[12] = r.uf();
  v[13] = r.uf();
  v[14] = r.uf() * 1.5f;  // radius
  if (lane == 3) v[12] = 0.f, v[13] = 0x1.fffffep-1f;
  if (lane == 5) {
    for (int k = 0; k < 3; ++k) v[6 + k] = v[3 + k];  // degenerate: a == b
  }
  if (lane == 7) v[14] = 10.f;                                        // x inside the sphere
  if (lane == 9) v[13] = 0.f, v[12] = 1.f;
  if (lane == 11) v[14] = 0.f;
  if (lane == 13) v[3] = v[0], v[6] = v[0], v[9] = v[0];              // x in a plane of the source
  if (lane == 15) v[12] = 0.5f, v[13] = 0.5f;
}
// Rectangle lanes: e2 made orthogonal to e1.
void gen_rect(Rng& r, int lane, float* v) {
  gen_geometry(r, lane, v);
  const vec3f e1(v[6], v[7], v[8]), e(v[9], v[10], v[11]);
  const vec3f e2 = e - e1 * (dot(e, e1) / dot(e1, e1));
  if (lane % 2 == 0) v[9] = e2.x, v[10] = e2.y, v[11] = e2.z;  // odd lanes stay skewed
}
void gen_rect_only(Rng& r, int lane, float* v) {
  gen_rect(r, 2 * (lane / 2), v);  // every lane orthogonal (degenerate cases at even lanes)
}

}  // namespace

TEST(Lanes, CosineAndTriangleAreaAndSphereArea) {
  if (compiler_fuses_mul_add())
    std::printf("  note: built with fused multiply-add contraction; lanes compared within 2e-6 "
                "(build with -ffp-contract=off for bit-exact lanes)\n");
  expect_lanes_equal(
      [](auto* in, auto* out) {
        using T = std::remove_pointer_t<decltype(in)>;
        put3(out, sample_cosine_hemisphere(in[12], in[13]));
        out[3] = pdf_cosine_hemisphere(in[0]);
        sample_triangle_area(in[12], in[13], out[4], out[5]);
        out[6] = pdf_triangle_area(v3(in + 3), v3(in + 6));
        out[7] = pdf_sphere_area(in[14]) + T(0.f);
      },
      gen_geometry, "cosine/triangle");
  expect_lanes_equal(
      [](auto* in, auto* out) {
        put3(out, sample_sphere_area(v3(in + 3), in[14], in[12], in[13]));
        lane_math::sincos(in[3] * 3, out[3], out[4]);
        out[5] = lane_math::atan2(in[4], in[5]);
        out[6] = lane_math::asin(in[0]);
      },
      gen_geometry, "sphere area/math");
}

TEST(Lanes, SphericalTriangle) {
  expect_lanes_equal(
      [](auto* in, auto* out) {
        using T = std::remove_pointer_t<decltype(in)>;
        Vec3<T> d;
        T pdf;
        const auto m = sample_spherical_triangle(v3(in), v3(in + 3), v3(in + 6), v3(in + 9), in[12], in[13], d, pdf);
        put3(out, d);
        out[3] = pdf;
        out[4] = mask_f<T>(m);
        out[5] = spherical_triangle_solid_angle(v3(in), v3(in + 3), v3(in + 6), v3(in + 9));
        out[6] = pdf_spherical_triangle_sa(v3(in), v3(in + 3), v3(in + 6), v3(in + 9));
      },
      gen_geometry, "spherical triangle");
}

TEST(Lanes, Parallelogram) {
  expect_lanes_equal(
      [](auto* in, auto* out) {
        using T = std::remove_pointer_t<decltype(in)>;
        Vec3<T> d;
        T pdf;
        const auto m = sample_parallelogram_sa(v3(in), v3(in + 3), v3(in + 6), v3(in + 9), in[12], in[13], d, pdf);
        put3(out, d);
        out[3] = pdf;
        out[4] = mask_f<T>(m);
        out[5] = parallelogram_solid_angle(v3(in), v3(in + 3), v3(in + 6), v3(in + 9));
        out[6] = pdf_parallelogram_sa(v3(in), v3(in + 3), v3(in + 6), v3(in + 9));
        out[7] = mask_f<T>(parallelogram_is_rectangle(v3(in + 6), v3(in + 9)));
      },
      gen_rect, "parallelogram");
  expect_lanes_equal(
      [](auto* in, auto* out) {
        using T = std::remove_pointer_t<decltype(in)>;
        Vec3<T> d;
        T pdf;
        const auto m =
            sample_spherical_parallelogram(v3(in), v3(in + 3), v3(in + 6), v3(in + 9), in[12], in[13], d, pdf);
        put3(out, d);
        out[3] = pdf;
        out[4] = mask_f<T>(m);
        const auto m2 = sample_spherical_rectangle(v3(in), v3(in + 3), v3(in + 6), v3(in + 9), in[12], in[13], d, pdf);
        out[5] = d.x + d.y * T(3.f) + d.z * T(9.f);
        out[6] = pdf;
        out[7] = mask_f<T>(m2) + spherical_rectangle_solid_angle(v3(in), v3(in + 3), v3(in + 6), v3(in + 9));
      },
      // Urena's S = sum(asin) - ... has an absolute error of ~1e-7 sr, so a different fusion
      // moves the pdf of these 0.02-0.05 sr rectangles by up to ~1e-5 relative.
      gen_rect_only, "rectangle/parallelogram parts", 1e-4f);
}

TEST(Lanes, SphereCone) {
  expect_lanes_equal(
      [](auto* in, auto* out) {
        using T = std::remove_pointer_t<decltype(in)>;
        Vec3<T> d;
        T pdf;
        const auto m = sample_sphere_cone(v3(in), v3(in + 3), in[14], in[12], in[13], d, pdf);
        put3(out, d);
        out[3] = pdf;
        out[4] = mask_f<T>(m);
        out[5] = sphere_cone_solid_angle(v3(in), v3(in + 3), in[14]);
        out[6] = pdf_sphere_cone(v3(in), v3(in + 3), in[14]);
        out[7] = mask_f<T>(solid_angle_sampling_safe(out[5]));
      },
      gen_geometry, "sphere cone");
}

// =========================================================================================
// 7. Polygon irradiance
namespace {
// E / L of an s x s square parallel to the receiver, centred on its normal at height h:
// four a x a rectangles with a corner above x, F = (1/2pi)(A/sqrt(1+A^2) atan(A/sqrt(1+A^2))*2),
// A = a / h; E / L = pi * F summed.
double square_on_axis(double s, double h) {
  const double A = 0.5 * s / h;
  const double q = std::sqrt(1 + A * A);
  const double F_quarter = (1.0 / (2 * kPi)) * 2.0 * (A / q) * std::atan(A / q);
  return 4 * kPi * F_quarter;
}
// Monte Carlo E / L = integral over the polygon of max(cos, 0) cos_l / d^2 dA for the
// parallelogram p0 + s e1 + t e2, by stratified uniform area samples.
double mc_parallelogram(D3 x, D3 n, D3 p0, D3 e1, D3 e2, int m) {
  const D3 nl = cross(e1, e2);
  const double area = len(nl);
  const D3 nu = nl * (1 / area);
  double sum = 0;
  for (int i = 0; i < m; ++i)
    for (int j = 0; j < m; ++j) {
      const D3 p = p0 + e1 * ((i + 0.5) / m) + e2 * ((j + 0.5) / m);
      const D3 d = p - x;
      const double d2 = dot(d, d), dl = std::sqrt(d2);
      sum += std::max(0.0, dot(n, d) / dl) * std::fabs(dot(nu, d)) / dl / d2;
    }
  return sum * area / (double(m) * m);
}
}  // namespace

TEST(PolygonIrradiance, SquareOnAxisClosedForm) {
  const double x[3] = {0, 0, 0}, n[3] = {0, 0, 1};
  for (double h : {0.1, 0.5, 1.0, 3.0}) {
    const double sq[12] = {-0.5, -0.5, h, 0.5, -0.5, h, 0.5, 0.5, h, -0.5, 0.5, h};
    EXPECT_NEAR(polygon_form_factor_irradiance(x, n, sq, 4), square_on_axis(1.0, h), 1e-12) << h;
    // reversed winding gives the same value
    const double rv[12] = {-0.5, 0.5, h, 0.5, 0.5, h, 0.5, -0.5, h, -0.5, -0.5, h};
    EXPECT_NEAR(polygon_form_factor_irradiance(x, n, rv, 4), square_on_axis(1.0, h), 1e-12) << h;
  }
  // an infinite plane above x gives E = pi L
  const double big[12] = {-1e7, -1e7, 1, 1e7, -1e7, 1, 1e7, 1e7, 1, -1e7, 1e7, 1};
  EXPECT_NEAR(polygon_form_factor_irradiance(x, n, big, 4), kPi, 1e-6);
}

TEST(PolygonIrradiance, TiltedAgainstMonteCarlo) {
  const D3 xd{0.1, -0.2, 0.0}, nd = unit(D3{0.2, 0.1, 1.0});
  const D3 p0{-0.3, 0.4, 1.0}, e1{0.8, 0.1, 0.3}, e2{-0.2, 0.9, 0.4};
  const double x[3] = {xd.x, xd.y, xd.z}, n[3] = {nd.x, nd.y, nd.z};
  const D3 vs[4] = {p0, p0 + e1, p0 + e1 + e2, p0 + e2};
  double v[12];
  for (int i = 0; i < 4; ++i) v[3 * i] = vs[i].x, v[3 * i + 1] = vs[i].y, v[3 * i + 2] = vs[i].z;
  const double exact = polygon_form_factor_irradiance(x, n, v, 4);
  const double mc = mc_parallelogram(xd, nd, p0, e1, e2, 1000);
  EXPECT_NEAR(exact, mc, 1e-5 * mc);
  EXPECT_EQ(exact, polygon_irradiance_clipped(x, n, v, 4));
}

TEST(PolygonIrradiance, CrossingTheTangentPlane) {
  // A vertical wall x + [-1,1] x {1} x [-1,1] in front of a receiver facing +z: half of it
  // lies below the tangent plane.
  const double x[3] = {0, 0, 0}, n[3] = {0, 0, 1};
  const double wall[12] = {-1, 1, -1, 1, 1, -1, 1, 1, 1, -1, 1, 1};
  const double clipped = polygon_irradiance_clipped(x, n, wall, 4);
  const double mc = mc_parallelogram({0, 0, 0}, {0, 0, 1}, {-1, 1, -1}, {2, 0, 0}, {0, 0, 2}, 2000);
  EXPECT_NEAR(clipped, mc, 2e-4 * mc);
  const double upper[12] = {-1, 1, 0, 1, 1, 0, 1, 1, 1, -1, 1, 1};
  EXPECT_NEAR(clipped, polygon_form_factor_irradiance(x, n, upper, 4), 1e-14);
  // the unclipped formula is wrong here (the lower half cancels the upper half)
  EXPECT_GT(std::fabs(polygon_form_factor_irradiance(x, n, wall, 4) - mc), 0.1 * mc);
  // fully below: zero
  const double below[12] = {-1, -1, -1, 1, -1, -1, 1, 1, -1, -1, 1, -1};
  EXPECT_EQ(polygon_irradiance_clipped(x, n, below, 4), 0.0);
  // a triangle crossing the plane obliquely, against Monte Carlo over its upper part
  const double tri[9] = {-0.5, 0.3, -0.6, 0.9, 0.5, 0.8, -0.2, 1.2, 0.4};
  const D3 a{-0.5, 0.3, -0.6}, b{0.9, 0.5, 0.8}, c{-0.2, 1.2, 0.4};
  // MC over the triangle as a degenerate parallelogram map (s, s t): area density 2 s
  double sum = 0;
  const int m = 1500;
  const D3 nt = unit(cross(b - a, c - a));
  const double area = 0.5 * len(cross(b - a, c - a));
  for (int i = 0; i < m; ++i)
    for (int j = 0; j < m; ++j) {
      double u = (i + 0.5) / m, w = (j + 0.5) / m;
      if (u + w > 1) u = 1 - u, w = 1 - w;
      const D3 p = a + (b - a) * u + (c - a) * w;
      const double d2 = dot(p, p), dl = std::sqrt(d2);
      sum += std::max(0.0, p.z / dl) * std::fabs(dot(nt, p)) / dl / d2;
    }
  const double mct = sum * area / (double(m) * m);
  EXPECT_NEAR(polygon_irradiance_clipped(x, n, tri, 3), mct, 2e-4 * mct);
}

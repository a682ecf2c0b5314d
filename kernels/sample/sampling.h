// Sampling math: warps from [0,1)^2 to directions and points, with their pdfs.
// Reads: uniform numbers u1, u2 and plain geometry (points, edges, radii) per lane.
// Writes: directions (unit), points, barycentrics, pdfs, validity masks.
// Assumes: T = float (the scalar reference) or vfloat; no -ffast-math. Every function is
// branch-free over lanes (masks + sel) and returns finite values for any finite input;
// where a sample can fail it returns a mask and writes a harmless direction and pdf 0.
// Sources: Shirley & Chiu 1997 (concentric disk) + Malley's method; Heitz 2019 (low-
// distortion triangle map); Van Oosterom & Strackee 1983 (triangle solid angle); Arvo 1995
// (spherical triangle sampling, rewritten below in half-angle form for precision); Ureña,
// Fajardo & King 2013 (spherical rectangle sampling); uniform cone sampling (pbrt, 4th ed.).
//
// Elementary functions (sin, cos, atan2, asin) are evaluated by the polynomial code in
// namespace tuile::lane_math, written once for both lane types from +, -, *, /, sqrt and
// floor only. Those are correctly rounded in IEEE arithmetic, so every SIMD lane gives the
// same bits as the scalar reference (as long as the compiler does not fuse a*b+c
// differently in the two instantiations: build with -ffp-contract=off for bit-exactness).
#pragma once
#include "lanes/simd.h"
#include "lanes/vec.h"

namespace tuile {

inline constexpr float pi_f = 3.14159265358979323846f;
inline constexpr float two_pi_f = 6.28318530717958647692f;
inline constexpr float inv_pi_f = 0.318309886183790671538f;
inline constexpr float inv_four_pi_f = 0.0795774715459476678844f;

// Solid-angle sampling is used only for sources subtending min_sa_sample_omega <= Omega <=
// max_sa_sample_omega; outside that range the renderer samples the light by area. The rule
// depends on Omega alone, so MIS can re-apply it from (x, light) when evaluating the pdf.
//
// Measured (tests/test_sampling.cpp, SolidAngleThresholds): the float maps against the same
// maps in double (textbook Urena; textbook Arvo), oblique sources at distance 1. "pdf" is the
// worst relative error of 1/pdf against the exact solid angle, "pos" the worst distance on
// the source between the float and double sample points, over the source's size (worst
// over a 48 x 48 grid of (u1, u2)):
//     Omega (sr)     1e-2     1e-3     3e-4     1e-4     3e-5     1e-5     1e-6     1e-8
//     rect  pdf    6e-08    5e-07    3e-06    1e-05    2e-05    6e-05    8e-04    8e-03
//     rect  pos    9e-07    3e-06    7e-06    2e-05    5e-05    8e-05    6e-04    6e-02
//     tri   pdf    4e-08    1e-07    4e-08    8e-08    1e-08    1e-07    6e-08    2e-07
//     tri   pos    6e-07    1e-05    3e-05    8e-05    7e-04    2e-03    8e-03    3e-01
// Urena's S = sum(gamma_i) - 2 pi has an absolute error of ~1e-7 sr (ulps of O(1) angles), so
// its relative pdf error grows as 1/Omega; Arvo's map keeps its pdf (Van Oosterom-Strackee)
// but its sample points drift as the angular size approaches float direction precision.
// Requiring both errors below 1e-4 puts the limit at 1e-4 sr: the triangle's points fail it
// at 3e-5 sr (pbrt-v4 uses 3e-4 for triangles). Area sampling of such small sources is
// accurate to a few ulps and has almost no variance (the integrand is nearly constant).
// Above 6.22 sr (99% of the hemisphere; pbrt-v4's value) the receiver lies almost in the
// source's plane: directions are almost all grazing, the solid-angle pdf gains nothing over
// the area pdf, and the sub-triangle construction degenerates (alpha - A/2 -> 0).
inline constexpr float min_sa_sample_omega = 1e-4f;
inline constexpr float max_sa_sample_omega = 6.22f;

template <class T> inline mask_t<T> solid_angle_sampling_safe(const T& omega) noexcept {
  return omega >= T(min_sa_sample_omega) && omega <= T(max_sa_sample_omega);
}

// ---------------------------------------------------------------------------------------
// Lane-generic elementary functions (bit-identical for float and vfloat). Calls between
// them are qualified: unqualified, ADL would pick xsimd's own atan2/asin for batches.
namespace lane_math {

// sin and cos for |x| <= pi/4 (Taylor series, truncation error < 1e-11).
template <class T> inline void sincos_reduced(const T& x, T& s, T& c) noexcept {
  const T x2 = x * x;
  T ps = T(-2.5052108385441718775e-8f);
  ps = mul_add(ps, x2, T(2.7557319223985890653e-6f));
  ps = mul_add(ps, x2, T(-1.9841269841269841270e-4f));
  ps = mul_add(ps, x2, T(8.3333333333333333333e-3f));
  ps = mul_add(ps, x2, T(-1.6666666666666666667e-1f));
  s = mul_add(x * x2, ps, x);
  T pc = T(2.0876756987868098979e-9f);
  pc = mul_add(pc, x2, T(-2.7557319223985890653e-7f));
  pc = mul_add(pc, x2, T(2.4801587301587301587e-5f));
  pc = mul_add(pc, x2, T(-1.3888888888888888889e-3f));
  pc = mul_add(pc, x2, T(4.1666666666666666667e-2f));
  pc = mul_add(pc, x2, T(-0.5f));
  c = mul_add(x2, pc, T(1.f));
}

// Rotate (s, c) = (sin r, cos r) by q quarter turns, q an integer-valued float.
template <class T> inline void rotate_quadrant(const T& q, T& s, T& c) noexcept {
  const T m = q - T(4.f) * floor(q * T(0.25f));  // 0, 1, 2, 3
  const mask_t<T> odd = m == T(1.f) || m == T(3.f);
  const T s1 = sel(odd, c, s), c1 = sel(odd, s, c);
  s = sel(m >= T(2.f), -s1, s1);                          // quadrants 2, 3: sin < 0
  c = sel(m == T(1.f) || m == T(2.f), -c1, c1);           // quadrants 1, 2: cos < 0
}

// sin and cos for |x| <= 100 (Cody-Waite reduction by pi/2; the high part of pi/2 has
// 8 significant bits, so q * hi is exact).
template <class T> inline void sincos(const T& x, T& s, T& c) noexcept {
  const T q = floor(x * T(0.636619772367581343076f) + T(0.5f));
  const T r = (x - q * T(1.5703125f)) - q * T(4.83826794897e-4f);
  lane_math::sincos_reduced(r, s, c);
  lane_math::rotate_quadrant(q, s, c);
}

// sin and cos of 2 pi u for any |u| <= 2^20, reduced exactly in turns.
template <class T> inline void sincos_2pi(const T& u, T& s, T& c) noexcept {
  const T u4 = u * T(4.f);
  const T q = floor(u4 + T(0.5f));
  lane_math::sincos_reduced((u4 - q) * T(1.57079632679489661923f), s, c);
  lane_math::rotate_quadrant(q, s, c);
}

// atan(z) for |z| <= tan(pi/8) (Taylor series to z^17, relative error < 1e-8).
template <class T> inline T atan_reduced(const T& z) noexcept {
  const T z2 = z * z;
  T p = T(1.f / 17.f);
  p = mul_add(p, z2, T(-1.f / 15.f));
  p = mul_add(p, z2, T(1.f / 13.f));
  p = mul_add(p, z2, T(-1.f / 11.f));
  p = mul_add(p, z2, T(1.f / 9.f));
  p = mul_add(p, z2, T(-1.f / 7.f));
  p = mul_add(p, z2, T(1.f / 5.f));
  p = mul_add(p, z2, T(-1.f / 3.f));
  return mul_add(z * z2, p, z);
}

// atan2(y, x) in [-pi, pi]; 0 for (0, 0).
template <class T> inline T atan2(const T& y, const T& x) noexcept {
  const T ax = abs(x), ay = abs(y);
  const T mx = max(ax, ay), mn = min(ax, ay);
  // z = r or (r - 1) / (r + 1) with r = mn / mx in [0, 1], in one division
  const mask_t<T> big = mn > T(0.414213562373095048802f) * mx;
  const T z = sel(big, mn - mx, mn) / sel(big, mn + mx, sel(mx > T(0.f), mx, T(1.f)));
  T a = lane_math::atan_reduced(z) + sel(big, T(0.785398163397448309616f), T(0.f));
  a = sel(ay > ax, T(1.57079632679489661923f) - a, a);
  a = sel(x < T(0.f), T(pi_f) - a, a);
  return sel(y < T(0.f), -a, a);
}

// asin(t) for t in [-1, 1] (clamped), accurate near 0 and near +-1.
template <class T> inline T asin(const T& t) noexcept {
  const T tc = min(max(t, T(-1.f)), T(1.f));
  return lane_math::atan2(tc, sqrt((T(1.f) - tc) * (T(1.f) + tc)));
}

} // namespace lane_math

namespace sampling_detail {

template <class T> inline T safe_sqrt(const T& x) noexcept { return sqrt(max(x, T(0.f))); }

// v / |v|, or fallback where |v| is 0 or not finite.
template <class T> inline Vec3<T> normalize_or(const Vec3<T>& v, const Vec3<T>& fallback) noexcept {
  const T l2 = dot(v, v);
  const mask_t<T> ok = l2 > T(0.f) && is_finite(l2);
  const T inv = T(1.f) / sqrt(sel(ok, l2, T(1.f)));
  return sel(ok, v * inv, fallback);
}

template <class T> inline mask_t<T> finite3(const Vec3<T>& v) noexcept {
  return is_finite(v.x) && is_finite(v.y) && is_finite(v.z);
}

// Make an output safe: invalid lanes get direction fallback and pdf 0.
template <class T>
inline mask_t<T> finish(mask_t<T> valid, Vec3<T>& dir, T& pdf, const Vec3<T>& fallback) noexcept {
  valid = valid && finite3(dir) && is_finite(pdf) && pdf > T(0.f);
  dir = sel(valid, dir, fallback);
  pdf = sel(valid, pdf, T(0.f));
  return valid;
}

} // namespace sampling_detail

// ---------------------------------------------------------------------------------------
// 1. Cosine-weighted hemisphere, local frame with z up (Shirley-Chiu disk, then Malley).
template <class T> inline Vec3<T> sample_cosine_hemisphere(const T& u1, const T& u2) noexcept {
  const T a = T(2.f) * u1 - T(1.f), b = T(2.f) * u2 - T(1.f);
  const mask_t<T> a_major = abs(a) > abs(b);
  const T r = sel(a_major, a, b);
  const T num = sel(a_major, b, a);
  const T den = sel(r == T(0.f), T(1.f), r);
  T s, c;
  lane_math::sincos_reduced(T(0.785398163397448309616f) * (num * rcp_nr(den)), s, c);
  // a major: phi = t; b major: phi = pi/2 - t, so cos and sin swap.
  const T x = r * sel(a_major, c, s);
  const T y = r * sel(a_major, s, c);
  const T z = sampling_detail::safe_sqrt(T(1.f) - x * x - y * y);
  return {x, y, z};
}

template <class T> inline T pdf_cosine_hemisphere(const T& cos_theta) noexcept {
  return max(cos_theta, T(0.f)) * T(inv_pi_f);
}

// ---------------------------------------------------------------------------------------
// 2. Uniform point on a triangle p0 + b1 e1 + b2 e2 (Heitz 2019: area-preserving, keeps
// stratification with little distortion). pdf_area = 1 / area.
template <class T> inline void sample_triangle_area(const T& u1, const T& u2, T& b1, T& b2) noexcept {
  const mask_t<T> upper = u2 > u1;
  const T h1 = u1 * T(0.5f), h2 = u2 * T(0.5f);
  b1 = sel(upper, h1, u1 - h2);
  b2 = sel(upper, u2 - h1, h2);
}

template <class T> inline T pdf_triangle_area(const Vec3<T>& e1, const Vec3<T>& e2) noexcept {
  const T area = T(0.5f) * length(cross(e1, e2));
  return sel(area > T(0.f), T(1.f) / sel(area > T(0.f), area, T(1.f)), T(0.f));
}

// ---------------------------------------------------------------------------------------
// 3. Spherical triangles.
//
// Setup from the viewpoint x and vertices A, B, C, computed from edge vectors so that tiny
// and distant triangles keep full relative precision (no differences of nearly equal unit
// vectors). alpha is the angle at A, c the side AB (arc), Omega the solid angle.
template <class T> struct SphericalTriangle {
  Vec3<T> a, b;       // unit directions to A and B
  Vec3<T> t_ac;       // unit tangent of the great circle at A, towards C
  T sin_alpha, cos_alpha;
  T sin_c, one_plus_cos_c;
  T omega;
  mask_t<T> valid;
};

template <class T>
inline SphericalTriangle<T> spherical_triangle_setup(const Vec3<T>& x, const Vec3<T>& pa, const Vec3<T>& pb,
                                                     const Vec3<T>& pc) noexcept {
  using namespace sampling_detail;
  const Vec3<T> da = pa - x, db = pb - x, dc = pc - x;
  const Vec3<T> eb = pb - pa, ec = pc - pa;
  const T la = length(da), lb = length(db), lc = length(dc);
  const mask_t<T> ok_len = la > T(0.f) && lb > T(0.f) && lc > T(0.f);
  const T ila = T(1.f) / sel(ok_len, la, T(1.f));
  const T ilb = T(1.f) / sel(ok_len, lb, T(1.f));
  const T ilc = T(1.f) / sel(ok_len, lc, T(1.f));
  const Vec3<T> a = da * ila, b = db * ilb, c = dc * ilc;
  // Normals of the planes (x, A, B) and (x, A, C): a x b = a x (eb / lb), exact form.
  const Vec3<T> n_ab = cross(a, eb * ilb), n_ac = cross(a, ec * ilc);
  // det(a, b, c) = a . (eb x ec) / (lb lc): no cancellation for small triangles.
  const T det = dot(a, cross(eb * ilb, ec * ilc));
  const T adet = abs(det);
  // Van Oosterom & Strackee: tan(Omega / 2) = |det| / (1 + a.b + a.c + b.c).
  const T den = T(1.f) + dot(a, b) + dot(a, c) + dot(b, c);
  SphericalTriangle<T> s;
  s.omega = T(2.f) * lane_math::atan2(adet, den);
  // |n_ab x n_ac| = |det|, n_ab . n_ac = |n_ab||n_ac| cos(alpha).
  const T cosp = dot(n_ab, n_ac);
  const T h = sqrt(adet * adet + cosp * cosp);
  const mask_t<T> ok_h = h > T(0.f);
  const T ih = T(1.f) / sel(ok_h, h, T(1.f));
  s.sin_alpha = adet * ih;
  s.cos_alpha = cosp * ih;
  s.sin_c = length(n_ab);
  s.one_plus_cos_c = T(1.f) + dot(a, b);
  s.a = a;
  s.b = b;
  // (a x ec) x a is orthogonal to a, in the plane (x, A, C), pointing towards C.
  s.t_ac = normalize_or(cross(n_ac, a), Vec3<T>(T(0.f), T(0.f), T(1.f)));
  s.valid = ok_len && ok_h && adet > T(0.f) && s.omega > T(0.f) && is_finite(s.omega) && is_finite(h) &&
            s.sin_c > T(0.f);
  s.omega = sel(s.valid, s.omega, T(0.f));
  return s;
}

template <class T>
inline SphericalTriangle<T> sel(const mask_t<T>& m, const SphericalTriangle<T>& p, const SphericalTriangle<T>& q) noexcept {
  SphericalTriangle<T> r;
  r.a = sel(m, p.a, q.a);
  r.b = sel(m, p.b, q.b);
  r.t_ac = sel(m, p.t_ac, q.t_ac);
  r.sin_alpha = sel(m, p.sin_alpha, q.sin_alpha);
  r.cos_alpha = sel(m, p.cos_alpha, q.cos_alpha);
  r.sin_c = sel(m, p.sin_c, q.sin_c);
  r.one_plus_cos_c = sel(m, p.one_plus_cos_c, q.one_plus_cos_c);
  r.omega = sel(m, p.omega, q.omega);
  r.valid = (m && p.valid) || (!m && q.valid);
  return r;
}

// Solid angle (sr) subtended at x by triangle (a, b, c); 0 when degenerate or x is in its plane.
template <class T>
inline T spherical_triangle_solid_angle(const Vec3<T>& x, const Vec3<T>& a, const Vec3<T>& b,
                                        const Vec3<T>& c) noexcept {
  return spherical_triangle_setup(x, a, b, c).omega;
}

template <class T>
inline T pdf_spherical_triangle_sa(const Vec3<T>& x, const Vec3<T>& a, const Vec3<T>& b, const Vec3<T>& c) noexcept {
  const T omega = spherical_triangle_solid_angle(x, a, b, c);
  return sel(omega > T(0.f), T(1.f) / sel(omega > T(0.f), omega, T(1.f)), T(0.f));
}

// Arvo's map for a prepared triangle. Arvo picks the sub-triangle (A, B, C') of area
// u1 * Omega with C' on arc AC; here C' is found from the half-angle identity for two
// sides and the included angle, tan(E/2) = tan(b/2) tan(c/2) sin(alpha) / (1 + tan(b/2)
// tan(c/2) cos(alpha)), solved for the side b' = AC':
//   tan(b'/2) = sin(E/2) / (sin(alpha - E/2) tan(c/2)),  E = u1 * Omega,
// which has no cancellation for small triangles (Arvo's cos(b') = q form has 1 - q ~ b'^2).
// Then the direction is uniform in cos(theta) along arc BC' (theta measured from B).
template <class T>
inline mask_t<T> sample_spherical_triangle(const SphericalTriangle<T>& s, const T& u1, const T& u2, Vec3<T>& dir,
                                           T& pdf_sa) noexcept {
  using namespace sampling_detail;
  const T half_e = T(0.5f) * u1 * s.omega;
  T sh, ch;
  lane_math::sincos(half_e, sh, ch);
  const T num = sh * s.one_plus_cos_c;                               // ~ sin(E/2) (1 + cos c)
  const T den = (s.sin_alpha * ch - s.cos_alpha * sh) * s.sin_c;     // ~ sin(alpha - E/2) sin c
  // cos b' = (den^2 - num^2) / (den^2 + num^2), sin b' = 2 num den / (den^2 + num^2), scaled first.
  const T m = max(abs(num), abs(den));
  const T im = T(1.f) / sel(m > T(0.f), m, T(1.f));
  const T n1 = num * im, d1 = max(den * im, T(0.f));
  const T r2 = n1 * n1 + d1 * d1;
  const T ir2 = T(1.f) / sel(r2 > T(0.f), r2, T(1.f));
  const T cos_b = (d1 * d1 - n1 * n1) * ir2;
  const T sin_b = T(2.f) * n1 * d1 * ir2;
  const Vec3<T> cp = s.a * cos_b + s.t_ac * sin_b;  // C', unit up to rounding
  // Along arc B -> C': 1 - cos(theta) = u2 (1 - B.C'), 1 - B.C' = |C' - B|^2 / 2.
  const Vec3<T> w = cp - s.b;
  const T w2 = dot(w, w);
  const T omz = u2 * T(0.5f) * w2;
  const T z = T(1.f) - omz;
  const T sin_t = safe_sqrt(omz * (T(2.f) - omz));
  // Tangent at B towards C': w minus its component along B (w.B = -|w|^2/2 for unit B, C').
  const Vec3<T> tb = normalize_or(w - s.b * dot(w, s.b), s.a);
  dir = normalize_or(s.b * z + tb * sin_t, s.a);
  pdf_sa = T(1.f) / sel(s.omega > T(0.f), s.omega, T(1.f));
  return finish(s.valid, dir, pdf_sa, Vec3<T>(T(0.f), T(0.f), T(1.f)));
}

// Direction from x uniform (by solid angle) within triangle (a, b, c); pdf_sa = 1/Omega.
template <class T>
inline mask_t<T> sample_spherical_triangle(const Vec3<T>& x, const Vec3<T>& a, const Vec3<T>& b, const Vec3<T>& c,
                                           const T& u1, const T& u2, Vec3<T>& dir, T& pdf_sa) noexcept {
  return sample_spherical_triangle(spherical_triangle_setup(x, a, b, c), u1, u2, dir, pdf_sa);
}

// ---------------------------------------------------------------------------------------
// 4. Spherical rectangles (Urena, Fajardo & King 2013) for p0 + u e1 + v e2, e1 . e2 = 0.
//
// In the local frame (x at the origin, the rectangle [x0, x1] x [y0, y1] at height z0 < 0)
// Urena's angles between the planes through x and the edges are gamma_i = pi/2 + asin(t_i),
// so S = sum(gamma_i) - 2 pi = sum(asin(t_i)). The sums asin(t0) + asin(t1) (the edge
// x = x1) and asin(t2) + asin(t3) (the edge x = x0) are each one atan2 whose arguments,
// after dropping a common positive factor, need only the local coordinates and the
// distances R to the four corners:
//   asin t0 + asin t1 = atan2(|z0| x1 (y1 R(x1,y0) - y0 R(x1,y1)), z0^2 R(x1,y0) R(x1,y1) + x1^2 y0 y1)
//   asin t2 + asin t3 = atan2(|z0| x0 (y0 R(x0,y1) - y1 R(x0,y0)), z0^2 R(x0,y0) R(x0,y1) + x0^2 y0 y1)
// (the products (c0 + i t0)(c1 + i t1) with t0 = -y0 x1 / (m0 m1), c0 = |z0| R(x1,y0) / (m0 m1),
// m_i the lengths of the edge planes' normals). The setup evaluates them divided by the two
// R's, as rsqrt gives 1 / R. No acos of a dot product and no 1 - t^2, so S keeps its
// relative precision when the rectangle is small and straight ahead.
template <class T> struct SphericalRectangle {
  Vec3<T> ex, ey, ez;  // local frame, ez towards the rectangle's side opposite x
  T x0, x1, y0, y1, z0;  // corners in the local frame (z0 <= 0)
  T b0, b1, k_sin_off;   // Urena's b0, b1, and asin(t2) + asin(t3)
  T c0;                  // 1 - b0^2 = z0^2 / (z0^2 + y0^2)
  T omega;
  mask_t<T> valid;
};

// Setup from the unit edge directions ex = e1 / |e1|, ey = e2 / |e2| and the edge lengths
// (a source's constants, made once per light by the renderer).
template <class T>
inline SphericalRectangle<T> spherical_rectangle_setup_unit(const Vec3<T>& x, const Vec3<T>& p0, const Vec3<T>& ex,
                                                            const Vec3<T>& ey, const T& lx, const T& ly) noexcept {
  SphericalRectangle<T> r;
  const mask_t<T> ok_e = lx > T(0.f) && ly > T(0.f) && is_finite(lx) && is_finite(ly);
  r.ex = ex;
  r.ey = ey;
  r.ez = cross(r.ex, r.ey);
  const Vec3<T> d = p0 - x;
  const T zd = dot(d, r.ez);
  const mask_t<T> flip = zd > T(0.f);
  r.ez = sel(flip, -r.ez, r.ez);
  r.z0 = -abs(zd);
  r.x0 = dot(d, r.ex);
  r.y0 = dot(d, r.ey);
  r.x1 = r.x0 + lx;
  r.y1 = r.y0 + ly;
  const T z2 = r.z0 * r.z0;
  // The inverse distances to the corners, and the atan2 arguments above divided by their
  // two R's (so they scale as length^2, like the squares here). Where z0 < 0 every q > 0;
  // elsewhere, or where a q overflows, S comes out 0 or NaN and the lane is invalid.
  const T zx0 = mul_add(r.x0, r.x0, z2), zx1 = mul_add(r.x1, r.x1, z2);
  const T y00 = r.y0 * r.y0, y11 = r.y1 * r.y1;
  const T p00 = rsqrt_nr(zx0 + y00), p01 = rsqrt_nr(zx0 + y11), p10 = rsqrt_nr(zx1 + y00), p11 = rsqrt_nr(zx1 + y11);
  const T az = -r.z0, yy = r.y0 * r.y1;
  const T a01 = lane_math::atan2(az * r.x1 * (r.y1 * p11 - r.y0 * p10), mul_add(r.x1 * r.x1 * yy, p10 * p11, z2));
  const T a23 = lane_math::atan2(az * r.x0 * (r.y0 * p00 - r.y1 * p01), mul_add(r.x0 * r.x0 * yy, p00 * p01, z2));
  // b0 = -y0 / m0, b1 = y1 / m2 with m0^2 = z0^2 + y0^2, m2^2 = z0^2 + y1^2
  const T i0 = rsqrt_nr(z2 + y00), i2 = rsqrt_nr(z2 + y11);
  r.b0 = -r.y0 * i0;
  r.b1 = r.y1 * i2;
  r.c0 = z2 * (i0 * i0);
  r.k_sin_off = a23;
  r.omega = a01 + a23;
  r.valid = ok_e && r.z0 < T(0.f) && r.omega > T(0.f) && is_finite(r.omega);
  r.omega = sel(r.valid, r.omega, T(0.f));
  return r;
}

// Setup from the edges themselves.
template <class T>
inline SphericalRectangle<T> spherical_rectangle_setup(const Vec3<T>& x, const Vec3<T>& p0, const Vec3<T>& e1,
                                                       const Vec3<T>& e2) noexcept {
  const T lx = length(e1), ly = length(e2);
  const mask_t<T> ok = lx > T(0.f) && ly > T(0.f);
  return spherical_rectangle_setup_unit(x, p0, e1 * (T(1.f) / sel(ok, lx, T(1.f))), e2 * (T(1.f) / sel(ok, ly, T(1.f))),
                                        lx, ly);
}

template <class T>
inline T spherical_rectangle_solid_angle(const Vec3<T>& x, const Vec3<T>& p0, const Vec3<T>& e1,
                                         const Vec3<T>& e2) noexcept {
  return spherical_rectangle_setup(x, p0, e1, e2).omega;
}

// Urena's map for a prepared rectangle: the unit direction and the distance from x to the
// point it reaches on the rectangle (the local point (xu, yv, z0) is known, so no plane
// intersection is needed). The density is 1 / r.omega. Every output is finite wherever
// r.valid holds: xu and yv are clamped to the rectangle, so every distance is at most the
// farthest corner's, which the setup found finite.
template <class T>
inline mask_t<T> sample_spherical_rectangle(const SphericalRectangle<T>& r, const T& u1, const T& u2, Vec3<T>& dir,
                                            T& dist_y) noexcept {
  using namespace sampling_detail;
  // Urena's au = u1 S + k with k = 2 pi - gamma2 - gamma3 = pi - (asin t2 + asin t3), so
  // sin(au) = sin(psi), cos(au) = -cos(psi) with psi = asin t2 + asin t3 - u1 S.
  const T psi = r.k_sin_off - u1 * r.omega;
  T sp, cp;
  lane_math::sincos(psi, sp, cp);
  // fu = (cos(au) b0 - b1) / sin(au), cu = sign(fu) / sqrt(fu^2 + b0^2) and
  // xu = -cu z0 / sqrt(1 - cu^2). With N = -cos(psi) b0 - b1 and D = sin(psi) (fu = N / D),
  // cu = sign(N) D / sqrt(N^2 + b0^2 D^2) and 1 - cu^2 = (N^2 - (1 - b0^2) D^2) / (N^2 + b0^2 D^2),
  // so xu = -sign(N) D z0 / sqrt(N^2 - (1 - b0^2) D^2): one square root, no division.
  // Where rounding leaves no room under the root, xu is beyond the rectangle and clamped.
  const T n = mul_add(-cp, r.b0, -r.b1);
  const T den = mul_add(-r.c0 * sp, sp, n * n);
  const T sd = sel(n < T(0.f), -sp, sp);
  const T xu = min(max(-(sd * r.z0) * rsqrt_nr(max(den, T(1e-30f))), r.x0), r.x1);
  const T dist2 = mul_add(xu, xu, r.z0 * r.z0);  // in [z0^2, farthest corner^2] where r.valid
  const T dist2s = sel(r.valid, dist2, T(1.f));
  const T id = rsqrt_nr(dist2s);
  const T dist = dist2s * id;
  const T q1 = mul_add(r.y1, r.y1, dist2s);
  const T i0 = rsqrt_nr(mul_add(r.y0, r.y0, dist2s)), i1 = rsqrt_nr(q1);
  const T h0 = r.y0 * i0, h1 = r.y1 * i1;
  const T hv = mul_add(u2, h1 - h0, h0);
  // yv = hv dist / sqrt(1 - hv^2), and the distance to (xu, yv, z0) is dist / sqrt(1 - hv^2)
  const T w = T(1.f) - hv * hv;
  const mask_t<T> inner = w > T(1e-6f);
  const T s = rsqrt_nr(sel(inner, w, T(1.f)));
  const T yc = sel(inner, min(max(hv * dist * s, r.y0), r.y1), r.y1);
  // 1 / |(xu, yc, z0)|: from the map where inner, else the root of q1 = |(xu, y1, z0)|^2
  const T il = sel(inner, id * w * s, i1);
  const Vec3<T> v = r.ex * xu + r.ey * yc + r.ez * r.z0;
  dir = sel(r.valid, v * il, Vec3<T>(T(0.f), T(0.f), T(1.f)));
  dist_y = sel(r.valid, sel(inner, dist * s, q1 * i1), T(0.f));
  return r.valid;
}

template <class T>
inline mask_t<T> sample_spherical_rectangle(const Vec3<T>& x, const Vec3<T>& p0, const Vec3<T>& e1, const Vec3<T>& e2,
                                            const T& u1, const T& u2, Vec3<T>& dir, T& pdf_sa) noexcept {
  const SphericalRectangle<T> r = spherical_rectangle_setup(x, p0, e1, e2);
  T dist;
  const mask_t<T> valid = sample_spherical_rectangle(r, u1, u2, dir, dist);
  pdf_sa = sel(valid, T(1.f) / sel(r.omega > T(0.f), r.omega, T(1.f)), T(0.f));
  return valid;
}

// Parallelograms with non-orthogonal edges: two triangles (p0, p0+e1, p0+e1+e2) and
// (p0, p0+e1+e2, p0+e2), one picked with probability proportional to its solid angle, then
// Arvo's map; pdf_sa = 1 / (Omega1 + Omega2).
template <class T>
inline T spherical_parallelogram_solid_angle(const Vec3<T>& x, const Vec3<T>& p0, const Vec3<T>& e1,
                                             const Vec3<T>& e2) noexcept {
  const Vec3<T> p1 = p0 + e1, p2 = p1 + e2, p3 = p0 + e2;
  return spherical_triangle_solid_angle(x, p0, p1, p2) + spherical_triangle_solid_angle(x, p0, p2, p3);
}

template <class T>
inline mask_t<T> sample_spherical_parallelogram(const Vec3<T>& x, const Vec3<T>& p0, const Vec3<T>& e1,
                                                const Vec3<T>& e2, const T& u1, const T& u2, Vec3<T>& dir,
                                                T& pdf_sa) noexcept {
  using namespace sampling_detail;
  const Vec3<T> p1 = p0 + e1, p2 = p1 + e2, p3 = p0 + e2;
  const SphericalTriangle<T> s1 = spherical_triangle_setup(x, p0, p1, p2);
  const SphericalTriangle<T> s2 = spherical_triangle_setup(x, p0, p2, p3);
  const T total = s1.omega + s2.omega;
  const mask_t<T> ok = total > T(0.f);
  const T itot = T(1.f) / sel(ok, total, T(1.f));
  const T p_first = s1.omega * itot;
  const mask_t<T> first = u1 < p_first;
  // Reuse u1: rescale its part of [0,1) to [0,1).
  const T lo = sel(first, T(0.f), p_first);
  const T width = sel(first, p_first, T(1.f) - p_first);
  const T u1r = min((u1 - lo) / sel(width > T(0.f), width, T(1.f)), T(0x1.fffffep-1f));
  const mask_t<T> valid = sample_spherical_triangle(sel(first, s1, s2), u1r, u2, dir, pdf_sa);
  pdf_sa = itot;
  return finish(valid && ok, dir, pdf_sa, Vec3<T>(T(0.f), T(0.f), T(1.f)));
}

// Edges count as orthogonal (and use Urena's map) when |cos(e1, e2)| <= this.
inline constexpr float rectangle_orthogonality_tolerance = 1e-5f;

template <class T> inline mask_t<T> parallelogram_is_rectangle(const Vec3<T>& e1, const Vec3<T>& e2) noexcept {
  return abs(dot(e1, e2)) <= T(rectangle_orthogonality_tolerance) * length(e1) * length(e2);
}

// Standalone entry points for a parallelogram given only its edges: Urena where the edges
// are orthogonal, two triangles otherwise. The renderer applies the same rule through its
// per-source constants instead (LightGeom::rect from parallelogram_is_rectangle, lights.h).
template <class T>
inline T parallelogram_solid_angle(const Vec3<T>& x, const Vec3<T>& p0, const Vec3<T>& e1, const Vec3<T>& e2) noexcept {
  const mask_t<T> rect = parallelogram_is_rectangle(e1, e2);
  T omega_r(0.f), omega_p(0.f);
  if (any(rect)) omega_r = spherical_rectangle_solid_angle(x, p0, e1, e2);
  if (!all(rect)) omega_p = spherical_parallelogram_solid_angle(x, p0, e1, e2);
  return sel(rect, omega_r, omega_p);
}

template <class T>
inline T pdf_parallelogram_sa(const Vec3<T>& x, const Vec3<T>& p0, const Vec3<T>& e1, const Vec3<T>& e2) noexcept {
  const T omega = parallelogram_solid_angle(x, p0, e1, e2);
  return sel(omega > T(0.f), T(1.f) / sel(omega > T(0.f), omega, T(1.f)), T(0.f));
}

template <class T>
inline mask_t<T> sample_parallelogram_sa(const Vec3<T>& x, const Vec3<T>& p0, const Vec3<T>& e1, const Vec3<T>& e2,
                                         const T& u1, const T& u2, Vec3<T>& dir, T& pdf_sa) noexcept {
  const mask_t<T> rect = parallelogram_is_rectangle(e1, e2);
  Vec3<T> dr(T(0.f), T(0.f), T(1.f)), dp(T(0.f), T(0.f), T(1.f));
  T pr(0.f), pp(0.f);
  mask_t<T> vr = rect, vp = !rect;
  if (any(rect)) vr = sample_spherical_rectangle(x, p0, e1, e2, u1, u2, dr, pr);
  if (!all(rect)) vp = sample_spherical_parallelogram(x, p0, e1, e2, u1, u2, dp, pp);
  dir = sel(rect, dr, dp);
  pdf_sa = sel(rect, pr, pp);
  return (rect && vr) || (!rect && vp);
}

// ---------------------------------------------------------------------------------------
// 5. Spheres.
//
// Cone of directions from x towards a sphere: 1 - cos(theta_max) is computed as
// sin^2 / (1 + cos) so that tiny, distant spheres keep their solid angle.
template <class T>
inline T sphere_cone_one_minus_cos(const Vec3<T>& x, const Vec3<T>& center, const T& radius, mask_t<T>& outside) noexcept {
  const Vec3<T> d = center - x;
  const T dist2 = dot(d, d);
  const T r2 = radius * radius;
  outside = dist2 > r2 && is_finite(dist2) && radius > T(0.f);
  const T sin2 = min(r2 / sel(outside, dist2, T(1.f)), T(1.f));
  const T cos_max = sqrt(T(1.f) - sin2);
  return sel(outside, sin2 / (T(1.f) + cos_max), T(0.f));
}

template <class T> inline T sphere_cone_solid_angle(const Vec3<T>& x, const Vec3<T>& center, const T& radius) noexcept {
  mask_t<T> outside;
  return T(two_pi_f) * sphere_cone_one_minus_cos(x, center, radius, outside);
}

// 1 / Omega of the cone, 0 when x is inside the sphere (the caller checks the direction hits it).
template <class T> inline T pdf_sphere_cone(const Vec3<T>& x, const Vec3<T>& center, const T& radius) noexcept {
  const T omega = sphere_cone_solid_angle(x, center, radius);
  return sel(omega > T(0.f), T(1.f) / sel(omega > T(0.f), omega, T(1.f)), T(0.f));
}

template <class T>
inline mask_t<T> sample_sphere_cone(const Vec3<T>& x, const Vec3<T>& center, const T& radius, const T& u1, const T& u2,
                                    Vec3<T>& dir, T& pdf_sa) noexcept {
  using namespace sampling_detail;
  mask_t<T> outside;
  const T omc_max = sphere_cone_one_minus_cos(x, center, radius, outside);
  const Vec3<T> w = normalize_or(center - x, Vec3<T>(T(0.f), T(0.f), T(1.f)));
  Vec3<T> t, b;
  make_basis(w, t, b);
  const T omc = u1 * omc_max;
  const T cos_t = T(1.f) - omc;
  const T sin_t = safe_sqrt(omc * (T(2.f) - omc));
  T sp, cp;
  lane_math::sincos_2pi(u2, sp, cp);
  dir = normalize_or(t * (sin_t * cp) + b * (sin_t * sp) + w * cos_t, w);
  const T omega = T(two_pi_f) * omc_max;
  pdf_sa = T(1.f) / sel(omega > T(0.f), omega, T(1.f));
  return finish(outside && omega > T(0.f), dir, pdf_sa, w);
}

// Uniform point on the sphere's surface; pdf_area = 1 / (4 pi r^2).
template <class T> inline Vec3<T> sample_sphere_area(const Vec3<T>& center, const T& radius, const T& u1, const T& u2) noexcept {
  const T z = T(1.f) - T(2.f) * u1;
  const T rxy = T(2.f) * sampling_detail::safe_sqrt(u1 * (T(1.f) - u1));
  T sp, cp;
  lane_math::sincos_2pi(u2, sp, cp);
  return center + Vec3<T>(rxy * cp, rxy * sp, z) * radius;
}

template <class T> inline T pdf_sphere_area(const T& radius) noexcept {
  const T a = radius * radius;
  return sel(a > T(0.f), T(inv_four_pi_f) / sel(a > T(0.f), a, T(1.f)), T(0.f));
}

} // namespace tuile

// Directions uniform in the solid angle a polygon subtends: spherical triangles (Arvo
// 1995, rewritten in half-angle form for precision; solid angle by Van Oosterom &
// Strackee 1983), spherical rectangles (Urena, Fajardo & King 2013) and parallelograms
// (two triangles), each with its solid angle and density.
// Lane-generic like sample/sampling.h: masks, not branches; finite outputs for finite
// inputs, invalid samples flagged with a harmless direction and pdf 0.
#pragma once
#include "sample/sampling.h"

namespace tuile {

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

}  // namespace tuile

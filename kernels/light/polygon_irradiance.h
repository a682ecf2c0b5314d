// Exact irradiance from a uniformly emitting polygon (Lambert 1760; the contour-integral form
// of the point-to-polygon form factor, e.g. Baum, Rushmeier & Winget 1989), for exact-answer
// tests of the renderer. Double precision, scalar only; no allocation.
//
// For a receiver at x with unit normal n and a polygon of constant radiance L,
//   E = L * integral over the polygon's solid angle of cos(theta) d omega
//     = L * (1/2) * | sum_i Theta_i (n . unit(R_i x R_(i+1))) |,
// R_i = v_i - x, Theta_i = angle between R_i and R_(i+1). polygon_form_factor_irradiance
// returns E / L (in sr; the form factor is E / (pi L)). The outgoing radiance of a Lambertian
// receiver of albedo rho is then rho / pi * E.
//
// polygon_form_factor_irradiance assumes the polygon is planar, simple, either winding, and
// does not cross the tangent plane of x (every vertex has n . (v - x) >= 0). Polygons that
// cross it are handled by polygon_irradiance_clipped, which first clips them against the
// half-space n . (p - x) >= 0 (Sutherland-Hodgman).
#pragma once
#include <cmath>

namespace tuile {

inline constexpr int polygon_max_vertices = 64;

// E / L for a polygon fully above the tangent plane of x. verts holds count points (xyz).
inline double polygon_form_factor_irradiance(const double x[3], const double n[3], const double* verts,
                                             int count) noexcept {
  double sum = 0.0;
  for (int i = 0; i < count; ++i) {
    const double* p = verts + 3 * i;
    const double* q = verts + 3 * ((i + 1) % count);
    const double a[3] = {p[0] - x[0], p[1] - x[1], p[2] - x[2]};
    const double b[3] = {q[0] - x[0], q[1] - x[1], q[2] - x[2]};
    const double c[3] = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
    const double lc = std::sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
    if (!(lc > 0.0)) continue;  // collinear with x: the edge subtends no angle
    const double theta = std::atan2(lc, a[0] * b[0] + a[1] * b[1] + a[2] * b[2]);
    sum += theta * (n[0] * c[0] + n[1] * c[1] + n[2] * c[2]) / lc;
  }
  return 0.5 * std::fabs(sum);
}

// Sutherland-Hodgman clip of a polygon against n . (p - x) >= 0. out must hold
// 3 * 2 * count doubles (count + 1 vertices suffice for a convex polygon); returns the number
// of vertices written (0 when the polygon lies fully below the plane).
inline int clip_polygon_to_halfspace(const double x[3], const double n[3], const double* verts, int count,
                                     double* out) noexcept {
  int m = 0;
  for (int i = 0; i < count; ++i) {
    const double* p = verts + 3 * i;
    const double* q = verts + 3 * ((i + 1) % count);
    const double dp = n[0] * (p[0] - x[0]) + n[1] * (p[1] - x[1]) + n[2] * (p[2] - x[2]);
    const double dq = n[0] * (q[0] - x[0]) + n[1] * (q[1] - x[1]) + n[2] * (q[2] - x[2]);
    if (dp >= 0.0) {
      for (int k = 0; k < 3; ++k) out[3 * m + k] = p[k];
      ++m;
    }
    if ((dp >= 0.0) != (dq >= 0.0)) {
      const double t = dp / (dp - dq);
      for (int k = 0; k < 3; ++k) out[3 * m + k] = p[k] + t * (q[k] - p[k]);
      ++m;
    }
  }
  return m;
}

// E / L for any planar polygon of at most polygon_max_vertices vertices (more are ignored),
// counting only the part above the tangent plane of x.
inline double polygon_irradiance_clipped(const double x[3], const double n[3], const double* verts,
                                         int count) noexcept {
  if (count > polygon_max_vertices) count = polygon_max_vertices;
  double clipped[3 * 2 * polygon_max_vertices];
  const int m = clip_polygon_to_halfspace(x, n, verts, count, clipped);
  return m >= 3 ? polygon_form_factor_irradiance(x, n, clipped, m) : 0.0;
}

} // namespace tuile

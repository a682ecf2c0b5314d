// Private helpers of the pbrt-v4 reader: 4x4 transforms, whole-file reads (plain or
// gzip), and the error format every message follows.
#pragma once
#include <cmath>
#include <string>
#include <string_view>

#include "scene/scene.h"

namespace tuile::pbrt {

// "FILE:LINE:COL: error: MESSAGE (expected EXPECTED)"
[[noreturn]] void fail(const std::string& file, int line, int col, const std::string& message,
                       const std::string& expected);

// Reads a whole file into memory; gunzips it when the name ends in .gz or the data
// starts with the gzip magic. Returns false with a reason when it cannot.
bool read_file(const std::string& path, std::string& out, std::string& reason);

// Joins a relative file name to a directory ("" = current directory).
std::string resolve_path(const std::string& base_dir, const std::string& name);
std::string parent_dir(const std::string& path);

// Row-major 4x4 matrix in double: p' = m * p.
struct Mat4 {
  double m[4][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}};
  static Mat4 identity() { return {}; }
  bool is_identity() const {
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j)
        if (m[i][j] != (i == j ? 1.0 : 0.0)) return false;
    return true;
  }
  double det3() const {
    return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
           m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
           m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
  }
  bool swaps_handedness() const { return det3() < 0; }
  bool is_affine() const { return m[3][0] == 0 && m[3][1] == 0 && m[3][2] == 0 && m[3][3] == 1; }
};

Mat4 operator*(const Mat4& a, const Mat4& b);
// General inverse; returns false when the matrix is singular or not finite.
bool invert(const Mat4& a, Mat4& out);
Mat4 transpose(const Mat4& a);
Mat4 translate(double x, double y, double z);
Mat4 scale(double x, double y, double z);
// Rotation by angle (degrees) about an axis; the axis must be non-zero.
Mat4 rotate(double angle_deg, double x, double y, double z);

struct Vec3d {
  double x = 0, y = 0, z = 0;
};
inline Vec3d sub(Vec3d a, Vec3d b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline Vec3d cross(Vec3d a, Vec3d b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double dot(Vec3d a, Vec3d b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline double length(Vec3d a) { return std::sqrt(dot(a, a)); }
inline Vec3d normalized(Vec3d a) {
  const double l = length(a);
  return l > 0 ? Vec3d{a.x / l, a.y / l, a.z / l} : a;
}

inline Vec3d apply_point(const Mat4& t, Vec3d p) {
  const auto& m = t.m;
  Vec3d r{m[0][0] * p.x + m[0][1] * p.y + m[0][2] * p.z + m[0][3],
          m[1][0] * p.x + m[1][1] * p.y + m[1][2] * p.z + m[1][3],
          m[2][0] * p.x + m[2][1] * p.y + m[2][2] * p.z + m[2][3]};
  const double w = m[3][0] * p.x + m[3][1] * p.y + m[3][2] * p.z + m[3][3];
  if (w != 1 && w != 0) r = {r.x / w, r.y / w, r.z / w};
  return r;
}
inline Vec3d apply_vector(const Mat4& t, Vec3d v) {
  const auto& m = t.m;
  return {m[0][0] * v.x + m[0][1] * v.y + m[0][2] * v.z, m[1][0] * v.x + m[1][1] * v.y + m[1][2] * v.z,
          m[2][0] * v.x + m[2][1] * v.y + m[2][2] * v.z};
}
// Normals transform by the inverse transpose: pass the inverse matrix.
inline Vec3d apply_normal_inv(const Mat4& inv, Vec3d n) {
  const auto& m = inv.m;
  return {m[0][0] * n.x + m[1][0] * n.y + m[2][0] * n.z, m[0][1] * n.x + m[1][1] * n.y + m[2][1] * n.z,
          m[0][2] * n.x + m[1][2] * n.y + m[2][2] * n.z};
}

// Transforms packed xyz floats in place (identity is skipped).
void transform_positions(const Mat4& t, float* xyz, size_t count);


// Colour from spectra, normalised like pbrt-v4: an emission spectrum to luminance 1.
Rgb blackbody_rgb(double kelvin);
// Piecewise-linear spectrum given as (lambda nm, value) pairs. emission: normalised to
// luminance 1; otherwise a reflectance (a constant 1 maps to white).
Rgb sampled_spectrum_rgb(const double* pairs, size_t count, bool emission);
// An unbounded spectrum (a refractive index eta or an absorption k), given as (lambda nm,
// value) pairs, piecewise linear and clamped to its end values, as linear sRGB: weighted
// by D65 and the CIE 1931 matching functions, XYZ to linear sRGB, each channel divided by
// that of the constant 1, so a constant c maps to (c, c, c). Linear in the spectrum; the
// sRGB matching functions have negative lobes, so a channel may leave the spectrum's range
// (copper's red eta is below its smallest value) -- chosen because the normal-incidence
// Fresnel reflectance of the RGB eta/k then matches the RGB of pbrt's spectral one within
// about 0.01 for Cu, Ag, Al (0.05 for Au's out-of-gamut red). Callers clamp.
Rgb unbounded_spectrum_rgb(const double* pairs, size_t count);
// The same spectrum's value at lambda nm (piecewise linear, clamped to its end values).
double spectrum_at(const double* pairs, size_t count, double lambda);

// The mean of an image texture's texels (a reflectance texture used where tuile takes a
// constant), and of a float texture's.
inline Rgb average(const Texture& t) {
  double s[3] = {0, 0, 0};
  const size_t n = size_t(t.width) * t.height;
  for (size_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) s[c] += t.rgb[3 * i + c];
  return n ? Rgb{float(s[0] / n), float(s[1] / n), float(s[2] / n)} : Rgb{};
}
inline float average(const FloatTexture& t) {
  double s = 0;
  for (float v : t.value) s += v;
  return t.value.empty() ? 0.f : float(s / double(t.value.size()));
}

}  // namespace tuile::pbrt

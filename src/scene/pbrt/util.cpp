// The pbrt-v4 reader's helpers: transforms, file reading (gzip too), error messages.
#include "util.h"

#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>

namespace tuile::pbrt {

// Control characters of a message (a NUL or a newline the file put in a name it quotes) as
// \xNN: what() is a C string, which a NUL would cut short, and the message stays one line.
static std::string printable(const std::string& s) {
  std::string out;
  out.reserve(s.size());
  for (const char c : s) {
    const unsigned char u = static_cast<unsigned char>(c);
    if (u < 0x20 || u == 0x7f) {
      static const char hex[] = "0123456789abcdef";
      out += "\\x";
      out += hex[u >> 4];
      out += hex[u & 15];
    } else {
      out += c;
    }
  }
  return out;
}

void fail(const std::string& file, int line, int col, const std::string& message, const std::string& expected) {
  throw SceneError(printable(file + ":" + std::to_string(line) + ":" + std::to_string(col) + ": error: " + message +
                             " (expected " + expected + ")"));
}

static bool ends_with(const std::string& s, std::string_view suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

static bool read_gzip(const std::string& path, std::string& out, std::string& reason) {
  gzFile f = gzopen(path.c_str(), "rb");
  if (!f) {
    reason = std::strerror(errno ? errno : ENOENT);
    return false;
  }
  gzbuffer(f, 1 << 17);
  out.clear();
  size_t used = 0;
  constexpr size_t chunk = size_t(1) << 22;
  constexpr size_t limit = size_t(1) << 34;  // 16 GiB: refuse decompression bombs
  for (;;) {
    if (out.size() < used + chunk) out.resize(used + chunk);
    const int n = gzread(f, out.data() + used, unsigned(chunk));
    if (n < 0) {
      int code = 0;
      reason = std::string("gzip data is corrupt: ") + gzerror(f, &code);
      gzclose(f);
      return false;
    }
    used += size_t(n);
    if (n == 0) {
      int code = 0;
      gzerror(f, &code);
      if (code == Z_BUF_ERROR) {  // (zlib: the input ended inside a gzip stream)
        reason = "gzip data cut short (the file ends inside its compressed stream)";
        gzclose(f);
        return false;
      }
      break;
    }
    if (used > limit) {
      reason = "decompressed size exceeds 16 GiB";
      gzclose(f);
      return false;
    }
  }
  gzclose(f);
  out.resize(used);
  return true;
}

bool read_file(const std::string& path, std::string& out, std::string& reason) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    reason = "it is a directory";
    return false;
  }
  // a device (/dev/zero, /dev/urandom) never ends and a named pipe without a writer never
  // opens: refused; the standard input or a shell's process substitution (/dev/fd/N) is
  // read, up to the limit below
  const auto kind = std::filesystem::status(path, ec).type();
  const bool stream = path == "/dev/stdin" || path.rfind("/dev/fd/", 0) == 0 || path.rfind("/proc/self/fd/", 0) == 0;
  if (!stream && (kind == std::filesystem::file_type::character || kind == std::filesystem::file_type::block)) {
    reason = "it is a device, not a file";
    return false;
  }
  if (!stream && kind != std::filesystem::file_type::regular && kind != std::filesystem::file_type::not_found &&
      kind != std::filesystem::file_type::none) {
    reason = "it is not a regular file (a pipe or a socket)";
    return false;
  }
  if (ends_with(path, ".gz")) return read_gzip(path, out, reason);
  FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) {
    reason = std::strerror(errno);
    return false;
  }
  out.clear();
  if (std::fseek(f, 0, SEEK_END) == 0) {
    const long size = std::ftell(f);
    if (size > 0) out.resize(size_t(size));
    std::fseek(f, 0, SEEK_SET);
  }
  size_t got = out.empty() ? 0 : std::fread(out.data(), 1, out.size(), f);
  if (got < out.size()) out.resize(got);
  // Streams whose size is unknown: read the rest in chunks, up to 4 GiB.
  char buf[1 << 16];
  for (size_t n; (n = std::fread(buf, 1, sizeof buf, f)) > 0;) {
    out.append(buf, n);
    if (out.size() > (size_t(1) << 32)) {
      std::fclose(f);
      out.clear();
      reason = "the stream is longer than 4 GiB";
      return false;
    }
  }
  const bool bad = std::ferror(f);
  std::fclose(f);
  if (bad) {
    reason = "read error";
    return false;
  }
  if (out.size() >= 2 && uint8_t(out[0]) == 0x1f && uint8_t(out[1]) == 0x8b) return read_gzip(path, out, reason);
  return true;
}

std::string resolve_path(const std::string& base_dir, const std::string& name) {
  std::filesystem::path p(name);
  if (p.is_absolute() || base_dir.empty()) return name;
  return (std::filesystem::path(base_dir) / p).string();
}

std::string parent_dir(const std::string& path) { return std::filesystem::path(path).parent_path().string(); }

Mat4 operator*(const Mat4& a, const Mat4& b) {
  Mat4 r;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) {
      double s = 0;
      for (int k = 0; k < 4; ++k) s += a.m[i][k] * b.m[k][j];
      r.m[i][j] = s;
    }
  return r;
}

Mat4 transpose(const Mat4& a) {
  Mat4 r;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) r.m[i][j] = a.m[j][i];
  return r;
}

// Gauss-Jordan elimination with partial pivoting.
bool invert(const Mat4& a, Mat4& out) {
  double w[4][8];
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) {
      if (!std::isfinite(a.m[i][j])) return false;
      w[i][j] = a.m[i][j];
      w[i][j + 4] = i == j ? 1 : 0;
    }
  for (int c = 0; c < 4; ++c) {
    int piv = c;
    for (int r = c + 1; r < 4; ++r)
      if (std::abs(w[r][c]) > std::abs(w[piv][c])) piv = r;
    if (w[piv][c] == 0) return false;
    if (piv != c)
      for (int j = 0; j < 8; ++j) std::swap(w[c][j], w[piv][j]);
    const double inv = 1 / w[c][c];
    for (int j = 0; j < 8; ++j) w[c][j] *= inv;
    for (int r = 0; r < 4; ++r) {
      if (r == c || w[r][c] == 0) continue;
      const double f = w[r][c];
      for (int j = 0; j < 8; ++j) w[r][j] -= f * w[c][j];
    }
  }
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) {
      out.m[i][j] = w[i][j + 4];
      if (!std::isfinite(out.m[i][j])) return false;
    }
  return true;
}

Mat4 translate(double x, double y, double z) {
  Mat4 r;
  r.m[0][3] = x;
  r.m[1][3] = y;
  r.m[2][3] = z;
  return r;
}

Mat4 scale(double x, double y, double z) {
  Mat4 r;
  r.m[0][0] = x;
  r.m[1][1] = y;
  r.m[2][2] = z;
  return r;
}

Mat4 rotate(double angle_deg, double x, double y, double z) {
  const Vec3d a = normalized({x, y, z});
  const double th = angle_deg * (M_PI / 180.0);
  const double s = std::sin(th), c = std::cos(th), t = 1 - c;
  Mat4 r;
  r.m[0][0] = a.x * a.x * t + c;
  r.m[0][1] = a.x * a.y * t - a.z * s;
  r.m[0][2] = a.x * a.z * t + a.y * s;
  r.m[1][0] = a.x * a.y * t + a.z * s;
  r.m[1][1] = a.y * a.y * t + c;
  r.m[1][2] = a.y * a.z * t - a.x * s;
  r.m[2][0] = a.x * a.z * t - a.y * s;
  r.m[2][1] = a.y * a.z * t + a.x * s;
  r.m[2][2] = a.z * a.z * t + c;
  return r;
}

void transform_positions(const Mat4& t, float* xyz, size_t count) {
  if (t.is_identity()) return;
  for (size_t i = 0; i < count; ++i) {
    float* p = xyz + 3 * i;
    const Vec3d q = apply_point(t, {p[0], p[1], p[2]});
    p[0] = float(q.x);
    p[1] = float(q.y);
    p[2] = float(q.z);
  }
}

// CIE 1931 colour matching functions: the multi-lobe Gaussian fit of Wyman, Sloan and
// Shirley, "Simple Analytic Approximations to the CIE XYZ Color Matching Functions"
// (JCGT 2013).
static double lobe(double l, double mu, double s1, double s2) {
  const double t = (l - mu) / (l < mu ? s1 : s2);
  return std::exp(-0.5 * t * t);
}
static void cmf(double l, double& x, double& y, double& z) {
  x = 1.056 * lobe(l, 599.8, 37.9, 31.0) + 0.362 * lobe(l, 442.0, 16.0, 26.7) - 0.065 * lobe(l, 501.1, 20.4, 26.2);
  y = 0.821 * lobe(l, 568.8, 46.9, 40.5) + 0.286 * lobe(l, 530.9, 16.3, 31.1);
  z = 1.217 * lobe(l, 437.0, 11.8, 36.0) + 0.681 * lobe(l, 459.0, 26.0, 13.8);
}

static Rgb xyz_to_srgb(double x, double y, double z) {
  return {float(3.2404542 * x - 1.5371385 * y - 0.4985314 * z), float(-0.9692660 * x + 1.8760108 * y + 0.0415560 * z),
          float(0.0556434 * x - 0.2040259 * y + 1.0572252 * z)};
}

template <class F> static void integrate_xyz(F&& spectrum, double& X, double& Y, double& Z) {
  X = Y = Z = 0;
  for (double l = 360; l <= 830; l += 1) {
    double x, y, z;
    cmf(l, x, y, z);
    const double s = spectrum(l);
    X += s * x;
    Y += s * y;
    Z += s * z;
  }
}

static Rgb clamp_positive(Rgb c) { return {std::max(c.r, 0.f), std::max(c.g, 0.f), std::max(c.b, 0.f)}; }

Rgb blackbody_rgb(double kelvin) {
  if (!(kelvin > 0)) return {0, 0, 0};
  const double c = 299792458.0, h = 6.62606957e-34, kb = 1.3806488e-23;
  auto planck = [&](double l_nm) {
    const double l = l_nm * 1e-9;
    return (2 * h * c * c) / (std::pow(l, 5) * (std::exp((h * c) / (l * kb * kelvin)) - 1));
  };
  double X, Y, Z;
  integrate_xyz(planck, X, Y, Z);
  if (!(Y > 0) || !std::isfinite(Y)) return {0, 0, 0};
  Rgb rgb = clamp_positive(xyz_to_srgb(X / Y, 1, Z / Y));
  const float lum = luminance(rgb);  // clamping moved it off 1 slightly
  if (lum > 0) rgb = {rgb.r / lum, rgb.g / lum, rgb.b / lum};
  return rgb;
}

double spectrum_at(const double* pairs, size_t count, double l) {
  if (count == 0) return 0.0;
  if (l <= pairs[0]) return pairs[1];
  for (size_t i = 0; i + 1 < count; ++i) {
    const double l0 = pairs[2 * i], l1 = pairs[2 * i + 2];
    if (l <= l1) {
      const double t = l1 > l0 ? (l - l0) / (l1 - l0) : 0;
      return pairs[2 * i + 1] * (1 - t) + pairs[2 * i + 3] * t;
    }
  }
  return pairs[2 * count - 1];
}

// CIE standard illuminant D65 at 10 nm from 360 to 830 nm (the 10 nm entries of pbrt-v4's
// CIE_Illum_D6500 table), linearly interpolated.
static double d65(double l) {
  static constexpr double table[48] = {
      46.6383, 52.0891, 49.9755, 54.6482, 82.7549, 91.486,  93.4318, 86.6823, 104.865, 117.008, 117.812, 114.861,
      115.923, 108.811, 109.354, 107.802, 104.79,  107.689, 104.405, 104.046, 100,     96.3342, 95.788,  88.6856,
      90.0062, 89.5991, 87.6987, 83.2886, 83.6992, 80.0268, 80.2146, 82.2778, 78.2842, 69.7213, 71.6091, 74.349,
      61.604,  69.8856, 75.087,  63.5927, 46.4182, 66.8054, 63.3828, 64.304,  59.4519, 51.959,  57.4406, 60.3125};
  const double x = std::clamp((l - 360) / 10, 0.0, 47.0);
  const int i = std::min(int(x), 46);
  const double t = x - i;
  return table[i] * (1 - t) + table[i + 1] * t;
}

Rgb unbounded_spectrum_rgb(const double* pairs, size_t count) {
  double X, Y, Z, wx, wy, wz;
  integrate_xyz([&](double l) { return d65(l) * spectrum_at(pairs, count, l); }, X, Y, Z);
  integrate_xyz([&](double l) { return d65(l); }, wx, wy, wz);
  auto row = [](int c, double x, double y, double z) {
    static constexpr double m[3][3] = {{3.2404542, -1.5371385, -0.4985314},
                                       {-0.9692660, 1.8760108, 0.0415560},
                                       {0.0556434, -0.2040259, 1.0572252}};
    return m[c][0] * x + m[c][1] * y + m[c][2] * z;
  };
  return {float(row(0, X, Y, Z) / row(0, wx, wy, wz)), float(row(1, X, Y, Z) / row(1, wx, wy, wz)),
          float(row(2, X, Y, Z) / row(2, wx, wy, wz))};
}

Rgb sampled_spectrum_rgb(const double* pairs, size_t count, bool emission) {
  auto eval = [&](double l) { return spectrum_at(pairs, count, l); };
  double X, Y, Z;
  integrate_xyz(eval, X, Y, Z);
  if (emission) {
    if (!(Y > 0)) return {0, 0, 0};
    Rgb rgb = clamp_positive(xyz_to_srgb(X / Y, 1, Z / Y));
    const float lum = luminance(rgb);
    return lum > 0 ? Rgb{rgb.r / lum, rgb.g / lum, rgb.b / lum} : rgb;
  }
  double wx, wy, wz;
  integrate_xyz([](double) { return 1.0; }, wx, wy, wz);
  const Rgb white = xyz_to_srgb(wx, wy, wz);
  const Rgb c = xyz_to_srgb(X, Y, Z);
  return clamp_positive({c.r / white.r, c.g / white.g, c.b / white.b});
}

}  // namespace tuile::pbrt

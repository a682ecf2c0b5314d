// Environment maps: reading (src/scene/sky_map.h), checks, and the two sampling
// distributions of light/sky_map.h.
#include "scene/sky_map.h"

#include <ImfChannelList.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <stb/stb_image.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <stdexcept>

#include "light/sky_map.h"
#include "scene/atomic_file.h"
#include "scene/huge_pages.h"
#include "scene/pbrt/image.h"

namespace tuile {

namespace {

bool ends_with_ci(const std::string& s, const char* suffix) {
  const size_t n = std::strlen(suffix);
  if (s.size() < n) return false;
  for (size_t i = 0; i < n; ++i)
    if (std::tolower(static_cast<unsigned char>(s[s.size() - n + i])) != suffix[i]) return false;
  return true;
}

// PFM: "PF" (RGB) or "Pf" (grey), width, height, scale (negative: little-endian), then
// rows of floats from the bottom row up.
bool read_pfm(const std::string& path, RgbImage& out, std::string& reason) {
  std::ifstream f(path, std::ios::binary);
  if (!f) {
    reason = "cannot open the file";
    return false;
  }
  std::string magic;
  long w = 0, h = 0;
  double scale = 0;
  if (!(f >> magic >> w >> h >> scale) || (magic != "PF" && magic != "Pf")) {
    reason = "not a PFM file (expected a header \"PF width height scale\")";
    return false;
  }
  if (magic == "Pf") {
    reason = "a grey PFM (\"Pf\") has no R, G and B channels";
    return false;
  }
  if (w <= 0 || h <= 0 || w * h > (1l << 28) || scale == 0 || !std::isfinite(scale)) {
    reason = "PFM header has an unsupported size or scale (" + std::to_string(w) + " x " + std::to_string(h) + ")";
    return false;
  }
  f.get();  // the one whitespace character after the scale
  const size_t count = static_cast<size_t>(w) * static_cast<size_t>(h) * 3;
  std::vector<float> data;
  assign_huge(data, count, 0.f);
  // the file's first row is the image's bottom row: each row read straight into its place
  // (no second copy of the texels)
  const size_t row = static_cast<size_t>(w) * 3;
  size_t got = 0;
  for (long y = h - 1; y >= 0 && f; --y) {
    f.read(reinterpret_cast<char*>(&data[static_cast<size_t>(y) * row]), static_cast<std::streamsize>(row * sizeof(float)));
    got += static_cast<size_t>(f.gcount());
  }
  if (got != count * sizeof(float)) {
    reason = "PFM file is truncated (" + std::to_string(got) + " of " + std::to_string(count * sizeof(float)) +
             " bytes of texels)";
    return false;
  }
  if (std::fabs(scale) != 1.0)  // pbrt-v4 multiplies the texels by |scale|
    for (float& v : data) v *= static_cast<float>(std::fabs(scale));
  const bool little = scale < 0;
  const bool host_little = std::endian::native == std::endian::little;
  if (little != host_little)
    for (float& v : data) {
      uint32_t b;
      std::memcpy(&b, &v, 4);
      b = __builtin_bswap32(b);
      std::memcpy(&v, &b, 4);
    }
  out.width = static_cast<int>(w);
  out.height = static_cast<int>(h);
  out.rgb = std::move(data);
  return true;
}

bool exr_has_rgb(const std::string& path, std::string& reason) {
  try {
    Imf::InputFile file(path.c_str());
    const Imf::ChannelList& ch = file.header().channels();
    if (ch.findChannel("R") && ch.findChannel("G") && ch.findChannel("B")) return true;
    reason = "the EXR image has no R, G and B channels";
  } catch (const std::exception& e) {
    reason = e.what();
  }
  return false;
}

}  // namespace

bool read_rgb_image(const std::string& path, RgbImage& out, std::string& reason) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    reason = std::filesystem::exists(path, ec) ? "it is not a regular file" : "no such file";
    return false;
  }
  if (ends_with_ci(path, ".pfm")) return read_pfm(path, out, reason);
  if (ends_with_ci(path, ".exr")) {
    if (!exr_has_rgb(path, reason)) return false;
  } else {
    int w = 0, h = 0, n = 0;
    if (!stbi_info(path.c_str(), &w, &h, &n)) {
      // stbi_info tries every format and keeps the last one's complaint ("unknown image
      // type"); the decoder of the file's own format says what is wrong with it
      if (unsigned char* d = stbi_load(path.c_str(), &w, &h, &n, 3)) stbi_image_free(d);
      reason = stbi_failure_reason() ? stbi_failure_reason() : "cannot decode";
      return false;
    }
    if (n < 3) {
      reason = "the image has " + std::to_string(n) + " channel" + (n == 1 ? "" : "s") + ", not R, G and B";
      return false;
    }
  }
  Texture t;
  if (!pbrt::load_image(path, "sRGB", t, reason)) return false;
  out.width = t.width;
  out.height = t.height;
  out.rgb = std::move(t.rgb);
  return true;
}

void write_pfm(const std::string& path, const RgbImage& img) {
  write_atomically(path, [&](const std::string& tmp) {
    std::ofstream f(tmp, std::ios::binary);
    f << "PF\n" << img.width << " " << img.height << "\n" << (std::endian::native == std::endian::little ? "-1" : "1") << "\n";
    const size_t row = static_cast<size_t>(img.width) * 3;
    for (int y = img.height - 1; y >= 0; --y)
      f.write(reinterpret_cast<const char*>(&img.rgb[static_cast<size_t>(y) * row]), static_cast<std::streamsize>(row * sizeof(float)));
    if (!f) throw std::runtime_error(path + ": cannot write the file");
  });
}

bool make_sky_map(const std::string& name, const RgbImage& img, SkyMap& out, std::string& reason) {
  if (img.width != img.height) {
    reason = "the image is " + std::to_string(img.width) + " x " + std::to_string(img.height) +
             ", not square: an infinite light's map is an equal-area octahedral square (convert a latitude-longitude "
             "map with `tuile envmap`)";
    return false;
  }
  if (img.width > sky_map_max_res) {
    reason = "the image is " + std::to_string(img.width) + " x " + std::to_string(img.height) + ", more than " +
             std::to_string(sky_map_max_res) + " texels a side (its texels and distributions would take over " +
             std::to_string(static_cast<long long>(img.width) * img.width * 36 >> 30) + " GiB; `tuile envmap --resolution` makes a smaller one)";
    return false;
  }
  const size_t n = static_cast<size_t>(img.width) * static_cast<size_t>(img.height);
  for (size_t i = 0; i < 3 * n; ++i)
    if (!std::isfinite(img.rgb[i]) || img.rgb[i] < 0 || img.rgb[i] > 1e30f) {  // (sums of 1e30s fit a float)
      const size_t t = i / 3;
      reason = "texel (" + std::to_string(t % static_cast<size_t>(img.width)) + ", " +
               std::to_string(t / static_cast<size_t>(img.width)) + ") has a " +
               (!std::isfinite(img.rgb[i]) ? "NaN or infinite" : img.rgb[i] < 0 ? "negative" : "above 1e30") + " value";
      return false;
    }
  out.file = name;
  out.res = img.width;
  assign_huge(out.texels, 4 * n, 0.f);
  for (size_t i = 0; i < n; ++i)
    for (size_t c = 0; c < 3; ++c) out.texels[4 * i + c] = img.rgb[3 * i + c];
  build_sky_distributions(out);
  return true;
}

namespace {

// The cut points of a CDF of n + 1 values (non-decreasing, cdf[0] = 0): for j = 0 ... cuts,
// the largest i < n with cdf[i] <= j / cuts (exact in float: cuts is a power of two).
void build_cuts(const float* cdf, int32_t n, int32_t cuts, int32_t* out) {
  int32_t i = 0;
  for (int32_t j = 0; j <= cuts; ++j) {
    const float t = static_cast<float>(j) / static_cast<float>(cuts);
    while (i + 1 < n && cdf[i + 1] <= t) ++i;
    out[j] = i;
  }
}

// The tables of one distribution from its weights (all >= 0; all zero: uniform).
void build_dist(std::vector<float> func, int res, SkyMap::Dist& d) {
  const size_t n = static_cast<size_t>(res);
  double total = 0;
  for (float v : func) total += v;
  if (!(total > 0)) {
    std::fill(func.begin(), func.end(), 1.f);
    total = static_cast<double>(func.size());
  }
  assign_huge(d.cond_cdf, n * (n + 1), 0.f);
  d.marg_cdf.assign(n + 1, 0.f);
  std::vector<double> row_sum(n, 0);
  // a quarter as many cuts as texels in a row (at least one): a search from a cut spans a
  // few values of one cache line where the row is smooth
  const int32_t ni = static_cast<int32_t>(n);
  d.cuts = static_cast<int32_t>(std::bit_ceil(static_cast<uint32_t>(std::max(ni / 4, 1))));
  const size_t stride = static_cast<size_t>(d.cuts) + 1;
  assign_huge(d.cond_cut, n * stride, 0);
  d.marg_cut.assign(stride, 0);
  // rows in parallel, each row's CDF then its cut points (while the row is in the cache):
  // each row's values depend on that row alone
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 16), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t y = r.begin(); y < r.end(); ++y) {
      const float* f = &func[y * n];
      float* c = &d.cond_cdf[y * (n + 1)];
      double s = 0;
      for (size_t x = 0; x < n; ++x) s += f[x];
      row_sum[y] = s;
      double acc = 0;
      for (size_t x = 0; x < n; ++x) {
        c[x] = static_cast<float>(s > 0 ? acc / s : static_cast<double>(x) / static_cast<double>(n));
        acc += f[x];
      }
      c[n] = 1.f;
      build_cuts(c, ni, d.cuts, &d.cond_cut[y * stride]);
    }
  });
  double acc = 0;
  for (size_t y = 0; y < n; ++y) {
    d.marg_cdf[y] = static_cast<float>(acc / total);
    acc += row_sum[y];
  }
  d.marg_cdf[n] = 1.f;
  build_cuts(d.marg_cdf.data(), ni, d.cuts, d.marg_cut.data());
  d.inv_mean = static_cast<float>(static_cast<double>(func.size()) / total);
  d.func = std::move(func);
}

}  // namespace

void build_sky_distributions(SkyMap& m) {
  const size_t n = m.texels.size() / 4;
  std::vector<float> func;
  assign_huge(func, n, 0.f);
  double sum[3] = {0, 0, 0}, mean_f = 0;
  for (size_t i = 0; i < n; ++i) {
    const Rgb t = m.texel(i);
    func[i] = (t.r + t.g + t.b) / 3.f;  // pbrt-v4: the channels' average
    sum[0] += t.r;
    sum[1] += t.g;
    sum[2] += t.b;
    mean_f += func[i];
  }
  for (int c = 0; c < 3; ++c) m.mean[c] = n ? sum[c] / static_cast<double>(n) : 0;
  mean_f = n ? mean_f / static_cast<double>(n) : 0;
  // compensated: max(value - mean, 0); nothing left (a constant map): uniform
  std::vector<float> comp;
  assign_huge(comp, n, 0.f);
  m.constant = true;
  double comp_sum = 0;
  for (size_t i = 0; i < n; ++i) {
    comp[i] = static_cast<float>(std::max(0.0, static_cast<double>(func[i]) - mean_f));
    comp_sum += comp[i];
    const Rgb t = m.texel(i), t0 = m.texel(0);
    m.constant = m.constant && t.r == t0.r && t.g == t0.g && t.b == t0.b;
  }
  // (a constant map's compensated distribution is its uniform one: the whole map)
  m.compensated_share = m.constant || !(mean_f > 0) ? 1.0 : comp_sum / static_cast<double>(n) / mean_f;
  build_dist(std::move(func), m.res, m.dist[sky_dist_full]);
  build_dist(std::move(comp), m.res, m.dist[sky_dist_compensated]);
  // the compensated weights (the default's: MIS) beside each texel's radiance
  SkyMap::Dist& c = m.dist[sky_dist_compensated];
  for (size_t i = 0; i < n; ++i) m.texels[4 * i + 3] = c.func[i];
  c.func = std::vector<float>();
}

SkyMapView sky_map_view(const SkyMap& m) {
  SkyMapView v;
  v.res = m.res;
  v.texels = m.texels.data();
  for (int d = 0; d < 2; ++d) {
    const bool in_texels = d == sky_dist_compensated;
    v.dist[d] = {in_texels ? m.texels.data() + 3 : m.dist[d].func.data(),
                 in_texels ? 4 : 1,
                 m.dist[d].cond_cdf.data(),
                 m.dist[d].marg_cdf.data(),
                 m.dist[d].cond_cut.data(),
                 m.dist[d].marg_cut.data(),
                 m.dist[d].cuts,
                 m.dist[d].inv_mean};
  }
  return v;
}

double sky_map_upper_illuminance(const SkyMap& m) {
  double e = 0;
  const int n = m.res;
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      const vec3f w = equal_area_square_to_sphere((x + 0.5f) / static_cast<float>(n), (y + 0.5f) / static_cast<float>(n));
      if (w.z <= 0) continue;
      const size_t i = static_cast<size_t>(y) * static_cast<size_t>(n) + static_cast<size_t>(x);
      e += luminance(m.texel(i)) * static_cast<double>(w.z);
    }
  // each texel subtends 4 pi / n^2 steradians
  return e * 4.0 * 3.14159265358979323846 / (static_cast<double>(n) * static_cast<double>(n));
}

RgbImage latlong_to_equal_area(const RgbImage& ll, int res, int samples) {
  RgbImage out;
  out.width = out.height = res;
  out.rgb.assign(static_cast<size_t>(res) * static_cast<size_t>(res) * 3, 0.f);
  const int W = ll.width, H = ll.height;
  const double pi = 3.14159265358979323846;
  auto texel = [&](int x, int y, int c) {
    x = ((x % W) + W) % W;  // phi wraps around
    y = std::clamp(y, 0, H - 1);
    return static_cast<double>(ll.rgb[(static_cast<size_t>(y) * static_cast<size_t>(W) + static_cast<size_t>(x)) * 3 + static_cast<size_t>(c)]);
  };
  // rows in parallel (each texel depends on the input alone: the same bits on any thread count)
  tbb::parallel_for(0, res, [&](int y) {
    for (int x = 0; x < res; ++x) {
      double acc[3] = {0, 0, 0};
      for (int sy = 0; sy < samples; ++sy)
        for (int sx = 0; sx < samples; ++sx) {
          const float pu = (static_cast<float>(x) + (static_cast<float>(sx) + 0.5f) / static_cast<float>(samples)) / static_cast<float>(res);
          const float pv = (static_cast<float>(y) + (static_cast<float>(sy) + 0.5f) / static_cast<float>(samples)) / static_cast<float>(res);
          const vec3f w = equal_area_square_to_sphere(pu, pv);
          double phi = std::atan2(static_cast<double>(w.y), static_cast<double>(w.x));
          if (phi < 0) phi += 2 * pi;
          const double theta = std::acos(std::clamp(static_cast<double>(w.z), -1.0, 1.0));
          // bilinear at (phi / 2 pi, theta / pi), texel centres at half-integers
          const double fx = phi / (2 * pi) * W - 0.5, fy = theta / pi * H - 0.5;
          const int x0 = static_cast<int>(std::floor(fx)), y0 = static_cast<int>(std::floor(fy));
          const double ax = fx - x0, ay = fy - y0;
          for (int c = 0; c < 3; ++c)
            acc[c] += (1 - ay) * ((1 - ax) * texel(x0, y0, c) + ax * texel(x0 + 1, y0, c)) +
                      ay * ((1 - ax) * texel(x0, y0 + 1, c) + ax * texel(x0 + 1, y0 + 1, c));
        }
      for (int c = 0; c < 3; ++c)
        out.rgb[(static_cast<size_t>(y) * static_cast<size_t>(res) + static_cast<size_t>(x)) * 3 + static_cast<size_t>(c)] =
            static_cast<float>(acc[c] / (samples * samples));
    }
  });
  return out;
}

}  // namespace tuile

// Image textures for the pbrt-v4 reader: stb_image for 8- and 16-bit formats and HDR,
// OpenEXR for EXR, converted to linear RGB.
#define STB_IMAGE_IMPLEMENTATION
#include "image.h"

#include <ImfArray.h>
#include <ImfRgbaFile.h>
#include <stb/stb_image.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>

#include "scene/huge_pages.h"
#include "util.h"

namespace tuile::pbrt {

static float srgb_to_linear(float v) {
  return v <= 0.04045f ? v / 12.92f : std::pow((v + 0.055f) / 1.055f, 2.4f);
}

bool ends_with_ci(const std::string& s, const char* suffix) {
  const size_t n = std::char_traits<char>::length(suffix);
  if (s.size() < n) return false;
  for (size_t i = 0; i < n; ++i)
    if (std::tolower(static_cast<unsigned char>(s[s.size() - n + i])) != suffix[i]) return false;
  return true;
}

static bool load_exr(const std::string& path, Texture& out, std::string& reason) {
  try {
    Imf::RgbaInputFile file(path.c_str());
    const Imath::Box2i dw = file.dataWindow();
    const long w = long(dw.max.x) - dw.min.x + 1, h = long(dw.max.y) - dw.min.y + 1;
    if (w <= 0 || h <= 0 || w * h > (1l << 28)) {
      reason = "EXR image has an unsupported size";
      return false;
    }
    Imf::Array2D<Imf::Rgba> px(h, w);
    file.setFrameBuffer(&px[0][0] - dw.min.x - long(dw.min.y) * w, 1, size_t(w));
    file.readPixels(dw.min.y, dw.max.y);
    out.width = int(w);
    out.height = int(h);
    assign_huge(out.rgb, size_t(3 * w * h), 0.f);
    for (long y = 0; y < h; ++y)
      for (long x = 0; x < w; ++x) {
        float* d = &out.rgb[size_t(3 * (y * w + x))];
        d[0] = px[y][x].r;
        d[1] = px[y][x].g;
        d[2] = px[y][x].b;
      }
    return true;
  } catch (const std::exception& e) {
    reason = e.what();
    return false;
  }
}

// A float image's texels must be finite: a NaN or an infinity would turn every path that
// reads it into a rejected sample (a silently dark patch).
static bool finite_texels(const Texture& t, std::string& reason) {
  for (size_t i = 0; i < t.rgb.size(); ++i)
    if (!std::isfinite(t.rgb[i])) {
      const size_t p = i / 3;
      reason = "texel (" + std::to_string(p % size_t(std::max(t.width, 1))) + ", " + std::to_string(p / size_t(std::max(t.width, 1))) +
               ") is not finite (NaN or infinity)";
      return false;
    }
  return true;
}

bool load_image(const std::string& path, const std::string& encoding, Texture& out, std::string& reason) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    reason = "no such file";
    return false;
  }
  if (ends_with_ci(path, ".exr")) return load_exr(path, out, reason) && finite_texels(out, reason);
  int w = 0, h = 0, n = 0;
  if (ends_with_ci(path, ".hdr") || ends_with_ci(path, ".pfm")) {
    float* data = stbi_loadf(path.c_str(), &w, &h, &n, 3);
    if (!data) {
      reason = stbi_failure_reason() ? stbi_failure_reason() : "cannot decode";
      return false;
    }
    out.width = w;
    out.height = h;
    out.rgb.assign(data, data + size_t(w) * h * 3);
    stbi_image_free(data);
    return finite_texels(out, reason);
  }
  // Decode curve for 8/16-bit values in [0, 1].
  float gamma = 0;  // 0 = sRGB
  bool linear = false;
  if (encoding == "linear") linear = true;
  else if (encoding.rfind("gamma ", 0) == 0) gamma = std::strtof(encoding.c_str() + 6, nullptr);
  auto decode = [&](float v) { return linear ? v : gamma > 0 ? std::pow(v, gamma) : srgb_to_linear(v); };
  const bool is16 = stbi_is_16_bit(path.c_str());
  void* data = is16 ? static_cast<void*>(stbi_load_16(path.c_str(), &w, &h, &n, 3))
                    : static_cast<void*>(stbi_load(path.c_str(), &w, &h, &n, 3));
  if (!data) {
    reason = stbi_failure_reason() ? stbi_failure_reason() : "cannot decode";
    return false;
  }
  out.width = w;
  out.height = h;
  const size_t count = size_t(w) * h * 3;
  assign_huge(out.rgb, count, 0.f);
  if (is16) {
    const uint16_t* s = static_cast<const uint16_t*>(data);
    for (size_t i = 0; i < count; ++i) out.rgb[i] = decode(s[i] / 65535.f);
  } else {
    float lut[256];
    for (int i = 0; i < 256; ++i) lut[i] = decode(i / 255.f);
    const uint8_t* s = static_cast<const uint8_t*>(data);
    for (size_t i = 0; i < count; ++i) out.rgb[i] = lut[s[i]];
  }
  stbi_image_free(data);
  return true;
}

}  // namespace tuile::pbrt

// Image textures for the pbrt-v4 reader: stb_image for 8- and 16-bit formats and HDR,
// OpenEXR for EXR, converted to linear RGB.
#define STB_IMAGE_IMPLEMENTATION
#include "image.h"

#include <ImfArray.h>
#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfRgbaFile.h>
#include <stb/stb_image.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <vector>

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

// An EXR of one channel (pbrt-v4 reads any single channel as grey) into t's three.
static bool load_exr_grey(const std::string& path, Texture& out, std::string& reason) {
  Imf::InputFile file(path.c_str());
  const Imath::Box2i dw = file.header().dataWindow();
  const long w = long(dw.max.x) - dw.min.x + 1, h = long(dw.max.y) - dw.min.y + 1;
  if (w <= 0 || h <= 0 || w * h > (1l << 28)) {
    reason = "EXR image has an unsupported size";
    return false;
  }
  const std::string name = file.header().channels().begin().name();
  std::vector<float> v(size_t(w) * size_t(h));
  Imf::FrameBuffer fb;
  fb.insert(name, Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(v.data() - dw.min.x - long(dw.min.y) * w), sizeof(float),
                             sizeof(float) * size_t(w)));
  file.setFrameBuffer(fb);
  file.readPixels(dw.min.y, dw.max.y);
  out.width = int(w);
  out.height = int(h);
  assign_huge(out.rgb, size_t(3 * w * h), 0.f);
  for (size_t i = 0; i < v.size(); ++i) out.rgb[3 * i] = out.rgb[3 * i + 1] = out.rgb[3 * i + 2] = v[i];
  return true;
}

static bool load_exr(const std::string& path, Texture& out, std::string& reason) {
  try {
    {  // which channels: R, G and B; or luminance (Y, RY, BY: OpenEXR's RGBA interface turns it into
       // RGB); or a single channel, read as grey as pbrt-v4 does; anything else is not an image
       // tuile can read as colours (its RGBA interface fills missing channels with 0: black)
      Imf::InputFile probe(path.c_str());
      const Imf::ChannelList& ch = probe.header().channels();
      int n = 0;
      for (auto it = ch.begin(); it != ch.end(); ++it) ++n;
      const bool rgb = ch.findChannel("R") && ch.findChannel("G") && ch.findChannel("B");
      if (!rgb && !ch.findChannel("Y")) {
        if (n == 1) return load_exr_grey(path, out, reason);
        reason = "the EXR image has no R, G and B channels (nor Y, nor a single channel to read as grey)";
        return false;
      }
    }
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

// Whether a Radiance .hdr file holds all its scanlines: stb_image decodes one cut short as
// if the rest were black (run-length encoded) or repeats its last texel (flat), silently.
// Walks the header, the resolution line and each scanline's runs (the file's bytes d)
// without decoding them.
static bool hdr_complete(const std::string& d, std::string& reason) {
  size_t at = 0;
  const auto line = [&](std::string& l) {
    const size_t e = d.find('\n', at);
    if (e == std::string::npos) return false;
    l = d.substr(at, e - at);
    at = e + 1;
    return true;
  };
  std::string l;
  do {
    if (!line(l)) {
      reason = "the Radiance header never ends (no empty line before the resolution)";
      return false;
    }
  } while (!l.empty());
  long w = 0, h = 0;
  char ys = 0, xs = 0, ya = 0, xa = 0;
  if (!line(l) || std::sscanf(l.c_str(), "%c%c %ld %c%c %ld", &ys, &ya, &h, &xs, &xa, &w) != 6 || w <= 0 || h <= 0)
    return true;  // (an orientation stb_image refuses with its own message)
  const auto cut = [&](long y) {
    reason = "the file is cut short (scanline " + std::to_string(y) + " of " + std::to_string(h) + " is incomplete)";
    return false;
  };
  for (long y = 0; y < h; ++y) {
    const bool rle = w >= 8 && w < 32768 && at + 4 <= d.size() && uint8_t(d[at]) == 2 && uint8_t(d[at + 1]) == 2 &&
                     !(uint8_t(d[at + 2]) & 0x80);
    if (!rle) {  // flat from here on, 4 bytes a texel (as stb_image reads the rest)
      if (d.size() - at < size_t(4) * size_t(w) * size_t(h - y)) return cut(y + (long(d.size() - at) / 4) / w);
      return true;
    }
    at += 4;
    for (int c = 0; c < 4; ++c)
      for (long x = 0; x < w;) {
        if (at >= d.size()) return cut(y);
        long n = uint8_t(d[at++]);
        const bool run = n > 128;
        if (run) n -= 128;
        if (n == 0 || x + n > w) {
          reason = "scanline " + std::to_string(y) + " has a run past its end (corrupt run-length data)";
          return false;
        }
        const size_t bytes = run ? 1 : size_t(n);
        if (d.size() - at < bytes) return cut(y);
        at += bytes;
        x += n;
      }
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
    float* data = nullptr;
    if (ends_with_ci(path, ".hdr")) {  // read once: checked whole, then decoded from memory
      std::ifstream f(path, std::ios::binary);
      const std::string d((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
      if (!f.good() && !f.eof()) {
        reason = "cannot read the file";
        return false;
      }
      if (d.size() > size_t(std::numeric_limits<int>::max())) {
        reason = "the file is larger than 2 GB, more than the Radiance decoder reads";
        return false;
      }
      if (!hdr_complete(d, reason)) return false;
      data = stbi_loadf_from_memory(reinterpret_cast<const stbi_uc*>(d.data()), int(d.size()), &w, &h, &n, 3);
    } else {
      data = stbi_loadf(path.c_str(), &w, &h, &n, 3);
    }
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

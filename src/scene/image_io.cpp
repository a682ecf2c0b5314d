// OpenEXR output and input (Imf), PNG previews (libpng).
#include "scene/image_io.h"

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfOutputFile.h>
#include <ImfStandardAttributes.h>
#include <ImfStringAttribute.h>
#include <ImfIntAttribute.h>
#include <ImfDoubleAttribute.h>
#include <png.h>

#include <cmath>
#include <cstdio>
#include <memory>
#include <stdexcept>

#include "scene/atomic_file.h"

namespace tuile {

const std::string* ExrMetadata::find_text(const std::string& name) const {
  for (const auto& [k, v] : text)
    if (k == name) return &v;
  return nullptr;
}
const int* ExrMetadata::find_integer(const std::string& name) const {
  for (const auto& [k, v] : integers)
    if (k == name) return &v;
  return nullptr;
}
const double* ExrMetadata::find_real(const std::string& name) const {
  for (const auto& [k, v] : reals)
    if (k == name) return &v;
  return nullptr;
}

void write_exr(const std::string& path, int width, int height, const std::vector<float>& rgb,
               const std::vector<ImageLayer>& layers, const ExrMetadata& metadata) {
  const size_t n = static_cast<size_t>(width) * height;
  if (rgb.size() != 3 * n) throw std::runtime_error(path + ": internal error: image size mismatch");
  write_atomically(path, [&](const std::string& tmp) {
    try {
      Imf::Header header(width, height);
      for (const auto& [k, v] : metadata.text) header.insert(k, Imf::StringAttribute(v));
      for (const auto& [k, v] : metadata.integers) header.insert(k, Imf::IntAttribute(v));
      for (const auto& [k, v] : metadata.reals) header.insert(k, Imf::DoubleAttribute(v));
      Imf::FrameBuffer fb;
      const char* names[3] = {"R", "G", "B"};
      for (int c = 0; c < 3; ++c) {
        header.channels().insert(names[c], Imf::Channel(Imf::FLOAT));
        fb.insert(names[c], Imf::Slice(Imf::FLOAT, (char*)(rgb.data() + c), 3 * sizeof(float), 3 * sizeof(float) * width));
      }
      for (const ImageLayer& l : layers) {
        if (l.data.size() != n * static_cast<size_t>(l.channels))
          throw std::runtime_error(path + ": internal error: layer " + l.name + " size mismatch");
        for (int c = 0; c < l.channels; ++c) {
          const std::string ch = l.name + "." + (l.channels == 1 ? std::string("Y") : std::string(names[c]));
          header.channels().insert(ch, Imf::Channel(Imf::FLOAT));
          fb.insert(ch, Imf::Slice(Imf::FLOAT, (char*)(l.data.data() + c), l.channels * sizeof(float),
                                   l.channels * sizeof(float) * width));
        }
      }
      Imf::OutputFile file(tmp.c_str(), header);
      file.setFrameBuffer(fb);
      file.writePixels(height);
    } catch (const std::exception& e) {
      throw std::runtime_error(path + ": cannot write EXR: " + e.what());
    }
  });
}

ExrMetadata read_exr_metadata(const std::string& path) {
  ExrMetadata m;
  try {
    Imf::InputFile file(path.c_str());
    for (auto it = file.header().begin(); it != file.header().end(); ++it) {
      if (const auto* s = dynamic_cast<const Imf::StringAttribute*>(&it.attribute())) m.text.emplace_back(it.name(), s->value());
      else if (const auto* i = dynamic_cast<const Imf::IntAttribute*>(&it.attribute())) m.integers.emplace_back(it.name(), i->value());
      else if (const auto* d = dynamic_cast<const Imf::DoubleAttribute*>(&it.attribute())) m.reals.emplace_back(it.name(), d->value());
    }
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": cannot read EXR: " + e.what());
  }
  return m;
}

std::vector<float> read_exr(const std::string& path, int& width, int& height) {
  try {
    Imf::InputFile file(path.c_str());
    const Imath::Box2i dw = file.header().dataWindow();
    width = dw.max.x - dw.min.x + 1;
    height = dw.max.y - dw.min.y + 1;
    std::vector<float> rgb(static_cast<size_t>(width) * height * 3, 0.f);
    Imf::FrameBuffer fb;
    const char* names[3] = {"R", "G", "B"};
    char* base = (char*)(rgb.data()) - (static_cast<ptrdiff_t>(dw.min.x) + static_cast<ptrdiff_t>(dw.min.y) * width) * 3 * sizeof(float);
    for (int c = 0; c < 3; ++c) {
      if (!file.header().channels().findChannel(names[c]))
        throw std::runtime_error(std::string("no channel ") + names[c]);
      fb.insert(names[c], Imf::Slice(Imf::FLOAT, base + c * sizeof(float), 3 * sizeof(float), 3 * sizeof(float) * width));
    }
    file.setFrameBuffer(fb);
    file.readPixels(dw.min.y, dw.max.y);
    return rgb;
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": cannot read EXR: " + e.what());
  }
}

static unsigned char to_srgb8(float v) {
  if (!(v > 0.f)) return 0;
  if (v >= 1.f) return 255;
  const float s = v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1.f / 2.4f) - 0.055f;
  return static_cast<unsigned char>(std::lround(s * 255.f));
}

void write_png8(const std::string& path, int width, int height, const std::vector<unsigned char>& px) {
  write_atomically(path, [&](const std::string& tmp) {
    FILE* f = std::fopen(tmp.c_str(), "wb");
    if (!f) throw std::runtime_error(path + ": cannot open for writing");
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
    png_infop info = png ? png_create_info_struct(png) : nullptr;
    if (!png || !info) {
      png_destroy_write_struct(&png, &info);
      std::fclose(f);
      throw std::runtime_error(path + ": libpng initialisation failed");
    }
    if (setjmp(png_jmpbuf(png))) {
      png_destroy_write_struct(&png, &info);
      std::fclose(f);
      throw std::runtime_error(path + ": libpng write failed");
    }
    png_init_io(png, f);
    png_set_IHDR(png, info, width, height, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
                 PNG_FILTER_TYPE_DEFAULT);
    png_write_info(png, info);
    for (int y = 0; y < height; ++y)
      png_write_row(png, const_cast<png_bytep>(px.data() + static_cast<size_t>(y) * width * 3));
    png_write_end(png, nullptr);
    png_destroy_write_struct(&png, &info);
    // a full disk shows up here, when the buffered rows are flushed
    if (std::fflush(f) != 0 || std::ferror(f)) {
      std::fclose(f);
      throw std::runtime_error(path + ": write failed (disk full?)");
    }
    if (std::fclose(f) != 0) throw std::runtime_error(path + ": write failed (disk full?)");
  });
}

void write_png(const std::string& path, int width, int height, const std::vector<float>& rgb) {
  std::vector<unsigned char> px(rgb.size());
  for (size_t i = 0; i < rgb.size(); ++i) px[i] = to_srgb8(rgb[i]);
  write_png8(path, width, height, px);
}

}  // namespace tuile

// OpenEXR output and input (Imf), PNG previews (libpng).
#include "scene/image_io.h"

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfOutputFile.h>
#include <png.h>

#include <cmath>
#include <cstdio>
#include <memory>
#include <stdexcept>

namespace tuile {

void write_exr(const std::string& path, int width, int height, const std::vector<float>& rgb,
               const std::vector<ImageLayer>& layers) {
  const size_t n = static_cast<size_t>(width) * height;
  if (rgb.size() != 3 * n) throw std::runtime_error(path + ": internal error: image size mismatch");
  try {
    Imf::Header header(width, height);
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
    Imf::OutputFile file(path.c_str(), header);
    file.setFrameBuffer(fb);
    file.writePixels(height);
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": cannot write EXR: " + e.what());
  }
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
  std::unique_ptr<FILE, int (*)(FILE*)> f(std::fopen(path.c_str(), "wb"), std::fclose);
  if (!f) throw std::runtime_error(path + ": cannot open for writing");
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!png || !info) throw std::runtime_error(path + ": libpng initialisation failed");
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    throw std::runtime_error(path + ": libpng write failed");
  }
  png_init_io(png, f.get());
  png_set_IHDR(png, info, width, height, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
               PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  for (int y = 0; y < height; ++y)
    png_write_row(png, const_cast<png_bytep>(px.data() + static_cast<size_t>(y) * width * 3));
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
}

void write_png(const std::string& path, int width, int height, const std::vector<float>& rgb) {
  std::vector<unsigned char> px(rgb.size());
  for (size_t i = 0; i < rgb.size(); ++i) px[i] = to_srgb8(rgb[i]);
  write_png8(path, width, height, px);
}

}  // namespace tuile

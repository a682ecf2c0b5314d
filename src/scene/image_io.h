// Image files: OpenEXR (float32, linear, R G B at the top level plus named layers) and an
// 8-bit sRGB PNG preview (libpng).
#pragma once
#include <string>
#include <utility>
#include <vector>

namespace tuile {

struct ImageLayer {
  std::string name;         // "variance" -> channels variance.R, variance.G, variance.B
  int channels = 3;         // 3 (R G B) or 1 (Y)
  std::vector<float> data;  // interleaved, width * height * channels
};

// Header attributes beside the standard ones (tuile writes spp, seed, estimator, sampler,
// version, render seconds and the command line on every render).
struct ExrMetadata {
  std::vector<std::pair<std::string, std::string>> text;
  std::vector<std::pair<std::string, int>> integers;
  std::vector<std::pair<std::string, double>> reals;
  const std::string* find_text(const std::string& name) const;
  const int* find_integer(const std::string& name) const;
  const double* find_real(const std::string& name) const;
};

// Writes atomically (scene/atomic_file.h): the previous file of that name survives any
// failure. Throws std::runtime_error naming the file on failure.
void write_exr(const std::string& path, int width, int height, const std::vector<float>& rgb,
               const std::vector<ImageLayer>& layers = {}, const ExrMetadata& metadata = {});
// The string, int and double attributes of an EXR's header.
ExrMetadata read_exr_metadata(const std::string& path);
// Reads the top-level R G B channels.
std::vector<float> read_exr(const std::string& path, int& width, int& height);
// sRGB transfer, exposure 0, clamped to [0, 1]. PNGs are written atomically too.
void write_png(const std::string& path, int width, int height, const std::vector<float>& rgb);
// 8-bit RGB PNG from already-encoded bytes (used by the figures/plots).
void write_png8(const std::string& path, int width, int height, const std::vector<unsigned char>& rgb8);

}  // namespace tuile

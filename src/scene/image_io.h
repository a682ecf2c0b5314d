// Image files: OpenEXR (float32, linear, R G B at the top level plus named layers) and an
// 8-bit sRGB PNG preview (libpng).
#pragma once
#include <string>
#include <vector>

namespace tuile {

struct ImageLayer {
  std::string name;         // "variance" -> channels variance.R, variance.G, variance.B
  int channels = 3;         // 3 (R G B) or 1 (Y)
  std::vector<float> data;  // interleaved, width * height * channels
};

// Throws std::runtime_error naming the file on failure.
void write_exr(const std::string& path, int width, int height, const std::vector<float>& rgb,
               const std::vector<ImageLayer>& layers = {});
// Reads the top-level R G B channels.
std::vector<float> read_exr(const std::string& path, int& width, int& height);
// sRGB transfer, exposure 0, clamped to [0, 1].
void write_png(const std::string& path, int width, int height, const std::vector<float>& rgb);
// 8-bit RGB PNG from already-encoded bytes (used by the figures/plots).
void write_png8(const std::string& path, int width, int height, const std::vector<unsigned char>& rgb8);

}  // namespace tuile

// Environment maps for LightSource "infinite": reading them (PFM, EXR, HDR, PNG and the
// other formats of image textures), checking them as pbrt-v4 does, and building the
// distributions their light samples are drawn from (light/sky_map.h reads them).
#pragma once
#include <string>
#include <vector>

#include "light/sky_map.h"
#include "scene/scene.h"

namespace tuile {

// A linear RGB image of any shape, as read from a file (top row first).
struct RgbImage {
  int width = 0, height = 0;
  std::vector<float> rgb;  // interleaved
};

// Reads an image with R, G and B: PFM ("PF"; a grey "Pf" has no RGB), EXR (its R G B
// channels), HDR, and 8/16-bit formats (decoded from sRGB, as pbrt-v4). Returns false with
// the reason when it cannot: no such file, an unreadable or truncated file, no R G B.
bool read_rgb_image(const std::string& path, RgbImage& out, std::string& reason);

// Writes a PFM (colour, little-endian, bottom row first as the format stores it).
void write_pfm(const std::string& path, const RgbImage& img);

// An environment map from an image: square (pbrt-v4's equal-area layout has no other
// shape), every texel finite and >= 0. Returns false with the reason otherwise.
bool make_sky_map(const std::string& name, const RgbImage& img, SkyMap& out, std::string& reason);

// Fills out.dist (both distributions), out.mean and out.constant from the texels.
void build_sky_distributions(SkyMap& out);

// The map as the kernels read it (pointing into m, which must outlive it).
SkyMapView sky_map_view(const SkyMap& m);

// The illuminance the map gives a surface facing +z of its frame: the integral of its
// luminance times cos over the upper hemisphere (pbrt-v4's normalisation for "illuminance").
double sky_map_upper_illuminance(const SkyMap& m);

// A latitude-longitude map (theta from +z at the top row, phi = 2 pi u from +x towards +y,
// as pbrt-v4's imgtool makeequiarea reads one) resampled to an equal-area square of res x
// res texels: each texel the bilinear lookup at its centre's direction, averaged over
// samples x samples points of the texel.
RgbImage latlong_to_equal_area(const RgbImage& latlong, int res, int samples = 4);

}  // namespace tuile

// Image files for imagemap textures: TGA, PNG, JPEG, BMP, HDR through stb_image, EXR
// through OpenEXR. 8- and 16-bit images are decoded from their encoding (sRGB by
// default, as pbrt-v4) to linear RGB.
#pragma once
#include <string>

#include "scene/scene.h"

namespace tuile::pbrt {

// encoding: "sRGB", "linear" or "gamma G" (pbrt-v4's imagemap "encoding").
// Returns false with a reason when the file cannot be read or decoded.
bool load_image(const std::string& path, const std::string& encoding, Texture& out, std::string& reason);

// Whether s ends with suffix (given in lower case), ignoring case: ".TGA" ends with ".tga".
bool ends_with_ci(const std::string& s, const char* suffix);

}  // namespace tuile::pbrt

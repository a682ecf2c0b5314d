// The camera as the estimators that start paths at the lights see it (the light tracer of
// light_paths.h, the bidirectional path tracer of bdpt.h): pbrt-v4's pinhole, a point that
// a vertex is joined to, its importance, and the pixels a contribution at a raster position
// lands in through the pixel filter.
//
// Importance. The camera's rays are uniform over the screen window on the plane z = 1 of
// camera space (area A, the window times tan(fov / 2) squared); a direction towards camera
// point q on that plane has density |M q|^3 / (A |det M|) per unit world solid angle (M:
// world_from_camera, which may scale). That density is also the importance per unit solid
// angle of a camera whose image is the mean over one ray per pixel and sample: a light
// path per pixel and sample splatted through the pixel filter, normalised to integral 1,
// and the film's sum divided by its samples give each pixel its measurement.
#pragma once
#include <cstdint>
#include <vector>

#include "lanes/vec.h"
#include "wave/views.h"

namespace tuile {

struct LightPathSplat {
  uint32_t pixel;
  float r, g, b;
};

class Pinhole {
 public:
  // Throws std::invalid_argument (what: "<who>: the camera's transform is singular").
  Pinhole(const CameraView& c, int width, int height, const char* who);
  // Where point x is seen: false behind the camera or outside the image and its filter's
  // reach. Else the raster position (rx, ry), the vector from x to the camera (v), its
  // squared length d2, and the density of the camera's ray towards x per unit solid angle
  // (the importance; divide by d2 for the measure of area at x, times the cosine there).
  bool see(const Vec3<float>& x, double& rx, double& ry, double v[3], double& d2, double& density) const;
  // The density per unit solid angle of the camera's ray along the unit world direction d
  // (0 outside the screen window).
  double ray_density(const Vec3<float>& d) const;
  // A contribution at raster position (rx, ry) into the pixels whose filter covers it.
  void splat(double rx, double ry, const float c[3], std::vector<LightPathSplat>& out) const;
  const double* origin() const { return o_; }

 private:
  const CameraView& c_;
  int width_, height_;
  double o_[3] = {}, inv_[3][3] = {}, m_[3][3] = {};
  double det_ = 1, area_ = 1;  // |det M|, the screen window's area at distance 1
  double rx_ = 0.5, ry_ = 0.5, inv_norm_ = 1;  // the pixel filter's radii and 1 / its integral
};

}  // namespace tuile

#include "render_util.h"

#include <cmath>

#include "wave/generate.h"

namespace tuile::test {

std::vector<double> exact_image(const PlaneScene& p, int q) {
  // Gauss-Legendre nodes/weights on [0, 1]
  std::vector<double> x(q), w(q);
  for (int i = 0; i < q; ++i) {  // Newton on P_q
    double t = std::cos(3.14159265358979 * (i + 0.75) / (q + 0.5));
    for (int it = 0; it < 100; ++it) {
      double p0 = 1, p1 = t;
      for (int k = 2; k <= q; ++k) {
        const double p2 = ((2 * k - 1) * t * p1 - (k - 1) * p0) / k;
        p0 = p1;
        p1 = p2;
      }
      const double dp = q * (t * p1 - p0) / (t * t - 1);
      const double dt = p1 / dp;
      t -= dt;
      if (std::fabs(dt) < 1e-15) {
        x[i] = 0.5 * (1 - t);
        w[i] = 1.0 / ((1 - t * t) * dp * dp);  // = 2/((1-t^2)P'^2) on [-1,1], halved
        break;
      }
    }
  }
  const Camera& c = p.scene.camera;
  CameraView cv{};
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 4; ++k) cv.m[r][k] = c.world_from_camera[r][k];
  const float aspect = static_cast<float>(c.width) / static_cast<float>(c.height);
  cv.sx0 = aspect > 1 ? -aspect : -1;
  cv.sx1 = -cv.sx0;
  cv.sy0 = aspect > 1 ? -1 : -1 / aspect;
  cv.sy1 = -cv.sy0;
  cv.tan_half = std::tan(0.5f * c.fov_deg * 3.14159265f / 180.f);
  cv.inv_w = 1.f / static_cast<float>(c.width);
  cv.inv_h = 1.f / static_cast<float>(c.height);
  std::vector<double> img(static_cast<size_t>(c.width) * c.height, 0.0);
  for (int py = 0; py < c.height; ++py)
    for (int px = 0; px < c.width; ++px) {
      double sum = 0;
      for (int i = 0; i < q; ++i)
        for (int j = 0; j < q; ++j) {
          vec3f o, d;
          camera_ray(cv, static_cast<float>(px + x[i]), static_cast<float>(py + x[j]), o, d);
          const double t = -static_cast<double>(o.y) / d.y;
          sum += w[i] * w[j] * exact_floor_radiance(p, o.x + t * d.x, o.z + t * d.z);
        }
      img[static_cast<size_t>(py) * c.width + px] = sum;
    }
  return img;
}

}  // namespace tuile::test

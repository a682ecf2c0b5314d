// The pinhole camera of the estimators that start paths at the lights (render/pinhole.h).
#include "render/pinhole.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "sample/filter.h"

namespace tuile {

namespace {

// The integral of one axis of a tabulated filter (midpoint rule, fine enough for the
// smooth filters it is used for).
double axis_integral(const FilterView& f, const FilterAxis& a) {
  const int n = 1 << 14;
  const double h = 2.0 * a.r / n;
  double s = 0;
  for (int i = 0; i < n; ++i) s += filter_value_1d<float>(f, a, static_cast<float>(-a.r + (i + 0.5) * h));
  return s * h;
}

}  // namespace

Pinhole::Pinhole(const CameraView& c, int width, int height, const char* who) : c_(c), width_(width), height_(height) {
  // world_from_camera M, its inverse, |det M|, the screen window at distance 1
  for (int r = 0; r < 3; ++r) {
    o_[r] = c.m[r][3];
    for (int k = 0; k < 3; ++k) m_[r][k] = c.m[r][k];
  }
  const double(&a)[3][3] = m_;
  const double det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
                     a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
  if (!(std::abs(det) > 0) || !std::isfinite(det)) throw std::invalid_argument(std::string(who) + ": the camera's transform is singular");
  det_ = std::abs(det);
  inv_[0][0] = (a[1][1] * a[2][2] - a[1][2] * a[2][1]) / det;
  inv_[0][1] = (a[0][2] * a[2][1] - a[0][1] * a[2][2]) / det;
  inv_[0][2] = (a[0][1] * a[1][2] - a[0][2] * a[1][1]) / det;
  inv_[1][0] = (a[1][2] * a[2][0] - a[1][0] * a[2][2]) / det;
  inv_[1][1] = (a[0][0] * a[2][2] - a[0][2] * a[2][0]) / det;
  inv_[1][2] = (a[0][2] * a[1][0] - a[0][0] * a[1][2]) / det;
  inv_[2][0] = (a[1][0] * a[2][1] - a[1][1] * a[2][0]) / det;
  inv_[2][1] = (a[0][1] * a[2][0] - a[0][0] * a[2][1]) / det;
  inv_[2][2] = (a[0][0] * a[1][1] - a[0][1] * a[1][0]) / det;
  const double t = c.tan_half;
  area_ = std::abs((static_cast<double>(c.sx1) - c.sx0) * (static_cast<double>(c.sy1) - c.sy0)) * t * t;
  // the pixel filter, normalised
  const FilterView& f = c.filter;
  if (f.kind == FilterKind::box) {
    rx_ = 0.5 * f.box_b[0];
    ry_ = 0.5 * f.box_b[1];
    inv_norm_ = 1.0 / (4.0 * rx_ * ry_);
  } else if (f.kind == FilterKind::triangle) {
    rx_ = f.axis[0].r;
    ry_ = f.axis[1].r;
    inv_norm_ = 1.0 / (rx_ * rx_ * ry_ * ry_);
  } else {
    rx_ = f.axis[0].r;
    ry_ = f.axis[1].r;
    inv_norm_ = 1.0 / (axis_integral(f, f.axis[0]) * axis_integral(f, f.axis[1]));
  }
}

bool Pinhole::see(const Vec3<float>& x, double& rx, double& ry, double v[3], double& d2, double& density) const {
  const double vx = o_[0] - x.x, vy = o_[1] - x.y, vz = o_[2] - x.z;
  const double cz = inv_[2][0] * -vx + inv_[2][1] * -vy + inv_[2][2] * -vz;
  if (!(cz > 0)) return false;  // behind the camera
  const double cx = inv_[0][0] * -vx + inv_[0][1] * -vy + inv_[0][2] * -vz;
  const double cy = inv_[1][0] * -vx + inv_[1][1] * -vy + inv_[1][2] * -vz;
  const double qx = cx / cz, qy = cy / cz;
  const double sx = qx / c_.tan_half, sy = qy / c_.tan_half;
  rx = (sx - c_.sx0) / (static_cast<double>(c_.sx1) - c_.sx0) * width_;
  ry = (static_cast<double>(c_.sy1) - sy) / (static_cast<double>(c_.sy1) - c_.sy0) * height_;
  if (rx < -rx_ || ry < -ry_ || rx > width_ + rx_ || ry > height_ + ry_) return false;
  v[0] = vx;
  v[1] = vy;
  v[2] = vz;
  d2 = vx * vx + vy * vy + vz * vz;
  // |M q|^3 / (A |det M|)
  const double mq0 = m_[0][0] * qx + m_[0][1] * qy + m_[0][2], mq1 = m_[1][0] * qx + m_[1][1] * qy + m_[1][2],
               mq2 = m_[2][0] * qx + m_[2][1] * qy + m_[2][2];
  const double mq = std::sqrt(mq0 * mq0 + mq1 * mq1 + mq2 * mq2);
  density = mq * mq * mq / (area_ * det_);
  return true;
}

double Pinhole::ray_density(const Vec3<float>& d) const {
  const double cz = inv_[2][0] * d.x + inv_[2][1] * d.y + inv_[2][2] * d.z;
  if (!(cz > 0)) return 0;
  const double qx = (inv_[0][0] * d.x + inv_[0][1] * d.y + inv_[0][2] * d.z) / cz;
  const double qy = (inv_[1][0] * d.x + inv_[1][1] * d.y + inv_[1][2] * d.z) / cz;
  const double sx = qx / c_.tan_half, sy = qy / c_.tan_half;
  const double lo_x = std::min<double>(c_.sx0, c_.sx1), hi_x = std::max<double>(c_.sx0, c_.sx1);
  const double lo_y = std::min<double>(c_.sy0, c_.sy1), hi_y = std::max<double>(c_.sy0, c_.sy1);
  if (sx < lo_x || sx > hi_x || sy < lo_y || sy > hi_y) return 0;
  const double mq0 = m_[0][0] * qx + m_[0][1] * qy + m_[0][2], mq1 = m_[1][0] * qx + m_[1][1] * qy + m_[1][2],
               mq2 = m_[2][0] * qx + m_[2][1] * qy + m_[2][2];
  const double mq = std::sqrt(mq0 * mq0 + mq1 * mq1 + mq2 * mq2);
  return mq * mq * mq / (area_ * det_);
}

void Pinhole::splat(double rx, double ry, const float c[3], std::vector<LightPathSplat>& out) const {
  const FilterView& f = c_.filter;
  if (f.kind == FilterKind::box && rx_ == 0.5 && ry_ == 0.5) {  // the pixel it falls in (as the camera's samples)
    const double px = std::floor(rx), py = std::floor(ry);
    if (px < 0 || py < 0 || px >= width_ || py >= height_) return;
    const float w = static_cast<float>(inv_norm_);
    out.push_back({static_cast<uint32_t>(py) * static_cast<uint32_t>(width_) + static_cast<uint32_t>(px), c[0] * w, c[1] * w,
                   c[2] * w});
    return;
  }
  const int x0 = std::max(0, static_cast<int>(std::ceil(rx - 0.5 - rx_)));
  const int x1 = std::min(width_ - 1, static_cast<int>(std::floor(rx - 0.5 + rx_)));
  const int y0 = std::max(0, static_cast<int>(std::ceil(ry - 0.5 - ry_)));
  const int y1 = std::min(height_ - 1, static_cast<int>(std::floor(ry - 0.5 + ry_)));
  for (int y = y0; y <= y1; ++y)
    for (int x = x0; x <= x1; ++x) {
      const float w = static_cast<float>(filter_value(f, rx - (x + 0.5), ry - (y + 0.5)) * inv_norm_);
      if (w == 0.f) continue;
      out.push_back({static_cast<uint32_t>(y) * static_cast<uint32_t>(width_) + static_cast<uint32_t>(x), c[0] * w, c[1] * w,
                     c[2] * w});
    }
}

}  // namespace tuile

// Point, spot and distant lights against their exact answers: a diffuse floor lit by a
// delta light has radiance rho/pi * I falloff cos / d^2 (point, spot) or rho/pi * E cos
// (distant). Every strategy must get it right: a BSDF ray cannot hit a delta light, so
// MIS gives them weight one and the BSDF strategy still samples them; resampled importance
// sampling takes them as candidates of density their pick probability.
#include <gtest/gtest.h>

#include <cmath>

#include "wave/generate.h"
#include "render_util.h"

using namespace tuile;
using namespace tuile::test;

namespace {

double smoothstep(double a, double b, double x) {
  const double t = std::clamp((x - a) / (b - a), 0.0, 1.0);
  return t * t * (3 - 2 * t);
}

// Exact pixel means by q x q Gauss-Legendre-free midpoint quadrature (the integrand is
// smooth: a fine grid is accurate to well below the Monte Carlo error).
std::vector<double> exact_delta(const Scene& s, const Light& l, double rho, int q = 8) {
  SceneViews v = build_views(s, LightPick::power);
  std::vector<double> img(static_cast<size_t>(s.camera.width) * s.camera.height, 0.0);
  for (int py = 0; py < s.camera.height; ++py)
    for (int px = 0; px < s.camera.width; ++px) {
      double sum = 0;
      for (int i = 0; i < q; ++i)
        for (int j = 0; j < q; ++j) {
          vec3f o, d;
          camera_ray(v.camera, px + (i + 0.5f) / q, py + (j + 0.5f) / q, o, d);
          const double t = -static_cast<double>(o.y) / d.y;
          const double x[3] = {o.x + t * d.x, 0.0, o.z + t * d.z};
          double L = 0;
          if (l.type == LightKind::distant) {
            L = rho / M_PI * l.radiance.r * std::max(0.0, static_cast<double>(l.e1.y));
          } else {
            const double w[3] = {l.p0.x - x[0], l.p0.y - x[1], l.p0.z - x[2]};
            const double d2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2], dd = std::sqrt(d2);
            double I = l.radiance.r;
            if (l.type == LightKind::spot) {
              const double cos_t = -(w[0] * l.e1.x + w[1] * l.e1.y + w[2] * l.e1.z) / dd;
              I *= smoothstep(l.e2.y, l.e2.x, cos_t);
            }
            L = rho / M_PI * I * std::max(0.0, w[1] / dd) / d2;
          }
          sum += L;
        }
      img[static_cast<size_t>(py) * s.camera.width + px] = sum / (q * q);
    }
  return img;
}

}  // namespace

TEST(DeltaLights, PointSpotDistantAreExact) {
  for (LightKind type : {LightKind::point, LightKind::spot, LightKind::distant}) {
    PlaneScene p = plane_scene({0, 0.6f, 0}, 80, 20, 0.6f);
    Light l;
    l.type = type;
    l.p0 = {0.3f, 1.0f, -0.2f};
    l.radiance = {3, 3, 3};
    if (type == LightKind::spot) {
      l.e1 = normalize(vec3f{-0.2f, -1, 0.1f});
      l.e2 = {std::cos(0.35f), std::cos(0.6f), 0};  // falloff start, total
    }
    if (type == LightKind::distant) l.e1 = normalize(vec3f{0.3f, 1, -0.4f});
    p.scene.lights.push_back(l);
    finalize_scene(p.scene);
    const std::vector<double> exact = exact_delta(p.scene, p.scene.lights[0], 0.6);
    for (Strategy st : {Strategy::light, Strategy::bsdf, Strategy::mis, Strategy::ris})
      for (MisMode mode : {MisMode::multi, MisMode::one}) {
        RenderOptions o;
        o.est.strategy = st;
        o.est.mode = mode;
        o.est.sampler = SamplerKind::independent;
        o.est.spp = 64;
        for (bool general : {false, true}) {
          o.general_pipeline = general;
          const RenderResult r = render_scene(p.scene, o);
          const std::vector<float> var = r.film.variance_of_mean();
          double d = 0, v = 0, e = 0;
          for (size_t i = 0; i < exact.size(); ++i) {
            d += r.mean[3 * i] - exact[i];
            v += var[3 * i];
            e += exact[i];
          }
          ASSERT_GT(e, 0.0);
          // the only randomness is the pixel position: where the variance is ~0 compare
          // relatively (midpoint quadrature error ~1e-4), else within 3 standard errors
          const double z = std::fabs(d) / std::max(std::sqrt(v), 1e-4 * e);
          EXPECT_LT(z, 3.0) << int(type) << " " << describe(o.est) << " general " << general << ": mean " << d / e;
        }
      }
  }
}

// pbrt-v4's curves (Embree's flat, normal-oriented and round Bezier curves): a straight
// curve of known width seen head-on covers its exact area in the image, white curves of
// every type vanish in a white furnace (no ray leaks into a tube or is caught by the curve
// it leaves), and the loader converts every basis and degree to the Bezier segments
// pbrt-v4 makes, with errors naming file and line.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "render_util.h"
#include "scene/pbrt.h"
#include "test_scale.h"

using namespace tuile;
using namespace tuile::test;

namespace {

RenderOptions options(uint32_t spp, int depth = 1) {
  RenderOptions o;
  o.est.strategy = Strategy::mis;
  o.est.sampler = SamplerKind::independent;
  o.est.spp = spp;
  o.est.seed = 3;
  o.est.max_depth = depth;
  o.threads = 2;
  return o;
}

// A square camera of res pixels on the axis, d from the plane z = 0 that it sees head-on,
// and the side of one pixel in that plane.
double head_on_camera(Scene& s, int res, double d, double fov) {
  s.camera.width = s.camera.height = res;
  s.camera.fov_deg = static_cast<float>(fov);
  camera_look_at(s.camera, {0, 0, static_cast<float>(d)}, {0, 0, 0}, {0, 1, 0});
  return 2 * d * std::tan(fov * M_PI / 360) / res;
}

Scene load_curves(const std::string& body) { return load_pbrt_string("WorldBegin\n" + body, "c.pbrt", "."); }

std::string curve_error(const std::string& body) {
  try {
    load_curves(body);
  } catch (const SceneError& e) {
    return e.what();
  }
  return "(no error)";
}

}  // namespace

// Black curves (2 long, width 0.1) in front of an emitter of radiance 1, seen head-on by a
// camera 4 away: the image loses exactly the curve's area (the plane z = 0 maps to the
// image by a uniform scale, so a pixel covers a fixed area of it).
TEST(Curves, StraightCurveCoversItsExactArea) {
  for (CurveType type : {CurveType::flat, CurveType::ribbon, CurveType::cylinder}) {
    Scene s;
    s.source = "test:curve-area";
    s.materials.push_back(diffuse_material(Rgb{0, 0, 0}, -1));
    Mesh back;
    back.name = "backdrop";
    back.material = 0;
    back.emission = {1, 1, 1};
    add_quad(back, {-50, -50, -2}, {100, 0, 0}, {0, 100, 0});  // faces +z
    s.meshes.push_back(back);
    const float a = 1, r = 0.05f;
    s.curves.push_back(straight_curve(type, a, 0.2f, r));
    s.curves.back().material = 0;
    const int res = 64;
    const double pixel = head_on_camera(s, res, 4, 40);
    finalize_scene(s);
    const RenderResult out = render_scene(s, options(scaled(128u, 32u)));
    double lost = 0;
    for (int i = 0; i < res * res; ++i) lost += 1 - out.mean[3 * size_t(i)];
    // (a cylinder is a tube: its silhouette is 2r wide, open at its ends, its near side
    // r / d closer to the camera)
    const double area = lost * pixel * pixel, expect = 2 * a * 2 * r;
    EXPECT_NEAR(area / expect, 1.0, 0.015) << "type " << static_cast<int>(type) << ": " << area << " vs " << expect;
  }
}

// White diffuse curves of every type under a uniform sky of radiance 1 with paths as deep
// as Russian roulette lets them go: every pixel is 1. A ray that leaked into a tube, or
// met the curve it leaves, would be lost and darken the image.
TEST(Curves, WhiteFurnaceIsInvisible) {
  Scene s;
  s.source = "test:curve-furnace";
  s.materials.push_back(diffuse_material(Rgb{1, 1, 1}, -1));
  Light sky;
  sky.type = LightKind::infinite;
  sky.radiance = {1, 1, 1};
  s.lights.push_back(sky);
  for (int i = 0; i < 9; ++i) {
    const CurveType type = static_cast<CurveType>(i % 3);
    Curves c = straight_curve(type, 1.2f, -0.8f + 0.2f * i, 0.02f + 0.01f * i);
    // bend it out of its plane so rays meet curves at every angle
    c.points[6] = 0.4f;
    c.points[10] = -0.3f;
    c.material = 0;
    s.curves.push_back(c);
  }
  s.camera.width = s.camera.height = 32;
  s.camera.fov_deg = 40;
  camera_look_at(s.camera, {0, 0, 4}, {0, 0, 0}, {0, 1, 0});
  finalize_scene(s);
  const RenderResult r = render_scene(s, options(scaled(64u, 16u), 64));
  double sum = 0;
  int darker = 0;
  const std::vector<float> var = r.film.variance_of_mean();
  for (size_t i = 0; i < r.mean.size() / 3; ++i) {
    sum += r.mean[3 * i];
    if (r.mean[3 * i] < 1 - 6 * std::sqrt(var[3 * i]) - 1e-3) ++darker;
  }
  EXPECT_NEAR(sum / (r.mean.size() / 3), 1.0, 0.01);
  EXPECT_EQ(darker, 0);
}

// pbrt-v4's conversions: a cubic B-spline's segment to Bezier, a quadratic Bezier elevated,
// a quadratic B-spline, widths linear along the whole curve, ribbon normals, the transform.
TEST(Curves, LoaderConvertsEveryBasisToBezier) {
  const Scene s = load_curves(
      "Shape \"curve\" \"point3 P\" [0 0 0 1 0 0 2 0 0 3 0 0] \"string basis\" \"bspline\"\n"
      "Shape \"curve\" \"point3 P\" [0 0 0 1 1 0 2 0 0] \"integer degree\" 2 \"float width0\" 1 \"float width1\" 0\n"
      "Shape \"curve\" \"point3 P\" [0 0 0 2 2 0 4 0 0 6 2 0] \"string basis\" \"bspline\" \"integer degree\" 2 \"string type\" \"cylinder\"\n"
      "Scale 2 2 2 Shape \"curve\" \"point3 P\" [0 0 0 1 0 0 2 0 0 3 0 0] \"string type\" \"ribbon\" \"normal N\" [0 0 1 0 1 0]\n");
  ASSERT_EQ(s.curves.size(), 4u);
  for (const std::string& w : s.warnings) EXPECT_EQ(w.find("curve"), std::string::npos) << w;
  auto expect_points = [](const Curves& c, const std::vector<float>& xyzr) {
    ASSERT_EQ(c.points.size(), xyzr.size());
    for (size_t i = 0; i < xyzr.size(); ++i) EXPECT_NEAR(c.points[i], xyzr[i], 1e-6) << c.name << " value " << i;
  };
  // uniform cubic B-spline on a line: the Bezier points at 1, 4/3, 5/3, 2; width 1
  expect_points(s.curves[0], {1, 0, 0, 0.5f, 4 / 3.f, 0, 0, 0.5f, 5 / 3.f, 0, 0, 0.5f, 2, 0, 0, 0.5f});
  EXPECT_EQ(s.curves[0].type, CurveType::flat);
  // degree elevation; the radius from 0.5 down to 0, linear along u
  expect_points(s.curves[1], {0, 0, 0, 0.5f, 2 / 3.f, 2 / 3.f, 0, 1 / 3.f, 4 / 3.f, 2 / 3.f, 0, 1 / 6.f, 2, 0, 0, 0});
  // a quadratic B-spline of 4 points: 2 segments, from the midpoints (1,1) to (3,1) and (3,1) to (5,1)
  const Curves& q = s.curves[2];
  ASSERT_EQ(q.segment_count(), 2u);
  EXPECT_EQ(q.type, CurveType::cylinder);
  EXPECT_NEAR(q.points[0], 1, 1e-6);
  EXPECT_NEAR(q.points[1], 1, 1e-6);
  EXPECT_NEAR(q.points[12], 3, 1e-6);
  EXPECT_NEAR(q.points[16], 3, 1e-6);
  EXPECT_NEAR(q.points[28], 5, 1e-6);
  // a ribbon under Scale 2: points and widths scaled, normals from +z to +y through the diagonal
  const Curves& rb = s.curves[3];
  EXPECT_EQ(rb.type, CurveType::ribbon);
  EXPECT_NEAR(rb.points[12], 6, 1e-5);
  EXPECT_NEAR(rb.points[3], 1, 1e-6);
  ASSERT_GE(rb.normals.size(), 12u);
  EXPECT_NEAR(rb.normals[2], 1, 1e-6);
  EXPECT_NEAR(rb.normals[10], 1, 1e-6);
  EXPECT_NEAR(rb.normals[3 + 1], std::sin(M_PI / 6), 1e-6);  // slerp at u = 1/3: 30 degrees
  EXPECT_NEAR(rb.normals[3 + 2], std::cos(M_PI / 6), 1e-6);
}

TEST(Curves, BadCurvesNameFileAndLine) {
  const std::string cases[] = {
      "Shape \"curve\" \"point3 P\" [0 0 0 1 0 0 2 0 0]\n",                                   // 3 points, cubic
      "Shape \"curve\"\n",                                                                     // no P
      "Shape \"curve\" \"point3 P\" [0 0 0 1 0 0 2 0 0 3 0 0] \"integer degree\" 4\n",         // degree
      "Shape \"curve\" \"point3 P\" [0 0 0 1 0 0 2 0 0 3 0 0] \"string basis\" \"hermite\"\n", // basis
      "Shape \"curve\" \"point3 P\" [0 0 0 1 0 0 2 0 0 3 0 0] \"string type\" \"tube\"\n",     // type
      "Shape \"curve\" \"point3 P\" [0 0 0 1 0 0 2 0 0 3 0 0] \"string type\" \"ribbon\"\n",   // no N
      "Shape \"curve\" \"point3 P\" [0 0 0 1 0 0 2 0 0 3 0 0] \"float width\" -1\n",           // width
  };
  for (const std::string& c : cases) {
    const std::string e = curve_error(c);
    EXPECT_EQ(e.rfind("c.pbrt:2", 0), 0u) << c << " -> " << e;
  }
}

// Shading normals: white curves lit by a distant light behind the camera. A flat curve
// faces the ray and a ribbon here faces the camera: radiance E / pi over their area; a tube's
// Lambertian silhouette averages cos = pi / 4 across its width: E / 4. (Embree's Ng of a
// flat curve is its tangent: shaded by it, the flat curve would be black.)
TEST(Curves, FlatCurvesFaceTheRayRibbonsTheirNormalTubesTheirSurface) {
  for (CurveType type : {CurveType::flat, CurveType::ribbon, CurveType::cylinder}) {
    Scene s;
    s.source = "test:curve-shading";
    s.materials.push_back(diffuse_material(Rgb{1, 1, 1}, -1));
    Light sun;
    sun.type = LightKind::distant;
    sun.e1 = {0, 0, 1};
    sun.radiance = {2, 2, 2};
    s.lights.push_back(sun);
    const float a = 1, r = 0.05f;
    s.curves.push_back(straight_curve(type, a, 0.f, r));
    s.curves.back().material = 0;
    const int res = 64;
    const double pixel = head_on_camera(s, res, 6, 30);
    finalize_scene(s);
    const RenderResult out = render_scene(s, options(scaled(64u, 16u)));
    double sum = 0;
    for (int i = 0; i < res * res; ++i) sum += out.mean[3 * size_t(i)];
    const double mean_radiance = sum * pixel * pixel / (2 * a * 2 * r);
    const double expect = type == CurveType::cylinder ? 2.0 / 4 : 2.0 / M_PI;
    EXPECT_NEAR(mean_radiance / expect, 1.0, 0.02) << "type " << static_cast<int>(type);
  }
}

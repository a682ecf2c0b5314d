// The pbrt-v4 reader's Camera and Film directives: a perspective camera (its transform,
// field of view, frame aspect ratio and screen window) and the film's resolution and
// output name, with warnings for what tuile does not model (depth of field, crop windows).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>

#include "lexer.h"
#include "loader_state.h"
#include "params.h"
#include "util.h"

namespace tuile::pbrt {

void Loader::camera(Lexer& lx, const Token& t, Params& ps) {
  Camera& cam = scene.camera;
  Mat4 wfc;
  if (!invert(gs_.ctm, wfc)) lx.fail(t, "the camera transform is singular", "an invertible transform before Camera");
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 4; ++j) cam.world_from_camera[i][j] = float(wfc.m[i][j]);
  coord_systems_["camera"] = wfc;
  cam.fov_deg = ps.one_float("fov", 90);
  if (!(cam.fov_deg > 0 && cam.fov_deg < 180)) ps.get("fov", "float")->fail("fov out of range", "0 < fov < 180 degrees");
  if (const Param* fa = ps.get("frameaspectratio", "float")) {
    if (fa->nums.size() != 1) fa->fail("frameaspectratio has " + std::to_string(fa->nums.size()) + " values", "1 value");
    const float a = float(fa->nums[0]);
    if (!(a > 0)) fa->fail("frameaspectratio must be positive", "a positive ratio");
    if (a > 1) {
      cam.screen[0] = -a, cam.screen[1] = a, cam.screen[2] = -1, cam.screen[3] = 1;
    } else {
      cam.screen[0] = -1, cam.screen[1] = 1, cam.screen[2] = -1 / a, cam.screen[3] = 1 / a;
    }
  }
  if (const Param* sw = ps.get("screenwindow", "float")) {
    if (sw->nums.size() != 4) sw->fail("screenwindow has " + std::to_string(sw->nums.size()) + " values", "4 values: xmin xmax ymin ymax");
    if (!(sw->nums[0] < sw->nums[1] && sw->nums[2] < sw->nums[3])) sw->fail("screenwindow is empty", "xmin < xmax and ymin < ymax");
    for (int i = 0; i < 4; ++i) cam.screen[i] = float(sw->nums[i]);
  }
  // Embree takes rays whose origin lies within about 1.8e18 of the origin and whose
  // direction is finite: a camera far out, scaled beyond floats or with a screen window
  // billions of times its distance across would hand it rays it refuses (an abort)
  double far = 0, small = INFINITY, large = 0;
  for (int j = 0; j < 3; ++j) {
    far = std::max(far, std::abs(double(cam.world_from_camera[j][3])));
    double n2 = 0;
    for (int i = 0; i < 3; ++i) n2 += double(cam.world_from_camera[i][j]) * double(cam.world_from_camera[i][j]);
    small = std::min(small, std::sqrt(n2));
    large = std::max(large, std::sqrt(n2));
  }
  if (!(far <= 1e15) || !(small >= 1e-12) || !(large <= 1e12))
    lx.fail(t, "the camera's transform is out of range (its position beyond 1e15, its scale beyond 1e-12 to 1e12, or not finite)",
            "a camera within 1e15 of the origin, scaled by 1e-12 to 1e12");
  const double tan_half = std::tan(double(cam.fov_deg) * 3.14159265358979323846 / 360.0);
  double window = 0;
  for (int i = 0; i < 4; ++i) window = std::max(window, std::abs(double(cam.screen[i])));
  if (!(window * tan_half <= 1e6)) {  // (all zero: the film's aspect ratio, bounded by its resolution)
    char across[32];
    std::snprintf(across, sizeof across, "%.3g", window * tan_half);
    lx.fail(t, std::string("the screen window (frameaspectratio, screenwindow) is ") + across +
                   " times the camera's distance across",
            "a window of at most 1e6 at distance 1");
  }
  if (ps.one_float("lensradius", 0) > 0)
    warn("dof", loc_str(lx, t) + ": depth of field (lensradius) is not supported: the camera is a pinhole");
  ps.get("focaldistance", "float");
  ps.get("shutteropen", "float");
  ps.get("shutterclose", "float");
  warn_unused(ps, "Camera", lx, t);
  camera_medium_ = {"", gs_.medium_out, gs_.medium_where};  // pbrt-v4: the outside medium in force
}

void Loader::film(Lexer& lx, const Token& t, Params& ps) {
  const int w = ps.one_int("xresolution", 1280), h = ps.one_int("yresolution", 720);
  if (w <= 0 || w > 32768) ps.get("xresolution", "integer")->fail("xresolution " + std::to_string(w) + " out of range", "1 to 32768");
  if (h <= 0 || h > 32768) ps.get("yresolution", "integer")->fail("yresolution " + std::to_string(h) + " out of range", "1 to 32768");
  if (int64_t(w) * h > (int64_t(1) << 28))
    lx.fail(t, "film of " + std::to_string(w) + "x" + std::to_string(h) + " pixels is too large", "at most 2^28 pixels");
  scene.camera.width = w;
  scene.camera.height = h;
  scene.file_output = ps.one_string("filename", "");
  if (ps.get("cropwindow", "float") || ps.get("pixelbounds", "integer"))
    warn("crop", loc_str(lx, t) + ": Film cropwindow/pixelbounds are not supported: the full image is rendered");
  for (Param& p : ps.items)
    if (p.name == "iso" || p.name == "exposuretime" || p.name == "whitebalance" || p.name == "sensor" ||
        p.name == "maxcomponentvalue" || p.name == "savefp16" || p.name == "diagonal")
      p.used = true;
  warn_unused(ps, "Film", lx, t);
}

}  // namespace tuile::pbrt

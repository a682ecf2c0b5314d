// The pbrt-v4 reader's lights: AreaLightSource (diffuse, kept in the graphics state for
// the shapes that follow) and LightSource point, spot, distant and infinite (a constant L
// or an environment map, src/scene/sky_map.h; pbrt-v4's power and illuminance
// normalisations); other light types are ignored with a warning.
#include <algorithm>
#include <cmath>
#include <string>

#include "lexer.h"
#include "loader_state.h"
#include "params.h"
#include "scene/sky_map.h"
#include "util.h"

namespace tuile::pbrt {

void Loader::area_light(Lexer& lx, const Token& t, const std::string& type, Params& ps) {
  if (type != "diffuse") lx.fail(t, "unknown area light type \"" + type + "\"", "\"diffuse\"");
  AreaLight a;
  if (!ps.spectrum("L", true, a.L) && ps.get("L", "spectrum"))
    warn("namedspectrum", loc_str(lx, t) + ": named spectra are not supported; white used");
  const float s = ps.one_float("scale", 1);
  if (!(s >= 0)) ps.get("scale", "float")->fail("negative light scale", "a scale >= 0");
  a.L = mul(a.L, s);
  a.two_sided = ps.one_bool("twosided", false);
  a.power = ps.one_float("power", -1);
  if (!emission_in_range(a.L) || !(std::isfinite(a.power)))
    lx.fail(t, "the area light's emission (L times scale) or power is not finite or above 1e30", "values whose products fit a float");
  if (ps.get("filename", "string")) warn("arealightimage", loc_str(lx, t) + ": image area lights are not supported: L used");
  warn_unused(ps, "AreaLightSource", lx, t);
  gs_.has_area = true;
  gs_.area = a;
}

void Loader::light(Lexer& lx, const Token& t, const std::string& type, Params& ps) {
  const std::string where = loc_str(lx, t);
  if (object_ >= 0) {
    ps.mark_all_used();
    warn("instlight", where + ": light sources inside object definitions are not supported and were ignored");
    return;
  }
  if (type != "point" && type != "spot" && type != "distant" && type != "infinite") {
    ps.mark_all_used();
    warn("light:" + type, where + ": LightSource \"" + type + "\" is not supported and was ignored");
    return;
  }
  if (type == "infinite") {
    const Param* fp = ps.get("filename", "string");
    if (fp && fp->strs.size() == 1) {
      infinite_map(lx, t, resolve_path(lx.dir(), fp->strs[0]), ps);
      return;
    }
    if (fp) fp->fail("\"filename\" of an infinite light must be one string", "one file name");
  }
  const char* what = type == "distant" || type == "infinite" ? "L" : "I";
  Rgb c{1, 1, 1};
  if (!ps.spectrum(what, true, c) && ps.get(what, "spectrum")) warn("namedspectrum", where + ": named spectra are not supported; white used");
  const float s = ps.one_float("scale", 1);
  if (!(s >= 0)) ps.get("scale", "float")->fail("negative light scale", "a scale >= 0");
  double from[3] = {0, 0, 0}, to[3] = {0, 0, 1};
  ps.one_point("from", from);
  ps.one_point("to", to);
  Light l;
  const float lum = luminance(c);
  const Vec3d p = apply_point(gs_.ctm, {from[0], from[1], from[2]});
  if (type == "point") {
    l.type = LightKind::point;
    const float power = ps.one_float("power", -1);
    l.radiance = mul(c, s * (power > 0 && lum > 0 ? power / (4 * float(M_PI) * lum) : 1.f));
    l.p0 = vec3f(float(p.x), float(p.y), float(p.z));
    l.power = 4 * float(M_PI) * luminance(l.radiance);
  } else if (type == "spot") {
    l.type = LightKind::spot;
    const float cone = ps.one_float("coneangle", 30), delta = ps.one_float("conedeltaangle", 5);
    // pbrt-v4 takes a falloff that starts at coneangle - conedeltaangle, whose cosine is its
    // absolute value's: a conedeltaangle up to twice the cone is what pbrt-v4 renders
    if (!(cone >= 0 && cone <= 180 && delta >= 0 && delta <= 2 * cone) || (cone == 0 && delta > 0))
      lx.fail(t, "spot light cone angles out of range", "0 <= coneangle <= 180 and 0 <= conedeltaangle <= 2 coneangle");
    if (cone == 0) {  // (a cone of no width: pbrt-v4's emits nothing)
      warn("spot0:" + loc_str(lx, t), loc_str(lx, t) + ": a spot light of coneangle 0 emits nothing: left out");
      ps.mark_all_used();
      return;
    }
    if (delta > cone)
      warn("spotdelta", loc_str(lx, t) + ": conedeltaangle above coneangle: its falloff starts at |coneangle - conedeltaangle|, "
                                         "as pbrt-v4 reads it");
    const float cos_end = std::cos(cone * float(M_PI) / 180), cos_start = std::cos(std::abs(cone - delta) * float(M_PI) / 180);
    const float k_e = 2 * float(M_PI) * ((1 - cos_start) + (cos_start - cos_end) / 2);
    const float power = ps.one_float("power", -1);
    l.radiance = mul(c, s * (power > 0 && lum > 0 && k_e > 0 ? power / (k_e * lum) : 1.f));
    const Vec3d axis = normalized(apply_vector(gs_.ctm, {to[0] - from[0], to[1] - from[1], to[2] - from[2]}));
    if (length(axis) == 0) lx.fail(t, "spot light with from == to", "distinct from and to points");
    l.p0 = vec3f(float(p.x), float(p.y), float(p.z));
    l.e1 = vec3f(float(axis.x), float(axis.y), float(axis.z));
    l.e2 = vec3f(cos_start, cos_end, 0);
    l.power = k_e * luminance(l.radiance);
  } else if (type == "infinite") {
    // pbrt-v4's UniformInfiniteLight: radiance L scale, or, given "illuminance" E, the
    // radiance whose upper hemisphere gives a horizontal surface E (pi L)
    l.type = LightKind::infinite;
    const float e = ps.one_float("illuminance", -1);
    l.radiance = mul(c, s * (e > 0 && lum > 0 ? e / (float(M_PI) * lum) : 1.f));
  } else {
    l.type = LightKind::distant;
    const float e = ps.one_float("illuminance", -1);
    l.radiance = mul(c, s * (e > 0 && lum > 0 ? e / lum : 1.f));
    const Vec3d w = normalized(apply_vector(gs_.ctm, {from[0] - to[0], from[1] - to[1], from[2] - to[2]}));
    if (length(w) == 0) lx.fail(t, "distant light with from == to", "distinct from and to points");
    l.e1 = vec3f(float(w.x), float(w.y), float(w.z));
  }
  warn_unused(ps, "LightSource \"" + type + "\"", lx, t);
  if (!emission_in_range(l.radiance) || !std::isfinite(l.p0.x) || !std::isfinite(l.p0.y) || !std::isfinite(l.p0.z))
    lx.fail(t, "the light's emission (its " + std::string(what) + " times scale, power or illuminance) or position is not finite or above 1e30",
            "values whose products fit a float");
  if (l.type == LightKind::point || l.type == LightKind::spot)  // (resolved with the shapes' media: flatten)
    light_media_.push_back({scene.lights.size(), {"", gs_.medium_out, gs_.medium_where}});
  scene.lights.push_back(l);
}

// LightSource "infinite" with "filename": pbrt-v4's ImageInfiniteLight. The map's frame is
// the transform in force (its +z the map's centre), its radiance the texels times "scale"
// (or scaled so that its upper hemisphere gives "illuminance" to a surface facing +z of
// the frame, as pbrt-v4 normalises).
void Loader::infinite_map(Lexer& lx, const Token& t, const std::string& path, Params& ps) {
  const std::string where = loc_str(lx, t);
  if (ps.get("L", "rgb") || ps.get("L", "spectrum") || ps.get("L", "blackbody"))
    lx.fail(t, "an infinite light with both \"L\" and \"filename\"", "one of them (pbrt-v4 reads either)");
  const float s = ps.one_float("scale", 1);
  if (!(s >= 0) || !std::isfinite(s)) ps.get("scale", "float")->fail("negative or non-finite light scale", "a scale >= 0");
  const float e = ps.one_float("illuminance", -1);
  if (std::isnan(e) || std::isinf(e)) ps.get("illuminance", "float")->fail("non-finite illuminance", "a finite illuminance");
  if (const Param* portal = ps.get("portal", "point3")) {
    (void)portal;
    warn("light:infinite-portal", where + ": the \"portal\" of an infinite light is not used: its map is sampled over the "
                                  "whole sphere (unbiased, noisier where the portal is small)");
  }
  RgbImage img;
  std::string reason;
  scene.inputs.push_back(path);
  if (!read_rgb_image(path, img, reason)) lx.fail(t, "cannot read the infinite light's image \"" + path + "\": " + reason, "an existing, readable PFM, EXR, HDR or 8/16-bit image");
  SkyMap map;
  if (!make_sky_map(path, img, map, reason)) lx.fail(t, "infinite light's image \"" + path + "\": " + reason, "an equal-area (square) map of finite, non-negative texels");
  float k = s;
  if (e > 0) {
    const double ez = sky_map_upper_illuminance(map);
    if (ez > 0) k *= static_cast<float>(e / ez);
  }
  const float brightest = img.rgb.empty() ? 0.f : *std::max_element(img.rgb.begin(), img.rgb.end());
  if (!std::isfinite(k) || !(double(brightest) * k <= 1e30))
    lx.fail(t, "the infinite light's brightest texel of \"" + path + "\" times its scale or illuminance is above 1e30",
            "a radiance whose product with scale fits a float");
  // the frame: the transform's axes, made orthonormal (keeping a reflection's handedness)
  const Vec3d cx = apply_vector(gs_.ctm, {1, 0, 0}), cy = apply_vector(gs_.ctm, {0, 1, 0}), cz = apply_vector(gs_.ctm, {0, 0, 1});
  const double lx_ = length(cx), ly_ = length(cy), lz_ = length(cz);
  if (!(lx_ > 0 && ly_ > 0 && lz_ > 0)) lx.fail(t, "the transform of an infinite light is singular", "a rotation");
  const Vec3d ex = normalized(cx);
  const Vec3d ey = normalized(sub(cy, {ex.x * dot(cy, ex), ex.y * dot(cy, ex), ex.z * dot(cy, ex)}));
  Vec3d ez = cross(ex, ey);
  if (dot(ez, cz) < 0) ez = {-ez.x, -ez.y, -ez.z};
  const double tol = 1e-3 * std::max(lx_, std::max(ly_, lz_));
  if (std::abs(lx_ - ly_) > tol || std::abs(lx_ - lz_) > tol || std::abs(dot(cx, cy)) > tol * lx_ ||
      std::abs(dot(cx, cz)) > tol * lx_ || std::abs(dot(cy, cz)) > tol * ly_)
    warn("light:infinite-frame", where + ": the transform of an infinite light scales or shears: only its rotation is used");
  warn_unused(ps, "LightSource \"infinite\"", lx, t);
  Light l;
  l.type = LightKind::infinite;
  l.radiance = {k, k, k};
  l.e1 = vec3f(float(ex.x), float(ex.y), float(ex.z));
  l.e2 = vec3f(float(ey.x), float(ey.y), float(ey.z));
  l.p0 = vec3f(float(ez.x), float(ez.y), float(ez.z));
  l.sky_map = static_cast<int>(scene.sky_maps.size());
  scene.sky_maps.push_back(std::move(map));
  scene.lights.push_back(l);
}

}  // namespace tuile::pbrt

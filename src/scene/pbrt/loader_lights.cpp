// The pbrt-v4 reader's lights: AreaLightSource (diffuse, kept in the graphics state for
// the shapes that follow) and LightSource point, spot, distant and infinite with a constant
// L (pbrt-v4's power and illuminance normalisations); other light types, and infinite
// lights with an image, are ignored with a warning.
#include <cmath>
#include <string>

#include "lexer.h"
#include "loader_state.h"
#include "params.h"
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
  if (type == "infinite" && (ps.get("filename", "string") || ps.get("portal", "point3"))) {
    ps.mark_all_used();
    warn("light:infinite-map", where + ": LightSource \"infinite\" with an image (\"filename\") is not supported and was ignored");
    return;
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
    if (!(cone > 0 && cone <= 180 && delta >= 0 && delta <= cone))
      lx.fail(t, "spot light cone angles out of range", "0 < coneangle <= 180 and 0 <= conedeltaangle <= coneangle");
    const float cos_end = std::cos(cone * float(M_PI) / 180), cos_start = std::cos((cone - delta) * float(M_PI) / 180);
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
  scene.lights.push_back(l);
}

}  // namespace tuile::pbrt

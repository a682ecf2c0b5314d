// The pbrt-v4 reader's directive parser: directives are executed as they are read,
// against a graphics state (transform, material, area light, orientation) kept on an
// attribute stack; Include/Import push a lexer. Files named by the scene (PLY meshes,
// texture images) are only recorded while parsing; at the end (finish) they are read in
// parallel (loader_files.cpp), then textures are resolved (loader_materials.cpp), object
// instances flattened and area-light powers applied (loader_shapes.cpp). Also the public
// entry points load_pbrt and load_pbrt_string.
#include <cmath>
#include <memory>
#include <string>

#include "scene/pbrt.h"
#include "lexer.h"
#include "loader_state.h"
#include "params.h"
#include "render/filter_table.h"
#include "util.h"

namespace tuile {
namespace pbrt {
namespace {

constexpr int max_include_depth = 64;

}  // namespace

std::string loc_str(const Lexer& lx, const Token& t) { return lx.file() + ":" + std::to_string(t.line); }

void Loader::warn(const std::string& key, const std::string& message) {
  if (warned_.insert(key).second) scene.warnings.push_back(message);
}

void Loader::note(const std::string& key, const std::string& message) {
  if (warned_.insert(key).second) scene.notes.push_back(message);
}

void Loader::warn_unused(Params& ps, const std::string& what, const Lexer& lx, const Token& at) {
  for (Param& p : ps.items)
    if (!p.used)
      warn("param:" + what + ":" + p.name, loc_str(lx, at) + ": parameter \"" + p.type + " " + p.name + "\" of " + what +
                                               " is not supported by tuile and was ignored");
}

double Loader::number(Lexer& lx) { return parse_number(lx, lx.next()); }

void Loader::numbers(Lexer& lx, double* out, int n) {
  const bool bracket = lx.peek().kind == Tok::lbracket;
  if (bracket) lx.next();
  for (int i = 0; i < n; ++i) out[i] = number(lx);
  if (bracket) {
    const Token t = lx.next();
    if (t.kind != Tok::rbracket) lx.fail(t, "unexpected " + describe(t), "']' after " + std::to_string(n) + " numbers");
  }
}

std::string Loader::string_arg(Lexer& lx, const char* what) {
  const Token t = lx.next();
  if (t.kind != Tok::string) lx.fail(t, "unexpected " + describe(t), std::string("a quoted ") + what);
  return unescape(t.text);
}

void Loader::require_world(Lexer& lx, const Token& t, bool world) {
  if (world && !in_world_) lx.fail(t, std::string(t.text) + " before WorldBegin", "WorldBegin before scene content");
  if (!world && in_world_) lx.fail(t, std::string(t.text) + " after WorldBegin", "camera and render options before WorldBegin");
}

void Loader::include(Lexer& lx, const Token& t) {
  const Token nt = lx.next();
  if (nt.kind != Tok::string) lx.fail(nt, "unexpected " + describe(nt), "a quoted file name after " + std::string(t.text));
  if (lexers_.size() >= max_include_depth) lx.fail(t, "includes nested too deeply", "fewer than 64 nested includes");
  const std::string path = resolve_path(lx.dir(), unescape(nt.text));
  std::string text, reason;
  if (!read_file(path, text, reason))
    lx.fail(nt, "cannot read included file '" + path + "': " + reason, "an existing, readable file");
  scene.inputs.push_back(path);
  lexers_.push_back(std::make_unique<Lexer>(std::move(text), path, parent_dir(path)));
}

void Loader::run(std::unique_ptr<Lexer> main) {
  lexers_.push_back(std::move(main));
  Token eof;
  for (;;) {
    Lexer& lx = *lexers_.back();
    const Token t = lx.next();
    if (t.kind == Tok::eof) {
      if (lexers_.size() == 1) {
        eof = t;
        break;
      }
      lexers_.pop_back();
      continue;
    }
    if (t.kind != Tok::word) lx.fail(t, "unexpected " + describe(t), "a directive such as Shape or AttributeBegin");
    directive(lx, t);
  }
  Lexer& lx = *lexers_.back();
  if (!stack_.empty()) {
    const StackEntry& e = stack_.back();
    const char* what = e.kind == 'A' ? "AttributeBegin" : e.kind == 'T' ? "TransformBegin" : "ObjectBegin";
    const char* end = e.kind == 'A' ? "AttributeEnd" : e.kind == 'T' ? "TransformEnd" : "ObjectEnd";
    lx.fail(eof, std::string(what) + " at " + e.where + " is not closed", std::string(end) + " before the end of the file");
  }
  finish();
}

void Loader::directive(Lexer& lx, const Token& t) {
  const std::string_view d = t.text;
  const std::string where = loc_str(lx, t);
  auto apply = [&](const Mat4& m) { gs_.ctm = gs_.ctm * m; };
  if (d == "Identity") {
    gs_.ctm = Mat4::identity();
  } else if (d == "Translate") {
    double v[3];
    numbers(lx, v, 3);
    apply(translate(v[0], v[1], v[2]));
  } else if (d == "Scale") {
    double v[3];
    numbers(lx, v, 3);
    apply(scale(v[0], v[1], v[2]));
  } else if (d == "Rotate") {
    double v[4];
    numbers(lx, v, 4);
    if (v[1] == 0 && v[2] == 0 && v[3] == 0) lx.fail(t, "Rotate about a zero axis", "a non-zero rotation axis");
    apply(rotate(v[0], v[1], v[2], v[3]));
  } else if (d == "LookAt") {
    double v[9];
    numbers(lx, v, 9);
    const Vec3d eye{v[0], v[1], v[2]}, look{v[3], v[4], v[5]}, up{v[6], v[7], v[8]};
    const Vec3d dir = normalized(sub(look, eye));
    const Vec3d right0 = cross(normalized(up), dir);
    if (length(dir) == 0 || !(length(right0) > 1e-12))
      lx.fail(t, "LookAt with the eye at the target or the up vector along the view direction",
              "distinct eye and target and an up vector not parallel to the view direction");
    const Vec3d right = normalized(right0);
    const Vec3d new_up = cross(dir, right);
    Mat4 world_from_camera;
    const Vec3d cols[4] = {right, new_up, dir, eye};
    for (int c = 0; c < 4; ++c) {
      world_from_camera.m[0][c] = cols[c].x;
      world_from_camera.m[1][c] = cols[c].y;
      world_from_camera.m[2][c] = cols[c].z;
    }
    Mat4 camera_from_world;
    invert(world_from_camera, camera_from_world);
    apply(camera_from_world);
  } else if (d == "Transform" || d == "ConcatTransform") {
    double v[16];
    numbers(lx, v, 16);
    Mat4 m;
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) m.m[i][j] = v[4 * j + i];  // the file is column-major
    if (d == "Transform") gs_.ctm = m;
    else apply(m);
  } else if (d == "CoordinateSystem") {
    coord_systems_[string_arg(lx, "coordinate system name")] = gs_.ctm;
  } else if (d == "CoordSysTransform") {
    const std::string name = string_arg(lx, "coordinate system name");
    auto it = coord_systems_.find(name);
    if (it == coord_systems_.end()) warn("coordsys:" + name, where + ": unknown coordinate system '" + name + "' ignored");
    else gs_.ctm = it->second;
  } else if (d == "ReverseOrientation") {
    gs_.reverse = !gs_.reverse;
  } else if (d == "AttributeBegin" || d == "TransformBegin") {
    if (stack_.size() > 100000) lx.fail(t, "attributes nested too deeply", "fewer than 100000 nested AttributeBegin");
    stack_.push_back({gs_, d == "AttributeBegin" ? 'A' : 'T', where + ":" + std::to_string(t.col)});
  } else if (d == "AttributeEnd" || d == "TransformEnd") {
    const char kind = d == "AttributeEnd" ? 'A' : 'T';
    const char* begin = kind == 'A' ? "AttributeBegin" : "TransformBegin";
    if (stack_.empty() || stack_.back().kind != kind)
      lx.fail(t, std::string(d) + " without a matching " + begin,
              stack_.empty() ? std::string("a preceding ") + begin
                             : std::string("the end of the block opened at ") + stack_.back().where);
    if (kind == 'A') gs_ = stack_.back().gs;
    else gs_.ctm = stack_.back().gs.ctm;
    stack_.pop_back();
  } else if (d == "WorldBegin") {
    if (in_world_) lx.fail(t, "second WorldBegin", "a single WorldBegin");
    in_world_ = seen_world_ = true;
    gs_.ctm = Mat4::identity();
    coord_systems_["world"] = gs_.ctm;
  } else if (d == "WorldEnd") {
    // pbrt-v3 files end the world block explicitly; v4 has no WorldEnd.
  } else if (d == "Include" || d == "Import") {
    include(lx, t);
  } else if (d == "Camera") {
    require_world(lx, t, false);
    const std::string type = string_arg(lx, "camera type");
    Params ps = read_params(lx);
    if (type != "perspective") lx.fail(t, "unsupported camera type '" + type + "'", "\"perspective\"");
    camera(lx, t, ps);
  } else if (d == "Film") {
    require_world(lx, t, false);
    const std::string type = string_arg(lx, "film type");
    Params ps = read_params(lx);
    if (type != "rgb") warn("film:" + type, where + ": Film \"" + type + "\" is read as an RGB film");
    film(lx, t, ps);
  } else if (d == "Sampler") {
    require_world(lx, t, false);
    const std::string type = string_arg(lx, "sampler type");
    Params ps = read_params(lx);
    scene.file_spp = ps.one_int("pixelsamples", 16);
    if (scene.file_spp <= 0 || scene.file_spp > (1 << 24))
      ps.get("pixelsamples", "integer")->fail("pixelsamples out of range", "1 to 2^24 samples per pixel");
    if (type == "independent" || type == "stratified") scene.file_sampler = type;
    else if (type == "sobol" || type == "zsobol" || type == "paddedsobol" || type == "halton" || type == "pmj02bn")
      scene.file_sampler = "sobol";
    else warn("sampler:" + type, where + ": unknown sampler \"" + type + "\" ignored");
    ps.mark_all_used();
  } else if (d == "PixelFilter") {
    require_world(lx, t, false);
    const std::string type = string_arg(lx, "filter type");
    Params ps = read_params(lx);
    FilterKind kind;
    if (!filter_kind_from_name(type, kind))
      lx.fail(t, "unknown PixelFilter \"" + type + "\"", "box, triangle, gaussian, mitchell or sinc");
    // pbrt-v4's parameters and defaults (filters.cpp); a bad value is an error at its line
    FilterParams f = default_filter(kind);
    f.xradius = ps.one_float("xradius", f.xradius);
    f.yradius = ps.one_float("yradius", f.yradius);
    if (kind == FilterKind::gaussian) f.sigma = ps.one_float("sigma", f.sigma);
    if (kind == FilterKind::mitchell) {
      f.b = ps.one_float("B", f.b);
      f.c = ps.one_float("C", f.c);
    }
    if (kind == FilterKind::sinc) f.tau = ps.one_float("tau", f.tau);
    std::string param;
    const std::string problem = filter_problem(f, &param);
    if (!problem.empty()) {
      const Param* p = ps.get(param, "float");
      if (p) p->fail("PixelFilter \"" + type + "\": " + param + " out of range", problem);
      lx.fail(t, "PixelFilter \"" + type + "\": " + param + " out of range", problem);
    }
    scene.file_filter = f;
    warn_unused(ps, "PixelFilter \"" + type + "\"", lx, t);
  } else if (d == "Integrator") {
    require_world(lx, t, false);
    const std::string type = string_arg(lx, "integrator type");
    Params ps = read_params(lx);
    const std::string pick = ps.one_string("lightsampler", "");
    if (pick == "uniform" || pick == "power" || pick == "bvh") scene.file_light_pick = pick;
    else if (!pick.empty()) warn("lightsampler", where + ": unknown lightsampler \"" + pick + "\" ignored");
    const int depth = ps.one_int("maxdepth", 5);
    if (depth < 1 || depth > 100000) {
      const Param* p = ps.get("maxdepth", "integer");
      if (p) p->fail("Integrator \"" + type + "\": maxdepth " + std::to_string(depth) + " out of range", "1..100000");
      lx.fail(t, "Integrator maxdepth out of range", "1..100000");
    }
    scene.file_max_depth = depth;
    scene.file_regularize = ps.one_bool("regularize", false);
    scene.file_integrator = type;
    // (bdpt: tuile's own where it renders the scene, else a warning from the options: cli.cpp)
    if (type != "path" && type != "volpath" && type != "simplepath" && type != "bdpt")
      warn("integrator", where + ": Integrator \"" + type + "\" rendered by tuile's path tracer (next-event estimation "
                             "and MIS at every vertex, maxdepth " + std::to_string(depth) + ")");
    ps.mark_all_used();
  } else if (d == "MakeNamedMedium") {
    const std::string name = string_arg(lx, "medium name");
    Params ps = read_params(lx);
    make_medium(lx, t, name, ps);
  } else if (d == "Accelerator" || d == "ColorSpace") {
    string_arg(lx, "name");
    read_params(lx);
    warn(std::string(d), where + ": " + std::string(d) + " ignored");
  } else if (d == "Option") {
    read_params(lx);
    warn("Option", where + ": Option ignored");
  } else if (d == "MediumInterface") {
    // "inside" "outside", or one name for both; "" is no medium
    gs_.medium_in = string_arg(lx, "medium name");
    gs_.medium_out = lx.peek().kind == Tok::string ? string_arg(lx, "medium name") : gs_.medium_in;
    gs_.medium_where = where;
  } else if (d == "Attribute") {
    string_arg(lx, "attribute target");
    read_params(lx);
    warn("Attribute", where + ": Attribute ignored");
  } else if (d == "TransformTimes") {
    double v[2];
    numbers(lx, v, 2);
    warn("motion", where + ": motion blur (TransformTimes/ActiveTransform) is not supported and was ignored");
  } else if (d == "ActiveTransform") {
    const Token a = lx.next();
    if (a.kind != Tok::word || (a.text != "StartTime" && a.text != "EndTime" && a.text != "All"))
      lx.fail(a, "unexpected " + describe(a), "StartTime, EndTime or All");
    warn("motion", where + ": motion blur (TransformTimes/ActiveTransform) is not supported and was ignored");
  } else if (d == "Material") {
    require_world(lx, t, true);
    const std::string type = string_arg(lx, "material type");
    Params ps = read_params(lx);
    gs_.material = make_material(lx, t, type, ps);
  } else if (d == "MakeNamedMaterial") {
    require_world(lx, t, true);
    const std::string name = string_arg(lx, "material name");
    Params ps = read_params(lx);
    const Param* tp = ps.get("type", "string");
    if (!tp || tp->strs.size() != 1) lx.fail(t, "MakeNamedMaterial \"" + name + "\" without a type", "a \"string type\" parameter");
    const int m = make_material(lx, t, tp->strs[0], ps);
    if (named_materials_.count(name)) warn("redefined:" + name, where + ": named material \"" + name + "\" redefined");
    named_materials_[name] = m;
  } else if (d == "NamedMaterial") {
    require_world(lx, t, true);
    const Token nt = lx.peek();
    const std::string name = string_arg(lx, "material name");
    auto it = named_materials_.find(name);
    if (it == named_materials_.end()) lx.fail(nt, "unknown named material \"" + name + "\"", "a name defined by MakeNamedMaterial");
    gs_.material = it->second;
  } else if (d == "Texture") {
    require_world(lx, t, true);
    texture(lx, t);
  } else if (d == "AreaLightSource") {
    require_world(lx, t, true);
    const std::string type = string_arg(lx, "area light type");
    Params ps = read_params(lx);
    area_light(lx, t, type, ps);
  } else if (d == "LightSource") {
    require_world(lx, t, true);
    const std::string type = string_arg(lx, "light type");
    Params ps = read_params(lx);
    light(lx, t, type, ps);
  } else if (d == "Shape") {
    require_world(lx, t, true);
    const std::string type = string_arg(lx, "shape type");
    Params ps = read_params(lx);
    shape(lx, t, type, ps);
  } else if (d == "ObjectBegin") {
    require_world(lx, t, true);
    const Token nt = lx.peek();
    const std::string name = string_arg(lx, "object name");
    if (object_ >= 0) lx.fail(t, "ObjectBegin inside the definition of object \"" + object_names_[object_] + "\"", "ObjectEnd first");
    stack_.push_back({gs_, 'O', where + ":" + std::to_string(t.col)});
    if (objects_.count(name)) lx.fail(nt, "object \"" + name + "\" redefined", "a new object name");
    object_ = int(object_names_.size());
    objects_[name] = object_;
    object_names_.push_back(name);
  } else if (d == "ObjectEnd") {
    if (object_ < 0 || stack_.empty() || stack_.back().kind != 'O')
      lx.fail(t, "ObjectEnd without a matching ObjectBegin", "a preceding ObjectBegin");
    gs_ = stack_.back().gs;
    stack_.pop_back();
    object_ = -1;
  } else if (d == "ObjectInstance") {
    require_world(lx, t, true);
    const Token nt = lx.peek();
    const std::string name = string_arg(lx, "object name");
    if (object_ >= 0) lx.fail(t, "ObjectInstance inside an object definition", "ObjectInstance outside ObjectBegin/ObjectEnd");
    auto it = objects_.find(name);
    if (it == objects_.end()) lx.fail(nt, "unknown object \"" + name + "\"", "a name defined by ObjectBegin");
    if (instances_.size() >= (size_t(1) << 24)) lx.fail(t, "too many object instances", "fewer than 2^24 instances");
    const double det = gs_.ctm.det3();
    if (!gs_.ctm.is_affine() || !(std::abs(det) > 1e-30) || !std::isfinite(det))
      lx.fail(t, "singular or projective transform for the instance of \"" + name + "\" (determinant " + std::to_string(det) + ")",
              "an invertible affine transform");
    instances_.push_back({it->second, gs_.ctm, where});
  } else {
    lx.fail(t, "unknown directive " + describe(t), "a pbrt-v4 directive such as Shape, Material or AttributeBegin");
  }
}

void Loader::finish() {
  load_files();
  bake_materials();
  flatten();
}

namespace {

Scene load(std::unique_ptr<Lexer> lx, const std::string& source, const LoadOptions& options) {
  Loader l;
  l.strict = options.strict;
  l.scene.source = source;
  l.scene.file_max_depth = 5;  // pbrt-v4's integrator when the file names none: volpath, maxdepth 5
  l.run(std::move(lx));
  return std::move(l.scene);
}

}  // namespace
}  // namespace pbrt

Scene load_pbrt(const std::string& path, const LoadOptions& options) {
  std::string text, reason;
  if (!pbrt::read_file(path, text, reason))
    throw SceneError(path + ":1:1: error: cannot read scene file: " + reason + " (expected an existing, readable .pbrt file)");
  Scene s = pbrt::load(std::make_unique<pbrt::Lexer>(std::move(text), path, pbrt::parent_dir(path)), path, options);
  s.inputs.insert(s.inputs.begin(), path);
  return s;
}

Scene load_pbrt_string(const std::string& text, const std::string& virtual_name, const std::string& base_dir,
                       const LoadOptions& options) {
  return pbrt::load(std::make_unique<pbrt::Lexer>(text, virtual_name, base_dir), virtual_name, options);
}

}  // namespace tuile

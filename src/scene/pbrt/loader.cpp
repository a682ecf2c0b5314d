// The pbrt-v4 reader: directives are executed as they are read, against a graphics
// state (transform, material, area light, orientation) kept on an attribute stack.
// Files named by the scene (PLY meshes, texture images) are only recorded while parsing;
// at the end they are read in parallel (oneTBB), then textures are resolved, object
// instances flattened and area-light powers applied.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <filesystem>
#include <map>
#include <memory>
#include <set>
#include <unordered_map>

#include "scene/pbrt.h"
#include "image.h"
#include "lexer.h"
#include "params.h"
#include "ply.h"
#include "util.h"

namespace tuile {
namespace pbrt {
namespace {

constexpr int max_include_depth = 64;
constexpr int disk_segments = 64;
constexpr size_t max_triangles = size_t(1) << 31;

std::string loc_str(const Lexer& lx, const Token& t) { return lx.file() + ":" + std::to_string(t.line); }

struct AreaLight {
  Rgb L{1, 1, 1};
  float power = -1;
  bool two_sided = false;
};

struct GraphicsState {
  Mat4 ctm;
  bool reverse = false;
  int material = -1;
  bool has_area = false;
  AreaLight area;
};

struct StackEntry {
  GraphicsState gs;
  char kind;  // 'A' AttributeBegin, 'T' TransformBegin, 'O' ObjectBegin
  std::string where;
};

// A texture as defined in the file, resolved to an image or a constant at the end.
struct TexDef {
  enum Kind { constant, image, checker, mix } kind = constant;
  Rgb value{0.5f, 0.5f, 0.5f};
  float scale = 1;
  int job = -1;          // image: index into image jobs
  int a = -1, b = -1;    // checker / mix operands (TexDef indices)
  float amount = 0.5f;   // mix
  float uscale = 1, vscale = 1, udelta = 0, vdelta = 0;
  std::string name, where;
};

struct ImageJob {
  std::string path, encoding, where;
  bool needed = false, ok = false;
  std::string reason;
  Texture tex;
  int scene_index = -1;
};

struct PlyJob {
  size_t mesh;  // index into Loader::meshes_
  std::string path, where_file;
  int line, col;
  Mat4 ctm;
  bool ro;
  size_t degenerate = 0, polygons = 0;
  std::string error, expected;
  uintmax_t size = 0;
};

struct OwnedMesh {
  Mesh mesh;
  int object = -1;        // -1 = world, otherwise an object definition
  float power = -1;       // area light power to apply once the area is known
  std::string power_where;
};

struct OwnedSphere {
  Sphere sphere;
  int object = -1;
};

struct Instance {
  int object;
  Mat4 ctm;
};

struct Resolved {
  bool image = false;
  Rgb value{0.5f, 0.5f, 0.5f};
  int texture = -1;
};

class Loader {
 public:
  Scene scene;
  void run(std::unique_ptr<Lexer> main);

 private:
  void directive(Lexer& lx, const Token& t);
  void warn(const std::string& key, const std::string& message);
  void warn_unused(Params& ps, const std::string& what, const Lexer& lx, const Token& at);
  double number(Lexer& lx);
  void numbers(Lexer& lx, double* out, int n);
  std::string string_arg(Lexer& lx, const char* what);
  void require_world(Lexer& lx, const Token& t, bool world);
  void include(Lexer& lx, const Token& t);

  void camera(Lexer& lx, const Token& t, Params& ps);
  void film(Lexer& lx, const Token& t, Params& ps);
  int make_material(Lexer& lx, const Token& t, const std::string& type, Params& ps);
  int reflectance_texture(Lexer& lx, const Param& p);
  void texture(Lexer& lx, const Token& t);
  int tex_operand(Lexer& lx, Params& ps, const std::string& name, Rgb def);
  void area_light(Lexer& lx, const Token& t, const std::string& type, Params& ps);
  void light(Lexer& lx, const Token& t, const std::string& type, Params& ps);
  void shape(Lexer& lx, const Token& t, const std::string& type, Params& ps);
  size_t new_mesh(Lexer& lx, const Token& t);
  void set_emission(OwnedMesh& om, Lexer& lx, const Token& t);
  void orient_by_normals(Mesh& m, const std::vector<float>& n_obj, const Mat4& ctm, bool ro);

  void finish();
  void load_files();
  Resolved resolve(int td, int depth = 0);
  void bake_materials();
  void flatten();

  std::vector<std::unique_ptr<Lexer>> lexers_;
  GraphicsState gs_;
  std::vector<StackEntry> stack_;
  bool in_world_ = false, seen_world_ = false;
  int object_ = -1;  // object being defined
  std::map<std::string, Mat4> coord_systems_;
  std::unordered_map<std::string, int> named_materials_;
  std::unordered_map<std::string, int> textures_;       // spectrum textures by name
  std::unordered_map<std::string, int> float_textures_;
  std::unordered_map<std::string, int> objects_;
  std::vector<std::string> object_names_;
  std::vector<TexDef> texdefs_;
  std::vector<int> material_tex_;  // per scene material: TexDef index or -1
  std::vector<ImageJob> images_;
  std::map<std::pair<std::string, std::string>, int> image_by_path_;
  std::vector<PlyJob> plys_;
  std::vector<OwnedMesh> meshes_;
  std::vector<OwnedSphere> spheres_;
  std::vector<Instance> instances_;
  std::map<int, Resolved> resolved_;
  std::set<std::string> warned_;
  std::string camera_where_;
};

void Loader::warn(const std::string& key, const std::string& message) {
  if (warned_.insert(key).second) scene.warnings.push_back(message);
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
    if (type != "box") warn("filter", where + ": PixelFilter \"" + type + "\" approximated by tuile's box filter");
  } else if (d == "Integrator") {
    require_world(lx, t, false);
    const std::string type = string_arg(lx, "integrator type");
    Params ps = read_params(lx);
    const std::string pick = ps.one_string("lightsampler", "");
    if (pick == "uniform" || pick == "power") scene.file_light_pick = pick;
    else if (pick == "bvh") {
      scene.file_light_pick = "power";
      warn("lightsampler", where + ": lightsampler \"bvh\" replaced by power-proportional light selection");
    } else if (!pick.empty()) warn("lightsampler", where + ": unknown lightsampler \"" + pick + "\" ignored");
    const int depth = ps.one_int("maxdepth", 5);
    if (depth != 1 || (type != "path" && type != "volpath" && type != "simplepath"))
      warn("integrator", where + ": Integrator \"" + type + "\" (maxdepth " + std::to_string(depth) +
                             "): tuile computes direct lighting only");
    ps.mark_all_used();
  } else if (d == "Accelerator" || d == "ColorSpace" || d == "MakeNamedMedium") {
    string_arg(lx, "name");
    read_params(lx);
    warn(std::string(d), where + ": " + std::string(d) + " ignored");
  } else if (d == "Option") {
    read_params(lx);
    warn("Option", where + ": Option ignored");
  } else if (d == "MediumInterface") {
    string_arg(lx, "medium name");
    if (lx.peek().kind == Tok::string) lx.next();
    warn("medium", where + ": participating media are not supported and were ignored");
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
    instances_.push_back({it->second, gs_.ctm});
  } else {
    lx.fail(t, "unknown directive " + describe(t), "a pbrt-v4 directive such as Shape, Material or AttributeBegin");
  }
}

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
  if (ps.one_float("lensradius", 0) > 0)
    warn("dof", loc_str(lx, t) + ": depth of field (lensradius) is not supported: the camera is a pinhole");
  ps.get("focaldistance", "float");
  ps.get("shutteropen", "float");
  ps.get("shutterclose", "float");
  warn_unused(ps, "Camera", lx, t);
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

// A "texture reflectance" parameter: the TexDef index, or an error naming the texture.
int Loader::reflectance_texture(Lexer&, const Param& p) {
  if (p.strs.size() != 1) p.fail("parameter \"texture " + p.name + "\" has " + std::to_string(p.count()) + " values", "1 texture name");
  auto it = textures_.find(p.strs[0]);
  if (it != textures_.end()) return it->second;
  if (float_textures_.count(p.strs[0]))
    p.fail("texture \"" + p.strs[0] + "\" is a float texture", "a spectrum texture for " + p.name);
  p.fail("unknown texture \"" + p.strs[0] + "\"", "a name defined by Texture before its use");
}

int Loader::make_material(Lexer& lx, const Token& t, const std::string& type, Params& ps) {
  const std::string where = loc_str(lx, t);
  Material m;
  int tex = -1;
  auto read_reflectance = [&](const char* name) {
    const Param* p = ps.get(name, "rgb|blackbody|spectrum|texture");
    if (!p) return false;
    if (p->type == "texture") {
      tex = reflectance_texture(lx, *p);
    } else if (!ps.spectrum(name, false, m.reflectance)) {
      warn("namedspectrum", where + ": named spectra are not supported; grey 0.5 used");
    }
    return true;
  };
  if (type == "diffuse") {
    read_reflectance("reflectance");
    for (Param& p : ps.items)
      if (p.name == "displacement" || p.name == "normalmap") {
        p.used = true;
        warn("bump", where + ": displacement and normal maps are not supported and were ignored");
      }
    warn_unused(ps, "Material \"diffuse\"", lx, t);
  } else if (type == "mix") {
    const Param* mp = ps.get("materials", "string");
    auto it = mp && mp->strs.size() == 2 ? named_materials_.find(mp->strs[0]) : named_materials_.end();
    ps.mark_all_used();
    warn("material:mix", where + ": material \"mix\" approximated by its first material");
    if (it != named_materials_.end()) {
      m = scene.materials[size_t(it->second)];
      tex = material_tex_[size_t(it->second)];
    }
    if (m.approximated_from.empty()) m.approximated_from = "mix";
  } else {
    const bool found = read_reflectance("reflectance") || (ps.get("Kd", "rgb|spectrum|texture") && read_reflectance("Kd"));
    m.approximated_from = type.empty() ? "none" : type;
    ps.mark_all_used();
    warn("material:" + type, where + ": material \"" + type + "\" approximated as diffuse (" +
                                 (found ? "its reflectance" : "grey 0.5") + ")");
  }
  scene.materials.push_back(m);
  material_tex_.push_back(tex);
  return int(scene.materials.size() - 1);
}

int Loader::tex_operand(Lexer& lx, Params& ps, const std::string& name, Rgb def) {
  const Param* p = ps.get(name, "rgb|blackbody|spectrum|texture|float");
  TexDef d;
  d.value = def;
  if (p) {
    if (p->type == "texture") return reflectance_texture(lx, *p);
    if (p->type == "float") {
      if (p->nums.size() != 1) p->fail("parameter \"float " + name + "\" has " + std::to_string(p->nums.size()) + " values", "1 value");
      const float v = float(p->nums[0]);
      d.value = {v, v, v};
    } else {
      ps.spectrum(name, false, d.value);
    }
  }
  texdefs_.push_back(d);
  return int(texdefs_.size() - 1);
}

void Loader::texture(Lexer& lx, const Token& t) {
  const std::string where = loc_str(lx, t);
  const std::string name = string_arg(lx, "texture name");
  const std::string kind = string_arg(lx, "texture type (\"spectrum\" or \"float\")");
  const std::string cls = string_arg(lx, "texture class");
  Params ps = read_params(lx);
  if (kind == "float") {
    ps.mark_all_used();
    float_textures_[name] = 0;
    warn("floattex", where + ": float textures (bump maps, roughness) are not supported and were ignored");
    return;
  }
  if (kind != "spectrum" && kind != "color") lx.fail(t, "unknown texture type \"" + kind + "\"", "\"spectrum\" or \"float\"");
  TexDef d;
  d.name = name;
  d.where = where;
  if (cls == "imagemap") {
    const Param* fp = ps.get("filename", "string");
    if (!fp || fp->strs.size() != 1) lx.fail(t, "imagemap texture \"" + name + "\" without a filename", "a \"string filename\" parameter");
    const std::string path = resolve_path(lx.dir(), fp->strs[0]);
    const std::string enc = ps.one_string("encoding", "sRGB");
    d.kind = TexDef::image;
    d.scale = ps.one_float("scale", 1);
    auto key = std::make_pair(path, enc);
    auto it = image_by_path_.find(key);
    if (it == image_by_path_.end()) {
      ImageJob j;
      j.path = path;
      j.encoding = enc;
      j.where = where;
      images_.push_back(std::move(j));
      it = image_by_path_.emplace(key, int(images_.size() - 1)).first;
    }
    d.job = it->second;
    if (ps.one_bool("invert", false)) warn("invert", where + ": imagemap \"invert\" is not supported and was ignored");
    const std::string wrap = ps.one_string("wrap", "repeat");
    if (wrap != "repeat") warn("wrap", where + ": imagemap wrap \"" + wrap + "\" is not supported: textures repeat");
    ps.get("filter", "string");
    ps.get("maxanisotropy", "float");
  } else if (cls == "constant") {
    ps.spectrum("value", false, d.value);
  } else if (cls == "scale") {
    const int base = tex_operand(lx, ps, "tex", {1, 1, 1});
    d = texdefs_[size_t(base)];
    d.name = name;
    d.where = where;
    const Param* sp = ps.get("scale", "float|texture");
    if (sp && sp->type == "texture") {
      warn("scaletex", where + ": a texture as the \"scale\" of a scale texture is not supported: 1 used");
    } else if (sp) {
      if (sp->nums.size() != 1) sp->fail("parameter \"float scale\" has " + std::to_string(sp->nums.size()) + " values", "1 value");
      const float s = float(sp->nums[0]);
      d.scale *= s;
      d.value = {d.value.r * s, d.value.g * s, d.value.b * s};
      if (d.kind == TexDef::constant) d.scale = 1;
    }
  } else if (cls == "mix") {
    d.kind = TexDef::mix;
    d.a = tex_operand(lx, ps, "tex1", {0, 0, 0});
    d.b = tex_operand(lx, ps, "tex2", {1, 1, 1});
    const Param* ap = ps.get("amount", "float|texture");
    if (ap && ap->type == "texture") warn("mixtex", where + ": a texture as the mix \"amount\" is not supported: 0.5 used");
    else if (ap) {
      if (ap->nums.size() != 1) ap->fail("parameter \"float amount\" has " + std::to_string(ap->nums.size()) + " values", "1 value");
      d.amount = float(ap->nums[0]);
    }
  } else if (cls == "checkerboard") {
    d.kind = TexDef::checker;
    d.a = tex_operand(lx, ps, "tex1", {1, 1, 1});
    d.b = tex_operand(lx, ps, "tex2", {0, 0, 0});
    d.uscale = ps.one_float("uscale", 1);
    d.vscale = ps.one_float("vscale", 1);
    d.udelta = ps.one_float("udelta", 0);
    d.vdelta = ps.one_float("vdelta", 0);
    if (ps.one_int("dimension", 2) != 2) {
      warn("checker3d", where + ": 3D checkerboard approximated by the average of its two textures");
      d.kind = TexDef::mix;
      d.amount = 0.5f;
    }
  } else {
    ps.mark_all_used();
    warn("texture:" + cls, where + ": texture class \"" + cls + "\" is not supported: grey 0.5 used");
  }
  for (Param& p : ps.items)
    if (p.name == "mapping" || p.name == "uscale" || p.name == "vscale" || p.name == "udelta" || p.name == "vdelta") {
      if (!p.used && !(p.strs.size() == 1 && p.strs[0] == "uv") &&
          !(p.nums.size() == 1 && p.nums[0] == ((p.name == "uscale" || p.name == "vscale") ? 1 : 0)))
        warn("mapping", where + ": texture mappings other than plain uv are not supported and were ignored");
      p.used = true;
    }
  warn_unused(ps, "Texture \"" + cls + "\"", lx, t);
  texdefs_.push_back(d);
  textures_[name] = int(texdefs_.size() - 1);
}

static Rgb mul(Rgb c, float s) { return {c.r * s, c.g * s, c.b * s}; }

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
  if (type != "point" && type != "spot" && type != "distant") {
    ps.mark_all_used();
    warn("light:" + type, where + ": LightSource \"" + type + "\" is not supported and was ignored");
    return;
  }
  const char* what = type == "distant" ? "L" : "I";
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
    l.type = LightType::point;
    const float power = ps.one_float("power", -1);
    l.radiance = mul(c, s * (power > 0 && lum > 0 ? power / (4 * float(M_PI) * lum) : 1.f));
    l.p0 = vec3f(float(p.x), float(p.y), float(p.z));
    l.power = 4 * float(M_PI) * luminance(l.radiance);
  } else if (type == "spot") {
    l.type = LightType::spot;
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
  } else {
    l.type = LightType::distant;
    const float e = ps.one_float("illuminance", -1);
    l.radiance = mul(c, s * (e > 0 && lum > 0 ? e / lum : 1.f));
    const Vec3d w = normalized(apply_vector(gs_.ctm, {from[0] - to[0], from[1] - to[1], from[2] - to[2]}));
    if (length(w) == 0) lx.fail(t, "distant light with from == to", "distinct from and to points");
    l.e1 = vec3f(float(w.x), float(w.y), float(w.z));
  }
  warn_unused(ps, "LightSource \"" + type + "\"", lx, t);
  scene.lights.push_back(l);
}

size_t Loader::new_mesh(Lexer& lx, const Token& t) {
  OwnedMesh om;
  om.object = object_;
  om.mesh.name = loc_str(lx, t);
  om.mesh.material = gs_.material;
  om.mesh.reverse_orientation = gs_.reverse != gs_.ctm.swaps_handedness();
  set_emission(om, lx, t);
  meshes_.push_back(std::move(om));
  return meshes_.size() - 1;
}

void Loader::set_emission(OwnedMesh& om, Lexer& lx, const Token& t) {
  if (!gs_.has_area) return;
  if (object_ >= 0) {
    warn("instarea", loc_str(lx, t) + ": area lights inside object definitions are not supported: the shape does not emit");
    return;
  }
  om.mesh.emission = gs_.area.L;
  om.mesh.two_sided = gs_.area.two_sided;
  om.power = gs_.area.power;
  om.power_where = loc_str(lx, t);
}

// pbrt-v4 turns a triangle's geometric normal towards its shading normal when the mesh
// has normals (N, flipped by ReverseOrientation): emission follows N, not the winding.
void Loader::orient_by_normals(Mesh& m, const std::vector<float>& n_obj, const Mat4& ctm, bool ro) {
  if (!m.emissive() || n_obj.size() != m.positions.size()) return;
  Mat4 inv;
  if (!invert(ctm, inv)) return;
  const float* P = m.positions.data();
  const size_t nt = m.triangle_count();
  std::vector<char> flip(nt, 0);
  size_t flips = 0;
  for (size_t i = 0; i < nt; ++i) {
    const uint32_t* v = &m.indices[3 * i];
    auto pos = [&](uint32_t k) { return Vec3d{P[3 * k], P[3 * k + 1], P[3 * k + 2]}; };
    const Vec3d w = cross(sub(pos(v[1]), pos(v[0])), sub(pos(v[2]), pos(v[0])));
    Vec3d ns;
    for (int k = 0; k < 3; ++k) {
      const float* n = &n_obj[3 * v[k]];
      const Vec3d nw = apply_normal_inv(inv, {n[0], n[1], n[2]});
      ns = {ns.x + nw.x, ns.y + nw.y, ns.z + nw.z};
    }
    double dd = dot(w, ns);
    if (ro) dd = -dd;
    flip[i] = dd < 0;
    flips += flip[i];
  }
  m.reverse_orientation = false;
  if (flips == 0) return;
  if (flips == nt) {
    m.reverse_orientation = true;
    return;
  }
  for (size_t i = 0; i < nt; ++i)
    if (flip[i]) std::swap(m.indices[3 * i + 1], m.indices[3 * i + 2]);
}

void Loader::shape(Lexer& lx, const Token& t, const std::string& type, Params& ps) {
  const std::string where = loc_str(lx, t);
  for (Param& p : ps.items)
    if (p.name == "alpha" || p.name == "displacement" || p.name == "edgelength") {
      p.used = true;
      warn("shape:" + p.name, where + ": shape parameter \"" + p.name + "\" is not supported and was ignored");
    }
  if (type == "trianglemesh" || type == "bilinearmesh" || type == "loopsubdiv") {
    const bool bilinear = type == "bilinearmesh";
    const size_t per = bilinear ? 4 : 3;
    const Param* P = ps.get("P", "point3");
    if (!P) lx.fail(t, type + " without \"point3 P\"", "a \"point3 P\" parameter");
    const size_t nv = P->nums.size() / 3;
    const Param* I = ps.get("indices", "integer");
    if (!I && nv != per)
      lx.fail(t, type + " without \"integer indices\"", "indices, or exactly " + std::to_string(per) + " vertices");
    if (I && I->nums.size() % per != 0)
      I->fail("\"integer indices\" has " + std::to_string(I->nums.size()) + " values", "a multiple of " + std::to_string(per));
    if (I)
      for (double v : I->nums)
        if (v < 0 || v >= double(nv))
          I->fail("index " + std::to_string(int64_t(v)) + " out of range", "an index below the vertex count " + std::to_string(nv));
    const Param* uv = ps.get("uv", "point2|float");
    if (uv && uv->nums.size() != 2 * nv)
      uv->fail("\"uv\" has " + std::to_string(uv->nums.size() / 2) + " pairs for " + std::to_string(nv) + " vertices", "one uv pair per vertex");
    const Param* N = ps.get("N", "normal3");
    if (N && N->nums.size() != 3 * nv)
      N->fail("\"N\" has " + std::to_string(N->nums.size() / 3) + " normals for " + std::to_string(nv) + " vertices", "one normal per vertex");
    ps.get("S", "vector3");
    ps.get("faceIndices", "integer");
    if (type == "loopsubdiv") {
      ps.get("levels", "integer");
      warn("loopsubdiv", where + ": loopsubdiv is not subdivided: its control mesh is rendered");
    }
    const size_t mi = new_mesh(lx, t);
    Mesh& m = meshes_[mi].mesh;
    m.positions.assign(P->nums.begin(), P->nums.end());
    transform_positions(gs_.ctm, m.positions.data(), nv);
    if (uv) m.uvs.assign(uv->nums.begin(), uv->nums.end());
    std::vector<uint32_t> idx;
    if (I) idx.assign(I->nums.begin(), I->nums.end());
    else
      for (uint32_t i = 0; i < per; ++i) idx.push_back(i);
    if (bilinear) {
      // patch (p00, p10, p01, p11) -> triangles (p00 p10 p11), (p00 p11 p01): one parallelogram pair
      for (size_t q = 0; q < idx.size(); q += 4) {
        const uint32_t a = idx[q], b = idx[q + 1], c = idx[q + 2], e = idx[q + 3];
        m.indices.insert(m.indices.end(), {a, b, e, a, e, c});
      }
    } else {
      m.indices = std::move(idx);
    }
    if (N) orient_by_normals(m, std::vector<float>(N->nums.begin(), N->nums.end()), gs_.ctm, gs_.reverse);
  } else if (type == "plymesh") {
    const Param* fp = ps.get("filename", "string");
    if (!fp || fp->strs.size() != 1) lx.fail(t, "plymesh without a filename", "a \"string filename\" parameter");
    PlyJob j;
    j.path = resolve_path(lx.dir(), fp->strs[0]);
    j.where_file = lx.file();
    j.line = t.line;
    j.col = t.col;
    j.ctm = gs_.ctm;
    j.ro = gs_.reverse;
    j.mesh = new_mesh(lx, t);
    plys_.push_back(std::move(j));
  } else if (type == "sphere") {
    const float r = ps.one_float("radius", 1);
    if (!(r > 0)) lx.fail(t, "sphere radius " + std::to_string(r), "a positive radius");
    const float zmin = ps.one_float("zmin", -r), zmax = ps.one_float("zmax", r), phimax = ps.one_float("phimax", 360);
    if (zmin > -r || zmax < r || phimax < 360)
      warn("partialsphere", where + ": partial spheres (zmin/zmax/phimax) are rendered as full spheres");
    OwnedSphere os;
    os.object = object_;
    const Vec3d c = apply_point(gs_.ctm, {0, 0, 0});
    const double sx = length(apply_vector(gs_.ctm, {1, 0, 0})), sy = length(apply_vector(gs_.ctm, {0, 1, 0})),
                 sz = length(apply_vector(gs_.ctm, {0, 0, 1}));
    if (std::abs(sx - sy) > 1e-4 * sx || std::abs(sx - sz) > 1e-4 * sx)
      warn("sphereellipsoid", where + ": a sphere under a non-uniform scale is rendered as a sphere of the same volume");
    os.sphere.center = vec3f(float(c.x), float(c.y), float(c.z));
    os.sphere.radius = float(r * std::cbrt(std::abs(gs_.ctm.det3())));
    if (!(os.sphere.radius > 0) || !std::isfinite(os.sphere.radius))
      lx.fail(t, "sphere with a degenerate transform", "a transform that keeps the sphere's size finite and non-zero");
    os.sphere.material = gs_.material;
    os.sphere.reverse_orientation = gs_.reverse != gs_.ctm.swaps_handedness();
    if (gs_.has_area) {
      if (object_ >= 0) {
        warn("instarea", where + ": area lights inside object definitions are not supported: the shape does not emit");
      } else {
        Rgb L = gs_.area.L;
        if (gs_.area.power > 0 && luminance(L) > 0) {
          const double area = 4 * M_PI * double(os.sphere.radius) * os.sphere.radius;
          L = mul(L, float(gs_.area.power / ((gs_.area.two_sided ? 2 : 1) * M_PI * area * luminance(L))));
        }
        os.sphere.emission = L;
        if (gs_.area.two_sided) warn("twosidedsphere", where + ": two-sided sphere lights emit outwards only");
      }
    }
    spheres_.push_back(os);
  } else if (type == "disk") {
    const float h = ps.one_float("height", 0), r = ps.one_float("radius", 1), ri = ps.one_float("innerradius", 0);
    if (!(r > 0) || !(ri >= 0) || !(ri < r)) lx.fail(t, "disk radii out of range", "radius > innerradius >= 0");
    if (ps.one_float("phimax", 360) < 360) warn("partialdisk", where + ": partial disks (phimax) are rendered as full disks");
    const size_t mi = new_mesh(lx, t);
    Mesh& m = meshes_[mi].mesh;
    // pbrt's disk faces +z in object space and its orientation ignores the handedness of
    // the transform (the normal is transformed, not recomputed), hence only ReverseOrientation.
    m.reverse_orientation = gs_.reverse;
    // Radii grown so that the 64-gon has the disk's area (emitted power is kept).
    const double n = disk_segments, k = std::sqrt(2 * M_PI / (n * std::sin(2 * M_PI / n)));
    const bool ring = ri > 0;
    for (int i = 0; i < disk_segments; ++i) {
      const double phi = 2 * M_PI * i / n, cx = std::cos(phi), sy = std::sin(phi);
      m.positions.insert(m.positions.end(), {float(r * k * cx), float(r * k * sy), h});
      m.uvs.insert(m.uvs.end(), {float(i / n), 0.f});
      if (ring) {
        m.positions.insert(m.positions.end(), {float(ri * k * cx), float(ri * k * sy), h});
        m.uvs.insert(m.uvs.end(), {float(i / n), float(1 - ri / r)});
      }
    }
    if (!ring) {
      m.positions.insert(m.positions.end(), {0.f, 0.f, h});
      m.uvs.insert(m.uvs.end(), {0.f, 1.f});
    }
    for (uint32_t i = 0; i < uint32_t(disk_segments); ++i) {
      const uint32_t j = (i + 1) % disk_segments;
      if (ring) m.indices.insert(m.indices.end(), {2 * i + 1, 2 * i, 2 * j, 2 * i + 1, 2 * j, 2 * j + 1});
      else m.indices.insert(m.indices.end(), {uint32_t(disk_segments), i, j});
    }
    transform_positions(gs_.ctm, m.positions.data(), m.positions.size() / 3);
  } else if (type == "cylinder" || type == "curve" || type == "cone" || type == "paraboloid" || type == "hyperboloid") {
    ps.mark_all_used();
    warn("shape:" + type, where + ": shape \"" + type + "\" is not supported and was skipped");
    return;
  } else {
    lx.fail(t, "unknown shape \"" + type + "\"", "trianglemesh, plymesh, bilinearmesh, sphere or disk");
  }
  warn_unused(ps, "Shape \"" + type + "\"", lx, t);
}

void Loader::load_files() {
  // Images only when a material reaches them.
  std::vector<char> seen(texdefs_.size(), 0);
  std::vector<int> todo;
  for (int td : material_tex_)
    if (td >= 0) todo.push_back(td);
  while (!todo.empty()) {
    const int td = todo.back();
    todo.pop_back();
    if (seen[size_t(td)]) continue;
    seen[size_t(td)] = 1;
    const TexDef& d = texdefs_[size_t(td)];
    if (d.job >= 0) images_[size_t(d.job)].needed = true;
    if (d.a >= 0) todo.push_back(d.a);
    if (d.b >= 0) todo.push_back(d.b);
  }
  // One task per file, largest first.
  std::vector<int> order;
  for (size_t i = 0; i < plys_.size(); ++i) {
    std::error_code ec;
    plys_[i].size = std::filesystem::file_size(plys_[i].path, ec);
    order.push_back(int(i));
  }
  for (size_t i = 0; i < images_.size(); ++i)
    if (images_[i].needed) order.push_back(-1 - int(i));
  auto size_of = [&](int o) -> uintmax_t {
    if (o >= 0) return plys_[size_t(o)].size;
    std::error_code ec;
    const uintmax_t s = std::filesystem::file_size(images_[size_t(-1 - o)].path, ec);
    return ec ? 0 : 4 * s;  // decoding costs more per byte than PLY parsing
  };
  std::vector<std::pair<uintmax_t, int>> sized;
  for (int o : order) sized.push_back({size_of(o), o});
  std::stable_sort(sized.begin(), sized.end(), [](auto& a, auto& b) { return a.first > b.first; });
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, sized.size(), 1),
      [&](const tbb::blocked_range<size_t>& r) {
        for (size_t k = r.begin(); k < r.end(); ++k) {
          const int o = sized[k].second;
          if (o < 0) {
            ImageJob& j = images_[size_t(-1 - o)];
            try {
              j.ok = load_image(j.path, j.encoding, j.tex, j.reason);
            } catch (const std::exception& e) {
              j.ok = false;
              j.reason = e.what();
              j.tex = Texture();
            }
            continue;
          }
          PlyJob& j = plys_[size_t(o)];
          Mesh& m = meshes_[j.mesh].mesh;
          try {
            std::string data, reason;
            if (!read_file(j.path, data, reason)) {
              j.error = "cannot read mesh file '" + j.path + "': " + reason;
              j.expected = "an existing, readable PLY file";
              continue;
            }
            PlyMesh ply = parse_ply(data, m.emissive());
            std::string().swap(data);
            m.positions = std::move(ply.positions);
            m.indices = std::move(ply.indices);
            m.uvs = std::move(ply.uvs);
            j.degenerate = ply.degenerate;
            j.polygons = ply.polygons;
            transform_positions(j.ctm, m.positions.data(), m.positions.size() / 3);
            orient_by_normals(m, ply.normals, j.ctm, j.ro);
          } catch (const PlyError& e) {
            j.error = "in mesh file '" + j.path + "': " + e.what();
            j.expected = e.expected;
          } catch (const std::exception& e) {
            j.error = "cannot load mesh file '" + j.path + "': " + e.what();
            j.expected = "a PLY file that fits in memory";
          }
        }
      },
      tbb::simple_partitioner());
  size_t degenerate = 0, polygons = 0;
  std::string first_degenerate, first_polygon;
  for (const PlyJob& j : plys_) {
    if (!j.error.empty()) fail(j.where_file, j.line, j.col, j.error, j.expected);
    if (j.degenerate && first_degenerate.empty()) first_degenerate = j.path;
    if (j.polygons && first_polygon.empty()) first_polygon = j.path;
    degenerate += j.degenerate;
    polygons += j.polygons;
  }
  if (degenerate)
    warn("plydegenerate", std::to_string(degenerate) + " degenerate PLY faces skipped (first in " + first_degenerate + ")");
  if (polygons)
    warn("plypolygon", std::to_string(polygons) + " PLY faces with more than 4 vertices were fan-triangulated (first in " +
                           first_polygon + ")");
  for (const ImageJob& j : images_)
    if (j.needed && !j.ok)
      warn("image:" + j.path, j.where + ": cannot read image '" + j.path + "' (" + j.reason + "): constant grey 0.5 used");
}

static Rgb average(const Texture& t) {
  double s[3] = {0, 0, 0};
  const size_t n = size_t(t.width) * t.height;
  for (size_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) s[c] += t.rgb[3 * i + c];
  return n ? Rgb{float(s[0] / n), float(s[1] / n), float(s[2] / n)} : Rgb{};
}

Resolved Loader::resolve(int td, int depth) {
  auto memo = resolved_.find(td);
  if (memo != resolved_.end()) return memo->second;
  const TexDef d = texdefs_[size_t(td)];
  Resolved r;
  r.value = d.value;
  auto avg = [&](const Resolved& x) { return x.image ? average(scene.textures[size_t(x.texture)]) : x.value; };
  if (depth > 64) {
    r.value = {0.5f, 0.5f, 0.5f};
  } else if (d.kind == TexDef::image) {
    ImageJob& j = images_[size_t(d.job)];
    if (!j.ok) {
      r.value = {0.5f, 0.5f, 0.5f};
    } else {
      if (j.scene_index < 0) {
        j.tex.name = d.name;
        scene.textures.push_back(std::move(j.tex));
        j.scene_index = int(scene.textures.size() - 1);
      }
      r.image = true;
      r.texture = j.scene_index;
      if (d.scale != 1) {
        Texture t = scene.textures[size_t(j.scene_index)];
        t.name = d.name;
        for (float& v : t.rgb) v *= d.scale;
        scene.textures.push_back(std::move(t));
        r.texture = int(scene.textures.size() - 1);
      }
    }
  } else if (d.kind == TexDef::checker) {
    const Resolved a = resolve(d.a, depth + 1), b = resolve(d.b, depth + 1);
    if (a.image || b.image) {
      warn("checkerimage", d.where + ": checkerboard of image textures approximated by their average");
      const Rgb x = avg(a), y = avg(b);
      r.value = {(x.r + y.r) / 2, (x.g + y.g) / 2, (x.b + y.b) / 2};
    } else {
      // Baked over uv in [0,1]^2 (exact when uscale/vscale are integers and the texture repeats).
      warn("checkerbake", d.where + ": checkerboard texture baked into an image over uv [0,1]");
      Texture t;
      t.name = d.name;
      const float checks = std::max(std::abs(d.uscale), std::abs(d.vscale));
      t.width = t.height = int(std::clamp(checks * 16.f, 16.f, 1024.f));
      t.rgb.resize(size_t(3) * t.width * t.height);
      for (int y = 0; y < t.height; ++y)
        for (int x = 0; x < t.width; ++x) {
          const float u = (x + 0.5f) / t.width, v = 1 - (y + 0.5f) / t.height;  // image rows run top-down in v
          const double s = std::floor(double(u) * d.uscale + d.udelta) + std::floor(double(v) * d.vscale + d.vdelta);
          const Rgb c = std::fmod(std::abs(s), 2.0) == 0 ? a.value : b.value;
          float* p = &t.rgb[3 * (size_t(y) * t.width + x)];
          p[0] = c.r, p[1] = c.g, p[2] = c.b;
        }
      scene.textures.push_back(std::move(t));
      r.image = true;
      r.texture = int(scene.textures.size() - 1);
    }
  } else if (d.kind == TexDef::mix) {
    const Resolved a = resolve(d.a, depth + 1), b = resolve(d.b, depth + 1);
    const float w = d.amount;
    auto lerp = [&](Rgb x, Rgb y) { return Rgb{x.r * (1 - w) + y.r * w, x.g * (1 - w) + y.g * w, x.b * (1 - w) + y.b * w}; };
    const Texture* ta = a.image ? &scene.textures[size_t(a.texture)] : nullptr;
    const Texture* tb = b.image ? &scene.textures[size_t(b.texture)] : nullptr;
    if (!a.image && !b.image) {
      r.value = lerp(a.value, b.value);
    } else if (ta && tb && ta->width == tb->width && ta->height == tb->height) {
      Texture t;
      t.name = d.name;
      t.width = ta->width;
      t.height = ta->height;
      t.rgb.resize(ta->rgb.size());
      for (size_t i = 0; i < t.rgb.size(); ++i) t.rgb[i] = ta->rgb[i] * (1 - w) + tb->rgb[i] * w;
      scene.textures.push_back(std::move(t));
      r.image = true;
      r.texture = int(scene.textures.size() - 1);
    } else {
      warn("miximage", d.where + ": mix of textures of different kinds or sizes approximated by a constant");
      r.value = lerp(avg(a), avg(b));
    }
  }
  resolved_[td] = r;
  return r;
}

void Loader::bake_materials() {
  for (size_t i = 0; i < scene.materials.size(); ++i) {
    if (material_tex_[i] < 0) continue;
    const Resolved r = resolve(material_tex_[i]);
    if (r.image) scene.materials[i].texture = r.texture;
    else scene.materials[i].reflectance = r.value;
  }
}

static double mesh_area(const Mesh& m) {
  double a = 0;
  const float* P = m.positions.data();
  for (size_t i = 0; i + 2 < m.indices.size(); i += 3) {
    auto pos = [&](uint32_t k) { return Vec3d{P[3 * k], P[3 * k + 1], P[3 * k + 2]}; };
    const Vec3d p0 = pos(m.indices[i]);
    a += 0.5 * length(cross(sub(pos(m.indices[i + 1]), p0), sub(pos(m.indices[i + 2]), p0)));
  }
  return a;
}

void Loader::flatten() {
  size_t total = 0;
  for (OwnedMesh& om : meshes_) {
    if (om.object >= 0) continue;
    if (om.mesh.indices.empty()) {
      warn("emptymesh", om.mesh.name + ": a mesh without triangles was skipped");
      continue;
    }
    if (om.power > 0 && luminance(om.mesh.emission) > 0) {
      const double area = mesh_area(om.mesh);
      if (area > 0)
        om.mesh.emission = mul(om.mesh.emission, float(om.power / ((om.mesh.two_sided ? 2 : 1) * M_PI * area *
                                                                    luminance(om.mesh.emission))));
      else warn("zeroarea:" + om.power_where, om.power_where + ": area light of zero area: power ignored");
    }
    total += om.mesh.triangle_count();
    scene.meshes.push_back(std::move(om.mesh));
  }
  for (OwnedSphere& os : spheres_)
    if (os.object < 0) scene.spheres.push_back(os.sphere);
  if (!instances_.empty())
    warn("instances", "object instances were flattened into copies of their meshes");
  for (const Instance& in : instances_) {
    const bool swaps = in.ctm.swaps_handedness();
    for (const OwnedMesh& om : meshes_) {
      if (om.object != in.object || om.mesh.indices.empty()) continue;
      total += om.mesh.triangle_count();
      if (total >= max_triangles)
        throw SceneError(om.mesh.name + ": error: too many triangles after flattening object instances (expected fewer than 2^31)");
      Mesh m = om.mesh;
      transform_positions(in.ctm, m.positions.data(), m.positions.size() / 3);
      m.reverse_orientation = m.reverse_orientation != swaps;
      scene.meshes.push_back(std::move(m));
    }
    for (const OwnedSphere& os : spheres_) {
      if (os.object != in.object) continue;
      Sphere s = os.sphere;
      const Vec3d c = apply_point(in.ctm, {s.center.x, s.center.y, s.center.z});
      s.center = vec3f(float(c.x), float(c.y), float(c.z));
      s.radius = float(s.radius * std::cbrt(std::abs(in.ctm.det3())));
      s.reverse_orientation = s.reverse_orientation != swaps;
      scene.spheres.push_back(s);
    }
  }
}

void Loader::finish() {
  load_files();
  bake_materials();
  flatten();
}

Scene load(std::unique_ptr<Lexer> lx, const std::string& source) {
  Loader l;
  l.scene.source = source;
  l.run(std::move(lx));
  return std::move(l.scene);
}

}  // namespace
}  // namespace pbrt

Scene load_pbrt(const std::string& path) {
  std::string text, reason;
  if (!pbrt::read_file(path, text, reason))
    throw SceneError(path + ":1:1: error: cannot read scene file: " + reason + " (expected an existing, readable .pbrt file)");
  return pbrt::load(std::make_unique<pbrt::Lexer>(std::move(text), path, pbrt::parent_dir(path)), path);
}

Scene load_pbrt_string(const std::string& text, const std::string& virtual_name, const std::string& base_dir) {
  return pbrt::load(std::make_unique<pbrt::Lexer>(text, virtual_name, base_dir), virtual_name);
}

}  // namespace tuile

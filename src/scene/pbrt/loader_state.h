// Internal to the pbrt-v4 reader: the Loader that executes directives, the graphics state
// it keeps on its attribute stack, and the records it fills while parsing (textures as
// defined, image and PLY files to read, meshes and spheres per object, instances) that
// are resolved when parsing ends. Its member functions are defined by job in loader.cpp
// (directives, graphics state, the end of loading), loader_camera.cpp, loader_materials.cpp,
// loader_lights.cpp, loader_shapes.cpp and loader_files.cpp.
#pragma once
#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "lexer.h"
#include "params.h"
#include "scene/scene.h"
#include "util.h"

namespace tuile::pbrt {

// "FILE:LINE" of a token, the prefix of warnings and mesh names.
std::string loc_str(const Lexer& lx, const Token& t);

// A colour scaled by s.
inline Rgb mul(Rgb c, float s) { return {c.r * s, c.g * s, c.b * s}; }

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

}  // namespace tuile::pbrt

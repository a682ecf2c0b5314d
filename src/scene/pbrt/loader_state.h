// Internal to the pbrt-v4 reader: the Loader that executes directives, the graphics state
// it keeps on its attribute stack, and the records it fills while parsing (textures as
// defined, image and PLY files to read, meshes and spheres per object, instances) that
// are resolved when parsing ends. Its member functions are defined by job in loader.cpp
// (directives, graphics state, the end of loading), loader_camera.cpp, loader_materials.cpp,
// loader_lights.cpp, loader_shapes.cpp and loader_files.cpp.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <tuple>
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
inline bool finite_rgb(const Rgb& c) { return std::isfinite(c.r) && std::isfinite(c.g) && std::isfinite(c.b); }
// An emission the renderer's products (areas, pi, MIS weights, throughputs) keep finite:
// below 1e30 in every channel (3e38, a float's largest, made every sample of a sky NaN).
inline bool emission_in_range(const Rgb& c) { return finite_rgb(c) && std::max(std::max(std::abs(c.r), std::abs(c.g)), std::abs(c.b)) <= 1e30f; }

struct AreaLight {
  Rgb L{1, 1, 1};
  float power = -1;
  bool two_sided = false;
};

struct GraphicsState {
  Mat4 ctm;
  bool reverse = false;
  int material = -1;
  std::string medium_in, medium_out, medium_where;  // MediumInterface's names ("": none) and where it was
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

// A float texture as defined in the file (Texture "name" "float" CLASS), baked at the end
// into a FloatTexture or a constant.
struct FloatTexDef {
  enum Kind { constant, image, product, mix, checker } kind = constant;
  float value = 0;          // constant (also the stand-in of classes tuile cannot bake)
  float scale = 1;          // image: pbrt's "scale"
  bool invert = false;      // image: max(0, 1 - v)
  TexFilter filter = TexFilter::bilinear;  // image: pbrt-v4's "filter"
  bool first_channel = false;              // image: point and EWA read channel 0, the others the RGB average
  int job = -1;             // image: index into image jobs
  int a = -1, b = -1;       // product (pbrt's scale texture: a * b), mix and checker operands (FloatTexDef indices)
  int amount = -1;          // mix: FloatTexDef index
  float uscale = 1, vscale = 1, udelta = 0, vdelta = 0;  // checker
  std::string name, where, file;
  int line = 0, col = 0;
};

struct ResolvedFloat {
  bool image = false;
  float value = 0;
  int texture = -1;  // Scene::float_textures
};

// A material field given by a spectrum texture, set when textures are resolved.
struct SpectrumFix {
  enum Field { reflectance, transmittance, albedo, eta, k, conductor_reflectance } field = reflectance;
  int material = -1;
  int def = -1;       // TexDef index
  float scale = 1;    // diffusetransmission's "scale"
  std::string where;  // "FILE:LINE" of the material
};

// A material field given by a float texture (or a float constant), set at the end.
struct FloatFix {
  enum Field { alpha_u, alpha_v, base_alpha_u, base_alpha_v, mix_amount, displacement, thickness, g, shape_alpha } field = alpha_u;
  int material = -1;
  // shape_alpha: a shape's "alpha" texture, for meshes_[mesh, mesh_end) and spheres_[sphere, sphere_end)
  int mesh = 0, mesh_end = 0, sphere = 0, sphere_end = 0;
  int def = -1;  // FloatTexDef index
  std::string file, name;  // the parameter, for errors
  int line = 0, col = 0;
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

// A shape's media by name, resolved when parsing ends (pbrt-v4 allows MakeNamedMedium after
// the shapes that name it).
struct MediumNames {
  std::string in, out, where;
};

struct OwnedMesh {
  Mesh mesh;
  MediumNames media;
  int object = -1;        // -1 = world, otherwise an object definition
  float power = -1;       // area light power to apply once the area is known
  std::string power_where;
};

struct OwnedSphere {
  Sphere sphere;
  MediumNames media;
  int object = -1;
};

struct OwnedCurves {
  Curves curves;
  MediumNames media;
  int object = -1;
};

struct Instance {
  int object;
  Mat4 ctm;
  std::string where;  // file:line of the ObjectInstance
};

struct Resolved {
  bool image = false;
  Rgb value{0.5f, 0.5f, 0.5f};
  int texture = -1;
};

class Loader {
 public:
  Scene scene;
  bool strict = false;  // LoadOptions::strict: a missing image is an error
  void run(std::unique_ptr<Lexer> main);

 private:
  void directive(Lexer& lx, const Token& t);
  void warn(const std::string& key, const std::string& message);
  // Said once per key, not an approximation: what the loader did changes nothing rendered.
  void note(const std::string& key, const std::string& message);
  void warn_unused(Params& ps, const std::string& what, const Lexer& lx, const Token& at);
  double number(Lexer& lx);
  void numbers(Lexer& lx, double* out, int n);
  std::string string_arg(Lexer& lx, const char* what);
  void require_world(Lexer& lx, const Token& t, bool world);
  void include(Lexer& lx, const Token& t);

  void camera(Lexer& lx, const Token& t, Params& ps);
  void film(Lexer& lx, const Token& t, Params& ps);
  void make_hair(Params& ps, const std::string& where, Material& m);
  void make_medium(Lexer& lx, const Token& t, const std::string& name, Params& ps);
  // a shape's media (names to Scene::media indices; a name no MakeNamedMedium gave is an
  // error naming where the MediumInterface was), counted as bounding them
  void resolve_media(const MediumNames& n, int& inside, int& outside);
  int make_material(Lexer& lx, const Token& t, const std::string& type, Params& ps);
  int reflectance_texture(Lexer& lx, const Param& p);
  void texture(Lexer& lx, const Token& t);
  int tex_operand(Lexer& lx, Params& ps, const std::string& name, Rgb def);
  void mapping_warnings(Params& ps, const std::string& where);
  int image_job(const std::string& path, const std::string& encoding, const std::string& where);
  std::string image_encoding(Params& ps, const std::string& path, const std::string& where);
  void float_texture(Lexer& lx, const Token& t, const std::string& name, const std::string& cls, Params& ps);
  int float_operand(Params& ps, const std::string& name, float def);
  int float_texture_ref(const Param& p);
  bool constant_float(int fd, float& v, int depth = 0) const;
  bool float_param(Params& ps, const std::string& name, Material& m, int material, FloatFix::Field field);
  void set_float(Material& m, FloatFix::Field field, float v, const std::string& file, int line, int col,
                 const std::string& name);
  bool unbounded_param(Lexer& lx, Params& ps, const std::string& name, int material, SpectrumFix::Field field,
                       const std::string& where, Rgb& out);
  float eta_param(Params& ps, const std::string& name, const std::string& where);
  void make_mix(Lexer& lx, const Token& t, Params& ps, const std::string& where, Material& m, int index);
  void area_light(Lexer& lx, const Token& t, const std::string& type, Params& ps);
  void light(Lexer& lx, const Token& t, const std::string& type, Params& ps);
  void infinite_map(Lexer& lx, const Token& t, const std::string& path, Params& ps);
  void shape(Lexer& lx, const Token& t, const std::string& type, Params& ps);
  void shape_alpha(const Param& p, size_t meshes0, size_t spheres0);
  void set_shape_alpha(const FloatFix& f, const ResolvedFloat& r);
  void mesh_shape(Lexer& lx, const Token& t, const std::string& type, Params& ps, const std::string& where);
  void ply_shape(Lexer& lx, const Token& t, Params& ps);
  void sphere_shape(Lexer& lx, const Token& t, Params& ps, const std::string& where);
  void disk_shape(Lexer& lx, const Token& t, Params& ps);
  void cylinder_shape(Lexer& lx, const Token& t, Params& ps);
  void partial_sphere(Lexer& lx, const Token& t, float r, float zmin, float zmax, double phimax);
  void curve_shape(Lexer& lx, const Token& t, Params& ps, const std::string& where);
  // The mesh's shading normals from object-space ones on a quadric (pbrt-v4 turns a
  // quadric's normal by ReverseOrientation XOR the transform's handedness, in object space).
  void quadric_normals(Mesh& m, const std::vector<float>& n_obj);
  size_t new_mesh(Lexer& lx, const Token& t);
  void set_emission(OwnedMesh& om, Lexer& lx, const Token& t);
  void orient_by_normals(Mesh& m, const std::vector<float>& n_obj, const Mat4& ctm, bool ro);
  // The mesh's shading normals: "N" in world space (inverse transpose), unit, turned by
  // ReverseOrientation (pbrt-v4's TriangleMesh); zero-length ones stay zero (the stage
  // then falls back to the geometric normal).
  static void set_shading_normals(Mesh& m, const std::vector<float>& n_obj, const Mat4& ctm, bool ro);

  void finish();
  void load_files();
  Resolved resolve(int td, int depth = 0);
  ResolvedFloat resolve_float(int fd, int depth = 0);
  const Texture& job_texture(ImageJob& j);
  int add_float_texture(FloatTexture t);
  void bake_materials();
  void flatten();
  template <class IsInterface> void place_instances(IsInterface&& is_interface, size_t& total);

  std::vector<std::unique_ptr<Lexer>> lexers_;
  GraphicsState gs_;
  std::vector<StackEntry> stack_;
  bool in_world_ = false, seen_world_ = false;
  int object_ = -1;  // object being defined
  std::map<std::string, Mat4> coord_systems_;
  std::unordered_map<std::string, int> named_materials_;
  std::unordered_map<std::string, int> named_media_;
  MediumNames camera_medium_;
  std::vector<std::pair<size_t, MediumNames>> light_media_;  // point and spot sources' (Scene::lights index)
  std::unordered_map<std::string, int> textures_;       // spectrum textures by name
  std::unordered_map<std::string, int> float_textures_;  // float textures by name: FloatTexDef index
  std::unordered_map<std::string, int> objects_;
  std::vector<std::string> object_names_;
  std::vector<TexDef> texdefs_;
  std::vector<FloatTexDef> float_defs_;
  std::vector<SpectrumFix> spectrum_fixes_;
  std::vector<FloatFix> float_fixes_;
  std::map<int, int> mix_amount_def_;  // mix material -> FloatTexDef of its amount
  std::vector<ImageJob> images_;
  std::map<std::pair<std::string, std::string>, int> image_by_path_;
  std::vector<PlyJob> plys_;
  std::vector<OwnedMesh> meshes_;
  std::vector<OwnedSphere> spheres_;
  std::vector<OwnedCurves> curves_;
  std::vector<Instance> instances_;
  std::map<int, Resolved> resolved_;
  std::map<int, ResolvedFloat> resolved_float_;
  std::map<std::pair<int, float>, int> scaled_textures_;       // (texture, scale) -> scaled copy
  std::map<std::tuple<int, float, bool, int, bool>, int> float_images_;  // (job, scale, invert, filter, channel 0) -> float texture
  std::set<std::string> warned_;
  std::string camera_where_;
};

}  // namespace tuile::pbrt

// The scene as the renderer sees it: plain arrays with int handles, made once at load.
// Loaders (the built-in scenes, the pbrt-v4 reader) fill Meshes, Spheres, Materials,
// Textures, point-like lights and the Camera; finalize_scene() then derives the light
// table (one source per emissive triangle, or per emissive parallelogram when two
// triangles of a mesh form one) and the scene's feature set.
#pragma once
#include <algorithm>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "bsdf/bsdf.h"
#include "lanes/vec.h"
#include "light/kinds.h"
#include "light/sky_map.h"
#include "sample/filter.h"

namespace tuile {

struct Rgb {
  float r = 0, g = 0, b = 0;
  bool any_positive() const { return r > 0 || g > 0 || b > 0; }
};
// Linear sRGB luminance (Rec. 709 Y).
inline float luminance(const Rgb& c) { return 0.2126f * c.r + 0.7152f * c.g + 0.0722f * c.b; }

// An error that names where it came from (scene file and line, or the option).
struct SceneError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct Texture {
  std::string name;
  int width = 0, height = 0;
  std::vector<float> rgb;  // linear RGB, row-major, top row first
};

// A float parameter pbrt lets a texture give: the constant, or a float texture
// (Scene::float_textures) when texture >= 0, looked up at the hit's uv.
struct FloatParam {
  float value = 0;
  int texture = -1;
};

// One material, pbrt-v4's parameters already resolved to what the BSDFs read: spectra to
// linear RGB, roughness to Trowbridge-Reitz alphas (pbrt's RoughnessToAlpha where
// remaproughness). Fields a kind does not use keep their defaults.
struct Material {
  MaterialKind kind = MaterialKind::diffuse;
  Rgb reflectance{0.5f, 0.5f, 0.5f};  // diffuse, coated diffuse's base, diffuse transmission's R
  int texture = -1;  // index into Scene::textures: replaces reflectance when >= 0
  Rgb transmittance{0.25f, 0.25f, 0.25f};  // diffuse transmission's T (times its "scale", as reflectance)
  int transmittance_texture = -1;          // index into Scene::textures, or -1
  Rgb eta_rgb{1, 1, 1}, k_rgb{0, 0, 0};    // conductor and coated conductor's base (pbrt: eta / k spectra)
  float eta = 1.5f;                        // dielectric, thin dielectric, and the coat of coated*
  FloatParam alpha_u, alpha_v;             // Trowbridge-Reitz alphas: conductor, dielectric, coat interface
  FloatParam base_alpha_u, base_alpha_v;   // coated conductor: the conductor's alphas
  bool remap_roughness = true;             // textured roughness goes through RoughnessToAlpha at the hit
  float thickness = 0.01f;                 // coated*: the layer between coat and base
  Rgb albedo{0, 0, 0};                     // coated*: the layer's scattering albedo
  float g = 0;                             // coated*: its Henyey-Greenstein asymmetry
  int max_depth = 10, nsamples = 1;        // coated*: pbrt's random-walk settings (recorded)
  int displacement = -1;                   // float texture for bump mapping, or -1
  // hair: the interior's absorption (from pbrt's sigma_a, reflectance or melanin
  // concentrations), the longitudinal and azimuthal roughness and the scales' tilt
  // (degrees); its index is eta (1.55 by default)
  Rgb hair_sigma_a{0, 0, 0};
  float beta_m = 0.3f, beta_n = 0.3f, hair_alpha = 2;
  // pbrt's "mix": when mix[0] >= 0 this material is a choice, per hit, between materials
  // mix[0] and mix[1] (indices into Scene::materials, never mixes themselves): the second
  // where a hash of the hit is below amount (pbrt-v4's MixMaterial::ChooseMaterial).
  int mix[2] = {-1, -1};
  FloatParam mix_amount{0.5f, -1};
  std::string approximated_from;  // non-empty when the material was approximated (pbrt type)
  bool interface = false;         // pbrt's "interface": a boundary between media that does not scatter light
};

// A diffuse material of reflectance rho, or of the texture's texels when texture >= 0.
inline Material diffuse_material(Rgb rho, int texture = -1) {
  Material m;
  m.reflectance = rho;
  m.texture = texture;
  return m;
}

// A float texture (pbrt's imagemap, constant, scale, mix of float textures) baked to an
// image: one value per texel, looked up nearest with wrap at the hit's uv. A constant is a
// 1x1 image.
// pbrt-v4's image texture filters ("string filter"): point, bilinear (its default) and
// trilinear all read MIP levels of the image chosen by the ray's footprint (pbrt-v4's
// "bilinear" is bilinear at one level, "trilinear" blends two); EWA is read as trilinear.
enum class TexFilter : uint8_t { point, bilinear, trilinear };  // (GeomView::ftex_filter: 0, 1, 2)

struct FloatTexture {
  std::string name;
  int width = 0, height = 0;
  std::vector<float> value;  // row-major, top row first
  TexFilter filter = TexFilter::bilinear;  // how bump maps read it (wave/textures.h float_texture_filtered)
  // pbrt-v4's MIP pyramid of the texture (finalize_scene builds it for the bump maps):
  // level i is mip_w[i] x mip_h[i] values from mip[mip_at[i]], row-major, top row first.
  // Level 0 is the image, resampled up to powers of two where it is not (pbrt-v4's
  // windowed sinc); each next level averages 2 x 2 texels; the last is 1 x 1.
  std::vector<float> mip;
  std::vector<int32_t> mip_w, mip_h;
  std::vector<size_t> mip_at;
};

// Builds t's MIP pyramid (FloatTexture::mip) as pbrt-v4's Image::GeneratePyramid does,
// with repeat wrap; pbrt-v4 keeps each level in the image's own pixel format (8-bit sRGB
// for most files), tuile in float.
void build_mip(FloatTexture& t);

struct Mesh {
  std::string name;                // for messages (file name or "trianglemesh at f.pbrt:12")
  std::vector<float> positions;    // x y z per vertex, world space
  std::vector<uint32_t> indices;   // 3 per triangle
  std::vector<float> uvs;          // u v per vertex, optional (empty)
  // shading normals, x y z per vertex, world space, unit, optional (empty): pbrt's "N"
  // (turned by ReverseOrientation); they also decide which side is the outside
  std::vector<float> normals;
  int material = -1;
  int medium_inside = -1, medium_outside = -1;  // Scene::media, -1: none
  Rgb emission;                    // radiance L when emissive (all zero otherwise)
  bool two_sided = false;          // emits on both sides
  bool reverse_orientation = false;  // emission on the side opposite the geometric normal
  // pbrt's "alpha" (wave/alpha.h): 1 is opaque; a constant below 1 or a float texture
  // (Scene::float_textures) cuts the mesh out where it is 0, stochastically between
  FloatParam alpha{1, -1};
  bool has_alpha() const { return alpha.texture >= 0 || alpha.value < 1; }
  // filled by finalize_scene: light index of each triangle or -1
  std::vector<int32_t> prim_light;
  int object = -1;  // an instanced object's shape (Scene::instances), in its object space; -1: world
  size_t triangle_count() const { return indices.size() / 3; }
  bool emissive() const { return emission.any_positive(); }
};

struct Sphere {
  vec3f center{0, 0, 0};
  float radius = 1;
  int material = -1;
  Rgb emission;
  bool reverse_orientation = false;  // emit inwards
  float alpha = 1;  // pbrt's "alpha", a constant (wave/alpha.h)
  int medium_inside = -1, medium_outside = -1;  // Scene::media, -1: none
  int light = -1;  // filled by finalize_scene
  int object = -1;  // an instanced object's shape (Scene::instances), in its object space; -1: world
  bool emissive() const { return emission.any_positive(); }
};

// pbrt-v4's "curve" shape: cubic Bezier segments (the loader converts B-splines and
// quadratics), each with 4 control points of its own, x y z and radius (half pbrt's width)
// per point, in world space. Embree intersects them as pbrt-v4's types: flat (a ribbon that
// faces the ray), ribbon (oriented by a normal per control point) or cylinder (a round tube).
enum class CurveType : int32_t { flat = 0, ribbon = 1, cylinder = 2 };
struct Curves {
  std::string name;                // for messages ("curve at f.pbrt:12")
  CurveType type = CurveType::flat;
  std::vector<float> points;       // x y z r per control point, 4 per segment
  std::vector<float> normals;      // ribbons: x y z per control point (then padded by one float)
  int material = -1;
  int medium_inside = -1, medium_outside = -1;  // Scene::media, -1: none
  int object = -1;  // an instanced object's shape (Scene::instances), in its object space; -1: world
  size_t segment_count() const { return points.size() / 16; }
  float max_radius() const {
    float r = 0;
    for (size_t i = 3; i < points.size(); i += 4) r = std::max(r, points[i]);
    return r;
  }
};

// A participating medium as pbrt-v4 describes it (MakeNamedMedium): a homogeneous medium's
// absorption and scattering coefficients (per unit length, times "scale" already), its
// Henyey-Greenstein asymmetry and emission. Other types (grids, clouds, nanovdb) are kept by
// name and type only (supported = false). Which shapes bound a medium: their
// medium_inside / medium_outside (indices here, -1 for none); the camera's: camera_medium.
// Listed by `tuile info`; homogeneous ones are rendered (wave/media.h), others warned of
// and left out (a shape filled with one renders as if it held nothing).
struct Medium {
  std::string name, type;      // MakeNamedMedium's name and "type"
  std::string where;           // "file:line" of its definition
  bool supported = false;      // homogeneous
  std::string preset;          // pbrt-v4's measured preset, if one gave sigma_a and sigma_s
  Rgb sigma_a{1, 1, 1}, sigma_s{1, 1, 1};
  float g = 0;
  Rgb Le{0, 0, 0};
  int bounding_shapes = 0;     // shapes whose inside or outside it is (interface shapes included)
};

// An environment map (LightSource "infinite" with "filename"): pbrt-v4's equal-area
// octahedral square (light/sky_map.h), res x res linear RGB texels, with the two sampling
// distributions the kernels read (src/scene/sky_map.cpp builds them).
struct SkyMap {
  std::string file;                // as the scene names it (for messages and `tuile info`)
  int res = 0;
  // res * res texels, row-major, top row first, four floats each: r, g, b and the
  // compensated distribution's weight (SkyMapView::texels: one cache line per texel for
  // the lookups of a light sample, whose density and radiance both read it)
  std::vector<float> texels;
  Rgb texel(size_t i) const { return {texels[4 * i], texels[4 * i + 1], texels[4 * i + 2]}; }
  // distribution d's weight of texel i (the full one's in its func, the compensated one's
  // in the texels)
  float weight(int d, size_t i) const { return d == sky_dist_compensated ? texels[4 * i + 3] : dist[d].func[i]; }
  struct Dist {
    std::vector<float> func, cond_cdf, marg_cdf;  // SkyDistView's tables (func empty: in texels)
    std::vector<int32_t> cond_cut, marg_cut;       // their cut points (SkyDistView)
    int32_t cuts = 1;
    float inv_mean = 0;
  } dist[2];                       // sky_dist_full, sky_dist_compensated
  double mean[3] = {0, 0, 0};      // the texels' mean per channel (the power's)
  // the compensated distribution's mean over the full one's, mean(max(f - mean f, 0)) / mean f
  // (f: the channels' average): the part of the map the light technique draws under MIS
  double compensated_share = 1;
  bool constant = false;           // every texel the same (the compensated distribution is uniform)
};

// A light source: its kind and shape (light/kinds.h: the one list of kinds, whose code is
// in light/kinds/<name>.h) and what the scene knows of it.
struct Light : LightShape {
  Rgb radiance;       // L for area lights and skies, I (W/sr) for point and spot, E (irradiance) for distant
  float power = 0;    // emitted power (LightKindOps<kind>::power; luminance of radiance times pi A for one-sided area lights)
  int mesh = -1, prim = -1;  // where it came from (-1 for spheres/delta lights)
  int sphere = -1;
  int sky_map = -1;   // a sky with an environment map: its index in Scene::sky_maps
  int medium = -1;    // a point or spot source: the medium it sits in (Scene::media; pbrt-v4: the
                      // outside one in force at its LightSource), or -1
};

// pbrt-v4's ObjectInstance: object `object` (Scene::objects: its shapes are the meshes,
// spheres and curves whose `object` is that index, in the object's own space) placed in the
// world by an affine transform. Embree traces it as an instance of one BVH per object (two
// levels): an object's triangles are stored once however many times it is placed.
struct Instance {
  int object = 0;
  float world_from_object[3][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}};
  std::string where;  // "file:line" of the ObjectInstance, for messages
};

// pbrt-v4's perspective camera: world_from_camera is affine (3 rows of 4).
struct Camera {
  float world_from_camera[3][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}};
  float fov_deg = 90;           // over the shorter image axis (pbrt-v4)
  float screen[4] = {0, 0, 0, 0};  // xmin xmax ymin ymax; all zero = derive from the aspect ratio
  int width = 512, height = 512;
};

// Sets the camera from pbrt's LookAt (camera space: +z forward, +y up, +x = up x dir).
void camera_look_at(Camera& cam, vec3f eye, vec3f look, vec3f up);

// Scene feature bits, detected once by finalize_scene. The renderer runs a tile pipeline
// specialised to them, which leaves out the stages and lookups the scene never needs.
enum SceneFeature : uint32_t {
  feat_area_lights = 1u << 0,
  feat_delta_lights = 1u << 1,
  feat_single_light = 1u << 2,
  feat_textures = 1u << 3,
  feat_spheres = 1u << 4,
  feat_visible_emitters = 1u << 5,
  feat_rect_lights_only = 1u << 6,  // every source is a rectangle (Urena's map, no dispatch on kind)
  feat_sky = 1u << 7,               // a light at infinity with a density (LightSource "infinite"): escaped rays see it
  feat_media = 1u << 8,             // a rendered medium fills some shape or surrounds the camera (wave/media.h)
};
// Their names (`tuile info`), bit i named by entry i.
inline constexpr const char* scene_feature_names[] = {"area-lights", "delta-lights",     "single-light",    "textures",
                                                      "spheres",     "visible-emitters", "rect-lights-only", "sky",
                                                      "media"};

struct Scene {
  std::string source;  // file name or "built-in:NAME"
  Camera camera;
  std::vector<Mesh> meshes;
  std::vector<Sphere> spheres;
  std::vector<Curves> curves;       // after the spheres in Embree's geomIDs
  std::vector<std::string> objects;   // instanced objects' names (Mesh::object etc. index them)
  std::vector<Instance> instances;    // their placements
  std::vector<Medium> media;        // MakeNamedMedium, in the file's order
  int camera_medium = -1;           // the medium the camera sits in (pbrt: the outside one at Camera), or -1
  std::vector<Material> materials;  // meshes with material -1 use a default grey 0.5
  std::vector<Texture> textures;
  std::vector<FloatTexture> float_textures;
  std::vector<Light> lights;        // delta lights and skies are added by loaders; area lights by finalize_scene
  std::vector<SkyMap> sky_maps;     // the skies' environment maps (Light::sky_map)
  std::vector<std::string> warnings;  // approximations made at load, one per kind
  std::vector<std::string> notes;     // what the loader did that changes nothing in the image (zero-area faces dropped)
  std::vector<std::string> inputs;    // the files it was read from (scene files, meshes, images): no output may replace them
  // Settings from the file (pbrt Sampler/Film/Integrator); the command line overrides them.
  int file_spp = 0;
  std::string file_sampler;       // "", "independent", "stratified", "sobol"
  std::string file_light_pick;    // "", "uniform", "power", "bvh"
  int file_max_depth = 0;         // Integrator's maxdepth (pbrt's 5 when a file gives none); 0 for built-in scenes
  bool file_regularize = false;   // Integrator's "bool regularize" (pbrt-v4's path and volpath)
  std::string file_integrator;    // the Integrator's type ("" without one): "bdpt" makes --bdpt auto on
  std::string file_output;        // Film "filename"
  FilterParams file_filter;       // PixelFilter (pbrt-v4's defaults per filter; none: the box of radius 1/2)
  uint32_t features = 0;
  size_t triangle_count() const;            // triangles stored (an object's once)
  size_t instanced_triangle_count() const;  // triangles rendered (an object's once per instance)
};

// Derives the light table and features; validates (NaN/Inf vertices, indices in range).
// Throws SceneError naming the mesh on bad data. Degenerate triangles are kept for
// geometry but never become light sources.
void finalize_scene(Scene& scene);
// The medium a shape's side holds as rendered: m, or -1 (vacuum) for none or a medium of a
// type tuile does not render.
int rendered_medium(const Scene& scene, int medium);
// Whether rays pass a shape without a vertex (pbrt-v4's "interface" material, not
// emissive, between two different media as rendered): the walks of wave/media.h cross it,
// and Embree's occlusion queries report crossing it instead of stopping there.
bool passes_between_media(const Scene& scene, int material, int medium_inside, int medium_outside, bool emissive);
// The kernels' view of a mesh's alpha (wave/alpha.h), pointing into the mesh and the
// scene's float textures: the Embree filters' and the light stage's.
struct AlphaShape;
AlphaShape alpha_shape(const Scene& scene, const Mesh& m);

// Built-in scenes (compiled in). Names: "two-panels" (the default), "cornell".
Scene builtin_scene(const std::string& name);
std::vector<std::string> builtin_scene_names();

// How a scene file is read. strict: pbrt-v4's behaviour where tuile is lenient (an image
// texture that cannot be read is an error, not a constant with a warning).
struct LoadOptions {
  bool strict = false;
};

// Loads a scene: "built-in:NAME" or a pbrt-v4 file (.pbrt or .pbrt.gz). Calls finalize_scene.
Scene load_scene(const std::string& path, const LoadOptions& options = {});

}  // namespace tuile

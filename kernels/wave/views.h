// The scene as the stages read it besides the light table (light/table.h): per-geometry
// lookups by Embree's geomID / primID, and the camera. Plain pointers into arrays the
// renderer owns (src/render/views.h builds them).
#pragma once
#include <cstdint>

#include "sample/filter.h"

namespace tuile {

// The float parameters of the materials' BSDFs (kernels/bsdf/material.h), one array each in
// GeomView::mat_param, indexed by material. Kinds read the ones they need.
enum MatParam : int {
  mp_tr, mp_tg, mp_tb,           // diffuse transmission's transmittance
  mp_eta_r, mp_eta_g, mp_eta_b,  // conductor's eta (or coated conductor's base)
  mp_k_r, mp_k_g, mp_k_b,        // conductor's k
  mp_eta,                        // dielectric / thin dielectric / coat index
  mp_ax, mp_ay,                  // Trowbridge-Reitz alphas (conductor, dielectric, coat)
  mp_bax, mp_bay,                // coated conductor's base alphas
  mp_thickness,                  // coated: layer thickness
  mp_alb_r, mp_alb_g, mp_alb_b,  // coated: layer albedo
  // hair (bsdf/hair.h): sigma_a, then HairConstants of beta_m, beta_n, alpha
  mp_hair_sa_r, mp_hair_sa_g, mp_hair_sa_b,
  mp_hair_inv_v0, mp_hair_inv_v1, mp_hair_inv_v2,
  mp_hair_log_norm0, mp_hair_log_norm1, mp_hair_log_norm2,
  mp_hair_exp_m2v0, mp_hair_exp_m2v1, mp_hair_exp_m2v2,
  mp_hair_v0, mp_hair_v1, mp_hair_v2,
  mp_hair_s, mp_hair_e_pi_s,
  mp_hair_sin0, mp_hair_sin1, mp_hair_sin2,
  mp_hair_cos0, mp_hair_cos1, mp_hair_cos2,
  mp_hg_g,                       // phase (a medium's points): Henyey-Greenstein's asymmetry
  // coated diffuse: the coat's internal reflectance R_i per channel (bsdf/coated.h), which
  // depends on eta, thickness and albedo alone: computed once per material
  // (coat_internal_reflectance_rgb) instead of at every evaluation
  mp_ri_r, mp_ri_g, mp_ri_b,
  mp_count
};

// The kind of geometry an Embree geomID names, which decides how its hits are found and
// shaded: a triangle mesh (its triangles flattened in GeomView::tri_pos), or a sphere.
// curve: a ribbon or a tube, whose Embree Ng is the surface's normal; flat_curve: a ribbon
// facing each ray, whose Ng is the curve's tangent (Embree's convention)
// medium: no Embree geometry, one row per medium after the scene's (MediumView::geom0 + m):
// the medium stage (wave/media.h) makes a ray that scatters in medium m a hit of that row,
// at the scattering point, so the hit stages turn it into a shading point like any other.
enum class GeomKind : int32_t { triangles = 0, sphere = 1, curve = 2, flat_curve = 3, medium = 4 };

// Participating media as the medium stages read them (wave/media.h): per medium, its
// coefficients per channel and emission; per geomID, the media on the inside and outside of
// a surface that changes the medium (else -1 both: a ray keeps its medium through it) and
// whether it is an interface (no surface at all: rays pass through it).
struct MediumView {
  int32_t count = 0;
  int32_t geom0 = 0;                           // the geomID of medium 0's row
  const float* sigma_t[3] = {};                // sigma_a + sigma_s
  const float* sigma_s[3] = {};
  const float* emit[3] = {};                   // sigma_a Le
  const int32_t* scatters = nullptr;           // some sigma_s > 0 (else absorption alone: no flights)
  const int32_t* emits = nullptr;              // some sigma_a Le > 0
  const int32_t* geom_in = nullptr;            // per geomID
  const int32_t* geom_out = nullptr;
  const int32_t* geom_interface = nullptr;
  bool has_interfaces = false;                 // some geomID is an interface (else every surface occludes shadow rays)
  // no medium scatters or emits and no surface is an interface: a ray's flight is its
  // origin medium's transmittance to its hit (medium_flights' SIMD route, no random numbers)
  bool absorb_only = false;
  int32_t camera = -1;                         // the camera's medium
};

struct GuideView;  // wave/guide.h

// Per-geometry data the hit stages look up by Embree's geomID / primID.
struct GeomView {
  // The geometry table, one row per geomID (build_views: the meshes, then the spheres),
  // that every stage asks instead of comparing geomIDs: the geometry's kind, material,
  // outside, where its primitives are, and its light. A new kind of geometry (instances,
  // curves) is a GeomKind and the rows build_views writes for it (docs/DESIGN.md).
  int32_t geom_count = 0;
  const int32_t* geom_kind = nullptr;          // GeomKind
  const int32_t* geom_material = nullptr;      // never -1
  // triangles: its first triangle in the flattened table (triangle geom_first[g] + primID
  // of tri_pos and tri_light); a sphere or a curve: its row in sphere_center
  const int32_t* geom_first = nullptr;
  const int32_t* geom_light = nullptr;         // a sphere's light or -1 (a mesh's lights are per triangle)
  const float* sphere_center = nullptr;        // per sphere: centre xyz and radius; per curve: 0 0 0 and its largest radius
  bool has_textures = false;
  // Every triangle of every mesh, flattened (flat_triangles: scenes below 2^23 stored
  // triangles; larger ones read vertices through the meshes' indices, 36 bytes per
  // triangle less).
  bool flat_triangles = true;
  const float* tri_pos = nullptr;              // per triangle: v0 v1 v2, xyz each (9 floats)
  const int32_t* tri_light = nullptr;          // per triangle: light or -1
  const float *mat_r = nullptr, *mat_g = nullptr, *mat_b = nullptr;
  const int32_t* mat_texture = nullptr;
  const int32_t* mat_kind = nullptr;           // per material: MaterialKind
  const float* mat_param[mp_count] = {};       // per material: the BSDF parameters (MatParam)
  // pbrt's mix: per material, the two it chooses between (-1: not a mix) and the
  // probability of the second; resolved per shading point (surface_hits.h resolve_mixes)
  bool has_mix = false;
  const int32_t *mat_mix0 = nullptr, *mat_mix1 = nullptr;
  const float* mat_mix_amount = nullptr;
  // pbrt-v4's regularization (Estimator::regularize): per material, the row that is its
  // regularized twin (alphas below 0.3 as clamp(2 alpha, 0.1, 0.3), the coated conductor's
  // base too; every other column the same), or itself where nothing changes (no alphas,
  // all at 0.3 or more, a mix: resolved before, a phase function)
  const int32_t* mat_reg = nullptr;
  // --light-paths (src/render/light_paths.h): per material, 1 where its microfacet lobe is
  // near-specular, so that a distant source's light at such a vertex, on a path whose first
  // vertex is rough, is the light tracer's (LightView::lt_glossy); nullptr: no such split
  const int32_t* mat_lt_glossy = nullptr;
  // per geomID: +1, or -1 where the surface's outside (pbrt's normal, which decides which
  // side of a dielectric is inside) is opposite Embree's Ng
  const float* geom_side = nullptr;
  // per geomID, a mesh's arrays (nullptr for other kinds)
  const uint32_t* const* indices = nullptr;
  const float* const* positions = nullptr;     // xyz per vertex
  const float* const* uvs = nullptr;           // nullptr without uv
  const float* const* normals = nullptr;       // shading normals per vertex, nullptr without
  // per geomID, a curve's control points (Curves::points: x y z r, 4 per segment, the
  // segment is Embree's primID), nullptr for other kinds; read where a hair material
  // needs the fiber's axis and the hit's offset across it (surface_hits.h apply_hair_frames)
  const float* const* curve_points = nullptr;
  bool has_hair = false;                       // some material (or a mix's) is hair
  bool has_normals = false;                    // some mesh has shading normals
  // Bump mapping (pbrt-v4's "displacement"): per material, the float texture whose
  // gradient tilts the shading normal, or -1 (none, or a constant: build_views drops
  // those, they tilt nothing); the float textures (one value per texel, top row first)
  bool has_bump = false;                       // some geometry's material (or a mix's) bumps
  const int32_t* mat_bump = nullptr;           // per material: float texture or -1
  const float* const* ftex_value = nullptr;    // per float texture
  const int32_t *ftex_w = nullptr, *ftex_h = nullptr;
  // per float texture, its MIP pyramid (FloatTexture::mip; the bump maps' only: 0 levels
  // elsewhere) and pbrt-v4's filter (TexFilter), which float_texture_filtered reads
  const float* const* ftex_mip = nullptr;
  const int32_t* const* ftex_mip_w = nullptr;
  const int32_t* const* ftex_mip_h = nullptr;
  const size_t* const* ftex_mip_at = nullptr;
  const int32_t* ftex_levels = nullptr;
  const int32_t* ftex_filter = nullptr;
  // The pixel footprint the bump's finite differences are scaled to (surface_hits.h
  // bump_normal): the camera's centre, the world-space change of the camera ray's
  // direction (camera z = 1) per pixel along x and along y, times footprint_scale, and
  // the camera's z row (dot(zrow, p - o) is the camera depth of p).
  float cam_o[3] = {0, 0, 0}, cam_dx[3] = {0, 0, 0}, cam_dy[3] = {0, 0, 0}, cam_zrow[3] = {0, 0, 1};
  // The stages read the shading normal (ShadingPoints::snx..) instead of the geometric
  // one: some mesh has vertex normals or some material bumps (has_normals || has_bump)
  bool shading_normals = false;
  // --guide: the path guide the renderer learned so far (wave/guide.h; null: none), read by
  // the general pipeline's BSDF and light stages
  const GuideView* guide = nullptr;
  // Textured roughness (pbrt's "texture roughness" / uroughness / vroughness): per
  // material, the float textures of alpha_u and alpha_v (2 entries, -1: the constant in
  // mat_param) and whether their values go through RoughnessToAlpha (sqrt); looked up per
  // shading point (surface_hits.h apply_roughness_textures)
  bool has_rough_tex = false;
  const int32_t* mat_alpha_tex = nullptr;
  const int32_t* mat_remap = nullptr;
  const float* const* tex_rgb = nullptr;       // per texture
  const int32_t *tex_w = nullptr, *tex_h = nullptr;
  // Participating media (scenes with some: has_media; wave/media.h)
  bool has_media = false;
  MediumView media;
  // Instances (scenes with some: has_instances). A hit of instance i (Embree's instID,
  // which src/accel keeps as i) is of a shape whose rows hold it in its object's space:
  // the hit stages compute the point there and place it by inst_m (world_from_object, 3
  // rows of 4 per instance); inst_inv is its inverse (object_from_world), whose transpose
  // turns normals. Both are what Embree traces with (the same floats).
  bool has_instances = false;
  int32_t inst_count = 0;
  const float* inst_m = nullptr;
  const float* inst_inv = nullptr;
};

// Whether geometry g is a triangle mesh.
inline bool is_mesh(const GeomView& G, int32_t g) { return G.geom_kind[g] == static_cast<int32_t>(GeomKind::triangles); }

struct CameraView {
  float m[3][4];          // world_from_camera
  float sx0, sx1, sy0, sy1;  // screen window
  float tan_half;         // tan(fov / 2)
  float inv_w, inv_h;
  FilterView filter;      // the pixel filter (sample/filter.h); default: the unit box
};

}  // namespace tuile

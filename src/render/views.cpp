// build_views: the scene as the kernels read it (SoA light table with its pick
// distribution and alias table, flattened triangles, per-geometry lookups, camera).
#include "render/views.h"
#include "bsdf/coated.h"
#include "bsdf/hair.h"
#include "bsdf/microfacet.h"
#include "scene/sky_map.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <stdexcept>

namespace tuile {

// Vose's alias method: O(1) sampling of a discrete distribution.
static void build_alias(const std::vector<float>& p, std::vector<float>& prob, std::vector<int32_t>& alias) {
  const size_t n = p.size();
  prob.assign(n, 1.f);
  alias.resize(n);
  std::iota(alias.begin(), alias.end(), 0);
  std::vector<double> scaled(n);
  std::vector<int32_t> small, large;
  for (size_t i = 0; i < n; ++i) {
    scaled[i] = static_cast<double>(p[i]) * static_cast<double>(n);
    (scaled[i] < 1.0 ? small : large).push_back(static_cast<int32_t>(i));
  }
  while (!small.empty() && !large.empty()) {
    const int32_t s = small.back(), l = large.back();
    small.pop_back();
    prob[s] = static_cast<float>(scaled[s]);
    alias[s] = l;
    scaled[l] = (scaled[l] + scaled[s]) - 1.0;
    if (scaled[l] < 1.0) {
      large.pop_back();
      small.push_back(l);
    }
  }
  for (int32_t i : large) prob[i] = 1.f;
  for (int32_t i : small) prob[i] = 1.f;  // numerical leftovers
}


namespace {

// The light table as the kernels read it (LightView: each source's shape and radiance, the
// constants of its kind, the pick distribution and the light BVH), padded to its tier.
void build_light_table(SceneViews& v, const Scene& scene, LightPick pick, bool sky_compensated) {
  const auto& lights = scene.lights;
  const size_t n = lights.size();
  v.features = scene.features;
  v.lights.any_two_sided = false;
  for (const Light& l : lights) {
    v.type.push_back(static_cast<int32_t>(l.type));
    if (is_sky(l.type)) {  // a sky's table row: p0.x its map (-1: none), n its frame's z axis (light/kinds/infinite.h)
      v.p0x.push_back(static_cast<float>(l.sky_map)); v.p0y.push_back(0.f); v.p0z.push_back(0.f);
    } else {
      v.p0x.push_back(l.p0.x); v.p0y.push_back(l.p0.y); v.p0z.push_back(l.p0.z);
    }
    v.e1x.push_back(l.e1.x); v.e1y.push_back(l.e1.y); v.e1z.push_back(l.e1.z);
    v.e2x.push_back(l.e2.x); v.e2y.push_back(l.e2.y); v.e2z.push_back(l.e2.z);
    v.Lr.push_back(l.radiance.r); v.Lg.push_back(l.radiance.g); v.Lb.push_back(l.radiance.b);
    v.two_sided.push_back(l.two_sided ? 1.f : 0.f);
    v.lights.any_two_sided = v.lights.any_two_sided || l.two_sided;
    LightGeom<float> g;
    g.type = static_cast<int32_t>(l.type);
    g.e1 = l.e1;
    g.e2 = l.e2;
    g.area = l.area;
    light_geom_derive(g);
    v.area.push_back(g.area);
    v.len1.push_back(g.len1); v.len2.push_back(g.len2);
    v.inv_len1.push_back(g.inv_len1); v.inv_len2.push_back(g.inv_len2);
    v.rect.push_back(g.rect);
    v.exx.push_back(g.ex.x); v.exy.push_back(g.ex.y); v.exz.push_back(g.ex.z);
    v.eyx.push_back(g.ey.x); v.eyy.push_back(g.ey.y); v.eyz.push_back(g.ey.z);
    // the emitting side's unit normal; a rectangle's is cross(ex, ey), which rectangle
    // pipelines compute from the unit edges instead of reading it (the same bits)
    vec3f nn{0, 0, 0};
    if (g.rect > 0.5f) nn = cross(g.ex, g.ey);
    else if (is_planar(l.type)) nn = normalize(cross(l.e1, l.e2));
    else if (is_sky(l.type)) nn = l.p0;
    v.nx.push_back(nn.x); v.ny.push_back(nn.y); v.nz.push_back(nn.z);
  }
  // pick distribution
  v.pick_pdf.assign(n, 0.f);
  if (n > 0) {
    std::vector<double> weight(n, 1.0);
    if (pick == LightPick::area) {  // the sources without a surface (delta, sky) weigh the mean area
      double mean_area = 0;
      int na = 0;
      for (const Light& l : lights)
        if (l.area > 0) mean_area += l.area, ++na;
      mean_area = na ? mean_area / na : 1.0;
      for (size_t i = 0; i < n; ++i) weight[i] = lights[i].area > 0 ? lights[i].area : mean_area;
    } else if (pick == LightPick::power) {
      for (size_t i = 0; i < n; ++i) {
        weight[i] = std::max(0.f, lights[i].power);
        // under MIS a sky's light samples draw its compensated part alone (the BSDF samples
        // the rest): a constant sky none, a map the share above its mean
        if (sky_compensated && is_sky(lights[i].type))
          weight[i] *= lights[i].sky_map < 0 ? 0.0 : scene.sky_maps[static_cast<size_t>(lights[i].sky_map)].compensated_share;
      }
    }
    double total = 0;
    for (double w : weight) total += w;
    if (!(total > 0) || !std::isfinite(total)) {
      std::fill(weight.begin(), weight.end(), 1.0);
      total = static_cast<double>(n);
    }
    for (size_t i = 0; i < n; ++i)
      v.pick_pdf[i] = pick == LightPick::all ? 1.f : static_cast<float>(weight[i] / total);
    std::vector<float> p(n);
    for (size_t i = 0; i < n; ++i) p[i] = static_cast<float>(weight[i] / total);
    build_alias(p, v.alias_prob, v.alias_idx);
  }
  // Small and medium tables are read with permutes of vector loads (lookup_small,
  // lookup_medium): pad them to their tier's size so that those loads stay inside.
  const int tier = table_tier(n);
  if (n > 0 && tier != tier_gather) {
    const size_t padded = static_cast<size_t>(tier == tier_small ? small_table_size : medium_table_size);
    for (auto* f : {&v.p0x, &v.p0y, &v.p0z, &v.e1x, &v.e1y, &v.e1z, &v.e2x, &v.e2y, &v.e2z, &v.nx, &v.ny, &v.nz, &v.Lr,
                    &v.Lg, &v.Lb, &v.area, &v.two_sided, &v.len1, &v.len2, &v.inv_len1, &v.inv_len2, &v.rect,
                    &v.exx, &v.exy, &v.exz, &v.eyx, &v.eyy, &v.eyz,
                    &v.pick_pdf, &v.alias_prob})
      f->resize(padded, 0.f);
    v.type.resize(padded, 0);
    v.alias_idx.resize(padded, 0);
  }
  LightView& L = v.lights;
  L.count = static_cast<int32_t>(n);
  L.tier = tier;
  L.type = v.type.data();
  L.p0x = v.p0x.data(); L.p0y = v.p0y.data(); L.p0z = v.p0z.data();
  L.e1x = v.e1x.data(); L.e1y = v.e1y.data(); L.e1z = v.e1z.data();
  L.e2x = v.e2x.data(); L.e2y = v.e2y.data(); L.e2z = v.e2z.data();
  L.nx = v.nx.data(); L.ny = v.ny.data(); L.nz = v.nz.data();
  L.Lr = v.Lr.data(); L.Lg = v.Lg.data(); L.Lb = v.Lb.data();
  L.one_radiance = n > 0;
  for (size_t i = 1; i < n; ++i)
    L.one_radiance = L.one_radiance && v.Lr[i] == v.Lr[0] && v.Lg[i] == v.Lg[0] && v.Lb[i] == v.Lb[0];
  L.area = v.area.data();
  L.two_sided = v.two_sided.data();
  L.len1 = v.len1.data(); L.len2 = v.len2.data();
  L.inv_len1 = v.inv_len1.data(); L.inv_len2 = v.inv_len2.data();
  L.rect = v.rect.data();
  L.exx = v.exx.data(); L.exy = v.exy.data(); L.exz = v.exz.data();
  L.eyx = v.eyx.data(); L.eyy = v.eyy.data(); L.eyz = v.eyz.data();
  L.pick_pdf = v.pick_pdf.data();
  L.alias_prob = v.alias_prob.data();
  L.alias_idx = v.alias_idx.data();
  for (size_t i = 0; i < n; ++i)
    if (is_sky(lights[i].type)) v.sky_light.push_back(static_cast<int32_t>(i));
  L.sky_count = static_cast<int32_t>(v.sky_light.size());
  L.sky_light = v.sky_light.data();
  for (const SkyMap& m : scene.sky_maps) v.sky_maps.push_back(sky_map_view(m));
  L.sky_maps = v.sky_maps.data();
  L.sky_map_count = static_cast<int32_t>(v.sky_maps.size());
  // cut-out emitters: each source's shape with an alpha (one entry per mesh or sphere)
  std::vector<int32_t> mesh_shape(scene.meshes.size(), -1), sphere_shape(scene.spheres.size(), -1);
  for (size_t i = 0; i < n; ++i) {
    const Light& l = lights[i];
    int32_t* shape = nullptr;
    AlphaShape a;
    if (l.mesh >= 0 && scene.meshes[static_cast<size_t>(l.mesh)].has_alpha()) {
      shape = &mesh_shape[static_cast<size_t>(l.mesh)];
      a = alpha_shape(scene, scene.meshes[static_cast<size_t>(l.mesh)]);
    } else if (l.sphere >= 0 && scene.spheres[static_cast<size_t>(l.sphere)].alpha < 1) {
      shape = &sphere_shape[static_cast<size_t>(l.sphere)];
      a.value = scene.spheres[static_cast<size_t>(l.sphere)].alpha;
    }
    if (!shape) continue;
    if (v.light_alpha_shape.empty()) {
      v.light_alpha_shape.assign(n, -1);
      v.light_alpha_prim.assign(n, 0);
    }
    if (*shape < 0) {
      *shape = static_cast<int32_t>(v.alpha_shapes.size());
      v.alpha_shapes.push_back(a);
    }
    v.light_alpha_shape[i] = *shape;
    v.light_alpha_prim[i] = std::max(l.prim, 0);
  }
  if (!v.light_alpha_shape.empty()) {
    L.alpha_shape = v.light_alpha_shape.data();
    L.alpha_prim = v.light_alpha_prim.data();
    L.alpha_shapes = v.alpha_shapes.data();
  }
  if (pick == LightPick::bvh && n > 1) {
    const auto t0 = std::chrono::steady_clock::now();
    v.light_bvh = std::make_unique<LightBvh>(build_light_bvh(lights));
    v.light_bvh_view = std::make_unique<LightBvhView>(v.light_bvh->view());
    v.light_bvh_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    L.bvh = v.light_bvh_view.get();
  }
}

// The geometry view's pointers into the tables (again after a table grows).
void point_tables(SceneViews& v) {
  GeomView& G = v.geom;
  G.geom_kind = v.geom_kind.data();
  G.geom_material = v.geom_material.data();
  G.geom_first = v.geom_first.data();
  G.geom_light = v.geom_light.data();
  G.geom_side = v.geom_side.data();
  G.sphere_center = v.sphere_center.data();
  G.tri_pos = v.tri_pos.data();
  G.tri_light = v.tri_light.data();
  G.mat_r = v.mat_r.data();
  G.mat_g = v.mat_g.data();
  G.mat_b = v.mat_b.data();
  G.mat_texture = v.mat_texture.data();
  G.mat_kind = v.mat_kind.data();
  G.mat_alpha_tex = v.mat_alpha_tex.data();
  G.mat_remap = v.mat_remap.data();
  G.mat_mix0 = v.mat_mix0.data();
  G.mat_mix1 = v.mat_mix1.data();
  G.mat_mix_amount = v.mat_mix_amount.data();
  G.mat_reg = v.mat_reg.data();
  for (int i = 0; i < mp_count; ++i) G.mat_param[i] = v.mat_param[i].data();
  G.indices = v.indices.data();
  G.positions = v.positions.data();
  G.uvs = v.uvs.data();
  G.normals = v.normals.data();
  G.curve_points = v.curve_points.data();
  G.tex_rgb = v.tex_rgb.data();
  G.tex_w = v.tex_w.data();
  G.tex_h = v.tex_h.data();
  G.mat_bump = v.mat_bump.data();
  G.ftex_value = v.ftex_value.data();
  G.ftex_w = v.ftex_w.data();
  G.ftex_h = v.ftex_h.data();
  G.ftex_mip = v.ftex_mip.data();
  G.ftex_mip_w = v.ftex_mip_w.data();
  G.ftex_mip_h = v.ftex_mip_h.data();
  G.ftex_mip_at = v.ftex_mip_at.data();
  G.ftex_levels = v.ftex_levels.data();
  G.ftex_filter = v.ftex_filter.data();
}

// The geometry table (one row per geomID: GeomView::geom_kind and its fields) and the
// flattened triangles.
void build_geometry_table(SceneViews& v, const Scene& scene) {
  const int32_t default_material = static_cast<int32_t>(scene.materials.size());
  // Flattened triangles, gathered by the camera-hit stage at 9 * triangle in int32 lanes.
  size_t tris = 0;
  for (const Mesh& m : scene.meshes) tris += m.triangle_count();
  if (tris + 1 > static_cast<size_t>(INT32_MAX))
    throw std::runtime_error("scene has " + std::to_string(tris) + " triangles; at most " +
                             std::to_string(INT32_MAX - 1) + " are supported");
  // (GeomView::flat_triangles: the table for scenes below 2^23 triangles, 300 MB)
  v.geom.flat_triangles = tris < (size_t(1) << 23);
  // The triangles' rows are written in parallel blocks after the table's rows, into arrays
  // allocated without zero-filling (their pages are first touched by the threads that fill
  // them): the kitchen's 1.4 M triangles took a tenth of its set-up one at a time.
  v.tri_pos.resize(v.geom.flat_triangles ? 9 * (tris + 1) : 9);
  v.tri_light.resize(tris + 1);
  std::vector<size_t> mesh_first;  // each mesh's first triangle
  mesh_first.reserve(scene.meshes.size() + 1);
  // The geometry table, one row per Embree geomID (src/accel/embree.cpp attaches the meshes,
  // then the spheres, then the curves, in scene order).
  for (const Mesh& m : scene.meshes) {
    v.geom_kind.push_back(static_cast<int32_t>(GeomKind::triangles));
    v.geom_material.push_back(m.material >= 0 ? m.material : default_material);
    v.geom_side.push_back(m.reverse_orientation ? -1.f : 1.f);
    const size_t first = mesh_first.empty() ? 0 : mesh_first.back() + scene.meshes[mesh_first.size() - 1].triangle_count();
    mesh_first.push_back(first);
    v.geom_first.push_back(static_cast<int32_t>(first));
    v.geom_light.push_back(-1);  // per triangle: tri_light
    v.indices.push_back(m.indices.data());
    v.positions.push_back(m.positions.data());
    v.uvs.push_back(m.uvs.empty() ? nullptr : m.uvs.data());
    v.normals.push_back(m.normals.empty() ? nullptr : m.normals.data());
    v.curve_points.push_back(nullptr);
    v.geom.has_normals |= !m.normals.empty();
  }
  for (const Sphere& s : scene.spheres) {
    v.geom_kind.push_back(static_cast<int32_t>(GeomKind::sphere));
    v.geom_material.push_back(s.material >= 0 ? s.material : default_material);
    v.geom_side.push_back(s.reverse_orientation ? -1.f : 1.f);
    v.geom_first.push_back(static_cast<int32_t>(v.sphere_center.size() / 4));
    v.geom_light.push_back(s.light);
    v.sphere_center.insert(v.sphere_center.end(), {s.center.x, s.center.y, s.center.z, s.radius});
    v.indices.push_back(nullptr);  // a mesh's arrays: none
    v.positions.push_back(nullptr);
    v.uvs.push_back(nullptr);
    v.normals.push_back(nullptr);
    v.curve_points.push_back(nullptr);
  }
  for (const Curves& c : scene.curves) {
    v.geom_kind.push_back(static_cast<int32_t>(c.type == CurveType::flat ? GeomKind::flat_curve : GeomKind::curve));
    v.geom_material.push_back(c.material >= 0 ? c.material : default_material);
    v.geom_side.push_back(1.f);
    v.geom_first.push_back(static_cast<int32_t>(v.sphere_center.size() / 4));
    v.geom_light.push_back(-1);  // curves never emit
    v.sphere_center.insert(v.sphere_center.end(), {0.f, 0.f, 0.f, c.max_radius()});
    v.indices.push_back(nullptr);
    v.positions.push_back(nullptr);
    v.uvs.push_back(nullptr);
    v.normals.push_back(nullptr);
    v.curve_points.push_back(c.points.data());
  }
  mesh_first.push_back(tris);
  // the triangles' rows: the vertices of each (flat_triangles) and its light (-1: none)
  tbb::parallel_for(tbb::blocked_range<size_t>(0, tris, size_t(1) << 14), [&](const tbb::blocked_range<size_t>& r) {
    size_t mi = static_cast<size_t>(std::upper_bound(mesh_first.begin(), mesh_first.end(), r.begin()) - mesh_first.begin()) - 1;
    for (size_t t = r.begin(); t < r.end(); ++t) {
      while (t >= mesh_first[mi + 1]) ++mi;
      const Mesh& m = scene.meshes[mi];
      const size_t local = t - mesh_first[mi];
      v.tri_light[t] = m.prim_light.empty() ? -1 : m.prim_light[local];
      if (!v.geom.flat_triangles) continue;
      float* out = v.tri_pos.data() + 9 * t;
      for (int k = 0; k < 3; ++k) {
        const float* p = m.positions.data() + 3 * static_cast<size_t>(m.indices[3 * local + static_cast<size_t>(k)]);
        out[3 * k] = p[0];
        out[3 * k + 1] = p[1];
        out[3 * k + 2] = p[2];
      }
    }
  });
  v.geom.geom_count = static_cast<int32_t>(v.geom_kind.size());
  // never empty (a scene without geometry reads row 0 of no hit)
  v.geom_kind.push_back(static_cast<int32_t>(GeomKind::triangles));
  v.geom_first.push_back(0);
  v.geom_light.push_back(-1);
  v.sphere_center.insert(v.sphere_center.end(), 4, 0.f);
  std::fill_n(v.tri_pos.end() - 9, 9, 0.f);  // a spare triangle: never empty
  v.tri_light.back() = -1;
}

// The material table (each material's reflectance, kind and BSDF parameters, its mix and
// textures), the kinds of surface the geometry has, bump mapping, the textures, and the
// geometry view's pointers into all of it.
void build_material_table(SceneViews& v, const Scene& scene) {
  // A displacement texture whose texels are all equal moves the surface along its normal
  // without turning it (the offset surface's normal field is the surface's): no bump
  // (pbrt-v4's d dn/du term, from the interpolated vertex normals, is left out with it).
  const auto bump_texture = [&](const Material& m) -> int32_t {
    if (m.displacement < 0) return -1;
    const FloatTexture& t = scene.float_textures[static_cast<size_t>(m.displacement)];
    if (t.value.empty() || std::all_of(t.value.begin(), t.value.end(), [&](float x) { return x == t.value[0]; }))
      return -1;
    return m.displacement;
  };
  auto add_material = [&](const Material& m) {
    v.mat_bump.push_back(bump_texture(m));
    // a textured reflectance replaces the constant (Scene's Material): the points of a
    // textured material take their texel (apply_texels); those without one (no uv, a
    // sphere, a mix's choice) take the texture's mean
    Rgb r = m.reflectance;
    if (m.texture >= 0) {
      const Texture& t = scene.textures[static_cast<size_t>(m.texture)];
      double sum[3] = {0, 0, 0};
      const size_t n = t.rgb.size() / 3;
      for (size_t i = 0; i < n; ++i)
        for (int c = 0; c < 3; ++c) sum[c] += t.rgb[3 * i + static_cast<size_t>(c)];
      if (n > 0) r = {static_cast<float>(sum[0] / static_cast<double>(n)), static_cast<float>(sum[1] / static_cast<double>(n)),
                      static_cast<float>(sum[2] / static_cast<double>(n))};
    }
    v.mat_r.push_back(r.r);
    v.mat_g.push_back(r.g);
    v.mat_b.push_back(r.b);
    v.mat_texture.push_back(m.texture);
    v.mat_kind.push_back(static_cast<int32_t>(m.kind));
    const HairConstants h = hair_constants(m.beta_m, m.beta_n, m.hair_alpha);
    const Rgb3<float> ri = m.kind == MaterialKind::coated_diffuse
                               ? coat_internal_reflectance_rgb(m.eta, m.thickness, Rgb3<float>{m.albedo.r, m.albedo.g, m.albedo.b})
                               : Rgb3<float>{0.f, 0.f, 0.f};
    const float p[mp_count] = {m.transmittance.r, m.transmittance.g, m.transmittance.b, m.eta_rgb.r, m.eta_rgb.g,
                               m.eta_rgb.b,       m.k_rgb.r,         m.k_rgb.g,         m.k_rgb.b,   m.eta,
                               m.alpha_u.value,   m.alpha_v.value,   m.base_alpha_u.value, m.base_alpha_v.value,
                               m.thickness,       m.albedo.r,        m.albedo.g,        m.albedo.b,
                               m.hair_sigma_a.r,  m.hair_sigma_a.g,  m.hair_sigma_a.b,
                               h.inv_v[0],        h.inv_v[1],        h.inv_v[2],
                               h.log_norm[0],     h.log_norm[1],     h.log_norm[2],
                               h.exp_m2v[0],      h.exp_m2v[1],      h.exp_m2v[2],
                               h.v[0],            h.v[1],            h.v[2],
                               h.s,               h.e_pi_s,
                               h.sin2k[0],        h.sin2k[1],        h.sin2k[2],
                               h.cos2k[0],        h.cos2k[1],        h.cos2k[2],
                               0.f,               ri.r,              ri.g,              ri.b};
    for (int i = 0; i < mp_count; ++i) v.mat_param[i].push_back(p[i]);
    v.mat_alpha_tex.push_back(m.alpha_u.texture);
    v.mat_alpha_tex.push_back(m.alpha_v.texture);
    v.mat_remap.push_back(m.remap_roughness ? 1 : 0);
    v.mat_mix0.push_back(m.mix[0]);
    v.mat_mix1.push_back(m.mix[1]);
    v.mat_mix_amount.push_back(m.mix_amount.value);
  };
  for (const Material& m : scene.materials) {
    add_material(m);
    v.geom.has_textures |= m.texture >= 0;
  }
  add_material(Material{});  // the default material: diffuse grey 0.5
  // the kinds of surface some geometry has (an empty scene counts as diffuse)
  v.bsdf_kinds = 1u << static_cast<int>(MaterialKind::diffuse);
  if (!v.geom_material.empty()) v.bsdf_kinds = 0;
  for (const int32_t m : v.geom_material) {
    const auto k = static_cast<size_t>(m);
    if (v.mat_mix0[k] < 0) {
      v.bsdf_kinds |= 1u << v.mat_kind[k];
    } else {
      v.geom.has_mix = true;
      v.bsdf_kinds |= 1u << v.mat_kind[static_cast<size_t>(v.mat_mix0[k])];
      v.bsdf_kinds |= 1u << v.mat_kind[static_cast<size_t>(v.mat_mix1[k])];
    }
  }
  // bump mapping: where a mesh's material, or one a mix of it chooses, has a bump texture
  for (size_t g = 0; g < scene.meshes.size(); ++g) {
    const auto k = static_cast<size_t>(v.geom_material[g]);
    v.geom.has_bump |= v.mat_bump[k] >= 0;
    for (const int32_t c : {v.mat_mix0[k], v.mat_mix1[k]})
      if (c >= 0) v.geom.has_bump |= v.mat_bump[static_cast<size_t>(c)] >= 0;
  }
  v.geom.shading_normals = v.geom.has_normals || v.geom.has_bump;
  v.geom.has_hair = (v.bsdf_kinds & bsdf_hair) != 0;
  for (const FloatTexture& t : scene.float_textures) {
    v.ftex_value.push_back(t.value.data());
    v.ftex_w.push_back(t.width);
    v.ftex_h.push_back(t.height);
    v.ftex_mip.push_back(t.mip.data());
    v.ftex_mip_w.push_back(t.mip_w.data());
    v.ftex_mip_h.push_back(t.mip_h.data());
    v.ftex_mip_at.push_back(t.mip_at.data());
    v.ftex_levels.push_back(static_cast<int32_t>(t.mip_w.size()));
    v.ftex_filter.push_back(static_cast<int32_t>(t.filter));
  }
  for (const Texture& t : scene.textures) {
    v.tex_rgb.push_back(t.rgb.data());
    v.tex_w.push_back(t.width);
    v.tex_h.push_back(t.height);
  }
  v.geom_side.push_back(1.f);  // never empty
  point_tables(v);
  GeomView& G = v.geom;
  for (const int32_t m : v.geom_material) {  // (a mix's materials: their own textures)
    const auto k = static_cast<size_t>(m);
    for (const int32_t e : {m, v.mat_mix0[k], v.mat_mix1[k]})
      if (e >= 0 && (v.mat_alpha_tex[2 * static_cast<size_t>(e)] >= 0 || v.mat_alpha_tex[2 * static_cast<size_t>(e) + 1] >= 0))
        G.has_rough_tex = true;
  }
}

// Participating media (GeomView::media, wave/media.h): per medium its coefficients, a
// material row (its phase function) and a geometry row (GeomKind::medium: where its
// scattering points are hits); per geomID the media a surface separates. Media of types
// tuile does not render (warned at load) are vacuum here.
void build_media_table(SceneViews& v, const Scene& scene) {
  GeomView& G = v.geom;
  G.has_media = (scene.features & feat_media) != 0;
  if (!G.has_media) return;
  const size_t geoms = static_cast<size_t>(G.geom_count);
  auto sides = [&](int in, int out, int material, bool emissive) {
    in = rendered_medium(scene, in);
    out = rendered_medium(scene, out);
    const bool change = in != out;
    v.med_geom_in.push_back(change ? in : -1);
    v.med_geom_out.push_back(change ? out : -1);
    v.med_geom_interface.push_back(passes_between_media(scene, material, in, out, emissive) ? 1 : 0);
  };
  for (const Mesh& m : scene.meshes) sides(m.medium_inside, m.medium_outside, m.material, m.emissive());
  for (const Sphere& s : scene.spheres) sides(s.medium_inside, s.medium_outside, s.material, s.emissive());
  for (const Curves& c : scene.curves) sides(c.medium_inside, c.medium_outside, c.material, false);
  // the spare row of the geometry table (build_geometry_table) in the tables that lack it,
  // so that medium m's row is geoms + 1 + m in every one
  v.geom_material.push_back(static_cast<int32_t>(scene.materials.size()));
  v.indices.push_back(nullptr);
  v.positions.push_back(nullptr);
  v.uvs.push_back(nullptr);
  v.normals.push_back(nullptr);
  v.curve_points.push_back(nullptr);
  sides(-1, -1, -1, false);
  G.media.geom0 = static_cast<int32_t>(geoms + 1);
  const int32_t phase0 = static_cast<int32_t>(v.mat_kind.size());
  for (size_t i = 0; i < scene.media.size(); ++i) {
    const Medium& md = scene.media[i];
    const Rgb sa = md.supported ? md.sigma_a : Rgb{0, 0, 0}, ss = md.supported ? md.sigma_s : Rgb{0, 0, 0};
    const float st[3] = {sa.r + ss.r, sa.g + ss.g, sa.b + ss.b}, s[3] = {ss.r, ss.g, ss.b};
    const float e[3] = {sa.r * md.Le.r, sa.g * md.Le.g, sa.b * md.Le.b};
    for (int c = 0; c < 3; ++c) {
      v.med_sigma_t[c].push_back(st[c]);
      v.med_sigma_s[c].push_back(s[c]);
      v.med_emit[c].push_back(md.supported ? e[c] : 0.f);
    }
    v.med_scatters.push_back(s[0] > 0 || s[1] > 0 || s[2] > 0 ? 1 : 0);
    v.med_emits.push_back(md.supported && (e[0] > 0 || e[1] > 0 || e[2] > 0) ? 1 : 0);
    // its phase function: a material row
    v.mat_bump.push_back(-1);
    v.mat_r.push_back(1.f);
    v.mat_g.push_back(1.f);
    v.mat_b.push_back(1.f);
    v.mat_texture.push_back(-1);
    v.mat_kind.push_back(static_cast<int32_t>(MaterialKind::phase));
    for (int p = 0; p < mp_count; ++p) v.mat_param[p].push_back(p == mp_hg_g ? md.g : 0.f);
    v.mat_alpha_tex.push_back(-1);
    v.mat_alpha_tex.push_back(-1);
    v.mat_remap.push_back(0);
    v.mat_mix0.push_back(-1);
    v.mat_mix1.push_back(-1);
    v.mat_mix_amount.push_back(0.f);
    // and a geometry row
    v.geom_kind.push_back(static_cast<int32_t>(GeomKind::medium));
    v.geom_material.push_back(phase0 + static_cast<int32_t>(i));
    v.geom_side.push_back(1.f);
    v.geom_first.push_back(static_cast<int32_t>(i));
    v.geom_light.push_back(-1);
    v.indices.push_back(nullptr);
    v.positions.push_back(nullptr);
    v.uvs.push_back(nullptr);
    v.normals.push_back(nullptr);
    v.curve_points.push_back(nullptr);
    const int m = static_cast<int>(i);
    sides(m, m, -1, false);  // (a point in the medium: the medium on both sides, stage-set)
  }
  v.bsdf_kinds |= bsdf_phase;
  MediumView& M = G.media;
  M.count = static_cast<int32_t>(scene.media.size());
  for (int c = 0; c < 3; ++c) {
    M.sigma_t[c] = v.med_sigma_t[c].data();
    M.sigma_s[c] = v.med_sigma_s[c].data();
    M.emit[c] = v.med_emit[c].data();
  }
  M.scatters = v.med_scatters.data();
  M.emits = v.med_emits.data();
  M.geom_in = v.med_geom_in.data();
  M.geom_out = v.med_geom_out.data();
  M.geom_interface = v.med_geom_interface.data();
  M.has_interfaces = std::any_of(v.med_geom_interface.begin(), v.med_geom_interface.end(), [](int32_t i) { return i != 0; });
  M.camera = rendered_medium(scene, scene.camera_medium);
  M.absorb_only = !M.has_interfaces && std::none_of(v.med_scatters.begin(), v.med_scatters.end(), [](int32_t x) { return x != 0; }) &&
                  std::none_of(v.med_emits.begin(), v.med_emits.end(), [](int32_t x) { return x != 0; });
  point_tables(v);  // the tables grew: their views again
}

// The camera as the generate stage reads it, and the pixel footprint of bump mapping.
void build_camera_view(SceneViews& v, const Scene& scene) {
  const Camera& c = scene.camera;
  GeomView& G = v.geom;
  CameraView& cv = v.camera;
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 4; ++k) cv.m[r][k] = c.world_from_camera[r][k];
  const float aspect = static_cast<float>(c.width) / static_cast<float>(c.height);
  if (c.screen[0] != 0 || c.screen[1] != 0 || c.screen[2] != 0 || c.screen[3] != 0) {
    cv.sx0 = c.screen[0]; cv.sx1 = c.screen[1]; cv.sy0 = c.screen[2]; cv.sy1 = c.screen[3];
  } else if (aspect > 1.f) {
    cv.sx0 = -aspect; cv.sx1 = aspect; cv.sy0 = -1; cv.sy1 = 1;
  } else {
    cv.sx0 = -1; cv.sx1 = 1; cv.sy0 = -1 / aspect; cv.sy1 = 1 / aspect;
  }
  cv.tan_half = std::tan(0.5f * c.fov_deg * 3.14159265f / 180.f);
  cv.inv_w = 1.f / static_cast<float>(c.width);
  cv.inv_h = 1.f / static_cast<float>(c.height);
  // The pixel footprint of bump mapping (surface_hits.h bump_normal): the camera ray's
  // direction with camera z = 1 is M (sx tan, sy tan, 1), which moves by M's first column
  // times (sx1 - sx0) tan / width per pixel along x (likewise y). pbrt-v4 scales its camera
  // differentials by max(1/8, 1/sqrt(spp)); tuile takes 1/8 at every spp, pbrt's value
  // from 64 spp on, so that the bump (and the image's expectation) does not depend on
  // the spp of a render.
  constexpr float footprint_scale = 0.125f;
  const vec3f col0{cv.m[0][0], cv.m[1][0], cv.m[2][0]}, col1{cv.m[0][1], cv.m[1][1], cv.m[2][1]};
  const vec3f col2{cv.m[0][2], cv.m[1][2], cv.m[2][2]};
  const vec3f dx = col0 * ((cv.sx1 - cv.sx0) * cv.tan_half * cv.inv_w * footprint_scale);
  const vec3f dy = col1 * ((cv.sy1 - cv.sy0) * cv.tan_half * cv.inv_h * footprint_scale);
  const vec3f c01 = cross(col0, col1);
  const float det = dot(c01, col2);
  const vec3f zrow = det != 0.f ? c01 * (1.f / det) : vec3f{0, 0, 0};
  const float dxa[3] = {dx.x, dx.y, dx.z}, dya[3] = {dy.x, dy.y, dy.z}, za[3] = {zrow.x, zrow.y, zrow.z};
  for (int i = 0; i < 3; ++i) {
    G.cam_o[i] = cv.m[i][3];
    G.cam_dx[i] = dxa[i];
    G.cam_dy[i] = dya[i];
    G.cam_zrow[i] = za[i];
  }
}

// The instances' transforms (GeomView::inst_m, inst_inv): the scene's floats, which Embree
// traces with, and their inverse (in double, then rounded).
void build_instance_table(SceneViews& v, const Scene& scene) {
  GeomView& G = v.geom;
  G.has_instances = !scene.instances.empty();
  G.inst_count = static_cast<int32_t>(scene.instances.size());
  v.inst_m.reserve(12 * (scene.instances.size() + 1));
  v.inst_inv.reserve(12 * (scene.instances.size() + 1));
  for (const Instance& in : scene.instances) {
    double a[3][3], t[3];
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) a[r][c] = in.world_from_object[r][c];
      t[r] = in.world_from_object[r][3];
      v.inst_m.insert(v.inst_m.end(), in.world_from_object[r], in.world_from_object[r] + 4);
    }
    // the inverse of the linear part by cofactors, then -A^-1 t
    const double det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
                       a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    double inv[3][3];
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) {
        const int r1 = (c + 1) % 3, r2 = (c + 2) % 3, c1 = (r + 1) % 3, c2 = (r + 2) % 3;
        inv[r][c] = (a[r1][c1] * a[r2][c2] - a[r1][c2] * a[r2][c1]) / det;
      }
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) v.inst_inv.push_back(static_cast<float>(inv[r][c]));
      v.inst_inv.push_back(static_cast<float>(-(inv[r][0] * t[0] + inv[r][1] * t[1] + inv[r][2] * t[2])));
    }
  }
  v.inst_m.insert(v.inst_m.end(), 12, 0.f);  // never empty
  v.inst_inv.insert(v.inst_inv.end(), 12, 0.f);
  G.inst_m = v.inst_m.data();
  G.inst_inv = v.inst_inv.data();
}

// Regularization's twin rows (GeomView::mat_reg), appended after every other material
// (the media's phase rows too), one per material whose BSDF has Trowbridge-Reitz alphas
// that regularization changes. A textured alpha changes per point (regularize_points);
// its material gets a twin anyway, for its constant columns.
void build_regularized_twins(SceneViews& v) {
  const size_t n = v.mat_kind.size();
  v.mat_reg.resize(n);
  for (size_t m = 0; m < n; ++m) {
    v.mat_reg[m] = static_cast<int32_t>(m);
    const auto kind = static_cast<MaterialKind>(v.mat_kind[m]);
    if (!microfacet_kind(v.mat_kind[m]) || v.mat_mix0[m] >= 0) continue;
    float p[mp_count];
    for (int i = 0; i < mp_count; ++i) p[i] = v.mat_param[i][m];
    bool changes = v.mat_alpha_tex[2 * m] >= 0 || v.mat_alpha_tex[2 * m + 1] >= 0;
    for (const int i : {int(mp_ax), int(mp_ay), int(mp_bax), int(mp_bay)}) {
      if (i >= mp_bax && kind != MaterialKind::coated_conductor) continue;
      const float r = regularized_alpha(p[i]);
      changes |= r != p[i];
      p[i] = r;
    }
    if (!changes) continue;
    v.mat_reg[m] = static_cast<int32_t>(v.mat_kind.size());
    v.mat_reg.push_back(v.mat_reg[m]);  // a twin is its own twin (regularizing twice changes nothing more)
    v.mat_bump.push_back(v.mat_bump[m]);
    v.mat_r.push_back(v.mat_r[m]);
    v.mat_g.push_back(v.mat_g[m]);
    v.mat_b.push_back(v.mat_b[m]);
    v.mat_texture.push_back(v.mat_texture[m]);
    v.mat_kind.push_back(v.mat_kind[m]);
    for (int i = 0; i < mp_count; ++i) v.mat_param[i].push_back(p[i]);
    v.mat_alpha_tex.push_back(v.mat_alpha_tex[2 * m]);
    v.mat_alpha_tex.push_back(v.mat_alpha_tex[2 * m + 1]);
    v.mat_remap.push_back(v.mat_remap[m]);
    v.mat_mix0.push_back(-1);
    v.mat_mix1.push_back(-1);
    v.mat_mix_amount.push_back(0.f);
  }
  point_tables(v);
}

}  // namespace

SceneViews build_views(const Scene& scene, LightPick pick, bool sky_compensated) {
  SceneViews out;
  build_light_table(out, scene, pick, sky_compensated);
  build_geometry_table(out, scene);
  build_material_table(out, scene);
  build_media_table(out, scene);
  build_regularized_twins(out);
  build_instance_table(out, scene);
  build_camera_view(out, scene);
  return out;
}

}  // namespace tuile

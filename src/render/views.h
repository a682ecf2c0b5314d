// SceneViews: the scene as the kernels read it, built once per renderer.
#pragma once
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "render/light_bvh.h"
#include "scene/scene.h"
#include "wave/alpha.h"
#include "wave/tile.h"

namespace tuile {

// The scene as the kernels read it: SoA light table (with the pick distribution and its
// alias table), per-geometry lookups, camera. The views point into the vectors here and
// into the Scene, which must outlive them.
struct SceneViews {
  // light table, SoA
  std::vector<int32_t> type;
  SceneViews() = default;
  SceneViews(const SceneViews&) = delete;
  SceneViews& operator=(const SceneViews&) = delete;
  SceneViews(SceneViews&&) = default;
  SceneViews& operator=(SceneViews&&) = default;
  std::vector<float> p0x, p0y, p0z, e1x, e1y, e1z, e2x, e2y, e2z, nx, ny, nz, Lr, Lg, Lb, area, two_sided;
  std::vector<float> len1, len2, inv_len1, inv_len2, rect, exx, exy, exz, eyx, eyy, eyz;
  std::vector<float> pick_pdf, alias_prob;
  std::vector<int32_t> alias_idx;
  std::vector<int32_t> sky_light;  // LightView::sky_light
  std::vector<SkyMapView> sky_maps;  // LightView::sky_maps (pointing into Scene::sky_maps)
  std::vector<int32_t> light_alpha_shape, light_alpha_prim;  // LightView::alpha_shape, alpha_prim
  std::vector<AlphaShape> alpha_shapes;                      // LightView::alpha_shapes (into the Scene)
  LightView lights;
  // --light-pick bvh with two sources or more: the light BVH and its view (lights.bvh; on
  // the heap, so that moving the views keeps the pointer), its build time
  std::unique_ptr<LightBvh> light_bvh;
  std::unique_ptr<LightBvhView> light_bvh_view;
  double light_bvh_seconds = 0;
  // geometry
  std::vector<float> sphere_center;
  std::vector<int32_t> geom_kind, geom_material, geom_first, geom_light, mat_texture, tex_w, tex_h;  // the geometry table
  // (allocated without zero-filling: build_geometry_table writes every element, in parallel)
  template <class T> struct Uninit : std::allocator<T> {
    template <class U> struct rebind { using other = Uninit<U>; };
    template <class U, class... A> void construct(U* p, A&&... a) {
      if constexpr (sizeof...(A) == 0) ::new (static_cast<void*>(p)) U;
      else ::new (static_cast<void*>(p)) U(std::forward<A>(a)...);
    }
  };
  std::vector<int32_t, Uninit<int32_t>> tri_light;
  std::vector<float, Uninit<float>> tri_pos;
  std::vector<const uint32_t*> indices;
  std::vector<const float*> positions;
  std::vector<const float*> uvs, tex_rgb, normals, curve_points;
  std::vector<float> mat_r, mat_g, mat_b;
  std::vector<int32_t> mat_kind, mat_mix0, mat_mix1, mat_alpha_tex, mat_remap;
  std::vector<int32_t> mat_reg;  // regularization's twin of each material (GeomView::mat_reg)
  std::vector<int32_t> mat_lt_glossy, lt_glossy;  // --light-paths (GeomView::mat_lt_glossy, LightView::lt_glossy)
  std::vector<float> mat_mix_amount;
  std::vector<float> mat_param[mp_count];
  std::vector<float> geom_side;
  std::vector<int32_t> mat_bump, ftex_w, ftex_h;  // bump mapping (GeomView::mat_bump, ftex_*)
  std::vector<const float*> ftex_value, ftex_mip;
  std::vector<const int32_t*> ftex_mip_w, ftex_mip_h;
  std::vector<const size_t*> ftex_mip_at;
  std::vector<int32_t> ftex_levels, ftex_filter;
  // participating media (GeomView::media)
  std::vector<float> med_sigma_t[3], med_sigma_s[3], med_emit[3];
  std::vector<int32_t> med_scatters, med_emits, med_geom_in, med_geom_out, med_geom_interface;
  std::vector<float> inst_m, inst_inv;  // instances (GeomView::inst_m, inst_inv)
  GeomView geom;
  CameraView camera;
  std::vector<float> filter_table;  // camera.filter's tables (render/filter_table.h), set by the renderer
  uint32_t bsdf_kinds = 0;  // bit per MaterialKind some geometry uses (through a mix too)
  // the pipelines for other surfaces than diffuse are needed (a kind, or a mix to resolve)
  bool has_materials() const { return (bsdf_kinds & ~1u) != 0 || geom.has_mix; }
  uint32_t features = 0;  // the scene's (SceneFeature bits, detected by finalize_scene)
  bool has_area() const { return (features & feat_area_lights) != 0; }
  bool has_delta() const { return (features & feat_delta_lights) != 0; }
  bool all_rects() const { return (features & feat_rect_lights_only) != 0; }  // Urena's map, no dispatch
};


// sky_compensated: the estimator draws the skies' light samples from their compensated
// distributions (LightView::sky_dist, under MIS with BSDF samples), so the power picker
// weighs each sky by the part of it those samples draw (SkyMap::compensated_share; none of
// a constant sky, which is left to the BSDF technique).
SceneViews build_views(const Scene& scene, LightPick pick, bool sky_compensated = false);

}  // namespace tuile

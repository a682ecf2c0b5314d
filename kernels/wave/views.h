// The scene as the stages read it besides the light table (light/table.h): per-geometry
// lookups by Embree's geomID / primID, and the camera. Plain pointers into arrays the
// renderer owns (src/render/views.h builds them).
#pragma once
#include <cstdint>

namespace tuile {

// Per-geometry data the hit stages look up by Embree's geomID / primID.
struct GeomView {
  int32_t mesh_count = 0;
  const int32_t* geom_material = nullptr;      // per geomID (meshes then spheres), never -1
  const float* sphere_center = nullptr;        // per sphere: centre xyz and radius
  bool has_textures = false;
  // Every triangle of every mesh, flattened: triangle tri_offset[geomID] + primID.
  const int32_t* tri_offset = nullptr;         // per geomID (0 for spheres)
  const float* tri_pos = nullptr;              // per triangle: v0 v1 v2, xyz each (9 floats)
  const int32_t* tri_light = nullptr;          // per triangle: light or -1
  const int32_t* sphere_light = nullptr;       // per sphere: light or -1
  const float *mat_r = nullptr, *mat_g = nullptr, *mat_b = nullptr;
  const int32_t* mat_texture = nullptr;
  const uint32_t* const* indices = nullptr;    // per mesh
  const float* const* positions = nullptr;     // per mesh, xyz per vertex
  const float* const* uvs = nullptr;           // per mesh, nullptr without uv
  const float* const* tex_rgb = nullptr;       // per texture
  const int32_t *tex_w = nullptr, *tex_h = nullptr;
};

struct CameraView {
  float m[3][4];          // world_from_camera
  float sx0, sx1, sy0, sy1;  // screen window
  float tan_half;         // tan(fov / 2)
  float inv_w, inv_h;
};

}  // namespace tuile

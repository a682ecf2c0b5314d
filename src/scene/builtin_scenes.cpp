// Scenes compiled into the binary: the default ("two-panels", the course's
// demonstration of light sampling) and a Cornell-box-like room ("cornell").
#include <cmath>

#include "scene/scene.h"

namespace tuile {

namespace {

// Appends the quad p0, p0+e1, p0+e1+e2, p0+e2 as two triangles (0,1,2) (0,2,3):
// normal cross(e1, e2), recognised as one parallelogram source when emissive.
void add_quad(Mesh& m, vec3f p0, vec3f e1, vec3f e2) {
  const uint32_t base = static_cast<uint32_t>(m.positions.size() / 3);
  for (vec3f p : {p0, p0 + e1, p0 + e1 + e2, p0 + e2}) {
    m.positions.push_back(p.x);
    m.positions.push_back(p.y);
    m.positions.push_back(p.z);
  }
  for (uint32_t i : {0u, 1u, 2u, 0u, 2u, 3u}) m.indices.push_back(base + i);
}

Mesh make_mesh(const char* name, int material) {
  Mesh m;
  m.name = std::string("built-in:") + name;
  m.material = material;
  return m;
}

// An axis-aligned box with outward normals.
void add_box(Mesh& m, vec3f lo, vec3f hi) {
  const vec3f d = hi - lo;
  const vec3f ex{d.x, 0, 0}, ey{0, d.y, 0}, ez{0, 0, d.z};
  add_quad(m, lo, ey, ex);                     // z = lo (normal -z)
  add_quad(m, lo + ez, ex, ey);                // z = hi (+z)
  add_quad(m, lo, ez, ey);                     // x = lo (-x)
  add_quad(m, lo + ex, ey, ez);                // x = hi (+x)
  add_quad(m, lo, ex, ez);                     // y = lo (-y)
  add_quad(m, lo + ey, ez, ex);                // y = hi (+y)
}

Scene two_panels() {
  Scene s;
  s.source = "built-in:two-panels";
  s.materials.push_back(diffuse_material(Rgb{0.8f, 0.8f, 0.8f}, -1));    // floor
  s.materials.push_back(diffuse_material(Rgb{0.2f, 0.2f, 0.2f}, -1));    // panel backs
  Mesh floor = make_mesh("two-panels floor", 0);
  add_quad(floor, {-6, 0, -6}, {0, 0, 12}, {12, 0, 0});      // normal +y
  s.meshes.push_back(std::move(floor));
  const float h = 0.8f;  // both panels at the same height, facing down
  const Rgb L{4.f, 4.f, 4.f};
  Mesh left = make_mesh("two-panels left source", 1);
  add_quad(left, {-1.6f, h, -0.5f}, {1, 0, 0}, {0, 0, 1});   // cross(x, z) = -y: emits down
  left.emission = L;
  s.meshes.push_back(std::move(left));
  Mesh right = make_mesh("two-panels right 10x10 sources", 1);
  for (int i = 0; i < 10; ++i)
    for (int j = 0; j < 10; ++j)
      add_quad(right, {0.6f + 0.1f * i, h, -0.5f + 0.1f * j}, {0.1f, 0, 0}, {0, 0, 0.1f});
  right.emission = L;
  s.meshes.push_back(std::move(right));
  s.camera.width = 640;
  s.camera.height = 360;
  s.camera.fov_deg = 45;
  // pbrt-style camera: Scale -1 1 1 then LookAt makes +x appear to the right
  camera_look_at(s.camera, {0, 0.55f, 3.4f}, {0, 0.2f, 0}, {0, 1, 0});
  for (int r = 0; r < 3; ++r) s.camera.world_from_camera[r][0] = -s.camera.world_from_camera[r][0];
  return s;
}

Scene cornell() {
  Scene s;
  s.source = "built-in:cornell";
  s.materials.push_back(diffuse_material(Rgb{0.73f, 0.73f, 0.73f}, -1));  // white
  s.materials.push_back(diffuse_material(Rgb{0.65f, 0.05f, 0.05f}, -1));  // red
  s.materials.push_back(diffuse_material(Rgb{0.12f, 0.45f, 0.15f}, -1));  // green
  Mesh white = make_mesh("cornell white walls", 0);
  add_quad(white, {0, 0, 0}, {0, 0, 1}, {1, 0, 0});   // floor, +y
  add_quad(white, {0, 1, 0}, {1, 0, 0}, {0, 0, 1});   // ceiling, -y
  add_quad(white, {0, 0, 0}, {1, 0, 0}, {0, 1, 0});   // back wall z=0, +z
  add_box(white, {0.53f, 0, 0.12f}, {0.83f, 0.6f, 0.42f});  // tall block
  add_box(white, {0.15f, 0, 0.50f}, {0.45f, 0.3f, 0.80f});  // short block
  s.meshes.push_back(std::move(white));
  Mesh red = make_mesh("cornell red wall", 1);
  add_quad(red, {0, 0, 0}, {0, 1, 0}, {0, 0, 1});     // x=0, +x
  s.meshes.push_back(std::move(red));
  Mesh green = make_mesh("cornell green wall", 2);
  add_quad(green, {1, 0, 0}, {0, 0, 1}, {0, 1, 0});   // x=1, -x
  s.meshes.push_back(std::move(green));
  Mesh light = make_mesh("cornell light", 0);
  add_quad(light, {0.38f, 0.999f, 0.38f}, {0.24f, 0, 0}, {0, 0, 0.24f});  // emits down
  light.emission = {17.f, 12.f, 4.f};
  s.meshes.push_back(std::move(light));
  s.camera.width = 512;
  s.camera.height = 512;
  s.camera.fov_deg = 40;
  camera_look_at(s.camera, {0.5f, 0.5f, 1.95f}, {0.5f, 0.5f, 0}, {0, 1, 0});
  for (int r = 0; r < 3; ++r) s.camera.world_from_camera[r][0] = -s.camera.world_from_camera[r][0];
  return s;
}

}  // namespace

std::vector<std::string> builtin_scene_names() { return {"two-panels", "cornell"}; }

Scene builtin_scene(const std::string& name) {
  if (name == "two-panels" || name.empty()) return two_panels();
  if (name == "cornell") return cornell();
  throw SceneError("built-in:" + name + ": error: no such built-in scene (expected two-panels or cornell)");
}

}  // namespace tuile

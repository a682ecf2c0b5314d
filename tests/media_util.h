// Scenes with participating media built in code, for the media tests
// (tests/test_media_render.cpp, tests/test_stress.cpp).
#pragma once
#include <algorithm>
#include <array>
#include <utility>

#include "render/render.h"
#include "scene/scene.h"
#include "render_util.h"

namespace tuile::test {

// A closed box [lo, hi] as triangles whose Embree normal (cross(v1 - v0, v2 - v0)) points out.
inline Mesh media_box(vec3f lo, vec3f hi) {
  Mesh m;
  m.name = "box";
  const vec3f c = (lo + hi) * 0.5f;
  auto quad = [&](vec3f a, vec3f b, vec3f d, vec3f e) {
    for (const auto& t : {std::array<vec3f, 3>{a, b, d}, std::array<vec3f, 3>{a, d, e}}) {
      vec3f v0 = t[0], v1 = t[1], v2 = t[2];
      const vec3f n = cross(v1 - v0, v2 - v0);
      if (dot(n, (v0 + v1 + v2) * (1.f / 3.f) - c) < 0) std::swap(v1, v2);
      for (const vec3f& v : {v0, v1, v2}) {
        m.indices.push_back(static_cast<uint32_t>(m.positions.size() / 3));
        m.positions.insert(m.positions.end(), {v.x, v.y, v.z});
      }
    }
  };
  const float x0 = lo.x, y0 = lo.y, z0 = lo.z, x1 = hi.x, y1 = hi.y, z1 = hi.z;
  quad({x0, y0, z0}, {x1, y0, z0}, {x1, y1, z0}, {x0, y1, z0});
  quad({x0, y0, z1}, {x1, y0, z1}, {x1, y1, z1}, {x0, y1, z1});
  quad({x0, y0, z0}, {x0, y1, z0}, {x0, y1, z1}, {x0, y0, z1});
  quad({x1, y0, z0}, {x1, y1, z0}, {x1, y1, z1}, {x1, y0, z1});
  quad({x0, y0, z0}, {x1, y0, z0}, {x1, y0, z1}, {x0, y0, z1});
  quad({x0, y1, z0}, {x1, y1, z0}, {x1, y1, z1}, {x0, y1, z1});
  return m;
}

inline Medium homogeneous(Rgb sigma_a, Rgb sigma_s, float g = 0, Rgb Le = {0, 0, 0}) {
  Medium m;
  m.name = "m";
  m.type = "homogeneous";
  m.supported = true;
  m.sigma_a = sigma_a;
  m.sigma_s = sigma_s;
  m.g = g;
  m.Le = Le;
  return m;
}

inline Material interface_material() {
  Material m;
  m.interface = true;
  return m;
}

// A slab of medium (thickness d along z, wide) between the camera and a two-sided emitter
// of radiance L, bounded by an interface box; a narrow field of view (0.5 degrees), so every
// camera ray crosses the slab within 2e-5 of straight (1 / cos 0.36 degrees - 1).
// boundary: the slab's material, an interface by default (a dielectric: the medium inside glass).
inline Scene slab_scene(const Medium& md, float d, Rgb L, const Material& boundary = interface_material()) {
  Scene s;
  s.source = "test:slab";
  s.media.push_back(md);
  s.materials.push_back(boundary);
  s.materials.push_back(diffuse_material(Rgb{0.5f, 0.5f, 0.5f}));
  Mesh slab = media_box({-50, -50, 0}, {50, 50, d});
  slab.material = 0;
  slab.medium_inside = 0;
  s.meshes.push_back(slab);
  if (L.any_positive()) {
    Mesh lamp;
    lamp.name = "lamp";
    lamp.material = 1;
    add_quad(lamp, {-20, -20, 10}, {40, 0, 0}, {0, 40, 0});
    lamp.emission = L;
    lamp.two_sided = true;
    s.meshes.push_back(lamp);
  }
  s.camera.width = s.camera.height = 8;
  s.camera.fov_deg = 0.5f;
  camera_look_at(s.camera, {0, 0, -5}, {0, 0, 0}, {0, 1, 0});
  finalize_scene(s);
  return s;
}

// Uniform sky L around a sphere of medium (radius 1 at the origin, an interface), seen from
// (0, 0, -5); fov: the camera's field.
inline Scene furnace_scene(const Medium& md, float L, float fov, int res) {
  Scene s;
  s.source = "test:medium-furnace";
  s.media.push_back(md);
  s.materials.push_back(interface_material());
  Sphere sp;
  sp.center = {0, 0, 0};
  sp.radius = 1;
  sp.material = 0;
  sp.medium_inside = 0;
  s.spheres.push_back(sp);
  Light sky;
  sky.type = LightKind::infinite;
  sky.radiance = {L, L, L};
  s.lights.push_back(sky);
  s.camera.width = s.camera.height = res;
  s.camera.fov_deg = fov;
  camera_look_at(s.camera, {0, 0, -5}, {0, 0, 0}, {0, 1, 0});
  finalize_scene(s);
  return s;
}

// An estimator the media tests run, and its render options (a uniform pick, independent
// samples whose per-pixel variances state the error, two threads).
struct MediaEst {
  const char* name;
  Strategy strategy;
  MisMode mode;
};
inline RenderOptions media_options(const MediaEst& e, int depth, uint32_t spp, uint32_t seed) {
  return independent_options(e.strategy, LightPick::uniform, e.mode, depth, spp, seed);
}

}  // namespace tuile::test

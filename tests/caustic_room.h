// A closed room with caustics, shared by the tests of the estimators that trace paths
// from the lights (tests/test_light_paths.cpp, tests/test_bdpt.cpp).
#pragma once
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "media_util.h"
#include "render_util.h"

namespace tuile::test {

// A box [lo, hi] as two meshes: its top face (material top) and its other faces (material
// rest), each triangle's Embree normal pointing out.
inline void add_slab(Scene& s, vec3f lo, vec3f hi, int top, int rest) {
  const Mesh box = media_box(lo, hi);
  Mesh upper, other;
  upper.name = "slab top";
  upper.material = top;
  other.name = "slab";
  other.material = rest;
  for (size_t t = 0; t < box.indices.size(); t += 3) {
    bool up = true;
    for (size_t k = 0; k < 3; ++k) up = up && box.positions[3 * box.indices[t + k] + 1] == hi.y;
    Mesh& m = up ? upper : other;
    for (size_t k = 0; k < 3; ++k) {
      const uint32_t i = box.indices[t + k];
      m.indices.push_back(static_cast<uint32_t>(m.positions.size() / 3));
      m.positions.insert(m.positions.end(), {box.positions[3 * i], box.positions[3 * i + 1], box.positions[3 * i + 2]});
    }
  }
  EXPECT_EQ(upper.indices.size(), 6u);  // the top face's two triangles
  s.meshes.push_back(upper);
  s.meshes.push_back(other);
}

// A closed room (diffuse walls, one of them coloured, the back one a smooth coat over a
// diffuse base: a delta lobe and a diffuse one), a smooth glass sphere, a mirror on the
// right wall, and a light on the ceiling facing down, a fifth of the ceiling wide (large
// enough that the path tracer finds its caustics often: its image is a reference the test
// can trust), or a sphere source under the ceiling.
inline Scene caustic_room(int res, bool shading_normals_ball = false, bool finalize = true, bool sphere_light = false) {
  Scene s;
  s.source = "test:caustic-room";
  s.materials.push_back(diffuse_material(Rgb{0.7f, 0.7f, 0.7f}));  // 0
  s.materials.push_back(diffuse_material(Rgb{0.6f, 0.2f, 0.1f}));  // 1
  s.materials.push_back(glass_material());  // 2
  Material mirror;
  mirror.kind = MaterialKind::conductor;
  mirror.eta_rgb = {0.2f, 0.9f, 1.1f};
  mirror.k_rgb = {3.9f, 2.4f, 2.1f};
  s.materials.push_back(mirror);  // 3
  Material coat;
  coat.kind = MaterialKind::coated_diffuse;
  coat.reflectance = {0.3f, 0.5f, 0.6f};
  s.materials.push_back(coat);  // 4: alpha 0, a smooth coat
  Material rough_glass = glass_material();
  rough_glass.alpha_u.value = rough_glass.alpha_v.value = 0.25f;
  s.materials.push_back(rough_glass);  // 5
  auto quad = [&](const char* name, int mat, vec3f p0, vec3f e1, vec3f e2, float L = 0) {
    add_named_quad(s, name, mat, p0, e1, e2, L);
  };
  quad("floor", 0, {-1.5f, 0, -1.5f}, {0, 0, 4.5f}, {3, 0, 0});
  quad("ceiling", 0, {-1.5f, 2, -1.5f}, {3, 0, 0}, {0, 0, 4.5f});
  quad("back", 4, {-1.5f, 0, -1.5f}, {3, 0, 0}, {0, 2, 0});
  quad("left", 1, {-1.5f, 0, -1.5f}, {0, 2, 0}, {0, 0, 4.5f});
  quad("right", 0, {1.5f, 0, -1.5f}, {0, 0, 4.5f}, {0, 2, 0});
  quad("front", 0, {-1.5f, 0, 3}, {0, 2, 0}, {3, 0, 0});
  // a glass slab whose top is smooth and its other faces rough: light that enters by the
  // top (a delta lobe) leaves by a rough face, where the light tracer's vertex inside the
  // glass joins the camera (its throughput carries the entry's etap^2)
  {
    add_slab(s, {0.4f, 0.9f, -1.2f}, {1.2f, 1.05f, -0.4f}, 2, 5);
  }
  quad("mirror", 3, {1.49f, 0.2f, -1.2f}, {0, 0, 1.4f}, {0, 1.2f, 0});
  if (sphere_light) {
    Sphere light;
    light.center = {0.1f, 1.65f, -0.3f};
    light.radius = 0.15f;
    light.material = 0;
    light.emission = {25, 25, 25};
    s.spheres.push_back(light);
  } else {
    quad("light", 0, {-0.6f, 1.99f, -0.9f}, {1.2f, 0, 0}, {0, 0, 1.0f}, 6);  // facing down
  }
  if (shading_normals_ball) {  // a coarse sphere with vertex normals: shading normals
    Mesh ball;
    ball.name = "ball";
    ball.material = 2;
    const int nu = 16, nv = 10;
    const vec3f c{-0.2f, 0.55f, -0.2f};
    const float r = 0.45f;
    for (int j = 0; j <= nv; ++j)
      for (int i = 0; i <= nu; ++i) {
        const float th = 3.14159265f * static_cast<float>(j) / nv, ph = 6.2831853f * static_cast<float>(i) / nu;
        const vec3f n{std::sin(th) * std::cos(ph), std::cos(th), std::sin(th) * std::sin(ph)};
        ball.positions.insert(ball.positions.end(), {c.x + r * n.x, c.y + r * n.y, c.z + r * n.z});
        ball.normals.insert(ball.normals.end(), {n.x, n.y, n.z});
      }
    for (int j = 0; j < nv; ++j)
      for (int i = 0; i < nu; ++i) {
        const uint32_t a = static_cast<uint32_t>(j * (nu + 1) + i), b = a + 1, d = a + nu + 1, e = d + 1;
        for (uint32_t k : {a, d, b, b, d, e}) ball.indices.push_back(k);
      }
    s.meshes.push_back(ball);
  } else {
    Sphere ball;
    ball.center = {-0.2f, 0.55f, -0.2f};
    ball.radius = 0.45f;
    ball.material = 2;
    s.spheres.push_back(ball);
  }
  s.camera.width = s.camera.height = res;
  s.camera.fov_deg = 60;
  camera_look_at(s.camera, {0, 1.2f, 2.8f}, {0, 0.5f, 0}, {0, 1, 0});
  if (finalize) finalize_scene(s);
  return s;
}


// A glass slab seen from below, lit from above: its top is smooth, its other faces diffuse
// transmitters, so light that entered by the top (a delta lobe) leaves by the bottom, where
// a light path's vertex inside the glass joins the camera. Its throughput must carry the
// entry's etap^2 (importance is not scaled by 1 / eta^2 as radiance is).
inline Scene glass_slab_scene() {
  Scene s;
  s.source = "test:glass-slab";
  s.materials.push_back(diffuse_material(Rgb{0.5f, 0.5f, 0.5f}));
  Material top;
  top.kind = MaterialKind::dielectric;
  top.eta = 1.5f;
  s.materials.push_back(top);
  Material rough;
  rough.kind = MaterialKind::diffuse_transmission;
  rough.reflectance = {0.3f, 0.3f, 0.3f};
  rough.transmittance = {0.6f, 0.6f, 0.6f};
  s.materials.push_back(rough);
  add_slab(s, {-0.6f, 0.f, -0.6f}, {0.6f, 0.15f, 0.6f}, 1, 2);
  Mesh light;
  light.material = 0;
  light.emission = {4, 4, 4};
  add_quad(light, {-0.5f, 1.f, -0.5f}, {1.f, 0, 0}, {0, 0, 1.f});  // facing down
  s.meshes.push_back(light);
  s.camera.width = s.camera.height = 16;
  s.camera.fov_deg = 50;
  camera_look_at(s.camera, {0.2f, -1.2f, 0.1f}, {0, 0, 0}, {0, 0, 1});
  finalize_scene(s);
  return s;
}

// An estimator that splats (the light tracer, bdpt): the same bits on one thread and on two
// (Sobol' sampler, `on`), and an image that differs from `off`'s (it ran).
inline void expect_same_bits_on_any_thread_count(const Scene& s, RenderOptions on, RenderOptions off, uint32_t spp) {
  Accel accel(s);
  auto render = [&](RenderOptions o, int threads) {
    o.est.sampler = SamplerKind::sobol;
    o.threads = threads;
    return render_mean(s, accel, o, spp);
  };
  const std::vector<float> two = render(on, 2), one = render(on, 1), plain = render(off, 2);
  size_t differ = 0, differ_plain = 0;
  for (size_t i = 0; i < two.size(); ++i) {
    differ += two[i] != one[i];
    differ_plain += two[i] != plain[i];
  }
  EXPECT_EQ(differ, 0u);
  EXPECT_GT(differ_plain, two.size() / 4);
}

// The room filled with a fog (inside an interface box that also holds the light and the
// glass), the camera outside it: the glass throws a caustic into the fog, which the light
// tracer's vertices in the medium join to the camera through the interface. With
// camera_inside, the box reaches past the camera, which sits in the fog (Scene::camera_medium).
inline Scene caustic_fog_room(int res, Rgb sigma_s, bool camera_inside = false) {
  Scene s = caustic_room(res, false, false);
  s.media.push_back(homogeneous({0.05f, 0.05f, 0.08f}, sigma_s, 0.3f));
  const int fog = 0;
  const int iface = static_cast<int>(s.materials.size());
  s.materials.push_back(interface_material());
  Mesh box = media_box({-1.45f, 0.01f, -1.45f}, {1.45f, 1.98f, camera_inside ? 2.95f : 2.5f});
  box.material = iface;
  box.medium_inside = fog;
  s.meshes.push_back(box);
  if (camera_inside) s.camera_medium = fog;
  for (Sphere& sp : s.spheres) sp.medium_outside = fog;  // the glass: vacuum inside, fog outside
  // the light just under the ceiling, inside the fog: a MediumInterface says so
  for (Mesh& m : s.meshes)
    if (m.name == "light") {
      for (size_t k = 1; k < m.positions.size(); k += 3) m.positions[k] = 1.95f;
      m.medium_inside = fog;
      m.medium_outside = fog;
    }
  finalize_scene(s);
  return s;
}

}  // namespace tuile::test
